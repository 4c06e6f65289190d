"""An MX2 or RX inverter with its CompoNet option board, as a CIP device.

``OmronDevice`` puts the objects of appendices C-E and the assemblies of appendix B on one
message router and binds them to the inverter simulation (``Inverter``). It serves them over
EtherNet/IP directly (``cipstack adapter --profile mx2``) or as a CompoNet slave behind the
gateway of ``cipstack.componet`` (``build_componet_gateway``). Time comes from the shell:
``advance(now)`` before every request and datagram, ``next_deadline()`` for the ramps and the
P044 network error timer.

Saved parameters: the EEPROM save (0900h, section E-2-2) writes the inverter's saved values to
the state file; a restart on the same file is a power cycle, and so is ``power_cycle`` in process
(the ``power-cycle`` fault). Key 0 of the file (no function
code has number 0) holds the configuration consistency value of Identity attribute 9, which
counts those saves (Table C-2) and so lives in the same non-volatile memory.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ...assemblies.schema import AssemblySchema
from ...cip.model import ClassSpec
from ...componet.gateway import COMPONET_PORT, CompoNetGateway
from ...componet.network import NODE_ADDRESSES, CompoNetNetwork
from ...eip.target.io_target import IoConnection, IoProfile
from ...errors import BadRequest, UnknownKey
from ...objects.assembly import AssemblyPoint
from ...objects.file import StoredFile
from ...objects.identity import IdentityInfo, IdentityStatus
from ...objects.tcpip import NetworkInterface
from ..base import Device, DeviceLimits, DriveTrips, TripRefused, TripReport
from ..registers import RegisterError, RegisterRefusal
from ..state import ParameterStore, StateFileError, StateWriter
from .assemblies import (
    CENTIHERTZ,
    DECIHERTZ,
    FAULT_DATA_SETTING,
    FAULT_FUNCTION_CODE,
    FAULT_REGISTER_NUMBER,
    FAULT_REGISTER_SIZE,
    FAULT_SLAVE_DEVICE,
    FAULT_WRITING_MODE,
    FLEXIBLE_INPUT,
    FLEXIBLE_OUTPUT,
    INPUT_INSTANCES,
    OUTPUT_INSTANCES,
    RPM,
    SIZES,
    SPECIAL_FAILURE,
    SPECIAL_FAULTS,
    SPECIAL_FUNCTION_CODES,
    SPECIAL_READ_DOUBLE,
    SPECIAL_READ_WORD,
    SPECIAL_WRITE_DOUBLE,
    SPECIAL_WRITE_WORD,
    flexible_schema,
    omron_schemas,
    pair_sizes,
)
from .board import MISSING_INSTANCE
from .inverter import Inverter, InverterModeError
from .models import DEVICE_TYPE, REVISION, VENDOR_ID, Family, Model, model
from .objects import (
    CLASS_SPECS,
    STATUS_ALWAYS_ON,
    AcDcDriveObject,
    CompoNetLinkObject,
    ConnectionObject,
    ControlSupervisorObject,
    DiscreteInputPointObject,
    DiscreteOutputPointObject,
    FunctionCodeObject,
    LinkState,
    ModbusRegisterObject,
    MotorDataObject,
    OptionBoardIdentity,
    UnitParameterObject,
    speed_word,
)
from .registers import CONNECTION_PATHS, TRIP_CODES, SpeedUnit, TripCode, trip_code

if TYPE_CHECKING:
    from .operator import DigitalOperator

_UNIT_OF = {SpeedUnit.CENTIHERTZ: CENTIHERTZ, SpeedUnit.DECIHERTZ: DECIHERTZ, SpeedUnit.RPM: RPM}
#: State-file key of the configuration consistency value (see the module docstring).
CONSISTENCY_KEY = 0
#: Rotary switch settings 64-99 hand the node address to P190 (section 2-1-4).
SWITCHES_USE_P190 = 64

log = logging.getLogger(__name__)


def omron_identity(inverter_model: Model, serial_number: int) -> IdentityInfo:
    """Table C-2 with the product code and name of Tables C-3/C-4."""
    return IdentityInfo(vendor_id=VENDOR_ID, device_type=DEVICE_TYPE, product_code=inverter_model.product_code,
                        revision=REVISION, serial_number=serial_number, product_name=inverter_model.product_name)


def _word(value: int) -> int:
    return value & 0xFFFF


@dataclass
class SpecialIo:
    """Special I/O (assemblies 100/150, Tables B-13 to B-17): one register request per output change.

    Reads (03h/43h) are served every time the output arrives, so input 150 follows the register;
    writes (10h/50h) act once per new output data, as a register write is not to repeat each cycle.
    """

    last_request: bytes = bytes(8)
    response: bytes = bytes(8)


@dataclass
class OmronDevice(Device):
    """One MX2 or RX model with its option board; build it with ``build_omron_device``."""

    model: Model | None = None
    state_path: Path | None = None
    #: The option board's rotary switches: 0-63 is the node address, 64-99 hands it to P190.
    rotary_switches: int = 0

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.model is None:
            raise BadRequest("an OmronDevice needs its inverter model")
        inverter_model = self.model
        self._now = 0.0
        #: False simulates a broken link between option board and inverter (E60/E70 territory).
        self.inverter_link_ok = True
        self.store = ParameterStore(self.state_path, inverter_model.family.value.lower(), inverter_model.name) \
            if self.state_path is not None else None
        saved = dict(self.store.load()) if self.store is not None else {}
        if self.store is not None:
            # Saves are written off the event loop's thread (DESIGN: file I/O never runs on it).
            self.saves = StateWriter(self.store, saved)
        consistency = saved.pop(CONSISTENCY_KEY, 0)
        try:
            self.inverter = Inverter(inverter_model, now=0.0, saved=saved, on_save=self._saved,
                                     consistency_value=consistency)
        except ValueError as exc:   # a saved value this model cannot hold: the file is named
            raise StateFileError(f"{self.state_path}: {exc}") from None
        self.link = LinkState(self.rotary_switches)
        self.special = SpecialIo()
        traits = self.inverter.traits
        # Table C-2 Identity replaces the generic one (services 0Eh and 05h, attributes 9 and 65h).
        self.identity = OptionBoardIdentity(self.identity_info, self, self._on_reset)
        self.router.objects[self.identity.spec.class_id] = self.identity
        self.connection = ConnectionObject(frozenset(OUTPUT_INSTANCES), frozenset(INPUT_INSTANCES))
        for obj in (
            self.connection,
            DiscreteInputPointObject(self, traits),
            DiscreteOutputPointObject(self, traits),
            motor_data := MotorDataObject(self, inverter_model.name, inverter_model.voltage_class),
            ControlSupervisorObject(self),
            AcDcDriveObject(self, motor_data),
            ModbusRegisterObject(self, self.inverter.registers),
            FunctionCodeObject(self, self.inverter.registers),
            UnitParameterObject(self),
            CompoNetLinkObject(self, self.link, self.node_setting),
        ):
            self.router.register(obj)
        for instance in (*OUTPUT_INSTANCES, *INPUT_INSTANCES):
            if instance in SIZES:
                self.assembly.add_assembly(self._point(instance))
        # Table E-5 gives 0x16 for an instance that does not exist, in every object the board serves
        # (Identity, Message Router and Assembly as well as appendices C/D): one answer for the device.
        for served in self.router.objects.values():
            served.missing_instance_status = MISSING_INSTANCE
        self._start()

    # -- the option board as its objects see it ------------------------------------------------
    @property
    def now(self) -> float:
        """The last time the shell gave (``advance``), or the inverter's if a test rig moved it on directly."""
        return max(self._now, self.inverter.time)

    @property
    def family(self) -> Family:
        return self.inverter.family

    def command(self, **fields: Any) -> None:
        self.inverter.command(self.now, **fields)

    def motor_type_changed(self) -> None:
        """Table D-2 (MX2): a new Motor Type resets the inverter and the option board."""
        self._restart_board()

    def node_setting(self) -> int:
        """The node address the switches (or P190) set now (section 2-1-4)."""
        if self.rotary_switches >= SWITCHES_USE_P190:
            return self.inverter.read_code("P190")
        return self.rotary_switches

    def _start(self) -> None:
        """What the board reads at power-on and reset: node address, default connection path (P046,
        Table 10) and the flexible mapping (appendix F)."""
        self.link.mac_id = self.node_setting()
        _, output, input_ = CONNECTION_PATHS[self.inverter.connection_path]
        self.connection.select(output, input_)
        for instance in (FLEXIBLE_OUTPUT, FLEXIBLE_INPUT):
            self.assembly.instances.pop(instance, None)
            self.assembly.points.pop(instance, None)
            self.assembly.stores.pop(instance, None)
        mapping = self.inverter.flexible
        if mapping is not None:
            self.assembly.add_assembly(self._point(FLEXIBLE_OUTPUT, len(mapping.outputs)))
            self.assembly.add_assembly(self._point(FLEXIBLE_INPUT, len(mapping.inputs)))
        self.update_io_status()

    # -- assemblies ------------------------------------------------------------------------------
    def schemas(self) -> Mapping[int, AssemblySchema]:
        """The assembly schemas in the current speed unit (P049, d060; section 4-2-5), flexible ones included."""
        schemas = dict(omron_schemas(_UNIT_OF[self.inverter.speed_unit]))
        mapping = self.inverter.flexible
        if mapping is not None:
            schemas[FLEXIBLE_OUTPUT] = flexible_schema(FLEXIBLE_OUTPUT, len(mapping.outputs))
            schemas[FLEXIBLE_INPUT] = flexible_schema(FLEXIBLE_INPUT, len(mapping.inputs))
        return schemas

    def data_schema(self, instance: int) -> AssemblySchema | None:
        return self.schemas().get(instance)

    def _point(self, instance: int, words: int = 0) -> AssemblyPoint:
        consumed = instance in OUTPUT_INSTANCES
        size = 2 * words if words else SIZES[instance]
        name = flexible_schema(instance, words).name if words else omron_schemas()[instance].name
        if consumed:
            return AssemblyPoint(instance, size, True, consume=lambda data, now: self._consume(instance, data, now),
                                 name=name)
        return AssemblyPoint(instance, size, False, produce=lambda: self._produce(instance), name=name)

    def _consume(self, instance: int, data: bytes, now: float) -> None:
        now = self._now = max(self.now, now)
        inverter = self.inverter
        if instance == FLEXIBLE_OUTPUT:
            inverter.flexible_output([int.from_bytes(data[i:i + 2], "little") for i in range(0, len(data), 2)], now)
        elif instance == 100:
            self._special_request(data, now)
        else:
            inverter.command(now, **self._command_fields(instance, self.schemas()[instance].decode(data)))
        inverter.on_network_ok(now)

    def _command_fields(self, instance: int, values: Mapping[str, Any]) -> dict[str, Any]:
        """``OptionCommand`` fields of an output assembly: only what its layout carries (appendix B)."""
        fields: dict[str, Any] = {}
        names = {"run_forward": "fwd", "run_reverse": "rev", "fault_reset": "fault_reset", "net_ctrl": "net_ctrl",
                 "net_ref": "net_ref", "force_fault": "force_fault", "free_run": "free_run",
                 "torque_reference": "torque_reference", "torque_bias": "torque_bias"}
        for field_name, command in names.items():
            if field_name in values:
                fields[command] = values[field_name]
        if "speed_reference" in values:
            fields["speed_reference"] = _word(values["speed_reference"])
        if instance == 110:
            # Table B-25: 0.1 s units, 0.1 to 3600.0 s; 0 leaves F002/F003 in charge.
            for name in ("accel_time", "decel_time"):
                raw = values[name]
                fields[name] = raw / 10 if 1 <= raw <= 36000 else None
        if instance == 101:
            traits = self.inverter.traits
            current = self.inverter.option_command
            # CI3-CI8 (CI8 on the RX only) override input terminals [3]-[8]; [1]/[2] stay as 0x08 set them.
            overrides = current.input_overrides & 0b11
            for n in range(3, traits.input_terminals + 1):
                overrides |= values[f"override_input_{n}"] << (n - 1)
            fields["input_overrides"] = overrides | (current.input_overrides & ~((1 << traits.input_terminals) - 1))
            # CO1-CO2 (CO3-CO5 on the RX) and CR, in Discrete Output Point order (Table C-12).
            outputs = 0
            for n in range(1, len(traits.output_terminals)):
                outputs |= values[f"set_output_{n}"] << (n - 1)
            outputs |= values["set_relay"] << (len(traits.output_terminals) - 1)
            fields["outputs"] = outputs
        return fields

    def _produce(self, instance: int) -> bytes:
        inverter = self.inverter
        if instance == FLEXIBLE_INPUT:
            return b"".join(word.to_bytes(2, "little") for word in inverter.flexible_input())
        if instance == 150:
            return self.special.response
        status = inverter.status()
        traits = inverter.traits
        relay = len(traits.output_terminals) - 1
        values: dict[str, Any] = {
            "faulted": status.faulted, "warning": status.warning, "running_forward": status.forward,
            "running_reverse": status.reverse, "ready": status.ready, "ctrl_from_net": status.ctrl_from_net,
            "ref_from_net": status.ref_from_net, "at_reference": status.at_reference,
            "drive_state": int(status.drive_state), "speed_actual": speed_word(status.speed_actual),
            "torque_actual": inverter.read_code("d012"), "output_current": 0, "zero_speed": status.zero_speed,
            "relay_output": bool(status.outputs >> relay & 1),
            "drive_state_detail": int(status.drive_state_detail), "trip_cause": status.trip_cause,
            "forward_terminal": inverter.local_run > 0,
        }
        for n in range(1, 5):
            values[f"output_{n}"] = n <= relay and bool(status.outputs >> (n - 1) & 1)
        for n in range(1, 9):
            values[f"input_{n}"] = bool(status.inputs >> (n - 1) & 1)
        schema = self.schemas()[instance]
        return schema.encode({name: value for name, value in values.items() if name in schema.field_names})

    # -- Special I/O ---------------------------------------------------------------------------------
    def _special_request(self, data: bytes, now: float) -> None:
        request = omron_schemas()[100].decode(data)
        function = request["function_code"]
        if function in (SPECIAL_WRITE_WORD, SPECIAL_WRITE_DOUBLE) and data == self.special.last_request:
            return
        self.special.last_request = bytes(data)
        self.special.response = self.special_io(function, request["register_number"], request["data_word_0"],
                                                request["data_word_1"], now)

    def special_io(self, function: int, address: int, word_0: int, word_1: int, now: float) -> bytes:
        """Execute one Special I/O request; returns the bytes of input 150 (Table B-16)."""
        schema = omron_schemas()[150]
        fault = self._special_fault(function, address)
        if fault is None:
            inverter = self.inverter
            found = inverter.registers.word(address)
            assert found is not None
            parameter = found[0]
            try:
                if function == SPECIAL_READ_WORD:
                    return schema.encode(function_code=function, register_number=address,
                                         data_word_0=inverter.read_word(address))
                if function == SPECIAL_READ_DOUBLE:
                    value = inverter.read(address) & 0xFFFFFFFF
                    return schema.encode(function_code=function, register_number=address,
                                         data_word_0=value & 0xFFFF, data_word_1=value >> 16)
                value = word_0 if function == SPECIAL_WRITE_WORD else word_1 << 16 | word_0
                if parameter.signed:
                    bits = 16 if function == SPECIAL_WRITE_WORD else 32
                    if value >= 1 << (bits - 1):
                        value -= 1 << bits
                inverter.write(address, value, now)
                return schema.encode(function_code=function, register_number=address)
            except InverterModeError:
                fault = FAULT_WRITING_MODE
            except RegisterError as exc:
                # A save the state file did not take is the device failing: 04h, the nearest of Table B-17.
                fault = {RegisterRefusal.OUT_OF_RANGE: FAULT_DATA_SETTING,
                         RegisterRefusal.NO_SUCH_REGISTER: FAULT_REGISTER_NUMBER,
                         RegisterRefusal.SAVE_FAILED: FAULT_SLAVE_DEVICE}.get(exc.refusal, FAULT_WRITING_MODE)
        log.debug("Special I/O %02Xh %04Xh: fault %02Xh, %s", function, address, fault, SPECIAL_FAULTS[fault])
        return schema.encode(function_code=(function | SPECIAL_FAILURE) & 0xFF, register_number=address,
                             data_word_0=fault)

    def _special_fault(self, function: int, address: int) -> int | None:
        """Table B-17 checks made before the inverter is asked."""
        if function not in SPECIAL_FUNCTION_CODES:
            return FAULT_FUNCTION_CODE
        if not self.inverter_link_ok:
            return FAULT_SLAVE_DEVICE
        found = self.inverter.registers.word(address)
        if found is None:
            return FAULT_REGISTER_NUMBER
        parameter, index = found
        double = function in (SPECIAL_READ_DOUBLE, SPECIAL_WRITE_DOUBLE)
        # 23h: 2-byte access to a 4-byte register or 4-byte access to a 2-byte one; the second word of a
        # double word alone is a word.
        if double != (parameter.words == 2 and index == 0):
            return FAULT_REGISTER_SIZE
        return None

    # -- class 1 -----------------------------------------------------------------------------------
    def pairs(self) -> set[tuple[int, int]]:
        """The assembly pairs of Table 10 the device serves now (139/159 while the flexible format is active)."""
        return {(output, input_) for _, output, input_ in CONNECTION_PATHS.values()
                if output in self.assembly.points and input_ in self.assembly.points}

    @property
    def default_pair(self) -> tuple[int, int]:
        """The pair of the default connection path: P046 at the last start, as the Connection object holds it."""
        return self.connection.pair

    def pair_sizes(self) -> tuple[int, int]:
        """(output bytes, input bytes) of the default pair (the ``[CompoNet_IO]`` sizes, in bytes)."""
        output, input_ = self.default_pair
        mapping = self.inverter.flexible
        flexible = (len(mapping.outputs), len(mapping.inputs)) if mapping is not None else None
        return pair_sizes(output, input_, flexible)

    def io_profile(self) -> IoProfile | None:
        points = self.assembly.points
        return IoProfile(consumed=lambda: {i: p for i, p in points.items() if p.consumed},
                         produced=lambda: {i: p for i, p in points.items() if not p.consumed},
                         pairs=self.pairs)

    def io_opened(self, connection: IoConnection) -> None:
        super().io_opened(connection)

    def io_closed(self, connection: IoConnection, timed_out: bool) -> None:
        super().io_closed(connection, timed_out)
        if timed_out:
            # Table 12 / Table 26: connection time-out, the P045 action.
            self.inverter.on_network_error(self.now)

    def io_run_idle(self, connection: IoConnection, run: bool) -> None:
        super().io_run_idle(connection, run)
        if run:
            self.inverter.on_network_ok(self.now)
        else:
            self.inverter.on_idle(self.now)   # Table 12: the P048 action

    def update_io_status(self) -> None:
        # Table C-2 (CompoNet manual): the status is "communications status for CompoNet Option Board"
        # with bits 0 (always ON) and 8-11 (the four fault bits) only; the extended device status
        # of bits 4-7 is not the board's, so it stays 0. The fault bits follow the board's faults
        # (the MS indicator, Table 4: a flexible configuration rejected, the node address changed),
        # never an inverter trip: a trip (E62 forced by the network too) shows in Control
        # Supervisor 0x29 (Faulted, Fault Code), not in Identity (Table 24 leaves MS green for it).
        super().update_io_status()
        status = STATUS_ALWAYS_ON
        if self.inverter.flexible_error is not None:
            status |= IdentityStatus.MAJOR_RECOVERABLE_FAULT   # appendix F Note 5
        if self.node_setting() != self.link.mac_id:
            status |= IdentityStatus.MINOR_RECOVERABLE_FAULT   # Table 4: node address changed (MS flashing red)
        self.identity.set(1, 5, status)

    # -- time, resets, saves ---------------------------------------------------------------------------
    def advance(self, now: float) -> None:
        self._now = max(self.now, now)
        self.inverter.advance(self._now)
        self.update_io_status()

    def next_deadline(self) -> float | None:
        return self.inverter.next_deadline()

    def reset(self, reset_type: int) -> None:
        """Identity Reset (Table C-1, appendix E Example 1): the option board restarts and re-reads its
        configuration (P046, P160-P179, P190)."""
        self._restart_board()

    def _restart_board(self) -> None:
        """The option board returns to its initial status (Table C-1, "Reset (return to initial status)"):
        its output assemblies hold zeros, as at power-on (Table C-6 defaults 00 ...), the Special I/O
        exchange starts afresh, and the inverter forgets what the network commanded (Net Ctrl, Net Ref,
        run bits: ``Inverter.reset_option_board``); then it reads its configuration again. The
        inverter itself keeps its power: what it was told and did not save stays, it goes on running
        or stopping as the cleared run bits say."""
        for instance, point in self.assembly.points.items():
            if point.consumed:
                self.assembly.stores[instance][:] = bytes(point.size)
        self.special = SpecialIo()
        self.inverter.reset_option_board(self.now)
        self._start()

    def power_cycle(self, now: float) -> None:
        """The inverter loses its power, and the option board it feeds with it; both come back at ``now``.
        Unlike the Identity Reset (``reset``: the board alone), the inverter restarts too, with its
        EEPROM and nothing else (``Inverter.power_cycle`` cites the manual); the board starts as at
        power-on: zeros in its assemblies, a fresh Special I/O exchange, the node address, P046 and
        the flexible mapping read again (section 1-1-1)."""
        self._now = max(self.now, now)
        self.special = SpecialIo()
        self.inverter.power_cycle(self._now)
        super().power_cycle(self._now)
        self._start()

    def _saved(self, values: dict[int, int]) -> None:
        """The inverter's EEPROM save, handed to the state writer (which may refuse it: StateFileError)."""
        if self.saves is not None:
            self.saves.request({**values, CONSISTENCY_KEY: self.inverter.consistency_value})

    def drive_trips(self) -> DriveTrips:
        """The trip codes of Table D-5 this family has, each reported as the emulator names it ("E05
        Overload protection")."""
        def reset() -> TripReport | None:
            cleared = self.reset_trip()
            return None if cleared is None else TripReport(cleared.label)

        return DriveTrips(inject=lambda code: TripReport(self.inject_trip(code).label), check=self.check_trip_code,
                          reset=reset, codes=self.trip_codes, choices=self.trip_choices)

    def reset_trip(self) -> TripCode | None:
        """The Digital Operator's STOP/RESET key clears the trip present (section 4-5-2, Table 25 Step
        II): which one it was, None when the inverter had none."""
        present = self.inverter.trip
        if not present:
            return None
        self.inverter.press_stop_reset(self.now)
        return trip_code(self.family, present)

    def _trip_of(self, code: int | str) -> tuple[int, TripCode]:
        """En (Table D-5) given as n or as "En": its number and trip; ``ValueError`` for what is no
        trip code, ``KeyError`` for a code the family does not have."""
        text = str(code).strip().upper()
        try:
            number = int(text[1:] if text.startswith("E") else text)
        except ValueError:
            raise BadRequest(f"not a trip code of Table D-5: {code!r} (e.g. 5 or E05)") from None
        return number, trip_code(self.family, number)

    def check_trip_code(self, code: int | str) -> None:
        self._trip_of(code)

    def inject_trip(self, code: int | str) -> TripCode:
        """Trip the inverter with En (Table D-5), given as n or as "En", for test rigs; returns the trip."""
        number, trip = self._trip_of(code)
        if self.inverter.trip:
            # The inverter keeps its first trip until it is reset (Table D-4 Fault Code: one code).
            raise TripRefused(f"the inverter is already tripped: E{self.inverter.trip:02d}; it keeps that trip "
                             f"until a Fault Rst, so E{number:02d} is not taken")
        self.inverter.raise_trip(self.now, number)
        return trip

    # -- CompoNet word slave ---------------------------------------------------------------------------
    @property
    def node_address(self) -> int:
        return self.link.mac_id

    def componet_sizes(self) -> tuple[int, int]:
        """(output bytes, input bytes) the CompoNet master exchanges: the default pair (section 3-3)."""
        return self.pair_sizes()

    def componet_refresh(self, output: bytes | None, now: float) -> bytes:
        """One communications cycle: the master's output words in (None: the master is idle, P048),
        the input words out."""
        self.advance(now)
        out_instance, in_instance = self.default_pair
        if output is None:
            self.inverter.on_idle(self.now)
        elif out_instance in self.assembly.points:
            self.assembly.deliver(out_instance, output, self.now)
        return self.assembly.data(in_instance) if in_instance in self.assembly.points else b""

    def componet_lost(self, now: float) -> None:
        """Communication lost (Table 26): the P045 action."""
        self.advance(now)
        self.inverter.on_network_error(self.now)

    def componet_duplicate(self, now: float) -> None:
        """Node address duplication (Table 26): E61 (MX2) / E71 (RX), Table D-5."""
        self.advance(now)
        self.inverter.raise_trip(self.now, self.inverter.traits.option_trip_base + 1)

    def componet_baud_rate(self, code: int) -> None:
        """Automatic baud rate recognition (section 1-1-1): the master's rate, as CompoNet Link attribute 2."""
        self.link.baud_rate = code

    # -- shells ----------------------------------------------------------------------------------------
    def keypad(self) -> DigitalOperator:
        """The inverter's Digital Operator: function codes (F001, A004, P044...) in the operator's unit."""
        from .operator import DigitalOperator

        return DigitalOperator(self)

    def trip_codes(self) -> str:
        """The trip numbers of Table D-5 this family has (5 or E05)."""
        return " ".join(str(t.number) for t in TRIP_CODES if self.family in t.families) + " (or as En, e.g. E05)"

    def trip_choices(self) -> list[dict[str, object]]:
        """The trip codes of Table D-5 this family has (CompoNet manual), with the CIP fault code."""
        return [{"code": t.code, "label": f"{t.code} {t.name}", "fault_code": t.cip_code}
                for t in TRIP_CODES if self.family in t.families]

    def status_fields(self) -> dict[str, object]:
        status = self.inverter.status()
        return {
            "model": self.model.name if self.model else None, "node": self.link.mac_id,
            "state": status.drive_state.name.lower(), "output_frequency_hz": status.output_frequency / 100,
            "speed_actual": status.speed_actual, "speed_reference": self.inverter.option_command.speed_reference,
            "speed_unit": self.inverter.speed_unit.value,
            "trip": f"E{status.trip_cause:02d}" if status.trip_cause else None,
            "connection_path": self.inverter.connection_path,
            # What the panel shows "not simulated" for: no motor or load model (objects.AcDcDriveObject).
            "not_simulated": ["output_current_a"],
        }

    def status_line(self) -> str:
        f = self.status_fields()
        return (f"{f['model'] or '?'} node {f['node']}: {f['state']} {f['output_frequency_hz']:.2f} Hz (speed "
                f"{f['speed_actual']}, reference {f['speed_reference']} [{f['speed_unit']}]) trip {f['trip'] or '-'} "
                f"P046={f['connection_path']}")

    def catalog_classes(self) -> tuple[ClassSpec, ...]:
        """The class declarations a scanner needs to decode this device's replies."""
        return CLASS_SPECS


