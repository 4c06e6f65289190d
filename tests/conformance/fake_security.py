"""CIP Security for the scripted fake target: the three objects' attributes (a Configured device with
the ECDHE-ECDSA and PSK suites), the configuration services a configured device answers, a TLS listener on a
port of its own that hands each TLS connection to the fake's encapsulation server (a connection whose
ClientHello offers only PSK suites is served with the folder's key, through pyOpenSSL), and a DTLS
listener on UDP at the same port number. Each check of group security has one deviation here, named
by its id."""

from __future__ import annotations

import shutil
import socket
import ssl
import struct
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from cipstack.security.provisioning import init

SUITES = {0xC023: "ECDHE-ECDSA-AES128-SHA256", 0xC02B: "ECDHE-ECDSA-AES128-GCM-SHA256",
          0xC02C: "ECDHE-ECDSA-AES256-GCM-SHA384"}
#: The PSK suites it allows too (it holds the folder's key), by IANA id.
PSK_SUITES = (0xC037, 0xCCAC, 0x00A8, 0x00A9)
OWN_PATH = b"\x02\x20\x5f\x24\x01"     # one path: 2 words, 0x5F/1


def _bind_both(host: str) -> tuple[socket.socket, socket.socket]:
    """A TCP listener and a UDP socket on the same free port number (a device's 2221 is both)."""
    for _ in range(50):
        stream = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        stream.bind((host, 0))
        datagrams = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            datagrams.bind((host, stream.getsockname()[1]))
        except OSError:
            stream.close()
            datagrams.close()
            continue
        return stream, datagrams
    raise OSError("no port number free for both TCP and UDP")


#: The PSK suites by IANA id (RFC 5489, RFC 7905, RFC 5487) and the renegotiation SCSV (RFC 5746).
PSK_SUITE_IDS = frozenset({0xC037, 0xCCAC, 0x00A8, 0x00A9})
SCSV = 0x00FF


def offers_psk_only(conn: socket.socket) -> bool:
    """Whether the ClientHello waiting on ``conn`` offers PSK suites alone (RFC 5246, 7.4.1.2: the
    record and handshake headers, version, random and session id come before the suites). Loopback
    delivers the ClientHello whole; one peeked in part counts as a certificate client."""
    try:
        hello = conn.recv(4096, socket.MSG_PEEK)
    except OSError:
        return False   # the certificate path meets the same error and closes the connection
    at = 5 + 4 + 2 + 32
    if len(hello) <= at:
        return False
    at += 1 + hello[at]
    if len(hello) < at + 2:
        return False
    (size,) = struct.unpack_from(">H", hello, at)
    suites = {int.from_bytes(hello[i:i + 2], "big") for i in range(at + 2, min(at + 2 + size, len(hello) - 1), 2)}
    suites.discard(SCSV)
    return bool(suites) and suites <= PSK_SUITE_IDS


def _reply(service: int, status: int = 0, data: bytes = b"") -> bytes:
    return bytes((service | 0x80, 0, status, 0)) + data


