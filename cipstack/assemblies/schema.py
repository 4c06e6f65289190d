"""Assembly schemas: an I/O assembly declared once as named fields and bit flags.

From one declaration come the ``construct`` schema (``AssemblySchema.construct``, compiled),
the size, decoding to a flat dict of field values, encoding, the EDS ``[Assembly]`` members
and the scanner's field access. A field is either whole bytes of a CIP type at a byte
offset, or ``bits`` bits starting at bit ``bit`` (0 = least significant) of byte ``offset``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from ..cip.types import USINT, CipType
from ..cip.units import count_unit
from ..errors import BadRequest, UnknownKey

if TYPE_CHECKING:
    import construct as cs


@dataclass(frozen=True)
class AssemblyField:
    name: str
    offset: int
    #: CIP type of a whole-byte field (ignored for bit fields).
    type: CipType = USINT
    #: Width of a bit field in bits (0: a whole-byte field of ``type``).
    bits: int = 0
    #: Position of a bit field's least significant bit within byte ``offset``.
    bit: int = 0
    #: Engineering unit of the scaled value ("Hz" for a word of 0.01 Hz: see ``count_unit``).
    unit: str = ""
    #: Engineering value = raw x scale.
    scale: float = 1.0
    help: str = ""
    #: The attribute this field mirrors, as (class, instance, attribute), for the EDS and docs.
    link: tuple[int, int, int] | None = None

    @property
    def count_unit(self) -> str:
        """The unit a raw value of the field is in ("0.01 Hz" for a frequency word of scale 0.01):
        what ``--set`` takes and the decoded input shows."""
        return count_unit(self.unit, self.scale)

    @property
    def size_bits(self) -> int:
        if self.bits:
            return self.bits
        assert self.type.size is not None
        return 8 * self.type.size

    @property
    def start_bit(self) -> int:
        """Position of the field's first bit counted from the start of the assembly."""
        return 8 * self.offset + (self.bit if self.bits else 0)


def bit(name: str, offset: int, position: int, **kwargs: Any) -> AssemblyField:
    return AssemblyField(name, offset, bits=1, bit=position, **kwargs)


def word(name: str, offset: int, cip_type: CipType, **kwargs: Any) -> AssemblyField:
    return AssemblyField(name, offset, cip_type, **kwargs)


#: Field values whose equality now means equality later (see ``AssemblySchema.encode``).
_IMMUTABLE_VALUES = frozenset({bool, int, float, str, bytes})


