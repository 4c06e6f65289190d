"""ACG-ET2 assemblies: the bytes of the ACG-ET2 manual's input/output instance tables for known drive states."""

from __future__ import annotations

import pytest

from cipstack.devices.acg.assemblies import INPUT_INSTANCES, OUTPUT_INSTANCES, assembly_size, parameter_words
from cipstack.devices.acg.device import AcgDevice, build_acg_device
from cipstack.devices.acg.drive import Trip
from cipstack.devices.acg.registers import ACG_REGISTERS
from cipstack.devices.acg.status_words import OperationStatus


def addr(code: str) -> int:
    return ACG_REGISTERS.by_code(code).address


DRV, FRQ, ACC = addr("drv"), addr("Frq"), addr("ACC")


@pytest.fixture
def device() -> AcgDevice:
    """Run and reference from the network (drv = 4, Frq = 8); ACC 5.0 s / dEC 10.0 s to 60 Hz, 4 poles."""
    dev = build_acg_device(now=0.0)
    dev.drive.write(DRV, 4, 0.0)
    dev.drive.write(FRQ, 8, 0.0)
    return dev


def data(device: AcgDevice, instance: int, now: float) -> bytes:
    device.advance(now)
    return device.assembly.data(instance)


def test_sizes_follow_the_cm23_cm24_tables() -> None:
    # "Data Size": 4 bytes for 20/21/100/101 and 70/71/110/111, 2 x "Parameter Number" for the others.
    assert [assembly_size(i) for i in OUTPUT_INSTANCES] == [4, 4, 4, 4, 2, 4, 6, 8, 10, 12, 14, 16]
    assert [assembly_size(i) for i in INPUT_INSTANCES] == [4, 4, 4, 4, 2, 4, 6, 8, 10, 12, 14, 16]
    assert [parameter_words(i) for i in (121, 128, 141, 148, 20, 71)] == [1, 8, 1, 8, 0, 0]


def test_output_bit_layouts(device: AcgDevice) -> None:
    # Instance 21/101 byte 0: bit 0 Run Fwd, 1 Run Rev, 2 Fault reset, 5 NetCtrl, 6 NetRef; byte 1 is 0.
    s21, s101 = device.assembly_schema(21), device.assembly_schema(101)
    everything = dict(run_forward=1, run_reverse=1, fault_reset=1, net_ctrl=1, net_ref=1)
    assert s21.encode(everything, speed_reference=1800) == bytes.fromhex("67000807")
    assert s101.encode(everything, speed_reference=6000) == bytes.fromhex("67007017")
    # Instance 20/100: bit 0 Run Fwd, bit 2 Fault reset only.
    assert device.assembly_schema(20).encode(run_forward=1, fault_reset=1, speed_reference=900) == bytes.fromhex(
        "05008403")
    # A reference in Hz reaches 400.00 Hz: the word is unsigned like the drive's frequency registers.
    assert device.assembly_schema(100).encode(speed_reference=40000) == bytes.fromhex("0000409c")
    assert device.assembly_schema(100).field("speed_reference").scale == 0.01
    assert device.assembly_schema(20).field("speed_reference").unit == "rpm"
    for instance in OUTPUT_INSTANCES + INPUT_INSTANCES:
        schema = device.assembly_schema(instance)
        sample = bytes(range(1, schema.size + 1))
        if instance in (20, 21, 100, 101, 70, 71, 110, 111):
            sample = schema.encode(schema.decode(sample))
        assert schema.encode(schema.decode(sample)) == sample


def test_inputs_when_ready(device: AcgDevice) -> None:
    # Ready (bit 4), Drive State 3 "Ready", speed 0; Ctrl/Ref From Net (bits 5, 6) from drv/Frq.
    assert data(device, 70, 0.0) == bytes.fromhex("00000000")
    assert data(device, 71, 0.0) == bytes.fromhex("70030000")
    device.drive.write(DRV, 1, 0.0)
    device.drive.write(FRQ, 0, 0.0)
    assert data(device, 71, 0.0) == bytes.fromhex("10030000")
    assert data(device, 111, 0.0) == bytes.fromhex("10030000")


