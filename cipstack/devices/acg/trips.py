"""Trips: the "Drive Fault Codes" table (ACG-ET2 manual, class 0x29 attribute 13) with the trip bits of
the monitoring words 0x0330-0x0335 (ACG RS-485 manual)."""

from __future__ import annotations

from enum import Enum
from typing import TYPE_CHECKING

from ...errors import BadRequest
from .status_words import LatchTrip1, LatchTrip2, LevelTrip

if TYPE_CHECKING:
    from .ramps import Ramp
    from .state import AcgState


class Trip(Enum):
    """The trips of the "Drive Fault Codes" table (ACG-ET2 manual, class 0x29 attribute 13).

    Each value: display name, fault code, the monitoring word that shows it and its bit there
    (ACG RS-485 manual, 0x0330-0x0335; None where that table has no bit for it), and whether it is a
    level-type trip (0x0332), which clears by itself once its cause is gone.
    The table lists 0x2330 twice (GFT and GroundTrip, both the ground fault of 0x0330 B4) and an
    "UNDEFINED" entry under 0x1000, which is no trip and is left out.
    """

    ETHERMAL = ("Ethermal", 0x1000, 0x0330, LatchTrip1.E_THERMAL)
    OUT_PHASE_OPEN = ("Out Phase Open", 0x1000, 0x0330, LatchTrip1.OUTPUT_OPEN_PHASE)
    INVERTER_OLT = ("InverterOLT", 0x1000, 0x0330, LatchTrip1.DRIVE_OVERLOAD)
    IN_PHASE_OPEN = ("InPhaseOpen", 0x1000, 0x0330, LatchTrip1.INPUT_OPEN_PHASE)
    THERMAL_TRIP = ("ThermalTrip", 0x1000, None, 0)
    UNDER_LOAD = ("UnderLoad", 0x1000, 0x0330, LatchTrip1.UNDERLOAD)
    PARA_WRITE_TRIP = ("ParaWriteTrip", 0x1000, None, 0)
    IO_BOARD_TRIP = ("IOBoardTrip", 0x1000, 0x0331, LatchTrip2.BAD_CONTACT_IO_BOARD)
    PRE_PID_FAIL = ("PrePIDFail", 0x1000, 0x0331, LatchTrip2.PRE_PID_FAIL)
    OPTION_TRIP_1 = ("OptionTrip1", 0x1000, 0x0331, LatchTrip2.BAD_OPTION_CARD)
    OPTION_TRIP_2 = ("OptionTrip2", 0x1000, None, 0)
    OPTION_TRIP_3 = ("OptionTrip3", 0x1000, None, 0)
    LOST_COMMAND = ("LostCommand", 0x1000, 0x0332, LevelTrip.LOST_COMMAND, True)
    LOST_KEYPAD = ("LostKeypad", 0x1000, 0x0332, LevelTrip.KEYPAD_LOST_COMMAND, True)
    OVER_LOAD = ("OverLoad", 0x2200, 0x0330, LatchTrip1.OVERLOAD)
    OVER_CURRENT_1 = ("OverCurrent1", 0x2310, 0x0330, LatchTrip1.OVERCURRENT)
    GFT = ("GFT", 0x2330, 0x0330, LatchTrip1.GROUND_FAULT)
    OVER_CURRENT_2 = ("OverCurrent2", 0x2340, 0x0330, LatchTrip1.ARM_SHORT)
    OVER_VOLTAGE = ("OverVoltage", 0x3210, 0x0330, LatchTrip1.OVERVOLTAGE)
    LOW_VOLTAGE = ("LowVoltage", 0x3220, 0x0332, LevelTrip.LOW_VOLTAGE, True)
    GROUND_TRIP = ("GroundTrip", 0x2330, 0x0330, LatchTrip1.GROUND_FAULT)
    NTC_OPEN = ("NTCOpen", 0x4000, 0x0330, LatchTrip1.NTC)
    OVER_HEAT = ("OverHeat", 0x4200, 0x0330, LatchTrip1.OVER_HEAT)
    FUSE_OPEN = ("FuseOpen", 0x5000, 0x0330, LatchTrip1.FUSE_OPEN)
    HW_DIAG = ("HWDiag", 0x5000, None, 0)
    FAN_TRIP = ("FanTrip", 0x7000, 0x0331, LatchTrip2.FAN_TRIP)
    NO_MOTOR_TRIP = ("No Motor Trip", 0x7120, 0x0331, LatchTrip2.NO_MOTOR)
    ENCODER_TRIP = ("EncoderTrip", 0x7300, None, 0)
    SPEED_DEV_TRIP = ("SpeedDevTrip", 0x8401, None, 0)
    OVER_SPEED = ("OverSpeed", 0x8402, None, 0)
    EXTERNAL_TRIP = ("ExternalTrip", 0x9000, 0x0330, LatchTrip1.EXTERNAL_TRIP)
    BX = ("BX", 0x9000, 0x0332, LevelTrip.BX, True)

    def __init__(self, label: str, fault_code: int, info_address: int | None, bit: int, level: bool = False) -> None:
        self.label = label
        self.fault_code = fault_code
        self.info_address = info_address
        self.bit = int(bit)
        self.level = level

    @classmethod
    def from_fault_code(cls, code: int) -> Trip:
        """The first trip the table lists under ``code`` (0x1000 -> Ethermal)."""
        for trip in cls:
            if trip.fault_code == code:
                return trip
        raise BadRequest(f"0x{code:04X} is not a trip of the Drive Fault Codes table")


NO_FAULT = 0x0000


class TripLog:
    """Trips and their causes: a trip cuts the output and is logged in the fault history; a latch
    type holds until a Fault Reset, a level type while its cause lasts."""

    def __init__(self, state: AcgState, ramp: Ramp) -> None:
        self._state = state
        self._ramp = ramp

    def trip(self, trip: Trip, free_run: bool = True) -> None:
        """``trip`` occurred: logged; the drive trips unless it is tripped already."""
        state = self._state
        state.fault_history.append(trip)
        if state.trip is not None:
            return
        state.trip = trip
        state.command = None
        if free_run:
            self._ramp.free_run()

    def set_level_cause(self, trip: Trip, active: bool, free_run: bool = True) -> None:
        """The cause of level-type ``trip`` is present (it trips) or gone (the trip clears)."""
        causes = self._state.level_causes
        if active and trip not in causes:
            causes.add(trip)
            self.trip(trip, free_run)
        elif not active and trip in causes:
            causes.discard(trip)
            if self._state.trip is trip:
                self._state.trip = None             # level type: clears with its cause
                self._ramp.settle()

    def reset(self) -> bool:
        """A Fault Reset: whether a trip was cleared."""
        state = self._state
        if state.trip is None or state.trip in state.level_causes:
            return False                            # a level-type trip holds while its cause lasts
        state.trip = None
        return True


__all__ = ["NO_FAULT", "Trip", "TripLog"]
