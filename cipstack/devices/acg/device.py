"""The emulated ACG drive with its ACG-ET2 card: the drive model behind the card's CIP objects
and assemblies (ACG-ET2 manual, appendix B).

* Objects: Identity, Motor Data 0x28, Control Supervisor 0x29, AC/DC Drive 0x2A and class 0x64
  (``objects.py``), on top of the standard objects of every EtherNet/IP adapter.
* Assemblies: all 24 instances are served by the Assembly object (explicit messaging); a class 1
  connection may use only the pair that CM.23/CM.24 select, as the card last applied them with
  CM.94 Comm Update ("CIP Input Instance (CM.23)", "CIP Output Instance (CM.24)").
* Lost command: an exclusive-owner class 1 connection that times out starts the drive's
  lost-command timers (Pr.12 after Pr.13, ACG-ET2 manual "Lost command conditions by protocol").
* Idle: the manual says nothing about a class 1 run/idle header. An idle originator sends no new
  command data, so the drive keeps the last commands it consumed; the connection is alive, so
  it is no command loss either.
* Reset (Identity service 0x05): type 0 is a power cycle (values written but not saved are lost,
  saved ones kept, ACG RS-485 manual "Saving Parameters Defined by Communication"; ``power_cycle``, which
  the ``power-cycle`` fault calls too); type 1 returns to the factory values and forgets the saved
  ones.
* Saves: the drive hands each save to the device; with a state file a ``StateWriter`` writes it
  off the event loop's thread, coalescing back-to-back saves (``flush_saves`` waits for them).
"""

from __future__ import annotations

import copy
import logging
import struct
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

from ...assemblies.schema import AssemblySchema
from ...cip.model import ClassSpec
from ...eip.target.io_target import ConnectionKind, IoConnection, IoProfile
from ...errors import BadRequest
from ...objects.assembly import AssemblyPoint
from ...objects.file import StoredFile
from ...objects.tcpip import NetworkInterface
from ..base import Device, DeviceLimits, DriveTrips, ModbusDrive, RtuPort, TripRefused, TripReport
from ..keypad import shown_value
from ..profiles import DEFAULT_MAC, serial_from_mac
from ..registers import Register, RegisterError
from ..state import ParameterStore, StateWriter
from . import registers as reg
from .assemblies import (
    HZ_INPUTS,
    HZ_OUTPUTS,
    INPUT_INSTANCES,
    OUTPUT_INSTANCES,
    AcgAssemblies,
    acg_assemblies,
    assembly_size,
    parameter_words,
)
from .drive import FAMILY, MODEL, AcgDrive, Trip
from .keypad import AcgKeypad
from .modbus import ModbusTcpCore
from .modbus_rtu import MAX_DRIVES_PER_LINE, LineSettings, RtuSlave
from .objects import (
    CATALOG_CLASSES,
    OUTPUT_CURRENT,
    OUTPUT_FREQUENCY,
    AcDcDriveObject,
    AcgIdentityObject,
    ControlSupervisorObject,
    KeypadParameterObject,
    MotorDataObject,
    acg_identity_info,
)

log = logging.getLogger(__name__)

#: The manual gives no RPI limits: 1 ms is the fastest the emulator keeps to (benchmarks/io.py measures
#: it: sends leave within tens of microseconds of their slot); the upper limit is the adapter's
#: default (``IoProfile.rpi_max_us``).
RPI_MIN_US = 1_000


#: Register addresses of CM.51-CM.58 (Para Control-n) and CM.31-CM.38 (Para Status-n).
_CONTROL_ADDRESSES = tuple(reg.ACG_REGISTERS.by_code(f"CM.{51 + i}").address for i in range(8))
_STATUS_ADDRESSES = tuple(reg.ACG_REGISTERS.by_code(f"CM.{31 + i}").address for i in range(8))


@lru_cache(maxsize=64)
def _assemblies_at(key: tuple[tuple[int, ...], tuple[int, ...]]) -> AcgAssemblies:
    """The schemas for the CM.51-58 / CM.31-38 addresses ``key``, built once per process for every
    drive that has those addresses (a fleet's drives mostly share one set): building them was a
    large part of a drive's start-up."""
    return acg_assemblies(reg.SPEED_REFERENCE, OUTPUT_FREQUENCY, _words(key[0]), _words(key[1]))


