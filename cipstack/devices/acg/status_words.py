"""The bit fields and codes of the ACG drive's status and command words (ACG RS-485 manual: the
common area's operation command and status, the control area's command word, the monitoring area's
trip, warning and operation words), each as the register map declares it (``registers``)."""

from __future__ import annotations

from collections.abc import Mapping
from enum import IntEnum, IntFlag


class OperationCommand(IntFlag):
    """Common area 0x0006 "Operation command (option)", written bits B0-B4 (ACG RS-485 manual).

    The OCR text reads B3 as "W: Trip (0->1)"; like B2 of the control word 0x0382 ("0 -> 1: Trip
    initialization") it is the trip reset, acting on a 0 -> 1 change.
    """

    STOP = 1 << 0
    FORWARD = 1 << 1
    REVERSE = 1 << 2
    TRIP_RESET = 1 << 3
    EMERGENCY_STOP = 1 << 4


#: 0x0006 read-back: B6-B8 hold the command source, B9-B14 the frequency source (ACG RS-485 manual).
OPERATION_COMMAND_SOURCE_SHIFT = 6
OPERATION_COMMAND_SOURCE_MASK = 0x7
OPERATION_FREQUENCY_SOURCE_SHIFT = 9
OPERATION_FREQUENCY_SOURCE_MASK = 0x3F

#: Frequency-source codes of 0x0006 B9-B14 (ACG RS-485 manual, Compatible Common Area, 0x0006).
COMMON_FREQUENCY_SOURCES: Mapping[int, str] = {
    0: "Keypad Freq", 1: "Keypad Torq limit", **{n: f"Terminal block multi-step speed {n}" for n in range(2, 17)},
    17: "Up", 18: "Down", 19: "STEADY", 22: "V1", 24: "V0", 25: "I2", 26: "Reserved", 27: "Built-in 485",
    28: "Communication option", 30: "JOG", 31: "PID",
}


class ControlCommand(IntFlag):
    """Control area 0x0382 "Operation command" (ACG RS-485 manual): forward run is 0x0003, reverse 0x0001."""

    RUN = 1 << 0            # 0: stop command, 1: run command
    FORWARD = 1 << 1        # 0: reverse command, 1: forward command
    TRIP_RESET = 1 << 2     # 0 -> 1: trip initialization
    FREE_RUN_STOP = 1 << 3  # 0 -> 1: free-run stop


class OperationStatus(IntFlag):
    """Common area 0x000E "Operation status" (ACG RS-485 manual)."""

    STOPPED = 1 << 0
    FORWARD = 1 << 1
    REVERSE = 1 << 2
    FAULT_TRIP = 1 << 3
    ACCELERATING = 1 << 4
    DECELERATING = 1 << 5
    SPEED_REACHED = 1 << 6
    DC_BRAKING = 1 << 7
    STOPPING = 1 << 8
    JOG = 1 << 9
    BRAKE_RELEASE = 1 << 10
    FORWARD_COMMAND = 1 << 11
    REVERSE_COMMAND = 1 << 12
    COMMAND_FROM_COMMUNICATION = 1 << 13
    FREQUENCY_FROM_COMMUNICATION = 1 << 14


class FaultTripInformation(IntFlag):
    """Common area 0x000F "Fault trip information" (ACG RS-485 manual)."""

    LATCH_TYPE_TRIP = 1 << 0
    LEVEL_TYPE_TRIP = 1 << 3
    HW_DIAG = 1 << 10


class LatchTrip1(IntFlag):
    """Monitoring 0x0330 "Latch type trip information - 1" (ACG RS-485 manual)."""

    OVERLOAD = 1 << 0
    UNDERLOAD = 1 << 1
    DRIVE_OVERLOAD = 1 << 2
    E_THERMAL = 1 << 3
    GROUND_FAULT = 1 << 4
    OUTPUT_OPEN_PHASE = 1 << 5
    INPUT_OPEN_PHASE = 1 << 6
    NTC = 1 << 9
    OVERCURRENT = 1 << 10
    OVERVOLTAGE = 1 << 11
    EXTERNAL_TRIP = 1 << 12
    ARM_SHORT = 1 << 13
    OVER_HEAT = 1 << 14
    FUSE_OPEN = 1 << 15


