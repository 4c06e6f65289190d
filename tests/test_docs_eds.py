"""docs/eds.md says what the checker and the adapter do: its rules table is the checker's own
(``RULES``, ``SOURCES`` and the severities), and the adapter's lines it shows are what the adapter
prints. Its console blocks run in tests/test_docs.py with every other page's."""

from __future__ import annotations

import re
from pathlib import Path

from cipstack.eds.checker import RULES, SOURCES
from cipstack.eds.emulated_device import build_eds_device
from cipstack.eds.reader import read_eds

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "eds.md"
def test_the_rules_table_is_the_checkers() -> None:
    """One row per rule: its name, its severity (as the checker reports it) and its source."""
    text = DOC.read_text(encoding="utf-8")
    rows = dict(re.findall(r"^\| `([a-z0-9-]+)` \| (.*) \|$", text, re.MULTILINE))
    assert set(rows) == set(RULES)
    for rule, row in rows.items():
        severity, source = (cell.strip() for cell in row.split(" | ", 1))
        assert source == SOURCES[rule], rule
        assert severity, rule


def test_the_adapter_lines_shown_are_what_it_prints() -> None:
    text = DOC.read_text(encoding="utf-8")
    shown = re.findall(r"^cipstack adapter: (tests/eds/files/\S+\.eds):(\d+): warning: (.*)$", text, re.MULTILINE)
    assert shown
    by_file: dict[str, list[tuple[int, str]]] = {}
    for path, line, message in shown:
        by_file.setdefault(path, []).append((int(line), message))
    for path, lines in by_file.items():
        issues = [(i.line, i.message) for i in build_eds_device(read_eds(ROOT / path)).issues]
        assert lines == issues, path
