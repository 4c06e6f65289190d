"""EtherNet/IP over DTLS, originator side, for blocking code: one UDP socket to the device's port 2221
and a ``DtlsChannel`` over it, with no event loop and no thread.

``DtlsLink`` is what the blocking originator uses in place of its TCP socket (``sendall``/``recv`` of
encapsulation messages, one per record, ``BlockingEncapsulationClient``) and what its class 1 shell
uses in place of its UDP socket (``send_io``, ``drain``, ``blocking_io.SyncIoConnection``): a
Forward_Open sent in the session opens a connection whose data flows in the same session. Records
are sorted as the target sorts them (``dtls_target.is_io_datagram``). The handshake runs here, its
lost flights resent at the record layer's deadlines; a handshake that fails raises ``SecurityError``
naming the cause, one that gets no answer ``PeerUnreachable``.
"""

from __future__ import annotations

import select
import socket
import time
from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING

from ..eip.io_server import RECEIVE_BUFFER
from ..errors import NoReply, NothingListens, PeerUnreachable, SecurityError
from .dtls import DtlsChannel, describe_dtls_failure, dtls_context
from .dtls_target import is_io_datagram

if TYPE_CHECKING:
    from .credentials import Credentials

#: The largest UDP payload.
MAX_DATAGRAM = 65535


class DtlsLink:
    """One DTLS session with a device, blocking."""

    def __init__(self, credentials: Credentials, host: str, port: int, timeout: float) -> None:
        """Connect to ``host:port`` and complete the handshake within ``timeout`` seconds."""
        from OpenSSL import SSL

        self._ssl_error = SSL.Error
        self.credentials = credentials
        self.host = host
        self.port = port
        #: The PSK identity offered, named in a refusal that is about the key.
        self.identity = credentials.psk.identity if credentials.psk is not None else None
        self._timeout: float | None = timeout
        self._stream: deque[bytes] = deque()
        #: Class 1 records read while waiting for something else, for the class 1 shell's next ``drain``.
        self._io: deque[tuple[bytes, float]] = deque()
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.connect((host, port))
            self.sock.setblocking(False)
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER)
            self.channel = DtlsChannel.client(dtls_context(credentials, server=False))
            self._handshake(time.monotonic() + timeout)
        except PeerUnreachable:   # already says where and why (an OSError too: not wrapped again)
            self.sock.close()
            raise
        except OSError as exc:
            self.sock.close()
            raise PeerUnreachable.connecting(host, port, exc) from None
        except BaseException:
            self.sock.close()
            raise

    def _handshake(self, deadline: float) -> None:
        channel = self.channel
        self._flush()
        while not channel.established:
            now = time.monotonic()
            if now >= deadline:
                raise NoReply(f"DTLS with {self.host}:{self.port}: no answer to the handshake "
                              "(is the device serving CIP Security over UDP there?)")
            retransmit = channel.timeout()
            wait = deadline - now if retransmit is None else min(deadline - now, max(retransmit, 0.0))
            if not select.select([self.sock], [], [], wait)[0]:
                if retransmit is not None:
                    channel.on_timer()
                    self._flush()
                continue
            for datagram in self._read_all():
                try:
                    self._sort(channel.feed(datagram), time.monotonic())
                except self._ssl_error as exc:
                    self._flush()
                    cause = self.credentials.explain(
                        describe_dtls_failure(exc, self.identity, self.channel.verify_error))
                    raise SecurityError(f"DTLS with {self.host}:{self.port} failed: {cause}") from None
            self._flush()

    def _read_all(self) -> list[bytes]:
        out = []
        while True:
            try:
                out.append(self.sock.recv(MAX_DATAGRAM))
            except (BlockingIOError, InterruptedError):
                return out
            except ConnectionRefusedError:
                raise NothingListens(f"DTLS with {self.host}:{self.port}: nothing listens there "
                                     "(ICMP port unreachable)") from None

    def _sort(self, records: list[bytes], now: float) -> None:
        for plain in records:
            if is_io_datagram(plain):
                self._io.append((plain, now))
            elif plain:
                self._stream.append(plain)
        if self.channel.closed:
            raise PeerUnreachable(f"DTLS session with {self.host}:{self.port} closed by the device")

    def _flush(self) -> None:
        for datagram in self.channel.datagrams():
            try:
                self.sock.send(datagram)
            except (BlockingIOError, InterruptedError):
                pass   # a full buffer: DTLS resends what matters (the handshake), class 1 sends newer data
            except ConnectionRefusedError:
                raise NothingListens(f"DTLS with {self.host}:{self.port}: nothing listens there "
                                     "(ICMP port unreachable)") from None

    def _pump(self) -> None:
        """Read what arrived, sorting records into the stream and the class 1 queue."""
        try:
            for datagram in self._read_all():
                self._sort(self.channel.feed(datagram), time.monotonic())
        except self._ssl_error as exc:
            cause = self.credentials.explain(describe_dtls_failure(exc, self.identity, self.channel.verify_error))
            raise SecurityError(f"DTLS with {self.host}:{self.port} failed: {cause}") from None
        self._flush()

    # -- what the blocking originator uses of a socket -------------------------------------------------
    def settimeout(self, timeout: float | None) -> None:
        self._timeout = timeout

    def sendall(self, data: bytes) -> None:
        """Send one encapsulation message (or several back to back) as one record."""
        self.channel.send(data)
        self._flush()

    def recv(self, size: int) -> bytes:
        """The next encapsulation record's plaintext; ``NoReply`` (a ``TimeoutError``, as a socket's
        timeout is) after the timeout."""
        deadline = None if self._timeout is None else time.monotonic() + self._timeout
        while not self._stream:
            self._pump()
            if self._stream:
                break
            wait = None if deadline is None else deadline - time.monotonic()
            if wait is not None and wait <= 0:
                raise NoReply(f"no DTLS record from {self.host}:{self.port}")
            select.select([self.sock], [], [], wait)
        return self._stream.popleft()

    def getsockname(self) -> tuple[str, int]:
        return self.sock.getsockname()   # type: ignore[no-any-return]  # typeshed: Any; an AF_INET pair here

    def getpeername(self) -> tuple[str, int]:
        return self.sock.getpeername()   # type: ignore[no-any-return]  # typeshed: Any; an AF_INET pair here

    def close(self) -> None:
        """close_notify, then the socket."""
        try:
            self.channel.close()
            self._flush()
        except (OSError, PeerUnreachable):
            pass
        self.sock.close()

    # -- what the class 1 shell uses -------------------------------------------------------------------
    def send_io(self, datagram: bytes) -> None:
        """Send a class 1 datagram in the session."""
        self.channel.send(datagram)
        self._flush()

    def drain(self, receive: Callable[[bytes, tuple[str, int], float], None]) -> None:
        """Give every class 1 record that arrived to ``receive`` (with the device's address)."""
        self._pump()
        source = (self.host, self.port)
        while self._io:
            plain, now = self._io.popleft()
            receive(plain, source, now)


__all__ = ["DtlsLink"]
