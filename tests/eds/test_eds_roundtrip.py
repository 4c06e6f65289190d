"""Round trips between text and model, as properties.

* What ``format_eds`` writes reads back to the same document and is written again byte for
  byte the same.
* Any EDS text, however laid out (CRLF or LF, comments anywhere, entries over many lines,
  strings in pieces, hex or decimal, Latin-1), reads to the document it spells, and writing
  that document and reading it again keeps its meaning.
"""

from __future__ import annotations

import datetime
import string

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cipstack.eds.model import EdsDocument, Entry, Field, FieldKind, Section, escape_string, semantic_differences
from cipstack.eds.reader import parse_eds
from cipstack.eds.writer import encode_eds, format_eds

from .samples import ADAPTER_EDS, MESSY_EDS

# Sections whose fields change kind with their place (EPATH, revision) are built separately.
PLACE_DEPENDENT_SECTIONS = {"File", "Params", "Assembly", "Connection Manager", "Port"}

section_names = (
    st.text(alphabet=string.ascii_letters + string.digits + " /_-.", min_size=1, max_size=24)
    .map(str.strip)
    .filter(lambda name: name != "" and name not in PLACE_DEPENDENT_SECTIONS)
)
# The words below are built from their parts, each the language of a regular expression (in the
# comment): st.from_regex drew them several times slower than the code under test reads them.
LETTERS = string.ascii_letters
NAME_CHARACTERS = string.ascii_letters + string.digits + "_"
keywords = st.one_of(
    # [A-Za-z][A-Za-z0-9_]{0,12}
    st.builds(str.__add__, st.sampled_from(LETTERS), st.text(alphabet=NAME_CHARACTERS, max_size=12)),
    # (Param|Assem|Connection|Enum)[1-9][0-9]{0,2}
    st.builds("{}{}".format, st.sampled_from(["Param", "Assem", "Connection", "Enum"]), st.integers(1, 999)),
    # [1-9][0-9]{0,3}_[A-Za-z0-9_]{1,8}
    st.builds("{}_{}".format, st.integers(1, 9999), st.text(alphabet=NAME_CHARACTERS, min_size=1, max_size=8)),
)
comments = st.text(
    alphabet=st.characters(min_codepoint=0x20, max_codepoint=0xFF, exclude_characters="\x7f"), max_size=30
)
latin1_text = st.text(alphabet=st.characters(max_codepoint=0xFF, exclude_categories=("Cs",)), max_size=40)
# [A-Za-z_][A-Za-z0-9_./-]{0,10}
bare_keyword_values = st.builds(str.__add__, st.sampled_from(LETTERS + "_"),
                                st.text(alphabet=NAME_CHARACTERS + "./-", max_size=10))


def _integer_field(value: int, hex_digits: int | None) -> Field:
    return Field.integer(value, hex_digits=hex_digits)


scalar_fields = st.one_of(
    st.builds(
        _integer_field,
        st.integers(min_value=-(2**40), max_value=2**40),
        st.one_of(st.none(), st.integers(min_value=1, max_value=8)),
    ),
    st.floats(allow_nan=False, allow_infinity=False).map(Field.real),
    latin1_text.map(Field.string),
    bare_keyword_values.map(Field.keyword),
    st.just(Field.empty()),
    st.dates().map(Field.date),
    st.times().map(Field.time),
)
fields = st.one_of(scalar_fields, st.lists(scalar_fields, max_size=4).map(Field.dataset))
# The strategies the composites below draw from, built once: a strategy built inside a composite is
# built and validated again at every draw, which cost more than the drawing and the code under test.
maybe_comments = st.one_of(st.none(), comments)
comment_lists = st.lists(comments, max_size=2)


@st.composite
def commented_field(draw: st.DrawFn) -> Field:
    item = draw(fields)
    comment = draw(maybe_comments)
    # Build a fresh field: strategies may hand out the same Field object twice.
    return Field(item.kind, item.value, item.raw, comment=None if comment is None else comment.strip() or None)


section_name_lists = st.lists(section_names, min_size=1, max_size=5, unique=True)
keyword_lists = st.lists(keywords, max_size=6)
entry_fields = st.lists(commented_field(), min_size=1, max_size=26)


