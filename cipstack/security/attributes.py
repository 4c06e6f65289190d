"""The data types of the CIP Security objects' attributes, as CIP types (encode, decode, check).

Layouts as OpENer's CIP Security branch declares them (``ethernetipsecurity.h``,
``certificatemanagement.h``, ``cipsecurity.c``; Volume 8 sections 5-4.4 and 5-5.4 cited there):

* a cipher suite list: USINT count, then each IANA id as two octets, first byte first
  (``EIPSecurityObjectCipherSuiteId``: ``iana_first_byte``, ``iana_second_byte``);
* a path list: USINT count, then each path as its size in 16-bit words (USINT) and the padded
  EPATH (``EncodeCipSecurityObjectPath``); a single path the same without the count, size 0 for none;
* pre-shared keys: USINT count, then per key USINT identity size, identity (at most 128 octets),
  USINT key size, key (at most 64 octets);
* a certificate (Certificate Management attributes 3 and 4): a USINT certificate status, then one
  path, to the File object instance that holds the certificate (Wireshark's packet-enip.c,
  dissect_eip_cert_device_cert, reads it the same way).
"""

from __future__ import annotations

from typing import Any

from ..cip.epath import LogicalSegment, LogicalType, decode_path, request_path
from ..cip.status import CipError, GeneralStatus
from ..cip.types import USINT, CipType

#: Longest PSK identity and key, octets (OpENer's SIZE_MAX_PSK_IDENTITY, SIZE_MAX_PSK).
MAX_PSK_IDENTITY = 128
MAX_PSK = 64
#: Longest certificate a device takes, DER octets: no public source bounds it; a P-256 certificate
#: of a plant CA is well under 1 KB, an RSA-4096 chain link under 2 KB.
MAX_CERTIFICATE = 4096
#: Most entries a list attribute holds (the USINT count allows 255; a device keeps fewer).
MAX_LIST = 8


def _short(message: str) -> CipError:
    return CipError(GeneralStatus.NOT_ENOUGH_DATA, message=message)


def _invalid(message: str) -> CipError:
    return CipError(GeneralStatus.INVALID_ATTRIBUTE_VALUE, message=message)


class CipherSuiteList(CipType):
    """USINT count, then 2-octet IANA cipher suite ids; the value is a tuple of ids (0xC02B...).
    ``names``: the suites' OpenSSL names, for a person reading the list."""

    def __init__(self, name: str = "CIPHER_SUITES", names: dict[int, str] | None = None) -> None:
        self.name = name
        self.code = None
        self.size = None
        self.names = dict(names or {})

    def text(self, value: tuple[int, ...]) -> str:
        return ", ".join(f"0x{s:04X}" + (f" {self.names[s]}" if s in self.names else "") for s in value) or "none"

    def encode(self, value: Any) -> bytes:
        suites = self.check(value)
        return bytes((len(suites),)) + b"".join(suite.to_bytes(2, "big") for suite in suites)

    def decode_from(self, data: bytes, offset: int = 0) -> tuple[tuple[int, ...], int]:
        count, offset = USINT.decode_from(data, offset)
        end = offset + 2 * count
        if end > len(data):
            raise _short(f"{count} cipher suites need {2 * count} octets")
        return tuple(int.from_bytes(data[i:i + 2], "big") for i in range(offset, end, 2)), end

    def check(self, value: Any) -> tuple[int, ...]:
        suites = tuple(value)
        if len(suites) > MAX_LIST:
            raise _invalid(f"{len(suites)} cipher suites; at most {MAX_LIST}")
        if any(not isinstance(s, int) or not 0 <= s <= 0xFFFF for s in suites) or len(set(suites)) != len(suites):
            raise _invalid("a cipher suite list holds distinct 16-bit IANA ids")
        return suites

    def to_json(self, value: Any) -> Any:
        return [f"0x{suite:04X}" for suite in value]