def build_omron_device(model_name: str, interface: NetworkInterface | None = None,
                       limits: DeviceLimits | None = None, state_path: Path | None = None,
                       ethernet: bool = True, rotary_switches: int = 0,
                       files: tuple[StoredFile, ...] = ()) -> OmronDevice:
    """An emulated MX2 or RX of Tables 2/3 with its option board; ``ethernet=False`` for a CompoNet-only
    slave (no TCP/IP or Ethernet Link object). The serial number comes from the interface's MAC.
    ``files``: what its File object serves (its EDS file, ``cipstack.objects.file``)."""
    inverter_model = model(model_name)
    interface = interface or NetworkInterface()
    serial = int.from_bytes(interface.mac[-4:], "big")
    return OmronDevice(omron_identity(inverter_model, serial), interface, limits or DeviceLimits(), ethernet,
                       model=inverter_model, state_path=state_path, rotary_switches=rotary_switches, files=files)


# -- a CompoNet network behind an EtherNet/IP gateway -------------------------------------------------

#: Assembly instances of the gateway: the master's OUT area (words 0-63, what the master sends the
#: slaves; settable) and IN area (words 0-63, what the slaves answered). Word n belongs to node n
#: and the words after it that node occupies (section 3-3).
GATEWAY_OUT_AREA = 100
GATEWAY_IN_AREA = 101
#: The gateway's own identity: the manual describes no EtherNet/IP gateway, so these are the
#: emulator's: OMRON's vendor ID, device type 0Ch (communications adapter).
GATEWAY_DEVICE_TYPE = 0x0C
GATEWAY_PRODUCT_CODE = 1
GATEWAY_PRODUCT_NAME = "CompoNet Gateway"