def _words(addresses: tuple[int, ...]) -> list[Register | None]:
    """The registers at communication addresses (a parameter without one, CM.94, is at none)."""
    found = (reg.ACG_REGISTERS.get(a) for a in addresses)
    return [r if r is not None and r.addressed else None for r in found]


@dataclass
class AcgDevice(Device):
    drive: AcgDrive = field(default_factory=AcgDrive)
    #: The drive's power-up instant is the first time the shell advances the device to (the device
    #: was built before the shell's clock was known).
    power_up_on_first_advance: bool = field(default=False, kw_only=True)

    def __post_init__(self) -> None:
        super().__post_init__()
        #: The latest time the adapter has moved the device to (loop time, seconds).
        self._now = self.drive.time
        # The ACG's Identity replaces the generic one: its services, status bits and state.
        self.identity = AcgIdentityObject(self.identity_info, lambda: self.drive, on_reset=self._on_reset)
        self.router.objects[self.identity.spec.class_id] = self.identity
        drive, clock = (lambda: self.drive), (lambda: self.now)
        self.motor_data = MotorDataObject(drive, clock)
        self.control_supervisor = ControlSupervisorObject(drive, clock)
        self.ac_dc_drive = AcDcDriveObject(drive, clock)
        self.keypad_parameters = KeypadParameterObject(drive, clock)
        for obj in (self.motor_data, self.control_supervisor, self.ac_dc_drive, self.keypad_parameters):
            self.router.register(obj)
        self._schemas: tuple[tuple[tuple[int, ...], tuple[int, ...]], AcgAssemblies] | None = None
        # 20/21/100/101 and 70/71/110/111 do not depend on any setting: decoded on the I/O path as they are.
        speed = self.schemas()
        # A copy of each for this drive: a schema remembers the last values it encoded, and drives
        # that shared one would take turns replacing what each produces on every class 1 firing.
        self._speed_schemas = {i: copy.copy(speed[i]) for i in (*OUTPUT_INSTANCES, *INPUT_INSTANCES)
                               if not parameter_words(i)}
        self._points: dict[int, AssemblyPoint] = {}
        #: Last data each smart-scaling output consumed: a word is written when it changes.
        self._last_words: dict[int, bytes] = {}
        #: Each speed output's last data applied, the drive it went to and the drive's ``command_mark``
        #: right after: the same data again, to the same unchanged drive, is not applied again.
        self._applied: dict[int, tuple[bytes, AcgDrive, tuple[object, ...]]] = {}
        #: Each speed input's last bytes, with the drive and its ``status_mark`` they were made from.
        self._produced: dict[int, tuple[AcgDrive, tuple[object, ...], bytes]] = {}
        for instance in (*OUTPUT_INSTANCES, *INPUT_INSTANCES):
            point = self._assembly_point(instance, speed[instance].name)
            self._points[instance] = point
            self.assembly.add_assembly(point)
        self.update_io_status()

    # -- assemblies -------------------------------------------------------------------------------
    def schemas(self) -> AcgAssemblies:
        """Every assembly schema at the present CM.31-CM.38 / CM.51-CM.58 addresses."""
        drive = self.drive
        key = (tuple(drive.read(_CONTROL_ADDRESSES[i]) for i in range(8)),
               tuple(drive.read(_STATUS_ADDRESSES[i]) for i in range(8)))
        if self._schemas is None or self._schemas[0] != key:
            self._schemas = key, _assemblies_at(key)
        return self._schemas[1]

    def assembly_schema(self, instance: int) -> AssemblySchema:
        """The schema of one instance; 121-128 and 141-148 as CM.51-58 / CM.31-38 name them now."""
        schema = self._speed_schemas.get(instance)
        return schema if schema is not None else self.schemas()[instance]

    def data_schema(self, instance: int) -> AssemblySchema | None:
        try:
            return self.assembly_schema(instance)
        except KeyError:
            return None

    @property
    def active_output_instance(self) -> int:
        """The output instance CM.24 selects, as the card applied it (CM.94)."""
        return self.drive.active_comm_settings.output_instance.instance

    @property
    def active_input_instance(self) -> int:
        return self.drive.active_comm_settings.input_instance.instance

    def _assembly_point(self, instance: int, name: str) -> AssemblyPoint:
        """``name``: the instance's name, which no CM.31-38 / CM.51-58 setting changes (read from the
        schemas once for all the points: each reading of them reads sixteen registers)."""
        size = assembly_size(instance)
        if instance in OUTPUT_INSTANCES:
            return AssemblyPoint(instance, size, consumed=True,
                                 consume=lambda data, now: self._consume(instance, data, now), name=name)
        if parameter_words(instance):
            return AssemblyPoint(instance, size, consumed=False, produce=lambda: self._produce_words(instance),
                                 name=name)
        schema = self.assembly_schema(instance)
        return AssemblyPoint(instance, size, consumed=False, produce=lambda: self._produce_speed(schema),
                             name=schema.name)

    def _produce_speed(self, schema: AssemblySchema) -> bytes:
        """Inputs 70/71/110/111 (ACG-ET2 manual, input instances and the bits table after them); made
        again only when the drive's ``status_mark`` moved since the last (every class 1 firing asks)."""
        drive = self.drive
        mark = drive.status_mark()
        made = self._produced.get(schema.instance)
        if made is not None and made[0] is drive and made[1] == mark:
            return made[2]
        hz = schema.instance in HZ_INPUTS
        values = {
            "faulted": drive.faulted,                          # 0x29 attribute 10
            "running_forward": drive.running_forward,          # 0x29 attribute 7
            "speed_actual": drive.output_frequency if hz else drive.speed_actual_rpm,  # 0x2A attribute 7 / 100
        }
        if schema.instance in (71, 111):
            values.update(
                warning=False,                                 # "Not supported"
                running_reverse=drive.running_reverse,         # 0x29 attribute 8
                ready=drive.ready,                             # 0x29 attribute 9
                ctrl_from_net=drive.control_from_net,          # 0x29 attribute 14
                ref_from_net=drive.reference_from_net,         # 0x2A attribute 29
                at_reference=drive.at_reference,               # 0x2A attribute 3
                drive_state=int(drive.drive_state),            # 0x29 attribute 6
            )
        produced = schema.encode(values)
        self._produced[schema.instance] = drive, mark, produced
        return produced

    def _produce_words(self, instance: int) -> bytes:
        """Inputs 141-148: the words of 0x0100-0x0107, the registers CM.31-CM.38 name."""
        count = parameter_words(instance)
        drive = self.drive
        return struct.pack(f"<{count}H", *(drive.read(reg.STATUS_PARAMETER_BASE + i) & 0xFFFF for i in range(count)))

    def _consume(self, instance: int, data: bytes, now: float) -> None:
        now = max(now, self.drive.time)
        if parameter_words(instance):
            self._consume_words(instance, data, now)
        else:
            self._consume_speed(instance, data, now)

    def _consume_speed(self, instance: int, data: bytes, now: float) -> None:
        """Outputs 20/21/100/101: Run Fwd/Rev through the Drive Run edge table, Fault reset on
        0 -> 1, the speed reference (rpm or Hz). NetCtrl/NetRef are "Not used" (note 2).

        A scanner sends the same output every RPI; applied again to a drive nothing else changed
        since (``AcgDrive.command_mark``), it changes nothing, and is skipped: most of what a class 1
        packet cost the device. A value written by other means in between (explicit messaging, Modbus,
        the keypad) moves the mark, and the next data is applied over it as it always was."""
        drive = self.drive
        applied = self._applied.get(instance)
        if applied is not None and applied[0] == data and applied[1] is drive and applied[2] == drive.command_mark():
            return
        values = self.assembly_schema(instance).decode(data)
        drive.set_run_command(values["run_forward"], values.get("run_reverse", False), now)
        drive.set_fault_reset(values["fault_reset"], now)
        try:
            if instance in HZ_OUTPUTS:
                drive.set_speed_reference(values["speed_reference"], now)
            else:
                drive.set_speed_reference_rpm(values["speed_reference"], now)
        except RegisterError as exc:
            # Refused: tried again with the next data, as before (and logged each time).
            self._applied.pop(instance, None)
            log.debug("assembly %d: speed reference refused: %s", instance, exc)
            return
        self._applied[instance] = bytes(data), drive, drive.command_mark()

    def _consume_words(self, instance: int, data: bytes, now: float) -> None:
        """Outputs 121-128: each word goes to the register its CM.51-CM.58 names, in order (the
        manual puts the speed and the run command last). A word is written when it changes, so a
        command word held at the same value is not repeated (and a trip is not run over)."""
        count = parameter_words(instance)
        previous = self._last_words.get(instance)
        self._last_words[instance] = bytes(data)
        words = struct.unpack(f"<{count}H", data)
        old = struct.unpack(f"<{count}H", previous) if previous is not None else (None,) * count
        drive = self.drive
        for index, (value, before) in enumerate(zip(words, old, strict=True)):
            if value == before:
                continue
            target = reg.ACG_REGISTERS.get(drive.read(_CONTROL_ADDRESSES[index]))
            raw = target.from_words([value]) if target is not None else value
            try:
                drive.write(reg.CONTROL_PARAMETER_BASE + index, raw, now)
            except RegisterError as exc:
                log.debug("assembly %d word %d refused: %s", instance, index + 1, exc)

    # -- class 1 ----------------------------------------------------------------------------------
    def io_profile(self) -> IoProfile:
        return IoProfile(
            consumed=lambda: {self.active_output_instance: self._points[self.active_output_instance]},
            produced=lambda: {self.active_input_instance: self._points[self.active_input_instance]},
            rpi_min_us=RPI_MIN_US,
            pairs=lambda: {(self.active_output_instance, self.active_input_instance)},
            pair_hint=self.class1_pair_hint,
        )

    def class1_pair_hint(self) -> str:
        """Which exclusive-owner pair class 1 accepts now, and how to select another (ACG-ET2 manual,
        "CIP Input Instance (CM.23)", "CIP Output Instance (CM.24)", applied by CM.94 Comm Update)."""
        settings = self.drive.active_comm_settings
        return (f"class 1 takes only output {settings.output_instance.instance} / input "
                f"{settings.input_instance.instance}, the pair CM.24 = {settings.output_instance.setting} / "
                f"CM.23 = {settings.input_instance.setting} select; write CM.24 and CM.23 (class 0x64 instance 7 "
                f"attributes 24/23) then CM.94 = 1, or start with --param CM.24=N --param CM.23=N --param CM.94=1")

    def io_opened(self, connection: IoConnection) -> None:
        super().io_opened(connection)
        if connection.kind is ConnectionKind.EXCLUSIVE_OWNER:
            self._last_words.clear()
            self._applied.clear()
            self.drive.on_io_connection_opened(self.now)

    def io_closed(self, connection: IoConnection, timed_out: bool) -> None:
        super().io_closed(connection, timed_out)
        # Only a break counts: a Forward_Close is the originator ending control on purpose.
        if timed_out and connection.kind is ConnectionKind.EXCLUSIVE_OWNER:
            self.drive.on_io_connection_lost(self.now)

    def io_run_idle(self, connection: IoConnection, run: bool) -> None:
        super().io_run_idle(connection, run)  # idle: the last commands stay (module docstring)

    @property
    def io_connection_count(self) -> int:
        return len(self._io_connections)

    # -- time -------------------------------------------------------------------------------------
    @property
    def now(self) -> float:
        """The device's present time: the latest the adapter gave it, or later if another protocol
        (Modbus TCP) has moved the drive since."""
        return max(self._now, self.drive.time)

    def advance(self, now: float) -> None:
        if self.power_up_on_first_advance:
            self.power_up_on_first_advance = False
            self.drive.power_up_at(now)
        self._now = max(now, self._now, self.drive.time)
        self.drive.advance(self._now)

    def next_deadline(self) -> float | None:
        return self.drive.next_deadline()

    def tick(self, now: float) -> float | None:
        if self.power_up_on_first_advance:
            self.advance(now)
            return self.next_deadline()
        if now > self._now:
            self._now = now
        return self.drive.advance_to(self._now)

    def reset(self, reset_type: int) -> None:
        """Identity Reset: 0 power cycle (unsaved values lost), 1 factory defaults (saved ones too)."""
        if reset_type == 1:
            self.drive.forget_saved_parameters()   # a refused save (StateFileError) refuses the reset
        self.power_cycle(self.now)

    def modbus_drive(self) -> ModbusDrive:
        """The ACG speaks Modbus TCP on its ACG-ET2 card and Modbus-RTU on the drive's RS-485 port."""
        def drive() -> AcgDrive:
            return self.drive

        # Up to 16 drives on one line: the ACG RS-485 manual's Communication Standards.
        rtu = RtuPort(lambda paced, written: RtuSlave(drive, paced, written),
                      lambda: LineSettings.from_drive(self.drive), MAX_DRIVES_PER_LINE,
                      "ACG RS-485 manual, Communication Standards")
        return ModbusDrive(drive, self.saves, rtu, tcp=lambda written: ModbusTcpCore(drive, written))

    def power_cycle(self, now: float) -> None:
        """The drive and its ACG-ET2 card lose power and get it back at ``now``: the drive comes back with
        what it saved (``AcgDrive.power_cycled`` says what that is), the card with the instance pair
        CM.23/CM.24 name as saved (CM.94 saves the CM group), and no connection."""
        self.advance(max(now, self.now))   # places a power-up not yet placed, then runs to the loss
        self.drive = self.drive.power_cycled(self._now)
        self._last_words.clear()
        self._applied.clear()
        super().power_cycle(self._now)

    def inject_trip(self, code: Trip | int | str) -> Trip:
        """Trip the drive as if ``code`` occurred: a ``Trip``, its name ("OverHeat", "OVER_HEAT") or a
        fault code of the Drive Fault Codes table (0x4200 or "0x4200").

        A drive already tripped keeps its trip: class 0x29 attribute 13 holds one Drive Fault Code,
        and a trip is left only by a Fault Reset (attribute 12, ACG-ET2 manual) or, for a level
        type, by its cause going away. So a second trip is refused (``TripRefused`` naming the
        present one), and nothing changes."""
        trip = parse_trip(code)
        present = self.drive.trip
        if present is not None:
            raise TripRefused(f"the drive is already tripped: {present.label} (fault code 0x{present.fault_code:04X}); "
                             f"it keeps that trip until a Fault Reset, so {trip.label} is not taken")
        return self.drive.inject_trip(trip, self.now)

    def check_trip_code(self, code: int | str) -> None:
        parse_trip(code)

    def reset_trip(self) -> Trip | None:
        """A Fault Reset, as class 0x29 attribute 12's rising edge makes one (the ACG-ET2 manual,
        "Drive Fault Reset"): the trip present is cleared, unless it is a level type whose cause lasts."""
        present = self.drive.trip
        if present is None:
            return None
        if not self.drive.fault_reset(self.now):
            raise TripRefused(f"{present.label} holds: a level-type trip lasts while its cause does")
        return present

    def trip_codes(self) -> str:
        """The fault codes of the Drive Fault Codes table (ACG-ET2 manual), or a trip's name."""
        codes = sorted({trip.fault_code for trip in Trip})
        return ", ".join(f"0x{code:04X}" for code in codes) + " (or a trip name, e.g. OverHeat)"

    def trip_choices(self) -> list[dict[str, object]]:
        """The trips of the Drive Fault Codes table (ACG-ET2 manual) by name: several share a code."""
        return [{"code": trip.label, "label": trip.label, "fault_code": trip.fault_code} for trip in Trip]

    def drive_trips(self) -> DriveTrips:
        """The trips of the Drive Fault Codes table (ACG-ET2 manual), each reported with its fault code."""
        def report(trip: Trip) -> TripReport:
            return TripReport(trip.label, trip.fault_code)

        def reset() -> TripReport | None:
            cleared = self.reset_trip()
            return None if cleared is None else report(cleared)

        return DriveTrips(inject=lambda code: report(self.inject_trip(code)), check=self.check_trip_code,
                          reset=reset, codes=self.trip_codes, choices=self.trip_choices)

    def keypad(self) -> AcgKeypad:
        """The drive's keypad: its codes (drv, ACC, CM.23...) in the keypad's unit."""
        return AcgKeypad(lambda: self.drive, self.router.objects)

    def status_fields(self) -> dict[str, object]:
        drive = self.drive
        return {
            "state": drive.drive_state.name,
            "direction": "fwd" if drive.running_forward else "rev" if drive.running_reverse else None,
            "output_frequency_hz": drive.output_frequency / 100, "reference_hz": drive.speed_reference / 100,
            # In its register's unit and step (0x0009, 0.1 A: ACG RS-485 manual, Monitoring Area Parameter).
            "output_current_a": float(shown_value(OUTPUT_CURRENT, drive.read(OUTPUT_CURRENT.address))),
            # What the panel shows "not simulated" beside: there is no motor or load model (registers.py).
            "not_simulated": [] if OUTPUT_CURRENT.simulated else ["output_current_a"],
            "io_connections": len(self._io_connections),
            "trip": drive.trip.label if drive.trip is not None else None,
            "fault_code": drive.fault_code if drive.trip is not None else None,
            "lost_command": bool(drive.command_lost), "comm_update_pending": bool(drive.comm_update_pending),
        }

    def status_line(self) -> str:
        """One compact line for the emulator's console."""
        f = self.status_fields()
        parts = [
            f"{f['state']:<10}", str(f["direction"] or "---"),
            f"out {f['output_frequency_hz']:6.2f} Hz", f"ref {f['reference_hz']:6.2f} Hz", f"io {f['io_connections']}",
        ]
        if f["trip"] is not None:
            parts.append(f"trip {f['trip']} (0x{f['fault_code']:04X})")
        if f["lost_command"]:
            parts.append("lost command")
        if f["comm_update_pending"]:
            parts.append("CM.94 pending")
        return " | ".join(parts)

    @staticmethod
    def catalog_classes() -> tuple[ClassSpec, ...]:
        """The ClassSpecs of 0x28, 0x29, 0x2A and 0x64, for a scanner's ``Catalog``."""
        return CATALOG_CLASSES


