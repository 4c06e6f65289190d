"""The ``power-cycle`` fault is a whole power loss for every device family, seen from outside over
loopback: the originator's class 1 connection times out and its TCP session is gone, the run stops
(0 Hz), a parameter written and not saved is lost, a saved one is back, and a trip does what the
family's manual says of it.

* MX2 and RX with the CompoNet option board (CompoNet manual): section E-2-2 note (written values live in
  the inverter's memory until the ENTER command, 0900h = 1, stores them in EEPROM); Table 25 Step II
  (power OFF and ON restarts after a trip); section 5-1-1 Tip (the trip history keeps the trip, d081).
  The option board's Identity Reset restarts the board alone, not the inverter: a power cycle is more.
* ACG (the ACG-ET2 and ACG RS-485 manuals): the memory control area 0x03E0-0x03EC saves what it sets.
* A device emulated from an EDS keeps nothing it was told.

The fault is applied from Python here, from the command line and over HTTP in the tests that start
the emulator as ``cipstack adapter`` (pycomm3 reads the parameters back there)."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.catalog import Catalog
from cipstack.cip.types import UDINT as CIP_UDINT
from cipstack.cip.types import UINT as CIP_UINT
from cipstack.cip.types import USINT as CIP_USINT
from cipstack.devices.acg.device import build_acg_device
from cipstack.devices.acg.drive import AcgDrive, Trip
from cipstack.devices.acg.registers import ACG_REGISTERS
from cipstack.devices.omron.device import GATEWAY_OUT_AREA, OmronDevice, build_componet_gateway
from cipstack.devices.omron.inverter import Inverter
from cipstack.devices.omron.registers import function_code_path
from cipstack.devices.profiles import catalog_for
from cipstack.eds.emulated_device import build_eds_device
from cipstack.eds.reader import parse_eds
from cipstack.eip.originator.io_originator import IoTimeoutError
from cipstack.eip.target.io_target import IoConnection
from cipstack.scanner import Scanner
from tests.eds.samples import GENERIC_EDS
from tests.optional import needs
from tests.ports import refused
from tests.waiting import wait_until

MX2 = "MX2-A2015-E"
RX = "RX-A4055-E"

#: Function Code object (class 0x65, Table E-3): the RX's registers have no Modbus address in this
#: manual, its function codes are its way in. The ENTER command is the Modbus Register object's
#: (class 0x64, section E-3-2): write 01h to 0900h, instance 09h attribute 00h (section E-2-2 note).
F002 = function_code_path("F002")      # acceleration time 1, 0.01 s
F003 = function_code_path("F003")      # deceleration time 1
D081 = function_code_path("d081")      # trip monitor 1: the latest trip
ENTER = (0x09, 0x00)
SAVED_ACCEL = 50           # 0.50 s: saved
UNSAVED_DECEL = 360000     # 3600.00 s, the longest: written, not saved
DEFAULT_DECEL = 1000       # 10.00 s (Table D-7)
ACG_CATALOG = catalog_for(259, 100)
#: A power-cycle's off period for the tests that check what happens while the power is off: longer than
#: a loaded machine may stall a test, and ended by clearing the fault (as the fault allows) once checked.
LONG_OFF = "30s"


async def o_t_packets(connection: IoConnection, count: int) -> None:
    """Until ``count`` more O->T packets reached the device's class 1 ``connection``: what it does with
    them is judged on data that did arrive, not on how long the test slept."""
    since = connection.stats.received
    await wait_until(lambda: connection.stats.received - since >= count, 5, f"{count} O->T packets")


def catalog(device: OmronDevice) -> Catalog:
    return Catalog(device.catalog_classes(), device.schemas().values())


@pytest.fixture(params=[MX2, RX])
async def omron(request: pytest.FixtureRequest, tmp_path: Path) -> AsyncIterator[Adapter]:
    model = request.param
    adapter = Adapter(AdapterSettings(port=0, io_port=0, profile="rx" if model.startswith("RX") else "mx2", model=model,
                                      state_path=tmp_path / "state.json"))
    await adapter.start()
    yield adapter
    await adapter.faults.settle()
    await adapter.close()


async def connect(adapter: Adapter) -> Scanner:
    assert isinstance(adapter.device, OmronDevice)
    return await Scanner.connect(f"127.0.0.1:{adapter.port}", catalog=catalog(adapter.device), timeout=2.0)


async def one_saved_one_not(scanner: Scanner) -> None:
    """F002 written and saved by the ENTER command, then F003 written and not saved."""
    await scanner.set_attribute_single(0x65, *F002, SAVED_ACCEL, CIP_UDINT)
    await scanner.set_attribute_single(0x64, *ENTER, 1, CIP_UINT)
    await scanner.set_attribute_single(0x65, *F003, UNSAVED_DECEL, CIP_UDINT)
    assert await scanner.read(0x65, *F003, CIP_UDINT) == UNSAVED_DECEL


async def test_power_cycle_is_the_whole_inverter_losing_power(omron: Adapter) -> None:
    """Before, the fault restarted the option board alone (its Identity Reset, Table C-1): the unsaved
    F003 stayed and the inverter went on decelerating over it, at 10 Hz still after the power was back."""
    assert omron.io_endpoint is not None
    async with await connect(omron) as scanner:
        await one_saved_one_not(scanner)
        async with scanner.io_connection(output=21, input=71, rpi=0.01, timeout_multiplier=5,
                                         target_io_port=omron.io_endpoint.port) as io:
            io.output.update(net_ctrl=True, net_ref=True, speed_reference=1000)
            await io.wait_input(lambda i: i.ctrl_from_net and i.ready, timeout=5)
            io.output.run_forward = True
            image = await io.wait_input(lambda i: i.at_reference and i.speed_actual == 1000, timeout=5)
            assert image.running_forward
            # Off until cleared (LONG_OFF): what must happen while the power is off cannot find it back on.
            omron.fault("power-cycle", off=LONG_OFF)
            await wait_until(lambda: refused(omron.port), 5, "the port to close")  # no power: nothing answers
            with pytest.raises(IoTimeoutError):                               # the originator's connection
                async for _ in io.updates():
                    pass
            with pytest.raises((ConnectionError, OSError, asyncio.TimeoutError, TimeoutError)):
                await scanner.read(0x01, 1, 1)                                # its session went with the power
    assert not omron.runtime.power.powered                                    # all of it while off
    omron.clear_faults("power-cycle")
    await omron.faults.settle()
    assert omron.io is not None and not omron.io.connections
    async with await connect(omron) as scanner:
        assert await scanner.read(0x65, *F002, CIP_UDINT) == SAVED_ACCEL      # saved: back from EEPROM
        assert await scanner.read(0x65, *F003, CIP_UDINT) == DEFAULT_DECEL    # not saved: lost
        assert await scanner.read(0x2A, 1, 7) == 0                            # Speed Actual: 0
        assert await scanner.read(0x29, 1, 7) == 0                            # Running1: the run stopped
        assert await scanner.read(0x29, 1, 6) == 3                            # Drive State: Ready
        assert await scanner.read(0x29, 1, 0x0F) == 0                         # CtrlFromNet: Net Ctrl forgotten
        assert await scanner.read(0x01, 1, 5) == 0x0001                       # Table C-2: as at power-on
        assert await scanner.read(0x01, 1, 9) == 1                            # one save counted, in EEPROM
        # Table B-2 note: after power-on the run bit acts on a rising edge only: held at 1, nothing runs.
        async with scanner.io_connection(output=21, input=71, rpi=0.01, timeout_multiplier=5,
                                         target_io_port=omron.io_endpoint.port) as io:
            assert omron.io is not None
            [consuming] = omron.io.connections.values()
            io.output.update(net_ctrl=True, net_ref=True, speed_reference=1000, run_forward=True)
            await io.wait_input(lambda i: i.ctrl_from_net, timeout=5)
            await o_t_packets(consuming, 10)                                  # the bit held at 1 all along
            assert not io.input.running_forward
            io.output.run_forward = False
            await o_t_packets(consuming, 3)                                   # a few packets with the bit at 0
            io.output.run_forward = True
            await io.wait_input(lambda i: i.at_reference, timeout=5)          # 0.5 s ramp: F002 as saved


async def test_a_trip_is_cleared_by_the_power_cycle_and_kept_in_the_trip_history(omron: Adapter) -> None:
    """Table 25 Step II: "Power OFF and ON" restarts after a trip; section 5-1-1 Tip: the trip history
    still has it (d081, the latest trip). Before, the option board restarted alone and an inverter trip
    (E05 here, Table D-5) stayed."""
    omron.control({"command": "trip", "code": "E05"})                        # what `cipstack drive trip` does
    async with await connect(omron) as scanner:
        assert await scanner.read(0x29, 1, 0x0A) == 1                         # Faulted
        omron.fault("power-cycle")
    await omron.faults.settle()
    async with await connect(omron) as scanner:
        assert await scanner.read(0x29, 1, 0x0A) == 0                         # no trip after power-on
        assert await scanner.read(0x29, 1, 0x0D) == 0                         # Fault Code
        assert await scanner.read(0x65, *D081, CIP_UINT) == 5                 # the trip history keeps it


async def test_power_cycle_over_http(tmp_path: Path) -> None:
    """``POST /faults`` with ``power-cycle``: the reply comes once the power is back; the MX2 run by
    explicit messages (Control Supervisor Run1, section 4-5) is stopped, its unsaved sources are lost."""
    aiohttp = needs("aiohttp")
    adapter = Adapter(AdapterSettings(port=0, io_port=0, profile="mx2", model=MX2, state_path=tmp_path / "mx2.json",
                                      control_path=tmp_path / "control.sock", http="127.0.0.1:0"))
    await adapter.start_serving()
    try:
        async with await connect(adapter) as scanner:
            for code in ("A001", "A002"):                                    # Option Board Interface, not saved
                await scanner.set_attribute_single(0x65, *function_code_path(code), 4, CIP_UINT)
            await scanner.set_attribute_single(0x2A, 1, 8, 1000)              # Speed Ref 10.00 Hz
            await scanner.set_attribute_single(0x29, 1, 3, 1)                 # Run1
            while await scanner.read(0x2A, 1, 3) != 1:                        # At Reference
                await asyncio.sleep(0.02)
        async with aiohttp.ClientSession() as session:
            base = f"http://127.0.0.1:{adapter.http_api.port}"
            body = {"name": "power-cycle", "options": {"off": "100ms"}}
            async with session.post(base + "/faults", json=body) as reply:
                assert reply.status == 201 and (await reply.json())["name"] == "power-cycle"
            async with session.get(base + "/status") as reply:
                drive = (await reply.json())["drive"]
            assert (drive["state"], drive["output_frequency_hz"], drive["trip"]) == ("ready", 0.0, None)
        async with await connect(adapter) as scanner:
            assert await scanner.read(0x65, *function_code_path("A002"), CIP_UINT) == 1   # the default again
            assert await scanner.read(0x29, 1, 7) == 0
    finally:
        await adapter.stop_serving()


async def test_the_board_starts_its_connection_object_afresh(omron: Adapter) -> None:
    """Table C-8: the Connection object's settable attributes are at their defaults after power-on."""
    async with await connect(omron) as scanner:
        await scanner.set_attribute_single(0x05, 1, 0x09, 50, CIP_UINT)       # expected packet rate
        await scanner.set_attribute_single(0x05, 1, 0x0C, 1, CIP_USINT)       # watchdog timeout action
        omron.fault("power-cycle")
    await omron.faults.settle()
    async with await connect(omron) as scanner:
        assert await scanner.read(0x05, 1, 0x09, CIP_UINT) == 0
        assert await scanner.read(0x05, 1, 0x0C, CIP_USINT) == 0


