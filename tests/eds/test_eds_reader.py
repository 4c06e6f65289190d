"""Reading EDS text: lexical rules, the model it builds, syntax errors and their lines."""

from __future__ import annotations

import datetime

import pytest

from cipstack.assemblies.drive_profile import DriveState
from cipstack.cip.status import GeneralStatus
from cipstack.eds.model import (
    EdsDocument,
    Entry,
    Field,
    FieldKind,
    Section,
    semantic_differences,
    semantically_equal,
)
from cipstack.eds.reader import EdsSyntaxError, parse_eds, read_eds
from cipstack.eds.writer import encode_eds, format_eds

from .samples import ADAPTER_EDS, MESSY_EDS


def kinds_and_values(doc: EdsDocument, section: str, keyword: str) -> list[tuple[str, object]]:
    entry = doc.entry(section, keyword)
    assert entry is not None, f"[{section}] {keyword} missing"
    return [(item.kind.value, item.value) for item in entry.fields]


@pytest.fixture(scope="module")
def messy(tmp_path_factory: pytest.TempPathFactory) -> EdsDocument:
    path = tmp_path_factory.mktemp("eds") / "messy.eds"
    path.write_bytes(MESSY_EDS)
    return read_eds(path)


class TestAdapterSample:
    def test_sections_in_file_order(self) -> None:
        doc = parse_eds(ADAPTER_EDS)
        assert [section.name for section in doc] == [
            "File", "Device", "Device Classification", "Params", "Groups", "Assembly", "Connection Manager",
            "Port", "Capacity", "TCP/IP Interface Class", "259_Drive Service",
        ]

    def test_typed_values(self) -> None:
        doc = parse_eds(ADAPTER_EDS)
        assert kinds_and_values(doc, "File", "CreateDate") == [("date", (3, 14, 2024))]
        assert kinds_and_values(doc, "File", "CreateTime") == [("time", (9, 30, 0))]
        assert kinds_and_values(doc, "File", "Revision") == [("revision", (1, 2))]
        assert kinds_and_values(doc, "Device Classification", "Class1") == [("keyword", "EtherNetIP")]
        assert kinds_and_values(doc, "Port", "Port1") == [
            ("keyword", "TCP"), ("string", "EtherNet/IP Port"), ("epath", (0x20, 0xF5, 0x24, 0x01)), ("int", 2),
        ]
        assert kinds_and_values(doc, "259_Drive Service", "Flags") == [("int", 3), ("int", 7)]

    def test_parameter_fields_and_lines(self) -> None:
        doc = parse_eds(ADAPTER_EDS)
        param = doc.entry("Params", "Param2")
        assert param is not None
        assert len(param.fields) == 21
        assert param.line == ADAPTER_EDS.splitlines().index("    Param2 =") + 1
        assert param.field(3).kind is FieldKind.EPATH
        assert param.value(3) == (0x20, 0x2A, 0x24, 0x01, 0x30, 0x08)
        assert param.value(10) == -3600
        assert param.field(5).raw == "0xC3"
        assert param.field(17).is_empty
        # The limits are on the line after the help text.
        assert param.field(10).line == param.field(9).line + 1
        assert doc.entry("Params", "Param8").value(11) == 500.0

    def test_comment_before_an_entry_belongs_to_it(self) -> None:
        doc = parse_eds(ADAPTER_EDS)
        assert doc.entry("Params", "Param1").comments == ["the control word has no attribute of its own: no link path"]
        assert doc.sections[0].comments[0].startswith("ACG drive with its ACG-ET2")