def test_inputs_accelerating_then_at_reference(device: AcgDevice) -> None:
    device.drive.set_speed_reference(3000, 0.0)        # 30.00 Hz = 900 rpm with 4 poles
    device.drive.set_run_command(True, False, 0.0)
    # 1.25 s into a 5 s ramp to 60 Hz: 15.00 Hz (450 rpm), Enabled (4), not At Reference.
    assert data(device, 71, 1.25) == bytes.fromhex("7404c201")
    assert data(device, 111, 1.25) == bytes.fromhex("7404dc05")
    assert data(device, 70, 1.25) == bytes.fromhex("0400c201")
    # 2.5 s: 30.00 Hz reached: At Reference (bit 7).
    assert data(device, 71, 3.0) == bytes.fromhex("f4048403")
    assert data(device, 110, 3.0) == bytes.fromhex("0400b80b")
    assert data(device, 111, 3.0) == bytes.fromhex("f404b80b")


def test_inputs_reverse_stopping_and_fault(device: AcgDevice) -> None:
    device.drive.set_speed_reference(3000, 0.0)
    device.drive.set_run_command(False, True, 0.0)
    assert data(device, 71, 3.0) == bytes.fromhex("f8048403")  # Running2 (bit 3), not Running1
    assert data(device, 70, 3.0) == bytes.fromhex("00008403")
    device.drive.set_run_command(False, False, 3.0)           # decelerate: 10 s per 60 Hz
    assert data(device, 71, 5.5) == bytes.fromhex("7805c201")  # Stopping (5) at 15 Hz
    device.drive.set_run_command(True, False, 10.0)
    device.advance(20.0)
    device.inject_trip(Trip.OVER_HEAT)
    # Faulted (bit 0), not Ready, Drive State 6 "Fault Stop", output cut.
    assert data(device, 71, 20.0) == bytes.fromhex("61060000")
    assert data(device, 70, 20.0) == bytes.fromhex("01000000")


def test_status_parameter_inputs(device: AcgDevice) -> None:
    # CM.31-CM.33 default to 0x000A output frequency, 0x000E operation status, 0x000F fault information.
    assert [f.name for f in device.assembly_schema(143).fields] == [
        "output_frequency", "operation_status", "fault_trip_information"]
    device.drive.set_speed_reference(3000, 0.0)
    device.drive.set_run_command(True, False, 0.0)
    status = (OperationStatus.FORWARD | OperationStatus.SPEED_REACHED | OperationStatus.FORWARD_COMMAND
              | OperationStatus.COMMAND_FROM_COMMUNICATION | OperationStatus.FREQUENCY_FROM_COMMUNICATION)
    assert int(status) == 0x6842
    assert data(device, 143, 3.0) == bytes.fromhex("b80b" "4268" "0000")
    assert data(device, 141, 3.0) == bytes.fromhex("b80b")
    assert device.assembly_schema(143).decode(data(device, 143, 3.0))["output_frequency"] == 3000
    # Naming another register in CM.31 changes the word and the field (name, scale, unit).
    device.drive.write(addr("CM.31"), ACC, 3.0)
    schema = device.assembly_schema(142)
    assert [(f.name, f.scale, f.unit) for f in schema.fields] == [("acc", 0.1, "s"), ("operation_status", 1.0, "")]
    assert data(device, 142, 3.0) == bytes.fromhex("3200" "4268")


def test_speed_outputs_command_the_drive(device: AcgDevice) -> None:
    device.assembly.deliver(21, bytes.fromhex("01008403"), 0.0)   # Run Fwd, 900 rpm
    assert device.drive.read(0x0380) == 3000 and device.drive.running_forward
    device.advance(3.0)
    assert device.drive.at_reference
    device.assembly.deliver(101, bytes.fromhex("0200b80b"), 3.0)  # Run Rev, 30.00 Hz: Drive Run row "1 -> 0, 1"
    assert device.drive.control_supervisor.run_reverse and device.drive.decelerating
    device.assembly.deliver(100, bytes.fromhex("0000d007"), 4.0)  # stop, 20.00 Hz
    assert device.drive.read(0x0380) == 2000 and device.drive.control_supervisor.run_forward is False


