"""The EDS checker: a clean sample passes, and each broken variant fails the one rule it breaks,
on the line it breaks it."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cipstack.eds.checker import RULES, SOURCES, Finding, check_eds, data_type
from cipstack.eds.reader import parse_eds
from cipstack.eds.writer import format_eds

from .samples import ACG_IDENTITY, ADAPTER_EDS, MESSY_EDS


def line_of(text: str, snippet: str, after: int = 0) -> int:
    """1-based line where ``snippet`` starts, plus ``after`` lines."""
    position = text.index(snippet)
    assert text.count(snippet) == 1, f"{snippet!r} is not unique"
    return text.count("\n", 0, position) + 1 + after


def broken(old: str, new: str) -> str:
    assert ADAPTER_EDS.count(old) >= 1, f"{old!r} not in the sample"
    return ADAPTER_EDS.replace(old, new, 1)


def found(text: str, identity: dict | None = None) -> set[tuple[str, int]]:
    return {(finding.rule, finding.line) for finding in check_eds(parse_eds(text), identity)}


def test_sample_is_clean() -> None:
    assert check_eds(parse_eds(ADAPTER_EDS)) == []
    assert check_eds(parse_eds(ADAPTER_EDS), ACG_IDENTITY) == []


def test_written_sample_is_clean() -> None:
    assert check_eds(parse_eds(format_eds(parse_eds(ADAPTER_EDS), layout=True)), ACG_IDENTITY) == []


def test_messy_sample_is_clean() -> None:
    assert check_eds(parse_eds(MESSY_EDS.decode("latin-1")), ACG_IDENTITY) == []


def test_every_rule_has_a_description_and_a_source() -> None:
    assert all(RULES.values())
    assert len(RULES) == len(set(RULES))
    assert set(SOURCES) == set(RULES) and all(SOURCES.values())


# Each case: name, text replaced, replacement, the findings expected as (rule, snippet of the
# line, lines after the snippet); a snippet of None stands for line 0, the whole file.
CASES = [
    (
        "classification missing",
        "[Device Classification]\n    Class1 = EtherNetIP;\n\n", "",
        [("required-section", None, 0)],
    ),
    (
        "file section missing",
        ADAPTER_EDS[: ADAPTER_EDS.index("[Device]")], "",
        [("required-section", None, 0)],
    ),
    ("file keyword missing", "    CreateTime = 09:30:00;\n", "", [("required-keyword", "[File]", 0)]),
    ("device keyword missing", '    ProdTypeStr = "AC Drive";\n', "", [("required-keyword", "[Device]", 0)]),
    (
        "classification keyword missing",
        "    Class1 = EtherNetIP;\n", "    Class2 = EtherNetIP;\n",
        [("required-keyword", "[Device Classification]", 0)],
    ),
    (
        "duplicate keyword",
        "    MinRev = 1;\n", "    MinRev = 1;\n    ProdCode = 101;\n",
        [("duplicate-keyword", "ProdCode = 101", 0)],
    ),
    (
        "duplicate section",
        "    BootLoader", "    BootLoader = 1;\n[Capacity]\n    MaxIOConnections = 2;\n    Other",
        [("duplicate-section", "[Capacity]\n    MaxIOConnections = 2", 0)],
    ),
    (
        "section order",
        "[Device Classification]\n    Class1 = EtherNetIP;\n\n[Params]", "[Params]",
        [],  # completed below: the classification moves to the end of the file
    ),
    (
        "file not first",
        "$ ACG drive", "[Device Classification]\n    Class1 = EtherNetIP;\n$ ACG drive",
        [("section-order", "[Device Classification]\n    Class1 = EtherNetIP;\n$", 0),
         ("section-order", "[File]", 0), ("section-order", "[Device]", 0),
         ("duplicate-section", "[Device Classification]\n    Class1 = EtherNetIP;\n\n", 0)],
    ),
    (
        "parameter field count",
        '"Time from 0 to high speed",\n        1, 32000, 100,', '"Time from 0 to high speed",\n        1, 32000,',
        [("field-count", "Param5 =", 0)],
    ),
    (
        "connection field count",
        '"Input Only",\n        "",\n', '"Input Only",\n',
        [("field-count", "Connection2 =", 0)],
    ),
    (
        "assembly field count",
        '"20 04 24 C6 30 03", 0, 0x0000, , ;', '"20 04 24 C6 30 03", 0, 0x0000, ;',
        [("field-count", "Assem198 =", 0)],
    ),
    ("enum field count", '7, "Faulted";', "7;", [("field-count", "Enum7 =", 0)]),
    (
        "group member count",
        'Group2 = "Setup", 3, 5, 6, 9;', 'Group2 = "Setup", 4, 5, 6, 9;',
        [("field-count", "Group2 =", 0)],
    ),
    ("two values for one", "VendCode = 259;", "VendCode = 259, 1;", [("field-count", "VendCode =", 0)]),
    ("port field count", '"20 F5 24 01", 2;', '"20 F5 24 01";', [("field-count", "Port1 =", 0)]),
    ("transport spec field count", "TSpec1 = TxRx, 4, 1000;", "TSpec1 = TxRx, 4;", [("field-count", "TSpec1", 0)]),
    ("field type", "VendCode = 259;", 'VendCode = "259";', [("field-type", "VendCode =", 0)]),
    ("parameter name type", '"Decel Time",', "DecelTime,", [("field-type", "DecelTime,", 0)]),
    ("date format", "CreateDate = 03-14-2024;", "CreateDate = 2024-03-14;", [("date-format", "CreateDate", 0)]),
    ("impossible date", "ModDate = 11-02-2026;", "ModDate = 02-30-2026;", [("date-format", "ModDate", 0)]),
    ("time format", "CreateTime = 09:30:00;", "CreateTime = 25:30:00;", [("time-format", "CreateTime", 0)]),
    ("revision format", "Revision = 1.2;", "Revision = 1;", [("revision-format", "Revision = 1;", 0)]),
    (
        "epath format",
        '"20 2A 24 01 30 07"', '"20 2A 24 1 30 07"',
        [("epath-format", '"20 2A 24 1 30 07"', 0)],
    ),
    (
        "link path size",
        '6, "20 2A 24 01 30 08"', '4, "20 2A 24 01 30 08"',
        [("epath-format", '4, "20 2A 24 01 30 08"', 0)],
    ),
    (
        "empty connection path",
        '"20 04 24 01 2C C7 2C 47"', '""',
        [("epath-format", '"Listen Only",', 2)],
    ),
    (
        "network unknown",
        "Class1 = EtherNetIP;", "Class1 = Profibus;",
        [("device-classification", "Class1 = Profibus", 0)],
    ),
    ("data type", "0xC6, 1,", "0xC0, 1,", [("data-type", "0xC0, 1,", 0)]),
    ("data size", "0xCA, 4,", "0xCA, 2,", [("data-size", "0xCA, 2,", 0)]),
    (
        "default above maximum",
        "2000, 3200000, 10000,", "2000, 3200000, 1000,",
        [("min-default-max", "2000, 3200000, 1000,", 0)],
    ),
    (
        "minimum above maximum",
        "0.0, 500.0, 0.0,", "600.0, 500.0, 0.0,",
        [("min-default-max", "600.0, 500.0, 0.0,", 0)],
    ),
    ("value outside the type", "0, 7, 1,", "0, 300, 1,", [("value-range", "0, 300, 1,", 0)]),
    ("assembly member missing", "16, Param2;", "16, Param12;", [("param-reference", "16, Param12;", 0)]),
    (
        "parameter in a path missing",
        '6, "20 2A 24 01 30 08"', '6, "20 2A 24 [Param20] 30 08"',
        [("param-reference", "[Param20]", 0)],
    ),
    (
        "connection RPI parameter missing",
        "Param9, 4, Assem21,", "Param19, 4, Assem21,",
        [("param-reference", "Param19, 4, Assem21,", 0)],
    ),
    ("group member missing", '"Setup", 3, 5, 6, 9;', '"Setup", 3, 5, 6, 10;', [("param-reference", "Group2", 0)]),
    (
        "enum without parameter",
        "    Enum7 =", "    Enum17 =",
        [("enum-reference", "Enum17 =", 0), ("enum-reference", "0x0012,", 0)],
    ),
    (
        "connection assembly missing",
        "Param9, 4, Assem21,", "Param9, 4, Assem22,",
        [("assembly-reference", "Param9, 4, Assem22,", 0)],
    ),
    (
        "assembly members do not fill it",
        "16, Param4;", "8, Param4;",
        [("assembly-size", '"20 04 24 47 30 03",', 1)],
    ),
    (
        "connection size differs from its assembly",
        "Param9, 4, Assem21,", "Param9, 2, Assem21,",
        [("connection-size", "Param9, 2, Assem21,", 0)],
    ),
    (
        "connection without trigger",
        "0x04010002,", "0x04000002,",
        [("connection-format", "0x04000002,", 0)],
    ),
    (
        "listen only without multicast",
        "0x44240305,", "0x44440305,",
        [("connection-format", "0x44440305,", 0)],
    ),
    (
        "heartbeat with data",
        "Param9, 0, Assem198,", "Param9, 2, Assem198,",
        [("connection-format", "Param9, 2, Assem198,", 0), ("connection-size", "Param9, 2, Assem198,", 0)],
    ),
    (
        "connection point differs from the assembly",
        '"20 04 24 01 2C 15 2C 47"', '"20 04 24 01 2C 16 2C 47"',
        [("connection-path", '"20 04 24 01 2C 16 2C 47"', 0)],
    ),
]


@pytest.mark.parametrize(("old", "new", "expected"), [case[1:] for case in CASES], ids=[case[0] for case in CASES])
def test_broken_file(old: str, new: str, expected: list[tuple[str, str | None, int]]) -> None:
    text = broken(old, new)
    if not expected:  # section order: the classification goes to the end of the file
        text += "\n[Device Classification]\n    Class1 = EtherNetIP;\n"
        expected = [("section-order", "[Device Classification]", 0)]
    wanted = {(rule, 0 if snippet is None else line_of(text, snippet, after)) for rule, snippet, after in expected}
    assert found(text) == wanted


@pytest.mark.parametrize(
    ("identity", "keyword"),
    [
        ({**ACG_IDENTITY, "vendor_id": 258}, "VendCode"),
        ({**ACG_IDENTITY, "device_type": 3}, "ProdType"),
        ({**ACG_IDENTITY, "product_code": 101}, "ProdCode"),
        ({**ACG_IDENTITY, "revision": (2, 1)}, "MajRev"),
        ({**ACG_IDENTITY, "revision": {"major": 1, "minor": 3}}, "MinRev"),
        ({**ACG_IDENTITY, "product_name": "ACG"}, "ProdName"),
    ],
)
def test_device_identity(identity: dict, keyword: str) -> None:
    assert found(ADAPTER_EDS, identity) == {("device-identity", line_of(ADAPTER_EDS, f"    {keyword} ="))}


def test_partial_identity_checks_what_it_has() -> None:
    assert found(ADAPTER_EDS, {"product_code": 100}) == set()
    assert found(ADAPTER_EDS, {"product_code": 7}) == {("device-identity", line_of(ADAPTER_EDS, "ProdCode ="))}


def test_findings_are_in_line_order_with_severities() -> None:
    text = broken("0, 7, 1,", "0, 300, 1,").replace("VendCode = 259;", 'VendCode = "x";')
    findings = check_eds(parse_eds(text))
    assert [finding.line for finding in findings] == sorted(finding.line for finding in findings)
    assert {(finding.rule, finding.severity) for finding in findings} == {
        ("field-type", "error"), ("value-range", "warning"),
    }
    assert all(isinstance(finding, Finding) and finding.rule in RULES for finding in findings)


def test_parameter_with_international_strings_has_24_fields() -> None:
    text = broken('        "Motor current",\n        0.0, 500.0, 0.0,\n        , , , ,\n        , , , ,\n        1;',
                  '        "Motor current",\n        0.0, 500.0, 0.0,\n        , , , ,\n        , , , ,\n        1,'
                  ' "", "", "";')
    assert found(text) == set()


def test_devicenet_file_needs_no_classification() -> None:
    text = broken("[Device Classification]\n    Class1 = EtherNetIP;\n\n", "[IO_Info]\n    Default = 0x0001;\n\n")
    assert "required-section" not in {rule for rule, _ in found(text)}


def test_data_types_known_beyond_the_elementary() -> None:
    assert data_type(0xC7) == ("UINT", 2)
    assert data_type(0xDA) == ("SHORT_STRING", None)
    assert data_type(0xDC) == ("EPATH", None)
    assert data_type(0xDE) == ("STRINGI", None)
    assert data_type(0xC0) is None


def test_string_parameter_is_exempt_from_size() -> None:
    text = broken("0xC6, 1,", "0xDA, 17,").replace("0, 7, 1,", '"", "", "",')
    assert found(text) == set()


def test_assembly_member_sizes_taken_from_the_parameters() -> None:
    text = broken("16, Param3,\n        16, Param4;", ", Param3,\n        , Param4;")
    assert found(text) == set()
    text = broken("16, Param3,\n        16, Param4;", ", Param3,\n        , Param7;")
    assert found(text) == {("assembly-size", line_of(text, '"20 04 24 47 30 03",', 1))}


# -- the checker reads anything the reader accepts ------------------------------------------

_SECTIONS = ["File", "Device", "Device Classification", "Params", "Groups", "Assembly", "Connection Manager",
             "Port", "Capacity", "IO_Info"]
_KEYWORDS = st.one_of(
    st.sampled_from(["DescText", "CreateDate", "CreateTime", "ModDate", "Revision", "VendCode", "ProdName",
                     "MajRev", "MinRev", "ProdCode", "ProdType", "MaxIOConnections", "Class1"]),
    # (Param|Enum|Assem|Connection|Group|Port|TSpec|Class)[1-3], from its parts: st.from_regex draws slowly.
    st.builds("{}{}".format, st.sampled_from(["Param", "Enum", "Assem", "Connection", "Group", "Port", "TSpec",
                                              "Class"]), st.integers(1, 3)),
)
_WORDS = st.sampled_from(["Param1", "Param2", "Assem1", "Assem2", "Enum1", "TxRx", "EtherNetIP", "1.5", "0x10",
                          "-7", "300", "0", "01-02-2020", "99-99-9999", "12:00:00", "x", "0xC7", "0xDA", "2"])
_FIELD_TEXT = st.one_of(
    _WORDS,
    st.just(""),
    st.sampled_from(['"name"', '"20 04 24 01 2C 01 2C 02"', '"20 04 24 [Param1]"', '"21 00 04 00 25 00 01 00"',
                     '"20 2A 24 01 30 08"', '"zz"', '""']),
    st.integers(min_value=-(2**33), max_value=2**33).map(str),
)

# Lengths the rules look for (a parameter's 21 or 24, a connection's 15, an assembly's pairs).
# One strategy per length, built once: a flatmap built and validated a new one at every draw, which
# took most of the test's time.
_FIELD_LISTS = st.one_of(*(st.lists(_FIELD_TEXT, min_size=count, max_size=count)
                           for count in (1, 2, 3, 4, 6, 8, 10, 15, 21, 24)))


@settings(max_examples=150, deadline=None)
@given(
    st.lists(
        st.tuples(st.sampled_from(_SECTIONS), st.lists(st.tuples(_KEYWORDS, _FIELD_LISTS))),
        max_size=8,
    ),
    st.one_of(st.none(), st.just(ACG_IDENTITY), st.just({"revision": {"major": 1, "minor": 1}})),
)
def test_checker_never_fails_on_what_the_reader_accepts(layout, identity) -> None:  # type: ignore[no-untyped-def]
    text = "".join(
        f"[{name}]\n" + "".join(f"{keyword} = {', '.join(fields)};\n" for keyword, fields in entries)
        for name, entries in layout
    )
    findings = check_eds(parse_eds(text), identity)
    lines = text.count("\n")
    for finding in findings:
        assert finding.rule in RULES
        assert finding.severity in ("error", "warning")
        assert 0 <= finding.line <= lines
        assert finding.message and "\n" not in finding.message


COMPONET_EDS = """\
[File]
    DescText = "MX2 CompoNet option board";
    CreateDate = 06-01-2025;
    CreateTime = 10:00:00;
    Revision = 1.0;