class TestMessyFile:
    def test_latin1_and_concatenated_strings(self, messy: EdsDocument) -> None:
        assert messy.entry("File", "DescText").value() == "Variateur ACG pour r\xe9seau"
        assert messy.entry("Device", "VendName").value() == "Soci\xe9t\xe9 Exemple"
        assert messy.entry("Params", "Param1").value(7) == "Speed Reference"

    def test_crlf_and_several_entries_on_a_line(self, messy: EdsDocument) -> None:
        create_date = messy.entry("File", "CreateDate")
        create_time = messy.entry("File", "CreateTime")
        assert create_date.line == create_time.line == 5
        assert create_time.value() == (8, 0, 0)
        assert messy.entry("Device Classification", "Class1").line == 15

    def test_numbers(self, messy: EdsDocument) -> None:
        assert kinds_and_values(messy, "Device", "ProdType") == [("int", 2)]
        assert kinds_and_values(messy, "File", "Revision") == [("revision", (2, 10))]
        ratio = messy.entry("259_Extras", "259_Ratio")
        assert [(item.kind, item.number) for item in ratio.fields[:3]] == [
            (FieldKind.FLOAT, 0.004), (FieldKind.FLOAT, 1000.0), (FieldKind.INT, 5),
        ]
        assert ratio.field(4).kind is FieldKind.DATASET
        assert [child.value for child in ratio.field(4).value] == [1, 2, 3]
        assert ratio.field(5).kind is FieldKind.TIME

    def test_lowercase_epath(self, messy: EdsDocument) -> None:
        assert messy.entry("Params", "Param1").value(3) == (0x20, 0x2A, 0x24, 0x01, 0x30, 0x08)

    def test_multi_line_entry_with_empty_fields(self, messy: EdsDocument) -> None:
        param = messy.entry("Params", "Param1")
        assert param.line == 18
        assert len(param.fields) == 21
        assert [item.line for item in param.fields[12:20]] == [25] * 8
        assert all(item.is_empty for item in param.fields[12:20])
        assert param.field(21).value == 0 and param.field(21).line == 26

    def test_comments_kept(self, messy: EdsDocument) -> None:
        file_section = messy.get("File")
        assert file_section.comments == ["Fichier EDS \xe9crit \xe0 la main", "second header line", "section comment"]
        param = messy.entry("Params", "Param1")
        assert param.comments == ["the only parameter", "own-line comment inside the entry"]
        assert param.field(1).comment == "reserved"
        assert param.field(3).comment == "link path"
        assert param.field(21).comment == "after the end"
        assert messy.entry("Device", "VendCode").field(1).comment == "vendor"
        assert messy.trailing_comments == ["closing comment"]

    def test_written_back_byte_for_byte(self, messy: EdsDocument) -> None:
        assert encode_eds(format_eds(messy)) == MESSY_EDS

    def test_laid_out_afresh_as_latin1_crlf_with_the_same_meaning(self, messy: EdsDocument) -> None:
        text = format_eds(messy, layout=True)
        assert "\n" not in text.replace("\r\n", "")
        # Latin-1 letters are written as themselves: other readers take "\xE9" literally.
        assert '"Variateur ACG pour r\xe9seau"' in text and "\\x" not in text
        assert "$ Fichier EDS \xe9crit \xe0 la main" in text
        again = parse_eds(encode_eds(text).decode("latin-1"))
        assert semantic_differences(again, messy) == []
        assert format_eds(again, layout=True) == text


class TestLexicalDetails:
    def test_dollar_inside_quotes_is_text(self) -> None:
        doc = parse_eds('[File]\nDescText = "costs $5"; $ but this is a comment\n')
        entry = doc.entry("File", "DescText")
        assert entry.value() == "costs $5"
        assert entry.field(1).comment == "but this is a comment"

    def test_escapes_in_strings(self) -> None:
        # An unknown escape keeps its backslash: Windows paths appear in real files.
        doc = parse_eds('[A]\nK = "say \\"hi\\"", "C:\\drives\\acg", "\\x41\\n";\n')
        assert [item.value for item in doc.entry("A", "K").fields] == ['say "hi"', "C:\\drives\\acg", "A\n"]

    def test_empty_fields(self) -> None:
        doc = parse_eds("[A]\nK = ,,;\nL = ;\n")
        assert [item.kind for item in doc.entry("A", "K").fields] == [FieldKind.EMPTY] * 3
        assert [item.kind for item in doc.entry("A", "L").fields] == [FieldKind.EMPTY]

    def test_keywords_are_case_sensitive(self) -> None:
        doc = parse_eds("[Device]\nvendcode = 1;\n")
        assert doc.entry("Device", "VendCode") is None
        assert doc.entry("Device", "vendcode").value() == 1

    def test_revision_only_where_the_place_calls_for_it(self) -> None:
        doc = parse_eds("[File]\nRevision = 1.10;\n[X]\nRevision = 1.10;\n")
        assert doc.entry("File", "Revision").value() == (1, 10)
        assert doc.entry("X", "Revision").fields[0].kind is FieldKind.FLOAT

    def test_epath_only_where_the_place_calls_for_it(self) -> None:
        doc = parse_eds('[Assembly]\nAssem1 = "20 04", "20 04 24 [Param3]", 2, 0, , ;\n')
        assem = doc.entry("Assembly", "Assem1")
        assert assem.field(1).kind is FieldKind.STRING
        assert assem.field(2).value == (0x20, 0x04, 0x24, "Param3")

    def test_byte_order_mark_and_eof_mark(self) -> None:
        doc = parse_eds("\ufeff[File]\r\nDescText = \"x\";\r\n\x1a")
        assert doc.entry("File", "DescText").value() == "x"

    def test_vendor_keyword_kept(self) -> None:
        doc = parse_eds("[Device]\n1234_Secret = 0x12, Foo_Bar;\n[1234_Own Section]\nAnything = 1;\n")
        assert kinds_and_values(doc, "Device", "1234_Secret") == [("int", 0x12), ("keyword", "Foo_Bar")]
        assert doc.get("1234_Own Section").entries[0].keyword == "Anything"