def test_fault_reset_bit_acts_on_0_to_1_only(device: AcgDevice) -> None:
    device.assembly.deliver(20, bytes.fromhex("01008403"), 0.0)
    device.advance(1.0)
    device.inject_trip(0x4200)
    device.assembly.deliver(20, bytes.fromhex("05008403"), 1.0)   # Fault reset 0 -> 1: reset
    assert not device.drive.faulted
    device.inject_trip(Trip.OVER_HEAT)
    device.assembly.deliver(20, bytes.fromhex("05008403"), 1.5)   # held at 1: no reset
    assert device.drive.faulted
    device.assembly.deliver(20, bytes.fromhex("01008403"), 2.0)
    device.assembly.deliver(20, bytes.fromhex("05008403"), 2.0)
    assert not device.drive.faulted
    assert not device.drive.running  # a held run bit does not restart the drive


def test_control_parameter_outputs(device: AcgDevice) -> None:
    # CM.51 = 0x0005 target frequency, CM.52 = 0x0006 operation command (B1: forward).
    assert [f.name for f in device.assembly_schema(122).fields] == ["target_frequency", "operation_command_option"]
    device.assembly.deliver(122, bytes.fromhex("b80b" "0200"), 0.0)
    assert device.drive.read(0x0005) == 3000 and device.drive.running_forward
    device.advance(3.0)
    assert device.drive.output_frequency == 3000
    device.assembly.deliver(122, bytes.fromhex("d007" "0200"), 3.0)  # only the changed word is written
    assert device.drive.read(0x0380) == 2000
    device.assembly.deliver(121, bytes.fromhex("e803"), 3.0)
    assert device.drive.read(0x0380) == 1000
    device.assembly.deliver(122, bytes.fromhex("e803" "0100"), 3.0)  # B0: stop
    assert device.drive.drive_state.name == "STOPPING"


def test_the_profile_catalog_is_the_device_s_own_declarations_without_building_one() -> None:
    """``cipstack get`` decodes by the ACG catalog, made from the declarations alone: the same classes
    and the same fixed assemblies (20/21/100/101, 70/71/110/111) a built device serves."""
    from cipstack.devices.profiles import PROFILES

    catalog = PROFILES["acg"].catalog()
    device = build_acg_device()
    assert sorted(catalog.assemblies) == [20, 21, 70, 71, 100, 101, 110, 111]
    for instance, schema in catalog.assemblies.items():
        served = device.assembly_schema(instance)
        assert (schema.name, schema.size, schema.fields) == (served.name, served.size, served.fields)
    for spec in device.catalog_classes():
        assert catalog.classes[spec.class_id] == spec


def test_the_same_output_data_again_overrides_what_was_written_in_between(device: AcgDevice) -> None:
    """A scanner sends the same output every RPI. Data unchanged on a drive nothing else changed is not
    applied again; a value written by other means in between (explicit messaging: class 0x2A
    attribute 8, class 0x29 attribute 3; a register write) is overridden by the next data, as always."""
    run_900 = bytes.fromhex("01008403")                          # Run Fwd, 900 rpm
    device.assembly.deliver(21, run_900, 0.0)
    device.assembly.deliver(21, run_900, 0.5)
    assert device.drive.speed_reference_rpm == 900 and device.drive.running_forward
    device.drive.set_speed_reference_rpm(1200, 1.0)              # SpeedRef written explicitly
    assert device.drive.speed_reference_rpm == 1200
    device.assembly.deliver(21, run_900, 1.0)
    assert device.drive.speed_reference_rpm == 900
    device.drive.set_run_forward(False, 1.5)                     # Run Fwd written explicitly: stop
    assert device.drive.control_supervisor.run_forward is False
    device.assembly.deliver(21, run_900, 1.5)                    # Run Fwd 0 -> 1 again: runs
    assert device.drive.control_supervisor.run_forward and device.drive.running_forward
    device.drive.write(0x0381, 600, 2.0)                         # the reference register over Modbus
    device.assembly.deliver(21, run_900, 2.0)
    assert device.drive.speed_reference_rpm == 900
    stop = bytes.fromhex("00008403")
    device.assembly.deliver(21, stop, 3.0)
    device.assembly.deliver(21, stop, 3.5)
    device.drive.set_run_forward(True, 4.0)                      # run by explicit messaging under a held stop
    assert device.drive.running_forward
    device.assembly.deliver(21, stop, 4.0)                       # the held stop stops it again
    assert not device.drive.control_supervisor.run_forward
    device.advance(30.0)
    assert not device.drive.running
