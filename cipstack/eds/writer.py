"""Writing an :class:`EdsDocument` as EDS text.

A document read from text is written back over that text: what was not edited comes back byte
for byte (layout, line breaks, comments, strings in pieces, Latin-1 characters); an edited value
changes only where that value stands; an edited entry's comments or field count lay out that
entry alone; added entries and sections are laid out and put where they belong.

A document built in code, or any document with ``layout=True``, is laid out afresh: CRLF,
deterministic, short entries on one line, entries with many fields (ParamN, EnumN, AssemN,
ConnectionN) over several lines, grouped the way readers of EDS files expect to find them (a
parameter's limits on one line, an assembly's members one per line), so a diff of two files shows
which field changed; a long string is split into quoted pieces, one a line. Reading back what
was written gives the same text.

EDS files are Latin-1: :func:`encode_eds` gives the bytes, and characters outside Latin-1 (which
no EDS reader could decode) are written as "?". Latin-1 letters are written as themselves, not as
escapes: other readers take a backslash escape literally.
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable, Sequence

from ..errors import BadRequest
from .model import (
    SECTION_NAME,
    DocumentSource,
    EdsDocument,
    Entry,
    EntrySource,
    Field,
    FieldKind,
    Section,
    SectionSource,
    escape_string,
    is_bare_word,
    render_field,
    written_comment,
)

NEWLINE = "\r\n"
ENTRY_INDENT = "    "
FIELD_INDENT = "        "
#: The longest quoted piece of a string (escaped text): a longer string is written in pieces.
PIECE_WIDTH = 72


#: Field groups, as (first field, last field) numbered from 1; later fields one group each.
_PARAM_GROUPS = ((1, 1), (2, 3), (4, 4), (5, 6), (7, 7), (8, 8), (9, 9), (10, 12), (13, 16), (17, 20), (21, 21))
_CONNECTION_GROUPS = ((1, 1), (2, 2), (3, 5), (6, 8), (9, 10), (11, 12), (13, 13), (14, 14), (15, 15))
_ASSEMBLY_HEAD = ((1, 1), (2, 2), (3, 3), (4, 4), (5, 6))


def _fixed_groups(spans: Sequence[tuple[int, int]]) -> Callable[[int], list[list[int]]]:
    def layout(count: int) -> list[list[int]]:
        groups = [list(range(first - 1, min(last, count))) for first, last in spans if first <= count]
        covered = spans[-1][1]
        groups.extend([index] for index in range(covered, count))
        return groups

    return layout


def _pairs_after(spans: Sequence[tuple[int, int]]) -> Callable[[int], list[list[int]]]:
    """A head of fixed groups, then the remaining fields two per line (size and member,
    value and name)."""

    def layout(count: int) -> list[list[int]]:
        groups = [list(range(first - 1, min(last, count))) for first, last in spans if first <= count]
        start = spans[-1][1] if spans else 0
        groups.extend(list(range(index, min(index + 2, count))) for index in range(start, count, 2))
        return groups

    return layout


_MULTI_LINE: tuple[tuple[re.Pattern[str], Callable[[int], list[list[int]]]], ...] = (
    (re.compile(r"(?:Proxy)?Param[0-9]+"), _fixed_groups(_PARAM_GROUPS)),
    (re.compile(r"(?:Proxy|Proxied)?Assem(?:Exa)?[0-9]+"), _pairs_after(_ASSEMBLY_HEAD)),
    (re.compile(r"Connection[0-9]+"), _fixed_groups(_CONNECTION_GROUPS)),
    (re.compile(r"Enum[0-9]+"), _pairs_after(())),
)


def _field_groups(entry: Entry) -> list[list[int]]:
    """Indexes of the fields on each line; a single group means a one-line entry."""
    count = len(entry.fields)
    groups = [list(range(count))]
    for pattern, layout in _MULTI_LINE:
        if pattern.fullmatch(entry.keyword):
            groups = layout(count)
            break
    # A field's comment ends its line, so the line breaks after every commented field.
    split: list[list[int]] = []
    for group in groups:
        current: list[int] = []
        for index in group:
            current.append(index)
            if entry.fields[index].comment is not None:
                split.append(current)
                current = []
        if current:
            split.append(current)
    return split


def _comment_line(indent: str, text: str) -> str:
    text = written_comment(text)
    return f"{indent}$ {text}" if text else f"{indent}$"


def _string_pieces(value: str) -> list[str]:
    """A string's quoted pieces, each at most PIECE_WIDTH characters of escaped text; an escape
    is never cut in two, since each piece is escaped on its own."""
    pieces: list[str] = []
    current = ""
    for char in value:
        escaped = escape_string(char)
        if current and len(current) + len(escaped) > PIECE_WIDTH:
            pieces.append(current)
            current = ""
        current += escaped
    pieces.append(current)
    return [f'"{piece}"' for piece in pieces]


def _render(item: Field, continuation: str) -> str:
    """A field's text; a long string in pieces, ``continuation`` (a line break and indent) apart."""
    text = render_field(item)
    if item.kind is FieldKind.STRING and len(text) > PIECE_WIDTH + 2:
        return continuation.join(_string_pieces(item.value))
    return text


