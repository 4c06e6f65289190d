"""Writing an :class:`EdsDocument` as EDS text: pure ASCII, CRLF, deterministic.

Short entries take one line. Entries with many fields (ParamN, EnumN, AssemN, ConnectionN)
are laid out over several lines, grouped the way readers of EDS files expect to find them
(a parameter's limits on one line, an assembly's members one per line), so a diff of two
files shows which field changed. Reading back what was written gives the same text.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence

from .model import SECTION_NAME, EdsDocument, Entry, Section, ascii_comment, is_bare_word, render_field

NEWLINE = "\r\n"
ENTRY_INDENT = "    "
FIELD_INDENT = "        "

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
    text = ascii_comment(text)
    return f"{indent}$ {text}" if text else f"{indent}$"


def _group_text(entry: Entry, group: list[int]) -> str:
    last = len(entry.fields) - 1
    parts = []
    for index in group:
        separator = ";" if index == last else ","
        parts.append(render_field(entry.fields[index]) + separator)
    text = " ".join(parts)
    comment = entry.fields[group[-1]].comment
    if comment is not None:
        text += "  " + _comment_line("", comment)
    return text


def format_entry(entry: Entry) -> list[str]:
    """The lines of one entry, its comments first."""
    lines = [_comment_line(ENTRY_INDENT, comment) for comment in entry.comments]
    if not entry.fields:
        raise ValueError(f"entry {entry.keyword!r} has no field")
    if not is_bare_word(entry.keyword):
        raise ValueError(f"keyword {entry.keyword!r} cannot be written")
    groups = _field_groups(entry)
    if len(groups) == 1:
        lines.append(f"{ENTRY_INDENT}{entry.keyword} = {_group_text(entry, groups[0])}")
    else:
        lines.append(f"{ENTRY_INDENT}{entry.keyword} =")
        lines.extend(FIELD_INDENT + _group_text(entry, group) for group in groups)
    return lines


def format_section(section: Section) -> list[str]:
    if not SECTION_NAME.fullmatch(section.name):
        raise ValueError(f"section name {section.name!r} cannot be written")
    lines = [_comment_line("", comment) for comment in section.comments]
    lines.append(f"[{section.name}]")
    for entry in section.entries:
        lines.extend(format_entry(entry))
    return lines


def format_eds(doc: EdsDocument) -> str:
    """The document as EDS text: ASCII, CRLF line ends, a blank line between sections."""
    blocks = [NEWLINE.join(format_section(section)) for section in doc.sections]
    if doc.trailing_comments:
        blocks.append(NEWLINE.join(_comment_line("", comment) for comment in doc.trailing_comments))
    return (NEWLINE + NEWLINE).join(blocks) + NEWLINE
