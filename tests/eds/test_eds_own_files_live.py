"""Our own EDS files against our own emulators, as a user runs the two tools that compare them:
`cipstack eds check FILE --against HOST` and `cipstack conform HOST --eds FILE`. A file and the
device it describes give no warning in either (`--strict` passes), and a connection the device does
not open is one finding with one severity and one wording in both (`cipstack.eds.refusals`; a note
of `eds check` is n/a in `conform`, which has no notes)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.library_support import adapter_process

#: The families whose EDS files `cipstack eds generate` writes, one model each: the ACG-ET2 (its file
#: declares 36 class 1 connections, of which the card accepts those of the pair CM.24/CM.23 select)
#: and the Omron option boards (CompoNet files: identity, parameters and assemblies).
PROFILES = [("acg",), ("mx2", "--model", "MX2-A2015-E"), ("rx", "--model", "RX-A4055-E")]
#: eds check's severity as conform's verdict.
VERDICT = {"error": "fail", "warning": "warning", "info": "n/a"}


def run(*args: str, timeout: float = 180) -> subprocess.CompletedProcess[str]:
    result = subprocess.run([sys.executable, "-m", "cipstack", *args], capture_output=True, text=True,
                            timeout=timeout, stdin=subprocess.DEVNULL)
    assert "Traceback" not in result.stderr, result.stderr
    return result


def generated(tmp_path: Path, profile: tuple[str, ...]) -> Path:
    result = run("eds", "generate", "--profile", *profile, "-o", str(tmp_path))
    assert result.returncode == 0, result.stderr
    return Path(result.stdout.split()[0])


def both_tools(path: Path, address: str, io_port: int) -> tuple[subprocess.CompletedProcess[str], dict,
                                                                subprocess.CompletedProcess[str], dict]:
    """`eds check --against --strict --json` (its file's record) and `conform --eds --strict --json`."""
    check = run("eds", "check", str(path), "--against", address, "--target-io-port", str(io_port), "--strict",
                "--json")
    record = json.loads(check.stdout.splitlines()[0])
    conform = run("conform", address, "--eds", str(path), "--only", "eds", "--strict", "--json")
    return check, record, conform, json.loads(conform.stdout)


def judged_connections(record: dict, report: dict) -> tuple[dict[str, tuple[str, str]], dict[str, tuple[str, str]]]:
    """Each connection not opened, in each tool: {ConnectionN: (verdict, what is said)}."""
    checked = {}
    for finding in record["findings"]:
        found = re.match(r"(Connection[0-9]+) \([^)]*\): (.*)$", finding["message"])
        if finding["rule"] == "live-connection" and found:
            checked[found[1]] = (VERDICT[finding["severity"]], found[2])
    conformed = {c["subject"]: (c["verdict"], c["observed"]) for c in report["checks"]
                 if c["id"] == "eds.connection.open" and c["verdict"] != "pass" and c["subject"]}
    return checked, conformed


@pytest.mark.parametrize("profile", PROFILES, ids=[p[0] for p in PROFILES])
def test_a_generated_file_and_its_emulator_give_no_warning_in_either_tool(tmp_path: Path,
                                                                          profile: tuple[str, ...]) -> None:
    path = generated(tmp_path, profile)
    with adapter_process("--profile", *profile, "--factory") as (address, io_port):
        check, record, conform, report = both_tools(path, address, io_port)
    assert (check.returncode, record["errors"], record["warnings"]) == (0, 0, 0), check.stdout
    assert conform.returncode == 0, conform.stdout
    assert (report["counts"]["fail"], report["counts"]["warning"]) == (0, 0)
    checked, conformed = judged_connections(record, report)
    assert checked == conformed
    if profile[0] == "acg":
        # The card accepts the factory pair 21/71 (CM.24 = CM.23 = 1): its exclusive owner, input only
        # and listen only open; the other eleven pairs' three connections each are its configuration.
        assert "3 of 36 class 1 connections opened and closed" in record["against"]
        assert len(checked) == 33 and {verdict for verdict, _ in checked.values()} == {"n/a"}
        assert checked["Connection2"][1] == (
            "not accepted in the device's present configuration, which accepts Connection1 (Exclusive Owner "
            "21/71): Forward_Open refused (0x01 (connection failure), extended 0x012A (invalid consuming path)), "
            "assemblies 20, 70 present")
        assert checked["Connection15"][1].startswith("not accepted in the device's present configuration, which "
                                                     "accepts Connection13 (Input Only 71): ")
        assert checked["Connection16"][1].startswith("listen only, and nothing produces input 70 by multicast")
    else:
        assert checked == {} and "0 of 0 class 1 connections opened and closed" in record["against"]


def test_a_file_whose_owners_the_device_accepts_none_of_warns_alike_in_both_tools(tmp_path: Path) -> None:
    """The ACG-ET2's file without the connection of the pair the card serves: none of the file's
    exclusive owners opens, so their refusals are warnings, the same in both tools (and --strict
    fails both); the input-only and listen-only connections of the pair still open."""
    original = generated(tmp_path, ("acg",)).read_text(encoding="latin-1")
    text, removed = re.subn(r"\n    Connection1 =\n.*?\";\n", "\n", original, count=1, flags=re.DOTALL)
    assert removed == 1 and "Exclusive Owner 21/71" not in text
    path = tmp_path / "without_21_71.eds"
    path.write_text(text, encoding="latin-1")
    with adapter_process("--profile", "acg", "--factory") as (address, io_port):
        check, record, conform, report = both_tools(path, address, io_port)
    assert check.returncode == conform.returncode == 1
    assert record["errors"] == 0 and report["counts"]["fail"] == 0
    checked, conformed = judged_connections(record, report)
    assert checked == conformed
    warned = sorted(name for name, (verdict, _) in checked.items() if verdict == "warning")
    assert warned == sorted(f"Connection{n}" for n in range(2, 13))
    assert record["warnings"] == report["counts"]["warning"] == 11
    assert checked["Connection2"][1] == (
        "Forward_Open refused by the device (0x01 (connection failure), extended 0x012A (invalid consuming path)); "
        "the device has assemblies 20, 70 but does not offer this path now")
