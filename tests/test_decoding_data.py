"""The compact declarations a one-shot command decodes by (``devices/declared/``) are the device
declarations: generated from them, and equal to them wherever a reply is decoded."""

from __future__ import annotations

import pytest

from cipstack.catalog import Catalog, compact_standard_classes, standard_classes
from cipstack.cip.compact import attribute_spec, cip_type, row_of, type_data
from cipstack.cip.model import AttributeSpec
from cipstack.cip.types import REVISION, ArrayType, OctetString, RealType, StructType
from cipstack.devices.decoding import DECLARED, STANDARD_DECLARED, generate, generate_standard
from cipstack.devices.profiles import PROFILES, catalog_for
from cipstack.profile_catalog import decoding_catalog


def test_the_generated_modules_are_up_to_date() -> None:
    """Run ``python -m cipstack.devices.decoding`` after changing a declaration."""
    generated = generate()
    assert sorted(generated) == sorted(p.name for p in DECLARED.glob("*.py"))
    for name, text in generated.items():
        assert (DECLARED / name).read_text(encoding="utf-8") == text, f"devices/declared/{name} is stale"
    assert STANDARD_DECLARED.read_text(encoding="utf-8") == generate_standard(), "objects/declared.py is stale"


def decoding(spec: AttributeSpec | None) -> tuple[object, ...] | None:
    """What reading a reply and writing a value take from a declaration (the range: what a value is
    checked against before it is sent)."""
    if spec is None:
        return None
    return (spec.id, spec.name, type(spec.type), spec.type.name, spec.access, spec.scaling, spec.in_get_all,
            spec.minimum, spec.maximum)


@pytest.mark.parametrize("name", sorted(PROFILES))
def test_every_declaration_decodes_alike(name: str) -> None:
    profile = PROFILES[name]
    for product_code in sorted(profile.product_codes)[:2]:
        full = catalog_for(profile.vendor_id, product_code)
        compact = decoding_catalog(profile.vendor_id, product_code)
        assert (compact.source, compact.profile, compact.save) == (full.source, full.profile, full.save)
        paths = [(class_id, instance, attribute.id) for class_id, spec in full.classes.items()
                 for instance in (1, 2) for attribute in spec.instance_attributes]
        paths += [(class_id, instance, attribute) for class_id in full.resolvers
                  for instance in range(0, 256, 3) for attribute in range(256)]
        checked = 0
        for path in paths:
            expected = decoding(full.attribute(*path))
            assert decoding(compact.attribute(*path)) == expected, path
            checked += expected is not None
        assert checked > 20
        assert [decoding(a) for a in compact.get_all_layout(0x2A) or []] == \
               [decoding(a) for a in full.get_all_layout(0x2A) or []]


@pytest.mark.parametrize("name", sorted(PROFILES))
def test_every_assembly_schema_is_the_device_models(name: str) -> None:
    """Class 1 fields are named by the compact data's schemas: the same fields (name, place, type,
    width, unit, scale, help, linked attribute), size and description as the device model's, and the
    same bytes for the same values."""
    profile = PROFILES[name]
    product_code = min(profile.product_codes)
    full = catalog_for(profile.vendor_id, product_code).assemblies
    compact = decoding_catalog(profile.vendor_id, product_code).assemblies
    assert sorted(compact) == sorted(full) and full
    for instance, schema in full.items():
        built = compact[instance]
        assert (built.name, built.size, built.description) == (schema.name, schema.size, schema.description)
        assert built.fields == schema.fields, instance
        data = bytes(range(1, schema.size + 1))
        assert built.decode(data) == schema.decode(data)
        assert built.encode(built.decode(data)) == schema.encode(schema.decode(data))


def test_a_device_of_no_profile_gets_the_standard_objects() -> None:
    assert decoding_catalog(1, 1).source == catalog_for(1, 1).source
    assert decoding_catalog(1, 1).attribute(0x2A, 1, 102) is None


