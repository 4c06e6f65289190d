"""A default run never takes a device down: the checks that exhaust a device's resources on purpose
(``CheckSpec.stress``) run only with ``--allow-stress``, and every other check stays far below what a
small stack holds. The scripted target here aborts, as stock OpENer's debug build does on an
assertion, at its 21st TCP connection open at once."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from xml.etree import ElementTree

from cipstack.conformance import CHECKS, Verdict, run

from .fake_target import FakeTarget

EDS = Path(__file__).with_name("fake_device.eds")
#: OpENer's default build holds 20 TCP connections; at the 21st it aborts.
OPENER_TCP_CONNECTIONS = 20
NOT_RUN = "needs --allow-stress (this check opens up to 40 TCP connections and sessions at once)"


def conform(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "cipstack", "conform", *args], capture_output=True, text=True,
                          timeout=120, check=False)


def test_the_session_limit_is_declared_a_stress_check() -> None:
    """Declared once, on the check: the runner reads the declaration, never a list of names."""
    assert CHECKS["encap.session_limit"].stress
    assert not [i for i, spec in CHECKS.items() if spec.stress and not spec.stress.startswith("opens ")]


def test_a_default_run_leaves_a_20_connection_device_up() -> None:
    """Every group, every option but --allow-stress (and --allow-motion, no drive here): the target is
    never taken down, and no check holds more than a few TCP connections at once."""
    with FakeTarget(tcp_limit=OPENER_TCP_CONNECTIONS) as target:
        report = run(target.host, target.port, eds=EDS, timeout=2.0, allow_writes=True, allow_reset=True)
        aborted, peak = target.aborted, target.peak_connections
    assert not aborted
    # A few at once: the battery opens one or two, and the fake counts a connection until its serving
    # thread has read the end, a poll later than the close, or longer on a loaded machine.
    assert peak <= 8, peak
    verdicts = {o.id: (o.verdict, o.observed) for o in report}
    assert verdicts["encap.session_limit"] == (Verdict.NOT_RUN, NOT_RUN)
    assert report.failures == [], [(o.name, o.observed) for o in report.failures]
    assert report.options["allow_stress"] is False


def test_allow_stress_runs_it_and_every_report_says_why_not_without(tmp_path: Path) -> None:
    junit = tmp_path / "conform.xml"
    with FakeTarget() as target:  # 12 sessions, then 0x0002: a target that survives the check
        without = conform(target.address, "--only", "encap", "--json", "--junit", str(junit))
        stressed = conform(target.address, "--only", "encap", "--allow-stress", "--json")
    assert (without.returncode, stressed.returncode) == (0, 0), without.stderr + stressed.stderr
    plain, allowed = json.loads(without.stdout), json.loads(stressed.stdout)
    before = next(c for c in plain["checks"] if c["id"] == "encap.session_limit")
    assert (before["verdict"], before["observed"], before["exchanges"]) == ("not run", NOT_RUN, [])
    assert before["stress"] == "opens up to 40 TCP connections and sessions at once"
    assert plain["options"]["allow_stress"] is False and allowed["options"]["allow_stress"] is True
    after = next(c for c in allowed["checks"] if c["id"] == "encap.session_limit")
    assert after["verdict"] == "pass" and after["observed"].startswith("12 sessions granted, limit reached after 12")
    cases = ElementTree.parse(junit).getroot().iter("testcase")
    case = next(c for c in cases if c.get("name") == "encap.session_limit")
    skipped = case.find("skipped")
    assert skipped is not None and skipped.get("message") == NOT_RUN


def test_the_help_and_the_docs_name_the_option() -> None:
    result = subprocess.run([sys.executable, "-m", "cipstack", "conform", "--help"], capture_output=True, text=True,
                            timeout=30, check=True)
    assert "--allow-stress" in result.stdout
    page = (Path(__file__).resolve().parents[2] / "docs" / "conformance.md").read_text()
    assert "--allow-stress" in page