class FakeSecurity:
    """What the fake serves of CIP Security; ``deviates(check_id)`` is the fake target's."""

    def __init__(self, deviates: Callable[[str], bool], host: str, start: Callable[..., None],
                 serve: Callable[[Any], None], stopped: Callable[[], bool],
                 answer: Callable[[bytes, dict[str, int]], bytes | None], variant: str | None = None) -> None:
        """``serve``: the fake's encapsulation server, given a connection; ``answer``: the same for one
        encapsulation message of a session's ``state`` (DTLS records, PSK sessions), its reply or None;
        ``variant``: the fake target's (``VARIANTS``), or ``"no-dtls:unreachable"`` (its UDP port closed:
        ICMP port unreachable) or ``"no-dtls:silent"`` (datagrams read, none answered)."""
        self.deviates = deviates
        self.serve = serve
        self.start = start
        self.stopped = stopped
        self.answer = answer
        self._temporary = tempfile.mkdtemp(prefix="fake-security-")
        #: The credentials folder the battery is given (``--security DIR``): certificates and a key.
        self.folder = Path(self._temporary) / "lab"
        init(self.folder, psk=True)
        identity, _, key = (self.folder / "psk.txt").read_text().strip().partition(":")
        #: The pre-shared key the device holds: its identity and octets.
        self.psk = (identity.encode(), bytes.fromhex(key))
        ids = (*SUITES, *PSK_SUITES)
        suites = bytes((len(ids),)) + b"".join(s.to_bytes(2, "big") for s in ids)
        self.attributes: dict[tuple[int, int], bytes] = {
            (0x5D, 1): b"\x02",
            (0x5E, 1): b"\x02", (0x5E, 2): struct.pack("<I", 1),
            (0x5E, 3): suites[:-2] if deviates("security.objects.attributes") else suites,   # one id short
            (0x5E, 4): suites, (0x5E, 6): b"\x01" + OWN_PATH, (0x5E, 7): b"\x01" + OWN_PATH,
            (0x5E, 8): b"\x00", (0x5E, 9): b"\x01", (0x5E, 10): b"\x00", (0x5E, 11): b"\x00", (0x5E, 12): b"\x00",
            (0x5E, 13): b"\x01", (0x5E, 14): b"\x00\x00", (0x5E, 15): struct.pack("<H", 12), (0x5E, 16): b"\x00",
            (0x5F, 1): b"\x1aDefault Device Certificate", (0x5F, 2): b"\x03", (0x5F, 5): b"\x00",
            (0x5F, 3): b"\x01\x02\x20\x37\x24\xca", (0x5F, 4): b"\x01\x02\x20\x37\x24\xcb",
        }
        self.context = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
        self.context.minimum_version = self.context.maximum_version = ssl.TLSVersion.TLSv1_2
        self.context.load_cert_chain(self.folder / "device.pem", self.folder / "device.key")
        self.context.load_verify_locations(cafile=self.folder / "ca.pem")
        self.context.verify_mode = ssl.CERT_NONE if deviates("security.tls.untrusted_client") else ssl.CERT_REQUIRED
        names = list(SUITES.values())
        if deviates("security.tls.allowed_suite"):
            names = ["ECDHE-ECDSA-AES256-GCM-SHA384"]     # not the first it lists as allowed
        if deviates("security.tls.disallowed_suite"):
            names.append("ECDHE-ECDSA-CHACHA20-POLY1305")
        self.context.set_ciphers(":".join(names))
        self.listener, datagrams = _bind_both(host)
        self.listener.listen(8)
        self.listener.settimeout(0.05)
        #: The TLS port, and the DTLS port of the same number.
        self.port = self.listener.getsockname()[1]
        self.variant = variant
        # pyOpenSSL only for a secured fake: the plain fake runs where only the wheel is installed.
        from .fake_secured import FakeDtls

        self.dtls = FakeDtls(datagrams, self.folder, deviates, answer, stopped, variant)
        start(self._accept)
        if variant == "no-dtls:unreachable":
            self.dtls.close()
        else:
            start(self.dtls.serve)

    def close(self) -> None:
        self.listener.close()
        self.dtls.close()
        shutil.rmtree(self._temporary, ignore_errors=True)

    # -- the objects -------------------------------------------------------------------------------------
    def request(self, service: int, class_id: int, attribute: int | None) -> bytes:
        if service == 0x0E and attribute is not None:
            if (class_id, attribute) == (0x5E, 5):
                if self.deviates("security.objects.psk_unreadable"):
                    return _reply(service, 0, b"\x01\x03lab\x04\x00\x01\x02\x03")
                return _reply(service, 0x14)
            value = self.attributes.get((class_id, attribute))
            return _reply(service, 0x14) if value is None else _reply(service, 0, value)
        if (service, class_id) == (0x4C, 0x5E):          # Kick_Timer: no session here
            return _reply(service, 0 if self.deviates("security.session.outside") else 0x0C)
        if (service, class_id) == (0x4B, 0x5E):          # Begin_Config: the device is Configured
            return _reply(service, 0 if self.deviates("security.session.begin") else 0x0C)
        return _reply(service, 0x08)

    # -- the TLS port ------------------------------------------------------------------------------------
    def _accept(self) -> None:
        while not self.stopped():
            try:
                conn, _ = self.listener.accept()
            except (TimeoutError, OSError):
                continue
            conn.settimeout(2.0)
            try:
                first = conn.recv(1, socket.MSG_PEEK)
            except OSError:
                conn.close()
                continue
            if first == b"\x16" and offers_psk_only(conn):
                from .fake_secured import serve_psk_connection

                self.start(serve_psk_connection, conn, self.psk, self.deviates, self.answer, self.stopped,
                           self.variant)
                continue
            if first != b"\x16":                          # not a TLS handshake record
                if self.deviates("security.tls.plaintext"):
                    conn.settimeout(0.05)
                    self.start(self.serve, conn)          # answered in plain, as on 44818
                else:
                    conn.close()
                continue
            try:
                tls = self.context.wrap_socket(conn, server_side=True)
            except (ssl.SSLError, OSError):
                conn.close()
                continue
            tls.settimeout(0.05)
            self.start(self.serve, tls)
