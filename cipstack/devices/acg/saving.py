"""How the ACG saves its parameters over CIP, for a scanner's recipe (``cipstack params load``)."""

from __future__ import annotations

from ...catalog import SaveProcedure
from .objects import KEYPAD_PARAMETERS
from .registers import ACG_REGISTERS, SAVE_PARAMETERS, class64_path


def _para_control_1() -> tuple[int, int, int]:
    path = class64_path(ACG_REGISTERS.by_code("CM.51"))
    assert path is not None   # CM is a group of class 0x64
    return (KEYPAD_PARAMETERS, *path)


#: CM.51 (Para Control-1, ACG-ET2 manual) points the first word of output assembly 121 (the smart-scaling
#: output instances 121-128) at 0x03E0 "Save parameters" (ACG RS-485 manual, 0x03E0-0x03EC), whose 0 -> 1
#: change saves; CM.51 then gets its value back.
SAVE_OVER_CIP = SaveProcedure(pointer=_para_control_1(), target=SAVE_PARAMETERS.address, trigger=(0x04, 121, 3),
                              edges=(0, 1), width=2)

__all__ = ["SAVE_OVER_CIP"]
