"""The class 1 benchmarks' own arithmetic and a short run of each: ``fleet.py`` (addresses the fleet
and the scanner agree on at any size, the matrix and its verdicts) and ``io_cost.py`` (CPU per
class 1 packet)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

BENCHMARKS = Path(__file__).resolve().parent.parent / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))

import fleet  # noqa: E402
import io_cost  # noqa: E402

from cipstack.fleet.spec import MAX_DEVICES, parse_addresses  # noqa: E402


@pytest.mark.parametrize("count", [1, 200, 247, 256, 300, MAX_DEVICES])
@pytest.mark.parametrize("block", [0, 3])
def test_the_fleet_is_given_exactly_the_addresses_the_scanner_dials(block: int, count: int) -> None:
    """Across /24 boundaries (.0 and .255 included) and at the fleet's largest size: what the fleet
    reads from its ``--addresses`` is the scanner's list, in its order."""
    dialled = fleet.hosts(block, count)
    assert len(set(dialled)) == count
    assert [str(a) for a in parse_addresses(fleet.fleet_addresses(dialled))] == dialled


def test_cases_of_one_run_never_share_an_address() -> None:
    first = set(fleet.hosts(0, MAX_DEVICES))
    assert not first & set(fleet.hosts(1, MAX_DEVICES))


def case(**changes: Any) -> dict[str, Any]:
    figures = {"tree": "this tree", "devices": 256, "workers": 1, "rpi_ms": 50.0, "late_pct": 0.2, "lost": 0,
               "timeouts": 0, "fleet_cpu_share": 0.5, "fleet_cpu_wait_share": 0.1, "scanner_cpu_share": 0.2,
               "fleet_cpu_us_per_pair": 30.0,
               "scanner_cpu_us_per_pair": 12.0, "start_s": 2.0, "start_ms_per_drive": 4.0, "rss_mb": 100.0,
               "rss_per_device_mb": 0.4}
    figures.update(changes)
    return figures


@pytest.mark.parametrize(("changes", "failed"), [
    ({}, set()),
    ({"late_pct": 1.0}, {"holds"}),
    ({"lost": 1}, {"holds"}),
    ({"timeouts": 1}, {"holds"}),
    ({"late_pct": None}, {"holds"}),
    ({"fleet_cpu_us_per_pair": 35.5}, {"fleet"}),
    ({"fleet_cpu_us_per_pair": 60.0, "devices": 128}, set()),   # the per-pair target is from 256 drives on
    ({"start_ms_per_drive": 5.2}, {"start"}),
])
def test_matrix_verdicts_are_issue_50s_targets(changes: dict[str, Any], failed: set[str]) -> None:
    verdicts = fleet.matrix_verdicts(case(**changes))
    assert {name.split()[0] for name, ok in verdicts if not ok} == failed
    row = fleet.matrix_row(case(**changes))
    assert row.count("[FAIL]") == len(failed) and row.count("[PASS]") == len(verdicts) - len(failed), row


def test_a_case_that_could_not_run_is_a_failed_row_naming_its_tree() -> None:
    """A fleet too loaded to open its connections ends its case, not the matrix (``--against``: each
    row says whose fleet it was)."""
    failed = {"tree": "/tmp/fleet-before", "devices": 1024, "workers": 1, "rpi_ms": 10.0,
              "error": "a scanner could not open its connections"}
    assert not fleet.holds(failed)
    row = fleet.matrix_row(failed)
    assert row.startswith("fleet-before") and "[FAIL] a scanner could not open" in row, row
    assert fleet.matrix_row(case()).startswith("this tree"), fleet.matrix_row(case())


@pytest.mark.parametrize("argument", [["--sizes", "64,x"], ["--sizes", "0"], ["--rpis", "10ms,fast"],
                                      ["--rpi", "-1ms"]])
def test_a_bad_matrix_argument_is_one_line_and_no_traceback(argument: list[str]) -> None:
    result = subprocess.run([sys.executable, str(BENCHMARKS / "fleet.py"), "--matrix", *argument],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2 and "Traceback" not in result.stderr, result.stderr
    assert "error: argument" in result.stderr.splitlines()[-1]


def test_a_small_matrix_runs_each_case_at_its_rpi_and_prints_its_targets() -> None:
    result = subprocess.run([sys.executable, str(BENCHMARKS / "fleet.py"), "--matrix", "--sizes", "2", "--rpis",
                             "20ms,40ms", "--seconds", "1", "--json"], capture_output=True, text=True, timeout=240)
    assert result.returncode in (0, 1), result.stderr
    cases = json.loads(result.stdout.splitlines()[0])["cases"]
    assert [(c["devices"], c["rpi_ms"], c["workers"]) for c in cases] == [(2, 20.0, 1), (2, 40.0, 1)]
    for found in cases:
        assert found["connections"] == 2 and found["t_to_o_packets"] > 0 and found["start_s"] > 0
        assert found["fleet_cpu_us_per_pair"] > 0 and found["scanner_cpu_us_per_pair"] > 0


def test_io_cost_measures_both_processes_per_packet_at_each_rpi() -> None:
    result = subprocess.run([sys.executable, str(BENCHMARKS / "io_cost.py"), "--rpi", "10ms", "--seconds", "1",
                             "--rounds", "1", "--json"], capture_output=True, text=True, timeout=240)
    assert result.returncode == 0, result.stderr
    figures = json.loads(result.stdout)
    [run] = next(iter(figures["runs"].values()))["10ms"]
    assert run["packets"] > 0 and run["target_us"] > 0 and run["originator_us"] > 0
    lines = io_cost.report(figures)
    assert lines[0] == "RPI 10ms:" and "target" in lines[1] and "originator" in lines[1], lines
    assert "OpENer's 183 us" in lines[2], lines


def test_io_cost_refuses_a_directory_that_is_no_checkout(tmp_path: Path) -> None:
    result = subprocess.run([sys.executable, str(BENCHMARKS / "io_cost.py"), "--against", str(tmp_path)],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert result.stderr.strip() == f"io_cost.py: {tmp_path} is not a checkout of cipstack"


def test_io_cost_runs_a_tree_again_with_a_fault_applied() -> None:
    """``--fault``: the tree once fault-free and once with the fault applied through ``cipstack drive``,
    each run by its own label."""
    result = subprocess.run([sys.executable, str(BENCHMARKS / "io_cost.py"), "--rpi", "10ms", "--seconds", "1",
                             "--rounds", "1", "--fault", "drop --every 1000000", "--json"],
                            capture_output=True, text=True, timeout=240)
    assert result.returncode == 0, result.stderr
    figures = json.loads(result.stdout)
    assert [t.partition(" ")[2] for t in figures["trees"]] == ["", "fault drop --every 1000000"]
    for runs in figures["runs"].values():
        [run] = runs["10ms"]
        assert run["packets"] > 0 and run["target_us"] > 0


def test_fault_filter_measures_each_fault_s_filter_per_datagram() -> None:
    result = subprocess.run([sys.executable, str(BENCHMARKS / "fault_filter.py"), "--datagrams", "500", "--rounds",
                             "1", "--json"], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    [medians] = json.loads(result.stdout)["medians"].values()
    assert set(medians) == {"drop --every 1000000", "wrong-size --size 12", "freeze-sequence"}
    assert all(ns > 0 for ns in medians.values())
