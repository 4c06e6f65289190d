"""CIP elementary data types and the composites built from them.

Every type is a `construct` codec (``CipType.construct``) so that assemblies and larger
schemas can embed it; the fixed-size numeric types also keep a precompiled ``struct.Struct``
because attribute reads are on the explicit-messaging hot path. Each type encodes and decodes
its own values without ``construct``, which is imported when a type's codec is first asked for
(an assembly schema): a one-shot ``cipstack get`` never pays for it.

Decoding is strict: a request that carries too few bytes for a value raises
``CipError(0x13)`` and one that carries more raises ``CipError(0x15)``, the codes a
conformance tool expects.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from ..errors import BadRequest
from .status import CipError, GeneralStatus

if TYPE_CHECKING:
    import construct as cs


class CipType:
    """A CIP data type: name, EDS type code, size, codec and value checks."""

    name: str
    #: Data type code used in EDS files and typed services (0xC1 BOOL ... 0xDA SHORT_STRING).
    code: int | None
    #: Encoded size in bytes, or None for variable-size types.
    size: int | None
    #: The fixed-size numeric types' precompiled little-endian codec (None for the others): what
    #: the hot paths (assembly decoding) unpack with instead of the ``construct`` parser.
    struct_codec: struct.Struct | None = None

    @property
    def construct(self) -> cs.Construct[Any, Any]:
        """This type as a ``construct`` codec, for schemas that embed it; built on first use."""
        built: cs.Construct[Any, Any] | None = self.__dict__.get("_construct")
        if built is None:
            built = self.__dict__["_construct"] = self._build_construct()
        return built

    def _build_construct(self) -> cs.Construct[Any, Any]:
        """The codec; each type imports ``construct`` here, on first use."""
        raise NotImplementedError

    def encode(self, value: Any) -> bytes:
        raise NotImplementedError

    def decode_from(self, data: bytes, offset: int = 0) -> tuple[Any, int]:
        """Decode one value at ``offset``; return it and the offset just past it."""
        raise NotImplementedError

    def decode(self, data: bytes) -> Any:
        """Decode exactly one value from ``data`` (0x13 if short, 0x15 if long)."""
        value, end = self.decode_from(data, 0)
        if end != len(data):
            raise CipError(GeneralStatus.TOO_MUCH_DATA, message=f"{self.name}: trailing bytes")
        return value

    def decode_written_from(self, data: bytes, offset: int = 0) -> tuple[Any, int]:
        """Decode the value a Set service carries, as the wire has it, for ``check`` and the
        declared range to judge. A reader is tolerant (``decode_from``); what a request writes is
        stored only if it is a value of the type (most types decode the same either way)."""
        return self.decode_from(data, offset)

    def decode_written(self, data: bytes) -> Any:
        """Exactly one value as a Set service carries it (0x13 if short, 0x15 if long): ``decode``,
        for every type whose reader is not more tolerant than its writer."""
        return self.decode(data)

    def check(self, value: Any) -> Any:
        """Return ``value`` as this type holds it, or raise ``CipError(0x09)``."""
        return value

    def parse_text(self, text: str) -> Any:
        """A value typed on the command line ("1500", "0x5DC", "1.5", "name")."""
        raise BadRequest(f"cannot parse a {self.name} from text")

    def to_json(self, value: Any) -> Any:
        return value

    def __repr__(self) -> str:
        return self.name


def parse_int(text: str) -> int:
    """Decimal or 0x hexadecimal integer (also 0b/0o), with an optional sign."""
    try:
        return int(text.strip(), 0)
    except ValueError:
        raise BadRequest(f"not a number: {text!r}") from None


class IntegerType(CipType):
    #: Fixed-size: the size and the precompiled codec are always there.
    size: int
    struct_codec: struct.Struct

    def __init__(self, name: str, code: int | None, size: int, signed: bool) -> None:
        self.name = name
        self.code = code
        self.size = size
        self.signed = signed
        fmt = {1: "b", 2: "h", 4: "i", 8: "q"}[size]
        self.struct_codec = struct.Struct("<" + (fmt if signed else fmt.upper()))
        bits = size * 8
        self.minimum = -(1 << (bits - 1)) if signed else 0
        self.maximum = (1 << (bits - 1)) - 1 if signed else (1 << bits) - 1

    def _build_construct(self) -> cs.Construct[Any, Any]:
        import construct as cs

        return cs.BytesInteger(self.size, signed=self.signed, swapped=True)

    def encode(self, value: Any) -> bytes:
        if value.__class__ is int and self.minimum <= value <= self.maximum:
            return self.struct_codec.pack(value)  # the common case, without check()'s call
        return self.struct_codec.pack(self.check(value))

    def decode_from(self, data: bytes, offset: int = 0) -> tuple[int, int]:
        end = offset + self.size
        if end > len(data):
            raise CipError(GeneralStatus.NOT_ENOUGH_DATA, message=f"{self.name} needs {self.size} bytes")
        return self.struct_codec.unpack_from(data, offset)[0], end

    def decode(self, data: bytes) -> int:
        if len(data) != self.size:
            code = GeneralStatus.NOT_ENOUGH_DATA if len(data) < self.size else GeneralStatus.TOO_MUCH_DATA
            raise CipError(code, message=f"{self.name} is {self.size} bytes, got {len(data)}")
        value: int = self.struct_codec.unpack(data)[0]
        return value

    def check(self, value: Any) -> int:
        number: int
        if isinstance(value, int) and not isinstance(value, bool):
            number = value
        else:
            try:
                number = int(value)
            except (TypeError, ValueError):
                raise CipError(GeneralStatus.INVALID_ATTRIBUTE_VALUE,
                               message=f"{value!r} is not a {self.name}") from None
        if not self.minimum <= number <= self.maximum:
            raise CipError(
                GeneralStatus.INVALID_ATTRIBUTE_VALUE,
                message=f"{number} outside {self.name} range {self.minimum}..{self.maximum}",
            )
        return number

    def parse_text(self, text: str) -> int:
        return parse_int(text)


class BoolType(IntegerType):
    """BOOL: one byte on the wire, 0 or 1."""

    def __init__(self) -> None:
        super().__init__("BOOL", 0xC1, 1, signed=False)
        self.maximum = 1

    def decode_from(self, data: bytes, offset: int = 0) -> tuple[int, int]:
        raw, end = super().decode_from(data, offset)
        return (1 if raw else 0), end

    def decode(self, data: bytes) -> int:
        return 1 if super().decode(data) else 0

    def decode_written_from(self, data: bytes, offset: int = 0) -> tuple[int, int]:
        # A write keeps the byte as sent: 2 or 0xFF is no BOOL (0 or 1), and ``check`` refuses it
        # with 0x09 rather than storing 1 (a run command would otherwise start the drive).
        return IntegerType.decode_from(self, data, offset)

    def decode_written(self, data: bytes) -> int:
        return IntegerType.decode(self, data)

    def check(self, value: Any) -> int:
        if isinstance(value, bool):
            return int(value)
        return super().check(value)

    def parse_text(self, text: str) -> int:
        lowered = text.strip().lower()
        if lowered in ("true", "on", "yes"):
            return 1
        if lowered in ("false", "off", "no"):
            return 0
        return parse_int(text)


class RealType(CipType):
    #: Fixed-size: the size and the precompiled codec are always there.
    size: int
    struct_codec: struct.Struct

    def __init__(self, name: str, code: int, size: int) -> None:
        self.name = name
        self.code = code
        self.size = size
        self.struct_codec = struct.Struct("<f" if size == 4 else "<d")

    def _build_construct(self) -> cs.Construct[Any, Any]:
        import construct as cs

        return cs.Float32l if self.size == 4 else cs.Float64l

    def encode(self, value: Any) -> bytes:
        return self.struct_codec.pack(self.check(value))

    def decode_from(self, data: bytes, offset: int = 0) -> tuple[float, int]:
        end = offset + self.size
        if end > len(data):
            raise CipError(GeneralStatus.NOT_ENOUGH_DATA, message=f"{self.name} needs {self.size} bytes")
        return self.struct_codec.unpack_from(data, offset)[0], end

    def check(self, value: Any) -> float:
        try:
            number = float(value)
        except (TypeError, ValueError):
            raise CipError(GeneralStatus.INVALID_ATTRIBUTE_VALUE, message=f"{value!r} is not a {self.name}") from None
        if self.size == 4:
            try:
                self.struct_codec.pack(number)
            except OverflowError:
                raise CipError(GeneralStatus.INVALID_ATTRIBUTE_VALUE, message=f"{number} overflows REAL") from None
        return number

    def parse_text(self, text: str) -> float:
        try:
            return float(text)
        except ValueError:
            raise BadRequest(f"not a number: {text!r}") from None


#: Stands for "no value encoded yet": no value a caller passes is this object.
_NOTHING = object()


class StringType(CipType):
    """SHORT_STRING (USINT length) or STRING (UINT length) of single-byte characters."""

    def __init__(self, name: str, code: int, length_size: int) -> None:
        self.name = name
        self.code = code
        self.size = None
        self._length = IntegerType("length", None, length_size, signed=False)
        #: The last value encoded and its bytes: strings do not change, and most string attributes
        #: (names, revisions) are read again and again with the same one.
        self._last: tuple[Any, bytes] = (_NOTHING, b"")

    def _build_construct(self) -> cs.Construct[Any, Any]:
        import construct as cs

        return cs.PascalString(self._length.construct, "latin-1")

    def encode(self, value: Any) -> bytes:
        last, encoded = self._last
        if value is last:
            return encoded
        raw = self._latin1(value)
        encoded = self._length.encode(len(raw)) + raw
        if value.__class__ is str or value.__class__ is bytes:  # immutable: the same object, the same bytes
            self._last = (value, encoded)
        return encoded

    def decode_from(self, data: bytes, offset: int = 0) -> tuple[str, int]:
        length, start = self._length.decode_from(data, offset)
        end = start + length
        if end > len(data):
            raise CipError(GeneralStatus.NOT_ENOUGH_DATA, message=f"{self.name} of {length} characters is cut short")
        return data[start:end].decode("latin-1"), end

    def check(self, value: Any) -> str:
        self._latin1(value)
        return value.decode("latin-1") if isinstance(value, bytes) else value

    def _latin1(self, value: Any) -> bytes:
        """The characters of ``value`` (text or bytes) as they go on the wire, or 0x09 if they cannot."""
        if isinstance(value, bytes):
            raw = value
        elif isinstance(value, str):
            try:
                raw = value.encode("latin-1")
            except UnicodeEncodeError:
                raise CipError(GeneralStatus.INVALID_ATTRIBUTE_VALUE, message=f"{value!r} is not Latin-1") from None
        else:
            raise CipError(GeneralStatus.INVALID_ATTRIBUTE_VALUE, message=f"{value!r} is not a {self.name}")
        if len(raw) > self._length.maximum:
            raise CipError(GeneralStatus.INVALID_ATTRIBUTE_VALUE,
                           message=f"{self.name} longer than {self._length.maximum}")
        return raw

    def parse_text(self, text: str) -> str:
        return text


class OctetString(CipType):
    """A fixed number of raw bytes (a MAC address, a reserved block); value is ``bytes``."""

    size: int

    def __init__(self, size: int, name: str | None = None) -> None:
        self.name = name or f"BYTE[{size}]"
        self.code = None
        self.size = size

    def _build_construct(self) -> cs.Construct[Any, Any]:
        import construct as cs

        return cs.Bytes(self.size)

    def encode(self, value: Any) -> bytes:
        return bytes(self.check(value))

    def decode_from(self, data: bytes, offset: int = 0) -> tuple[bytes, int]:
        end = offset + self.size
        if end > len(data):
            raise CipError(GeneralStatus.NOT_ENOUGH_DATA, message=f"{self.name} needs {self.size} bytes")
        return bytes(data[offset:end]), end

    def check(self, value: Any) -> bytes:
        if not isinstance(value, (bytes, bytearray)) or len(value) != self.size:
            raise CipError(GeneralStatus.INVALID_ATTRIBUTE_VALUE, message=f"{self.name} needs {self.size} bytes")
        return bytes(value)

    def parse_text(self, text: str) -> bytes:
        return bytes.fromhex(text.replace(":", "").replace("-", ""))

    def to_json(self, value: Any) -> Any:
        return value.hex()


class RemainingBytes(CipType):
    """All the bytes that remain (raw data of unknown structure, an assembly's data)."""

    def __init__(self, name: str = "BYTES") -> None:
        self.name = name
        self.code = None
        self.size = None

    def _build_construct(self) -> cs.Construct[Any, Any]:
        import construct as cs

        return cs.GreedyBytes

    def encode(self, value: Any) -> bytes:
        return bytes(value)

    def decode_from(self, data: bytes, offset: int = 0) -> tuple[bytes, int]:
        return bytes(data[offset:]), len(data)

    def check(self, value: Any) -> bytes:
        if not isinstance(value, (bytes, bytearray)):
            raise CipError(GeneralStatus.INVALID_ATTRIBUTE_VALUE, message="raw bytes expected")
        return bytes(value)

    def parse_text(self, text: str) -> bytes:
        return bytes.fromhex(text)

    def to_json(self, value: Any) -> Any:
        return value.hex()


class StructType(CipType):
    """A structure of named members; its value is a dict in member order."""

    def __init__(self, name: str, members: Sequence[tuple[str, CipType]]) -> None:
        self.name = name
        self.code = None
        self.members = tuple(members)
        sizes = [m.size for _, m in self.members]
        self.size = None if None in sizes else sum(s for s in sizes if s is not None)

    def _build_construct(self) -> cs.Construct[Any, Any]:
        import construct as cs

        return cs.Struct(*(member_name / member.construct for member_name, member in self.members))

    def encode(self, value: Any) -> bytes:
        value = self.check(value)
        return b"".join(member.encode(value[name]) for name, member in self.members)

    def decode_from(self, data: bytes, offset: int = 0) -> tuple[dict[str, Any], int]:
        result: dict[str, Any] = {}
        for name, member in self.members:
            result[name], offset = member.decode_from(data, offset)
        return result, offset

    def check(self, value: Any) -> dict[str, Any]:
        if not isinstance(value, dict):
            raise CipError(GeneralStatus.INVALID_ATTRIBUTE_VALUE, message=f"{self.name} needs a mapping")
        missing = [name for name, _ in self.members if name not in value]
        if missing:
            raise CipError(GeneralStatus.INVALID_ATTRIBUTE_VALUE, message=f"{self.name} lacks {', '.join(missing)}")
        return {name: member.check(value[name]) for name, member in self.members}

    def to_json(self, value: Any) -> Any:
        return {name: member.to_json(value[name]) for name, member in self.members}


class ArrayType(CipType):
    """``count`` elements of one type, or as many as the data holds when count is None."""

    def __init__(self, element: CipType, count: int | None = None, name: str | None = None) -> None:
        self.element = element
        self.count = count
        self.name = name or f"{element.name}[{'' if count is None else count}]"
        self.code = None
        self.size = None if count is None or element.size is None else count * element.size

    def _build_construct(self) -> cs.Construct[Any, Any]:
        import construct as cs

        element = self.element.construct
        return cs.Array(self.count, element) if self.count is not None else cs.GreedyRange(element)

    def encode(self, value: Any) -> bytes:
        return b"".join(self.element.encode(item) for item in self.check(value))

    def decode_from(self, data: bytes, offset: int = 0) -> tuple[list[Any], int]:
        items: list[Any] = []
        if self.count is None:
            while offset < len(data):
                item, offset = self.element.decode_from(data, offset)
                items.append(item)
        else:
            for _ in range(self.count):
                item, offset = self.element.decode_from(data, offset)
                items.append(item)
        return items, offset

    def check(self, value: Any) -> list[Any]:
        items = list(value)
        if self.count is not None and len(items) != self.count:
            raise CipError(GeneralStatus.INVALID_ATTRIBUTE_VALUE, message=f"{self.name} needs {self.count} items")
        return [self.element.check(item) for item in items]

    def to_json(self, value: Any) -> Any:
        return [self.element.to_json(item) for item in value]


BOOL = BoolType()
SINT = IntegerType("SINT", 0xC2, 1, signed=True)
INT = IntegerType("INT", 0xC3, 2, signed=True)
DINT = IntegerType("DINT", 0xC4, 4, signed=True)
LINT = IntegerType("LINT", 0xC5, 8, signed=True)
USINT = IntegerType("USINT", 0xC6, 1, signed=False)
UINT = IntegerType("UINT", 0xC7, 2, signed=False)
UDINT = IntegerType("UDINT", 0xC8, 4, signed=False)
ULINT = IntegerType("ULINT", 0xC9, 8, signed=False)
REAL = RealType("REAL", 0xCA, 4)
LREAL = RealType("LREAL", 0xCB, 8)
STRING = StringType("STRING", 0xD0, 2)
BYTE = IntegerType("BYTE", 0xD1, 1, signed=False)
WORD = IntegerType("WORD", 0xD2, 2, signed=False)
DWORD = IntegerType("DWORD", 0xD3, 4, signed=False)
LWORD = IntegerType("LWORD", 0xD4, 8, signed=False)
SHORT_STRING = StringType("SHORT_STRING", 0xDA, 1)

ELEMENTARY: dict[str, CipType] = {
    t.name: t
    for t in (BOOL, SINT, INT, DINT, LINT, USINT, UINT, UDINT, ULINT, REAL, LREAL,
              STRING, BYTE, WORD, DWORD, LWORD, SHORT_STRING)
}
BY_CODE: dict[int, CipType] = {t.code: t for t in ELEMENTARY.values() if t.code is not None}

#: Revision as Identity attribute 4 holds it: major then minor, one byte each.
REVISION = StructType("REVISION", [("major", USINT), ("minor", USINT)])


def type_by_name(name: str) -> CipType:
    """Look up an elementary type by its CIP name, case-insensitive ("uint", "SHORT_STRING")."""
    try:
        return ELEMENTARY[name.strip().upper()]
    except KeyError:
        known = ", ".join(ELEMENTARY)
        raise BadRequest(f"unknown CIP type {name!r} (known: {known})") from None
