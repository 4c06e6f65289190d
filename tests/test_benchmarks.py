"""The benchmarks' own arithmetic and the quickest of them, so that the figures the README gives
come from code the suite runs: the paired idle-sessions verdict of ``explicit.py`` and
``explicit_core.py`` end to end (a short run)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parent.parent / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))

import explicit  # noqa: E402


@pytest.mark.parametrize(("n", "low_rank", "confidence"), [(3, 1, 0.75), (5, 1, 0.9375), (9, 2, 0.9609375),
                                                           (15, 4, 0.96484375)])
def test_median_bounds_are_the_sign_test_ranks(n: int, low_rank: int, confidence: float) -> None:
    """The k-th smallest and k-th largest of n values hold the median with 1 - 2 P(Bin(n, 1/2) < k),
    k the largest rank that keeps at least 95 % (or 1 when n is too small for it)."""
    values = [float(v) for v in range(n, 0, -1)]  # unsorted on purpose
    assert explicit.median_bounds(values) == (float(low_rank), float(n + 1 - low_rank), confidence)


def idle_summary(idle: list[float], raw: list[float]) -> dict[str, object]:
    def run(client: str, server: str, rounds: list[float]) -> explicit.Run:
        return explicit.Run(client, server, 1, 1.0, 1.0, sorted(rounds)[len(rounds) // 2], 0.0,
                            server_cpu_rounds_us=tuple(rounds))

    runs = [run("raw", "adapter", raw), run("raw +100 idle", "adapter", idle),
            run("raw", "echo-asyncio", raw), run("raw +100 idle", "echo-asyncio", raw),
            run("raw", "echo-socket", raw)]
    return explicit.summarise(runs)


@pytest.mark.parametrize(("added", "verdict"), [
    ([0.5, -0.3, 1.0, 0.2, 1.9], "PASS"),           # every paired difference within 2 µs
    ([3.0, 2.5, 4.0, 2.2, 5.0], "FAIL"),            # even the smallest above it
    ([0.5, -0.3, 1.0, 0.2, 9.0], "INCONCLUSIVE"),   # the bounds straddle the target
])
def test_idle_sessions_verdict_is_taken_on_paired_rounds(added: list[float], verdict: str) -> None:
    raw = [40.0, 55.0, 38.0, 61.0, 45.0]  # the machine's load moves both halves of each pair alike
    summary = idle_summary([r + a for r, a in zip(raw, added, strict=True)], raw)
    line = explicit.idle_verdict(summary).line()
    assert summary["adapter_idle_added_us"] == pytest.approx(sorted(added)[2])
    assert line.startswith("[PASS]" if verdict == "PASS" else "[FAIL]"), line
    assert ("INCONCLUSIVE" in line) == (verdict == "INCONCLUSIVE"), line


@pytest.mark.parametrize("rounds", [1, 3])
def test_too_few_idle_rounds_give_no_verdict(rounds: int) -> None:
    """One or three paired rounds bound the median at 0 % or 75 %: however small the differences,
    the run cannot tell (INCONCLUSIVE, a FAIL), as 5 rounds (94 %) can."""
    raw = [40.0, 55.0, 38.0][:rounds]
    line = explicit.idle_verdict(idle_summary([r + 0.1 for r in raw], raw)).line()
    assert line.startswith("[FAIL]") and "too few rounds to bound the median: INCONCLUSIVE" in line, line


@pytest.mark.parametrize(("options", "mode"), [([], "the same frame each time"),
                                             (["--new-context"], "two sender contexts in turn")])
def test_explicit_core_serves_the_raw_clients_request_and_prints_its_cost(options: list[str], mode: str) -> None:
    result = subprocess.run([sys.executable, str(BENCHMARKS / "explicit_core.py"), "--requests", "500",
                             "--rounds", "2", *options], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("adapter work per Get_Attribute_Single, no sockets: "), result.stdout
    assert f"(best of 2 rounds of 500; {mode})" in result.stdout


def test_the_idle_sessions_pair_is_measured_back_to_back_in_either_order_by_turns() -> None:
    """``run_all``'s order: every client each round, the raw client and the same with idle sessions
    side by side (one or the other first, by turns), then that pair alone up to ``idle_rounds``."""
    def bench(name: str) -> explicit.Bench:
        return explicit.Bench(name, "adapter", 0, lambda n: None, lambda: None)

    scanner, raw, idle, many = bench("scanner"), bench("raw"), bench("raw +100 idle"), bench("raw x8")
    order = [b.client for b in explicit.schedule([scanner, raw, idle, many], [raw, idle], rounds=2, idle_rounds=4)]
    assert order == ["scanner", "raw", "raw +100 idle", "raw x8",
                     "scanner", "raw +100 idle", "raw", "raw x8",
                     "raw", "raw +100 idle",
                     "raw +100 idle", "raw"]
    # Without extra rounds, as many runs of the pair as of the others.
    assert [b.client for b in explicit.schedule([raw, idle, many], [raw, idle], rounds=1, idle_rounds=0)] == [
        "raw", "raw +100 idle", "raw x8"]


def test_user_cpu_is_judged_at_one_client_and_at_eight() -> None:
    """The issue gives the user CPU target "from 21.5 at one client, 12.5 at eight": a verdict each,
    beside the echo server's figure for the same clients; the eight clients' total has its own."""
    def run(client: str, server: str, user: float, system: float) -> explicit.Run:
        return explicit.Run(client, server, 1, 1.0, 1.0, user + system, 0.0, user, system,
                            server_cpu_rounds_us=(user + system,))

    runs = [run("raw", "adapter", 12.0, 20.0), run("raw x8", "adapter", 4.5, 7.0),
            run("raw", "echo-asyncio", 8.0, 20.0), run("raw x8", "echo-asyncio", 2.5, 6.0),
            run("raw", "echo-socket", 2.0, 20.0)]
    lines = {v.name: v.line() for v in explicit.verdicts(explicit.summarise(runs))}
    assert lines["adapter user CPU per Get_Attribute_Single, 1 client"].startswith("[FAIL]")
    eight = lines["adapter user CPU per Get_Attribute_Single, 8 clients"]
    assert eight.startswith("[PASS]") and "4.5 µs" in eight and "echo floor 2.5 µs" in eight, eight
    assert lines["adapter CPU per request, 8 clients (user + system)"].startswith("[PASS]")


@pytest.mark.parametrize("options", [[], ["--no-pin"]])
def test_a_class1_ladder_step_measures_both_ways_where_it_was_placed(options: list[str]) -> None:
    """``io_scale.py`` as its README runs it, one small step: the originators' windows are read
    ("measuring", then "measured"), both directions counted, and the step says whether the adapter
    and the originators had a CPU each (they do by default when there are two)."""
    import json
    import os

    result = subprocess.run([sys.executable, str(BENCHMARKS / "io_scale.py"), "--ladder", "10ms:4", "--seconds", "1",
                             "--json", *options], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    [step] = json.loads(result.stdout)["steps"]
    assert step["connections"] == 4 and step["originators"] == 2
    assert step["t_to_o_per_s"] > 0 and step["o_to_t_per_s"] > 0 and step["adapter_cpu"] > 0
    assert step["pinned"] is (not options and len(os.sched_getaffinity(0)) >= 2)


def test_rtu_prints_requests_per_second_against_the_lines_limit() -> None:
    """``rtu.py``: a short run at both baud rates; the ratio to the line's limit is below the most a
    drive on a real line can reach (the frame-end silence and CM.5 hold every exchange), and above 0."""
    result = subprocess.run([sys.executable, str(BENCHMARKS / "rtu.py"), "--requests", "10", "--json"],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    runs = json.loads(result.stdout)
    assert [r["baud"] for r in runs] == [9600, 115200]
    for run in runs:
        assert run["line_limit_per_s"] == pytest.approx(run["baud"] / 10 / 15)
        assert 0 < run["ratio"] <= run["ceiling_per_s"] / run["line_limit_per_s"] * 1.02
    text = subprocess.run([sys.executable, str(BENCHMARKS / "rtu.py"), "--requests", "5"], capture_output=True,
                          text=True, timeout=120)
    assert text.returncode == 0, text.stderr
    assert "    9,600 bps: " in text.stdout and "  115,200 bps: " in text.stdout and "ratio 0." in text.stdout


def test_dtls_io_holds_both_ways_and_compares_the_adapters_cpu() -> None:
    """``dtls_io.py``, one short round with few connections: both holds open every connection, count
    packets both ways and the adapter's CPU, and give a ratio (not judged here: a benchmark's figure)."""
    import json

    pytest.importorskip("OpenSSL", reason="the security extra (pyOpenSSL) is not installed")
    result = subprocess.run([sys.executable, str(BENCHMARKS / "dtls_io.py"), "--connections", "4", "--seconds", "1",
                             "--rounds", "1", "--json"], capture_output=True, text=True, timeout=120)
    [round_] = json.loads(result.stdout)["rounds"]
    for way in ("plain", "dtls"):
        assert round_[way]["opened"] == 4 and round_[way]["sent"] > 0 and round_[way]["received"] > 0, result.stderr
        # 4 connections at 10 ms for 1 s: about 400 packets each way, whatever the machine's load.
        assert round_[way]["sent"] >= 200


def test_psk_tls_reads_and_handshakes_both_ways() -> None:
    """``psk_tls.py``, one short round: both adapters answer every read and handshake, and the ratios
    are given (not judged here: a benchmark's figure)."""
    import json

    pytest.importorskip("OpenSSL", reason="the security extra (pyOpenSSL) is not installed")
    result = subprocess.run([sys.executable, str(BENCHMARKS / "psk_tls.py"), "--reads", "200", "--handshakes", "10",
                             "--rounds", "1", "--json"], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    [round_] = json.loads(result.stdout)["rounds"]
    for way in ("certificates", "psk"):
        assert set(round_[way]) == {"cpu_per_read_us", "cpu_per_handshake_us"}
    assert {"ratio_cpu_per_read_us", "ratio_cpu_per_handshake_us"} <= set(round_)


def test_configured_tls_reads_and_handshakes_both_ways() -> None:
    """``configured_tls.py``, one short round: the device configured over the network and the folder's
    both answer every read and handshake, and the ratios are given (not judged here)."""
    pytest.importorskip("OpenSSL", reason="the security extra (pyOpenSSL) is not installed")
    result = subprocess.run([sys.executable, str(BENCHMARKS / "configured_tls.py"), "--reads", "200",
                             "--handshakes", "10", "--rounds", "1", "--json"], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0, result.stderr
    [round_] = json.loads(result.stdout)["rounds"]
    for way in ("folder", "configured"):
        assert set(round_[way]) == {"cpu_per_read_us", "cpu_per_handshake_us"}
    assert {"ratio_cpu_per_read_us", "ratio_cpu_per_handshake_us"} <= set(round_)


def test_tls_benchmark_measures_both_ports_handshakes_and_idle_sessions() -> None:
    """``tls.py``, one short round: the adapter's CPU per request on plain TCP and over TLS (with and
    without idle TLS sessions beside it), and per connection with and without a TLS handshake, both
    TLS versions, on the P-256 certificate ``security init`` makes; a verdict for each target, and
    the exit status says whether all were met (the figures are not judged here: a benchmark's)."""
    pytest.importorskip("cryptography", reason="the security extra (cryptography) is not installed")
    result = subprocess.run([sys.executable, str(BENCHMARKS / "tls.py"), "--seconds", "0.2", "--rounds", "1",
                             "--warmup", "0.05", "--handshakes", "5", "--idle", "3", "--json"],
                            capture_output=True, text=True, timeout=180)
    summary = json.loads(result.stdout)
    assert result.returncode == (0 if summary["passed"] else 1), result.stderr
    assert summary["certificate"] == "ECDSA secp256r1"
    assert set(summary["cpu_per_request_us"]) == {"plain", "tls", "tls idle", "tls +idle"}
    assert all(cpu > 0 for cpu in summary["cpu_per_request_us"].values())
    assert [(h["kind"], h["count"], h["version"]) for h in summary["handshakes"]] == [
        ("plain TCP", 5, "-"), ("TLS", 5, "TLSv1.3"), ("TLS 1.2", 5, "TLSv1.2")]
    assert [v["target"] for v in summary["verdicts"]] == [1.5, 20.0, 20.0, 1.1]
    assert all(isinstance(v["passed"], bool) for v in summary["verdicts"])


@pytest.mark.parametrize(("ratios", "verdict"), [
    ([1.02, 0.97, 1.05, 0.99, 1.08], "PASS"),    # every paired ratio within 1.10
    ([1.30, 1.25, 1.40, 1.22, 1.50], "FAIL"),    # even the smallest above it
    ([1.02, 0.97, 1.05, 0.99, 1.60], "INCONCLUSIVE"),   # the bounds straddle the target
    ([1.00, 1.01, 1.02], "INCONCLUSIVE"),        # three rounds bound the median at 75 %: too few
])
def test_tls_idle_sessions_verdict_is_taken_on_paired_ratios(ratios: list[float], verdict: str) -> None:
    import tls

    low, high, confidence = explicit.median_bounds(ratios)
    summary = {"idle_ratio": sorted(ratios)[len(ratios) // 2], "idle_ratio_rounds": ratios, "idle_ratio_low": low,
               "idle_ratio_high": high, "idle_ratio_confidence": confidence,
               "cpu_per_request_us": {"tls +idle": 55.0, "tls idle": 54.0}}
    line = tls.idle_verdict(summary).line()
    assert line.startswith("[PASS]" if verdict == "PASS" else "[FAIL]"), line
    assert ("INCONCLUSIVE" in line) == (verdict == "INCONCLUSIVE"), line
