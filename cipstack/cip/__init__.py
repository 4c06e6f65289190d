"""CIP itself, transport-free: data types, EPATH, status, message-router codecs, object model.

The names below are loaded on first use (PEP 562): ``from cipstack.cip.status import CipError``
costs the status codes alone, not the object model and the construct codecs behind it.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

_HOMES = {
    "epath": ("ApplicationPath", "DataSegment", "ElectronicKey", "LogicalSegment", "LogicalType", "PortSegment",
              "decode_path", "encode_path", "logical_path", "parse_application_path", "request_path"),
    "messages": ("MessageRouterRequest", "MessageRouterResponse", "Service"),
    "model": ("Access", "AttributeSpec", "Binding", "CipObject", "ClassSpec", "Instance"),
    "router": ("MessageRouter", "RequestContext"),
    "status": ("CipError", "ExtendedStatus", "GeneralStatus"),
}
_MODULE_OF = {name: module for module, names in _HOMES.items() for name in names}

__all__ = [
    "Access", "ApplicationPath", "AttributeSpec", "Binding", "CipError", "CipObject", "ClassSpec",
    "DataSegment", "ElectronicKey", "ExtendedStatus", "GeneralStatus", "Instance",
    "LogicalSegment", "LogicalType", "MessageRouter", "MessageRouterRequest",
    "MessageRouterResponse", "PortSegment", "RequestContext", "Service", "decode_path",
    "encode_path", "logical_path", "parse_application_path", "request_path",
]


def __getattr__(name: str) -> Any:
    module = _MODULE_OF.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


if TYPE_CHECKING:
    from .epath import (
        ApplicationPath,
        DataSegment,
        ElectronicKey,
        LogicalSegment,
        LogicalType,
        PortSegment,
        decode_path,
        encode_path,
        logical_path,
        parse_application_path,
        request_path,
    )
    from .messages import MessageRouterRequest, MessageRouterResponse, Service
    from .model import Access, AttributeSpec, Binding, CipObject, ClassSpec, Instance
    from .router import MessageRouter, RequestContext
    from .status import CipError, ExtendedStatus, GeneralStatus