def _group_text(entry: Entry, group: list[int], continuation: str) -> str:
    last = len(entry.fields) - 1
    parts = []
    for index in group:
        separator = ";" if index == last else ","
        parts.append(_render(entry.fields[index], continuation) + separator)
    text = " ".join(parts)
    comment = entry.fields[group[-1]].comment
    if comment is not None:
        text += "  " + _comment_line("", comment)
    return text


def format_entry(entry: Entry, indent: str = ENTRY_INDENT, field_indent: str = FIELD_INDENT,
                 newline: str = NEWLINE) -> list[str]:
    """The lines of one entry, its comments first (a string in pieces holds ``newline``)."""
    lines = [_comment_line(indent, comment) for comment in entry.comments]
    if not entry.fields:
        raise BadRequest(f"entry {entry.keyword!r} has no field")
    if not is_bare_word(entry.keyword):
        raise BadRequest(f"keyword {entry.keyword!r} cannot be written")
    groups = _field_groups(entry)
    continuation = newline + field_indent
    if len(groups) == 1:
        lines.append(f"{indent}{entry.keyword} = {_group_text(entry, groups[0], continuation)}")
    else:
        lines.append(f"{indent}{entry.keyword} =")
        lines.extend(field_indent + _group_text(entry, group, continuation) for group in groups)
    return lines


def _section_header(section: Section) -> list[str]:
    if not SECTION_NAME.fullmatch(section.name):
        raise BadRequest(f"section name {section.name!r} cannot be written")
    return [*(_comment_line("", comment) for comment in section.comments), f"[{section.name}]"]


def format_section(section: Section) -> list[str]:
    lines = _section_header(section)
    for entry in section.entries:
        lines.extend(format_entry(entry))
    return lines


def format_eds(doc: EdsDocument, layout: bool = False) -> str:
    """The document as EDS text: over the text it was read from, unless ``layout`` or it was
    built in code, in which case laid out afresh (CRLF, a blank line between sections)."""
    if doc.source is not None and not layout:
        return _over_source(doc, doc.source)
    blocks = [NEWLINE.join(format_section(section)) for section in doc.sections]
    if doc.trailing_comments:
        blocks.append(NEWLINE.join(_comment_line("", comment) for comment in doc.trailing_comments))
    return (NEWLINE + NEWLINE).join(blocks) + NEWLINE


def encode_eds(text: str) -> bytes:
    """EDS text as the bytes of a file: Latin-1, the encoding EDS readers decode."""
    return text.encode("latin-1", errors="replace")


def write_eds(doc: EdsDocument, path: str | os.PathLike[str], layout: bool = False) -> None:
    """Write the document to a file (see :func:`format_eds`)."""
    with open(path, "wb") as stream:
        stream.write(encode_eds(format_eds(doc, layout)))


# -- writing over the text a document was read from ---------------------------------------------

_BLANK_LINES = re.compile(r"(?:[ \t\f\v]*(?:\r\n|\n|\r))*")
_INDENT = re.compile(r"[ \t]*")


def _leading_blank_lines(chunk: str) -> str:
    match = _BLANK_LINES.match(chunk)
    return match.group(0) if match else ""


