"""A target that stops answering stops the run, by name: the check after which it went silent is the
finding, every later check is "not run" with that reason, in every report, and the run ends in
bounded time rather than waiting out each later check's timeouts. The scripted target goes silent
where it is told to: hung (connections open, nothing answered) or gone (listener and connections
closed), or aborted at its 21st TCP connection as stock OpENer's debug build does."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path
from xml.etree import ElementTree

import pytest

from cipstack.conformance import Report, Verdict, check_ids, run
from cipstack.conformance.runner import DISCOVERY

from .fake_target import FakeTarget

EDS = Path(__file__).with_name("fake_device.eds")
#: The reply timeout of these runs. Once the target is silent the battery waits for at most one reply,
#: asks it twice more (a connection and a ListIdentity, each within the timeout, ``SILENCE_RETRY_S``
#: apart) and sends nothing after: the rest of the run is a few timeouts, where waiting out the ~50
#: later checks took at least one each.
TIMEOUT_S = 1.0
BOUND_S = 10 * TIMEOUT_S


def _run_until_silent(target: FakeTarget, allow_stress: bool = False) -> tuple[Report, float]:
    """The report, and how long the run went on after the target fell silent."""
    report = run(target.host, target.port, eds=EDS, timeout=TIMEOUT_S, allow_stress=allow_stress)
    assert target.silent_since is not None, "the target never fell silent"
    return report, time.monotonic() - target.silent_since


def _after(report: Report, check: str) -> list[tuple[str, Verdict, str]]:
    names = [o.name for o in report]
    return [(o.name, o.verdict, o.observed) for o in report.outcomes[names.index(check) + 1:]]


def _assert_stopped_at(report: Report, check: str) -> None:
    named = next(o for o in report if o.name == check)
    assert named.verdict is Verdict.FAIL
    assert named.observed.startswith("the target stopped answering after this check: "), named.observed
    later = _after(report, check)
    assert later and all(v is Verdict.NOT_RUN and o == f"the target stopped answering after {check}"
                         for _, v, o in later), later
    assert "final.as_found" in {n for n, _, _ in later}  # nothing can be checked on a silent target
    assert report.stopped is not None and report.stopped["after"] == check
    assert report.stopped["not_run"] == len(later)
    # Before it, the target answered: nothing fails but the named check.
    assert [o.name for o in report.failures] == [check]


@pytest.mark.parametrize("silence", ["hang", "close"])
@pytest.mark.parametrize("point", ["router.bad_path", "objects.identity.attributes"])
def test_the_check_after_which_the_target_went_silent_is_named(point: str, silence: str) -> None:
    """After a check (router.bad_path: its one request answered) or within one (Identity attributes 5-7
    unanswered), hung or gone: that check is the finding and every later one is not run."""
    with FakeTarget(silent_after=point, silence=silence) as target:
        report, after_silence = _run_until_silent(target)
    _assert_stopped_at(report, point)
    assert after_silence < BOUND_S, after_silence


@pytest.mark.parametrize("silence", ["hang", "close"])
def test_a_target_silent_while_its_connection_points_are_sought_runs_no_check(silence: str) -> None:
    """Without an EDS the battery looks for the connection points before the first check: a target
    that falls silent then is named in ``stopped`` and no check runs."""
    with FakeTarget(silent_after=DISCOVERY, silence=silence) as target:
        report = run(target.host, target.port, timeout=TIMEOUT_S)
        assert target.silent_since is not None
        after_silence = time.monotonic() - target.silent_since
    assert report.stopped is not None and report.stopped["after"] == DISCOVERY
    assert report.stopped["not_run"] == len(report.outcomes) == len(check_ids())
    assert {(o.verdict, o.observed) for o in report} == {(Verdict.NOT_RUN, f"the target stopped answering after "
                                                                           f"{DISCOVERY}")}
    assert after_silence < BOUND_S, after_silence


def test_an_opener_like_target_aborted_by_the_session_limit_is_named() -> None:
    """With --allow-stress, the session limit takes down a target that aborts at its 21st TCP
    connection: that is its finding, and the run stops there."""
    with FakeTarget(tcp_limit=20, max_sessions=40) as target:
        report, after_silence = _run_until_silent(target, allow_stress=True)
        aborted = target.aborted
    assert aborted
    _assert_stopped_at(report, "encap.session_limit")
    # The check itself waits RECOVERY_S for a new session before the battery asks.
    assert after_silence < BOUND_S + 2.0, after_silence
    assert "20 sessions granted" in next(o.observed for o in report if o.id == "encap.session_limit")
    assert report.stopped is not None and "Connection refused" in report.stopped["reason"]


def test_every_report_says_where_the_run_stopped(tmp_path: Path) -> None:
    junit, page = tmp_path / "conform.xml", tmp_path / "conform.html"
    args = ["--eds", str(EDS), "--timeout", "1", "--junit", str(junit), "--html", str(page)]
    with FakeTarget(silent_after="router.bad_path") as target:
        as_json = subprocess.run([sys.executable, "-m", "cipstack", "conform", target.address, *args, "--json"],
                                 capture_output=True, text=True, timeout=120, check=False)
    with FakeTarget(silent_after="router.bad_path", silence="close") as target:
        as_text = subprocess.run([sys.executable, "-m", "cipstack", "conform", target.address, "--eds", str(EDS),
                                  "--timeout", "1"], capture_output=True, text=True, timeout=120, check=False)
    assert (as_json.returncode, as_text.returncode) == (1, 1), as_json.stderr + as_text.stderr
    assert "Traceback" not in as_json.stderr + as_text.stderr
    report = json.loads(as_json.stdout)
    assert report["stopped"]["after"] == "router.bad_path" and report["stopped"]["not_run"] > 40
    assert report["stopped"]["reason"].startswith("no reply to ListIdentity on a new TCP connection")
    verdicts = {c["id"]: (c["verdict"], c["observed"]) for c in report["checks"]}
    assert verdicts["router.bad_path"][0] == "fail"
    assert verdicts["cm.forward_open.accepted"] == ("not run", "the target stopped answering after router.bad_path")
    # Text: one line names the check and the reason, below the summary.
    stopped = [line for line in as_text.stdout.splitlines() if line.startswith("the run stopped: ")]
    assert len(stopped) == 1 and "after router.bad_path (" in stopped[0] and "checks after it not run" in stopped[0]
    assert "  FAIL router.bad_path: " in as_text.stdout
    # JUnit: the named check fails, the later ones are skipped with the reason.
    cases = {c.get("name"): c for c in ElementTree.parse(junit).getroot().iter("testcase")}
    failure = cases["router.bad_path"].find("failure")
    assert failure is not None and failure.get("message", "").startswith("the target stopped answering after this")
    skipped = cases["class1.production"].find("skipped")
    assert skipped is not None and skipped.get("message") == "the target stopped answering after router.bad_path"
    # HTML: said at the top, linked to the named check's row.
    html = page.read_text()
    top = html.index('<p class="stopped">')
    assert top < html.index('id="summary"')
    assert 'href="#check-router.bad_path"' in html[top:html.index('id="summary"')]


def test_the_docs_show_what_the_opener_like_target_gives() -> None:
    """docs/conformance.md's run against the OpENer-like target with --allow-stress, as the command
    prints it today (its port and duration aside)."""
    page = (Path(__file__).resolve().parents[2] / "docs" / "conformance.md").read_text()
    section = page[page.index("## A target that stops answering"):page.index("## Safe by default")]
    section = section[section.index("```text\n"):section.index("```\n", section.index("```text\n") + 8)]
    with FakeTarget(opener_layout=True, tcp_limit=20, max_sessions=40) as target:
        result = subprocess.run([sys.executable, "-m", "cipstack", "conform", target.address, "--allow-stress",
                                 "--timeout", "2"], capture_output=True, text=True, timeout=120, check=False)
    assert result.returncode == 1, result.stderr
    printed = result.stdout.replace(target.address, "127.0.0.1:44818").splitlines()
    total = f"{len(check_ids())} checks: "
    shown = [line for line in section.splitlines()[1:] if line != "..." and not line.startswith(total)]
    assert shown and [line for line in shown if line not in printed] == []
    summary = next(line for line in section.splitlines() if line.startswith(total))
    assert any(line.startswith(summary.split(" (")[0] + " (") for line in printed), printed[:3]