def encode_object_path(path: tuple[int, int]) -> bytes:
    """One path as the security objects carry it: its size in words, then the padded EPATH."""
    raw = request_path(*path)
    return bytes((len(raw) // 2,)) + raw


def decode_object_path(data: bytes, offset: int) -> tuple[tuple[int, int] | None, int]:
    """A path at ``offset``: (class, instance), or None for size 0; the offset past it."""
    words, offset = USINT.decode_from(data, offset)
    end = offset + 2 * words
    if end > len(data):
        raise _short(f"a path of {words} words is cut short")
    if words == 0:
        return None, end
    try:
        segments = decode_path(bytes(data[offset:end]))
    except CipError:
        raise _invalid("a path that does not decode") from None
    kinds = [(s.kind, s.value) for s in segments if isinstance(s, LogicalSegment)]
    if len(kinds) != len(segments) or len(kinds) != 2 or kinds[0][0] != LogicalType.CLASS_ID \
            or kinds[1][0] != LogicalType.INSTANCE_ID:
        raise _invalid("a path to an object instance is a class and an instance segment")
    return (kinds[0][1], kinds[1][1]), end


class PathList(CipType):
    """USINT count, then paths to object instances; the value is a tuple of (class, instance)."""

    def __init__(self, name: str = "PATH_LIST") -> None:
        self.name = name
        self.code = None
        self.size = None

    def encode(self, value: Any) -> bytes:
        paths = self.check(value)
        return bytes((len(paths),)) + b"".join(encode_object_path(path) for path in paths)

    def decode_from(self, data: bytes, offset: int = 0) -> tuple[tuple[tuple[int, int], ...], int]:
        count, offset = USINT.decode_from(data, offset)
        paths = []
        for _ in range(count):
            path, offset = decode_object_path(data, offset)
            if path is None:
                raise _invalid("an empty path in a path list")
            paths.append(path)
        return tuple(paths), offset

    def check(self, value: Any) -> tuple[tuple[int, int], ...]:
        paths = []
        for path in value:
            pair = tuple(path)
            if len(pair) != 2 or not all(isinstance(n, int) and n >= 0 for n in pair):
                raise _invalid("a path is (class, instance)")
            paths.append((pair[0], pair[1]))
        if len(paths) > MAX_LIST:
            raise _invalid(f"{len(paths)} paths; at most {MAX_LIST}")
        return tuple(paths)

    def to_json(self, value: Any) -> Any:
        return [f"0x{c:02X}/{i}" for c, i in value]

    def text(self, value: tuple[tuple[int, int], ...]) -> str:
        return ", ".join(f"class 0x{c:02X} instance {i}" for c, i in value) or "none"


class ObjectPath(CipType):
    """One path, or none (size 0): the value is (class, instance) or ()."""

    def __init__(self, name: str = "PATH") -> None:
        self.name = name
        self.code = None
        self.size = None

    def encode(self, value: Any) -> bytes:
        path = self.check(value)
        return encode_object_path(path) if path else b"\x00"   # type: ignore[arg-type]  # a pair when set

    def decode_from(self, data: bytes, offset: int = 0) -> tuple[tuple[int, ...], int]:
        path, offset = decode_object_path(data, offset)
        return (path or ()), offset

    def check(self, value: Any) -> tuple[int, ...]:
        path = tuple(value or ())
        if len(path) not in (0, 2):
            raise _invalid("a path is (class, instance), or none")
        return path

    def to_json(self, value: Any) -> Any:
        return f"0x{value[0]:02X}/{value[1]}" if value else None

    def text(self, value: tuple[int, ...]) -> str:
        return f"class 0x{value[0]:02X} instance {value[1]}" if value else "none"


class PreSharedKeys(CipType):
    """USINT count, then (identity size, identity, key size, key) per key. Written, never read back:
    the value is a tuple of (identity, key) pairs."""

    def __init__(self, name: str = "PRE_SHARED_KEYS", supported: int = 1) -> None:
        self.name = name
        self.code = None
        self.size = None
        self.supported = supported

    def encode(self, value: Any) -> bytes:
        out = bytearray((len(value),))
        for identity, key in self.check(value):
            out += bytes((len(identity),)) + identity + bytes((len(key),)) + key
        return bytes(out)

    def decode_from(self, data: bytes, offset: int = 0) -> tuple[tuple[tuple[bytes, bytes], ...], int]:
        count, offset = USINT.decode_from(data, offset)
        keys = []
        for _ in range(count):
            parts = []
            for what in ("identity", "key"):
                size, offset = USINT.decode_from(data, offset)
                if offset + size > len(data):
                    raise _short(f"a PSK {what} of {size} octets is cut short")
                parts.append(bytes(data[offset:offset + size]))
                offset += size
            keys.append((parts[0], parts[1]))
        return tuple(keys), offset

    def check(self, value: Any) -> tuple[tuple[bytes, bytes], ...]:
        keys = tuple(value)
        if len(keys) > self.supported:
            raise _invalid(f"{len(keys)} pre-shared keys; this device keeps {self.supported}")
        for identity, key in keys:
            if not identity or len(identity) > MAX_PSK_IDENTITY:
                raise _invalid(f"a PSK identity of {len(identity)} octets (1 to {MAX_PSK_IDENTITY})")
            if not key or len(key) > MAX_PSK:
                raise _invalid(f"a PSK of {len(key)} octets (1 to {MAX_PSK})")
        return keys


class Certificate(CipType):
    """A certificate attribute: USINT certificate status, then the path (size in words, padded EPATH)
    to the File object instance that holds the certificate. The value is (status, (class, instance)),
    or (status, ()) for no path."""

    def __init__(self, name: str = "CERTIFICATE") -> None:
        self.name = name
        self.code = None
        self.size = None

    def encode(self, value: Any) -> bytes:
        status, path = self.check(value)
        return bytes((status,)) + (encode_object_path(path) if path else b"\x00")  # type: ignore[arg-type]  # a pair when set

    def decode_from(self, data: bytes, offset: int = 0) -> tuple[tuple[int, tuple[int, ...]], int]:
        status, offset = USINT.decode_from(data, offset)
        path, offset = decode_object_path(data, offset)
        return (status, path or ()), offset

    def check(self, value: Any) -> tuple[int, tuple[int, ...]]:
        status, path = value
        path = tuple(path or ())
        if not isinstance(status, int) or not 0 <= status <= 0xFF or len(path) not in (0, 2):
            raise _invalid("a certificate is (status, path to a File object instance)")
        return status, path

    def to_json(self, value: Any) -> Any:
        status, path = value
        return {"status": status, "file": f"0x{path[0]:02X}/{path[1]}" if path else None}

    def text(self, value: tuple[int, tuple[int, ...]]) -> str:
        status, path = value
        shown = {0: "not verified", 1: "verified", 2: "invalid"}.get(status, str(status))
        where = f"File object instance {path[1]} (class 0x{path[0]:02X})" if path else "no file"
        return f"{shown}, in {where}"


PATH_LIST = PathList()
OBJECT_PATH = ObjectPath()
PRE_SHARED_KEYS = PreSharedKeys()
CERTIFICATE = Certificate()

__all__ = ["CERTIFICATE", "MAX_CERTIFICATE", "MAX_LIST", "MAX_PSK", "MAX_PSK_IDENTITY",
           "OBJECT_PATH", "PATH_LIST", "PRE_SHARED_KEYS", "Certificate", "CipherSuiteList", "ObjectPath",
           "PathList", "PreSharedKeys", "decode_object_path", "encode_object_path"]
