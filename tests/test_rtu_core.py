"""Modbus-RTU on the ACG drive's RS-485 port (ACG RS-485 manual, chapter 5), sans I/O: the chapter's worked
frames byte for byte, the framing by silences with timestamps, the checks a slave makes (CRC,
station, truncated, oversize, broadcast), the exception codes of the chapter's table, the
command-source and lost-command rules of the RS-485 source, and the virtual multi-function inputs."""

from __future__ import annotations

import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cipstack.devices.acg.drive import AcgDrive, Trip
from cipstack.devices.acg.modbus import ModbusTcpCore
from cipstack.devices.acg.modbus_rtu import LineSettings, RtuSlave, crc16, with_crc
from cipstack.devices.acg.registers import ACG_REGISTERS


def addr(code: str) -> int:
    return ACG_REGISTERS.by_code(code).address


def request(hex_text: str) -> bytes:
    """A request frame: the hex of its station, function and data, and its CRC."""
    return with_crc(bytes.fromhex(hex_text))


def write(station: int, address: int, value: int) -> bytes:
    """Function 0x06 to the register at communication ``address``: its "Modbus RTU" number is
    40000 + address, so its PDU address is address - 1 (ACG RS-485 manual)."""
    return with_crc(struct.pack(">BBHH", station, 6, address - 1, value))


def read(station: int, address: int, count: int = 1) -> bytes:
    return with_crc(struct.pack(">BBHH", station, 3, address - 1, count))


def serve(slave: RtuSlave, frame: bytes, now: float) -> bytes | None:
    """Hear ``frame`` at ``now`` and let the line stay silent: the reply, or None."""
    replies = slave.feed(frame, now)
    assert replies == []                 # a frame ends at the silence after it, never before
    deadline = slave.deadline()
    assert deadline is not None
    replies = slave.poll(deadline)
    assert len(replies) <= 1
    return replies[0].frame if replies else None


@pytest.fixture
def drive() -> AcgDrive:
    return AcgDrive(now=0.0)


@pytest.fixture
def slave(drive: AcgDrive) -> RtuSlave:
    return RtuSlave(drive)


def test_crc16_modbus_check_value() -> None:
    assert crc16(b"123456789") == 0x4B37


def test_the_chapters_worked_example_byte_for_byte(slave: RtuSlave, drive: AcgDrive) -> None:
    """ACG RS-485 manual, "Example of Modbus-RTU Communication in Use": multi-step acceleration time 1
    (0x1246) to 5.0 s and deceleration time 1 (0x1247) to 10.0 s with function 0x10 from starting
    address 0x1245 ("0x1246-1"), CRC 0x4324; the response ends in 0x5565."""
    frame = bytes.fromhex("01 10 1245 0002 04 0032 0064 4324")
    reply = serve(slave, frame, 0.0)
    assert reply == bytes.fromhex("01 10 1245 0002 5565")
    assert (addr("bA.70"), addr("bA.71")) == (0x1246, 0x1247)
    assert drive.read(0x1246) == 50 and drive.read(0x1247) == 100      # 5.0 s and 10.0 s


def test_a_reply_leaves_cm5_after_the_frame_ended(slave: RtuSlave) -> None:
    """From a serial device (its UART times the bytes): 9,600 bps D8/PN/S1, a character is 10 bits;
    the frame ends 3.5 characters after the read that held its last byte; the reply is due CM.5
    (5 ms) later, when the UART is to start sending it."""
    settings = slave.settings
    assert settings == LineSettings(station=1, baud=9600, data_bits=8, parity="N", stop_bits=1,
                                    response_delay=0.005)
    char = 10 / 9600
    assert slave.feed(read(1, 0x1F01), 1.0) == []
    assert slave.poll(1.0 + 3.4 * char) == []
    (reply,) = slave.poll(1.0 + 3.5 * char)
    assert reply.frame == request("01 03 02 0032")
    assert reply.due == pytest.approx(1.0 + 3.5 * char + 0.005)


