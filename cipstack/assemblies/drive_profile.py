"""The AC drive profile assemblies both device families share: basic and extended speed
control, output 20/21 and input 70/71, in byte 0 flags + speed word layout.

The bit layout is the same in the ACG-ET2 appendix (ACG-ET2 manual, input instances 70/71/110/111,
output instances 20/21/100/101) and the Omron option board manual (CompoNet manual, Tables B-1 to
B-8); the families differ in the unit of the speed words, so the unit is a parameter and
each family names its own instances (the ACG's 100/101/110/111 are these layouts in Hz).
Each field links the Control Supervisor (0x29) or AC/DC Drive (0x2A) attribute it mirrors.
"""

from __future__ import annotations

from enum import IntEnum

from ..cip.types import INT, USINT
from .schema import AssemblyField, AssemblySchema, bit, word

CONTROL_SUPERVISOR = 0x29
AC_DC_DRIVE = 0x2A


class DriveState(IntEnum):
    """Control Supervisor attribute 6 "Drive State", the byte ``drive_state`` of input 71 carries.

    One state machine for both families: the ACG lists 0-6 (ACG-ET2 manual, class 0x29 attribute 6),
    the Omron option board 1-7 (CompoNet manual, Tables B-8 and D-4), Faulted being the state a
    trip holds after its Fault Stop."""

    VENDOR_SPECIFIC = 0
    STARTUP = 1
    NOT_READY = 2
    READY = 3
    ENABLED = 4
    STOPPING = 5
    FAULT_STOP = 6
    FAULTED = 7


def _speed(name: str, unit: str, scale: float, attribute: int, help_text: str) -> AssemblyField:
    return word(name, 2, INT, unit=unit, scale=scale, help=help_text, link=(AC_DC_DRIVE, 1, attribute))


def basic_speed_control_output(instance: int = 20, unit: str = "rpm", scale: float = 1.0) -> AssemblySchema:
    return AssemblySchema(instance, "Basic Speed Control Output", 4, [
        bit("run_forward", 0, 0, help="Forward run command", link=(CONTROL_SUPERVISOR, 1, 3)),
        bit("fault_reset", 0, 2, help="Fault reset on a 0 to 1 transition", link=(CONTROL_SUPERVISOR, 1, 12)),
        _speed("speed_reference", unit, scale, 8, "Speed reference"),
    ])


def extended_speed_control_output(instance: int = 21, unit: str = "rpm", scale: float = 1.0) -> AssemblySchema:
    return AssemblySchema(instance, "Extended Speed Control Output", 4, [
        bit("run_forward", 0, 0, help="Forward run command", link=(CONTROL_SUPERVISOR, 1, 3)),
        bit("run_reverse", 0, 1, help="Reverse run command", link=(CONTROL_SUPERVISOR, 1, 4)),
        bit("fault_reset", 0, 2, help="Fault reset on a 0 to 1 transition", link=(CONTROL_SUPERVISOR, 1, 12)),
        bit("net_ctrl", 0, 5, help="Run command from the network", link=(CONTROL_SUPERVISOR, 1, 5)),
        bit("net_ref", 0, 6, help="Speed reference from the network", link=(AC_DC_DRIVE, 1, 4)),
        _speed("speed_reference", unit, scale, 8, "Speed reference"),
    ])


def basic_speed_control_input(instance: int = 70, unit: str = "rpm", scale: float = 1.0) -> AssemblySchema:
    return AssemblySchema(instance, "Basic Speed Control Input", 4, [
        bit("faulted", 0, 0, help="Fault or trip", link=(CONTROL_SUPERVISOR, 1, 10)),
        bit("running_forward", 0, 2, help="Running forward", link=(CONTROL_SUPERVISOR, 1, 7)),
        _speed("speed_actual", unit, scale, 7, "Actual speed"),
    ])


def extended_speed_control_input(instance: int = 71, unit: str = "rpm", scale: float = 1.0,
                                 ctrl_from_net_attribute: int = 15) -> AssemblySchema:
    """``ctrl_from_net_attribute``: the Control Supervisor attribute the bit mirrors, 15 in the AC drive
    profile and Omron's Table D-4; the ACG serves it at 14 (the ACG-ET2 manual's object table)."""
    return AssemblySchema(instance, "Extended Speed Control Input", 4, [
        bit("faulted", 0, 0, help="Fault or trip", link=(CONTROL_SUPERVISOR, 1, 10)),
        bit("warning", 0, 1, help="Warning", link=(CONTROL_SUPERVISOR, 1, 11)),
        bit("running_forward", 0, 2, help="Running forward", link=(CONTROL_SUPERVISOR, 1, 7)),
        bit("running_reverse", 0, 3, help="Running reverse", link=(CONTROL_SUPERVISOR, 1, 8)),
        bit("ready", 0, 4, help="Ready", link=(CONTROL_SUPERVISOR, 1, 9)),
        bit("ctrl_from_net", 0, 5, help="Run command comes from the network",
            link=(CONTROL_SUPERVISOR, 1, ctrl_from_net_attribute)),
        bit("ref_from_net", 0, 6, help="Speed reference comes from the network", link=(AC_DC_DRIVE, 1, 29)),
        bit("at_reference", 0, 7, help="Speed has reached the reference", link=(AC_DC_DRIVE, 1, 3)),
        AssemblyField("drive_state", 1, USINT, help="Drive state (Control Supervisor attribute 6)",
                      link=(CONTROL_SUPERVISOR, 1, 6)),
        _speed("speed_actual", unit, scale, 7, "Actual speed"),
    ])
