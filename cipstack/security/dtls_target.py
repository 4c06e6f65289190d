"""EtherNet/IP over DTLS (UDP 2221), target side, as a shell around the same sans-I/O cores.

One UDP socket; each peer address that completes a handshake is a session: a ``DtlsChannel`` (the
record layer in memory) and an ``EncapsulationConnection`` of the target, exactly what a TCP
connection on 44818 gets. Each record's plaintext is one of two things:

* a class 0/1 datagram (the Common Packet Format of a Sequenced Address item 0x8002 and a Connected
  Data item: what UDP 2222 carries; Wireshark's packet-enip.c hands DTLS on port 2221 to its CIP I/O
  dissector), given to the class 1 core as coming from that session;
* otherwise an encapsulation message (RegisterSession, SendRRData, SendUnitData ...), given to the
  session's ``EncapsulationConnection``; its replies go back in the session. A Forward_Open that comes
  this way opens a connection whose data flows in this session both ways (OpENer issue #234): the
  class 1 core sends its T->O datagrams to the session's address, which ``DatagramPaths`` routes here.

Stateless cookies (RFC 6347, 4.2.1): a ClientHello without a valid cookie is answered with a
HelloVerifyRequest whose cookie is an HMAC of the source address under a secret of this process, and
nothing is kept; a session is made only for a ClientHello that returns it (``DTLSv1_listen``), so a
flood of spoofed ClientHellos makes no state per source. Sessions are bounded (``limiter``: 64, 32
from one host, by default); a
handshake has ``handshake_timeout`` seconds and is retransmitted at the record layer's deadlines; a
session without a record for ``idle_timeout`` seconds is closed (the EtherNet/IP Security object's
DTLS Timeout, whose default of 12 s is the one OpENer's CIP Security branch gives).

Garbage, plain EtherNet/IP, a client certificate not signed by the CA, a handshake that does not
finish: refused, counted in ``refused`` and logged once per source per 10 s; nothing else is
disturbed.

Not carried yet: the UDP-only profile's unconnected messages (CPF item 0x8003, Volume 8 chapter 3,
whose layout no public source gives whole); a record of that form is answered as encapsulation would
be, and refused there.
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import hmac
import logging
import os
import socket
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

from ..eip.io_server import (
    CATCH_UP_AFTER_S,
    CATCH_UP_READS,
    DRAIN_LIMIT,
    MAX_DATAGRAM,
    RECEIVE_BUFFER,
    DatagramPaths,
)
from ..eip.precise_loop import IoLane, lane_of
from ..eip.target.limits import ConnectionLimiter, RateLimitedLog
from ..eip.wire.cpf import SockAddr
from ..errors import CipstackError, SecurityError
from .credentials import SECURE_PORT
from .dtls import DtlsChannel, describe_dtls_failure, dtls_context
from .psk import identity_asked, verify_message
from .tls_target import HANDSHAKE_TIMEOUT, named_identity

if TYPE_CHECKING:
    from OpenSSL import SSL

    from ..eip.target.core import EncapsulationConnection, EncapsulationTarget
    from ..eip.target.seams import IoSeam, SecuredSeam
    from .credentials import Credentials

log = logging.getLogger(__name__)

#: Seconds a session may go without a record before it is closed: the default of the EtherNet/IP
#: Security object's DTLS Timeout attribute (0x5E, attribute 15) in OpENer's CIP Security branch.
DTLS_TIMEOUT = 12.0
#: Sessions at once.
DEFAULT_MAX_SESSIONS = 64
#: A class 0/1 datagram begins with its item count (2) and a Sequenced Address item (0x8002).
_IO_PREFIX = b"\x02\x00\x02\x80"
#: Content type 22 (handshake) of a DTLS record, and handshake type 1 (ClientHello) at its offset.
_HANDSHAKE, _CLIENT_HELLO = 22, 1
_COOKIE_SIZE = 16


def is_client_hello(datagram: bytes) -> bool:
    """A datagram that begins with a DTLS record of epoch 0 carrying a ClientHello (RFC 6347, 4.1, 4.2.2)."""
    return (len(datagram) >= 26 and datagram[0] == _HANDSHAKE and datagram[1] == 0xFE
            and datagram[3:5] == b"\0\0" and datagram[13] == _CLIENT_HELLO)


def is_dtls_record(datagram: bytes) -> bool:
    """A datagram that begins with a DTLS record header (RFC 6347, 4.1: content type 20 to 23, a
    version whose first octet is 254)."""
    return len(datagram) >= 13 and 20 <= datagram[0] <= 23 and datagram[1] == 0xFE


def is_io_datagram(plain: bytes) -> bool:
    """A class 0/1 datagram (CPF with a Sequenced Address item first), not an encapsulation message."""
    return plain[:4] == _IO_PREFIX


def _address_bytes(address: tuple[str, int]) -> bytes:
    return f"{address[0]}:{address[1]}".encode()


class _Session:
    """One peer address's DTLS association and, once its handshake is done, its encapsulation connection."""

    def __init__(self, server: DtlsServer, address: tuple[str, int], channel: DtlsChannel, now: float) -> None:
        self.server = server
        self.address = address
        self.peer = f"{address[0]}:{address[1]}"
        self.channel = channel
        self.started = now
        self.last_record = now
        self.connection: EncapsulationConnection | None = None
        self._timer: asyncio.TimerHandle | None = None
        self._timer_at: float | None = None

    # -- datagrams in and out ---------------------------------------------------------------------------
    def datagram(self, data: bytes, now: float) -> None:
        server = self.server
        try:
            records = self.channel.feed(data)
        except server.ssl_error as exc:
            self.flush()   # the alert that tells the peer why
            if self.connection is None:
                cause = describe_dtls_failure(exc, identity_asked(self.channel.connection))
                if cause.startswith("certificate verify failed"):   # OpenSSL's words for the client's certificate
                    cause = f"certificate verify failed: {verify_message(self.channel.connection)}"
                if cause.startswith("no cipher suite in common"):
                    allowed = [n for n in self.channel.connection.get_cipher_list() if not n.startswith("TLS_")]
                    cause = f"{cause}: the device allows {', '.join(allowed) or 'none'}"
                server.refuse(self.address[0], f"DTLS handshake from {self.peer} refused: {cause}")
            else:
                log.info("%s: DTLS session closed: %s", self.peer, describe_dtls_failure(exc))
            server.end(self)
            return
        self.last_record = now
        if self.connection is None and self.channel.established:
            self._established(now)
        explicit = False
        for plain in records:
            explicit = self._record(plain, now) or explicit
        self.flush()
        if self.channel.closed or (self.connection is not None and self.connection.closing):
            self.flush()
            server.end(self)
            return
        # Class 1 records move only the idle deadline on, which the timer finds when it fires; an
        # encapsulation message may bring a deadline nearer (a frame begun, a class 3 connection).
        if explicit or self._timer is None or self.connection is None:
            self.arm(now)

    def _established(self, now: float) -> None:
        server = self.server
        self.connection = server.target.connection(self.peer, server.local, now, io_path=self.address)
        server.paths.routes[self.address] = self.send_io
        log.info("%s: DTLS session accepted (%s%s)", self.peer, self.channel.description(),
                 named_identity(identity_asked(self.channel.connection)))

    def _record(self, plain: bytes, now: float) -> bool:
        """Serve one record's plaintext; whether it was an encapsulation message."""
        connection = self.connection
        if connection is None or not plain:
            return False
        if is_io_datagram(plain):
            io = self.server.io
            if io is not None:
                io.receive_secured(plain, self.address, now)
            return False
        connection.receive(plain, now)
        out = connection.data_to_send()
        if out:
            self.channel.send(out)
        return True

    def send_io(self, datagram: bytes) -> None:
        """Send a T->O datagram of a connection opened in this session (``DatagramPaths``)."""
        try:
            self.channel.send(datagram)
        except self.server.ssl_error as exc:
            log.debug("%s: DTLS write: %s", self.peer, exc)
            return
        self.flush()

    def flush(self) -> None:
        for datagram in self.channel.datagrams():
            self.server.sendto(datagram, self.address)

    # -- time ------------------------------------------------------------------------------------------
    def deadline(self) -> float:
        server = self.server
        if self.connection is None:
            at = self.started + server.handshake_timeout
            retransmit = self.channel.timeout()
            if retransmit is not None:
                at = min(at, server.loop.time() + retransmit)
            return at
        at = self.last_record + server.idle_timeout
        next_deadline = self.connection.next_deadline()
        return at if next_deadline is None else min(at, next_deadline)

    def arm(self, now: float) -> None:
        """Keep the timer at the earliest deadline; a later one is found when the timer fires (traffic
        moves the idle deadline on, and a timer is not moved for each record)."""
        at = self.deadline()
        if self._timer is not None and self._timer_at is not None and self._timer_at <= at:
            return
        if self._timer is not None:
            self._timer.cancel()
        self._timer_at = at
        self._timer = self.server.loop.call_at(at, self._on_timer)

    def _on_timer(self) -> None:
        self._timer = self._timer_at = None
        server = self.server
        now = server.loop.time()
        if self.connection is None:
            if now >= self.started + server.handshake_timeout:
                server.refuse(self.address[0], f"DTLS handshake from {self.peer} refused: not complete after "
                                               f"{server.handshake_timeout:g} s")
                server.end(self)
                return
            timeout = self.channel.timeout()
            if timeout is not None and timeout <= 0:
                try:
                    self.channel.on_timer()   # the last flight again
                except server.ssl_error as exc:
                    server.refuse(self.address[0], f"DTLS handshake from {self.peer} refused: "
                                                   f"{describe_dtls_failure(exc)}")
                    server.end(self)
                    return
                self.flush()
        else:
            if now >= self.last_record + server.idle_timeout:
                log.info("%s: DTLS session closed: no record for %g s", self.peer, server.idle_timeout)
                self.close()
                server.end(self)
                return
            self.connection.on_timer(now)
            if self.connection.closing:
                self.close()
                server.end(self)
                return
        self.arm(now)

    def close(self) -> None:
        """Say close_notify to the peer."""
        self.channel.close()
        self.flush()

    def cancel(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = self._timer_at = None


class _DtlsProtocol(asyncio.DatagramProtocol):
    def __init__(self, server: DtlsServer) -> None:
        self.server = server

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        try:
            self.server.datagram(data, addr)
        except Exception:   # a datagram must never take the port down
            log.exception("DTLS datagram from %s", addr)

    def error_received(self, exc: Exception) -> None:
        log.debug("DTLS UDP error: %s", exc)


class DtlsServer:
    """The DTLS port of one target, beside its TLS port (``TlsServer``) on the same number."""

    def __init__(self, target: EncapsulationTarget, credentials: Credentials, host: str = "127.0.0.1",
                 port: int = SECURE_PORT, *, io: IoSeam | None = None, paths: DatagramPaths | None = None,
                 verify_client: bool = True, max_sessions: int = DEFAULT_MAX_SESSIONS,
                 max_sessions_per_host: int | None = None, seam: SecuredSeam | None = None,
                 ciphers: str | None = None, recipe: Callable[[Credentials], SSL.Context] | None = None,
                 idle_timeout: float = DTLS_TIMEOUT) -> None:
        """``io``: the class 1 seam whose core takes the datagrams of connections opened over DTLS (the
        faults' filters act on them as on plain UDP 2222's); ``paths``:
        the datagram paths of its UDP endpoint, where this server adds the address of each session;
        ``seam``: where faults change the next handshakes and drop records (``SecuredSeam``);
        ``ciphers``: the suites accepted, as OpenSSL names them (None: the library's DTLS 1.2 ones);
        ``recipe``: how the context is made of credentials instead (a configuration applied over the
        network, with its pre-shared keys: ``endpoint.dtls_server_context``); ``idle_timeout``: seconds a
        session may go without a record (a configured device's DTLS Timeout, 0x5E attribute 15)."""
        from .dtls import require_pyopenssl

        require_pyopenssl()
        from OpenSSL import SSL

        self.target = target
        self.io = io
        self.paths = paths or DatagramPaths()
        self.host = host
        self.port = port
        self.ssl_error = SSL.Error
        self._ssl = SSL
        self._secret = os.urandom(32)
        self.credentials = credentials
        self.verify_client = verify_client
        self.ciphers = ciphers
        self.recipe = recipe
        self.seam = seam
        #: The DTLS context every session is made from, while no fault changes it.
        self.context = self._recipe(credentials)
        #: The folder's ``crl.pem`` the context was made with (``Credentials.crl_stamp``).
        self._crl = credentials.crl_stamp()
        self._variant: tuple[int, SSL.Context] | None = None
        #: Sessions at once, in all and per host (half of all by default: one host never holds every one).
        self.limiter = ConnectionLimiter(max_sessions, max_sessions_per_host)
        #: Seconds a handshake has from the ClientHello that returned its cookie.
        self.handshake_timeout = HANDSHAKE_TIMEOUT
        #: Seconds a session may go without a record (``DTLS_TIMEOUT`` unless a configuration says).
        self.idle_timeout = idle_timeout
        self.sessions: dict[tuple[str, int], _Session] = {}
        self.refused_log = RateLimitedLog(log)
        #: Datagrams and handshakes refused since the start.
        self.refused = 0
        #: HelloVerifyRequests sent (ClientHellos without a valid cookie): no state was kept for them.
        self.cookies_sent = 0
        #: DTLS records of no session (an ended association's last ones), dropped.
        self.stray = 0
        self.loop: asyncio.AbstractEventLoop
        self.local = SockAddr("0.0.0.0", port)
        self._transport: asyncio.DatagramTransport | None = None
        self._sock: socket.socket | None = None
        self._lane: IoLane | None = None
        #: When the socket was last read to its end (``_catch_up``).
        self._emptied_at = float("-inf")

    def _recipe(self, credentials: Credentials) -> SSL.Context:
        """The DTLS context of this listener made of ``credentials``, with its cookie exchange."""
        if self.recipe is not None:
            context = self.recipe(credentials)
        else:
            context = dtls_context(credentials, server=True, verify_client=self.verify_client)
            if self.ciphers is not None:
                context.set_cipher_list(self.ciphers.encode())
        context.set_cookie_generate_callback(self._cookie)
        context.set_cookie_verify_callback(self._cookie_matches)
        return context

    def handshake_context(self) -> SSL.Context:
        """The context of a new session: ``context``, or while a fault is in the seam the one made for
        it (once per change of the seam); both remade when the folder's CRL changed."""
        if (stamp := self.credentials.crl_stamp()) != self._crl:
            self._crl = stamp
            try:
                self.context, self._variant = self._recipe(self.credentials), None
            except SecurityError as exc:
                log.error("the DTLS port keeps the contexts it had: %s", exc)
        seam = self.seam
        if seam is None or not seam.handshake:
            return self.context
        if self._variant is None or self._variant[0] != seam.generation:
            from .authority import dtls_variant

            self._variant = (seam.generation, dtls_variant(self.credentials, self._recipe, seam))
        return self._variant[1]

    # -- cookies ---------------------------------------------------------------------------------------
    def _cookie(self, connection: object) -> bytes:
        address = connection.get_app_data()   # type: ignore[attr-defined]  # pyOpenSSL's Connection, typed object here
        return hmac.new(self._secret, address, hashlib.sha256).digest()[:_COOKIE_SIZE]

    def _cookie_matches(self, connection: object, cookie: bytes) -> bool:
        return hmac.compare_digest(cookie, self._cookie(connection))

    # -- datagrams -------------------------------------------------------------------------------------
    def datagram(self, data: bytes, address: tuple[str, int]) -> None:
        seam = self.seam
        if seam is not None and seam.records:   # a fault drops records before anything reads them
            data = seam.inbound(data, address)
            if not data:
                return
        now = self.loop.time()
        session = self.sessions.get(address)
        if session is not None and not (session.connection is not None and is_client_hello(data)):
            session.datagram(data, now)
            return
        if not is_client_hello(data) and is_dtls_record(data):
            # A record of an association that has ended (the close_notify of a peer whose session was
            # already closed, a retransmission): RFC 6347, 4.1.2.1 discards it; not a refusal.
            self.stray += 1
            log.debug("DTLS record from %s:%d of no session: dropped", *address)
            return
        if not is_client_hello(data):
            self.refuse(address[0], f"datagram from {address[0]}:{address[1]} on the DTLS port refused: "
                                    "not a DTLS ClientHello" + (" (plain EtherNet/IP?)" if len(data) >= 24 and
                                                               data[1] == 0 and data[0] in (0x63, 0x65, 0x6F, 0x70)
                                                               else ""))
            return
        if session is not None:   # a new ClientHello from an established session's address: the peer restarted
            log.info("%s: DTLS session replaced by a new handshake", session.peer)
            self.end(session)
        self._listen(data, address, now)

    def _listen(self, data: bytes, address: tuple[str, int], now: float) -> None:
        """A ClientHello from an address without a session: a HelloVerifyRequest and nothing kept, or,
        with the cookie it returns, a new session (``DTLSv1_listen``)."""
        SSL = self._ssl
        try:
            context = self.handshake_context()
        except (CipstackError, SSL.Error, OSError) as exc:   # what a fault presents did not load
            self.refuse(address[0], f"DTLS ClientHello from {address[0]}:{address[1]} refused: {exc}")
            return
        connection = SSL.Connection(context, None)
        connection.set_accept_state()
        connection.set_app_data(_address_bytes(address))
        connection.bio_write(data)
        try:
            connection.DTLSv1_listen()
        except SSL.WantReadError:
            self.cookies_sent += 1
            with contextlib.suppress(SSL.WantReadError):
                self.sendto(connection.bio_read(65536), address)
            return
        except SSL.Error as exc:
            self.refuse(address[0], f"DTLS ClientHello from {address[0]}:{address[1]} refused: "
                                    f"{describe_dtls_failure(exc)}")
            return
        if not self.limiter.admit(address[0]):
            self.refuse(address[0], f"DTLS session from {address[0]}:{address[1]} refused: "
                                    f"{self.limiter.reason(address[0]).replace('connections', 'sessions')}")
            return
        session = self.sessions[address] = _Session(self, address, DtlsChannel(connection), now)
        session.datagram(b"", now)

    def sendto(self, datagram: bytes, address: tuple[str, int]) -> None:
        sock = self._sock
        if sock is None:
            return
        seam = self.seam
        if seam is not None and seam.records:   # a fault drops records after they are made
            datagram = seam.outbound(datagram, address)
            if not datagram:
                return
        if self._transport is not None:
            if not self._transport.is_closing():
                self._transport.sendto(datagram, address)
            return
        try:
            sock.sendto(datagram, address)
        except (BlockingIOError, InterruptedError):   # a full buffer: DTLS resends a flight, class 1 newer data
            log.debug("DTLS datagram to %s:%d dropped: the socket's buffer is full", *address)
        except OSError as exc:
            log.debug("DTLS datagram to %s:%d: %s", address[0], address[1], exc)

    def _drain(self) -> None:
        """The lane's reader: what the socket holds, up to ``DRAIN_LIMIT`` datagrams."""
        sock = self._sock
        if sock is None:
            return
        datagram = self.datagram
        for _ in range(DRAIN_LIMIT):
            try:
                data, address = sock.recvfrom(MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                self._emptied_at = time.monotonic()
                return
            except OSError as exc:   # an ICMP error reported on the socket
                log.debug("DTLS UDP error: %s", exc)
                return
            try:
                datagram(data, address)
            except Exception:   # a datagram must never take the port down
                log.exception("DTLS datagram from %s", address)

    def end(self, session: _Session) -> None:
        """Forget ``session``: its route, its encapsulation connection, the class 1 connections opened in it."""
        session.cancel()
        if self.sessions.get(session.address) is session:
            del self.sessions[session.address]
            self.limiter.release(session.address[0])
        self.paths.routes.pop(session.address, None)
        if session.connection is not None:
            session.connection.connection_lost()
            session.connection = None
            if self.io is not None:
                self.io.core.close_path(session.address)

    def refuse(self, source: str, line: str) -> None:
        """Count one refusal; its line is logged at most once per source per 10 s."""
        self.refused_log("%s", line, source=source)
        self.refused += 1   # after its line: whoever sees the count sees the line too

    def _catch_up(self) -> None:
        """Before the class 1 endpoint judges its connections: what this socket still holds, unless it
        was read to its end just now (``DatagramPaths.catch_up``; ``io_server.CATCH_UP_AFTER_S``)."""
        for _ in range(CATCH_UP_READS):
            if time.monotonic() - self._emptied_at <= CATCH_UP_AFTER_S or self._sock is None:
                return
            self._drain()

    # -- the port --------------------------------------------------------------------------------------
    @property
    def is_open(self) -> bool:
        return self._sock is not None

    async def start(self) -> None:
        """Listen on the DTLS port (0: any free one, read back in ``port``). On the class 1 lane of a
        ``PreciseEventLoop`` (the command line's) the socket is read there, as UDP 2222 is: a wake-up
        drains what came, with no asyncio round per datagram; on any other loop through asyncio's
        datagram transport."""
        self.loop = asyncio.get_running_loop()
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.bind((self.host, self.port))
            # Class 1 of every session arrives here: room for a burst, as on 2222.
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER)
            sock.setblocking(False)
        except OSError:
            sock.close()
            raise
        self._sock = sock
        self._lane = lane_of(self.loop)
        self.paths.catch_up.append(self._catch_up)
        if self._lane is not None:
            self._lane.add_reader(sock.fileno(), self._drain)
        else:
            self._transport, _ = await self.loop.create_datagram_endpoint(lambda: _DtlsProtocol(self), sock=sock)
        self.host, self.port = sock.getsockname()
        self.local = SockAddr(self.host, self.port)
        log.info("EtherNet/IP over DTLS listening on %s:%d (UDP)", self.host, self.port)

    async def close(self) -> None:
        for session in list(self.sessions.values()):
            session.close()
            self.end(session)
        sock, self._sock = self._sock, None
        if self._catch_up in self.paths.catch_up:
            self.paths.catch_up.remove(self._catch_up)
        transport, self._transport = self._transport, None
        if transport is not None:
            transport.close()
        elif sock is not None:
            if self._lane is not None:
                self._lane.remove_reader(sock.fileno())
            sock.close()


__all__ = ["DEFAULT_MAX_SESSIONS", "DTLS_TIMEOUT", "DtlsServer", "is_client_hello", "is_dtls_record",
           "is_io_datagram"]
