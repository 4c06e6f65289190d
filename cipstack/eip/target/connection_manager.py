"""Connection Manager object (class 0x06), target side: Unconnected_Send, class 3 connections.

Sans-I/O: connections are entries in a ``ConnectionTable`` with a deadline; the transport
calls ``expire(now)`` and asks ``next_deadline()``. A class 3 connection belongs to the TCP
connection that opened it and dies with it. Transport class 1 is delegated to an
``IoConnectionHandler`` when the transport that carried the request offers one (the class 1 I/O
layer, ``RequestContext.class1``, given to the encapsulation target when it is made), else refused with
extended status 0x0103.
"""

from __future__ import annotations

import itertools
import logging
import random
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

from ...cip.epath import ElectronicKey, LogicalSegment, LogicalType, PortSegment, decode_path
from ...cip.messages import MessageRouterRequest, MessageRouterResponse, Service
from ...cip.model import CipObject, Instance
from ...cip.router import RequestContext
from ...cip.status import CipError, ExtendedStatus, GeneralStatus
from ..wire.cm_messages import (
    ConnectionTriad,
    ConnectionType,
    ForwardCloseReply,
    ForwardCloseRequest,
    ForwardOpenReply,
    ForwardOpenRequest,
    UnconnectedSendRequest,
    forward_open_failure_data,
)
from ..wire.cm_spec import BACKPLANE_PORT, SPEC

log = logging.getLogger(__name__)

def origin_host(origin: str) -> str:
    """The originator's address in a ``host:port`` origin text: a connection is named by its triad
    together with this address, so another host can neither close it nor open it twice."""
    return origin.rsplit(":", 1)[0]


def connection_failure(extended: int, triad: ConnectionTriad | None = None, message: str = "",
                       extra_words: tuple[int, ...] = ()) -> CipError:
    data = forward_open_failure_data(triad) if triad is not None else b""
    return CipError(GeneralStatus.CONNECTION_FAILURE, (extended, *extra_words), message=message, data=data)


@dataclass
class ExplicitConnection:
    """A class 3 connection to the message router."""

    ot_connection_id: int
    to_connection_id: int
    triad: ConnectionTriad
    timeout_s: float
    owner: Any
    deadline: float
    last_sequence: int | None = None
    last_reply: bytes = b""
    requests: int = 0
    #: Address of the originator that opened it (see ``origin_host``).
    host: str = ""


class IoConnectionHandler(Protocol):
    """What a class 1 I/O layer offers the Connection Manager."""

    def forward_open(self, request: ForwardOpenRequest, context: RequestContext) -> ForwardOpenReply: ...

    def forward_close(self, request: ForwardCloseRequest, context: RequestContext) -> bool: ...


RouteHandler = Callable[[PortSegment, bytes, list[Any], RequestContext], MessageRouterResponse]


@dataclass
class ConnectionTable:
    """Class 3 connections by O->T connection id, with the settable limit."""

    max_connections: int = 32
    connections: dict[int, ExplicitConnection] = field(default_factory=dict)
    timeouts: int = 0
    _ids: itertools.count[int] = field(default_factory=lambda: itertools.count(random.randrange(1, 0x7FFF0000)))

    def new_id(self) -> int:
        while True:
            candidate = next(self._ids) & 0xFFFFFFFF
            if candidate and candidate not in self.connections:
                return candidate

    def by_triad(self, triad: ConnectionTriad, host: str) -> ExplicitConnection | None:
        """The connection ``host`` opened with ``triad``, if any."""
        for connection in self.connections.values():
            if connection.triad == triad and connection.host == host:
                return connection
        return None

    def next_deadline(self, owner: Any = None) -> float | None:
        deadlines = [c.deadline for c in self.connections.values() if owner is None or c.owner is owner]
        return min(deadlines, default=None)

    def expire(self, now: float, owner: Any = None) -> list[ExplicitConnection]:
        expired = [c for c in self.connections.values()
                   if c.deadline <= now and (owner is None or c.owner is owner)]
        for connection in expired:
            del self.connections[connection.ot_connection_id]
            self.timeouts += 1
            log.info("class 3 connection 0x%08X timed out", connection.ot_connection_id)
        return expired

    def drop_owner(self, owner: Any) -> int:
        ids = [cid for cid, c in self.connections.items() if c.owner is owner]
        for cid in ids:
            del self.connections[cid]
        return len(ids)


