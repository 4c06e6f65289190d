"""cipstack: the Common Industrial Protocol for AC drives over EtherNet/IP and CompoNet.

One import for each thing a user touches::

    from cipstack import SyncScanner

    with SyncScanner("127.0.0.1") as drive:               # identifies the drive, decodes by its profile
        print(drive.read(0x2A, 1, 102))                   # 5.0 s

The scanner (``Scanner`` async, ``SyncScanner`` blocking), discovery, values with their unit, class 1
connections and their process images, EDS files, parameter recipes, the adapter emulator and the
errors (``CipstackError``, the root of every error the package raises on purpose, and its kinds). Each
name is imported when first used, so ``import cipstack`` (and ``cipstack --help``) stays fast.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

__version__ = "0.1.0"

#: Public name -> the module that defines it.
_EXPORTS: dict[str, str] = {
    # the scanner
    "Scanner": "cipstack.scanner",
    "SyncScanner": "cipstack.scanner",
    "AttributeValue": "cipstack.scanner",
    "ReplyDecodeError": "cipstack.scanner",
    "UnknownAttributeError": "cipstack.scanner",
    "backplane_route": "cipstack.scanner",
    "componet_route": "cipstack.scanner",
    "discover": "cipstack.scanner",
    "discover_blocking": "cipstack.scanner",
    "list_services_udp": "cipstack.scanner",
    "Catalog": "cipstack.catalog",
    "IdentityRecord": "cipstack.eip.wire.identity_items",
    # values
    "Value": "cipstack.cip.values",
    "Scaling": "cipstack.cip.values",
    # class 1
    "IoConnectionHandle": "cipstack.eip.originator.io_originator",
    "ProcessImage": "cipstack.eip.originator.process_image",
    "IoTimeoutError": "cipstack.eip.originator.class1",
    "OtFormat": "cipstack.eip.originator.class1",
    "SyncIoConnection": "cipstack.eip.originator.blocking_io",
    "run_precise": "cipstack.eip.io_server",
    "precise_event_loop": "cipstack.eip.io_server",
    # routes
    "PortSegment": "cipstack.cip.epath",
    # errors: the root every error of the package derives from, and its kinds
    "CipstackError": "cipstack.errors",
    "BadRequest": "cipstack.errors",
    "NotFound": "cipstack.errors",
    "StateRefused": "cipstack.errors",
    "PeerUnreachable": "cipstack.errors",
    "ProtocolError": "cipstack.errors",
    "SecurityError": "cipstack.errors",
    "NoReply": "cipstack.errors",
    "NothingListens": "cipstack.errors",
    "UnknownKey": "cipstack.errors",
    "UnknownField": "cipstack.errors",
    "ReadOnlyField": "cipstack.errors",
    "WrongType": "cipstack.errors",
    "WrongState": "cipstack.errors",
    "TimedOut": "cipstack.errors",
    "CipError": "cipstack.cip.status",
    "GeneralStatus": "cipstack.cip.status",
    "MalformedReplyError": "cipstack.eip.originator.replies",
    "EncapsulationStatusError": "cipstack.eip.originator.replies",
    # EDS files
    "read_eds": "cipstack.eds.reader",
    "parse_eds": "cipstack.eds.reader",
    "EdsDocument": "cipstack.eds.model",
    "catalog_from_eds": "cipstack.eds.catalog",
    # parameter recipes
    "dump_params": "cipstack.params",
    "load_params": "cipstack.params",
    "diff_params": "cipstack.params",
    "read_recipe": "cipstack.params",
    "write_recipe": "cipstack.params",
    # the emulator
    "Adapter": "cipstack.adapter",
    "AdapterSettings": "cipstack.adapter",
    "build_device": "cipstack.devices.profiles",
    "PROFILES": "cipstack.devices.profiles",
}

__all__ = [
    "PROFILES",
    "Adapter",
    "AdapterSettings",
    "AttributeValue",
    "BadRequest",
    "Catalog",
    "CipError",
    "CipstackError",
    "EdsDocument",
    "EncapsulationStatusError",
    "GeneralStatus",
    "IdentityRecord",
    "IoConnectionHandle",
    "IoTimeoutError",
    "MalformedReplyError",
    "NoReply",
    "NotFound",
    "NothingListens",
    "OtFormat",
    "PeerUnreachable",
    "PortSegment",
    "ProcessImage",
    "ProtocolError",
    "ReadOnlyField",
    "ReplyDecodeError",
    "Scaling",
    "Scanner",
    "SecurityError",
    "StateRefused",
    "SyncIoConnection",
    "SyncScanner",
    "TimedOut",
    "UnknownAttributeError",
    "UnknownField",
    "UnknownKey",
    "Value",
    "WrongState",
    "WrongType",
    "__version__",
    "backplane_route",
    "build_device",
    "catalog_from_eds",
    "componet_route",
    "diff_params",
    "discover",
    "discover_blocking",
    "dump_params",
    "list_services_udp",
    "load_params",
    "parse_eds",
    "precise_event_loop",
    "read_eds",
    "read_recipe",
    "run_precise",
    "write_recipe",
]


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'cipstack' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value  # later uses find it directly
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))


if TYPE_CHECKING:  # what type checkers and the API reference see; nothing is imported at run time
    from .adapter import Adapter, AdapterSettings
    from .catalog import Catalog
    from .cip.epath import PortSegment
    from .cip.status import CipError, GeneralStatus
    from .cip.values import Scaling, Value
    from .devices.profiles import PROFILES, build_device
    from .eds.catalog import catalog_from_eds
    from .eds.model import EdsDocument
    from .eds.reader import parse_eds, read_eds
    from .eip.io_server import precise_event_loop, run_precise
    from .eip.originator.blocking_io import SyncIoConnection
    from .eip.originator.class1 import IoTimeoutError, OtFormat
    from .eip.originator.io_originator import IoConnectionHandle
    from .eip.originator.process_image import ProcessImage
    from .eip.originator.replies import EncapsulationStatusError, MalformedReplyError
    from .eip.wire.identity_items import IdentityRecord
    from .errors import (
        BadRequest,
        CipstackError,
        NoReply,
        NotFound,
        NothingListens,
        PeerUnreachable,
        ProtocolError,
        ReadOnlyField,
        SecurityError,
        StateRefused,
        TimedOut,
        UnknownField,
        UnknownKey,
        WrongState,
        WrongType,
    )
    from .params import diff_params, dump_params, load_params, read_recipe, write_recipe
    from .scanner import (
        AttributeValue,
        ReplyDecodeError,
        Scanner,
        SyncScanner,
        UnknownAttributeError,
        backplane_route,
        componet_route,
        discover,
        discover_blocking,
        list_services_udp,
    )