[Device]
    VendCode = 47;
    VendName = "Example";
    ProdType = 2;
    ProdTypeStr = "AC Drive";
    ProdCode = 1;
    MajRev = 1;
    MinRev = 1;
    ProdName = "MX2 CompoNet";
    Catalog = "3G3AX-MX2-CRT";

[Device Classification]
    Class1 = CompoNet;

[CompoNet_IO]
    CompoNet_Input_Info = 1, 4;
    CompoNet_Output_Info = 1, 4;
"""


def test_componet_file() -> None:
    doc = parse_eds(COMPONET_EDS)
    assert check_eds(doc) == []
    assert doc.entry("CompoNet_IO", "CompoNet_Input_Info").value(2) == 4


# -- what configuration tools accept (issue: false errors on files from the field) -------------------------
#: In the style of EZ-EDS output: no Catalog, a CIP Safety device class, a safety connection of 17
#: fields, and a configuration format that is a parameter.
EZ_EDS_STYLE = """\
$ EZ-EDS Version 3.31 Generated Electronic Data Sheet

[File]
        DescText = "Safety I/O block";
        CreateDate = 04-02-2025;
        CreateTime = 10:11:12;
        ModDate = 04-02-2025;
        ModTime = 10:11:12;
        Revision = 1.1;

[Device]
        VendCode = 65001;
        VendName = "Example Controls";
        ProdType = 35;
        ProdTypeStr = "Safety Discrete I/O Device";
        ProdCode = 7;
        MajRev = 1;
        MinRev = 1;
        ProdName = "SIO-8";

