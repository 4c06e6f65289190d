"""CIP general and extended status codes, and the one exception type that carries them.

Codes and names follow the CIP general status table and the Connection Manager extended
status table (CIP Vol. 2, chapter 2, as Wireshark's ENIP dissector and OpENer read it).
"""

from __future__ import annotations

from collections.abc import Sequence
from enum import IntEnum

from ..errors import ProtocolError


class GeneralStatus(IntEnum):
    SUCCESS = 0x00
    CONNECTION_FAILURE = 0x01
    RESOURCE_UNAVAILABLE = 0x02
    INVALID_PARAMETER_VALUE = 0x03
    PATH_SEGMENT_ERROR = 0x04
    PATH_DESTINATION_UNKNOWN = 0x05
    PARTIAL_TRANSFER = 0x06
    CONNECTION_LOST = 0x07
    SERVICE_NOT_SUPPORTED = 0x08
    INVALID_ATTRIBUTE_VALUE = 0x09
    ATTRIBUTE_LIST_ERROR = 0x0A
    ALREADY_IN_REQUESTED_MODE = 0x0B
    OBJECT_STATE_CONFLICT = 0x0C
    OBJECT_ALREADY_EXISTS = 0x0D
    ATTRIBUTE_NOT_SETTABLE = 0x0E
    PRIVILEGE_VIOLATION = 0x0F
    DEVICE_STATE_CONFLICT = 0x10
    REPLY_DATA_TOO_LARGE = 0x11
    FRAGMENTATION_OF_PRIMITIVE = 0x12
    NOT_ENOUGH_DATA = 0x13
    ATTRIBUTE_NOT_SUPPORTED = 0x14
    TOO_MUCH_DATA = 0x15
    OBJECT_DOES_NOT_EXIST = 0x16
    SERVICE_FRAGMENTATION_SEQUENCE = 0x17
    NO_STORED_ATTRIBUTE_DATA = 0x18
    STORE_OPERATION_FAILURE = 0x19
    ROUTING_FAILURE_REQUEST_TOO_LARGE = 0x1A
    ROUTING_FAILURE_RESPONSE_TOO_LARGE = 0x1B
    MISSING_ATTRIBUTE_LIST_ENTRY_DATA = 0x1C
    INVALID_ATTRIBUTE_VALUE_LIST = 0x1D
    EMBEDDED_SERVICE_ERROR = 0x1E
    VENDOR_SPECIFIC = 0x1F
    INVALID_PARAMETER = 0x20
    WRITE_ONCE_VALUE_OR_MEDIUM_ALREADY_WRITTEN = 0x21
    INVALID_REPLY_RECEIVED = 0x22
    KEY_FAILURE_IN_PATH = 0x25
    PATH_SIZE_INVALID = 0x26
    UNEXPECTED_ATTRIBUTE_IN_LIST = 0x27
    INVALID_MEMBER_ID = 0x28
    MEMBER_NOT_SETTABLE = 0x29


class ExtendedStatus(IntEnum):
    """Connection Manager extended status (follows general status 0x01)."""

    CONNECTION_IN_USE = 0x0100
    TRANSPORT_CLASS_NOT_SUPPORTED = 0x0103
    OWNERSHIP_CONFLICT = 0x0106
    CONNECTION_NOT_FOUND = 0x0107
    INVALID_NETWORK_CONNECTION_PARAMETER = 0x0108
    INVALID_CONNECTION_SIZE = 0x0109
    TARGET_NOT_CONFIGURED = 0x0110
    RPI_NOT_SUPPORTED = 0x0111
    RPI_VALUE_NOT_ACCEPTABLE = 0x0112
    OUT_OF_CONNECTIONS = 0x0113
    VENDOR_OR_PRODUCT_CODE_MISMATCH = 0x0114
    DEVICE_TYPE_MISMATCH = 0x0115
    REVISION_MISMATCH = 0x0116
    INVALID_APPLICATION_PATH = 0x0117
    INVALID_CONFIGURATION_PATH = 0x0118
    NON_LISTEN_ONLY_NOT_OPENED = 0x0119
    TARGET_OBJECT_OUT_OF_CONNECTIONS = 0x011A
    INVALID_CONFIGURATION_SIZE = 0x0126
    INVALID_OT_SIZE = 0x0127
    INVALID_TO_SIZE = 0x0128
    INVALID_CONFIGURATION_APPLICATION_PATH = 0x0129
    INVALID_CONSUMING_PATH = 0x012A
    INVALID_PRODUCING_PATH = 0x012B
    INCONSISTENT_PATH_COMBINATION = 0x012F
    NULL_FORWARD_OPEN_NOT_SUPPORTED = 0x0132
    CONNECTION_TIMED_OUT = 0x0203
    UNCONNECTED_REQUEST_TIMED_OUT = 0x0204
    PORT_NOT_AVAILABLE = 0x0311
    LINK_ADDRESS_NOT_VALID = 0x0312
    INVALID_SEGMENT_IN_CONNECTION_PATH = 0x0315


def status_name(code: int) -> str:
    """Name of a general status code, e.g. ``0x14`` -> ``attribute not supported``."""
    try:
        return GeneralStatus(code).name.lower().replace("_", " ")
    except ValueError:
        return "unknown status"


def extended_status_name(code: int) -> str:
    try:
        return ExtendedStatus(code).name.lower().replace("_", " ")
    except ValueError:
        return "unknown extended status"


def describe_status(general: int, extended: Sequence[int] = ()) -> str:
    """``0x01 (connection failure), extended 0x0127 (invalid o t size), additional 0x000A``: the first
    additional status word is the extended status; the words after it are its data (a correct size,
    acceptable RPIs)."""
    text = f"0x{general:02X} ({status_name(general)})"
    if extended:
        first, *rest = extended
        name = extended_status_name(first) if general == GeneralStatus.CONNECTION_FAILURE else ""
        text += f", extended 0x{first:04X}" + (f" ({name})" if name else "")
        if rest:
            text += ", additional " + " ".join(f"0x{word:04X}" for word in rest)
    return text


class CipError(ProtocolError):
    """A CIP request failed with a general status and optional extended status words.

    Raised by objects while serving a request (the router turns it into an error reply)
    and by the scanner when a reply carries an error status.
    """

    general: int  # always a status here (a ProtocolError may have none)

    def __init__(
        self,
        general: int,
        extended: Sequence[int] = (),
        message: str = "",
        data: bytes = b"",
    ) -> None:
        self.general = int(general)
        self.extended = tuple(int(w) for w in extended)
        self.message = message
        #: Service-specific data of an error reply (e.g. a failed Forward_Open's serials).
        self.data = data
        text = describe_status(self.general, self.extended)
        super().__init__(f"{message}: {text}" if message else text)

    @property
    def general_name(self) -> str:
        return status_name(self.general)