@st.composite
def documents(draw: st.DrawFn) -> EdsDocument:
    doc = EdsDocument()
    for name in draw(section_name_lists):
        section = doc.section(name, comment=draw(comment_lists))
        for keyword in draw(keyword_lists):
            entry = section.add(keyword, draw(entry_fields))
            entry.comments = [c.strip() for c in draw(comment_lists)]
    doc.trailing_comments = [c.strip() for c in draw(comment_lists)]
    return doc


epath_items = st.lists(
    st.one_of(st.integers(min_value=0, max_value=255), st.builds("Param{}".format, st.integers(1, 999))),
    max_size=8,
)


@st.composite
def place_dependent_documents(draw: st.DrawFn) -> EdsDocument:
    """[File] Revision, and the EPATH fields of parameters, assemblies, connections, ports."""
    doc = EdsDocument()
    doc.section("File").add(
        "Revision", [Field.revision(draw(st.integers(0, 255)), draw(st.integers(0, 255)))]
    )
    params = doc.section("Params")
    for number in draw(st.lists(st.integers(1, 999), max_size=3, unique=True)):
        path = Field.epath(draw(epath_items))
        params.add(f"Param{number}", [0, len(path.value), path, *draw(st.lists(fields, min_size=18, max_size=21))])
    assembly = doc.section("Assembly")
    for number in draw(st.lists(st.integers(1, 999), max_size=3, unique=True)):
        assembly.add(f"Assem{number}", ["name", Field.epath(draw(epath_items)), 4, 0, None, None, 32, "Param1"])
    manager = doc.section("Connection Manager")
    manager.add("Connection1", [*draw(st.lists(fields, min_size=14, max_size=14)), Field.epath(draw(epath_items))])
    doc.section("Port").add("Port1", [Field.keyword("TCP"), "port", Field.epath(draw(epath_items)), 2])
    return doc


def assert_same_meaning(first: EdsDocument, second: EdsDocument) -> None:
    assert semantic_differences(first, second) == []


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(documents())
def test_written_text_reads_back_and_writes_identically(doc: EdsDocument) -> None:
    text = format_eds(doc)
    # Latin-1 throughout, the encoding EDS readers decode; nothing is lost to "?" on the way.
    assert encode_eds(text).decode("latin-1") == text
    assert text.endswith("\r\n") and "\n" not in text.replace("\r\n", "")
    back = parse_eds(text)
    assert_same_meaning(back, doc)
    assert format_eds(back) == text
    assert format_eds(back, layout=True) == text


@settings(max_examples=60, deadline=None)
@given(place_dependent_documents())
def test_place_dependent_kinds_survive(doc: EdsDocument) -> None:
    text = format_eds(doc)
    back = parse_eds(text)
    assert_same_meaning(back, doc)
    assert back.entry("File", "Revision").fields[0].kind is FieldKind.REVISION
    assert back.entry("Port", "Port1").fields[2].kind is FieldKind.EPATH
    assert format_eds(back) == text


# -- any layout -------------------------------------------------------------------------------


blanks = st.sampled_from(["", " ", "\t", "  "])
line_breaks = st.sampled_from(["", "\n", " \n  "])
hex_prefixes = st.sampled_from(["0x", "0X"])
header_blanks = st.sampled_from(["", " "])
newlines = st.sampled_from(["\n", "\r\n"])


@st.composite
def spelled_as_anyone_might(draw: st.DrawFn, doc: EdsDocument) -> str:
    """``doc`` written with free layout: the text a different tool might produce."""
    out: list[str] = []

    def gap() -> str:
        """Blanks, maybe a comment, maybe new lines, between two tokens."""
        text = draw(blanks)
        if draw(st.booleans()):
            text += "$" + draw(comments).replace("$", "") + "\n"
        text += draw(line_breaks)
        return text

    def spell(item: Field) -> str:
        if item.kind is FieldKind.STRING:
            value = item.value
            cut = draw(st.integers(0, len(value)))
            pieces = [value[:cut], value[cut:]] if draw(st.booleans()) else [value]
            # Latin-1 letters stay as they are; quotes, backslashes and controls are escaped.
            quoted = [
                '"' + "".join(c if 0xA0 <= ord(c) <= 0xFF else escape_string(c) for c in piece) + '"'
                for piece in pieces
            ]
            return gap().join(quoted)
        if item.kind is FieldKind.INT and draw(st.booleans()):
            value = item.value
            return ("-" if value < 0 else "") + draw(hex_prefixes) + format(abs(value), "x")
        if item.kind is FieldKind.DATASET:
            return "{" + ",".join(gap() + spell(child) + gap() for child in item.value) + "}"
        return str(item)

    for section in doc.sections:
        out.append(gap() + f"[{draw(header_blanks)}{section.name}]" + gap() + "\n")
        for entry in section.entries:
            pieces = [spell(item) for item in entry.fields]
            separators = "".join(gap() + piece + gap() + "," for piece in pieces)[:-1]
            out.append(f"{gap()}{entry.keyword}{gap()}={separators};{gap()}\n")
    text = "".join(out)
    newline = draw(newlines)
    return text.replace("\n", newline)


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.data())
def test_any_layout_reads_to_the_same_document(data: st.DataObject) -> None:
    doc = data.draw(documents())
    text = data.draw(spelled_as_anyone_might(doc))
    read = parse_eds(text)
    assert_same_meaning(read, doc)
    # Written back over its text, a file read and not edited is the same text, byte for byte.
    assert format_eds(read) == text
    rewritten = parse_eds(format_eds(read, layout=True))
    assert_same_meaning(rewritten, read)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.data())
