"""The generic device emulated from an EDS (``eds.emulated_device``), served by a real ``Adapter``.

* Round trip: the emulator started from the EDS we generate for a profile serves, over the
  network, the identity and the assembly instances and sizes the profile's own emulator serves,
  and the parameter values the profile starts with.
* A hand-written EDS of a device no profile knows: its parameters are attributes a scanner reads
  and writes (types, ranges, access), its assemblies show and set those attributes, and each of
  its ConnectionN opens (or is refused for the reason the target gives).
* Broken constructs: one warning each, never an exception; the rest of the file is served.
"""

from __future__ import annotations

from typing import Any

import pytest

from cipstack.cip.status import CipError, ExtendedStatus, GeneralStatus
from cipstack.cip.types import BOOL, INT, SHORT_STRING, UINT, USINT
from cipstack.devices.acg.device import build_acg_device
from cipstack.devices.acg.eds_file import acg_et2_description
from cipstack.devices.base import Device
from cipstack.devices.omron.device import build_omron_device
from cipstack.devices.omron.eds_file import omron_description
from cipstack.devices.omron.registers import function_code_path
from cipstack.devices.profiles import DEFAULT_MAC
from cipstack.eds.checker import check_eds
from cipstack.eds.emulated_device import EdsDevice, EdsDeviceError, build_eds_device
from cipstack.eds.generator import eds_text
from cipstack.eds.interpret import read_view
from cipstack.eds.reader import parse_eds
from cipstack.objects.tcpip import NetworkInterface
from cipstack.scanner import Scanner
from tests.library_support import serving

from .samples import BROKEN_EDS, BROKEN_WARNINGS, GENERIC_EDS

INTERFACE = NetworkInterface(ip_address="127.0.0.1", mac=DEFAULT_MAC)
#: Identity attributes a scanner reads from both emulators: vendor, device type, product code,
#: revision, serial number, product name (status and state belong to the running device).
IDENTITY_ATTRIBUTES = (1, 2, 3, 4, 6, 7)


async def identity(scanner: Scanner) -> dict[int, Any]:
    return {attribute: (await scanner.get_attribute_single(1, 1, attribute)).value
            for attribute in IDENTITY_ATTRIBUTES}


async def assemblies(scanner: Scanner, instances: list[int]) -> dict[str, Any]:
    """What the Assembly object says of itself: instance count, highest instance, each size."""
    return {
        "count": await scanner.read(4, 0, 3, UINT),
        "max": await scanner.read(4, 0, 2, UINT),
        "sizes": {i: await scanner.read(4, i, 4, UINT) for i in instances},
    }


def profile_device(name: str) -> Device:
    return build_acg_device(INTERFACE) if name == "ACG-ET2" else build_omron_device(name, INTERFACE)


def profile_text(name: str) -> str:
    return eds_text(acg_et2_description() if name == "ACG-ET2" else omron_description(name))


# -- round trip ---------------------------------------------------------------------------------------

#: Attributes each profile starts with a value, at the paths its EDS parameters link: ACG dr.20 Max
#: Freq (class 0x64, dr group, code 20), Control Supervisor Drive State, Motor Data rated voltage;
#: Omron P046 and C001 (input terminal 1 function) by function code (Table E-3: P046 = 15046 = 0x3AC6).
PARAMETER_PATHS = {
    "ACG-ET2": [(0x64, 1, 20), (0x29, 1, 6), (0x28, 1, 7)],
    "MX2-A2015-E": [(0x65, 0x3A, 0xC6), (0x65, *function_code_path("C001"))],
    "RX-A4055-E": [(0x65, 0x3A, 0xC6), (0x65, *function_code_path("C001"))],
}


async def values(scanner: Scanner, name: str) -> list[bytes]:
    """The bytes each parameter's attribute reads as."""
    return [(await scanner.get_attribute_single(*path)).data for path in PARAMETER_PATHS[name]]


@pytest.mark.parametrize("name", ["ACG-ET2", "MX2-A2015-E", "RX-A4055-E"])
async def test_emulator_from_generated_eds_serves_what_the_profile_serves(name: str) -> None:
    doc = parse_eds(profile_text(name))
    from_eds = build_eds_device(doc, INTERFACE)
    # Every construct of our files is served: the Omron function codes of instance 0, which Table E-3
    # puts on the class (F001, F002, F004), as class attributes at their default.
    assert from_eds.issues == []
    original = profile_device(name)
    instances = sorted(original.assembly.points)
    async with serving(original) as (_, scanner):
        expected_identity = await identity(scanner)
        expected_assemblies = await assemblies(scanner, instances)
        expected_values = await values(scanner, name)
    async with serving(from_eds) as (_, scanner):
        assert await identity(scanner) == expected_identity
        assert await assemblies(scanner, instances) == expected_assemblies
        assert await values(scanner, name) == expected_values
        if name != "ACG-ET2":
            assert (await scanner.get_attribute_single(0x65, *function_code_path("F002"))).data
    assert all(expected_values)
    assert expected_assemblies["count"] == len(instances) == (24 if name == "ACG-ET2" else 13)
    # Class 1: the ACG file offers every CM.24/CM.23 pair and the heartbeat points of the card;
    # the CompoNet files list no [Connection Manager], so no class 1 offer.
    offer = from_eds.io_profile()
    if name == "ACG-ET2":
        card = original.io_profile()
        assert offer is not None and card is not None
        assert card.pairs is not None and offer.pairs is not None and card.pairs() <= offer.pairs()
        assert len(offer.pairs()) == 12
        assert (offer.input_only_point, offer.listen_only_point, offer.rpi_min_us, offer.rpi_max_us) == (
            card.input_only_point, card.listen_only_point, card.rpi_min_us, card.rpi_max_us)
    else:
        assert offer is None


