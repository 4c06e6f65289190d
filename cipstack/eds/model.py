"""The EDS document model: sections, entries and fields, in file order, with their comments.

A field keeps the text it was read from (``raw``) next to the value parsed from it, so a file
can be rewritten without reformatting numbers the author chose to write in hex, while two
documents can still be compared by value alone (:func:`semantically_equal`).

Documents are also built in code, one entry at a time::

    doc = EdsDocument()
    device = doc.section("Device")
    device.add("VendCode", [Field.integer(259)])
    device.add("ProdName", ["ACG-ET2"], comment="the name Identity attribute 7 reports")
"""

from __future__ import annotations

import datetime
import math
import re
import unicodedata
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from dataclasses import field as dataclass_field
from enum import Enum
from functools import lru_cache
from typing import Any

from ..errors import BadRequest, WrongType


class FieldKind(str, Enum):
    INT = "int"
    FLOAT = "float"
    STRING = "string"
    DATE = "date"
    TIME = "time"
    REVISION = "revision"
    EPATH = "epath"
    #: A bare word: a keyword value (``EtherNetIP``, ``TxRx``) or a reference (``Param3``).
    KEYWORD = "keyword"
    EMPTY = "empty"
    #: A brace-enclosed list of fields (``{1, 2, 3}``), as some array defaults are written.
    DATASET = "dataset"


#: An EPATH item: a byte, or the name of a parameter whose value stands in for bytes.
EpathItem = int | str

#: Characters of an unquoted word: printable ASCII but blanks and the EDS punctuation.
WORD_CHARACTERS = frozenset(chr(code) for code in range(0x21, 0x7F)) - set('"$,;=[]{}')
_BARE_WORD = re.compile("[" + re.escape("".join(sorted(WORD_CHARACTERS))) + "]+")
_REFERENCE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_DECIMAL = re.compile(r"[+-]?[0-9]+")
_HEX = re.compile(r"[+-]?0[xX][0-9A-Fa-f]+")
_REAL = re.compile(r"[+-]?(?:[0-9]+\.[0-9]*|\.[0-9]+|[0-9]+(?=[eE]))(?:[eE][+-]?[0-9]+)?")
_DATE = re.compile(r"([0-9]+)-([0-9]+)-([0-9]+)")
_TIME = re.compile(r"([0-9]+):([0-9]+):([0-9]+)")
_REVISION = re.compile(r"([0-9]+)\.([0-9]+)")
_EPATH_BYTE = re.compile(r"[0-9A-Fa-f]{2}")
#: Public keywords are letters and digits; vendor ones start with the vendor id and "_".
_KEYWORD = re.compile(r"[A-Za-z0-9_]+")
#: A section name: printable ASCII but the brackets, with no blank at either end.
SECTION_NAME = re.compile(r"[!-Z\\^-~](?:[ -Z\\^-~]*[!-Z\\^-~])?")
# Longer numbers are no EDS value, and Python refuses to convert very long ones.
_MAX_NUMBER_LENGTH = 64
#: What escape_string changes: a quote, a backslash, a control character, beyond Latin-1.
_NEEDS_ESCAPE = re.compile(r'["\\\x00-\x1f\x7f-\x9f\u0100-\U0010ffff]')


def is_bare_word(text: str) -> bool:
    """Whether ``text`` can stand unquoted as a field or keyword."""
    return bool(_BARE_WORD.fullmatch(text))


@lru_cache(maxsize=4096)
def parse_word(text: str, revision: bool = False) -> tuple[FieldKind, Any]:
    """Kind and value of an unquoted field; ``revision`` where ``major.minor`` is expected.

    Remembered: a file repeats its words (data types, sizes, flags) thousands of times, and every
    written field is read back to check its spelling; the kinds and values are immutable."""
    if len(text) > _MAX_NUMBER_LENGTH:
        return FieldKind.KEYWORD, text
    if _DECIMAL.fullmatch(text):
        return FieldKind.INT, int(text, 10)
    if _HEX.fullmatch(text):
        return FieldKind.INT, int(text, 16)
    if revision and (match := _REVISION.fullmatch(text)):
        return FieldKind.REVISION, (int(match[1]), int(match[2]))
    if _REAL.fullmatch(text):
        return FieldKind.FLOAT, float(text)
    if match := _DATE.fullmatch(text):
        return FieldKind.DATE, (int(match[1]), int(match[2]), int(match[3]))
    if match := _TIME.fullmatch(text):
        return FieldKind.TIME, (int(match[1]), int(match[2]), int(match[3]))
    return FieldKind.KEYWORD, text


