"""A write outside an attribute's declared range is refused with 0x09 and changes nothing.

The rule is the object runtime's, from the declaration (the declared minimum and maximum; a BOOL
is 0-1 whatever else is declared): every settable attribute of every profile, and of a device
emulated from an EDS, is written one value past each bound over a real loopback connection, and
must answer 0x09 (invalid attribute value) and read back as before. The field saw the ACG's Run Fwd
(0x29/1/3) and Fault Reset (0x29/1/12) and the Omron's Net Ref (0x2A/1/4) take 2 or 0xFF as 1: the
drive ran, and a following 1 made no 0 -> 1 edge.
"""

from __future__ import annotations

from collections.abc import AsyncIterator, Callable, Iterator
from contextlib import asynccontextmanager

import pytest

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.cip.messages import Service
from cipstack.cip.model import AttributeSpec, CipObject
from cipstack.cip.types import BOOL, BoolType, IntegerType
from cipstack.devices.acg import registers as acg_registers
from cipstack.devices.acg.device import AcgDevice
from cipstack.devices.acg.eds_file import acg_et2_description
from cipstack.devices.acg.objects import KeypadParameterObject, keypad_parameter_spec
from cipstack.devices.base import Device
from cipstack.devices.omron.eds_file import omron_description
from cipstack.devices.profiles import build_device
from cipstack.eds.emulated_device import EdsObject, build_eds_device
from cipstack.eds.generator import eds_text
from cipstack.eds.reader import parse_eds
from cipstack.scanner import Scanner

INVALID_ATTRIBUTE_VALUE = 0x09


@asynccontextmanager
async def serving(device: Device) -> AsyncIterator[Scanner]:
    adapter = Adapter(AdapterSettings(host="127.0.0.1", port=0, io_port=0), device=device)
    await adapter.start()
    try:
        async with await Scanner.connect(f"127.0.0.1:{adapter.port}") as scanner:
            yield scanner
    finally:
        await adapter.close()


def bounds(spec: AttributeSpec) -> tuple[int | float | None, int | float | None]:
    if isinstance(spec.type, BoolType):
        return (0 if spec.minimum is None else spec.minimum, 1 if spec.maximum is None else spec.maximum)
    return spec.minimum, spec.maximum


def past_bounds(spec: AttributeSpec) -> list[int]:
    """One value past each declared bound that the attribute's type can still carry on the wire."""
    cip_type = spec.type
    if not isinstance(cip_type, IntegerType):
        return []
    bits = 8 * (cip_type.size or 0)
    wire_min, wire_max = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if cip_type.signed else (0, (1 << bits) - 1)
    low, high = bounds(spec)
    values = []
    if high is not None and high + 1 <= wire_max:
        values.append(int(high) + 1)
    if low is not None and low - 1 >= wire_min:
        values.append(int(low) - 1)
    if low is None and high is None and spec.enum:
        values.extend(v for v in (max(spec.enum) + 1,) if v <= wire_max)
    return values


def settable(device: Device) -> Iterator[tuple[int, int, AttributeSpec]]:
    """(class, instance, declaration) of every settable attribute the device declares."""
    for class_id, obj in sorted(device.router.objects.items()):
        for instance_id in sorted(obj.instances):
            for spec in declared(obj, instance_id):
                if spec.access.settable:
                    yield class_id, instance_id, spec


def declared(obj: CipObject, instance_id: int) -> list[AttributeSpec]:
    if isinstance(obj, EdsObject):
        return list(obj.declared.get(instance_id, {}).values())
    if isinstance(obj, KeypadParameterObject):
        # Class 0x64 serves each keypad parameter with its register's declaration (ACG-ET2 manual).
        found = (acg_registers.class64_register(instance_id, n) for n in range(256))
        return [keypad_parameter_spec(register) for register in found if register is not None]
    return list(obj.spec.instance_attributes)


def eds_device(name: str) -> Device:
    return build_eds_device(parse_eds(eds_text(acg_et2_description() if name == "ACG-ET2"
                                               else omron_description(name))))


DEVICES: dict[str, Callable[[], Device]] = {
    "acg": lambda: build_device("acg"), "mx2": lambda: build_device("mx2"), "rx": lambda: build_device("rx"),
    "eds-acg": lambda: eds_device("ACG-ET2"), "eds-mx2": lambda: eds_device("MX2-A2015-E"),
}


@pytest.mark.parametrize("name", sorted(DEVICES))
async def test_every_declared_range_is_enforced_on_the_wire(name: str) -> None:
    device = DEVICES[name]()
    checked, accepted = 0, []
    async with serving(device) as scanner:
        for class_id, instance_id, spec in settable(device):
            for value in past_bounds(spec):
                before = await scanner.request(Service.GET_ATTRIBUTE_SINGLE, class_id, instance_id, spec.id,
                                               check=False)
                reply = await scanner.request(Service.SET_ATTRIBUTE_SINGLE, class_id, instance_id, spec.id,
                                              spec.type.struct_codec.pack(value), check=False)
                after = await scanner.request(Service.GET_ATTRIBUTE_SINGLE, class_id, instance_id, spec.id,
                                              check=False)
                checked += 1
                if reply.general_status != INVALID_ATTRIBUTE_VALUE or after.data != before.data:
                    accepted.append(f"0x{class_id:02X}/{instance_id}/{spec.id} {spec.name} {bounds(spec)} <- {value}: "
                                    f"0x{reply.general_status:02X}, {before.data.hex()} -> {after.data.hex()}")
    assert checked > 0
    assert accepted == []


async def test_acg_run_forward_of_2_is_refused_and_the_next_1_still_runs() -> None:
    """ACG-ET2 manual, Control Supervisor table: Forward Run Cmd. and Drive Fault Reset are 0 or 1; the
    drive acts on a 0 -> 1 change (Drive Run table, Drive Fault Reset)."""
    device = build_device("acg")
    assert isinstance(device, AcgDevice)
    device.drive.write(acg_registers.ACG_REGISTERS.by_code("drv").address, 4, 0.0)   # run commands from the card
    async with serving(device) as scanner:
        for value in (b"\x02", b"\xff"):
            for attribute in (3, 4, 12):
                reply = await scanner.request(Service.SET_ATTRIBUTE_SINGLE, 0x29, 1, attribute, value, check=False)
                assert reply.general_status == INVALID_ATTRIBUTE_VALUE
        assert await scanner.read(0x29, 1, 3, BOOL) == 0
        assert await scanner.read(0x29, 1, 7, BOOL) == 0                 # Running Forward: the drive did not start
        await scanner.set_attribute_single(0x29, 1, 3, 1, BOOL)    # the edge is still there to make
        assert await scanner.read(0x29, 1, 7, BOOL) == 1


@pytest.mark.parametrize("profile", ["mx2", "rx"])
async def test_omron_net_ref_of_ff_is_refused(profile: str) -> None:
    """CompoNet manual Table D-7: Net Ref, setting range 0 - 1; Table E-5: 09 "The data written is outside range"."""
    device = build_device(profile)
    async with serving(device) as scanner:
        reply = await scanner.request(Service.SET_ATTRIBUTE_SINGLE, 0x2A, 1, 4, b"\xff", check=False)
        assert reply.general_status == INVALID_ATTRIBUTE_VALUE
        assert await scanner.read(0x2A, 1, 4, BOOL) == 0
        assert await scanner.read(0x2A, 1, 0x1D, BOOL) == 0               # Ref From Net: still local
