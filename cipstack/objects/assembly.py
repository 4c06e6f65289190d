"""Assembly object (class 0x04): instances whose attribute 3 is a block of I/O data.

Generic: each instance has a fixed size and either holds its bytes or takes them from the
device (``produce``) and hands written bytes to it (``consume``). Output (consumed)
assemblies are settable; a write must carry exactly the instance's size (0x13 short,
0x15 long).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ..cip.messages import Service
from ..cip.model import Access, AttributeSpec, Binding, CipObject, ClassSpec, Instance
from ..cip.router import RequestContext
from ..cip.status import CipError, GeneralStatus
from ..cip.types import UINT, RemainingBytes

CLASS_ID = 0x04

SPEC = ClassSpec(
    CLASS_ID, "Assembly", revision=2,
    instance_attributes=(
        AttributeSpec(3, "Data", RemainingBytes("ASSEMBLY DATA"), Access.GET_SET, default=b""),
        AttributeSpec(4, "Size", UINT),
    ),
    class_services=frozenset({Service.GET_ATTRIBUTE_SINGLE}),
    instance_services=frozenset({Service.GET_ATTRIBUTE_SINGLE, Service.SET_ATTRIBUTE_SINGLE}),
)


@dataclass
class AssemblyPoint:
    instance_id: int
    size: int
    #: True for output (consumed, O->T) assemblies: settable over the network.
    consumed: bool
    #: The device's current data of an input (produced) assembly.
    produce: Callable[[], bytes] | None = None
    #: Called with new data of an output (consumed) assembly and the time it arrived.
    consume: Callable[[bytes, float], None] | None = None
    name: str = ""
    #: A variable-size assembly (an EDS ``AssemExaN``): a connection that says its size is variable
    #: may carry fewer bytes than ``size`` (the first ones; the rest of an output reads as zeros).
    variable: bool = False


class AssemblyObject(CipObject):
    def __init__(self) -> None:
        super().__init__(SPEC)
        self.points: dict[int, AssemblyPoint] = {}
        #: Last data written to each assembly (what an output without a device consumer holds).
        self.stores: dict[int, bytearray] = {}

    def add_assembly(self, point: AssemblyPoint) -> None:
        self.points[point.instance_id] = point
        self.stores[point.instance_id] = bytearray(point.size)

        def produce() -> bytes:
            return point.produce() if point.produce is not None else bytes(self.stores[point.instance_id])

        self.add_instance(point.instance_id, data=Binding(produce), size=point.size)

    def deliver(self, instance_id: int, data: bytes, now: float) -> None:
        """New data for an output assembly, from explicit messaging or a class 1 connection."""
        self.stores[instance_id][:] = data
        point = self.points[instance_id]
        if point.consume is not None:
            point.consume(bytes(data), now)

    def data(self, instance_id: int) -> bytes:
        return bytes(self.get(instance_id, 3))

    def write_attribute(self, instance: Instance, spec: AttributeSpec, value: Any,
                        context: RequestContext | None = None) -> None:
        if spec.id == 3:
            point = self.points[instance.instance_id]
            where = f"assembly {point.instance_id}"
            if not point.consumed and context is not None:
                # An input (produced) assembly is the device's to write, not the network's.
                raise CipError(GeneralStatus.ATTRIBUTE_NOT_SETTABLE, message=f"{where} is an input")
            data = bytes(value)
            if len(data) != point.size:
                code = GeneralStatus.NOT_ENOUGH_DATA if len(data) < point.size else GeneralStatus.TOO_MUCH_DATA
                raise CipError(code, message=f"{where} is {point.size} bytes, got {len(data)}")
            self.deliver(point.instance_id, data, context.now if context is not None else 0.0)
            return
        super().write_attribute(instance, spec, value, context)