def parse_trip(code: Trip | int | str) -> Trip:
    """A trip from a ``Trip``, a fault code (int or "0x..." text) or a trip name."""
    if isinstance(code, Trip):
        return code
    if isinstance(code, int):
        return Trip.from_fault_code(code)
    text = code.strip()
    try:
        return Trip.from_fault_code(int(text, 0))
    except ValueError:
        pass
    wanted = text.replace(" ", "").replace("_", "").lower()
    for trip in Trip:
        if wanted in (trip.name.replace("_", "").lower(), trip.label.replace(" ", "").lower()):
            return trip
    raise BadRequest(f"unknown trip {code!r}: give a fault code (e.g. 0x4200) or a name (e.g. OverHeat)")


def build_acg_device(interface: NetworkInterface | None = None, limits: DeviceLimits | None = None,
                     state_path: Path | None = None, *, now: float | None = None,
                     files: tuple[StoredFile, ...] = ()) -> AcgDevice:
    """The ACG drive with its ACG-ET2 card. ``state_path``: the state file that holds the saved
    parameters (None: they are kept in memory only, for the life of the process). ``now``: the
    power-up time on the clock the device will be advanced with; None: the first time its shell
    advances it to (the device reads no clock). A corrupt or foreign state file raises
    ``StateFileError``. ``files``: what its File object serves (its EDS file, ``cipstack.objects.file``)."""
    interface = interface or NetworkInterface(mac=DEFAULT_MAC)
    writer: StateWriter | None = None
    if state_path is None:
        drive = AcgDrive(now=now or 0.0)
    else:
        store = ParameterStore(state_path, FAMILY, MODEL)
        saved = store.load()
        writer = StateWriter(store, saved)
        drive = AcgDrive(saved, now=now or 0.0, on_save=writer.request, origin=str(store.path))
    info = acg_identity_info(drive, serial_from_mac(interface.mac))
    return AcgDevice(info, interface, limits or DeviceLimits(), drive=drive, saves=writer,
                     power_up_on_first_advance=now is None, files=files)


__all__ = ["RPI_MIN_US", "AcgDevice", "build_acg_device", "parse_trip"]