def test_on_a_pty_the_slave_paces_request_and_reply_at_its_baud_rate(drive: AcgDrive) -> None:
    """A pty moves the 8 bytes of a request at once: the slave hears them as a 9,600 bps line would
    bring them (8 characters), ends the frame 3.5 characters later, and the 7-byte reply is due CM.5
    after that plus its own 7 characters on the line."""
    slave = RtuSlave(drive, paced=True)
    char = 10 / 9600
    assert slave.feed(read(1, 0x1F01), 1.0) == []
    assert slave.poll(1.0 + 11.4 * char) == []
    (reply,) = slave.poll(1.0 + 11.5 * char)
    assert reply.due == pytest.approx(1.0 + 11.5 * char + 0.005 + 7 * char)
    # Bytes read while the modelled line still brings earlier ones, or within t1.5 of their end,
    # continue the same frame.
    frame = read(1, 0x1F01)
    assert slave.feed(frame[:4], 2.0) == [] and slave.feed(frame[4:], 2.0 + 5.4 * char) == []
    assert len(slave.poll(2.0 + 9.4 * char + 3.5 * char)) == 1


def test_on_a_pty_a_silence_over_t15_inside_a_frame_discards_it(drive: AcgDrive) -> None:
    """Modbus over serial line 2.5.1.1: more than 1.5 characters of silence between two characters of
    a frame (and less than the 3.5 that would end it) make the frame incomplete: not answered, counted."""
    slave = RtuSlave(drive, paced=True)
    char = 10 / 9600
    frame = read(1, 0x1F01)
    assert slave.feed(frame[:4], 2.0) == [] and slave.feed(frame[4:], 2.0 + 5.9 * char) == []   # 1.9 characters
    assert slave.poll(2.0 + 9.9 * char + 3.5 * char) == []
    assert (slave.counters.frames, slave.counters.interrupted, slave.counters.replies) == (1, 1, 0)
    # The next whole frame is answered.
    assert slave.feed(frame, 3.0) == [] and len(slave.poll(3.0 + 11.5 * char)) == 1


def test_on_a_pty_a_flood_is_dropped_at_line_rate_and_the_line_is_free_a_frame_later(drive: AcgDrive) -> None:
    """A line carries one character per character time: what a pty brings faster, beyond one largest
    frame (256 characters) ahead of now, could not have come off a line; it is dropped and counted,
    never queued, so a request one frame time after the flood is answered."""
    slave = RtuSlave(drive, paced=True)
    char = 10 / 9600
    noise = bytes(range(256)) * 40                                        # 10,240 bytes at once
    assert slave.feed(noise, 5.0) == []
    assert slave.counters.overrun == len(noise) - 256
    assert slave.deadline() == pytest.approx(5.0 + 256 * char + 3.5 * char)
    later = 5.0 + 256 * char + 3.5 * char                                 # the flood's frame ends, dropped
    assert slave.poll(later) == [] and slave.counters.oversize + slave.counters.interrupted == 1
    assert slave.feed(read(1, 0x1F01), later + char) == []
    assert len(slave.poll(later + char + 11.5 * char)) == 1               # answered: free again


@pytest.mark.parametrize(("cm3", "cm4", "silence"), [
    (3, 0, 3.5 * 10 / 9600),       # 9,600 bps, 10-bit characters
    (3, 2, 3.5 * 11 / 9600),       # even parity: 11 bits
    (4, 1, 3.5 * 11 / 19200),      # 19,200 bps, two stop bits: still 3.5 characters
    (5, 0, 0.00175),               # 38,400 bps: fixed 1.75 ms
    (7, 3, 0.00175),               # 115,200 bps
])
def test_the_frame_end_silence_follows_cm3_and_cm4(drive: AcgDrive, cm3: int, cm4: int, silence: float) -> None:
    drive.write(addr("CM.3"), cm3, 0.0)
    drive.write(addr("CM.4"), cm4, 0.0)
    assert LineSettings.from_drive(drive).frame_silence == pytest.approx(silence)