[Device Classification]
        Class1 = EtherNetIP;
        Class2 = Safety;

[Params]
        Param1 =
                0,
                ,,
                0x0000,
                0xC7,
                2,
                "Config Word",
                "",
                "",
                0,0xFFFF,0,
                ,,,,
                ,,,,,
                ,,;

[Assembly]
        Assem100 = "Safety Input", "20 04 24 64 30 03", 2, 0x0000,,;
        Assem150 = "Safety Output", "20 04 24 96 30 03", 2, 0x0000,,;

[Connection Manager]
        Connection1 =
                0x02030001,
                0x44640405,
                , 2, Assem150,
                , 2, Assem100,
                , ,
                2, Param1,
                "Safety Exclusive Owner",
                "",
                "20 04 24 97 2C 96 2C 64",
                1,
                1;
"""


def test_a_file_in_the_ez_eds_style_is_clean() -> None:
    findings = check_eds(parse_eds(EZ_EDS_STYLE))
    assert [(f.rule, f.message) for f in findings if f.severity == "error"] == []
    assert not any("Safety" in f.message or "Catalog" in f.message or "17 fields" in f.message for f in findings)


def test_a_connection_of_16_fields_is_still_wrong() -> None:
    text = EZ_EDS_STYLE.replace("""                1,
                1;""", """                1;""")
    assert ("field-count", line_of(text, "        Connection1 =")) in found(text)


def test_a_configuration_parameter_that_is_not_there_is_reported() -> None:
    text = EZ_EDS_STYLE.replace("2, Param1,", "2, Param9,")
    assert any(rule.startswith("param") or "reference" in rule for rule, _ in found(text)), found(text)


def test_catalog_may_be_missing() -> None:
    assert found(broken('    Catalog = "ACG-ET2";\n', "")) == set()


# -- errors the checker used to miss ---------------------------------------------------------------------
def _rules(text: str) -> set[tuple[str, int]]:
    return {(f.rule, f.line) for f in check_eds(parse_eds(text)) if f.severity == "error"}


def test_an_assembly_naming_itself_is_its_own_data() -> None:
    """The idiom of a drive vendor's files: every assembly one member naming the assembly itself,
    sized or empty (its own size then). Read as the instance's own data: no finding."""
    for member in ("16, Assem150", ", Assem150"):
        text = EZ_EDS_STYLE.replace('''Assem150 = "Safety Output", "20 04 24 96 30 03", 2, 0x0000,,;''',
                                    f'''Assem150 = "Safety Output", "20 04 24 96 30 03", 2, 0x0000,,, {member};''')
        assert [f for f in check_eds(parse_eds(text)) if f.severity != "info"] == [], member
    # Sized wrong, it is still wrong: the member sum is checked as for any member.
    text = EZ_EDS_STYLE.replace('''Assem150 = "Safety Output", "20 04 24 96 30 03", 2, 0x0000,,;''',
                                '''Assem150 = "Safety Output", "20 04 24 96 30 03", 2, 0x0000,,, 8, Assem150;''')
    assert _rules(text) == {("assembly-size", line_of(text, "Assem150 = "))}