def test_the_standard_objects_compact_data_is_their_declarations() -> None:
    """What a one-shot command decodes a standard attribute by (``objects/declared.py``): every row
    the objects' own declaration gives, the structures' members and the octet strings' sizes included."""
    full, compact = standard_classes(), compact_standard_classes()
    assert sorted(compact) == sorted(full) and len(full) >= 6
    for class_id, spec in full.items():
        assert compact[class_id].name == spec.name
        assert [row_of(a) for a in compact[class_id].instance_attributes] == \
               [row_of(a) for a in spec.instance_attributes], class_id
        assert [decoding(a) for a in compact[class_id].instance_attributes] == \
               [decoding(a) for a in spec.instance_attributes]
    by_compact, by_objects = Catalog(standard=compact), Catalog()
    reply = bytes([2, 0, 1, 0, 4, 0, 6, 0])  # Object List: the count, then class ids to the end
    assert by_compact.attribute(2, 1, 1).type.decode(reply) == by_objects.attribute(2, 1, 1).type.decode(reply) \
        == {"number": 2, "classes": [1, 4, 6]}
    assert by_compact.attribute(0xF6, 1, 3).type.decode(bytes(range(6))) == bytes(range(6))


def test_a_row_builds_its_declaration_again() -> None:
    structure = StructType("PAIR", [("count", REVISION), ("items", ArrayType(OctetString(2, "TWO"), 3, "TRIPLE"))])
    assert type_data(REVISION) == "REVISION"
    rebuilt = cip_type(type_data(structure))
    assert isinstance(rebuilt, StructType) and rebuilt.name == "PAIR" and rebuilt.size == 8
    assert rebuilt.decode(bytes(range(8))) == structure.decode(bytes(range(8)))
    spec = AttributeSpec(9, "Pair", structure, unit="s", scale=0.1, decimals=2, in_get_all=False)
    assert row_of(attribute_spec(row_of(spec))) == row_of(spec)
    with pytest.raises(ValueError, match="Odd: type ODD cannot be named"):  # a type cip.types has not
        row_of(AttributeSpec(1, "Odd", RealType("ODD", 0xCA, 4)))


@pytest.mark.parametrize("name", sorted(PROFILES))
def test_every_parameter_code_is_the_device_model_s(name: str) -> None:
    """The codes a scanner reads and writes by (``parameter("ACC")``), from the compact data: the same
    codes in the same order (the order a recipe writes them), each at the same path, declared alike
    (its range too: a value is checked against it before it is sent)."""
    profile = PROFILES[name]
    product_code = min(profile.product_codes)
    full = catalog_for(profile.vendor_id, product_code)
    compact = decoding_catalog(profile.vendor_id, product_code)
    expected = [(p.code, p.path, row_of(p.spec), decoding(p.spec)) for p in full.parameters]
    assert len(expected) > 40
    # One code asked for builds one declaration; the whole list after it is the device model's.
    for code, path, row, _ in expected[::7]:
        found = decoding_catalog(profile.vendor_id, product_code).parameter(code)
        assert found is not None and (found.path, row_of(found.spec)) == (path, row), code
    assert [(p.code, p.path, row_of(p.spec), decoding(p.spec)) for p in compact.parameters] == expected
    assert compact.parameter("no such code") is None and full.parameter("no such code") is None


def test_the_assemblies_are_built_when_asked_for() -> None:
    """Class 1 fields by name (``catalog.assemblies``): the device model's schemas, in its order, in a
    copy of the catalog too."""
    compact, full = decoding_catalog(259, 100), catalog_for(259, 100)
    copied = compact.copy("mine")
    assert sorted(compact.assemblies) == sorted(full.assemblies) and len(full.assemblies) >= 8
    assert [a.instance for a in compact.assemblies.values()] == [a.instance for a in full.assemblies.values()]
    assert (copied.source, copied.profile, sorted(copied.assemblies)) == ("mine", "acg", sorted(full.assemblies))
    assert copied.attribute(0x2A, 1, 102) == compact.attribute(0x2A, 1, 102)
