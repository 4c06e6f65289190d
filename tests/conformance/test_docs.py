"""docs/conformance.md lists every check of the battery; its blocks run with every other page's in
tests/test_docs.py."""

from __future__ import annotations

from pathlib import Path

from cipstack.conformance import check_ids

PAGE = Path(__file__).resolve().parents[2] / "docs" / "conformance.md"


def test_the_page_lists_every_check() -> None:
    text = PAGE.read_text()
    assert [i for i in check_ids() if f"| `{i}` |" not in text] == []


def test_the_check_tables_are_generated_from_the_declarations() -> None:
    """Each group's table is what ``markdown_table`` makes of the checks as declared: one source."""
    from cipstack.conformance import GROUPS
    from cipstack.conformance.report import markdown_table

    text = PAGE.read_text()
    assert [g for g in GROUPS if markdown_table(g) + "\n" not in text] == []