def parse_epath(text: str) -> tuple[EpathItem, ...] | None:
    """The items of an EPATH string ("20 04 24 [Param3]"), or None if it is not one."""
    items: list[EpathItem] = []
    for token in text.split():
        if _EPATH_BYTE.fullmatch(token):
            items.append(int(token, 16))
        elif token.startswith("[") and token.endswith("]") and _REFERENCE.fullmatch(token[1:-1]):
            items.append(token[1:-1])
        else:
            return None
    return tuple(items)


def format_epath(items: Iterable[EpathItem]) -> str:
    return " ".join(f"[{item}]" if isinstance(item, str) else f"{item:02X}" for item in items)


def escape_string(value: str) -> str:
    """Quoted-string body: backslash escapes for quotes, backslashes and control characters;
    Latin-1 letters as themselves (EDS files are Latin-1, and readers take ``\\xF6`` literally);
    a character beyond Latin-1, which no EDS file can hold, as "?"."""
    if not _NEEDS_ESCAPE.search(value):
        # Nearly every string of a file is plain text: taken whole, not character by character.
        return value
    out: list[str] = []
    for char in value:
        code = ord(char)
        if char in '"\\':
            out.append("\\" + char)
        elif char == "\n":
            out.append("\\n")
        elif char == "\t":
            out.append("\\t")
        elif char == "\r":
            out.append("\\r")
        elif code < 0x20 or 0x7F <= code <= 0x9F:
            out.append(f"\\x{code:02X}")
        elif code > 0xFF:
            out.append("?")
        else:
            out.append(char)
    return "".join(out)


_ESCAPES = {"n": "\n", "t": "\t", "r": "\r", '"': '"', "\\": "\\"}


def unescape_string(body: str) -> str:
    """Inverse of :func:`escape_string`; an unknown escape keeps its backslash (real files
    contain Windows paths)."""
    if "\\" not in body:
        return body  # most strings: nothing to undo
    out: list[str] = []
    index = 0
    while index < len(body):
        char = body[index]
        if char == "\\" and index + 1 < len(body):
            follower = body[index + 1]
            if follower in _ESCAPES:
                out.append(_ESCAPES[follower])
                index += 2
                continue
            hex_digits = body[index + 2 : index + 4]
            if follower == "x" and len(hex_digits) == 2 and all(c in "0123456789abcdefABCDEF" for c in hex_digits):
                out.append(chr(int(hex_digits, 16)))
                index += 4
                continue
        out.append(char)
        index += 1
    return "".join(out)


def _comment_character(char: str) -> str:
    if " " <= char <= "~" or char == "\t" or "\xa0" <= char <= "\xff":
        return char
    # Beyond Latin-1, a letter keeps its base letter; anything else becomes "?".
    base = unicodedata.normalize("NFKD", char).encode("ascii", "ignore").decode("ascii")
    return base if base and all(" " <= c <= "~" for c in base) else "?"


def written_comment(text: str) -> str:
    """A comment as written: one line of printable Latin-1, no surrounding blanks."""
    return "".join(_comment_character(char) for char in text).strip()


@dataclass(frozen=True)
class FieldSource:
    """A field's place in the text it was read from (``text[start:end]``; empty for an empty
    field) and its value and comment then, to tell whether it has been edited since."""

    start: int
    end: int
    value: Any
    comment: str | None

    def edited(self, item: Field) -> bool:
        """Whether ``item``, in this field's place now, means something else than what was read."""
        return bool(item.semantic_value() != self.value)


@dataclass(frozen=True)
class EntrySource:
    """An entry's chunk of the text it was read from: ``text[start:end]`` holds the blank lines and
    comments before it, the entry and the rest of its last line; ``keyword_*`` the keyword, and
    ``fields`` the Field objects read, with the entry's comments then."""

    start: int
    end: int
    keyword_start: int
    keyword: str
    fields: tuple[Field, ...]
    comments: tuple[str, ...]
    #: The text itself, so that an item moved into another document is not taken for part of its text.
    text: str = dataclass_field(repr=False, compare=False, default="")