def test_editing_one_value_changes_that_value_alone(data: st.DataObject) -> None:
    text = data.draw(spelled_as_anyone_might(data.draw(documents())))
    read = parse_eds(text)
    entries = [entry for section in read.sections for entry in section.entries]
    if not entries:
        return
    entry = data.draw(st.sampled_from(entries))
    number = data.draw(st.integers(0, len(entry.fields) - 1))
    place = entry.fields[number].source
    assert place is not None
    drawn = data.draw(scalar_fields.filter(lambda f: f.semantic_value() != place.value))
    # A new value, the field's comment kept (a changed comment lays the entry out afresh).
    new = Field(drawn.kind, drawn.value, drawn.raw, comment=place.comment)
    entry.fields[number] = new
    assert format_eds(read) == text[: place.start] + str(new) + text[place.end :]


def test_samples_round_trip() -> None:
    for text in (ADAPTER_EDS, MESSY_EDS.decode("latin-1")):
        doc = parse_eds(text)
        assert format_eds(doc) == text
        written = format_eds(doc, layout=True)
        assert_same_meaning(parse_eds(written), doc)
        assert format_eds(parse_eds(written), layout=True) == written


def test_output_is_deterministic() -> None:
    assert format_eds(parse_eds(ADAPTER_EDS), layout=True) == format_eds(parse_eds(ADAPTER_EDS), layout=True)


def test_layout_of_the_adapter_sample() -> None:
    written = format_eds(parse_eds(ADAPTER_EDS), layout=True)
    assert (
        "    Assem21 =\r\n"
        '        "Extended Speed Control Output",\r\n'
        '        "20 04 24 15 30 03",\r\n'
        "        4,\r\n"
        "        0x0000,\r\n"
        "        , ,\r\n"
        "        16, Param1,\r\n"
        "        16, Param2;\r\n"
    ) in written
    assert (
        "    Connection1 =\r\n"
        "        0x04010002,\r\n"
        "        0x44640405,\r\n"
        "        Param9, 4, Assem21,\r\n"
        "        Param9, 4, Assem71,\r\n"
        "        , ,\r\n"
        "        , ,\r\n"
        '        "Exclusive Owner",\r\n'
        '        "",\r\n'
        '        "20 04 24 01 2C 15 2C 47";\r\n'
    ) in written
    assert '    Port1 = TCP, "EtherNet/IP Port", "20 F5 24 01", 2;\r\n' in written
    assert "\r\n\r\n[Device]\r\n" in written


def test_dates_and_times_keep_their_values() -> None:
    doc = EdsDocument()
    doc.section("X").add("When", [datetime.date(1999, 12, 31), datetime.time(23, 59, 58)])
    back = parse_eds(format_eds(doc))
    assert back.entry("X", "When").value(1) == (12, 31, 1999)
    assert back.entry("X", "When").value(2) == (23, 59, 58)


def test_entry_with_comment_on_a_middle_field_breaks_the_line() -> None:
    doc = EdsDocument()
    section = doc.section("X")
    entry: Entry = section.add("K", [1, 2, 3])
    entry.fields[1].comment = "second"
    assert format_eds(doc) == "[X]\r\n    K =\r\n        1, 2,  $ second\r\n        3;\r\n"
    assert isinstance(doc.sections[0], Section)