def test_a_saved_cause_trips_again_at_power_on_and_an_unsaved_fix_is_lost() -> None:
    """Appendix F Note 5: an illegal flexible mapping trips E64 at the board's start, power-on included.
    The power cycle clears the trip (Table 25 Step II) but not its cause, if the cause is saved."""
    inverter = Inverter(MX2)
    for code, value in (("P046", 6), ("P160", 0x1F01), ("P170", 0x1E01), ("P168", 1)):   # P168 must be 0
        inverter.write_code(code, value, 0.0)
    inverter.write(0x0900, 1, 0.0)                                            # ENTER
    inverter.power_cycle(1.0)
    assert inverter.trip == 64 and inverter.read_code("d081") == 64
    inverter.write_code("P168", 0, 1.0)                                       # the fix, not saved
    inverter.power_cycle(2.0)
    assert inverter.trip == 64
    inverter.write_code("P168", 0, 2.0)
    inverter.write(0x0900, 1, 2.0)
    inverter.power_cycle(3.0)
    assert inverter.trip == 0 and inverter.flexible is not None and inverter.read_code("d081") == 64


def test_the_option_boards_reset_is_not_a_power_cycle() -> None:
    """Table C-1: the Identity Reset returns the option board to its initial status; the inverter behind
    it keeps its power, what it was told, and its motor decelerating on the ramp."""
    inverter = Inverter(MX2)
    inverter.write_code("A002", 4, 0.0)
    inverter.write_code("A001", 4, 0.0)
    inverter.write_code("F003", UNSAVED_DECEL, 0.0)
    inverter.command(0.0, speed_reference=1000)
    inverter.command(0.0, fwd=True)
    inverter.advance(20.0)
    inverter.reset_option_board(20.0)
    assert inverter.read_code("F003") == UNSAVED_DECEL and inverter.status().running
    inverter.power_cycle(20.0)
    assert inverter.read_code("F003") == DEFAULT_DECEL and not inverter.status().running
    assert inverter.status().output_frequency == 0