@dataclass(frozen=True)
class SectionSource:
    """A section header's chunk (blank lines and comments before it, ``[name]``, the rest of its
    line), where its name stands, and its name and comments then."""

    start: int
    end: int
    name_start: int
    name_end: int
    name: str
    comments: tuple[str, ...]
    #: The text itself, so that an item moved into another document is not taken for part of its text.
    text: str = dataclass_field(repr=False, compare=False, default="")


@dataclass
class Field:
    """One field of an entry: its kind, parsed value and the text it came from."""

    kind: FieldKind
    value: Any
    raw: str
    line: int = 0
    #: A comment written on the same line right after this field.
    comment: str | None = None
    #: Where the field was read from, and what it was then (None for a field built in code).
    source: FieldSource | None = dataclass_field(default=None, compare=False, repr=False)

    # -- typed constructors, for documents built in code --------------------------------------

    @classmethod
    def integer(cls, value: int, hex_digits: int | None = None) -> Field:
        """An integer, in decimal or, with ``hex_digits``, as ``0x`` and that many digits."""
        if isinstance(value, bool) or not isinstance(value, int):
            raise WrongType(f"integer field needs an int, not {value!r}")
        value = int(value)  # an IntEnum member is its number (Python 3.10's str() gives its name)
        raw = str(value) if hex_digits is None else ("-" if value < 0 else "") + f"0x{abs(value):0{hex_digits}X}"
        return cls(FieldKind.INT, value, raw)

    @classmethod
    def real(cls, value: float) -> Field:
        value = float(value)
        if not math.isfinite(value):
            raise BadRequest("an EDS real must be finite")
        raw = repr(value)
        return cls(FieldKind.FLOAT, value, raw)

    @classmethod
    def string(cls, value: str) -> Field:
        return cls(FieldKind.STRING, value, '"' + escape_string(value) + '"')

    @classmethod
    def epath(cls, path: str | bytes | Sequence[EpathItem]) -> Field:
        """An EPATH from its text ("20 04 24 64"), its bytes, or bytes and parameter names."""
        if isinstance(path, str):
            items = parse_epath(path)
            if items is None:
                raise BadRequest(f"not an EPATH: {path!r}")
        else:
            items = tuple(path)
            for item in items:
                if isinstance(item, str) and not _REFERENCE.fullmatch(item):
                    raise BadRequest(f"not a parameter reference: {item!r}")
                if isinstance(item, int) and not 0 <= item <= 0xFF:
                    raise BadRequest(f"not a byte: {item!r}")
        return cls(FieldKind.EPATH, items, '"' + format_epath(items) + '"')

    @classmethod
    def keyword(cls, word: str) -> Field:
        """An unquoted word: a keyword value (``EtherNetIP``) or a reference (``Param3``)."""
        kind, _ = parse_word(word)
        if kind is not FieldKind.KEYWORD or not is_bare_word(word):
            raise BadRequest(f"not a keyword: {word!r}")
        return cls(FieldKind.KEYWORD, word, word)

    @classmethod
    def empty(cls) -> Field:
        return cls(FieldKind.EMPTY, None, "")

    @classmethod
    def date(cls, value: datetime.date) -> Field:
        triple = (value.month, value.day, value.year)
        return cls(FieldKind.DATE, triple, f"{value.month:02d}-{value.day:02d}-{value.year:04d}")

    @classmethod
    def time(cls, value: datetime.time) -> Field:
        triple = (value.hour, value.minute, value.second)
        return cls(FieldKind.TIME, triple, f"{value.hour:02d}:{value.minute:02d}:{value.second:02d}")

    @classmethod
    def revision(cls, major: int, minor: int) -> Field:
        return cls(FieldKind.REVISION, (major, minor), f"{major}.{minor}")

    @classmethod
    def dataset(cls, items: Sequence[Any]) -> Field:
        children = [as_field(item) for item in items]
        if len(children) == 1 and children[0].is_empty:
            children = []  # "{}" is written for both; it reads as the empty dataset
        value = tuple(children)
        return cls(FieldKind.DATASET, value, "{" + ", ".join(render_field(c) for c in children) + "}")

    # -- reading ----------------------------------------------------------------------------

    @property
    def is_empty(self) -> bool:
        return self.kind is FieldKind.EMPTY

    @property
    def number(self) -> int | float | None:
        """The numeric value, or None for a field that is not a number."""
        return self.value if self.kind in (FieldKind.INT, FieldKind.FLOAT) else None

    def semantic_value(self) -> Any:
        """What the field means, without its spelling: kind and value (datasets recursively)."""
        if self.kind is FieldKind.DATASET:
            return (self.kind, tuple(child.semantic_value() for child in self.value))
        return (self.kind, self.value)

    def __str__(self) -> str:
        return render_field(self)


