"""Explicit-messaging faults, applied where a request reaches the message router or a reply
leaves on TCP.

``RouterFaultLayer`` stands in for the device's message router in the encapsulation target while
an ``error-status`` or ``refuse-forward-open`` fault is active: a matching request is answered with
the chosen status and never reaches the device; every other request goes to the router as before.
``ReplyDelay`` holds each TCP reply back for a while (``delay-replies``), in order.
"""

from __future__ import annotations

import asyncio
import random
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from ..cip.epath import parse_application_path
from ..cip.messages import MessageRouterRequest, MessageRouterResponse, Service
from ..cip.status import CipError, GeneralStatus
from ..eip.cm_messages import ForwardOpenRequest
from ..eip.connection_manager import connection_failure
from .model import FaultRequest

if TYPE_CHECKING:
    from ..cip.router import MessageRouter, RequestContext
    from ..eip.server import EncapsulationServer

_FORWARD_OPENS = (Service.FORWARD_OPEN, Service.LARGE_FORWARD_OPEN)
_CONNECTION_MANAGER = 0x06


class ActiveRouterFault:
    def __init__(self, fault_id: int, request: FaultRequest) -> None:
        self.id = fault_id
        self.name = request.name
        options = request.options
        self.status = options.get("status")
        self.service: int | None = options.get("service")
        self.class_id: int | None = options.get("class")
        self.instance: int | None = options.get("instance")
        self.attribute: int | None = options.get("attribute")
        self.remaining: int | None = options.get("count", 1 if request.name == "refuse-forward-open" else None)


class RouterFaultLayer:
    """The message router as the target sees it while request faults are active."""

    def __init__(self, router: MessageRouter, used_up: Callable[[int], None]) -> None:
        self.router = router
        #: Called with a fault's id when its ``--count`` is spent (the controller clears it).
        self.used_up = used_up
        self.faults: list[ActiveRouterFault] = []

    def add(self, fault_id: int, request: FaultRequest) -> None:
        self.faults.append(ActiveRouterFault(fault_id, request))

    def remove(self, fault_id: int) -> None:
        self.faults = [f for f in self.faults if f.id != fault_id]

    def handle(self, raw: bytes, context: RequestContext) -> bytes:
        for fault in self.faults:
            reply = self._answer(fault, raw)
            if reply is not None:
                if fault.remaining is not None:
                    fault.remaining -= 1
                    if fault.remaining <= 0:
                        self.faults.remove(fault)
                        self.used_up(fault.id)
                return reply
        return self.router.handle(raw, context)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.router, name)

    def _answer(self, fault: ActiveRouterFault, raw: bytes) -> bytes | None:
        try:
            request = MessageRouterRequest.decode(raw)
            path = parse_application_path(request.path)
        except (CipError, ValueError):
            return None  # a malformed request is the router's to answer
        if fault.name == "refuse-forward-open":
            if request.service not in _FORWARD_OPENS or path.class_id != _CONNECTION_MANAGER:
                return None
            try:
                forward_open = ForwardOpenRequest.decode(request.data, request.service == Service.LARGE_FORWARD_OPEN)
            except (CipError, ValueError, IndexError):
                return None
            error = connection_failure(fault.status, forward_open.triad, "refused (fault refuse-forward-open)")
            return MessageRouterResponse.from_error(request.service, error).encode()
        if fault.service is not None and request.service != fault.service:
            return None
        if fault.class_id is not None and path.class_id != fault.class_id:
            return None
        if fault.instance is not None and path.instance != fault.instance:
            return None
        if fault.attribute is not None and path.attribute != fault.attribute:
            return None
        general, extended = fault.status or (GeneralStatus.SERVICE_NOT_SUPPORTED, ())
        return MessageRouterResponse(request.service, general, extended).encode()


class ReplyDelay:
    """``delay-replies``: each TCP reply of the encapsulation server leaves this much later, in order."""

    def __init__(self, server: EncapsulationServer, loop: asyncio.AbstractEventLoop, by: float, jitter: float,
                 rng: random.Random | None = None) -> None:
        self.server = server
        self.loop = loop
        self.by = by
        self.jitter = jitter
        self.rng = rng or random.Random()
        self._patched: list[Any] = []

    def install(self) -> None:
        server = self.server
        opened = server.opened

        def opened_with_delay(served: Any, peer_text: str, local: Any) -> Any:
            connection = opened(served, peer_text, local)
            self._patch(connection, served)
            return connection

        server.opened = opened_with_delay  # type: ignore[method-assign]
        for served in list(server.connections):
            self._patch(served.connection, served)

    def uninstall(self) -> None:
        self.server.__dict__.pop("opened", None)
        for connection in self._patched:
            connection.__dict__.pop("data_to_send", None)
        self._patched.clear()

    def _patch(self, connection: Any, served: Any) -> None:
        if connection is None:
            return
        take = type(connection).data_to_send.__get__(connection)
        last = [0.0]

        def data_to_send() -> bytes:
            out = take()
            if out:
                now = self.loop.time()
                spread = self.rng.uniform(-self.jitter, self.jitter) if self.jitter else 0.0
                at = max(now + max(0.0, self.by + spread), last[0])  # replies stay in order
                last[0] = at
                self.loop.call_at(at, served.send_reply, out)
            return b""

        connection.data_to_send = data_to_send
        self._patched.append(connection)