# -- the ACG -----------------------------------------------------------------------------------------------

ON_DAYS, RUN_DAYS, FAN_DAYS = 0x0340, 0x0342, 0x0344
DAY = 86400.0


def test_acg_keeps_what_its_memory_control_area_saves() -> None:
    """ACG RS-485 manual, drive memory control area: "the values are reflected to the drive operation and saved":
    the accumulated times (0x0340-0x0345, initialized by 0x03EB/0x03EC), the fault history (deleted by
    0x03E5) and the parameter lock (0x03E8). The trip present goes; the fault history keeps it.
    Before, a power cycle started every count from 0, unlocked the parameters and forgot the history."""
    device = build_acg_device(now=0.0)
    device.drive = drive = AcgDrive(now=0.0, password=1234)
    drive.write(ACG_REGISTERS.by_code("drv").address, 4, 0.0)                 # run command: Field Bus
    drive.set_run_command(True, False, 0.0)
    device.advance(1.5 * DAY)
    drive.set_run_command(False, False, 1.5 * DAY)
    drive.write(0x03E8, 1234, 1.5 * DAY)                                      # the password locks the parameters
    assert drive.read(0x03E8) == 1
    device.inject_trip(Trip.OVER_HEAT)
    device.advance(2 * DAY)
    assert (drive.read(ON_DAYS), drive.read(RUN_DAYS), drive.read(FAN_DAYS)) == (2, 1, 1)
    device.power_cycle(2 * DAY)
    drive = device.drive
    assert (drive.read(ON_DAYS), drive.read(RUN_DAYS), drive.read(FAN_DAYS)) == (2, 1, 1)
    assert drive.read(0x03E8) == 1                                            # still locked
    assert drive.trip is None and drive.fault_history == [Trip.OVER_HEAT]
    device.advance(3 * DAY)
    assert drive.read(ON_DAYS) == 3


