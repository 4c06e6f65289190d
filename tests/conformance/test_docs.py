"""docs/conformance.md lists every check of the battery; its blocks run with every other page's in
tests/test_docs.py."""

from __future__ import annotations

import re
from pathlib import Path

from cipstack.conformance import check_ids

PAGE = Path(__file__).resolve().parents[2] / "docs" / "conformance.md"
#: The deviations of the sample run in the page ("A sample run against a deviating target"): the
#: scripted target of ``fake_target`` with these, as OpENer showed them (one per finding explained).
SAMPLE_DEVIATIONS = ("encap.wrong_length", "router.too_much_data", "router.not_enough_data", "cm.forward_open.rpi",
                     "cm.forward_open.transport_class", "final.as_found")
SAMPLE_VARIANT = "warn:cm.forward_open.consuming_point"


def test_the_page_lists_every_check() -> None:
    text = PAGE.read_text()
    assert [i for i in check_ids() if f"| `{i}` |" not in text] == []


def test_the_check_tables_are_generated_from_the_declarations() -> None:
    """Each group's table is what ``markdown_table`` makes of the checks as declared: one source."""
    from cipstack.conformance import GROUPS
    from cipstack.conformance.report import markdown_table

    text = PAGE.read_text()
    assert [g for g in GROUPS if markdown_table(g) + "\n" not in text] == []


def test_the_sample_run_shows_what_the_deviating_target_gives() -> None:
    """The findings of the page's sample run are those the scripted target with its deviations gives
    today, and each is explained below the report."""
    from cipstack.conformance import Verdict, run

    from .fake_target import FakeTarget

    text = PAGE.read_text()
    section = text[text.index("## A sample run against a deviating target"):text.index("## Every check")]
    shown = set(re.findall(r"^  FAIL (\S+):", section, re.M))
    warned = set(re.findall(r"^  warning (\S+) ", section, re.M))
    with FakeTarget(deviation=SAMPLE_DEVIATIONS, variant=SAMPLE_VARIANT) as target:
        report = run(target.host, target.port, eds=PAGE.parents[1] / "tests/conformance/fake_device.eds", timeout=2.0)
    assert shown == {o.name for o in report.failures}
    assert warned == {o.name for o in report if o.verdict is Verdict.WARNING}
    assert [n for n in shown | warned if f"**`{n}`**" not in section and f"`{n}`**" not in section] == []
