"""Message Router object (class 0x02): the object list and Multiple_Service_Packet."""

from __future__ import annotations

import struct

from ..cip.epath import ApplicationPath
from ..cip.messages import MessageRouterRequest, Service
from ..cip.model import AttributeSpec, Binding, CipObject, ClassSpec, Instance
from ..cip.router import MessageRouter, RequestContext
from ..cip.status import CipError, GeneralStatus
from ..cip.types import UINT, ArrayType, StructType

CLASS_ID = 0x02

OBJECT_LIST = StructType("OBJECT_LIST", [("number", UINT), ("classes", ArrayType(UINT))])

SPEC = ClassSpec(
    CLASS_ID, "Message Router", revision=1,
    instance_attributes=(
        AttributeSpec(1, "Object List", OBJECT_LIST),
        AttributeSpec(2, "Number Available", UINT),
    ),
    class_services=frozenset({Service.GET_ATTRIBUTE_SINGLE}),
    instance_services=frozenset({Service.GET_ATTRIBUTE_SINGLE, Service.GET_ATTRIBUTES_ALL,
                                 Service.MULTIPLE_SERVICE_PACKET}),
)

_UINT = struct.Struct("<H")


class MessageRouterObject(CipObject):
    extra_services = {Service.MULTIPLE_SERVICE_PACKET: "multiple_service_packet"}

    def __init__(self, router: MessageRouter, max_connections: int) -> None:
        super().__init__(SPEC)
        self.router = router
        self.add_instance(1, object_list=Binding(self._object_list), number_available=max_connections)

    def _object_list(self) -> dict[str, object]:
        classes = sorted(self.router.objects)
        return {"number": len(classes), "classes": classes}

    def multiple_service_packet(self, instance: Instance | None, path: ApplicationPath,
                                request: MessageRouterRequest, context: RequestContext) -> bytes:
        data = request.data
        count, _ = UINT.decode_from(data, 0)
        table_end = 2 + 2 * count
        if len(data) < table_end:
            raise CipError(GeneralStatus.NOT_ENOUGH_DATA, message="offset table cut short")
        offsets = [_UINT.unpack_from(data, 2 + 2 * i)[0] for i in range(count)]
        bounds = [*offsets, len(data)]
        for i in range(count):
            if not table_end <= bounds[i] < bounds[i + 1] <= len(data):
                raise CipError(GeneralStatus.INVALID_PARAMETER, message=f"offset {i} of a service packet is invalid")
        replies = [self.router.handle(data[bounds[i]:bounds[i + 1]], context) for i in range(count)]
        out = bytearray(_UINT.pack(count))
        offset = 2 + 2 * count
        for reply in replies:
            out += _UINT.pack(offset)
            offset += len(reply)
        for reply in replies:
            out += reply
        if any(reply[2] != 0 for reply in replies):
            raise CipError(GeneralStatus.EMBEDDED_SERVICE_ERROR, data=bytes(out))
        return bytes(out)