class AssemblySchema:
    """Immutable description of one assembly instance's data."""

    def __init__(self, instance: int, name: str, size: int, fields: Iterable[AssemblyField],
                 description: str = "") -> None:
        self.instance = instance
        self.name = name
        self.size = size
        self.description = description
        self.fields: tuple[AssemblyField, ...] = tuple(sorted(fields, key=lambda f: f.start_bit))
        self.field_names = frozenset(f.name for f in self.fields)
        self._by_name = {f.name: f for f in self.fields}
        self._check()
        self._decoders = self._build_decoders()
        self._construct: cs.Construct[Any, Any] | None = None
        #: The field values last encoded and their bytes: a produced assembly whose values have not
        #: changed since (every firing of a class 1 timer, mostly) costs one comparison.
        self._last_encoded: tuple[tuple[tuple[str, Any], ...], bytes] | None = None

    @property
    def construct(self) -> cs.Construct[Any, Any]:
        """The compiled parser, built when first used (compiling is most of a schema's cost, and a
        catalog of schemas is mostly never parsed with)."""
        if self._construct is None:
            self._construct = self._build_construct().compile()
        return self._construct

    def _check(self) -> None:
        if len(self._by_name) != len(self.fields):
            raise BadRequest(f"assembly {self.instance}: a field name is declared twice")
        used = [False] * (8 * self.size)
        for f in self.fields:
            if f.bits and not f.bit >= 0 and f.bit + f.bits <= 8:
                raise BadRequest(f"assembly {self.instance}: bit field {f.name} crosses a byte")
            for position in range(f.start_bit, f.start_bit + f.size_bits):
                if position >= len(used):
                    raise BadRequest(f"assembly {self.instance}: field {f.name} runs past {self.size} bytes")
                if used[position]:
                    raise BadRequest(f"assembly {self.instance}: field {f.name} overlaps another")
                used[position] = True

    def _build_construct(self) -> cs.Struct:
        import construct as cs  # only here: what decodes by the readers below never imports it

        parts: list[cs.Construct[Any, Any]] = []
        offset = 0
        by_offset: dict[int, list[AssemblyField]] = {}
        for f in self.fields:
            by_offset.setdefault(f.offset, []).append(f)
        while offset < self.size:
            group = by_offset.get(offset)
            if group is None:
                parts.append(f"_byte_{offset}" / cs.Int8ul)  # a byte no field declares
                offset += 1
            elif group[0].bits:
                # A byte of flags: construct's BitStruct lists bits most significant first.
                members: list[cs.Construct[Any, Any]] = []
                position = 8
                for f in sorted(group, key=lambda g: -(g.bit + g.bits)):
                    top = f.bit + f.bits
                    if top < position:
                        members.append(f"_pad_{offset}_{top}" / cs.BitsInteger(position - top))
                    members.append(f.name / (cs.Flag if f.bits == 1 else cs.BitsInteger(f.bits)))
                    position = f.bit
                if position > 0:
                    members.append(f"_pad_{offset}_0" / cs.BitsInteger(position))
                parts.append(f"_flags_{offset}" / cs.BitStruct(*members))
                offset += 1
            else:
                f = group[0]
                parts.append(f.name / f.type.construct)
                assert f.type.size is not None
                offset += f.type.size
        return cs.Struct(*parts)

    def _build_decoders(self) -> tuple[tuple[str, Callable[[bytes], Any]], ...]:
        """One reader per field, in the order of the ``construct`` schema's fields: decoding is on the
        class 1 hot path (every O->T datagram a drive consumes), where the compiled schema's parse
        costs tens of microseconds for a few bytes. Each reader gives what the schema parses: a flag
        as bool, a multi-bit field as int, a word as its format's value (``decode_with_construct``
        is the reference it is tested against)."""
        readers: list[tuple[str, Callable[[bytes], Any]]] = []
        by_offset: dict[int, list[AssemblyField]] = {}
        for f in self.fields:
            by_offset.setdefault(f.offset, []).append(f)
        for offset in sorted(by_offset):
            group = by_offset[offset]
            if group[0].bits:
                for f in sorted(group, key=lambda g: -(g.bit + g.bits)):
                    readers.append((f.name, _bit_reader(f)))
            else:
                readers.append((group[0].name, _word_reader(group[0])))
        return tuple(readers)

    # -- values ---------------------------------------------------------------------------------------
    def decode(self, data: bytes) -> dict[str, Any]:
        """Field values by name (bit flags as bool, multi-bit fields and words as int)."""
        if len(data) != self.size:
            raise BadRequest(f"assembly {self.instance} is {self.size} bytes, got {len(data)}")
        return {name: read(data) for name, read in self._decoders}

    def decode_with_construct(self, data: bytes) -> dict[str, Any]:
        """``decode`` by the compiled ``construct`` schema: the reference ``decode`` is tested against."""
        if len(data) != self.size:
            raise BadRequest(f"assembly {self.instance} is {self.size} bytes, got {len(data)}")
        parsed = self.construct.parse(data)
        values: dict[str, Any] = {}
        for key, value in parsed.items():
            if key.startswith("_flags_"):
                values.update((k, v) for k, v in value.items() if not k.startswith("_"))
            elif not key.startswith("_"):
                values[key] = value
        return values

    def encode(self, values: Mapping[str, Any] | None = None, **more: Any) -> bytes:
        """Bytes for the given field values; fields not given are zero."""
        given = dict(values or {}, **more)
        # Remembered only when every value is immutable: a bytearray changed in place after being
        # encoded would compare equal to itself and bring back the old bytes.
        key = tuple(given.items()) if all(type(v) in _IMMUTABLE_VALUES for v in given.values()) else None
        last = self._last_encoded
        if key is not None and last is not None and last[0] == key:
            return last[1]
        unknown = set(given) - self.field_names
        if unknown:
            raise UnknownKey(f"assembly {self.instance} has no field {', '.join(sorted(unknown))}")
        out = bytearray(self.size)
        for name, value in given.items():
            self._put(out, self._by_name[name], value)
        encoded = bytes(out)
        if key is not None:
            self._last_encoded = (key, encoded)
        return encoded

    def with_field(self, data: bytes, name: str, value: Any) -> bytes:
        """``data`` with one field changed."""
        if name not in self._by_name:
            raise UnknownKey(f"assembly {self.instance} has no field {name!r}")
        out = bytearray(data)
        self._put(out, self._by_name[name], value)
        return bytes(out)

    def _put(self, out: bytearray, f: AssemblyField, value: Any) -> None:
        if f.bits:
            raw = int(value)
            if not 0 <= raw < (1 << f.bits):
                raise BadRequest(f"{f.name}: {value} does not fit {f.bits} bit(s)")
            mask = ((1 << f.bits) - 1) << f.bit
            out[f.offset] = (out[f.offset] & ~mask) | (raw << f.bit)
        else:
            out[f.offset:f.offset + (f.type.size or 0)] = f.type.encode(value)

    def field(self, name: str) -> AssemblyField:
        return self._by_name[name]

    def __repr__(self) -> str:
        return f"AssemblySchema({self.instance}, {self.name!r}, {self.size} bytes)"


def _bit_reader(f: AssemblyField) -> Callable[[bytes], Any]:
    offset, shift, mask = f.offset, f.bit, (1 << f.bits) - 1
    if f.bits == 1:
        return lambda data: bool((data[offset] >> shift) & 1)
    return lambda data: (data[offset] >> shift) & mask


def _word_reader(f: AssemblyField) -> Callable[[bytes], Any]:
    offset, size = f.offset, f.type.size or 0
    codec = f.type.struct_codec
    if codec is not None and codec.size == size:
        unpack = codec.unpack_from
        return lambda data: unpack(data, offset)[0]
    parse = f.type.construct.parse   # a type that is not one fixed format: its own codec
    return lambda data: parse(data[offset:offset + size])