class ConnectionManagerObject(CipObject):
    extra_services = {
        Service.FORWARD_OPEN: "forward_open",
        Service.LARGE_FORWARD_OPEN: "forward_open",
        Service.FORWARD_CLOSE: "forward_close",
        Service.UNCONNECTED_SEND: "unconnected_send",
    }

    def __init__(self, table: ConnectionTable, key_check: Callable[[ElectronicKey], None] | None = None) -> None:
        super().__init__(SPEC)
        self.table = table
        self.key_check = key_check
        #: Routes out of this device by port number (a CompoNet gateway registers its port).
        self.routes: dict[int, RouteHandler] = {}
        self.counters = self.add_instance(1)

    def _count(self, attribute_id: int) -> None:
        values = self.counters.values
        values[attribute_id] = (values[attribute_id] + 1) & 0xFFFF

    # -- Forward_Open -------------------------------------------------------------------------
    def forward_open(self, instance: Instance | None, path: Any, request: MessageRouterRequest,
                     context: RequestContext) -> bytes:
        self._count(1)
        try:
            fo = ForwardOpenRequest.decode(request.data, large=request.service == Service.LARGE_FORWARD_OPEN)
        except CipError:
            self._count(2)
            raise
        try:
            return self._open(fo, context)
        except CipError as exc:
            if exc.general == GeneralStatus.CONNECTION_FAILURE and exc.extended and exc.extended[0] == 0x0113:
                self._count(3)
            else:
                self._count(4)
            if not exc.data:
                exc.data = forward_open_failure_data(fo.triad)
            raise

    def _open(self, fo: ForwardOpenRequest, context: RequestContext) -> bytes:
        if fo.ot_parameters.type == fo.to_parameters.type == ConnectionType.NULL:
            # A null Forward_Open (both types null) reconfigures or pings a connection without opening
            # one; a target without that answers 0x0132 (CIP Vol. 1 §3-5.5.2.2, wire.md), whatever the class.
            raise connection_failure(ExtendedStatus.NULL_FORWARD_OPEN_NOT_SUPPORTED, fo.triad,
                                     "null Forward_Open not supported")
        if fo.transport.transport_class == 1:
            class1: IoConnectionHandler | None = context.class1
            if class1 is None:
                raise connection_failure(ExtendedStatus.TRANSPORT_CLASS_NOT_SUPPORTED, fo.triad,
                                         "class 1 I/O is not offered by this device")
            return class1.forward_open(fo, context).encode()
        if fo.transport.transport_class != 3:
            raise connection_failure(ExtendedStatus.TRANSPORT_CLASS_NOT_SUPPORTED, fo.triad,
                                     f"transport class {fo.transport.transport_class}")
        host = origin_host(context.origin)
        if self.table.by_triad(fo.triad, host) is not None:
            raise connection_failure(ExtendedStatus.CONNECTION_IN_USE, fo.triad, "duplicate Forward_Open")
        if any(c.triad == fo.triad for c in self.table.connections.values()):
            # The triad is another originator's (it came from another address): for this one there is
            # no such connection, and nothing of the other's is touched.
            raise connection_failure(ExtendedStatus.CONNECTION_NOT_FOUND, fo.triad,
                                     "the triad is a connection of another originator address")
        for params in (fo.ot_parameters, fo.to_parameters):
            if params.type != ConnectionType.POINT_TO_POINT:
                raise connection_failure(ExtendedStatus.INVALID_NETWORK_CONNECTION_PARAMETER, fo.triad,
                                         "class 3 connections are point-to-point")
        if fo.ot_rpi_us == 0:
            raise connection_failure(ExtendedStatus.RPI_NOT_SUPPORTED, fo.triad, "RPI 0")
        self._check_explicit_path(fo)
        if len(self.table.connections) >= self.table.max_connections:
            raise connection_failure(ExtendedStatus.OUT_OF_CONNECTIONS, fo.triad)
        ot_id = self.table.new_id()
        connection = ExplicitConnection(
            ot_connection_id=ot_id, to_connection_id=fo.to_connection_id, triad=fo.triad,
            timeout_s=fo.timeout_s, owner=context.transport,
            # Before the first packet at least 10 s, as for every connection.
            deadline=context.now + max(fo.timeout_s, 10.0), host=host,
        )
        self.table.connections[ot_id] = connection
        log.info("class 3 connection 0x%08X opened by %s (serial 0x%04X)", ot_id, context.origin,
                 fo.triad.connection_serial)
        return ForwardOpenReply(ot_id, fo.to_connection_id, fo.triad, fo.ot_rpi_us, fo.to_rpi_us).encode()

    def _check_explicit_path(self, fo: ForwardOpenRequest) -> None:
        try:
            segments = decode_path(fo.connection_path)
        except CipError:
            raise connection_failure(ExtendedStatus.INVALID_SEGMENT_IN_CONNECTION_PATH, fo.triad) from None
        logical: list[LogicalSegment] = []
        for segment in segments:
            if isinstance(segment, ElectronicKey):
                self.check_key(segment, fo.triad)
            elif isinstance(segment, PortSegment):
                # A route that ends here: the backplane port, link 0 (the device itself).
                if segment.port != BACKPLANE_PORT or logical:
                    raise connection_failure(ExtendedStatus.PORT_NOT_AVAILABLE, fo.triad)
                if segment.link != b"\x00":
                    raise connection_failure(ExtendedStatus.LINK_ADDRESS_NOT_VALID, fo.triad)
            elif isinstance(segment, LogicalSegment):
                logical.append(segment)
            else:
                raise connection_failure(ExtendedStatus.INVALID_SEGMENT_IN_CONNECTION_PATH, fo.triad)
        kinds = [(s.kind, s.value) for s in logical]
        if kinds not in ([(LogicalType.CLASS_ID, 0x02), (LogicalType.INSTANCE_ID, 1)],
                         [(LogicalType.CLASS_ID, 0x02)]):
            raise connection_failure(ExtendedStatus.INVALID_APPLICATION_PATH, fo.triad,
                                     "class 3 connections go to the message router")

    def check_key(self, key: ElectronicKey, triad: ConnectionTriad | None) -> None:
        if self.key_check is None:
            return
        try:
            self.key_check(key)
        except CipError as exc:
            raise connection_failure(exc.extended[0], triad, exc.message) from None

    # -- Forward_Close ------------------------------------------------------------------------
    def forward_close(self, instance: Instance | None, path: Any, request: MessageRouterRequest,
                      context: RequestContext) -> bytes:
        self._count(5)
        try:
            fc = ForwardCloseRequest.decode(request.data)
        except CipError:
            self._count(6)
            raise
        # Only the originator's own address may close a connection; to anyone else it does not exist.
        connection = self.table.by_triad(fc.triad, origin_host(context.origin))
        if connection is not None:
            del self.table.connections[connection.ot_connection_id]
            log.info("class 3 connection 0x%08X closed", connection.ot_connection_id)
            return ForwardCloseReply(fc.triad).encode()
        class1: IoConnectionHandler | None = context.class1
        if class1 is not None and class1.forward_close(fc, context):
            return ForwardCloseReply(fc.triad).encode()
        self._count(7)
        raise connection_failure(ExtendedStatus.CONNECTION_NOT_FOUND, fc.triad, "no such connection")

    # -- Unconnected_Send ---------------------------------------------------------------------
    def unconnected_send(self, instance: Instance | None, path: Any, request: MessageRouterRequest,
                         context: RequestContext) -> MessageRouterResponse:
        us = UnconnectedSendRequest.decode(request.data)
        try:
            route = decode_path(us.route_path)
        except CipError:
            raise CipError(GeneralStatus.PATH_SEGMENT_ERROR, message="bad route path") from None
        if not route:
            return context.router.dispatch(us.message, context)
        first = route[0]
        # An Unconnected_Send refused on its route answers the remaining path size (words) and a
        # reserved byte.
        remaining_words = len(us.route_path) // 2
        if not isinstance(first, PortSegment):
            raise CipError(GeneralStatus.PATH_SEGMENT_ERROR, data=bytes((remaining_words, 0)),
                           message="route path must start with a port segment")
        if first.port == BACKPLANE_PORT:
            if first.link != b"\x00" or len(route) > 1:
                raise CipError(GeneralStatus.CONNECTION_FAILURE, (ExtendedStatus.LINK_ADDRESS_NOT_VALID,),
                               data=bytes((remaining_words, 0)), message=f"no module at slot {first.link.hex()}")
            return context.router.dispatch(us.message, context)
        handler = self.routes.get(first.port)
        if handler is None:
            raise CipError(GeneralStatus.CONNECTION_FAILURE, (ExtendedStatus.PORT_NOT_AVAILABLE,),
                           data=bytes((remaining_words, 0)), message=f"no port {first.port}")
        return handler(first, us.message, route[1:], context)