SYNTAX_ERRORS = [
    ("unterminated string", '[File]\nDescText = "abc;\n', 2, "string not closed"),
    ("missing semicolon", '[File]\nDescText = "a"\nCreateDate = 01-01-2020;\n', 2, "';' missing"),
    ("entry before a section", 'DescText = "a";\n', 1, "before the first section"),
    ("keyword without =", '[File]\n$ c\nDescText "x";\n', 3, "not followed by '='"),
    ("unclosed section", "[File\nDescText = 1;\n", 1, "not closed"),
    ("empty section name", "[File]\nA = 1;\n[ ]\n", 3, "empty section name"),
    ("non-ASCII outside quotes", "[File]\nDescText = \xe9t\xe9;\n", 2, "unexpected character"),
    ("end of file inside an entry", '[File]\nDescText = "x",\n', 2, "not terminated by ';'"),
    ("entry starting with =", "[File]\n\n= 5;\n", 3, "expected a keyword"),
    ("separator in a field", "[File]\nA = 1, =;\n", 2, "where a field belongs"),
    ("unclosed dataset", "[X]\nA = {1, 2;\n", 2, "'}' missing"),
]


@pytest.mark.parametrize(
    ("text", "line", "words"), [case[1:] for case in SYNTAX_ERRORS], ids=[case[0] for case in SYNTAX_ERRORS]
)
def test_syntax_error_line_and_message(text: str, line: int, words: str) -> None:
    with pytest.raises(EdsSyntaxError) as caught:
        parse_eds(text)
    assert caught.value.line == line
    assert words in caught.value.message
    assert "\n" not in str(caught.value)
    assert str(caught.value).startswith(f"line {line}: ")


def test_read_eds_missing_file(tmp_path) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(OSError):
        read_eds(tmp_path / "absent.eds")