def test_a_frame_split_across_reads_is_one_frame_below_the_silence_and_two_above(slave: RtuSlave,
                                                                                 drive: AcgDrive) -> None:
    char = 10 / 9600
    frame = read(1, 0x1F01)
    # Gaps of 3 characters: still one frame.
    assert slave.feed(frame[:3], 0.0) == []
    assert slave.feed(frame[3:5], 3 * char) == []
    assert slave.feed(frame[5:], 6 * char) == []
    (reply,) = slave.poll(6 * char + 3.5 * char)
    assert reply.frame == request("01 03 02 0032")
    assert slave.counters.frames == 1
    # A gap of 4 characters: two frames, neither answered: 01 03 1F 00 is too short for 0x03, and
    # 00 01 and a CRC fails its CRC.
    assert slave.feed(frame[:4], 1.0) == []
    assert slave.feed(frame[4:], 1.0 + 4 * char) == []       # this read ends the first frame
    assert slave.poll(1.0 + 8 * char) == []
    c = slave.counters
    assert (c.frames, c.truncated, c.crc_errors, c.replies) == (3, 1, 1, 1)


def test_bad_crc_other_station_and_noise_get_no_reply_and_the_next_good_frame_is_served(slave: RtuSlave) -> None:
    good = read(1, 0x1F01)
    bad = good[:-1] + bytes((good[-1] ^ 0xFF,))
    assert serve(slave, bad, 0.0) is None
    assert serve(slave, read(2, 0x1F01), 1.0) is None
    assert serve(slave, b"\x00", 2.0) is None                  # a lone byte of noise
    assert serve(slave, good, 3.0) == request("01 03 02 0032")
    c = slave.counters
    assert (c.crc_errors, c.other_station, c.truncated, c.replies, c.frames) == (1, 1, 1, 1, 4)


def test_a_frame_longer_than_any_modbus_frame_is_dropped_whole(slave: RtuSlave) -> None:
    assert serve(slave, bytes(range(256)) + read(1, 0x1F01), 0.0) is None
    assert slave.counters.oversize == 1
    assert serve(slave, read(1, 0x1F01), 1.0) == request("01 03 02 0032")


def test_broadcast_writes_are_executed_without_reply_and_reads_ignored(slave: RtuSlave, drive: AcgDrive) -> None:
    assert serve(slave, write(0, addr("ACC"), 25), 0.0) is None
    assert drive.read(addr("ACC")) == 25
    assert serve(slave, read(0, addr("ACC")), 1.0) is None
    assert slave.counters.broadcasts == 2 and slave.counters.replies == 0


@pytest.mark.parametrize(("frame", "reply"), [
    (request("01 03 ffff 0001"), "01 83 02"),         # no PDU address reaches 0x0000 (nor beyond 0xFFFF)
    (read(1, 0x0400), "01 83 02"),                    # reserved area
    (request("01 17 1f01 0001 1f02 0001 02 0032"), "01 97 01"),   # 0x17 is the card's, not the chapter's
    (request("01 01 0000 0001"), "01 81 01"),
    (write(1, 0x0300, 1), "01 86 02"),                # read-only monitoring word
    (write(1, addr("CM.1"), 251), "01 86 03"),        # CM.1 takes 1-250
    (read(1, 0x0300, 17), "01 83 03"),                # 1-16 words
])
def test_exception_codes_of_the_chapters_table(slave: RtuSlave, frame: bytes, reply: str) -> None:
    """ACG RS-485 manual, "Exception Code": 01 illegal function, 02 illegal data address, 03 illegal data
    value (and 06 busy): the card's 0x20 is not on this port."""
    assert serve(slave, frame, 0.0) == request(reply)


def test_a_write_not_allowed_in_run_is_02_on_rtu_and_0x20_on_the_card(slave: RtuSlave, drive: AcgDrive) -> None:
    drive.write(addr("drv"), 3, 0.0)
    assert serve(slave, write(1, 0x0382, 0x0003), 0.0) == write(1, 0x0382, 0x0003)
    assert drive.running
    assert serve(slave, write(1, 0x03E0, 1), 1.0) == request("01 86 02")
    assert ModbusTcpCore(drive).handle_pdu(bytes.fromhex("06 03e0 0001"), 1.0) == bytes.fromhex("86 20")