async def test_acg_input_assembly_shows_the_attributes_it_links() -> None:
    # Input 71 of the file: byte 1 is Drive State (0x29/6), byte 0 bit 4 Drive Ready (0x29/9).
    device = build_eds_device(parse_eds(profile_text("ACG-ET2")), INTERFACE)
    async with serving(device) as (_, scanner):
        data = (await scanner.read(4, 71, 3)).raw
        assert data[1] == await scanner.read(0x29, 1, 6, USINT) == 3
        await scanner.set_attribute_single(0x29, 1, 3, 1, BOOL)  # Forward Run Cmd. is settable
        # Output 21 written over the network sets the attributes its members link.
        await scanner.set_attribute_single(4, 21, 3, bytes([0b0000_0100, 0]) + INT.encode(1500))
        assert await scanner.read(0x29, 1, 3, BOOL) == 0
        assert await scanner.read(0x29, 1, 12, BOOL) == 1
        assert await scanner.read(0x2A, 1, 8, INT) == 1500


# -- a device no profile knows ------------------------------------------------------------------------------

def generic_device() -> EdsDevice:
    doc = parse_eds(GENERIC_EDS)
    assert check_eds(doc) == []  # a valid file: everything in it is served
    device = build_eds_device(doc, INTERFACE)
    assert device.issues == []
    return device


async def test_generic_parameters_are_attributes() -> None:
    async with serving(generic_device()) as (_, scanner):
        assert await scanner.read(1, 1, 1, UINT) == 1234
        assert await scanner.read(1, 1, 2, UINT) == 0x2B
        assert await scanner.read(1, 1, 3, UINT) == 77
        assert await scanner.read(1, 1, 4) == {"major": 3, "minor": 14}
        assert await scanner.read(1, 1, 7, SHORT_STRING) == "Acme FC-10"
        # Class 0x70 made from the params: defaults, types and access as declared.
        assert await scanner.read(0x70, 1, 1, UINT) == 120
        assert await scanner.read(0x70, 1, 2, INT) == 0
        assert await scanner.read(0x70, 1, 3, BOOL) == 0
        assert await scanner.read(0x70, 1, 4, SHORT_STRING) == "FC-10 North"
        assert await scanner.read(0x70, 2, 1, USINT) == 1
        await scanner.set_attribute_single(0x70, 1, 1, 300, UINT)
        assert await scanner.read(0x70, 1, 1, UINT) == 300
        with pytest.raises(CipError) as refused:
            await scanner.set_attribute_single(0x70, 1, 1, 501, UINT)  # Param1 maximum 500
        assert refused.value.general == GeneralStatus.INVALID_ATTRIBUTE_VALUE
        with pytest.raises(CipError) as refused:
            await scanner.set_attribute_single(0x70, 1, 2, 5, INT)  # descriptor bit 4: read only
        assert refused.value.general == GeneralStatus.ATTRIBUTE_NOT_SETTABLE
        with pytest.raises(CipError) as refused:
            await scanner.read(0x70, 2, 2)  # instance 2 declares attribute 1 only
        assert refused.value.general == GeneralStatus.ATTRIBUTE_NOT_SUPPORTED
        # Get_Attributes_All of instance 1: attributes 1-4 in order.
        data, _ = await scanner.get_attributes_all(0x70, 1)
        assert data == UINT.encode(300) + INT.encode(0) + BOOL.encode(0) + SHORT_STRING.encode("FC-10 North")


