"""The EDS generator: the files of the ACG-ET2 and of every MX2/RX option board model.

Each generated file is checked by our checker (no error), read back byte-identically, read by
eds-pie with only its known false positives, and compared with the declarations it comes from
(identity, assembly sizes, parameter limits). ``eds generate --all`` must write exactly the
files of Tables 2 and 3 of the Omron option board manual, transcribed here from the manual.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterator
from datetime import datetime, timezone
from functools import cache
from pathlib import Path
from typing import Any

import pytest

from cipstack.assemblies.drive_profile import extended_speed_control_input, extended_speed_control_output
from cipstack.assemblies.schema import AssemblySchema, word
from cipstack.cip.model import Access, AttributeSpec
from cipstack.cip.types import INT, UINT
from cipstack.devices.acg.eds_file import acg_et2_description
from cipstack.devices.omron import models as omron
from cipstack.devices.omron.eds_file import omron_description, omron_models_by_file
from cipstack.devices.profiles import acg_et2_identity
from cipstack.eds.checker import ERROR, check_eds
from cipstack.eds.commands_generate import add_generate_arguments, run_generate
from cipstack.eds.description import EdsDescription, EdsObjectClass, EdsParameter, IoOffer, attribute_parameters
from cipstack.eds.generator import (
    DEFAULT_CREATED,
    EXCLUSIVE_OWNER_KIND,
    INPUT_ONLY_KIND,
    LISTEN_ONLY_KIND,
    class_section_name,
    connection_words,
    eds_text,
    generate_eds,
    scaling,
)
from cipstack.eds.model import EdsDocument, FieldKind
from cipstack.eds.profiles import eds_file_name
from cipstack.eds.reader import parse_eds
from cipstack.eds.writer import format_eds
from cipstack.eip.target.io_target import IoProfile
from cipstack.objects.assembly import AssemblyPoint
from cipstack.objects.identity import identity_spec
from cipstack.objects.tcpip import TCPIP_SPEC
from tests.optional import needs

from .conftest import EdsPieLog

# Table 2 (MX2 Device List) and Table 3 (RX Device List), "Name of EDS file" column.
TABLE_2 = (
    "3G3AX-MX2-CRT-AB001_A2001-E.eds", "3G3AX-MX2-CRT-AB002_A2002-E.eds", "3G3AX-MX2-CRT-AB004_A2004-E.eds",
    "3G3AX-MX2-CRT-AB007_A2007-E.eds", "3G3AX-MX2-CRT-AB015_A2015-E.eds", "3G3AX-MX2-CRT-AB022_A2022-E.eds",
    "3G3AX-MX2-CRT-A2037-E.eds", "3G3AX-MX2-CRT-A2055-E.eds", "3G3AX-MX2-CRT-A2075-E.eds",
    "3G3AX-MX2-CRT-A2110-E.eds", "3G3AX-MX2-CRT-A2150-E.eds", "3G3AX-MX2-CRT-A4004-E.eds",
    "3G3AX-MX2-CRT-A4007-E.eds", "3G3AX-MX2-CRT-A4015-E.eds", "3G3AX-MX2-CRT-A4022-E.eds",
    "3G3AX-MX2-CRT-A4030-E.eds", "3G3AX-MX2-CRT-A4040-E.eds", "3G3AX-MX2-CRT-A4055-E.eds",
    "3G3AX-MX2-CRT-A4075-E.eds", "3G3AX-MX2-CRT-A4110-E.eds", "3G3AX-MX2-CRT-A4150-E.eds",
)
TABLE_3 = tuple(f"3G3AX-RX-CRT-{code}-E.eds" for code in (
    "A2004", "A2007", "A2015", "A2022", "A2037", "A2055", "A2075", "A2110", "A2150", "A2185", "A2220", "A2300",
    "A2370", "A2450", "A2550", "A4004", "A4007", "A4015", "A4022", "A4040", "A4055", "A4075", "A4110", "A4150",
    "A4185", "A4220", "A4300", "A4370", "A4450", "A4550", "B4750", "B4900", "B411K", "B413K",
))

MODEL_NAMES = [item.name for item in omron.MODELS]
CREATED = datetime(2026, 3, 14, 9, 26, 53, tzinfo=timezone.utc)


@pytest.fixture(autouse=True)
def _no_epoch(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("SOURCE_DATE_EPOCH", raising=False)


@cache
def acg_text() -> str:
    return eds_text(acg_et2_description())


@cache
def omron_text(name: str) -> str:
    return eds_text(omron_description(name))


def all_texts() -> Iterator[tuple[str, str]]:
    yield "ACG-ET2", acg_text()
    for name in MODEL_NAMES:
        yield name, omron_text(name)


@cache
def parsed(name: str) -> EdsDocument:
    """The generated file of ``name`` ("ACG-ET2" or a model), parsed once for the tests of every file
    (each only reads it): parsing the 62 files takes seconds, and five tests go through them all."""
    return parse_eds(acg_text() if name == "ACG-ET2" else omron_text(name))


def all_parsed() -> Iterator[tuple[str, EdsDocument]]:
    for name, _ in all_texts():
        yield name, parsed(name)


def value(doc: EdsDocument, section: str, keyword: str) -> Any:
    entry = doc.entry(section, keyword)
    assert entry is not None, f"[{section}] {keyword}"
    return entry.value(1)


# -- determinism and dates ----------------------------------------------------------------------------

def test_same_description_same_bytes() -> None:
    first = eds_text(acg_et2_description()).encode("ascii")
    second = eds_text(acg_et2_description()).encode("ascii")
    assert first == second
    assert eds_text(omron_description("RX-A4015-E")) == eds_text(omron_description("rx-a4015-e "))


def test_default_date_is_fixed() -> None:
    doc = generate_eds(acg_et2_description())
    assert value(doc, "File", "CreateDate") == (DEFAULT_CREATED.month, DEFAULT_CREATED.day, DEFAULT_CREATED.year)
    assert value(doc, "File", "CreateTime") == (0, 0, 0)
    assert value(doc, "File", "ModDate") == value(doc, "File", "CreateDate")


def test_source_date_epoch_honoured(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SOURCE_DATE_EPOCH", str(int(CREATED.timestamp())))
    doc = generate_eds(acg_et2_description())
    assert value(doc, "File", "CreateDate") == (3, 14, 2026)
    assert value(doc, "File", "CreateTime") == (9, 26, 53)
    assert value(doc, "File", "ModTime") == (9, 26, 53)
    assert eds_text(acg_et2_description()) == eds_text(acg_et2_description(), CREATED)
    assert eds_text(acg_et2_description()) != eds_text(acg_et2_description(), DEFAULT_CREATED)


def test_created_argument_wins(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "0")
    doc = generate_eds(acg_et2_description(), created=CREATED)
    assert value(doc, "File", "CreateDate") == (3, 14, 2026)


def test_bad_source_date_epoch(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "yesterday")
    with pytest.raises(ValueError, match="SOURCE_DATE_EPOCH"):
        generate_eds(acg_et2_description())


# -- every generated file ------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["ACG-ET2", *MODEL_NAMES])
def test_checker_finds_no_error(name: str) -> None:
    findings = check_eds(parsed(name))
    assert [f for f in findings if f.severity == ERROR] == []
    assert findings == []


def test_round_trip_byte_identical() -> None:
    for name, text in all_texts():
        assert format_eds(parsed(name), layout=True) == text, name
        assert text.isascii() and "\r\n" in text and "\n" not in text.replace("\r\n", ""), name


def test_device_equals_acg_identity() -> None:
    doc = parse_eds(acg_text())
    identity = acg_et2_identity()
    assert value(doc, "Device", "VendCode") == identity.vendor_id == 259
    assert value(doc, "Device", "ProdType") == identity.device_type == 2
    assert value(doc, "Device", "ProdCode") == identity.product_code == 100
    assert (value(doc, "Device", "MajRev"), value(doc, "Device", "MinRev")) == identity.revision == (1, 1)
    assert value(doc, "Device", "ProdName") == identity.product_name == "CENT"
    # Vendor 259's name as the ODVA vendor list of the field's scanners has it (pycomm3's table).
    vendors = needs("pycomm3.cip.status_info").VENDORS
    assert value(doc, "Device", "VendName") == vendors[259] == "LS ELECTRIC"
    assert value(doc, "Device Classification", "Class1") == "EtherNetIP"
    live = {"vendor_id": 259, "device_type": 2, "product_code": 100, "revision": (1, 1), "product_name": "CENT"}
    assert check_eds(doc, live) == []
    assert [f.rule for f in check_eds(doc, {**live, "product_code": 101})] == ["device-identity"]


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_device_equals_omron_identity(name: str) -> None:
    doc = parsed(name)
    found = omron.model(name)
    assert value(doc, "Device", "VendCode") == omron.VENDOR_ID == 47
    assert value(doc, "Device", "VendName") == "OMRON Corporation"
    assert value(doc, "Device", "ProdType") == omron.DEVICE_TYPE
    assert value(doc, "Device", "ProdCode") == found.product_code
    assert (value(doc, "Device", "MajRev"), value(doc, "Device", "MinRev")) == omron.REVISION
    assert value(doc, "Device", "ProdName") == found.product_name
    assert value(doc, "Device", "Catalog") == found.family.option_board
    assert value(doc, "Device Classification", "Class1") == "CompoNet"


def test_assembly_members_add_up() -> None:
    for name, doc in all_parsed():
        params = doc.get("Params")
        assert params is not None
        # The keywords once: `ref in params` looks through every entry of the section.
        keywords = {entry.keyword for entry in params}
        for entry in doc.get("Assembly") or ():
            sizes = [item.value for item in entry.fields[6::2]]
            references = [item.value for item in entry.fields[7::2]]
            assert sum(sizes) == 8 * entry.value(3), f"{name} {entry.keyword}"
            assert all(ref is None or ref in keywords for ref in references), f"{name} {entry.keyword}"
            instance = int(entry.keyword[len("Assem"):])
            assert entry.value(2) == (0x20, 0x04, 0x24, instance, 0x30, 0x03)


def test_every_param_min_default_max() -> None:
    for name, doc in all_parsed():
        params = doc.get("Params")
        assert params is not None
        for entry in params:
            if not entry.keyword.startswith("Param"):
                continue
            low, high, default = (entry.value(n) for n in (10, 11, 12))
            assert low <= default <= high, f"{name} {entry.keyword}"
            assert len(entry.fields) == 21


# -- parameters --------------------------------------------------------------------------------------

def param(doc: EdsDocument, name: str) -> Any:
    params = doc.get("Params")
    assert params is not None
    for entry in params:
        if entry.keyword.startswith("Param") and entry.value(7) == name:
            return entry
    raise KeyError(name)


def test_scaled_keypad_parameter() -> None:
    doc = parse_eds(acg_text())
    entry = param(doc, "dr.20 Max Freq")
    assert entry.value(3) == (0x20, 0x64, 0x24, 0x01, 0x30, 20)  # class 0x64, dr group, code 20
    assert entry.value(2) == 6
    assert entry.value(4) & 0x04  # scaling
    assert (entry.value(5), entry.value(6)) == (0xC7, 2)
    assert entry.value(8) == "Hz"
    assert [entry.value(n) for n in (10, 11, 12)] == [4000, 40000, 6000]
    assert [entry.value(n) for n in (13, 14, 15, 16)] == [1, 100, 1, 0]
    assert entry.value(21) == 2
    assert scaling(0.1) == (1, 10, 1)
    assert scaling(1.0) is None


def test_enumerated_parameter() -> None:
    doc = parse_eds(acg_text())
    entry = param(doc, "Pr.12 Lost Cmd Mode")
    assert entry.value(4) & 0x02
    number = entry.keyword[len("Param"):]
    enum = doc.entry("Params", f"Enum{number}")
    assert enum is not None
    assert [item.value for item in enum.fields] == [0, "None", 1, "Free-Run", 2, "Dec", 3, "Hold Input",
                                                   4, "Hold Output", 5, "Lost Preset"]
    # A few named values in a wider range are no enumeration: they go to the help text.
    frq = param(parse_eds(omron_text("MX2-A2015-E")), "A001 Frequency source")
    assert not frq.value(4) & 0x02
    assert "4 = Option Board Interface" in frq.value(9)


def test_omron_function_code_paths() -> None:
    doc = parse_eds(omron_text("MX2-A2015-E"))
    # Table E-3: P046 = 15046 = 0x3AC6 -> instance 0x3A, attribute 0xC6.
    entry = param(doc, "P046 Default connection path")
    assert entry.value(3) == (0x20, 0x65, 0x24, 0x3A, 0x30, 0xC6)
    assert entry.value(4) & 0x02 and entry.value(12) == 1
    # F001 cannot be written through the Function Code object (section E-2-2): read only.
    f001 = param(doc, "F001 Output frequency setting")
    assert f001.value(4) & 0x10
    assert (f001.value(5), f001.value(6)) == (0xC8, 4)
    # b127 is two words by function code (section E-2-2).
    b127 = param(doc, "b127 Function code b127")
    assert b127.value(6) == 4


def test_groups_list_every_grouped_param() -> None:
    doc = parse_eds(acg_text())
    groups = doc.get("Groups")
    assert groups is not None
    names = [entry.value(1) for entry in groups]
    # The CIP objects' attributes first (one group per class), then the keypad groups.
    assert names[:6] == ["Motor Data", "Control Supervisor", "AC/DC Drive", "dr Group", "bA Group", "Ad Group"]
    assert "CM Group" in names
    members = [item.value for entry in groups for item in entry.fields[2:]]
    assert len(members) == len(set(members))
    assert all(entry.value(2) == len(entry.fields) - 2 for entry in groups)


# -- connections, ports, capacity -------------------------------------------------------------------

def test_connection_words_are_the_usual_values() -> None:
    assert connection_words(EXCLUSIVE_OWNER_KIND) == (0x04010002, 0x44640405)
    assert connection_words(INPUT_ONLY_KIND) == (0x02010002, 0x44640305)
    assert connection_words(LISTEN_ONLY_KIND) == (0x01010002, 0x44240305)


def test_acg_connections() -> None:
    doc = parse_eds(acg_text())
    manager = doc.get("Connection Manager")
    assert manager is not None
    connections = list(manager)
    first = connections[0]
    # The factory settings CM.24 = 1, CM.23 = 1 select outputs 21 and inputs 71: listed first.
    assert first.value(13) == "Exclusive Owner 21/71"
    assert (first.value(1), first.value(2)) == (0x04010002, 0x44640405)
    assert (first.value(4), first.value(5), first.value(7), first.value(8)) == (4, "Assem21", 4, "Assem71")
    assert first.value(15) == (0x20, 0x04, 0x24, 0x01, 0x2C, 21, 0x2C, 71)
    rpi = doc.entry("Params", first.value(3))
    assert rpi is not None and (rpi.value(10), rpi.value(11)) == (1_000, 10_000_000)
    kinds = {entry.value(1) for entry in connections}
    assert kinds == {0x04010002, 0x02010002, 0x01010002}
    heartbeat = [entry for entry in connections if entry.value(1) != 0x04010002]
    assert {entry.value(5) for entry in heartbeat} == {"Assem198", "Assem199"}
    assert all(entry.value(4) == 0 for entry in heartbeat)
    port = doc.entry("Port", "Port1")
    assert port is not None and [item.value for item in port.fields] == ["TCP", "EtherNet/IP Port",
                                                                         (0x20, 0xF5, 0x24, 0x01), 2]
    assert value(doc, "Capacity", "MaxIOConnections") == 64
    assert value(doc, "Capacity", "MaxMsgConnections") == 32
    # One TSpec per data size: 2 to 16 bytes (121-128 / 141-148), 4 (the speed assemblies), at 1 ms.
    capacity = doc.get("Capacity")
    assert capacity is not None
    tspecs = [[item.value for item in entry.fields] for entry in capacity if entry.keyword.startswith("TSpec")]
    assert tspecs == [["TxRx", size, 1000] for size in range(2, 17, 2)]
    # Every class the card's message router serves, but Assembly and Connection Manager.
    for section in ("Identity Class", "Message Router Class", "TCP/IP Interface Class", "Ethernet Link Class",
                    "259_Motor Data Class", "259_Control Supervisor Class", "259_AC/DC Drive Class",
                    "259_Keypad Parameters Class"):
        assert section in doc


def test_omron_file_has_no_ethernet_sections() -> None:
    doc = parse_eds(omron_text("RX-B413K-E"))
    for section in ("Connection Manager", "Port", "Capacity", "TCP/IP Interface Class"):
        assert section not in doc


def test_componet_io_default_path() -> None:
    # P046 = 1 at the factory: Extended Speed IO, output 21 / input 71, two words each (Table 10).
    doc = parse_eds(omron_text("MX2-A2015-E"))
    section = doc.get("CompoNet_IO")
    assert section is not None
    assert [item.value for item in section.get("CompoNet_Input_Info").fields] == [2, 2]  # type: ignore[union-attr]
    assert [item.value for item in section.get("CompoNet_Output_Info").fields] == [2, 2]  # type: ignore[union-attr]


def _words(instance: int, name: str, count: int) -> AssemblySchema:
    return AssemblySchema(instance, name, 2 * count, [word(f"word_{n}", 2 * n, UINT) for n in range(count)])


def test_componet_io_sizes_of_section_3_4_example() -> None:
    # Section 3-4 Step 6/7: P046 = 5 selects 101 (8 bytes) and 153 (10 bytes): input 5 words, output 4.
    base = omron_description("MX2-A2015-E")
    description = EdsDescription(
        identity=base.identity, vendor_name=base.vendor_name, product_type_name=base.product_type_name,
        catalog=base.catalog, network="CompoNet", description=base.description,
        outputs=(_words(101, "Output 101", 4),), inputs=(_words(153, "Input 153", 5),), componet_io=(101, 153),
    )
    doc = generate_eds(description)
    text = format_eds(doc)
    assert "CompoNet_Input_Info =\r\n        2,  $ length unit: 0 bits, 1 bytes, 2 words\r\n        5;" in text
    assert value(doc, "CompoNet_IO", "CompoNet_Output_Info") == 2
    assert doc.entry("CompoNet_IO", "CompoNet_Output_Info").value(2) == 4  # type: ignore[union-attr]
    assert check_eds(parse_eds(text)) == []


def test_members_reference_declared_attribute() -> None:
    # A declared attribute whose name gives the field's name ("Speed Reference": speed_reference) is
    # the member's parameter itself, not a copy.
    speed = AttributeSpec(8, "Speed Reference", INT, Access.GET_SET, default=0, unit="rpm", help="Speed reference")
    declared = EdsParameter.from_attribute(speed, (0x2A, 1, 8), group="AC/DC Drive")
    doc = generate_eds(acg_et2_description(attributes=[declared]))
    assem = doc.entry("Assembly", "Assem21")
    assert assem is not None
    assert assem.fields[-1].value == "Param1"
    assert value(doc, "Params", "Param1") == 0
    assert doc.entry("Params", "Param1").value(7) == "Speed Reference"  # type: ignore[union-attr]


def test_a_member_under_another_name_gets_its_own_parameter_with_the_same_link() -> None:
    # The attribute as the object table names it ("SpeedRef" gives speed_ref) keeps its name; the
    # member gets a parameter named after the field, with the attribute's link, type and range.
    speed = AttributeSpec(8, "SpeedRef", INT, Access.GET_SET, default=0, minimum=0, maximum=24000, unit="rpm",
                          help="Speed reference in rpm")
    declared = EdsParameter.from_attribute(speed, (0x2A, 1, 8), group="AC/DC Drive")
    doc = generate_eds(acg_et2_description(attributes=[declared]))
    assem = doc.entry("Assembly", "Assem21")
    assert assem is not None
    member = doc.entry("Params", assem.fields[-1].value)
    assert member is not None and assem.fields[-1].value != "Param1"
    assert doc.entry("Params", "Param1").value(7) == "SpeedRef"  # type: ignore[union-attr]
    assert (member.value(7), member.value(9)) == ("Speed Reference", "Speed reference")
    assert member.value(3) == doc.entry("Params", "Param1").value(3) == (0x20, 0x2A, 0x24, 0x01, 0x30, 0x08)  # type: ignore[union-attr]
    assert (member.value(5), member.value(10), member.value(11)) == (0xC3, 0, 24000)
    # Every other assembly with that field refers to the same member parameter.
    assert doc.entry("Assembly", "Assem20").fields[-1].value == assem.fields[-1].value  # type: ignore[union-attr]


def test_a_field_name_the_rule_would_change_is_refused() -> None:
    bad = AssemblySchema(21, "Output", 2, [word("SpeedRef", 0, UINT)])
    description = acg_et2_description(outputs=[bad], inputs=[extended_speed_control_input(71)],
                                      io=IoOffer(pairs=((21, 71),)))
    with pytest.raises(ValueError, match="'SpeedRef' is not in field-name form"):
        generate_eds(description)


def test_io_offer_from_io_profile() -> None:
    points = {21: AssemblyPoint(21, 4, True), 71: AssemblyPoint(71, 4, False)}
    profile = IoProfile(consumed=lambda: {21: points[21]}, produced=lambda: {71: points[71]}, rpi_min_us=2_000,
                        pairs=lambda: {(21, 71)})
    offer = IoOffer.from_io_profile(profile)
    assert offer.pairs == ((21, 71),)
    assert (offer.rpi_min_us, offer.rpi_max_us, offer.rpi_default_us) == (2_000, 10_000_000, 10_000)
    assert (offer.input_only_point, offer.listen_only_point, offer.config_instance) == (198, 199, 1)
    description = acg_et2_description(outputs=[extended_speed_control_output(21)],
                                      inputs=[extended_speed_control_input(71)], io=offer)
    doc = parse_eds(eds_text(description))
    assert check_eds(doc) == []
    manager = doc.get("Connection Manager")
    assert manager is not None and [entry.value(13) for entry in manager] == [
        "Exclusive Owner 21/71", "Input Only 71", "Listen Only 71"]


def test_description_rejects_unknown_pair() -> None:
    with pytest.raises(ValueError, match="pair 22/71"):
        acg_et2_description(io=IoOffer(pairs=((20, 70), (22, 71))))


# -- eds-pie ----------------------------------------------------------------------------------------

UNKNOWN_ENTRY = "Unknown Entry [{section.keyword,}].{entry.keyword}"




def known_false_positives(doc: EdsDocument) -> list[str]:
    """What eds-pie says of entries it does not know: [Groups] and [Port] (every entry and field),
    and for CompoNet its missing protocol database and the CompoNet sections."""
    expected: list[str] = []
    if doc.get("Device Classification") and value(doc, "Device Classification", "Class1") == "CompoNet":
        expected.append('Requested Protocol Database "CompoNet" not available!')
    for section in doc:
        unknown_section = section.name.startswith("CompoNet")
        if unknown_section:
            expected.append(f"Unknown Section [{section.name}]")
        if section.name not in ("Groups", "Port") and not unknown_section:
            continue
        for entry in section:
            expected.append(UNKNOWN_ENTRY)
            expected.extend(f"Unknown Field [{section.name}].{entry.keyword}.field{n}"
                            for n in range(len(entry.fields)))
    return expected


@pytest.mark.interop
def test_eds_pie_reads_acg(cip_eds: Any, eds_pie_log: EdsPieLog) -> None:
    text = acg_text()
    ours = parse_eds(text)
    theirs = cip_eds(text)
    assert [record.getMessage() for record in eds_pie_log.records] == known_false_positives(ours)
    assert theirs.protocol == "EtherNetIP"
    assert theirs.get_value("Device", "VendCode") == 259
    assert theirs.get_value("Device", "ProdName") == "CENT"
    assert list(theirs.sections) == [section.name for section in ours]


#: One model per generated file: every file of Tables 2 and 3.
FILE_MODELS = [item.name for family in omron.Family for item in omron_models_by_file(family)]


@pytest.mark.interop
@pytest.mark.parametrize("name", FILE_MODELS)
def test_eds_pie_reads_omron(cip_eds: Any, eds_pie_log: EdsPieLog, name: str) -> None:
    theirs = cip_eds(omron_text(name))
    assert [record.getMessage() for record in eds_pie_log.records] == known_false_positives(parsed(name))
    assert theirs.get_value("Device", "ProdCode") == omron.model(name).product_code


# -- the command --------------------------------------------------------------------------------------

def run(*argv: str) -> int:
    parser = argparse.ArgumentParser(prog="cipstack eds generate")
    add_generate_arguments(parser)
    return run_generate(parser.parse_args(list(argv)))


@pytest.mark.parametrize(("profile", "table"), [("mx2", TABLE_2), ("rx", TABLE_3)])
def test_generate_all_writes_the_table(profile: str, table: tuple[str, ...], tmp_path: Path,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    assert run("--profile", profile, "--all", "-o", str(tmp_path)) == 0
    assert sorted(path.name for path in tmp_path.iterdir()) == sorted(table)
    assert len(table) == (21 if profile == "mx2" else 34)
    out, err = capsys.readouterr()
    assert err == "" and len(out.splitlines()) == len(table)
    for path in tmp_path.iterdir():
        text = path.read_bytes().decode("ascii")
        doc = parse_eds(text)
        assert text == format_eds(doc, layout=True)
        assert value(doc, "Device", "ProdName") + ".eds" == path.name


def test_generate_paired_mx2_models_share_a_file(tmp_path: Path) -> None:
    assert run("--profile", "mx2", "--model", "MX2-A2001-E", "-o", str(tmp_path / "a")) == 0
    assert run("--profile", "mx2", "--model", "MX2-AB001-E", "-o", str(tmp_path / "b")) == 0
    (first,) = (tmp_path / "a").iterdir()
    (second,) = (tmp_path / "b").iterdir()
    assert first.name == second.name == "3G3AX-MX2-CRT-AB001_A2001-E.eds"
    assert first.read_bytes() == second.read_bytes()


def test_generate_acg(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert run("--profile", "acg", "-o", str(tmp_path)) == 0
    (path,) = tmp_path.iterdir()
    assert path.name == eds_file_name(acg_et2_description()) == "ACG-ET2_1.01.eds"
    assert path.read_bytes() == acg_text().encode("ascii")
    assert capsys.readouterr().out == f"{path}\n"


@pytest.mark.parametrize(("argv", "message"), [
    (("--profile", "mx2", "--model", "MX2-A9999-E"), "unknown inverter model 'MX2-A9999-E'"),
    # Nothing near: the message still says where the valid names are.
    (("--profile", "mx2", "--model", "MX2-XXXX"), "unknown inverter model 'MX2-XXXX': `cipstack models` lists "
                                                  "the 61 models (MX2-AB001-E to RX-B413K-E)"),
    (("--profile", "rx", "--model", "MX2-A2015-E"), "MX2-A2015-E is not an RX model"),
    (("--profile", "vfd", "--all"), "unknown profile 'vfd'"),
    (("--profile", "acg", "--model", "ACG"), "profile acg has one model"),
    (("--profile", "mx2",), "give --model M or --all"),
])
def test_generate_errors(argv: tuple[str, ...], message: str, tmp_path: Path,
                         capsys: pytest.CaptureFixture[str]) -> None:
    assert run(*argv, "-o", str(tmp_path)) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert err.count("\n") == 1 and err.startswith("cipstack eds generate: ") and message in err
    assert list(tmp_path.iterdir()) == []


def test_generate_unwritable_directory(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    assert run("--profile", "acg", "-o", str(blocker / "out")) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cannot create directory" in err


def test_generated_paths_are_epaths() -> None:
    doc = parse_eds(acg_text())
    for section in doc:
        for entry in section:
            if entry.keyword.startswith("Param"):
                assert entry.fields[2].kind is FieldKind.EPATH


def test_class_attributes_as_parameters() -> None:
    # Every attribute an EDS can type, strings included, gives a parameter our checker accepts.
    parameters = (*attribute_parameters(identity_spec()), *attribute_parameters(TCPIP_SPEC))
    assert (1, 1, 4) not in {p.link for p in parameters}  # the Revision structure has no EDS type
    doc = parse_eds(eds_text(acg_et2_description(attributes=parameters)))
    assert check_eds(doc) == []
    name = param(doc, "Product Name")
    assert (name.value(3), name.value(5)) == ((0x20, 0x01, 0x24, 0x01, 0x30, 0x07), 0xDA)
    assert name.value(4) & 0x10  # Get only: read only


# -- the files declare what the devices serve -----------------------------------------------------------

def test_acg_file_lists_every_assembly_and_pair_of_the_device() -> None:
    from cipstack.devices.acg import registers as acg_registers
    from cipstack.devices.acg.device import RPI_MIN_US, build_acg_device

    device = build_acg_device(now=0.0)
    doc = parse_eds(acg_text())
    assembly = doc.get("Assembly")
    assert assembly is not None
    sizes = {int(entry.keyword[5:]): entry.value(3) for entry in assembly}
    served = {instance: point.size for instance, point in device.assembly.points.items()}
    assert {i: s for i, s in sizes.items() if s} == served  # 20/21/100/101/121-128, 70/71/110/111/141-148
    assert len(served) == 24
    profile = device.io_profile()
    assert (sizes[profile.input_only_point], sizes[profile.listen_only_point]) == (0, 0)
    manager = doc.get("Connection Manager")
    assert manager is not None
    owners = [entry.value(15)[-3::2] for entry in manager if entry.value(1) == 0x04010002]
    # One exclusive owner per CM.24/CM.23 setting, the factory pair first.
    expected = [(o.instance, i.instance) for o, i in zip(acg_registers.CIP_OUTPUT_INSTANCES,
                                                           acg_registers.CIP_INPUT_INSTANCES, strict=True)]
    assert owners[0] == next(iter(profile.pairs()))
    assert sorted(owners) == sorted(expected)
    rpi = doc.entry("Params", manager.entries[0].value(3))
    assert rpi is not None and rpi.value(10) == RPI_MIN_US
    # Assembly members refer to the CIP attributes the card declares (Control Supervisor Run Fwd).
    run_forward = doc.entry("Params", doc.entry("Assembly", "Assem21").value(8))  # type: ignore[union-attr]
    assert run_forward is not None and run_forward.value(3) == (0x20, 0x29, 0x24, 0x01, 0x30, 0x03)


@pytest.mark.parametrize("name", ["MX2-A2015-E", "RX-A4055-E"])
def test_omron_file_lists_what_the_device_serves(name: str) -> None:
    from cipstack.devices.omron.assemblies import componet_io_words
    from cipstack.devices.omron.device import build_omron_device
    from cipstack.devices.omron.objects import CLASS_SPECS

    device = build_omron_device(name)
    doc = parse_eds(omron_text(name))
    assembly = doc.get("Assembly")
    assert assembly is not None
    assert {int(entry.keyword[5:]): entry.value(3) for entry in assembly} == {
        instance: point.size for instance, point in device.assembly.points.items()}
    words = componet_io_words(*device.default_pair)
    assert doc.entry("CompoNet_IO", "CompoNet_Input_Info").value(2) == words[0]  # type: ignore[union-attr]
    assert doc.entry("CompoNet_IO", "CompoNet_Output_Info").value(2) == words[1]  # type: ignore[union-attr]
    # A section for every class of CLASS_SPECS, with the instances the device has.
    for spec in CLASS_SPECS:
        section = doc.get(class_section_name(EdsObjectClass(spec), omron.VENDOR_ID) or "")
        assert section is not None, spec.name
        count = section.get("Number_Of_Static_Instances")
        assert count is not None and count.value() == len(device.router.objects[spec.class_id].instances)


@pytest.mark.parametrize(("name", "instances"), [("MX2-A2015-E", 7), ("RX-A4055-E", 9)])
def test_link_paths_name_only_instances_the_model_has(name: str, instances: int) -> None:
    """The Extended Control assemblies are the family's; their CI8/MI8 members link to Discrete Input
    Point instance 8 and the RX's forward terminal to instance 9, which the MX2 does not have (7
    instances, Table C-10): the MX2's file must not send a tool to them (it would read 0x16)."""
    doc = parse_eds(omron_text(name))
    paths = [str(entry.field(3).raw).strip('"') for entry in doc.get("Params").entries
             if entry.keyword.startswith("Param") and entry.field(3) is not None]
    linked = {int(path.split()[3], 16) for path in paths if path.startswith("20 08 24")}
    assert max(linked) == instances