def _line_break_at_end(chunk: str, newline: str) -> str:
    return newline if chunk.endswith(("\n", "\r")) else ""


def _indent_before(text: str, index: int) -> str:
    """The blanks that start the line holding ``index``, when only blanks precede it there."""
    line_start = max(text.rfind("\n", 0, index), text.rfind("\r", 0, index)) + 1
    before = text[line_start:index]
    return before if _INDENT.fullmatch(before) else ""


class _SourceWriter:
    def __init__(self, doc: EdsDocument, source: DocumentSource) -> None:
        self.doc = doc
        self.text = source.text
        self.source = source
        self.newline = source.newline
        self.out: list[str] = []

    def _new_lines(self, lines: list[str], blank_before: bool = False) -> None:
        """Append lines that have no text to keep, each ending with the file's line break."""
        written = "".join(self.out)
        if written and not written.endswith(("\n", "\r")):
            self.out.append(self.newline)
        if blank_before and written:
            self.out.append(self.newline)
        self.out.append("".join(line + self.newline for line in lines))

    def write(self) -> str:
        indent = ENTRY_INDENT
        for section in self.doc.sections:
            if section.source is None or section.source.text is not self.text:
                self._new_lines(_section_header(section), blank_before=True)
            else:
                self.out.append(self._section_chunk(section, section.source))
            for entry in section.entries:
                if entry.source is None or entry.source.text is not self.text:
                    self._new_lines(format_entry(entry, indent, _field_indent(indent), self.newline))
                else:
                    indent = _indent_before(self.text, entry.source.keyword_start) or ENTRY_INDENT
                    self.out.append(self._entry_chunk(entry, entry.source, indent))
        if list(self.doc.trailing_comments) == list(self.source.trailing_comments):
            self.out.append(self.text[self.source.epilogue_start :])
        elif self.doc.trailing_comments:
            self._new_lines([_comment_line("", comment) for comment in self.doc.trailing_comments])
        return "".join(self.out)

    def _section_chunk(self, section: Section, source: SectionSource) -> str:
        chunk = self.text[source.start : source.end]
        if list(section.comments) != list(source.comments):
            return (_leading_blank_lines(chunk) + self.newline.join(_section_header(section))
                    + _line_break_at_end(chunk, self.newline))
        if section.name != source.name:
            _section_header(section)  # refuses a name that cannot be written
            return (self.text[source.start : source.name_start] + f"[{section.name}]"
                    + self.text[source.name_end : source.end])
        return chunk

    def _entry_chunk(self, entry: Entry, source: EntrySource, indent: str) -> str:
        chunk = self.text[source.start : source.end]
        if _relaid(entry, source):
            lines = format_entry(entry, indent, _field_indent(indent), self.newline)
            return _leading_blank_lines(chunk) + self.newline.join(lines) + _line_break_at_end(chunk, self.newline)
        edits: list[tuple[int, int, str]] = []
        if entry.keyword != source.keyword:
            format_entry(Entry(entry.keyword, [Field.empty()]))  # refuses a keyword that cannot be written
            edits.append((source.keyword_start, source.keyword_start + len(source.keyword), entry.keyword))
        for item, read in zip(entry.fields, source.fields, strict=True):
            place = read.source
            assert place is not None
            if place.edited(item):
                continuation = self.newline + (_indent_before(self.text, place.start) or _field_indent(indent))
                edits.append((place.start, place.end, _render(item, continuation)))
        for start, end, replacement in sorted(edits, reverse=True):
            offset = source.start
            chunk = chunk[: start - offset] + replacement + chunk[end - offset :]
        return chunk


def _field_indent(indent: str) -> str:
    return indent + ("\t" if indent.startswith("\t") else "    ")


def _relaid(entry: Entry, source: EntrySource) -> bool:
    """Whether an entry read from text is laid out afresh: its field count or its comments changed
    (a comment's place in the text has no field to patch)."""
    if len(entry.fields) != len(source.fields) or list(entry.comments) != list(source.comments):
        return True
    for item, read in zip(entry.fields, source.fields, strict=True):
        place = read.source
        if place is None or item.comment != place.comment:
            return True
    return False


def _over_source(doc: EdsDocument, source: DocumentSource) -> str:
    return _SourceWriter(doc, source).write()