def test_an_assembly_that_contains_itself_through_another() -> None:
    # Sized consistently (16 bits, 2 bytes), so only the loop is wrong: it has no size.
    text = EZ_EDS_STYLE.replace('''Assem100 = "Safety Input", "20 04 24 64 30 03", 2, 0x0000,,;''',
                                '''Assem100 = "Safety Input", "20 04 24 64 30 03", 2, 0x0000,,, 16, Assem150;''')
    text = text.replace('''Assem150 = "Safety Output", "20 04 24 96 30 03", 2, 0x0000,,;''',
                        '''Assem150 = "Safety Output", "20 04 24 96 30 03", 2, 0x0000,,, 16, Assem100;''')
    assert _rules(text) == {("assembly-member", line_of(text, "Assem100 = ")),
                            ("assembly-member", line_of(text, "Assem150 = "))}
    message = next(f.message for f in check_eds(parse_eds(text)) if f.rule == "assembly-member")
    assert message == "Assem100 contains itself through Assem150 -> Assem100: it has no size"


def test_a_connection_path_without_a_connection_point() -> None:
    text = EZ_EDS_STYLE.replace('"20 04 24 97 2C 96 2C 64"', '"20 04 24 97 24 64"')
    assert ("connection-path", line_of(text, '"20 04 24 97 24 64"')) in _rules(text)


