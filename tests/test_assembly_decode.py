"""``AssemblySchema.decode`` reads each field directly (it is on the class 1 hot path); the compiled
``construct`` schema is the reference: the same values, of the same types, in the same order, for
every assembly every profile declares and for words of every fixed-size type."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cipstack.assemblies.schema import AssemblyField, AssemblySchema, bit, word
from cipstack.cip.types import DINT, INT, LREAL, REAL, SINT, UDINT, UINT, ULINT, USINT
from cipstack.devices.profiles import PROFILES


def _schemas() -> list[AssemblySchema]:
    found = []
    for profile in PROFILES.values():
        assert profile.catalog is not None
        found += list(profile.catalog().assemblies.values())
    # Words of every fixed-size integer and real type, flags and multi-bit fields, an undeclared byte.
    found.append(AssemblySchema(900, "every type", 36, [
        bit("flag", 0, 0), AssemblyField("wide", 0, bits=3, bit=2), bit("top", 0, 7), word("usint", 2, USINT),
        word("sint", 3, SINT), word("uint", 4, UINT), word("int", 6, INT), word("udint", 8, UDINT),
        word("dint", 12, DINT), word("real", 16, REAL), word("ulint", 20, ULINT), word("lreal", 28, LREAL)]))
    return found


SCHEMAS = _schemas()


@pytest.mark.parametrize("schema", SCHEMAS, ids=[f"{s.instance}-{s.name}" for s in SCHEMAS])
@settings(max_examples=60, deadline=None)
@given(data=st.data())
def test_decode_matches_the_construct_schema(schema: AssemblySchema, data: st.DataObject) -> None:
    raw = data.draw(st.binary(min_size=schema.size, max_size=schema.size))
    fast, reference = schema.decode(raw), schema.decode_with_construct(raw)
    assert list(fast) == list(reference)
    # repr: a REAL may decode to NaN, which equals nothing, itself included.
    assert [(type(v), repr(v)) for v in fast.values()] == [(type(v), repr(v)) for v in reference.values()]


def test_a_wrong_size_is_refused() -> None:
    schema = SCHEMAS[0]
    with pytest.raises(ValueError, match=f"is {schema.size} bytes"):
        schema.decode(bytes(schema.size + 1))