@dataclass
class CompoNetGatewayDevice(Device):
    """An EtherNet/IP target whose Connection Manager routes port 2 into a simulated CompoNet network."""

    network: CompoNetNetwork | None = None
    slaves: tuple[OmronDevice, ...] = ()

    def __post_init__(self) -> None:
        super().__post_init__()
        network = self.network if self.network is not None else CompoNetNetwork()
        self.network = network
        self.gateway = CompoNetGateway(network)
        self.gateway.register(self.connection_manager.routes)
        self.assembly.add_assembly(AssemblyPoint(GATEWAY_OUT_AREA, len(network.out_area), True,
                                                 consume=self._outputs, name="CompoNet OUT area"))
        self.assembly.add_assembly(AssemblyPoint(GATEWAY_IN_AREA, len(network.in_area), False,
                                                 produce=lambda: bytes(network.in_area), name="CompoNet IN area"))

    def _outputs(self, data: bytes, now: float) -> None:
        assert self.network is not None
        self.network.write_out_area(data)

    def slave(self, node: int) -> OmronDevice:
        for slave in self.slaves:
            if slave.node_address == node:
                return slave
        raise UnknownKey(f"no slave at node {node}")

    def advance(self, now: float) -> None:
        assert self.network is not None
        self.gateway.now = max(self.gateway.now, now)
        self.network.advance(self.gateway.now)

    def power_cycle(self, now: float) -> None:
        """The gateway loses its power and gets it back: its master starts as it started, idle with a
        zero OUT area until the originator writes the area again, so each slave gets idle cycles (its
        P048 action, Table 12). The slaves are inverters with power of their own: they keep it."""
        assert self.network is not None
        self.advance(now)
        super().power_cycle(now)
        self.network.out_area[:] = bytes(len(self.network.out_area))
        self.network.run = False

    def next_deadline(self) -> float | None:
        assert self.network is not None
        return self.network.next_deadline()

    def status_line(self) -> str:
        assert self.network is not None
        lines = [f"CompoNet gateway, port {COMPONET_PORT}, {len(self.slaves)} slave(s)", *self.network.status_lines()]
        lines.extend(slave.status_line() for slave in self.slaves)
        return "\n".join(lines)

    def catalog_classes(self) -> tuple[ClassSpec, ...]:
        return CLASS_SPECS