def test_an_object_class_code_of_another_class() -> None:
    text = EZ_EDS_STYLE.replace("[Connection Manager]\n", "[Connection Manager]\n        Object_Class_Code = 0x05;\n")
    assert _rules(text) == {("class-code", line_of(text, "Object_Class_Code = 0x05"))}
    assert _rules(text.replace("0x05", "0x06")) == set()


@pytest.mark.parametrize(("right", "wrong"), [("VendCode", "vendcode"), ("ProdName", "PRODNAME"),
                                              ("Assem100 =", "assem100 ="), ("Param1 =", "param1 =")])
def test_a_keyword_in_another_case_is_a_warning_and_read_as_written_right(right: str, wrong: str) -> None:
    """Keywords are case sensitive in the specification, but configuration tools and eds-pie read
    them in any case: a warning, and the entry counts (no missing keyword, no broken reference)."""
    text = EZ_EDS_STYLE.replace(right, wrong, 1)
    findings = check_eds(parse_eds(text))
    assert [(f.rule, f.severity, f.line) for f in findings] == [("keyword-case", "warning", line_of(text, wrong))]


def test_object_class_code_in_another_case() -> None:
    """A vendor file writes Object_Class_code: a warning, and the code is still checked."""
    text = EZ_EDS_STYLE.replace("[Connection Manager]\n", "[Connection Manager]\n        Object_Class_code = 0x06;\n")
    assert [(f.rule, f.severity) for f in check_eds(parse_eds(text))] == [("keyword-case", "warning")]
    assert _rules(text.replace("0x06;", "0x05;")) == {("class-code", line_of(text, "Object_Class_code"))}


