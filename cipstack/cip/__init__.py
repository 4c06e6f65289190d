"""CIP itself, transport-free: data types, EPATH, status, message-router codecs, object model."""

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

__all__ = [
    "Access", "ApplicationPath", "AttributeSpec", "Binding", "CipError", "CipObject", "ClassSpec",
    "DataSegment", "ElectronicKey", "ExtendedStatus", "GeneralStatus", "Instance",
    "LogicalSegment", "LogicalType", "MessageRouter", "MessageRouterRequest",
    "MessageRouterResponse", "PortSegment", "RequestContext", "Service", "decode_path",
    "encode_path", "logical_path", "parse_application_path", "request_path",
]
