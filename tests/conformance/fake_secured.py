"""The fake target's sessions through pyOpenSSL: DTLS 1.2 on its UDP port with the folder's device
certificate, and TLS 1.2 with the folder's pre-shared key on its TLS port (the standard library's
``ssl`` has no PSK before Python 3.13). Each record, or each message of a PSK session, goes to the
fake's encapsulation server (``answer``). Deviations: ``"security.dtls.handshake"`` (the session
answers nothing), ``"security.dtls.plaintext"`` (a plain datagram is answered in plain),
``"security.psk.handshake"`` (the PSK session answers nothing), ``"security.psk.unknown_identity"``
(any identity gets the key). Variants: a plain datagram answered by a fatal alert; an unknown identity
served a key of its own, so that the handshake fails on the Finished (RFC 4279, 2, permits both)."""

from __future__ import annotations

import os
import socket
from collections.abc import Callable
from pathlib import Path
from typing import Any

from OpenSSL import SSL

from cipstack.security.psk import bindings

#: DTLS 1.2 on the wire (RFC 6347, 4.1).
DTLS1_2 = 0xFEFD
#: A fatal unexpected_message alert in a DTLS 1.2 record of epoch 0 (RFC 6347 4.1; RFC 5246 7.2).
FATAL_ALERT = bytes((21, 0xFE, 0xFD)) + bytes(8) + b"\x00\x02\x02\x0a"
CERTIFICATE_SUITES = b"ECDHE-ECDSA-AES128-SHA256:ECDHE-ECDSA-AES128-GCM-SHA256:ECDHE-ECDSA-AES256-GCM-SHA384"
PSK_SUITES = b"ECDHE-PSK-AES128-CBC-SHA256:ECDHE-PSK-CHACHA20-POLY1305:PSK-AES128-GCM-SHA256:PSK-AES256-GCM-SHA384"
_SERVER_CALLBACK = "unsigned int (*)(SSL *, const char *, unsigned char *, unsigned int)"

Answer = Callable[[bytes, dict[str, int]], "bytes | None"]


def _flush(connection: SSL.Connection, send: Callable[[bytes], object]) -> None:
    while True:
        try:
            send(connection.bio_read(65536))
        except SSL.WantReadError:
            return


class FakeDtls:
    """DTLS on ``sock``: one pyOpenSSL server connection per peer address, no cookie exchange (a fake
    on loopback), no retransmission of its own flights (loopback loses none)."""

    def __init__(self, sock: socket.socket, folder: Path, deviates: Callable[[str], bool], answer: Answer,
                 stopped: Callable[[], bool], variant: str | None = None) -> None:
        self.sock = sock
        self.variant = variant
        self.sock.settimeout(0.05)
        self.deviates = deviates
        self.answer = answer
        self.stopped = stopped
        self.context = SSL.Context(SSL.DTLS_SERVER_METHOD)
        self.context.set_min_proto_version(DTLS1_2)
        self.context.set_max_proto_version(DTLS1_2)
        self.context.use_certificate_chain_file(str(folder / "device.pem"))
        self.context.use_privatekey_file(str(folder / "device.key"))
        self.context.load_verify_locations(str(folder / "ca.pem"))
        self.context.set_verify(SSL.VERIFY_PEER | SSL.VERIFY_FAIL_IF_NO_PEER_CERT)
        self.context.set_cipher_list(CERTIFICATE_SUITES)
        self.sessions: dict[tuple[str, int], tuple[SSL.Connection, dict[str, int]]] = {}

    def close(self) -> None:
        self.sock.close()

    def serve(self) -> None:
        while not self.stopped():
            try:
                data, peer = self.sock.recvfrom(65535)
            except TimeoutError:
                continue
            except OSError:
                return
            if self.variant != "no-dtls:silent":
                self.datagram(data, peer)

    def datagram(self, data: bytes, peer: tuple[str, int]) -> None:
        if peer not in self.sessions:
            if not (len(data) >= 13 and data[0] == 22 and data[1] == 0xFE):   # not a DTLS handshake record
                if self.deviates("security.dtls.plaintext"):
                    reply = self.answer(data, {"session": 0})   # answered in plain, as on 44818
                    if reply is not None:
                        self.sock.sendto(reply, peer)
                elif self.variant == "security.dtls.plaintext":
                    self.sock.sendto(FATAL_ALERT, peer)
                return
            connection = SSL.Connection(self.context, None)
            connection.set_accept_state()
            self.sessions[peer] = (connection, {"session": 0})
        connection, state = self.sessions[peer]
        connection.bio_write(data)
        try:
            connection.do_handshake()
            while True:
                record = connection.recv(65535)
                reply = None if self.deviates("security.dtls.handshake") else self.answer(record, state)
                if reply is not None:
                    connection.send(reply)
        except SSL.WantReadError:
            pass
        except SSL.Error:   # refused, or close_notify: the session ends
            del self.sessions[peer]
        _flush(connection, lambda datagram: self.sock.sendto(datagram, peer))


def psk_context(key: tuple[bytes, bytes], deviates: Callable[[str], bool], variant: str | None) -> SSL.Context:
    """TLS 1.2 with the PSK suites, the device holding ``key`` (identity, octets)."""
    lib, ffi = bindings()
    identity, octets = key
    context = SSL.Context(SSL.TLS_SERVER_METHOD)
    context.set_min_proto_version(SSL.TLS1_2_VERSION)
    context.set_max_proto_version(SSL.TLS1_2_VERSION)
    context.set_cipher_list(PSK_SUITES)

    def find(ssl: Any, named: Any, psk: Any, room: int) -> int:
        known = named != ffi.NULL and ffi.string(named) == identity
        served = octets
        if not known and variant == "security.psk.unknown_identity":
            served = os.urandom(len(octets))   # as if the identity existed with another key
        elif not known and not deviates("security.psk.unknown_identity"):
            return 0   # OpenSSL refuses with unknown_psk_identity
        ffi.memmove(psk, served, len(served))
        return len(served)

    handle = ffi.callback(_SERVER_CALLBACK, find)
    _KEPT.append(handle)   # OpenSSL holds the bare pointer: the callback must outlive the context
    lib.SSL_CTX_set_psk_server_callback(context._context, handle)  # internals: pyOpenSSL has no PSK call
    return context


_KEPT: list[Any] = []


def serve_psk_connection(conn: socket.socket, key: tuple[bytes, bytes], deviates: Callable[[str], bool],
                         answer: Answer, stopped: Callable[[], bool], variant: str | None = None) -> None:
    """A TLS connection whose ClientHello offers PSK suites alone, over memory BIOs."""
    connection = SSL.Connection(psk_context(key, deviates, variant), None)
    connection.set_accept_state()
    state = {"session": 0}
    buffer = b""
    conn.settimeout(0.05)
    with conn:
        while not stopped():
            try:
                data = conn.recv(65536)
            except TimeoutError:
                continue
            except OSError:
                return
            if not data:
                return
            connection.bio_write(data)
            try:
                connection.do_handshake()
                while True:
                    buffer += connection.recv(65536)
            except SSL.WantReadError:
                pass
            except SSL.Error:   # refused (its alert goes out), or close_notify
                _flush(connection, conn.sendall)
                return
            while len(buffer) >= 24:
                length = int.from_bytes(buffer[2:4], "little")
                if len(buffer) < 24 + length:
                    break
                message, buffer = buffer[:24 + length], buffer[24 + length:]
                reply = None if deviates("security.psk.handshake") else answer(message, state)
                if reply is not None:
                    connection.send(reply)
            try:
                _flush(connection, conn.sendall)
            except OSError:
                return
