"""What the EDS descriptions of the device families share, built from the devices themselves.

Each family's own description lives in its package and is named by its declaration
(``Profile.eds``, ``"module:function"``): the ACG's in ``devices/acg/eds_file.py``, the Omron
boards' in ``devices/omron/eds_file.py``, a family from another distribution in its own.

* ``device_object_classes(device)``: an object class section for every class a device serves.
* ``eds_file_name(description)``: the file the description is written to.
"""

from __future__ import annotations

from ..devices.base import Device
from .description import EdsDescription, EdsObjectClass

#: ``ProdTypeStr`` of device type 2: the CIP AC drive profile (ACG-ET2 manual: "Device Type (drive) 2";
#: CompoNet manual, Table 1: "CompoNet Profile AC Drive (0x02)").
AC_DRIVE = "AC Drive"


def device_object_classes(device: Device) -> tuple[EdsObjectClass, ...]:
    """An object class section for every class the device's message router serves, with the
    instances it has (the generator leaves out Assembly and Connection Manager, which have
    sections of their own)."""
    return tuple(EdsObjectClass(obj.spec, len(obj.instances))
                 for _, obj in sorted(device.router.objects.items()))


def eds_file_name(description: EdsDescription) -> str:
    """The description's file name, else ``<catalog>_<major>.<minor>.eds`` (``ACG-ET2_1.01.eds``:
    the revision as the ACG-ET2 shows its version, ACG-ET2 manual Identity attribute 4 note)."""
    if description.file_name:
        return description.file_name
    major, minor = description.identity.revision
    safe = "".join(char if char.isalnum() or char in "-_." else "_" for char in description.catalog)
    return f"{safe}_{major}.{minor:02d}.eds"
