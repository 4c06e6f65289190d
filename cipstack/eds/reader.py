"""Reading EDS text into an :class:`EdsDocument`.

Real EDS files come from many tools: Latin-1 text, CRLF or LF, comments between the fields
of an entry, entries over many lines and long strings split into adjacent quoted pieces.
All of that is accepted; what is not EDS syntax raises :class:`EdsSyntaxError` with the
line it was found on.

Comments: one on a line of its own belongs to what follows it (the next section or entry;
inside an entry, to that entry); one after other text on the same line belongs to the field
(or the entry or section header) that text ends.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterator
from dataclasses import dataclass

from ..errors import BadRequest
from .model import (
    WORD_CHARACTERS,
    DocumentSource,
    EdsDocument,
    Entry,
    EntrySource,
    Field,
    FieldKind,
    FieldSource,
    Section,
    SectionSource,
    parse_epath,
    parse_word,
    unescape_string,
)

#: One byte of a path as hex: two hex digits.
_HEX_BYTE = re.compile(r"[0-9A-Fa-f]{2}")


class EdsSyntaxError(BadRequest):
    """Text that is not EDS syntax, and the line where that shows."""

    def __init__(self, line: int, message: str) -> None:
        super().__init__(f"line {line}: {message}")
        self.line = line
        self.message = message


#: Fields that hold an EPATH when they hold a quoted string: (section, keyword pattern, field number).
#: Keywords in any case: configuration tools read ``assem100`` as ``Assem100`` (the checker warns).
EPATH_FIELDS: tuple[tuple[str, re.Pattern[str], int], ...] = (
    ("Params", re.compile(r"(?:Proxy)?Param[0-9]+", re.IGNORECASE), 3),
    ("Assembly", re.compile(r"(?:Proxy|Proxied)?Assem(?:Exa)?[0-9]+", re.IGNORECASE), 2),
    ("Connection Manager", re.compile(r"Connection[0-9]+", re.IGNORECASE), 15),
    ("Port", re.compile(r"Port[0-9]+", re.IGNORECASE), 3),
)
#: Fields written as ``major.minor``, which elsewhere would read as a real number.
REVISION_FIELDS: tuple[tuple[str, str, int], ...] = (("File", "Revision", 1),)

_PUNCTUATION = "=,;{}"
# A DOS end-of-file mark still ends some files written by old tools.
_END_OF_FILE_MARK = "\x1a"


@dataclass(slots=True)
class _Token:
    kind: str  # "section", "word", "string", "comment", or the punctuation character itself
    text: str
    line: int
    #: Where the token stands in the text: ``text[start:end]`` is its spelling.
    start: int = 0
    end: int = 0
    #: For a comment: nothing but blanks precede it on its line.
    own_line: bool = False


_LINE_END = "\r\n"
#: A run of word characters, and the body of a quoted string up to where it ends or its line does
#: (a backslash escapes the character after it, a quote included, but not a line break): matched
#: whole rather than character by character, as most of a file's text is in them.
_WORD_RUN = re.compile("[" + re.escape("".join(sorted(WORD_CHARACTERS))) + "]+")
_STRING_BODY = re.compile(r'(?:[^"\\\r\n]|\\[^\r\n]|\\(?=[\r\n]|\Z))*')


def _tokens(text: str, index: int = 0) -> Iterator[_Token]:
    line = 1
    length = len(text)
    line_has_token = False
    while index < length:
        char = text[index]
        if char in _LINE_END:
            # CRLF, LF and a lone CR each end one line.
            index += 2 if text.startswith("\r\n", index) else 1
            line += 1
            line_has_token = False
        elif char in " \t\f\v":
            index += 1
        elif char == "$":
            end = _line_end(text, index)
            yield _Token("comment", text[index + 1 : end], line, index, end, own_line=not line_has_token)
            index = end
        elif char == '"':
            body = _STRING_BODY.match(text, index + 1)
            end = body.end() if body else index + 1
            if end >= length or text[end] != '"':
                raise EdsSyntaxError(line, "string not closed on the line it starts")
            yield _Token("string", text[index + 1 : end], line, index, end + 1)
            line_has_token = True
            index = end + 1
        elif char == "[":
            end = index + 1
            while end < length and text[end] not in "]\r\n":
                end += 1
            if end >= length or text[end] != "]":
                raise EdsSyntaxError(line, "section name not closed by ']'")
            name = text[index + 1 : end].strip()
            if not name:
                raise EdsSyntaxError(line, "empty section name")
            bad = [c for c in name if not " " <= c <= "~" or c == "["]
            if bad:
                raise EdsSyntaxError(line, f"character {bad[0]!r} in section name")
            yield _Token("section", name, line, index, end + 1)
            line_has_token = True
            index = end + 1
        elif char in _PUNCTUATION:
            yield _Token(char, char, line, index, index + 1)
            line_has_token = True
            index += 1
        elif char in WORD_CHARACTERS:
            run = _WORD_RUN.match(text, index)
            end = run.end() if run else index + 1
            yield _Token("word", text[index:end], line, index, end)
            line_has_token = True
            index = end
        elif char == _END_OF_FILE_MARK and not text[index + 1 :].strip():
            return
        else:
            raise EdsSyntaxError(line, f"unexpected character {char!r}")


def _line_end(text: str, index: int) -> int:
    """Where the line holding ``index`` ends, before its line break."""
    ends = [found for found in (text.find("\n", index), text.find("\r", index)) if found >= 0]
    return min(ends) if ends else len(text)


def _chunk_end(text: str, index: int) -> int:
    """Where the chunk of an item that ends at ``index`` ends: the rest of its line (blanks and a
    comment) and the line break, when nothing else stands on that line; else ``index`` itself."""
    end = index
    while end < len(text) and text[end] in " \t\f\v":
        end += 1
    if end < len(text) and text[end] == "$":
        end = _line_end(text, end)
    if text.startswith("\r\n", end):
        return end + 2
    if end < len(text) and text[end] in _LINE_END:
        return end + 1
    return end if end == len(text) else index


class _Parser:
    def __init__(self, text: str, start: int = 0) -> None:
        self.text = text
        self.tokens = list(_tokens(text, start))
        self.count = len(self.tokens)
        self.position = 0
        #: Where the chunk of the next section header or entry starts: where the last one ended.
        self.chunk_start = 0
        #: Where each field, entry and section header was read, by id(): kept until the parse is
        #: over, when they get their sources (comments attach to them until then).
        self.field_spans: dict[int, tuple[int, int]] = {}
        self.entry_spans: dict[int, tuple[int, int, int]] = {}
        self.section_spans: dict[int, tuple[int, int, int, int]] = {}
        self.last_end = start
        self.doc = EdsDocument()
        #: Own-line comments waiting for the section or entry that follows them.
        self.pending: list[str] = []
        #: Where a comment at the end of a line goes: the field, entry or section that line ends.
        self.trailing_target: Field | Entry | Section | None = None
        self.entry: Entry | None = None
        self.last_line = 1

    # -- token access, with comments taken out of the stream as they pass ----------------------

    def _attach_comment(self, token: _Token) -> None:
        text = token.text.strip()
        target = self.trailing_target
        if not token.own_line and isinstance(target, Field) and target.comment is None:
            target.comment = text
        elif not token.own_line and isinstance(target, (Entry, Section)):
            target.comments.append(text)
        elif self.entry is not None:
            self.entry.comments.append(text)
        else:
            self.pending.append(text)

    def peek(self) -> _Token | None:
        position = self.position
        if position >= self.count:
            return None
        token = self.tokens[position]
        while token.kind == "comment":
            self._attach_comment(token)
            position += 1
            self.position = position
            if position >= self.count:
                return None
            token = self.tokens[position]
        return token

    def take(self) -> _Token | None:
        position = self.position
        if position < self.count:
            next_token = self.tokens[position]
            if next_token.kind != "comment":
                # Most tokens are no comment: taken without peek's look for comments to attach.
                self.position = position + 1
                self.last_line = next_token.line
                self.last_end = next_token.end
                return next_token
        token = self.peek()
        if token is not None:
            self.position += 1
            self.last_line = token.line
            self.last_end = token.end
        return token

    # -- grammar ----------------------------------------------------------------------------

    def parse(self) -> EdsDocument:
        section: Section | None = None
        while (token := self.take()) is not None:
            if token.kind == "section":
                section = Section(token.text, line=token.line, comments=self.pending)
                self.pending = []
                end = _chunk_end(self.text, token.end)
                self.section_spans[id(section)] = (self.chunk_start, end, token.start, token.end)
                self.chunk_start = end
                self.doc.sections.append(section)
                self.trailing_target = section
            elif token.kind == "word":
                if section is None:
                    raise EdsSyntaxError(token.line, f"entry {token.text!r} before the first section")
                section.entries.append(self._entry(section, token))
            else:
                raise EdsSyntaxError(token.line, f"expected a keyword or a section, found {token.text!r}")
        self.doc.trailing_comments = self.pending
        self._record_sources()
        return self.doc

    def _record_sources(self) -> None:
        """Give every section, entry and field its place in the text and its value as read."""
        doc = self.doc
        newline = next((mark for mark in ("\r\n", "\n", "\r") if mark in self.text), "\r\n")
        doc.source = DocumentSource(self.text, self.chunk_start, newline, tuple(doc.trailing_comments))
        for section in doc.sections:
            start, end, name_start, name_end = self.section_spans[id(section)]
            section.source = SectionSource(start, end, name_start, name_end, section.name, tuple(section.comments),
                                           self.text)
            for entry in section.entries:
                start, end, keyword_start = self.entry_spans[id(entry)]
                for item in entry.fields:
                    field_start, field_end = self.field_spans[id(item)]
                    item.source = FieldSource(field_start, field_end, item.semantic_value(), item.comment)
                entry.source = EntrySource(start, end, keyword_start, entry.keyword, tuple(entry.fields),
                                           tuple(entry.comments), self.text)

    def _entry(self, section: Section, keyword: _Token) -> Entry:
        entry = Entry(keyword.text, line=keyword.line, comments=self.pending)
        self.pending = []
        self.entry = entry
        self.trailing_target = entry
        assign = self.take()
        if assign is None or assign.kind != "=":
            raise EdsSyntaxError(keyword.line, f"keyword {keyword.text!r} not followed by '='")
        entry.fields = self._fields(entry, closing=";")
        self.entry = None
        end = _chunk_end(self.text, self.last_end)
        self.entry_spans[id(entry)] = (self.chunk_start, end, keyword.start)
        self.chunk_start = end
        _apply_field_hints(section.name, entry)
        return entry

    def _fields(self, entry: Entry, closing: str) -> list[Field]:
        """Fields up to ``closing`` (";" for an entry, "}" for a dataset), which is consumed."""
        fields: list[Field] = []
        while True:
            token = self.peek()
            if token is None:
                raise EdsSyntaxError(self.last_line, f"entry {entry.keyword!r} not terminated by '{closing}'")
            if token.kind == "," or token.kind == closing:
                item = Field(FieldKind.EMPTY, None, "", token.line)
                self.field_spans[id(item)] = (token.start, token.start)
            else:
                start = token.start
                item = self._field(entry)
                self.field_spans[id(item)] = (start, self.last_end)
            fields.append(item)
            self.trailing_target = item
            separator = self.take()
            if separator is None or (separator.kind != "," and separator.kind != closing):
                # The separator is missing where the field ends, not where the next token is.
                found = "the end of the file" if separator is None else f"{separator.text!r} on line {separator.line}"
                raise EdsSyntaxError(
                    item.line, f"entry {entry.keyword!r}: ',' or '{closing}' missing after a field (found {found})"
                )
            if separator.kind == closing:
                return fields

    def _field(self, entry: Entry) -> Field:
        token = self.take()
        assert token is not None
        if token.kind == "string":
            following = self.peek()
            if following is None or following.kind != "string":
                return Field(FieldKind.STRING, unescape_string(token.text), f'"{token.text}"', token.line)
            pieces = [token.text]
            # Adjacent quoted strings are one field: long texts are split over lines this way.
            while following is not None and following.kind == "string":
                pieces.append(following.text)
                self.take()
                following = self.peek()
            value = "".join(unescape_string(piece) for piece in pieces)
            raw = " ".join(f'"{piece}"' for piece in pieces)
            return Field(FieldKind.STRING, value, raw, token.line)
        if token.kind == "word":
            if len(token.text) == 2 and _HEX_BYTE.fullmatch(token.text) and (following := self.peek()) is not None \
                    and following.kind == "word" and _HEX_BYTE.fullmatch(following.text):
                return self._unquoted_path(entry, token)
            kind, value = parse_word(token.text)
            return Field(kind, value, token.text, token.line)
        if token.kind == "{":
            children = [] if self._closes_at_once() else self._fields(entry, closing="}")
            raw = "{" + ", ".join(child.raw for child in children) + "}"
            return Field(FieldKind.DATASET, tuple(children), raw, token.line)
        raise EdsSyntaxError(token.line, f"entry {entry.keyword!r}: unexpected {token.text!r} where a field belongs")

    def _unquoted_path(self, entry: Entry, first: _Token) -> Field:
        """Hex bytes without quotes (``Port1 = TCP, "A", 20 66 24 01, 2;``): a path written without
        its quotes. Read as that string (the place's hint makes it a path) and noted, not refused."""
        texts = [first.text]
        while (following := self.peek()) is not None and following.kind == "word" and _HEX_BYTE.fullmatch(
                following.text):
            texts.append(following.text)
            self.take()
        value = " ".join(texts)
        self.doc.reader_notes.append(
            (first.line, f"{entry.keyword}: unquoted value {value} read as the path \"{value}\""))
        return Field(FieldKind.STRING, value, value, first.line)

    def _closes_at_once(self) -> bool:
        token = self.peek()
        if token is not None and token.kind == "}":
            self.take()
            return True
        return False


def _apply_field_hints(section: str, entry: Entry) -> None:
    """Give fields whose meaning depends on their place the kind that place calls for."""
    for section_name, pattern, number in EPATH_FIELDS:
        if section == section_name and pattern.fullmatch(entry.keyword):
            item = entry.field(number)
            if item is not None and item.kind is FieldKind.STRING:
                items = parse_epath(item.value)
                if items is not None:
                    item.kind, item.value = FieldKind.EPATH, items
    for section_name, keyword, number in REVISION_FIELDS:
        if section == section_name and entry.keyword.lower() == keyword.lower():
            item = entry.field(number)
            if item is not None and item.kind in (FieldKind.FLOAT, FieldKind.INT):
                item.kind, item.value = parse_word(item.raw, revision=True)


def parse_eds(text: str) -> EdsDocument:
    """Parse EDS text (LF, CRLF or CR line ends); raise EdsSyntaxError on malformed text.

    The document keeps the text (``doc.source``) and every item its place in it, so that
    :func:`~cipstack.eds.writer.format_eds` gives the same text back where nothing was edited."""
    # A byte-order mark, decoded as Latin-1 or as Unicode, is no part of the EDS text; it stays in
    # the source, ahead of the first chunk, so the file is written back with it.
    start = next((len(mark) for mark in ("\ufeff", "\xef\xbb\xbf") if text.startswith(mark)), 0)
    return _Parser(text, start).parse()


def decode_eds(data: bytes) -> str:
    """EDS bytes as text: Latin-1, which never fails and is what most EDS files are in."""
    return data.decode("latin-1")


def read_eds(path: str | os.PathLike[str]) -> EdsDocument:
    """Read and parse an EDS file; OSError if it cannot be read, EdsSyntaxError if malformed."""
    with open(path, "rb") as stream:
        return parse_eds(decode_eds(stream.read()))
