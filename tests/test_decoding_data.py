"""The compact declarations a one-shot command decodes by (``devices/declared/``) are the device
declarations: generated from them, and equal to them wherever a reply is decoded."""

from __future__ import annotations

import pytest

from cipstack.cip.model import AttributeSpec
from cipstack.devices.decoding import DECLARED, decoding_catalog, generate
from cipstack.devices.profiles import PROFILES, catalog_for


def test_the_generated_modules_are_up_to_date() -> None:
    """Run ``python -m cipstack.devices.decoding`` after changing a declaration."""
    generated = generate()
    assert sorted(generated) == sorted(p.name for p in DECLARED.glob("*.py"))
    for name, text in generated.items():
        assert (DECLARED / name).read_text(encoding="utf-8") == text, f"devices/declared/{name} is stale"


def decoding(spec: AttributeSpec | None) -> tuple[object, ...] | None:
    """What reading a reply and writing a value take from a declaration."""
    if spec is None:
        return None
    return (spec.id, spec.name, type(spec.type), spec.type.name, spec.access, spec.scaling, spec.in_get_all)


@pytest.mark.parametrize("name", sorted(PROFILES))
def test_every_declaration_decodes_alike(name: str) -> None:
    profile = PROFILES[name]
    for product_code in sorted(profile.product_codes)[:2]:
        full = catalog_for(profile.vendor_id, product_code)
        compact = decoding_catalog(profile.vendor_id, product_code)
        assert (compact.source, compact.profile) == (full.source, full.profile)
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


def test_a_device_of_no_profile_gets_the_standard_objects() -> None:
    assert decoding_catalog(1, 1).source == catalog_for(1, 1).source
    assert decoding_catalog(1, 1).attribute(0x2A, 1, 102) is None