def as_field(value: Any) -> Field:
    """A field from a plain Python value: int, float, str (a quoted string), None (empty),
    a date, a time, or a ready-made Field."""
    if isinstance(value, Field):
        return value
    if value is None:
        return Field.empty()
    if isinstance(value, bool):
        return Field.integer(int(value))
    if isinstance(value, int):
        return Field.integer(value)
    if isinstance(value, float):
        return Field.real(value)
    if isinstance(value, str):
        return Field.string(value)
    if isinstance(value, datetime.datetime):
        raise WrongType("give a date or a time, not a datetime")
    if isinstance(value, datetime.date):
        return Field.date(value)
    if isinstance(value, datetime.time):
        return Field.time(value)
    raise WrongType(f"no EDS field for {value!r}")


def _raw_still_valid(item: Field) -> bool:
    """Whether ``raw`` is pure ASCII text that reads back as this field's value."""
    raw = item.raw
    if not raw.isascii() or not is_bare_word(raw):
        return False
    return parse_word(raw, revision=item.kind is FieldKind.REVISION) == (item.kind, item.value)


def render_field(item: Field) -> str:
    """The text a field is written as: its original spelling when that still reads back to
    the same value and is ASCII, else a canonical spelling of the value."""
    kind, value = item.kind, item.value
    if kind is FieldKind.EMPTY:
        return ""
    if kind is FieldKind.STRING:
        return '"' + escape_string(value) + '"'
    if kind is FieldKind.EPATH:
        return '"' + format_epath(value) + '"'
    if kind is FieldKind.DATASET:
        return "{" + ", ".join(render_field(child) for child in value) + "}"
    if _raw_still_valid(item):
        return item.raw
    if kind is FieldKind.INT:
        if _HEX.fullmatch(item.raw):
            # A number the author wrote in hex keeps hex, and at least as many digits.
            digits = len(item.raw.lstrip("+-")) - 2
            return ("-" if value < 0 else "") + f"0x{abs(value):0{digits}X}"
        return str(value)
    if kind is FieldKind.FLOAT:
        return repr(float(value))
    if kind is FieldKind.DATE:
        month, day, year = value
        return f"{month:02d}-{day:02d}-{year:04d}"
    if kind is FieldKind.TIME:
        return "{:02d}:{:02d}:{:02d}".format(*value)
    if kind is FieldKind.REVISION:
        return "{}.{}".format(*value)
    if kind is FieldKind.KEYWORD and isinstance(value, str) and is_bare_word(value) and value.isascii():
        return value
    raise BadRequest(f"field {item.raw!r} of kind {kind.value} cannot be written")


@dataclass
class Entry:
    """``Keyword = field, field, ...;`` with the comments written before it."""

    keyword: str
    fields: list[Field] = dataclass_field(default_factory=list)
    line: int = 0
    comments: list[str] = dataclass_field(default_factory=list)
    #: Where the entry was read from (None for an entry built in code).
    source: EntrySource | None = dataclass_field(default=None, compare=False, repr=False)

    def field(self, number: int) -> Field | None:
        """Field ``number``, counted from 1 as the EDS specification numbers them."""
        if 1 <= number <= len(self.fields):
            return self.fields[number - 1]
        return None

    def value(self, number: int = 1) -> Any:
        item = self.field(number)
        return None if item is None else item.value

    def line_of(self, number: int) -> int:
        """Line of field ``number``, or of the entry when the field is missing."""
        item = self.field(number)
        return item.line if item is not None and item.line else self.line


