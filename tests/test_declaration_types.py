"""The declaration types as values: made once, never changed, equal by what they declare.

``AttributeSpec`` is a named tuple and ``ClassSpec`` a slotted class (neither a dataclass: making
one compiles its methods at import, which a one-shot command cannot afford). What the rest of the
package relies on is held here: a changed copy leaves the original alone, a copy is checked as a
new declaration is, an object cannot be changed in place, equal declarations are equal and hash
alike, and `copy.copy` gives an equal declaration, indexed like the original.
"""

from __future__ import annotations

import copy

import pytest

from cipstack.cip.messages import Service
from cipstack.cip.model import Access, AttributeSpec, ClassSpec
from cipstack.cip.types import UINT, USINT
from cipstack.cip.values import Scaling

SPEED = AttributeSpec(2, "Speed Reference", UINT, Access.GET_SET, default=0, maximum=1800, unit="rpm")
MODE = AttributeSpec(3, "Mode", USINT, Access.GET_SET, enum={1: "speed", 2: "torque"})
DRIVE = ClassSpec(0x70, "Test Drive", revision=3, instance_attributes=(SPEED, MODE), max_instance=4)


def test_an_attribute_declaration_is_a_value() -> None:
    changed = SPEED._replace(maximum=3600)
    assert (changed.maximum, SPEED.maximum) == (3600, 1800)
    assert changed != SPEED and changed._replace(maximum=1800) == SPEED
    with pytest.raises(AttributeError):
        SPEED.maximum = 1  # type: ignore[misc]  # a named tuple's field is read-only: the point
    assert SPEED.scaling == Scaling("rpm", 1.0, 0.0, None, None)
    assert MODE.scaling.enum == {1: "speed", 2: "torque"}
    assert repr(SPEED).startswith("AttributeSpec(id=2, name='Speed Reference', type=")


def test_a_class_declaration_indexes_its_attributes_when_made() -> None:
    assert DRIVE.instance_attribute(3) is MODE
    assert DRIVE.instance_attribute(9) is None
    assert DRIVE.instance_services == frozenset({Service.GET_ATTRIBUTES_ALL, Service.GET_ATTRIBUTE_SINGLE,
                                                 Service.SET_ATTRIBUTE_SINGLE, Service.GET_ATTRIBUTE_LIST,
                                                 Service.SET_ATTRIBUTE_LIST})
    assert DRIVE.class_services == frozenset({Service.GET_ATTRIBUTE_SINGLE})


def test_an_attribute_id_declared_twice_is_refused_by_a_copy_too() -> None:
    with pytest.raises(ValueError, match="Test Drive: an instance attribute id is declared twice"):
        ClassSpec(0x70, "Test Drive", instance_attributes=(SPEED, MODE._replace(id=2)))
    with pytest.raises(ValueError, match="declared twice"):
        DRIVE.replace(instance_attributes=(SPEED, SPEED))


def test_a_changed_copy_of_a_class_leaves_the_original_alone() -> None:
    fewer = DRIVE.replace(instance_attributes=(SPEED,), name="Smaller Drive")
    assert (fewer.name, fewer.instance_attributes, fewer.revision, fewer.max_instance) == \
        ("Smaller Drive", (SPEED,), 3, 4)
    assert fewer.instance_attribute(3) is None
    assert DRIVE.instance_attribute(3) is MODE and DRIVE.name == "Test Drive"
    with pytest.raises(TypeError, match="ClassSpec has no field colour"):
        DRIVE.replace(colour="red")


def test_a_class_declaration_cannot_be_changed_in_place() -> None:
    with pytest.raises(AttributeError, match="immutable"):
        DRIVE.name = "Other"
    with pytest.raises(AttributeError, match="immutable"):
        del DRIVE.revision
    with pytest.raises(AttributeError):
        DRIVE.colour = "red"


def test_equal_class_declarations_are_equal_and_hash_alike() -> None:
    same = ClassSpec(0x70, "Test Drive", 3, (SPEED, MODE), max_instance=4)
    assert same == DRIVE and same is not DRIVE
    assert DRIVE.replace(revision=4) != DRIVE
    assert DRIVE != (0x70, "Test Drive")
    plain = ClassSpec(0x71, "Plain", instance_attributes=(AttributeSpec(1, "Count", UINT),))
    assert hash(plain) == hash(ClassSpec(0x71, "Plain", instance_attributes=(AttributeSpec(1, "Count", UINT),)))
    assert repr(plain).startswith("ClassSpec(class_id=113, name='Plain', revision=1, instance_attributes=(")


def test_a_copied_class_declaration_is_equal_and_indexed() -> None:
    copied = copy.copy(DRIVE)
    assert copied == DRIVE and copied is not DRIVE
    assert copied.instance_attribute(2) is SPEED
