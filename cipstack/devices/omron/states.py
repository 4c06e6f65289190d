"""The inverter's states and commands as the option board sees them: Drive State (Table D-4),
the network actions of P045/P048 (Table 12), run and frequency sources, the master's command
fields and the status the assemblies report."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from enum import Enum, IntEnum
from typing import TYPE_CHECKING

from ...assemblies.drive_profile import DriveState
from ..registers import RegisterError
from .registers import (
    SpeedUnit,
)

if TYPE_CHECKING:
    from .flexible import FlexibleMapping, FlexibleMappingError


class DriveStateDetail(IntEnum):
    """Drive Status Detail of assembly 111 and Control Supervisor attribute 0x64 (Tables B-27, D-4)."""

    STOPPING = 0
    RUNNING = 1
    JOGGING = 2
    FREE_RUNNING = 3
    DC_BRAKING = 4
    PICKUP = 5
    RETRY_PICKUP = 7
    RETRY_WAITING = 8
    TRIP = 10
    UNDERVOLTAGE = 11


class NetworkAction(IntEnum):
    """P045 (network error) and P048 (network idle) settings (Table 12)."""

    TRIP = 0
    DECELERATE_AND_TRIP = 1
    NONE = 2
    FREE_RUN = 3
    DECELERATE_AND_STOP = 4


class Source(Enum):
    """Where the run command or the frequency reference comes from."""

    OPTION_BOARD = "option board"   # A001/A002 = 4 (MX2) / 5 (RX), or the NetCtrl/NetRef override
    MODBUS = "Modbus"               # A001/A002 = 3: coil data 0 and F001 (flexible format)
    OPERATOR = "digital operator"   # A001 = 2: F001
    LOCAL = "local"                 # terminals and other local sources


@dataclass(frozen=True)
class OptionCommand:
    """What the master commands through the option board (appendix B outputs, Tables D-4, D-7, C-10, C-12)."""

    fwd: bool = False               # FWD, Control Supervisor Run1
    rev: bool = False               # REV, Run2
    fault_reset: bool = False       # RST, Fault Rst
    force_fault: bool = False       # FFL, Force Fault
    net_ctrl: bool = False          # CTR, Net Ctrl
    net_ref: bool = False           # REF, Net Ref
    free_run: bool = False          # FRS (assembly 110), Free Run (0x29 attribute 0x66)
    #: Rotational Speed Reference in the current speed unit (0.01 Hz, 0.1 Hz or RPM, section 4-2-5).
    speed_reference: int = 0
    #: Acceleration/deceleration times of assembly 110 in seconds; used while REF is set (Table B-25).
    accel_time: float | None = None
    decel_time: float | None = None
    torque_reference: int = 0       # % (Tables B-9, B-18)
    torque_bias: int = 0            # %
    #: CI3-CI8 and Discrete Input Point overrides: bit n-1 overrides input terminal [n] (Tables B-19, C-10).
    input_overrides: int = 0
    #: CO1-CO5, CR and Discrete Output Point values: bit i sets output ``traits.output_terminals[i]``.
    outputs: int = 0


@dataclass(frozen=True)
class Status:
    """A snapshot of everything the input assemblies and the status attributes report."""

    faulted: bool                   # FLT
    warning: bool                   # WR
    forward: bool                   # DFR, Running1
    reverse: bool                   # DRR, Running2
    ready: bool                     # RDY
    running: bool                   # RUN coil: the inverter drives the motor
    ctrl_from_net: bool             # CFN
    ref_from_net: bool              # RFN
    at_reference: bool              # ARF
    zero_speed: bool                # DZS
    drive_state: DriveState
    drive_state_detail: DriveStateDetail
    trip_cause: int                 # n of En, 0 when not tripped
    fault_code: int                 # CIP fault code of the trip (Table D-5), 0 when not tripped
    force_status: bool              # Force Status
    output_frequency: int           # 0.01 Hz, magnitude
    speed_unit: SpeedUnit
    speed_actual: int               # Rotational Speed Monitor in ``speed_unit``, magnitude
    inputs: int                     # intelligent input terminals, bit n-1 = terminal [n]
    outputs: int                    # output terminals, in ``traits.output_terminals`` order
    status_c: int                   # inverter status C (0005h)


class InverterState:
    """What one inverter and its option board are at one instant: the state the components of
    ``Inverter`` share (given it at construction) and change."""

    # Read many times per class 1 datagram: slots keep each read one step.
    __slots__ = ("armed_fwd", "armed_rev", "armed_rst", "cmd", "coils", "connection_path", "flexible",
                 "flexible_error", "force_status", "free_run_inputs", "frequency", "idle", "last_ok", "last_trip",
                 "local_reference", "local_run", "net_error", "pending_trip", "run_since", "t", "terminal_functions",
                 "terminals", "trip", "values")

    def __init__(self, values: Mapping[str, int], now: float) -> None:
        #: Physical intelligent input terminals, bit n-1 = terminal [n] (the test rig's wiring).
        self.terminals = 0
        #: Run command of the local sources (FW/RV terminals, operator): +1, -1 or 0.
        self.local_run = 0
        #: Frequency reference of the local sources (terminal analog input), 0.01 Hz.
        self.local_reference = 0
        #: The last trip (d081), kept across a power cycle.
        self.last_trip = 0
        self.power_on(values, now)

    def power_on(self, values: Mapping[str, int], now: float) -> None:
        """The inverter switched on at ``now`` with ``values`` (function code -> value)."""
        self.t = now
        self.values: dict[str, int] = dict(values)
        self.frequency = 0.0            # signed output frequency, 0.01 Hz (negative: reverse)
        self.trip = 0                   # n of En, 0 when not tripped
        self.pending_trip = 0           # trip to raise once a "deceleration and trip" stop ends
        self.force_status = False
        self.cmd = OptionCommand()
        self.coils = 0
        self.last_ok: float | None = None
        self.run_since: float | None = None
        self.net_error = False
        self.idle = False
        # What the option board read from the inverter at its start (``OptionBoard.start``).
        self.terminal_functions: tuple[int, ...] = ()
        #: The input terminals whose function is FRS (free-run stop), bit n-1 = terminal [n].
        self.free_run_inputs = 0
        self.connection_path = 0
        # Note to Tables B-2/B-6/B-10/B-19/B-25: FWD, REV and RST act only after a 0 -> 1 transition
        # following power-on or a trip reset; "armed" means the bit has been seen at 0 since.
        self.armed_fwd = self.armed_rev = self.armed_rst = False
        self.flexible: FlexibleMapping | None = None
        self.flexible_error: FlexibleMappingError | None = None

    def raise_trip(self, number: int) -> None:
        """Trip the inverter with En (none if it is tripped already): the output is cut."""
        if self.trip:
            return
        self.trip = self.last_trip = number
        self.pending_trip = 0
        self.frequency = 0.0   # the output is cut; the speed monitor reads 0


class InverterModeError(RegisterError):
    """A torque-related register written outside the constant-torque IM mode (section 4-4 note)."""


_EPSILON = 1e-6
_OPR = 1 << 1
_DIR = 1 << 2
_EXT = 1 << 3
_RS = 1 << 4
_IN_SHIFT = 7    # coil data 0 bit 7 is intelligent input [1] (Table 18)


__all__ = ["DriveState", "DriveStateDetail", "InverterModeError", "InverterState", "NetworkAction", "OptionCommand",
           "Source", "Status"]