def _safety_format(text: str) -> str:
    return text.replace("0x44640405,", "0x44640505,")


def test_real_time_format_5_on_a_safety_connection() -> None:
    """Format 5 is CIP Safety's: accepted on a connection with the safety fields or of a device
    classed Safety; elsewhere a warning; 6 and 7 stay reserved (errors)."""
    assert check_eds(parse_eds(_safety_format(EZ_EDS_STYLE))) == []
    plain = _safety_format(EZ_EDS_STYLE).replace("        Class2 = Safety;\n", "").replace(
        '2C 64",\n                1,\n                1;', '2C 64";')
    line = line_of(plain, "0x44640505,")
    assert [(f.rule, f.severity, f.line) for f in check_eds(parse_eds(plain))] == [
        ("connection-format", "warning", line)]
    reserved = EZ_EDS_STYLE.replace("0x44640405,", "0x44640605,")
    assert _rules(reserved) == {("connection-format", line_of(reserved, "0x44640605,"))}


def test_a_utf8_file_is_noted() -> None:
    text = EZ_EDS_STYLE.replace('"Example Controls"', '"Müller Steuerungen"')
    as_read = text.encode("utf-8").decode("latin-1")
    findings = check_eds(parse_eds(as_read))
    assert [(f.rule, f.severity, f.line) for f in findings] == [("encoding", "info", line_of(text, "Müller"))]
    assert "'Müller' on this line reads as 'MÃ¼ller'" in findings[0].message
    # Latin-1 is read as written: nothing to note.
    assert check_eds(parse_eds(text.encode("latin-1").decode("latin-1"))) == []
