"""EtherNet/IP over DTLS, originator side, on asyncio: one UDP socket to the device's port 2221 and a
``DtlsChannel`` over it, driven by the loop (its retransmission deadlines are loop timers).

``AsyncDtlsLink`` stands in for the TCP transport of the asyncio originator (``EncapsulationClient``:
``write`` one encapsulation message per record, ``data_received`` for each record that is one) and
carries the class 1 data of the connections opened in it: class 1 records go to its own class 1 core
(``io_core``, an ``IoOriginator`` made with it), and that core's O->T datagrams, which an
``IoEndpoint`` given ``paths`` produces, come back here through the route to the device's address.
"""

from __future__ import annotations

import asyncio
import logging
import socket
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from ..eip.io_server import CATCH_UP_READS, DRAIN_LIMIT, MAX_DATAGRAM, RECEIVE_BUFFER, DatagramPaths, IoEndpoint
from ..eip.originator.class1 import IoOriginator
from ..errors import PeerUnreachable, SecurityError
from .dtls import DtlsChannel, describe_dtls_failure, dtls_context
from .dtls_target import is_io_datagram

if TYPE_CHECKING:
    from .credentials import Credentials

log = logging.getLogger(__name__)


class AsyncDtlsLink(asyncio.DatagramProtocol):
    """One DTLS session with a device on the running loop: what ``open`` returns is established."""

    def __init__(self, channel: DtlsChannel, host: str, port: int, protocol: asyncio.Protocol,
                 credentials: Credentials) -> None:
        """``protocol``: the stream protocol encapsulation records go to (the originator client's);
        ``credentials``: those the channel was made of (a refusal says what they offered)."""
        from OpenSSL import SSL

        self._ssl_error = SSL.Error
        self.channel = channel
        self.credentials = credentials
        self.host = host
        self.port = port
        self.protocol = protocol
        #: The PSK identity offered, named in a refusal that is about the key.
        self.identity = credentials.psk.identity if credentials.psk is not None else None
        #: The class 1 core of the connections opened in this session.
        self.io_core = IoOriginator()
        #: The route of O->T datagrams into this session, for the class 1 endpoint of ``io_core``.
        self.paths = DatagramPaths()
        self.established: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        self._transport: asyncio.DatagramTransport | None = None
        self._timer: asyncio.TimerHandle | None = None
        self._closed = False
        self._sock: socket.socket | None = None
        #: The class 1 endpoint of ``io_core``, made with the first connection (``io_endpoint``).
        self._endpoint: IoEndpoint | None = None
        #: The endpoint's closing, once ``close`` began it.
        self.closing: asyncio.Future[None] | None = None

    async def io_endpoint(self, host: str) -> tuple[IoOriginator, IoEndpoint]:
        """The class 1 core of this session and the endpoint that times it: its O->T datagrams take
        the route of ``paths`` into the session (the endpoint's own socket carries nothing)."""
        if self._endpoint is None:
            endpoint = IoEndpoint(self.io_core, host, 0, paths=self.paths)
            await endpoint.start()
            self._endpoint = endpoint
        return self.io_core, self._endpoint

    @classmethod
    async def open(cls, credentials: Credentials, host: str, port: int, timeout: float,
                   protocol_factory: Callable[[], asyncio.Protocol]) -> tuple[AsyncDtlsLink, asyncio.Protocol]:
        """Complete a handshake with ``host:port`` within ``timeout``; ``SecurityError`` naming why it
        failed, ``PeerUnreachable`` when nothing answers."""
        loop = asyncio.get_running_loop()
        protocol = protocol_factory()
        link = cls(DtlsChannel.client(dtls_context(credentials, server=False)), host, port, protocol, credentials)
        try:
            infos = await loop.getaddrinfo(host, port, type=socket.SOCK_DGRAM)
            family, kind, proto, _name, address = infos[0]
            sock = socket.socket(family, kind, proto)
            link._sock = sock
            sock.setblocking(False)
            # T->O of every connection in the session arrives here: room for a burst.
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER)
            await loop.sock_connect(sock, address)
            await loop.create_datagram_endpoint(lambda: link, sock=sock)
            await asyncio.wait_for(asyncio.shield(link.established), timeout)
        except PeerUnreachable:
            link.close()   # the session's own failure (``_fail``), already in words
            raise
        except asyncio.TimeoutError:   # before OSError: from Python 3.11 it is the builtin TimeoutError, an OSError
            link.close()
            raise PeerUnreachable(f"DTLS with {host}:{port}: no answer to the handshake "
                                  "(is the device serving CIP Security over UDP there?)") from None
        except OSError as exc:
            link.close()
            raise PeerUnreachable.connecting(host, port, exc) from None
        except BaseException:
            link.close()
            raise
        link.paths.routes[(link.peer_address(), port)] = link.send_io
        protocol.connection_made(link)   # type: ignore[arg-type]  # the stream transport it writes to
        return link, protocol

    # -- the datagram side -----------------------------------------------------------------------------
    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self._transport = transport   # type: ignore[assignment]  # a datagram endpoint's
        self.paths.catch_up.append(self._catch_up)
        self._flush()
        self._arm()

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        try:
            records = self.channel.feed(data)
        except self._ssl_error as exc:
            self._flush()
            cause = self.credentials.explain(describe_dtls_failure(exc, self.identity, self.channel.verify_error))
            self._fail(SecurityError(f"DTLS with {self.host}:{self.port} failed: {cause}"))
            return
        if self.channel.established and not self.established.done():
            self.established.set_result(None)
        now = asyncio.get_running_loop().time()
        for plain in records:
            if is_io_datagram(plain):
                self.io_core.receive(plain, addr, now)
            elif plain:
                self.protocol.data_received(plain)
        self._flush()
        if self.channel.closed:
            self._fail(PeerUnreachable(f"DTLS session with {self.host}:{self.port} closed by the device"))
        elif not self.channel.established:
            self._arm()

    def _catch_up(self) -> None:
        """Before the class 1 endpoint judges the connections: the records this socket still holds
        (after a stall of the loop the endpoint's timer may come before the transport's read)."""
        sock = self._sock
        for _ in range(CATCH_UP_READS * DRAIN_LIMIT):
            if sock is None or self._closed:
                return
            try:
                data, address = sock.recvfrom(MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                return   # an ICMP error: the transport reports it
            self.datagram_received(data, address)

    def error_received(self, exc: Exception) -> None:
        if isinstance(exc, ConnectionRefusedError):   # ICMP port unreachable: nothing listens there
            self._fail(PeerUnreachable(f"DTLS with {self.host}:{self.port}: nothing listens there "
                                       "(ICMP port unreachable)"))

    def connection_lost(self, exc: Exception | None) -> None:
        self._fail(PeerUnreachable(f"DTLS session with {self.host}:{self.port} lost"))

    def _fail(self, error: Exception) -> None:
        if not self.established.done():
            self.established.set_exception(error)
            self.established.exception()   # retrieved: the opener raises its own
        if not self._closed:
            self.close()
            self.protocol.connection_lost(error)

    def _flush(self) -> None:
        transport = self._transport
        if transport is None or transport.is_closing():
            return
        for datagram in self.channel.datagrams():
            transport.sendto(datagram)

    def _arm(self) -> None:
        """The handshake's retransmission at the record layer's deadline."""
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        timeout = self.channel.timeout()
        if timeout is not None and not self.channel.established:
            self._timer = asyncio.get_running_loop().call_later(max(timeout, 0.0), self._on_timer)

    def _on_timer(self) -> None:
        self._timer = None
        if self.channel.established or self._closed:
            return
        try:
            self.channel.on_timer()
        except self._ssl_error as exc:
            cause = self.credentials.explain(describe_dtls_failure(exc, self.identity, self.channel.verify_error))
            self._fail(SecurityError(f"DTLS with {self.host}:{self.port} failed: {cause}"))
            return
        self._flush()
        self._arm()

    # -- what the stream client uses of a transport ----------------------------------------------------
    def write(self, data: bytes) -> None:
        """One encapsulation message (or several back to back) as one record."""
        self.channel.send(data)
        self._flush()

    def send_io(self, datagram: bytes) -> None:
        """A class 1 datagram in the session (the route of ``paths``)."""
        if not self._closed:
            self.channel.send(datagram)
            self._flush()

    def is_closing(self) -> bool:
        return self._closed

    def peer_address(self) -> str:
        transport = self._transport
        peer = transport.get_extra_info("peername") if transport is not None else None
        return str(peer[0]) if peer else self.host

    def get_extra_info(self, name: str, default: Any = None) -> Any:
        if name == "socket":
            return None   # not a TCP socket: nothing to set on it
        transport = self._transport
        return transport.get_extra_info(name, default) if transport is not None else default

    def close(self) -> None:
        """close_notify, then the socket."""
        if self._closed:
            return
        self._closed = True
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        if self.channel.established:
            self.channel.close()
            self._flush()
        if self._catch_up in self.paths.catch_up:
            self.paths.catch_up.remove(self._catch_up)
        if self._transport is not None:
            self._transport.close()
        elif self._sock is not None:
            self._sock.close()
        self._sock = None
        endpoint, self._endpoint = self._endpoint, None
        if endpoint is not None:
            self.closing = asyncio.ensure_future(endpoint.close())


__all__ = ["AsyncDtlsLink"]