async def test_acg_power_cycle_stops_the_run_and_loses_the_unsaved(tmp_path: Path) -> None:
    """ACG RS-485 manual: "Parameter SET via Communications + NOT Saved + Power Cycle = Parameters reverts back";
    the output is cut: the drive does not decelerate over a ramp, it has no power."""
    adapter = Adapter(AdapterSettings(port=0, io_port=0, state_path=tmp_path / "acg.json"))
    # Written as over communication (--param-unsaved): a keypad entry would be kept (test_keypad.py).
    adapter.apply_keypad_parameters(["drv=4", "Frq=8"], kept=False)
    await adapter.start()
    assert adapter.io_endpoint is not None
    try:
        async with await Scanner.connect(f"127.0.0.1:{adapter.port}", catalog=ACG_CATALOG, timeout=2.0) as scanner:
            await scanner.set_attribute_single(0x2A, 1, 102, 5)               # ACC 0.5 s
            await scanner.set_attribute_single(0x2A, 1, 103, 999)             # dEC 99.9 s; neither saved
            async with scanner.io_connection(output=21, input=71, rpi=0.01, timeout_multiplier=5,
                                             target_io_port=adapter.io_endpoint.port) as io:
                io.output.update(speed_reference=1800, run_forward=True)
                await io.wait_input(lambda i: i.at_reference, timeout=5)
                adapter.fault("power-cycle", off=LONG_OFF)
                with pytest.raises(IoTimeoutError):
                    async for _ in io.updates():
                        pass
        assert not adapter.runtime.power.powered                              # timed out while off
        adapter.clear_faults("power-cycle")
        await adapter.faults.settle()
        async with await Scanner.connect(f"127.0.0.1:{adapter.port}", catalog=ACG_CATALOG, timeout=2.0) as scanner:
            assert await scanner.read(0x2A, 1, 7) == 0                        # SpeedActual 0: stopped at once
            assert await scanner.read(0x29, 1, 7) == 0                        # Running1
            assert await scanner.read(0x2A, 1, 103) != 999                    # dEC not saved: lost
            assert await scanner.read(0x29, 1, 14) == 0                       # CtrlFromNet: drv = 4 not saved
    finally:
        await adapter.faults.settle()
        await adapter.close()