class TestBuildingInCode:
    def test_an_enumerated_member_is_written_as_its_number(self) -> None:
        """An ``EnumN`` value declared as an IntEnum member (the Drive State of the AC drive profile)
        is its number in the file on every Python: 3.10's ``str()`` of a member is its name, which
        made ``DriveState.READY, "Ready"`` an entry no reader takes."""
        field = Field.integer(DriveState.READY)
        assert (type(field.value), field.value, field.raw) == (int, 3, "3")
        assert Field.integer(GeneralStatus.PATH_SEGMENT_ERROR, hex_digits=2).raw == "0x04"

    def test_section_add_and_typed_fields(self) -> None:
        doc = EdsDocument()
        doc.section("File", comment="written by the project's generator tests").add("DescText", ["Drive"])
        doc.section("File").add("CreateDate", [datetime.date(2026, 2, 3)])
        doc.section("File").add("CreateTime", [datetime.time(4, 5, 6)])
        doc.section("File").add("Revision", [Field.revision(1, 0)])
        params = doc.section("Params")
        params.add(
            "Param1",
            [0, 6, Field.epath([0x20, 0x2A, 0x24, 0x01, 0x30, 0x08]), Field.integer(0, hex_digits=4),
             Field.integer(0xC7, hex_digits=2), 2, "Speed", "rpm", "", 0, 1800, 0, *[None] * 8, 0],
            comment="speed reference",
        )
        params.add("Enum1", [0, "Off", 1, "On"])
        doc.section("Device Classification").add("Class1", [Field.keyword("EtherNetIP")])
        doc.section("Extra").add("Ratio", [0.5, Field.dataset([1, "a"]), None])
        text = format_eds(doc)
        assert text.startswith("$ written by the project's generator tests\r\n[File]\r\n")
        assert '    CreateDate = 02-03-2026;\r\n    CreateTime = 04:05:06;\r\n    Revision = 1.0;\r\n' in text
        assert "    $ speed reference\r\n    Param1 =\r\n        0,\r\n        6, \"20 2A 24 01 30 08\",\r\n" in text
        assert "        0x0000,\r\n        0xC7, 2,\r\n" in text
        assert "    Enum1 =\r\n        0, \"Off\",\r\n        1, \"On\";\r\n" in text
        assert '    Ratio = 0.5, {1, "a"}, ;\r\n' in text
        back = parse_eds(text)
        assert semantically_equal(back, doc)
        assert format_eds(back) == text

    def test_section_returns_the_existing_one(self) -> None:
        doc = EdsDocument()
        assert doc.section("Params") is doc.section("Params")
        assert len(doc.sections) == 1

    @pytest.mark.parametrize(
        "build",
        [
            lambda: Field.epath("20 4"),
            lambda: Field.epath([256]),
            lambda: Field.keyword("12"),
            lambda: Field.keyword("two words"),
            lambda: Field.real(float("nan")),
            lambda: EdsDocument().section("Bad]Name"),
            lambda: EdsDocument().section("Ok").add("bad keyword", [1]),
        ],
    )
    def test_invalid_values_refused(self, build) -> None:  # type: ignore[no-untyped-def]
        with pytest.raises(ValueError):
            build()

    def test_writer_refuses_what_it_cannot_write(self) -> None:
        doc = EdsDocument()
        doc.sections.append(Section("Bad]Name"))
        with pytest.raises(ValueError, match="section name"):
            format_eds(doc)
        doc = EdsDocument()
        doc.section("Ok").entries.append(Entry("two words", [Field.integer(1)]))
        with pytest.raises(ValueError, match="keyword"):
            format_eds(doc)

    def test_semantic_equality_ignores_spelling_but_not_values(self) -> None:
        first = parse_eds("[A]\nK = 0x10, \"a\" \"b\"; $ c\n")
        second = parse_eds("$ other\n[A]\n  K =\n 16,\n \"ab\";\n")
        third = parse_eds("[A]\nK = 17, \"ab\";\n")
        fourth = parse_eds("[A]\nK = \"16\", \"ab\";\n")
        assert semantically_equal(first, second)
        assert not semantically_equal(first, third)
        assert not semantically_equal(first, fourth)
        assert not semantically_equal(first, parse_eds("[B]\nK = 16, \"ab\";\n"))
        assert not semantically_equal(first, parse_eds("[A]\nL = 16, \"ab\";\n"))


def test_an_unquoted_path_is_read_as_the_path_with_a_warning() -> None:
    """`Port1 = TCP, "A", 20 66 24 01, 2;` (a path without its quotes) made the whole file unreadable:
    it is the path it evidently is, and the checker names the line."""
    from cipstack.eds.checker import check_eds
    from cipstack.eds.model import FieldKind

    text = ('[File] DescText = "x"; CreateDate = 01-01-2025; CreateTime = 00:00:00; Revision = 1.0;\n'
            "[Port]\n"
            '  Port1 = TCP, "A", 20 66 24 01, 2;\n')
    doc = parse_eds(text)
    path = doc.get("Port").get("Port1").field(3)
    assert path.kind is FieldKind.EPATH and bytes(path.value) == bytes.fromhex("20662401")
    assert doc.get("Port").get("Port1").field(4).value == 2
    warnings = [(f.rule, f.line) for f in check_eds(doc) if f.severity == "warning"]
    assert ("unquoted-value", 3) in warnings
    # One hex-looking word alone is still the number it is, not a path.
    assert parse_eds(text.replace("20 66 24 01", "20")).reader_notes == []