def test_run_commands_obey_the_port_drv_names(slave: RtuSlave, drive: AcgDrive) -> None:
    """drv 3 Int485: the RS-485 port's run command runs the drive and the card's does not; drv 4
    Field Bus: the other way round (ACG RS-485 manual, Setting Operation Command and Frequency)."""
    tcp = ModbusTcpCore(drive)
    drive.write(addr("drv"), 4, 0.0)
    serve(slave, write(1, 0x0382, 0x0003), 0.0)
    assert not drive.running
    tcp.handle_pdu(bytes.fromhex("06 0382 0003"), 0.1)
    assert drive.running_forward
    tcp.handle_pdu(bytes.fromhex("06 0382 0000"), 0.2)
    drive.advance(20.0)
    drive.write(addr("drv"), 3, 20.0)
    tcp.handle_pdu(bytes.fromhex("06 0382 0003"), 20.0)
    assert not drive.running
    serve(slave, write(1, 0x0382, 0x0001), 20.1)
    assert drive.running_reverse


def test_frq_int485_takes_the_frequency_written_over_rs485(slave: RtuSlave, drive: AcgDrive) -> None:
    for code, value in (("drv", 3), ("Frq", 6), ("ACC", 0)):
        drive.write(addr(code), value, 0.0)
    serve(slave, write(1, 0x0005, 3000), 0.0)
    serve(slave, write(1, 0x0006, 0x0002), 0.1)         # common area: forward
    drive.advance(1.0)
    assert drive.output_frequency == 3000
    assert drive.read(0x000E) & (1 << 13 | 1 << 14) == 1 << 13 | 1 << 14   # command and frequency by communication


def test_rs485_silence_of_pr13_is_a_lost_command(slave: RtuSlave, drive: AcgDrive) -> None:
    """ACG RS-485 manual, Command Loss Protective Operation: Pr.12 acts once the loss time Pr.13 expires;
    for a drive run from the RS-485 port (drv 3)."""
    for code, value in (("drv", 3), ("Pr.12", 1), ("Pr.13", 20)):   # free run after 2.0 s
        drive.write(addr(code), value, 0.0)
    serve(slave, write(1, 0x0382, 0x0003), 0.0)
    assert drive.running and not drive.command_lost
    serve(slave, read(1, 0x0300), 1.5)                 # any request to the drive keeps it
    drive.advance(3.4)
    assert drive.trip is None
    drive.advance(3.6)
    assert drive.trip is Trip.LOST_COMMAND and not drive.running


def test_rs485_silence_does_not_act_on_a_drive_run_from_the_card(slave: RtuSlave, drive: AcgDrive) -> None:
    for code, value in (("drv", 4), ("Pr.12", 1), ("Pr.13", 20)):
        drive.write(addr(code), value, 0.0)
    serve(slave, read(1, 0x0300), 0.0)
    ModbusTcpCore(drive).handle_pdu(bytes.fromhex("06 0382 0003"), 0.0)
    for moment in range(1, 5):                          # the card's Modbus TCP stays busy
        ModbusTcpCore(drive).handle_pdu(bytes.fromhex("03 0300 0001"), float(moment))
    assert drive.running and drive.trip is None
    assert not drive.command_lost and drive.next_deadline() is not None   # the card's own 5 s watch only


def test_the_chapters_virtual_input_example_runs_the_drive(slave: RtuSlave, drive: AcgDrive) -> None:
    """ACG RS-485 manual, Setting Virtual Multi-Function Input: CM.70 = FX, then 0h0001 at 0h0322 runs
    forward; 0h0003 (CM.71 = RX) runs in reverse; 0h0000 stops. CM.86 shows the inputs."""
    drive.write(addr("drv"), 2, 0.0)                    # Fx/Rx-2, the reading of the chapter's table
    assert serve(slave, write(1, addr("CM.70"), 1), 0.0) == write(1, addr("CM.70"), 1)
    serve(slave, write(1, addr("CM.71"), 2), 0.0)
    serve(slave, write(1, 0x0322, 0x0001), 0.1)
    assert drive.running_forward
    assert drive.read(addr("CM.86")) == drive.read(0x0385) == 0x0001
    drive.advance(10.0)
    serve(slave, write(1, 0x0322, 0x0003), 10.0)
    drive.advance(30.0)
    assert drive.running_reverse
    serve(slave, write(1, 0x0385, 0x0000), 30.0)
    drive.advance(50.0)
    assert not drive.running and drive.read(addr("CM.86")) == 0


