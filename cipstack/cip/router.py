"""The message router: resolves a request's path to an object and returns its reply.

It knows no transport: EtherNet/IP (unconnected, class 3) and the CompoNet explicit
exchange both hand it encoded requests and send back what it returns. Every failure becomes
an error reply with the status the specification gives; nothing raised by an object escapes.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from typing import Any

from ..errors import BadRequest
from .epath import parse_application_path
from .messages import MessageRouterRequest, MessageRouterResponse
from .model import CipObject
from .status import CipError, GeneralStatus

log = logging.getLogger(__name__)

_GET_ATTRIBUTE_SINGLE = 0x0E
_GET_ATTRIBUTE_SINGLE_REPLY = bytes((_GET_ATTRIBUTE_SINGLE | 0x80, 0, 0, 0))
_COMMON_HANDLE = CipObject.handle
_COMMON_GET_ATTRIBUTE_SINGLE = CipObject.get_attribute_single


@dataclass
class RequestContext:
    """What a transport tells an object about the request it is serving."""

    router: MessageRouter
    #: Monotonic time of arrival, seconds.
    now: float = 0.0
    #: Peer address text, for logs.
    origin: str = ""
    #: Transport-specific owner of the request (an encapsulation connection), or None.
    transport: Any = None
    #: True when the request arrived on a class 3 connection.
    connected: bool = False
    extras: dict[str, Any] = field(default_factory=dict)
    #: How many requests enclose the one being served (Multiple_Service_Packet, Unconnected_Send).
    depth: int = 0
    #: The class 1 (I/O) connections the transport offers, which the Connection Manager hands a
    #: class 1 Forward_Open or Forward_Close (an ``IoConnectionHandler`` of ``eip.target``); None where
    #: the transport carries no I/O (CompoNet, a device without I/O assemblies).
    class1: Any = None


#: Readers of Get_Attribute_Single kept at most: every readable attribute of a large device, and a
#: bound on what a peer asking for every combination of bytes can make the router hold.
MAX_ATTRIBUTE_READERS = 4096

#: Requests nest (a packet of routed requests of packets...); deeper than this is refused with
#: 0x02 (resource unavailable) rather than recursing without bound.
MAX_NESTING = 4


class MessageRouter:
    def __init__(self) -> None:
        self.objects: dict[int, CipObject] = {}
        #: Counts of requests by service and the general status they were answered with, keyed
        #: ``service << 8 | status`` (one int key: no tuple to build per request); ``/metrics`` reads it.
        self.reply_counts: dict[int, int] = {}
        #: Get_Attribute_Single requests -> their readers (``_attribute_reader``), bounded.
        self._readers: dict[bytes, Callable[[], bytes | None]] = {}

    def register(self, obj: CipObject) -> CipObject:
        class_id = obj.spec.class_id
        if class_id in self.objects:
            raise BadRequest(f"class 0x{class_id:02X} registered twice")
        self.objects[class_id] = obj
        return obj

    def __getitem__(self, class_id: int) -> CipObject:
        return self.objects[class_id]

    def __contains__(self, class_id: int) -> bool:
        return class_id in self.objects

    def handle(self, raw: bytes, context: RequestContext) -> bytes:
        """Serve one encoded request and return the encoded reply (never raises)."""
        reader = self._readers.get(raw)  # kept for this very request: its shape was checked then
        if reader is None and len(raw) == 8 and raw[0] == _GET_ATTRIBUTE_SINGLE:
            reader = self._attribute_reader(raw)
        if reader is not None and context.depth <= MAX_NESTING:
            reply = reader()
            if reply is not None:
                return reply
            self._readers.pop(raw, None)  # the instance has gone, nothing was read: dispatch says so
        return self.dispatch(raw, context).encode()

    def _attribute_reader(self, raw: bytes) -> Callable[[], bytes | None] | None:
        """For the most common request, Get_Attribute_Single ``0E 03 20 cc 24 ii 30 aa``: a reader that
        reads the attribute and returns the whole reply, skipping the request, path and reply objects
        and the lookups (object, instance, attribute declaration); made once per request and kept. A
        read that fails is answered here as ``dispatch`` answers it, so that the attribute is read
        once whatever happens (a read may have an effect). None when the object does not serve the
        request the common way, and from the reader when its instance has gone before any read;
        ``dispatch`` then serves the request, as it serves every other."""
        if raw[1] != 3 or raw[2] != 0x20 or raw[4] != 0x24 or raw[6] != 0x30:
            return None  # another 8-byte Get_Attribute_Single (16-bit segments, a member...)
        class_id, instance_id, attribute_id = raw[3], raw[5], raw[7]
        obj = self.objects.get(class_id)
        if obj is None or _GET_ATTRIBUTE_SINGLE in obj.extra_services:
            return None
        kind = type(obj)
        if kind.handle is not _COMMON_HANDLE or kind.get_attribute_single is not _COMMON_GET_ATTRIBUTE_SINGLE:
            return None
        instance = None
        if instance_id:
            instance = obj.instances.get(instance_id)
            if instance is None or _GET_ATTRIBUTE_SINGLE not in obj.spec.instance_services:
                return None
        elif _GET_ATTRIBUTE_SINGLE not in obj.spec.class_services:
            return None
        try:
            spec, getter = obj._attribute(instance, attribute_id)  # declarations do not change
        except CipError:
            return None
        # A class attribute has its getter; an instance attribute is read from the instance found now,
        # which must still be the one that exists when the reader reads.
        value: Callable[[], Any]
        if getter is not None:
            value = getter
        elif instance is not None and spec.access.readable:
            value = partial(obj.read_attribute, instance, spec)
        else:
            return None
        encode, counts, failure, instances = spec.type.encode, self.reply_counts, self._failure, obj.instances
        success = _GET_ATTRIBUTE_SINGLE << 8

        def reader() -> bytes | None:
            if instance is not None and instances.get(instance_id) is not instance:
                return None
            try:
                data = encode(value())
            except Exception as exc:
                return failure(_GET_ATTRIBUTE_SINGLE, exc).encode()
            counts[success] = counts.get(success, 0) + 1
            return _GET_ATTRIBUTE_SINGLE_REPLY + data
        if len(self._readers) < MAX_ATTRIBUTE_READERS:
            self._readers[raw] = reader
        return reader

    def dispatch(self, raw: bytes, context: RequestContext) -> MessageRouterResponse:
        service = raw[0] & 0x7F if raw else 0
        if context.depth > MAX_NESTING:
            return MessageRouterResponse(service, GeneralStatus.RESOURCE_UNAVAILABLE)
        context.depth += 1
        try:
            request = MessageRouterRequest.decode(raw)
            path = parse_application_path(request.path)
            obj = self.objects.get(path.class_id)
            if obj is None:
                raise CipError(GeneralStatus.PATH_DESTINATION_UNKNOWN,
                               message=f"no class 0x{path.class_id:02X}")
            data = obj.handle(path, request, context)
            # A service that forwards a request (Unconnected_Send) returns the whole reply.
            response = data if isinstance(data, MessageRouterResponse) else MessageRouterResponse(service, 0, (), data)
        except Exception as exc:
            return self._failure(service, exc)
        finally:
            context.depth -= 1
        key = service << 8 | response.general_status
        self.reply_counts[key] = self.reply_counts.get(key, 0) + 1
        return response

    def _failure(self, service: int, exc: Exception) -> MessageRouterResponse:
        """The reply to a request whose service raised ``exc`` (called in its ``except``), counted: a
        ``CipError`` gives its status; anything else is an object bug, logged, and must not take the
        server down (0x1F)."""
        if isinstance(exc, CipError):
            response = MessageRouterResponse.from_error(service, exc)
        else:
            log.exception("internal error serving service 0x%02X", service)
            response = MessageRouterResponse(service, GeneralStatus.VENDOR_SPECIFIC)
        key = service << 8 | response.general_status
        self.reply_counts[key] = self.reply_counts.get(key, 0) + 1
        return response

    @property
    def status_counts(self) -> dict[int, int]:
        """Counts of requests answered with each general status, whatever the service."""
        counts: dict[int, int] = {}
        for key, count in self.reply_counts.items():
            counts[key & 0xFF] = counts.get(key & 0xFF, 0) + count
        return counts
