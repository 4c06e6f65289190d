"""Routing from EtherNet/IP into a CompoNet network.

``CompoNetGateway`` is a route of the Connection Manager (``routes[COMPONET_PORT]``): an
Unconnected_Send whose route path is (CompoNet port, link address = node address) has its
embedded request re-encoded as the CompoNet master's explicit-message frame (appendix E,
``explicit``), delivered to that node, and the slave's response frame decoded back into the
message-router reply the originator sees.

CompoNet port: **2**. Port 1 is the backplane of every EtherNet/IP device here; the gateway's
CompoNet network is its second port, so the route path of node 5 is ``02 05``
(pycomm3: ``CIPDriver("127.0.0.1:PORT/2/5")``).
"""

from __future__ import annotations

from collections.abc import Callable, MutableMapping
from typing import Any

from ..cip.epath import PortSegment, parse_application_path
from ..cip.messages import MessageRouterRequest, MessageRouterResponse
from ..cip.router import RequestContext
from ..cip.status import CipError, ExtendedStatus, GeneralStatus
from .explicit import NO_ADDITIONAL, ExplicitRequest, ExplicitResponse, FrameError
from .network import NODE_ADDRESSES, CompoNetNetwork, NoResponse

COMPONET_PORT = 2

RouteHandler = Callable[[PortSegment, bytes, list[Any], RequestContext], MessageRouterResponse]


class CompoNetGateway:
    def __init__(self, network: CompoNetNetwork, port: int = COMPONET_PORT) -> None:
        self.network = network
        self.port = port
        #: Time of the request being routed (the gateway device sets it in ``advance``).
        self.now = 0.0
        self.routed = 0

    def register(self, routes: MutableMapping[int, RouteHandler]) -> None:
        """Become the route of ``port`` in a Connection Manager's ``routes``."""
        routes[self.port] = self.route

    def route(self, segment: PortSegment, message: bytes, remaining: list[Any],
              context: RequestContext) -> MessageRouterResponse:
        words = bytes((1,))   # remaining path size reported with a routing error
        if remaining:
            raise CipError(GeneralStatus.CONNECTION_FAILURE, (ExtendedStatus.INVALID_SEGMENT_IN_CONNECTION_PATH,),
                           data=words, message="a CompoNet slave routes no further")
        if len(segment.link) != 1 or segment.link[0] >= NODE_ADDRESSES:
            raise CipError(GeneralStatus.CONNECTION_FAILURE, (ExtendedStatus.LINK_ADDRESS_NOT_VALID,), data=words,
                           message=f"CompoNet node address {segment.link.hex()} outside 0-63")
        node = segment.link[0]
        request = MessageRouterRequest.decode(message)
        path = parse_application_path(request.path)
        try:
            frame = ExplicitRequest(node, request.service, path.class_id, path.instance or 0, path.attribute,
                                    request.data).encode()
        except FrameError as exc:
            raise CipError(GeneralStatus.PATH_SEGMENT_ERROR, message=str(exc)) from None
        now = max(self.now, context.now)
        try:
            answer = ExplicitResponse.decode(self.network.exchange(frame, now))
        except NoResponse as exc:
            raise CipError(GeneralStatus.CONNECTION_FAILURE, (ExtendedStatus.UNCONNECTED_REQUEST_TIMED_OUT,),
                           data=words, message=str(exc)) from None
        self.routed += 1
        if answer.is_error:
            general, additional = answer.error_code
            return MessageRouterResponse(request.service, general, () if additional == NO_ADDITIONAL else (additional,))
        return MessageRouterResponse(request.service, 0, (), answer.data)


__all__ = ["COMPONET_PORT", "CompoNetGateway"]