async def test_generic_assemblies_carry_the_parameters() -> None:
    async with serving(generic_device()) as (adapter, scanner):
        assert sorted(adapter.device.assembly.points) == [100, 101]  # the heartbeats are no instances
        # Input 101: Flow Actual, Flow Setpoint, Valve Open (bit 32), 15 bits of padding.
        assert await scanner.read(4, 101, 3) == INT.encode(0) + UINT.encode(120) + bytes(2)
        await scanner.set_attribute_single(0x70, 1, 3, 1, BOOL)
        assert await scanner.read(4, 101, 3) == INT.encode(0) + UINT.encode(120) + bytes([1, 0])
        # Output 100: Flow Setpoint, Valve Open (bit 16), Mode (byte 3).
        await scanner.set_attribute_single(4, 100, 3, UINT.encode(250) + bytes([0, 2]))
        assert await scanner.read(0x70, 1, 1, UINT) == 250
        assert await scanner.read(0x70, 1, 3, BOOL) == 0
        assert await scanner.read(0x70, 2, 1, USINT) == 2
        # A value the attribute refuses is not taken; the assembly keeps the bytes written.
        await scanner.set_attribute_single(4, 100, 3, UINT.encode(900) + bytes([1, 3]))
        assert await scanner.read(0x70, 1, 1, UINT) == 250
        assert (await scanner.read(0x70, 1, 3, BOOL), await scanner.read(0x70, 2, 1, USINT)) == (1, 3)
        assert await scanner.read(4, 100, 3) == UINT.encode(900) + bytes([1, 3])
        with pytest.raises(CipError) as refused:
            await scanner.set_attribute_single(4, 101, 3, bytes(6))  # an input is the device's
        assert refused.value.general == GeneralStatus.ATTRIBUTE_NOT_SETTABLE


async def test_each_generic_connection_opens_by_its_number() -> None:
    view = read_view(parse_eds(GENERIC_EDS))
    assert [(c.number, c.name, c.kind) for c in view.connections] == [
        (1, "Control", "exclusive owner"), (2, "Monitor", "input only"), (3, "Listen", "listen only")]
    doc = parse_eds(GENERIC_EDS)
    async with serving(generic_device()) as (adapter, scanner):
        assert adapter.io_endpoint is not None
        port = adapter.io_endpoint.port
        async with scanner.io_connection_from_eds(doc, 1, target_io_port=port) as control, \
                scanner.io_connection_from_eds(doc, "Connection2", target_io_port=port) as monitor:
            # Field names come from the parameters the members refer to.
            control.output.flow_setpoint = 420
            control.output.valve_open = True
            control.output.mode = 3
            await control.wait_input(lambda image: image.flow_setpoint == 420 and image.valve_open, timeout=5)
            await monitor.wait_input(lambda image: image.flow_setpoint == 420, timeout=5)
            assert await scanner.read(0x70, 2, 1, USINT) == 3
            # The RPI the file proposes: Param6's default, 20 ms; the heartbeat point 197.
            kinds = sorted((c.kind.value, c.ot_rpi_us, c.consumed.instance_id if c.consumed else None)
                           for c in adapter.io.connections.values())  # type: ignore[union-attr]
            assert kinds == [("exclusive owner", 20_000, 100), ("input only", 20_000, None)]
            # Listen only asks for the multicast production of input 101; the owner above
            # receives it point to point, so the target has nothing to share (0x0119).
            with pytest.raises(CipError) as refused:
                async with scanner.io_connection_from_eds(doc, 3, target_io_port=port):
                    pass
            assert refused.value.extended[:1] == (ExtendedStatus.NON_LISTEN_ONLY_NOT_OPENED,)
        # The RPI range of Param6: 1 ms is below its 2 ms minimum.
        with pytest.raises(CipError) as refused:
            async with scanner.io_connection_from_eds(doc, "Control", rpi=0.001, target_io_port=port):
                pass
        assert refused.value.extended[:1] == (ExtendedStatus.RPI_VALUE_NOT_ACCEPTABLE,)
        with pytest.raises(KeyError, match="no class 1 connection 4"):
            async with scanner.io_connection_from_eds(doc, 4, target_io_port=port):
                pass


# -- what cannot be served ----------------------------------------------------------------------------------

def test_broken_constructs_are_warnings() -> None:
    device = build_eds_device(parse_eds(BROKEN_EDS), INTERFACE)
    messages = [issue.message for issue in device.issues]
    assert len(messages) == len(BROKEN_WARNINGS)
    for (keyword, fragment), message in zip(BROKEN_WARNINGS, messages, strict=True):
        assert fragment in message, (keyword, message)
    lines = BROKEN_EDS.splitlines()
    for (keyword, _), issue in zip(BROKEN_WARNINGS, device.issues, strict=True):
        assert keyword in lines[issue.line - 1], (keyword, issue)  # each warning names its line
    # What is left is served: the good parameter, its default, assemblies 101/103 and one pair.
    assert device.identity_info.product_code == 0 and device.identity_info.product_name == "Broken"
    obj = device.router.objects[0x70]
    assert obj.get(1, 1) == 5 and obj.get(1, 5) == 0
    assert sorted(device.assembly.points) == [101, 103]
    offer = device.io_profile()
    assert offer is not None and offer.pairs is not None and offer.pairs() == {(101, 103)}


def test_no_device_section_is_no_eds() -> None:
    with pytest.raises(EdsDeviceError, match=r"no \[Device\] section"):
        build_eds_device(parse_eds("[File]\n    DescText = \"nothing\";\n"))
