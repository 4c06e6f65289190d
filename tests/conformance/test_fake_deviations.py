"""Every check can fail: for each check id, the scripted target of ``fake_target`` deviates in that
one place, and the battery, run over the check's whole group, fails that check and no other."""

from __future__ import annotations

from pathlib import Path

import pytest

from cipstack.conformance import CHECKS, Verdict, check_ids, run

from .fake_target import FakeTarget

EDS = Path(__file__).with_name("fake_device.eds")


def run_group(target: FakeTarget, group: str):  # type: ignore[no-untyped-def]
    return run(target.host, target.port, eds=EDS, groups=group, allow_writes=True, allow_reset=True, timeout=2.0)


@pytest.mark.parametrize("group", ["encap", "router", "objects", "cm", "class1", "eds"])
def test_the_conformant_fake_passes_every_check(group: str) -> None:
    with FakeTarget() as target:
        report = run_group(target, group)
    assert target.errors == []
    assert {o.name: o.observed for o in report if o.verdict is not Verdict.PASS} == {}
    assert {o.id for o in report} == {i for i in check_ids() if CHECKS[i].group == group}


@pytest.mark.parametrize("check_id", check_ids())
def test_each_check_fails_on_its_deviation(check_id: str) -> None:
    with FakeTarget(deviation=check_id) as target:
        report = run_group(target, CHECKS[check_id].group)
    assert target.errors == []
    failed = {o.id for o in report.failures}
    assert failed == {check_id}, {o.name: o.observed for o in report.failures}


def test_every_check_has_a_deviation_in_the_fake() -> None:
    """The fake names each check id it can deviate for: a check added to the battery without a way
    to fail it is caught here (the parametrized test above would run it, and this says why)."""
    source = Path(__file__).with_name("fake_target.py").read_text(encoding="utf-8")
    assert [i for i in check_ids() if f'"{i}"' not in source] == []