def test_virtual_fx_rx_at_fx_rx_1_and_at_another_command_source(drive: AcgDrive) -> None:
    drive.write(addr("CM.70"), 1, 0.0)
    drive.write(addr("CM.71"), 2, 0.0)
    drive.write(addr("drv"), 4, 0.0)                    # Field Bus: the inputs command nothing
    drive.write(0x0385, 0x0001, 0.0)
    assert not drive.running and drive.read(addr("CM.86")) == 1
    drive.write(0x0385, 0x0000, 0.0)
    drive.write(addr("drv"), 1, 0.0)                    # Fx/Rx-1: FX forward, RX reverse, both stop
    drive.write(0x0385, 0x0002, 0.0)
    assert drive.running_reverse
    drive.write(0x0385, 0x0003, 0.0)
    drive.advance(30.0)
    assert not drive.running


def test_virtual_rst_bx_and_external_trip(drive: AcgDrive) -> None:
    for n, function in enumerate((3, 4, 5)):            # RST, External Trip, BX
        drive.write(addr(f"CM.{70 + n}"), function, 0.0)
    drive.write(0x0385, 0b010, 0.0)
    assert drive.trip is Trip.EXTERNAL_TRIP and drive.read(0x0330) == 1 << 12
    drive.write(0x0385, 0b001, 0.0)                     # RST closes: reset
    assert drive.trip is None
    drive.write(0x0385, 0b100, 0.0)                     # BX while closed
    assert drive.trip is Trip.BX
    drive.write(0x0385, 0b000, 0.0)
    assert drive.trip is None


def test_a_function_cannot_be_set_redundantly(slave: RtuSlave, drive: AcgDrive) -> None:
    serve(slave, write(1, addr("CM.70"), 1), 0.0)
    assert serve(slave, write(1, addr("CM.72"), 1), 0.0) == request("01 86 03")
    assert serve(slave, write(1, addr("In.65"), 1), 0.0) == request("01 86 03")
    assert serve(slave, write(1, addr("CM.72"), 2), 0.0) == write(1, addr("CM.72"), 2)


def test_a_tripped_drive_does_not_restart_while_fx_stays_closed(drive: AcgDrive) -> None:
    drive.write(addr("drv"), 1, 0.0)
    drive.write(addr("CM.70"), 1, 0.0)
    drive.write(0x0385, 1, 0.0)
    drive.inject_trip(Trip.OVER_HEAT, 1.0)
    drive.write(0x0006, 0x0008, 1.0)                    # trip reset
    drive.write(0x0385, 1, 1.0)
    assert drive.trip is None and not drive.running
    drive.write(0x0385, 0, 1.0)
    drive.write(0x0385, 1, 1.0)
    assert drive.running_forward


def test_a_change_of_station_id_answers_at_the_old_id_then_listens_at_the_new(slave: RtuSlave) -> None:
    assert serve(slave, write(1, addr("CM.1"), 7), 0.0) == write(1, addr("CM.1"), 7)
    assert serve(slave, read(1, addr("CM.1")), 1.0) is None
    assert serve(slave, read(7, addr("CM.1")), 2.0) == request("07 03 02 0007")


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.binary(max_size=300), st.floats(min_value=0, max_value=0.01)), max_size=12))
def test_line_noise_never_crashes_and_a_good_frame_is_served_after_it(chunks: list[tuple[bytes, float]]) -> None:
    slave = RtuSlave(AcgDrive(now=0.0))
    now = 0.0
    for data, gap in chunks:
        now += gap
        for reply in slave.feed(data, now):
            assert crc16(reply.frame[:-2]) == int.from_bytes(reply.frame[-2:], "little")
    assert serve(slave, read(1, 0x0300), now + 1.0) == request("01 03 02 0010")