@dataclass
class Section:
    """``[Name]`` and its entries, with the comments written before it."""

    name: str
    entries: list[Entry] = dataclass_field(default_factory=list)
    line: int = 0
    comments: list[str] = dataclass_field(default_factory=list)
    #: Where the section header was read from (None for a section built in code).
    source: SectionSource | None = dataclass_field(default=None, compare=False, repr=False)

    def add(self, keyword: str, fields: Sequence[Any], comment: str | Sequence[str] | None = None) -> Entry:
        """Append an entry; ``fields`` holds Fields or plain values (see :func:`as_field`)."""
        if not _KEYWORD.fullmatch(keyword):
            raise BadRequest(f"not an EDS keyword: {keyword!r}")
        entry = Entry(keyword, [as_field(item) for item in fields] or [Field.empty()])
        entry.comments = _comment_list(comment)
        self.entries.append(entry)
        return entry

    def get(self, keyword: str) -> Entry | None:
        """The first entry with this keyword (keywords are case sensitive)."""
        return next((entry for entry in self.entries if entry.keyword == keyword), None)

    def __contains__(self, keyword: object) -> bool:
        return any(entry.keyword == keyword for entry in self.entries)

    def __iter__(self) -> Iterator[Entry]:
        return iter(self.entries)


def _comment_list(comment: str | Sequence[str] | None) -> list[str]:
    if comment is None:
        return []
    lines = comment.splitlines() if isinstance(comment, str) else [line for c in comment for line in c.splitlines()]
    return [written_comment(line) for line in lines]


@dataclass(frozen=True)
class DocumentSource:
    """The whole text read, where its last chunk ends (what follows is the file's closing
    comments and blank lines), the line break it uses and its closing comments then."""

    text: str
    epilogue_start: int
    newline: str
    trailing_comments: tuple[str, ...]


@dataclass
class EdsDocument:
    sections: list[Section] = dataclass_field(default_factory=list)
    #: Comments after the last entry of the file.
    trailing_comments: list[str] = dataclass_field(default_factory=list)
    #: What the reader took in although the specification writes it otherwise, as (line, what):
    #: an unquoted path, read as the path it evidently is. The checker reports each as a warning.
    reader_notes: list[tuple[int, str]] = dataclass_field(default_factory=list)
    #: The text the document was read from, which the writer keeps wherever nothing was edited.
    source: DocumentSource | None = dataclass_field(default=None, compare=False, repr=False)

    def section(self, name: str, comment: str | Sequence[str] | None = None) -> Section:
        """The section with this name, appended if the document has none yet."""
        found = self.get(name)
        if found is None:
            if not SECTION_NAME.fullmatch(name):
                raise BadRequest(f"not an EDS section name: {name!r}")
            found = Section(name, comments=_comment_list(comment))
            self.sections.append(found)
        elif comment is not None:
            found.comments.extend(_comment_list(comment))
        return found

    def get(self, name: str) -> Section | None:
        return next((section for section in self.sections if section.name == name), None)

    def entry(self, section: str, keyword: str) -> Entry | None:
        found = self.get(section)
        return None if found is None else found.get(keyword)

    def __contains__(self, name: object) -> bool:
        return any(section.name == name for section in self.sections)

    def __iter__(self) -> Iterator[Section]:
        return iter(self.sections)


def semantic_differences(first: EdsDocument, second: EdsDocument) -> list[str]:
    """How two documents differ in meaning: sections, keywords and field values in order.
    Spelling, layout, comments and line numbers do not count."""
    differences: list[str] = []
    names_a = [s.name for s in first.sections]
    names_b = [s.name for s in second.sections]
    if names_a != names_b:
        return [f"sections differ: {names_a} != {names_b}"]
    for section_a, section_b in zip(first.sections, second.sections, strict=True):
        keywords_a = [e.keyword for e in section_a.entries]
        keywords_b = [e.keyword for e in section_b.entries]
        if keywords_a != keywords_b:
            differences.append(f"[{section_a.name}] keywords differ: {keywords_a} != {keywords_b}")
            continue
        for entry_a, entry_b in zip(section_a.entries, section_b.entries, strict=True):
            values_a = [f.semantic_value() for f in entry_a.fields]
            values_b = [f.semantic_value() for f in entry_b.fields]
            if values_a != values_b:
                differences.append(f"[{section_a.name}] {entry_a.keyword}: {values_a} != {values_b}")
    return differences


def semantically_equal(first: EdsDocument, second: EdsDocument) -> bool:
    """Same sections, keywords and parsed field values, in the same order."""
    return not semantic_differences(first, second)
