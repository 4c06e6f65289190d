"""The EtherNet/IP originator (scanner) client, asyncio.

``EncapsulationClient`` owns one TCP connection and one session: a thin asyncio shell over
``OriginatorCore``, which frames requests and matches replies (by sender context, class 3 requests by
their sequence count), so several requests may be in flight at once. ``discover`` sends ListIdentity
over UDP (unicast or broadcast) and collects replies until its timeout.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, TypeVar

from ...cip.epath import Segment
from ...cip.messages import MessageRouterResponse
from ...cip.status import CipError, GeneralStatus
from ...errors import CipstackError, PeerUnreachable
from ..wire.cpf import Item
from ..wire.encapsulation import DEFAULT_PORT, EncapsulationHeader
from ..wire.identity_items import IdentityRecord, ServiceRecord
from .core import (
    DEFAULT_TIMEOUT,
    MESSAGE_ROUTER_PATH,
    ORIGINATOR_VENDOR_ID,
    CoreClient,
    ExplicitConnectionInfo,
    NoReplyError,
    OriginatorCore,
    Plan,
    SecureChannel,
    Transaction,
    parse_host,
)
from .discovery import broadcast_addresses, discover, list_services_udp, udp_query
from .replies import EncapsulationStatusError, MalformedReplyError

if TYPE_CHECKING:
    # Imported where used: explicit messaging does not load class 1.
    from ...assemblies.schema import AssemblySchema
    from .class1 import OtFormat
    from .io_context import IoContext

log = logging.getLogger(__name__)

#: Seconds a secured client waits to learn why a connection closed as it opened (``_why_closed``).
_REFUSAL_WAIT = 1.0


async def _connected(loop: asyncio.AbstractEventLoop, host: str, port: int) -> socket.socket:
    """A TCP socket connected to ``host``:``port`` (the first address that takes it), non-blocking."""
    infos = await loop.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    for index, (family, kind, proto, _, address) in enumerate(infos):
        sock = socket.socket(family, kind, proto)
        sock.setblocking(False)
        try:
            await loop.sock_connect(sock, address)
        except OSError:
            sock.close()
            if index == len(infos) - 1:
                raise
            continue
        except BaseException:
            sock.close()
            raise
        return sock
    raise PeerUnreachable(f"cannot connect to {host}:{port}: no address")
T = TypeVar("T")

if asyncio.TimeoutError is TimeoutError:
    _NoReply: type[NoReplyError] = NoReplyError
else:  # Python 3.10: asyncio's own TimeoutError, which callers of an asyncio client catch
    class _NoReply(NoReplyError, asyncio.TimeoutError):  # type: ignore[no-redef]  # 3.10 only
        """No reply in time (an ``asyncio.TimeoutError`` too)."""


class _ClientProtocol(asyncio.Protocol):
    def __init__(self, client: EncapsulationClient) -> None:
        self.client = client
        self.transport: asyncio.Transport | None = None
        #: Done when the connection is lost (a secured client waits on it to learn why it closed).
        self.lost: asyncio.Future[None] | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = transport  # type: ignore[assignment]  # a TCP connection's transport
        self.lost = asyncio.get_running_loop().create_future()
        sock = transport.get_extra_info("socket")
        if sock is not None:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    def data_received(self, data: bytes) -> None:
        self.client._received(data)

    def connection_lost(self, exc: Exception | None) -> None:
        self.client._lost(exc)
        if self.lost is not None and not self.lost.done():
            self.lost.set_result(None)


class EncapsulationClient(CoreClient):
    """The asyncio originator: each request's reply resolves a future, so requests may overlap."""

    def __init__(self, host: str, port: int = DEFAULT_PORT, timeout: float = DEFAULT_TIMEOUT,
                 core: OriginatorCore | None = None) -> None:
        super().__init__(host, port, timeout, core)
        #: CIP Security: the connection is TLS, made with this channel's context (None: plain TCP).
        self.security: SecureChannel | None = None
        #: Why a secured connection was ended by a TLS alert (raised by every later request).
        self._refusal: CipstackError | None = None
        self._protocol: _ClientProtocol | None = None
        self._waiting: dict[Transaction[Any], asyncio.Future[Any]] = {}
        self._timer: asyncio.TimerHandle | None = None
        #: Over DTLS (``connect(datagrams=True)``): the session, which class 1 connections share.
        self.datagram_link: Any = None
        self._datagrams = False

    # -- life cycle -----------------------------------------------------------------------------
    @classmethod
    async def connect(cls, host: str, port: int = DEFAULT_PORT, timeout: float = DEFAULT_TIMEOUT,
                      register: bool = True, security: SecureChannel | None = None,
                      datagrams: bool = False) -> EncapsulationClient:
        """Connect (and register a session unless ``register`` is false); with ``security``, over
        TLS (CIP Security: the device's port 2221), or with ``datagrams`` too over DTLS (UDP 2221),
        where the class 1 connections it opens flow in the same DTLS session."""
        client = cls(host, port, timeout)
        client.security = security
        client._datagrams = datagrams and security is not None
        await client.open(register)
        return client

    async def open(self, register: bool = True) -> None:
        loop = asyncio.get_running_loop()
        security = self.security
        if security is not None and self._datagrams:
            self.datagram_link, protocol = await security.open_datagram_link(
                self.host, self.port, self.timeout, lambda: _ClientProtocol(self))
            self._protocol = protocol
            if register:
                await self.register_session()
            return
        if security is not None:
            protocol = await self._open_tls(loop, security)
        else:
            try:
                _, protocol = await asyncio.wait_for(
                    loop.create_connection(lambda: _ClientProtocol(self), self.host, self.port), self.timeout)
            except (OSError, asyncio.TimeoutError) as exc:
                raise PeerUnreachable.connecting(self.host, self.port, exc) from None
        self._protocol = protocol
        if register:
            try:
                await self.register_session()
            except PeerUnreachable:
                refusal = await self._why_closed(protocol)
                if refusal is None:
                    raise
                raise refusal from None

    async def _open_tls(self, loop: asyncio.AbstractEventLoop, security: SecureChannel) -> _ClientProtocol:
        """The TCP connection, then the TLS handshake on it, each within the timeout: a port that
        takes the connection and never answers the handshake (a plain EtherNet/IP port) is told from
        one that cannot be reached."""
        context = security.client_context()
        deadline = loop.time() + self.timeout
        try:
            sock = await asyncio.wait_for(_connected(loop, self.host, self.port), self.timeout)
        except (OSError, asyncio.TimeoutError) as exc:
            raise PeerUnreachable.connecting(self.host, self.port, exc) from None
        try:
            _, protocol = await asyncio.wait_for(
                loop.create_connection(lambda: _ClientProtocol(self), sock=sock, ssl=context, server_hostname=""),
                max(0.0, deadline - loop.time()))
        except asyncio.TimeoutError:
            sock.close()
            raise security.unanswered(self.host, self.port, self.timeout) from None
        except OSError as exc:
            sock.close()
            refusal = security.refusal(exc, self.host, self.port)
            raise (refusal or PeerUnreachable.connecting(self.host, self.port, exc)) from None
        return protocol

    async def _why_closed(self, protocol: _ClientProtocol) -> CipstackError | None:
        """The error of a connection that closed as it opened. A device that refuses a client's
        certificate after a TLS 1.3 handshake (which the client has already finished) sends its alert
        as the first request goes out: the transport is closing before asyncio reports why, a few
        callbacks later. Wait for that (bounded): the alert's error, or None for any other end."""
        if self.security is not None and protocol.lost is not None:
            with contextlib.suppress(asyncio.TimeoutError):
                await asyncio.wait_for(asyncio.shield(protocol.lost), _REFUSAL_WAIT)
        return self._refusal

    def local_host(self) -> str:
        """The local address of the TCP connection (where T->O data should come)."""
        assert self._protocol is not None and self._protocol.transport is not None
        return str(self._protocol.transport.get_extra_info("sockname")[0])

    def host_address(self) -> str:
        """The target's address as connected (an IP address even if a name was given)."""
        assert self._protocol is not None and self._protocol.transport is not None
        return str(self._protocol.transport.get_extra_info("peername")[0])

    @property
    def is_open(self) -> bool:
        return self._protocol is not None and self._protocol.transport is not None

    async def close(self) -> None:
        """Forward_Close the class 3 connection, UnRegisterSession, close the socket."""
        if not self.is_open:
            return
        try:
            await self.forward_close()
            if self.core.session:
                self._write(self.core.unregister_session())
        except (ConnectionError, CipError, EncapsulationStatusError, asyncio.TimeoutError, TimeoutError):
            pass
        finally:
            if self._protocol is not None and self._protocol.transport is not None:
                self._protocol.transport.close()
            self._protocol = None
            self.core.session = 0

    async def __aenter__(self) -> EncapsulationClient:
        if self._protocol is None:
            await self.open()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    # -- the shell ------------------------------------------------------------------------------
    def _write(self, frame: bytes) -> None:
        protocol = self._protocol
        if protocol is None or protocol.transport is None or protocol.transport.is_closing():
            if self._refusal is not None:
                raise self._refusal
            raise PeerUnreachable(f"connection to {self.host}:{self.port} is closed")
        protocol.transport.write(frame)

    def _received(self, data: bytes) -> None:
        for transaction, header, body in self.core.receive_data(data):
            future = self._waiting.pop(transaction, None)
            if future is None or future.done():
                continue
            try:
                future.set_result(transaction.result(header, body))
            except Exception as exc:  # the reply's error is the caller's to see
                future.set_exception(exc)

    def _lost(self, exc: Exception | None) -> None:
        refusal = self.security.refusal(exc, self.host, self.port) if self.security and exc else None
        self._refusal = refusal
        error = refusal or PeerUnreachable(f"connection to {self.host}:{self.port} lost" + (f": {exc}" if exc else ""))
        self.core.lost()
        for future in self._waiting.values():
            if not future.done():
                future.set_exception(error)
        self._waiting.clear()
        self._protocol = None

    def _expire(self) -> None:
        """The core's clock: fail every request whose deadline passed, then wait for the next deadline."""
        self._timer = None
        loop = asyncio.get_running_loop()
        for transaction in self.core.expired(loop.time()):
            future = self._waiting.pop(transaction, None)
            if future is not None and not future.done():
                future.set_exception(_NoReply(*self.no_reply(transaction).args))
        self._arm(loop)

    def _arm(self, loop: asyncio.AbstractEventLoop) -> None:
        deadline = self.core.next_deadline()
        if deadline is None:
            return
        timer = self._timer
        if timer is not None:
            if timer.when() <= deadline:
                return
            timer.cancel()
        self._timer = loop.call_at(deadline, self._expire)

    async def perform(self, transaction: Transaction[T]) -> T:
        """Send ``transaction`` and wait for its reply; the reply's meaning, or the error it carries."""
        loop = asyncio.get_running_loop()
        future: asyncio.Future[T] = loop.create_future()
        frame = self.core.start(transaction, loop.time())
        self._waiting[transaction] = future
        try:
            self._write(frame)
            self._arm(loop)
            return await future
        finally:
            if self._waiting.pop(transaction, None) is not None:  # cancelled, or the write failed
                self.core.forget(transaction)

    async def run(self, plan: Plan[T]) -> T:
        """Drive a plan of several requests to its result."""
        try:
            step = next(plan)
            while True:
                try:
                    result = await self.perform(step)
                except Exception as exc:  # the plan may handle the failure (a device that does not answer)
                    step = plan.throw(exc)
                else:
                    step = plan.send(result)
        except StopIteration as done:
            return done.value  # type: ignore[no-any-return]  # StopIteration.value is Any; the plan returns T

    # -- encapsulation commands -----------------------------------------------------------------
    async def exchange(self, command: int, data: bytes = b"", context: bytes | None = None,
                       timeout: float | None = None) -> tuple[EncapsulationHeader, bytes]:
        """Send one encapsulation frame and wait for the reply with the same sender context."""
        return await self.perform(self.core.command(command, data, context, timeout))

    async def register_session(self) -> int:
        return await self.perform(self.core.register_session())

    async def list_identity(self) -> list[IdentityRecord]:
        return await self.perform(self.core.list_identity())

    async def list_services(self) -> list[ServiceRecord]:
        return await self.perform(self.core.list_services())

    async def list_interfaces(self) -> list[Item]:
        return await self.perform(self.core.list_interfaces())

    async def nop(self, data: bytes = b"") -> None:
        self._write(self.core.nop(data))

    # -- explicit messaging ---------------------------------------------------------------------
    async def send_rr_data(self, request: bytes, timeout: float | None = None) -> bytes:
        """Unconnected explicit request (SendRRData); returns the encoded message-router reply."""
        return await self.perform(self.core.send_rr_data(request, timeout))

    async def send_rr_data_items(self, request: bytes, extra: Sequence[Item] = (),
                                 timeout: float | None = None) -> tuple[bytes, list[Item]]:
        """SendRRData with extra CPF items (Sockaddr Info); returns the reply and its extra items."""
        return await self.perform(self.core.send_rr_data_items(request, extra, timeout))

    async def send_unit_data(self, request: bytes, timeout: float | None = None) -> bytes:
        """Class 3 connected request on the open connection; returns the message-router reply."""
        return await self.perform(self.core.send_unit_data(request, timeout))

    async def request(self, service: int, path: bytes, data: bytes = b"", *,
                      route: Sequence[Segment] | bytes | None = None, connected: bool | None = None,
                      timeout: float | None = None) -> MessageRouterResponse:
        """Send any service; returns the reply (its status is not checked here). See
        ``OriginatorCore.request`` for ``route`` and ``connected``."""
        return await self.perform(self.core.request(service, path, data, route=route, connected=connected,
                                                    timeout=timeout))

    # -- class 3 connection -----------------------------------------------------------------------
    async def forward_open(self, rpi_us: int = 2_000_000, connection_size: int = 500, large: bool = False,
                           timeout_multiplier: int = 1, route: Sequence[Segment] | bytes = b"",
                           path: bytes = MESSAGE_ROUTER_PATH) -> ExplicitConnectionInfo:
        """Open a class 3 connection to the message router (Forward_Open or Large_Forward_Open)."""
        return await self.perform(self.core.forward_open(rpi_us, connection_size, large, timeout_multiplier,
                                                         route, path))

    async def forward_close(self) -> None:
        closing = self.core.forward_close()
        if closing is not None:
            await self.perform(closing)

    # -- class 1 -------------------------------------------------------------------------------------
    def io_connection(self, output: int | None, input: int, rpi: float, *, output_size: int,
                      input_size: int, config: int = 1, heartbeat: int | None = None,
                      target_io_port: int | None = None, local_io_port: int = 0, multicast: bool = False,
                      timeout_multiplier: int = 2, output_schema: AssemblySchema | None = None,
                      input_schema: AssemblySchema | None = None, run: bool = True,
                      keep_intervals: bool = False, config_data: bytes = b"",
                      ot_format: OtFormat | str | None = None, kernel_arrival_times: bool = False) -> IoContext:
        """Open a class 1 connection; use as ``async with client.io_connection(...) as io``.

        ``output``/``input`` are the assembly instances (``heartbeat`` replaces the output for
        input-only and listen-only connections); ``rpi`` is in seconds; ``config`` the
        configuration instance and ``config_data`` the data sent with it (a simple data segment).
        ``ot_format`` is the O->T real-time format: run/idle header (default), heartbeat (the
        sequence count alone) or modeless. T->O data comes to this host's UDP ``local_io_port``
        (0: the shared endpoint's port), which the Forward_Open announces in a Sockaddr Info
        item; O->T data goes to ``target_io_port`` on the target (None: the port the reply's O->T
        Sockaddr Info item names, else 2222). A target that refuses the
        O->T or T->O size with 0x0127/0x0128 and names the size it wants gets one retry with it.
        ``kernel_arrival_times``: T->O packets are timed (watchdog, statistics, ``keep_intervals``)
        when the kernel received them, as a capture shows them, not when this process read them;
        on the precise event loop under Linux, for every connection of the shared endpoint
        (``io.kernel_arrival_times`` says whether it is so).
        """
        from ..io_core import rpi_us_of
        from .class1 import Class1Request
        from .io_context import IoContext

        request = Class1Request.asked(output, input, rpi_us_of(rpi), output_size=output_size, input_size=input_size,
                                      config=config, heartbeat=heartbeat, multicast=multicast,
                                      timeout_multiplier=timeout_multiplier, config_data=config_data,
                                      ot_format=ot_format)
        return IoContext(self, request, target_io_port, local_io_port, output_schema, input_schema, run,
                         keep_intervals, kernel_arrival_times)


__all__ = ["DEFAULT_PORT", "MESSAGE_ROUTER_PATH", "ORIGINATOR_VENDOR_ID", "CipError", "EncapsulationClient",
           "EncapsulationStatusError", "ExplicitConnectionInfo", "GeneralStatus", "MalformedReplyError",
           "NoReplyError", "broadcast_addresses", "discover", "list_services_udp", "parse_host", "udp_query"]
