"""DIO-4, a digital I/O block with four inputs and four outputs: an example of a device family that
another distribution brings to cipstack. No manual describes it; its objects are those of the CIP object
library (CIP Vol 1): Identity, Assembly, Discrete Input Point (class 0x08, section 5-9) and Discrete
Output Point (class 0x09, section 5-10).

Its inputs are wired to its outputs, point by point, as on a test bench: input N reads what output N
is set to, over explicit messaging or the output assembly. Its EDS description is in ``eds.py``."""

from __future__ import annotations

from cipstack.cip.model import Access, AttributeSpec, Binding, CipObject, ClassSpec
from cipstack.cip.types import BOOL, UINT
from cipstack.devices.base import Device, DeviceLimits
from cipstack.devices.profiles import ModelInfo, Profile, ProfileOptions, serial_from_mac
from cipstack.objects.assembly import AssemblyPoint
from cipstack.objects.identity import IdentityInfo
from cipstack.objects.tcpip import NetworkInterface

#: Made up for the example: no vendor's product. Device type 7 is the General Purpose Discrete I/O
#: profile (CIP Vol 1, chapter 6).
VENDOR_ID = 0xFFF0
DEVICE_TYPE = 7
PRODUCT_CODE = 4
PRODUCT_NAME = "DIO-4"
REVISION = (1, 1)
POINTS = 4

#: Assembly instances in the vendor-specific range 0x64-0xC7 (CIP Vol 1, section 5-5): one byte each,
#: bit N-1 for point N.
INPUT_ASSEMBLY = 100
OUTPUT_ASSEMBLY = 150

_OFF_ON = {0: "off", 1: "on"}

#: Discrete Input Point, CIP Vol 1 section 5-9: Value (3, 0 = off, 1 = on), Status (4, 0 = OK), and the
#: input filters Off_On Delay (5) and On_Off Delay (6) in microseconds, 0 by default.
DISCRETE_INPUT_POINT = ClassSpec(0x08, "Discrete Input Point", instance_attributes=(
    AttributeSpec(3, "Value", BOOL, Access.GET, default=0, enum=_OFF_ON),
    AttributeSpec(4, "Status", BOOL, Access.GET, default=0, enum={0: "OK", 1: "alarm"}),
    AttributeSpec(5, "Off_On Delay", UINT, Access.GET_SET, default=0, unit="us"),
    AttributeSpec(6, "On_Off Delay", UINT, Access.GET_SET, default=0, unit="us"),
))

#: Discrete Output Point, CIP Vol 1 section 5-10: Value (3), Status (4), and what the output does on a
#: fault (5, 6) and when idle (7, 8): 0 = go to the Fault/Idle Value, 1 = hold the last state.
DISCRETE_OUTPUT_POINT = ClassSpec(0x09, "Discrete Output Point", instance_attributes=(
    AttributeSpec(3, "Value", BOOL, Access.GET_SET, default=0, enum=_OFF_ON),
    AttributeSpec(4, "Status", BOOL, Access.GET, default=0, enum={0: "OK", 1: "failure"}),
    AttributeSpec(5, "Fault Action", BOOL, Access.GET_SET, default=0,
                  enum={0: "Fault Value", 1: "hold last state"}),
    AttributeSpec(6, "Fault Value", BOOL, Access.GET_SET, default=0, enum=_OFF_ON),
    AttributeSpec(7, "Idle Action", BOOL, Access.GET_SET, default=0,
                  enum={0: "Idle Value", 1: "hold last state"}),
    AttributeSpec(8, "Idle Value", BOOL, Access.GET_SET, default=0, enum=_OFF_ON),
))


def build(interface: NetworkInterface, limits: DeviceLimits, options: ProfileOptions) -> Device:
    """The block: cipstack's standard objects, its points, and one input and one output assembly."""
    identity = IdentityInfo(VENDOR_ID, DEVICE_TYPE, PRODUCT_CODE, REVISION, serial_from_mac(interface.mac),
                            PRODUCT_NAME)
    device = Device(identity, interface, limits, files=options.files)
    outputs = CipObject(DISCRETE_OUTPUT_POINT)
    inputs = CipObject(DISCRETE_INPUT_POINT)
    for point in range(1, POINTS + 1):
        outputs.add_instance(point)
        # The bench wiring: input N reads output N.
        inputs.add_instance(point, value=Binding(lambda p=point: outputs.get(p, 3)))
    device.router.register(inputs)
    device.router.register(outputs)

    def produce() -> bytes:
        return bytes([sum(int(inputs.get(p, 3)) << (p - 1) for p in range(1, POINTS + 1))])

    def consume(data: bytes, now: float) -> None:
        for p in range(1, POINTS + 1):
            outputs.set(p, 3, (data[0] >> (p - 1)) & 1)

    device.assembly.add_assembly(AssemblyPoint(INPUT_ASSEMBLY, 1, consumed=False, produce=produce, name="inputs"))
    device.assembly.add_assembly(AssemblyPoint(OUTPUT_ASSEMBLY, 1, consumed=True, consume=consume, name="outputs"))
    return device


PROFILE = Profile("dio", "DIO-4 digital I/O block, four inputs wired to four outputs (examples/device-family)",
                  build, vendor_id=VENDOR_ID, product_codes=frozenset({PRODUCT_CODE}), device_type=DEVICE_TYPE,
                  model_info=lambda: (ModelInfo(PRODUCT_NAME, PRODUCT_CODE, PRODUCT_NAME),),
                  # Imported by the EDS tool when a file is made (eds.py imports cipstack.eds, which the
                  # device never does): a reference, not the function.
                  eds="cipstack_dio.eds:description")
