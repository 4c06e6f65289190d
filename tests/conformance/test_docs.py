"""docs/conformance.md lists every check of the battery; its blocks run with every other page's in
tests/test_docs.py."""

from __future__ import annotations

from pathlib import Path

from cipstack.conformance import check_ids

PAGE = Path(__file__).resolve().parents[2] / "docs" / "conformance.md"


def test_the_page_lists_every_check() -> None:
    text = PAGE.read_text()
    assert [i for i in check_ids() if f"| `{i}` |" not in text] == []