async def test_acg_comm_update_saves_the_cm_group_and_nothing_else(tmp_path: Path) -> None:
    """ACG-ET2 manual, Comm Update (CM.94): after changes to CM.7 and CM.10-CM.25, "you must set CM.94
    ... to save the changes"; what saves every parameter is 0x03E0 (ACG RS-485 manual, "Saving Parameters
    Defined by Communication"). Over CIP: CM.23 and ACC written, CM.94 = 1, a power cycle: CM.23 is kept,
    ACC is lost (docs/emulator/acg.md, "Saving parameters")."""
    adapter = Adapter(AdapterSettings(port=0, io_port=0, state_path=tmp_path / "acg.json"))
    await adapter.start()
    try:
        async with await Scanner.connect(f"127.0.0.1:{adapter.port}", catalog=ACG_CATALOG, timeout=2.0) as scanner:
            assert await scanner.read(0x2A, 1, 102) == 50                     # ACC 5.0 s from the factory
            await scanner.set_attribute_single(0x2A, 1, 102, 75)              # ACC 7.5 s, not saved by CM.94
            await scanner.set_attribute_single(0x64, 7, 23, 3)                   # CM.23 = 3 (input 111)
            await scanner.set_attribute_single(0x64, 7, 94, 1)                   # CM.94 Comm Update
        adapter.fault("power-cycle", off=LONG_OFF)
        await wait_until(lambda: refused(adapter.port), 5, "the port to close")
        adapter.clear_faults("power-cycle")
        await adapter.faults.settle()
        async with await Scanner.connect(f"127.0.0.1:{adapter.port}", catalog=ACG_CATALOG, timeout=2.0) as scanner:
            assert await scanner.read(0x64, 7, 23) == 3                       # the CM group: saved
            assert await scanner.read(0x2A, 1, 102) == 50                     # ACC: lost
    finally:
        await adapter.faults.settle()
        await adapter.close()


# -- a device emulated from an EDS ---------------------------------------------------------------------------

