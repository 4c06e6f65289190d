"""The option board as the CompoNet manual's tables give it, over a real loopback connection: the status of an
instance that does not exist (Table E-5), the Identity attributes (Table C-2), the Connection
object's path lengths (Table C-8) and what an Identity Reset leaves (Table C-1)."""

from __future__ import annotations

import pytest

from cipstack.cip.messages import Service
from cipstack.cip.types import BOOL, INT
from cipstack.devices.omron.device import OmronDevice
from cipstack.devices.profiles import build_device
from cipstack.objects.identity import DeviceState
from cipstack.scanner import Scanner
from tests.library_support import serving

OBJECT_DOES_NOT_EXIST = 0x16
PATH_DESTINATION_UNKNOWN = 0x05
ATTRIBUTE_NOT_SUPPORTED = 0x14


async def status(scanner: Scanner, service: int, class_id: int, instance: int, attribute: int | None,
                 data: bytes = b"") -> int:
    return (await scanner.request(service, class_id, instance, attribute, data, check=False)).general_status


@pytest.mark.parametrize("profile", ["mx2", "rx"])
async def test_omron_missing_instance_is_0x16_in_every_object(profile: str) -> None:
    # Table E-5 (CompoNet manual): "16 Object does not exist: The specified Instance ID is not supported";
    # Identity and Assembly answered 0x05 where every other object answered 0x16.
    device = build_device(profile)
    async with serving(device) as (_, scanner):
        answers = {f"0x{class_id:02X}": await status(scanner, Service.GET_ATTRIBUTE_SINGLE, class_id, 0xC8, 1)
                   for class_id in sorted(device.router.objects)}
        assert set(answers.values()) == {OBJECT_DOES_NOT_EXIST}, answers
        assert await status(scanner, Service.SET_ATTRIBUTE_SINGLE, 0x04, 99, 3, bytes(4)) == OBJECT_DOES_NOT_EXIST
        assert await status(scanner, Service.RESET, 0x01, 2, None) == OBJECT_DOES_NOT_EXIST


async def test_acg_missing_instance_stays_cip_0x05() -> None:
    # ACG-ET2 manual gives no error table for its objects: CIP's 0x05 (path destination unknown) stands.
    device = build_device("acg")
    async with serving(device) as (_, scanner):
        answers = {f"0x{class_id:02X}": await status(scanner, Service.GET_ATTRIBUTE_SINGLE, class_id, 0xC8, 1)
                   for class_id in sorted(device.router.objects)}
        assert set(answers.values()) == {PATH_DESTINATION_UNKNOWN}, answers


@pytest.mark.parametrize("profile", ["mx2", "rx"])
async def test_omron_identity_serves_the_attributes_of_table_c2(profile: str) -> None:
    # Table C-2 (CompoNet manual): attributes 1-7, 9 and 65h; no 8 (State).
    device = build_device(profile)
    async with serving(device) as (_, scanner):
        for attribute in (1, 2, 3, 4, 5, 6, 7, 9, 0x65):
            assert await status(scanner, Service.GET_ATTRIBUTE_SINGLE, 0x01, 1, attribute) == 0, attribute
        assert await status(scanner, Service.GET_ATTRIBUTE_SINGLE, 0x01, 1, 8) == ATTRIBUTE_NOT_SUPPORTED
        # ListIdentity still carries a state: the board is operational.
        [record] = await scanner.list_identity()
        assert record.state == DeviceState.OPERATIONAL


@pytest.mark.parametrize("profile", ["mx2", "rx"])
async def test_omron_connection_path_lengths_count_the_bytes_of_the_path(profile: str) -> None:
    # Table C-8 (CompoNet manual): "Number of bytes for produced [consumed] connection path".
    device = build_device(profile)
    async with serving(device) as (_, scanner):
        for length, path in ((0x0D, 0x0E), (0x0F, 0x10)):
            served = (await scanner.request(Service.GET_ATTRIBUTE_SINGLE, 0x05, 1, path)).data
            assert served in (bytes.fromhex("20 04 24 47 30 03"), bytes.fromhex("20 04 24 15 30 03"))
            assert (await scanner.request(Service.GET_ATTRIBUTE_SINGLE, 0x05, 1, length)).data == bytes((6, 0))
        await scanner.request(Service.SET_ATTRIBUTE_SINGLE, 0x05, 1, 0x0E, bytes.fromhex("20 04 24 96"))
        assert (await scanner.request(Service.GET_ATTRIBUTE_SINGLE, 0x05, 1, 0x0D)).data == bytes((4, 0))


@pytest.mark.parametrize("profile", ["mx2", "rx"])
async def test_omron_identity_reset_returns_the_board_to_its_initial_status(profile: str) -> None:
    # Table C-1: "05 Reset (return to initial status)". Output assembly 21's data and the network's
    # control override (Net Ctrl 0x29/5, Net Ref 0x2A/4) are the board's, and do not survive it.
    device = build_device(profile)
    assert isinstance(device, OmronDevice)
    async with serving(device) as (_, scanner):
        await scanner.request(Service.SET_ATTRIBUTE_SINGLE, 0x29, 1, 5, b"\x01")         # Net Ctrl
        await scanner.request(Service.SET_ATTRIBUTE_SINGLE, 0x2A, 1, 4, b"\x01")         # Net Ref
        assembly_21 = bytes.fromhex("60 00 e8 03")                                         # CTR REF, 10.00 Hz
        await scanner.request(Service.SET_ATTRIBUTE_SINGLE, 0x04, 21, 3, assembly_21)
        assert (await scanner.request(Service.GET_ATTRIBUTE_SINGLE, 0x04, 21, 3)).data == assembly_21
        assert await scanner.read(0x29, 1, 0x0F, BOOL) == 1 and await scanner.read(0x2A, 1, 0x1D, BOOL) == 1
        await scanner.request(Service.RESET, 0x01, 1)
        assert (await scanner.request(Service.GET_ATTRIBUTE_SINGLE, 0x04, 21, 3)).data == bytes(4)
        assert await scanner.read(0x29, 1, 5, BOOL) == 0 and await scanner.read(0x2A, 1, 4, BOOL) == 0
        assert await scanner.read(0x29, 1, 0x0F, BOOL) == 0 and await scanner.read(0x2A, 1, 0x1D, BOOL) == 0
        assert await scanner.read(0x2A, 1, 8, INT) == 0                      # Speed Ref