def build_componet_gateway(nodes: list[tuple[str, str, int]], interface: NetworkInterface | None = None,
                           limits: DeviceLimits | None = None) -> CompoNetGatewayDevice:
    """A gateway with one option-board slave per (profile "mx2"|"rx", model, node address 0-63); each
    slave's rotary switches are set to its node address and its P046 pair is what the master exchanges."""
    interface = interface or NetworkInterface()
    network = CompoNetNetwork()
    slaves = []
    for profile, model_name, node in nodes:
        inverter_model = model(model_name)
        if inverter_model.family.value.lower() != profile.lower():
            raise BadRequest(f"{model_name} is an {inverter_model.family.value}, not a {profile} model")
        if not 0 <= node < NODE_ADDRESSES:
            raise BadRequest(f"node address {node} outside 0-63")
        slave_interface = NetworkInterface(mac=interface.mac[:-1] + bytes([node]))
        slaves.append(build_omron_device(model_name, slave_interface, DeviceLimits(), ethernet=False,
                                         rotary_switches=node))
    serial = int.from_bytes(interface.mac[-4:], "big")
    identity = IdentityInfo(VENDOR_ID, GATEWAY_DEVICE_TYPE, GATEWAY_PRODUCT_CODE, REVISION, serial,
                            GATEWAY_PRODUCT_NAME)
    device = CompoNetGatewayDevice(identity, interface, limits or DeviceLimits(), network=network,
                                   slaves=tuple(slaves))
    for slave in slaves:
        network.attach(slave, 0.0)
    return device