async def test_an_eds_device_keeps_nothing_it_was_told() -> None:
    """An EDS says nothing of non-volatile memory: every parameter is back at its default (before, the
    written values stayed)."""
    adapter = Adapter(AdapterSettings(port=0, io_port=0), device=build_eds_device(parse_eds(GENERIC_EDS)))
    await adapter.start()
    try:
        async with await Scanner.connect(f"127.0.0.1:{adapter.port}", timeout=2.0) as scanner:
            await scanner.set_attribute_single(0x70, 1, 1, 300, CIP_UINT)    # Flow Setpoint, default 120
            await scanner.set_attribute_single(0x70, 2, 1, 3, CIP_USINT)     # Mode, default 1
            adapter.fault("power-cycle")
        await adapter.faults.settle()
        async with await Scanner.connect(f"127.0.0.1:{adapter.port}", timeout=2.0) as scanner:
            assert await scanner.read(0x70, 1, 1, CIP_UINT) == 120
            assert await scanner.read(0x70, 2, 1, CIP_USINT) == 1
            assert await scanner.read(0x01, 1, 1, CIP_UINT) == 1234           # the identity is the device's
    finally:
        await adapter.close()


def test_the_componet_gateway_restarts_its_master_and_not_its_slaves() -> None:
    """The gateway's master comes back idle with a zero OUT area, as it started; the slave inverter keeps
    its power and takes the idle cycles as a master in idle mode: P048 = 0 trips E63 (Table 12, Table 26)."""
    gateway = build_componet_gateway([("mx2", MX2, 3)])
    gateway.advance(0.0)
    area = bytearray(128)
    area[6:10] = bytes.fromhex("60 00 e8 03")                                 # node 3: CTR, REF, 10.00 Hz
    gateway.assembly.deliver(GATEWAY_OUT_AREA, bytes(area), 0.1)
    gateway.advance(0.2)
    area[6] = 0x61                                                            # FWD
    gateway.assembly.deliver(GATEWAY_OUT_AREA, bytes(area), 0.2)
    gateway.advance(0.3)                                                      # the next cycle carries FWD
    gateway.advance(20.0)
    inverter = gateway.slave(3).inverter
    assert inverter.status().at_reference
    gateway.power_cycle(20.0)
    assert gateway.assembly.data(GATEWAY_OUT_AREA) == bytes(128) and not gateway.network.run
    gateway.advance(20.1)
    assert inverter.trip == 63


async def test_a_device_without_power_takes_no_trip_no_keypad_write_and_no_second_power_cycle(
        tmp_path: Path) -> None:
    """While the power is off (``off``), nothing reaches the device: a trip, a keypad write and another
    power cycle are refused with the reason; once the power is back each is taken again."""
    aiohttp = needs("aiohttp")
    from cipstack.devices.keypad import WriteRefused
    from cipstack.errors import StateRefused
    from cipstack.faults import FaultStateError

    adapter = Adapter(AdapterSettings(port=0, io_port=0, state_path=tmp_path / "acg.json",
                                      control_path=tmp_path / "control.sock", http="127.0.0.1:0"))
    await adapter.start_serving()
    status = f"http://127.0.0.1:{adapter.http_api.port}/status"
    try:
        async with aiohttp.ClientSession() as session:
            async with session.get(status) as reply:
                assert (await reply.json())["power"] == "on"
            adapter.faults.apply("power-cycle", off=LONG_OFF)
            async with session.get(status) as reply:
                assert (await reply.json())["power"] == "off"
        with pytest.raises(StateRefused, match="powered off"):
            adapter.control({"command": "trip", "code": "OverHeat"})
        with pytest.raises(WriteRefused, match="powered off"):
            adapter.set_keypad_parameter("ACC", "2.5")
        with pytest.raises(FaultStateError, match="powered off already"):
            adapter.faults.apply("power-cycle")
        adapter.faults.clear("power-cycle")
        await adapter.faults.settle()
        assert adapter.set_keypad_parameter("ACC", "2.5")["raw"] == 25
        assert adapter.control({"command": "trip", "code": "OverHeat"})["trip"] == "OverHeat"
    finally:
        await adapter.faults.settle()
        await adapter.stop_serving()
