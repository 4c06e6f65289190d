"""Writing a file that was read keeps what was not edited (issue 11, item 6).

Reading and writing an unedited file gives the same bytes: strings in quoted pieces, Latin-1
letters in values and comments, tabs, LF or CRLF, comments between fields, a path written
without quotes. Editing one value changes only that value's line; an added entry or section is
laid out where it belongs, and nothing else moves.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from cipstack.eds.model import EdsDocument, Field
from cipstack.eds.reader import parse_eds, read_eds
from cipstack.eds.writer import PIECE_WIDTH, encode_eds, format_eds, write_eds

from .samples import ADAPTER_EDS, MESSY_EDS

FILES = Path(__file__).parent / "files"
PUMP = FILES / "hand_written_oil_pump.eds"


def written(doc: EdsDocument) -> bytes:
    return encode_eds(format_eds(doc))


def changed_lines(before: bytes, after: bytes) -> list[tuple[bytes, bytes]]:
    """The lines that differ, as (before, after), for two texts with the same number of lines."""
    old, new = before.splitlines(keepends=True), after.splitlines(keepends=True)
    assert len(old) == len(new), "lines were added or removed"
    return [(a, b) for a, b in zip(old, new, strict=True) if a != b]


@pytest.mark.parametrize("path", sorted(FILES.glob("*.eds")), ids=lambda p: p.name)
def test_every_corpus_file_is_written_back_byte_for_byte(path: Path) -> None:
    assert written(read_eds(path)) == path.read_bytes()


def test_samples_are_written_back_byte_for_byte() -> None:
    assert written(parse_eds(MESSY_EDS.decode("latin-1"))) == MESSY_EDS
    assert format_eds(parse_eds(ADAPTER_EDS)) == ADAPTER_EDS
    with_mark = "\xef\xbb\xbf" + ADAPTER_EDS.replace("\n", "\r")  # a byte-order mark, CR line ends
    assert format_eds(parse_eds(with_mark)) == with_mark


def test_the_pump_file_holds_what_a_writer_used_to_lose() -> None:
    data = PUMP.read_bytes()
    assert data.count(b'\t\t"') >= 60  # the icon in 60 quoted pieces, one a line
    assert "Überwachung".encode("latin-1") in data  # a Latin-1 comment
    assert b"\r" not in data and b"\t" in data
    doc = read_eds(PUMP)
    assert doc.entry("Device", "ProdName").value() == "Ölpumpe P-40"
    assert len(doc.entry("Device", "IconContents").value()) == 60 * 64


def test_editing_a_latin1_string_changes_its_line_only() -> None:
    doc = read_eds(PUMP)
    doc.entry("Device", "ProdName").fields[0] = Field.string("Ölpumpe P-50")
    assert changed_lines(PUMP.read_bytes(), written(doc)) == [
        ('\tProdName = "Ölpumpe P-40";\n'.encode("latin-1"), '\tProdName = "Ölpumpe P-50";\n'.encode("latin-1")),
    ]


def test_editing_a_hex_number_keeps_hex_its_digits_and_its_comment() -> None:
    doc = read_eds(PUMP)
    doc.entry("Params", "Param1").fields[11].value = 0x78  # the default
    assert changed_lines(PUMP.read_bytes(), written(doc)) == [
        (b"\t\t0, 0x0190, 0x0064,\t$ 0 ... 40,0 bar\n", b"\t\t0, 0x0190, 0x0078,\t$ 0 ... 40,0 bar\n"),
    ]


def test_editing_one_field_of_a_line_with_many_leaves_the_others_as_written() -> None:
    doc = read_eds(PUMP)
    param2 = doc.entry("Params", "Param2")
    param2.fields[10] = Field.integer(1000)  # the maximum
    param2.fields[4] = Field.integer(0xC8, hex_digits=2)  # the data type: UDINT
    assert changed_lines(PUMP.read_bytes(), written(doc)) == [
        (b'\t\t0, 6, "20 64 24 01 30 02", 0x0010, 0xC7, 2,\n', b'\t\t0, 6, "20 64 24 01 30 02", 0x0010, 0xC8, 2,\n'),
        (b"\t\t0, 65535, 0,\n", b"\t\t0, 1000, 0,\n"),
    ]


def test_an_empty_field_given_a_value_and_a_value_emptied() -> None:
    doc = read_eds(PUMP)
    param1 = doc.entry("Params", "Param1")
    param1.fields[16] = Field.integer(3)  # the first scaling link, empty in the file
    param1.fields[13] = Field.empty()  # the divider
    assert changed_lines(PUMP.read_bytes(), written(doc)) == [
        (b"\t\t1, 10, 1, 0,\n", b"\t\t1, , 1, 0,\n"),
        (b"\t\t,,,,\n", b"\t\t3,,,,\n"),
    ]
    assert parse_eds(format_eds(doc)).entry("Params", "Param1").value(17) == 3


def test_a_long_string_edited_is_written_in_pieces_in_place() -> None:
    doc = read_eds(PUMP)
    icon = "0123456789ABCDEF" * 300
    doc.entry("Device", "IconContents").fields[0] = Field.string(icon)
    before, after = PUMP.read_bytes(), written(doc)
    head, tail = before.split(b"\tIconContents =\n")[0], before.split(b"\n\n[Device Classification]")[1]
    assert after.startswith(head + b"\tIconContents =\n") and after.endswith(b"\n\n[Device Classification]" + tail)
    pieces = after[len(head) :].split(b"\n\n[Device Classification]")[0].splitlines()[1:]
    assert len(pieces) == len(icon) // PIECE_WIDTH + 1
    assert all(line.startswith(b'\t\t"') and len(line) <= PIECE_WIDTH + 4 for line in pieces)
    assert parse_eds(format_eds(doc)).entry("Device", "IconContents").value() == icon


def test_a_piece_never_cuts_an_escape() -> None:
    doc = EdsDocument()
    value = 'a"\\' * 200
    doc.section("X").add("Long", [value])
    text = format_eds(doc)
    assert all(len(line) <= PIECE_WIDTH + 16 for line in text.splitlines())
    assert parse_eds(text).entry("X", "Long").value() == value


def test_an_added_entry_takes_its_neighbours_indent_and_nothing_else_moves() -> None:
    doc = read_eds(PUMP)
    doc.get("Device").add("Catalog", ["P-40-E"])
    before, after = PUMP.read_bytes(), written(doc)
    following = b"\n\n[Device Classification]"
    assert after == before.replace(following, b'\n\tCatalog = "P-40-E";' + following)


def test_a_removed_entry_takes_its_comments_and_only_them() -> None:
    doc = read_eds(PUMP)
    params = doc.get("Params")
    params.entries.remove(params.get("Param1"))
    before, after = PUMP.read_bytes(), written(doc)
    start = before.index("\t$ Förderdruck".encode("latin-1"))
    end = before.index(b"\tParam2 =")
    assert after == before[:start] + before[end:]


def test_an_added_section_goes_before_the_closing_comment() -> None:
    doc = read_eds(PUMP)
    doc.section("Capacity").add("MaxMsgConnections", [4])
    before, after = PUMP.read_bytes(), written(doc)
    closing = "\n$ Ende der Datei\n".encode("latin-1")
    # Laid out like its neighbours (a tab), after a blank line, ahead of the file's closing comment.
    assert after == before.replace(closing, b"\n[Capacity]\n\tMaxMsgConnections = 4;\n" + closing)


def test_an_edited_comment_lays_out_that_entry_alone() -> None:
    doc = read_eds(PUMP)
    doc.entry("Params", "Param1").fields[0].comment = "reserved"
    before, after = PUMP.read_bytes(), written(doc)
    start, end = before.index("\t$ Förderdruck".encode("latin-1")), before.index(b"\tParam2 =")
    assert after[:start] == before[:start]
    assert after.endswith(before[end:])
    entry_text = after[start : len(after) - len(before) + end]
    assert entry_text.startswith("\t$ Förderdruck, Sollwert\n\tParam1 =\n\t\t0,  $ reserved\n".encode("latin-1"))
    again = parse_eds(format_eds(doc)).entry("Params", "Param1")
    edited = doc.entry("Params", "Param1")
    assert [f.semantic_value() for f in again.fields] == [f.semantic_value() for f in edited.fields]


def test_an_edited_unquoted_path_is_written_quoted() -> None:
    doc = read_eds(PUMP)
    doc.entry("Port", "Port1").fields[2] = Field.epath("20 F5 24 02")
    assert changed_lines(PUMP.read_bytes(), written(doc)) == [
        (b'\tPort1 = TCP, "Ethernet", 20 F5 24 01, 2;\n', b'\tPort1 = TCP, "Ethernet", "20 F5 24 02", 2;\n'),
    ]


def test_a_character_beyond_latin1_is_written_as_a_question_mark() -> None:
    doc = read_eds(PUMP)
    doc.entry("Device", "VendName").fields[0] = Field.string("Hydraulik Müller \u2013 Pumpen")
    assert b'\tVendName = "Hydraulik M\xfcller ? Pumpen";\n' in written(doc)


def test_write_eds_writes_the_file_bytes(tmp_path: Path) -> None:
    doc = read_eds(PUMP)
    doc.entry("Device", "MinRev").fields[0].value = 4
    write_eds(doc, tmp_path / "out.eds")
    assert changed_lines(PUMP.read_bytes(), (tmp_path / "out.eds").read_bytes()) == [
        (b"\tMajRev = 1;  MinRev = 3;\n", b"\tMajRev = 1;  MinRev = 4;\n"),
    ]
    write_eds(doc, tmp_path / "laid-out.eds", layout=True)
    assert b"\r\n    MinRev = 4;\r\n" in (tmp_path / "laid-out.eds").read_bytes()


def test_an_entry_moved_from_another_file_is_laid_out_not_cut_from_this_one() -> None:
    doc, other = read_eds(PUMP), parse_eds(ADAPTER_EDS)
    doc.get("Device").entries.append(other.entry("Device", "Catalog"))
    doc.sections.append(other.get("Device Classification"))
    after = written(doc)
    assert after.startswith(PUMP.read_bytes().split(b"\n\n[Device Classification]")[0] + b'\n\tCatalog = "ACG-ET2";\n')
    assert after.endswith(b"\n[Device Classification]\n\tClass1 = EtherNetIP;\n\n$ Ende der Datei\n")