class LatchTrip2(IntFlag):
    """Monitoring 0x0331 "Latch type trip information - 2" (ACG RS-485 manual)."""

    FAN_TRIP = 1 << 3
    PRE_PID_FAIL = 1 << 6
    BAD_CONTACT_IO_BOARD = 1 << 7
    EXTERNAL_BRAKE = 1 << 8
    NO_MOTOR = 1 << 9
    BAD_OPTION_CARD = 1 << 10
    PRE_OVER_HEAT = 1 << 14


class LevelTrip(IntFlag):
    """Monitoring 0x0332 "Level type trip information" (ACG RS-485 manual)."""

    BX = 1 << 0
    LOW_VOLTAGE = 1 << 1
    LOST_COMMAND = 1 << 2
    KEYPAD_LOST_COMMAND = 1 << 3


class HardwareDiagnosis(IntFlag):
    """Monitoring 0x0333 "H/W Diagnosis trip information" (ACG RS-485 manual)."""

    ADC_ERROR = 1 << 0
    EEPROM_ERROR = 1 << 1
    WATCHDOG_1 = 1 << 2
    WATCHDOG_2 = 1 << 3
    QUEUE_FULL = 1 << 5


class WarningInformation(IntFlag):
    """Monitoring 0x0334 "Warning information" (ACG RS-485 manual)."""

    OVERLOAD = 1 << 0
    UNDERLOAD = 1 << 1
    DRIVE_OVERLOAD = 1 << 2
    LOST_COMMAND = 1 << 3
    FAN_RUNNING = 1 << 4
    DB = 1 << 5
    ENCODER_WRONG_INSTALLATION = 1 << 6
    ENCODER_DISCONNECTION = 1 << 7
    KEYPAD_LOST = 1 << 8
    AUTO_TUNING_FAILED = 1 << 9


class LatchTrip3(IntFlag):
    """Monitoring 0x0335 "Latch type trip information - 3" (ACG RS-485 manual; the OCR text prints
    B2 as "Over torque detection", the pattern of B0/B1/B3 makes it detection 2)."""

    OVER_TORQUE_1 = 1 << 0
    UNDER_TORQUE_1 = 1 << 1
    OVER_TORQUE_2 = 1 << 2
    UNDER_TORQUE_2 = 1 << 3


class OperationHealth(IntEnum):
    """0x0305 B12-B15 (ACG RS-485 manual, "Drive operation state")."""

    NORMAL = 0
    WARNING = 4
    FAULT = 8


class OperationPhase(IntEnum):
    """0x0305 B4-B7 (ACG RS-485 manual). The table is garbled: the eight states are listed in this order
    under the label B4-B7 and their numbers are lost; they are numbered 1-8 in that order,
    0 being "none of them" (stopped or running at 0 Hz without a ramp)."""

    NONE = 0
    SPEED_SEARCHING = 1
    ACCELERATING = 2
    CONSTANT_SPEED = 3
    DECELERATING = 4
    DECELERATING_TO_STOP = 5
    HW_OCS = 6
    SW_OCS = 7
    DWELL = 8


class OperationDirection(IntEnum):
    """0x0305 B0-B3 (ACG RS-485 manual): listed in this order under the label B0-B3."""

    STOPPED = 0
    FORWARD = 1
    REVERSE = 2
    DC_OPERATING = 3


OPERATION_HEALTH_SHIFT = 12
OPERATION_PHASE_SHIFT = 4

#: 0x0306 B8-B15 operation command source (ACG RS-485 manual).
MONITOR_COMMAND_SOURCES: Mapping[int, str] = {0: "Keypad", 1: "Communication option", 3: "Built-in RS 485",
                                              4: "Terminal block"}
#: 0x0306 B0-B7 frequency command source (ACG RS-485 manual).
MONITOR_FREQUENCY_SOURCES: Mapping[int, str] = {
    0: "Keypad speed", 1: "Keypad torque limit", 2: "Up/Down operation speed", 3: "Up/Down operation speed",
    4: "Up/Down operation speed", 5: "V1", 7: "V0", 8: "I2", 10: "Built-in RS 485", 11: "Communication option",
    13: "Jog", 14: "PID", **{n: "Multi-step speed frequency" for n in range(25, 40)},
}
MONITOR_COMMAND_SOURCE_SHIFT = 8
