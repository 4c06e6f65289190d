"""Explicit-messaging faults: filters where a request reaches the message router
(``cipstack.eip.target.seams.RequestSeam``) or a reply leaves on TCP (``ReplySeam``), and the actions on
the encapsulation layer.

``error-status`` and ``refuse-forward-open`` answer a matching request with the chosen status; it
never reaches the device, every other request goes on to the router. ``delay-replies`` holds each
TCP reply back for a while, in order. ``close-tcp`` and ``drop-sessions`` happen once.
"""

from __future__ import annotations

import asyncio
from typing import TYPE_CHECKING

from ..cip.epath import parse_application_path
from ..cip.messages import MessageRouterRequest, MessageRouterResponse, Service
from ..cip.status import CipError, GeneralStatus
from ..eip.target.connection_manager import connection_failure
from ..eip.wire.cm_messages import ForwardOpenRequest
from .class1 import DEFAULT_DELAY
from .effect import Action, FaultContext

if TYPE_CHECKING:
    from ..cip.router import RequestContext
    from ..eip.target.seams import Handle, ReplySender

_FORWARD_OPENS = (Service.FORWARD_OPEN, Service.LARGE_FORWARD_OPEN)
_CONNECTION_MANAGER = 0x06
#: Connections ``delay-replies`` remembers the last reply of before it forgets those with none held.
_CONNECTIONS_KEPT = 256


class RequestFault:
    """A request filter that answers matching requests itself, at most ``--count`` times."""

    def __init__(self, context: FaultContext, remaining: int | None) -> None:
        self.context = context
        self.remaining = remaining

    def start(self) -> None:
        self.context.runtime.requests.add(self)

    def stop(self) -> None:
        self.context.runtime.requests.remove(self)

    def request(self, raw: bytes, context: RequestContext, call_next: Handle) -> bytes:
        reply = self._answer(raw)
        if reply is None:
            return call_next(raw, context)
        if self.remaining is not None:
            self.remaining -= 1
            if self.remaining <= 0:
                self.context.used_up()
        return reply

    def _answer(self, raw: bytes) -> bytes | None:
        raise NotImplementedError


def _decode(raw: bytes) -> tuple[MessageRouterRequest, int | None, int | None, int | None] | None:
    """The request, its class, instance and attribute; None for a malformed one (the router's to answer)."""
    try:
        request = MessageRouterRequest.decode(raw)
        path = parse_application_path(request.path)
    except (CipError, ValueError):
        return None
    return request, path.class_id, path.instance, path.attribute


class ErrorStatus(RequestFault):
    def __init__(self, context: FaultContext) -> None:
        super().__init__(context, context.options.count)
        options = context.options
        #: What a request must be to be answered: (what to compare, the option), each option given.
        self.match = tuple((index, wanted) for index, wanted in enumerate(
            (options.service, options.class_id, options.instance, options.attribute)) if wanted is not None)
        self.status = options.status or (GeneralStatus.SERVICE_NOT_SUPPORTED, ())

    def _answer(self, raw: bytes) -> bytes | None:
        decoded = _decode(raw)
        if decoded is None:
            return None
        request, class_id, instance, attribute = decoded
        found = (request.service, class_id, instance, attribute)
        if any(found[index] != wanted for index, wanted in self.match):
            return None
        general, extended = self.status
        return MessageRouterResponse(request.service, general, extended).encode()


class RefuseForwardOpen(RequestFault):
    def __init__(self, context: FaultContext) -> None:
        super().__init__(context, 1 if context.options.count is None else context.options.count)
        # The fault model requires it (its positional argument).
        self.extended_status = context.options.extended_status or 0

    def _answer(self, raw: bytes) -> bytes | None:
        decoded = _decode(raw)
        if decoded is None:
            return None
        request, class_id, _instance, _attribute = decoded
        if request.service not in _FORWARD_OPENS or class_id != _CONNECTION_MANAGER:
            return None
        try:
            forward_open = ForwardOpenRequest.decode(request.data, request.service == Service.LARGE_FORWARD_OPEN)
        except (CipError, ValueError, IndexError):
            return None
        error = connection_failure(self.extended_status, forward_open.triad,
                                   "refused (fault refuse-forward-open)")
        return MessageRouterResponse.from_error(request.service, error).encode()


class DelayReplies:
    """``delay-replies``: each TCP reply of the encapsulation server leaves this much later, in order
    per connection. One at a time: a new one replaces the one in force (``FaultKind.exclusive``)."""

    def __init__(self, context: FaultContext) -> None:
        self.context = context
        self.by: float = DEFAULT_DELAY if context.options.by is None else context.options.by
        self.jitter: float = context.options.jitter or 0.0
        #: When the last reply of each connection leaves: the next never leaves before it.
        self._last: dict[int, float] = {}

    def start(self) -> None:
        self.context.runtime.replies.filter = self

    def stop(self) -> None:
        if self.context.runtime.replies.filter is self:
            self.context.runtime.replies.filter = None

    def reply(self, served: ReplySender, out: bytes) -> None:
        loop = asyncio.get_running_loop()
        now = loop.time()
        if len(self._last) > _CONNECTIONS_KEPT:   # bounded: forget the connections whose replies have all left
            self._last = {key: at for key, at in self._last.items() if at > now}
        spread = self.context.rng.uniform(-self.jitter, self.jitter) if self.jitter else 0.0
        at = max(now + max(0.0, self.by + spread), self._last.get(id(served), 0.0))
        self._last[id(served)] = at
        loop.call_at(at, served.send_reply, out)


class CloseTcp(Action):
    def start(self) -> None:
        self.context.runtime.close_tcp()


class DropSessions(Action):
    def start(self) -> None:
        self.context.runtime.drop_sessions()


__all__ = ["CloseTcp", "DelayReplies", "DropSessions", "ErrorStatus", "RefuseForwardOpen"]
