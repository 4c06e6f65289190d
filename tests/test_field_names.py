"""The field-name rule (cipstack/assemblies/names.py): vendor-style names, repeats, and the profiles'
own names, which the rule must leave as they are."""

from __future__ import annotations

import pytest

from cipstack.assemblies.names import display_name, field_name, unique_field_names
from cipstack.devices.acg.device import build_acg_device
from cipstack.devices.omron.assemblies import (
    CENTIHERTZ,
    DECIHERTZ,
    FLEXIBLE_MAX_WORDS,
    RPM,
    flexible_schema,
    omron_schemas,
)


@pytest.mark.parametrize(("text", "name"), [
    # Words as a configuration tool shows them.
    ("Drive Fault", "drive_fault"),
    ("Faulted", "faulted"),
    ("DC Bus Voltage", "dc_bus_voltage"),
    ("Input 1", "input_1"),
    ("Motor-Current (A)", "motor_current_a"),
    ("Ref.From Network", "ref_from_network"),
    ("Control From Net.", "control_from_net"),
    ("Torque Ref (rel)", "torque_ref_rel"),
    ("  Speed   Actual  ", "speed_actual"),
    # CamelCase as the CIP specification writes attribute names.
    ("SpeedActual", "speed_actual"),
    ("CtrlFromNet", "ctrl_from_net"),
    ("FaultRst", "fault_rst"),
    ("speedRef", "speed_ref"),
    ("RPMActual", "rpm_actual"),
    ("DCBusVoltage", "dc_bus_voltage"),
    ("IPAddress", "ip_address"),
    ("Mx2Drive", "mx2_drive"),
    # Already a field name, or snake case in another case.
    ("Ctrl_From_Net", "ctrl_from_net"),
    ("speed_actual", "speed_actual"),
    ("SPEED_ACTUAL", "speed_actual"),
    # A letter then a digit is one word; short mixed-case codes stay whole.
    ("Running1", "running1"),
    ("bA.1", "ba_1"),
    ("dEC", "dec"),
    ("nOn", "non"),
    ("kWh", "kwh"),
    # A leading digit makes no identifier: the prefix.
    ("1st Accel", "p_1st_accel"),
    ("0.00", "p_0_00"),
    # Accents go, ß is ss, other non-ASCII characters are dropped.
    ("Drehzahl Ist-Wert \u00e4", "drehzahl_ist_wert_a"),
    ("Gr\u00f6\u00dfe", "grosse"),
    ("Strom \u00b5A", "strom_a"),
    # Nothing usable.
    ("", ""),
    ("---", ""),
    ("\u2014", ""),
])
def test_vendor_style_names(text: str, name: str) -> None:
    assert field_name(text) == name


def test_one_device_two_spellings_one_name() -> None:
    """The issue's case: the names of the profile and of a configuration tool are one field."""
    for profile, tool in (("faulted", "Faulted"), ("ready", "Ready"), ("speed_actual", "Speed Actual"),
                          ("speed_actual", "SpeedActual"), ("ctrl_from_net", "Ctrl From Net"),
                          ("ctrl_from_net", "CtrlFromNet"), ("run_forward", "Run Forward")):
        assert field_name(tool) == field_name(profile) == profile


def test_repeats_take_their_position() -> None:
    assert unique_field_names(["input", "input", "speed", "input"]) == ["input", "input_2", "speed", "input_4"]
    # A suffixed name never takes a name that occurs in its own right, earlier or later.
    assert unique_field_names(["a", "a", "a_2"]) == ["a", "a_2_2", "a_2"]
    assert unique_field_names(["a", "a_2", "a"]) == ["a", "a_2", "a_3"]
    assert unique_field_names(["x", "y"]) == ["x", "y"]
    # The same input always gives the same names.
    names = ["reserved", "speed", "reserved", "reserved"]
    assert unique_field_names(names) == unique_field_names(list(names)) == ["reserved", "speed", "reserved_3",
                                                                            "reserved_4"]


def test_display_name_reads_well_and_maps_back() -> None:
    assert display_name("ctrl_from_net") == "Ctrl From Net"
    assert display_name("speed_actual") == "Speed Actual"
    assert display_name("p_1st_accel") == "P 1st Accel"
    for name in ("ctrl_from_net", "speed_actual", "p_1st_accel", "output_1", "data_word_0", "drive_model_4"):
        assert field_name(display_name(name)) == name


def _declared_schemas() -> list:
    device = build_acg_device()
    acg = [device.assembly_schema(instance) for instance in device.assembly.points]
    omron = [schema for unit in (CENTIHERTZ, DECIHERTZ, RPM) for schema in omron_schemas(unit).values()]
    flexible = [flexible_schema(instance, words) for instance in (139, 159)
                for words in range(1, FLEXIBLE_MAX_WORDS + 1)]
    return acg + omron + flexible


def test_every_profile_field_is_in_field_name_form() -> None:
    """The profiles' names are what scripts use: the rule leaves each unchanged, and an EDS that names
    the member ``display_name(field)`` gives it back."""
    wrong = {(schema.instance, item.name) for schema in _declared_schemas() for item in schema.fields
             if field_name(item.name) != item.name or field_name(display_name(item.name)) != item.name}
    assert wrong == set()


def test_acg_smart_scaling_words_keep_their_names() -> None:
    """Words 121-128 / 141-148 are named after the registers CM.51-58 / CM.31-38 name, by the rule; a
    register named twice gets its word number (the names at the factory addresses, as before)."""
    device = build_acg_device()
    assert [f.name for f in device.assembly_schema(145).fields] == [
        "output_frequency", "operation_status", "fault_trip_information", "drive_model", "drive_model_5"]
    assert [f.name for f in device.assembly_schema(124).fields] == [
        "target_frequency", "operation_command_option", "drive_model", "drive_model_4"]
