"""``cipstack io`` on short RPIs, checked against a capture of the same run.

Writes the ACG-ET2's EDS (``cipstack eds generate``) with its RPI range opened down to 0.5 ms (the
drive itself accepts 1 ms), serves it (``cipstack adapter --eds``) on free loopback ports, starts
``dumpcap`` on the loopback interface for the class 1 port, and runs, for each RPI (default 1 ms and
0.5 ms), ``cipstack io HOST --output 21 --input 71 --rpi RPI --duration D --print summary --json
--timeout-multiplier 3`` as a user would (3: a 32 ms watchdog at 1 ms, 16 ms at 0.5 ms; the default
2 allows half that, less than a loaded machine may stall a process; ``--timeout-multiplier`` here
changes it). Then reads the capture with ``tshark`` and computes, for each direction, the share
of intervals within half an RPI of the RPI; beside it the share ``cipstack io`` measured itself
(T->O, where its packets arrive). Targets (issue 16): no timeout; >= 99 % of the intervals within
+-0.5 RPI, both directions, on the wire; the command's own figure agrees with the capture's (within
one percentage point).

    python benchmarks/io_cli.py [--seconds 10] [--minutes M] [--rpi 1ms --rpi 0.5ms] [--json]

``--minutes`` runs each RPI for that many minutes instead (the issue asks for 10 without a timeout).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from io_common import Verdict, can_capture, class1_capture, free_port, start_adapter, stop_adapter, wire_times, within

SHARE_TARGET = 99.0
AGREEMENT_POINTS = 1.0
DEFAULT_RPIS = ("1ms", "0.5ms")
#: Where the generated EDS gives its RPI parameter's range (minimum, maximum, default), in microseconds.
RPI_RANGE = re.compile(r"^(\s+)1000, 10000000, 10000,", re.MULTILINE)


def fast_eds(directory: Path) -> Path:
    """The ACG-ET2 EDS with its RPI minimum at 500 us."""
    subprocess.run([sys.executable, "-m", "cipstack", "eds", "generate", "--profile", "acg", "-o", str(directory)],
                   check=True, capture_output=True)
    source = next(directory.glob("*.eds"))
    text, count = RPI_RANGE.subn(r"\g<1>500, 10000000, 10000,", source.read_bytes().decode("ascii"))
    if count != 1:
        raise RuntimeError(f"{source}: the RPI range to lower was not found")
    target = directory / "fast.eds"
    target.write_bytes(text.encode("ascii"))
    return target


def parse_rpi(text: str) -> float:
    value = text.strip().lower()
    if value.endswith("ms"):
        return float(value[:-2]) / 1e3
    if value.endswith("us"):
        return float(value[:-2]) / 1e6
    return float(value.rstrip("s"))


#: The watchdog's timeout multiplier ``cipstack io`` is given: 3 is 32 ms at 1 ms and 16 ms at 0.5 ms (the
#: command's default, 2, allows 16 ms and 8 ms, less than a loaded machine may stall a process).
TIMEOUT_MULTIPLIER = 3


def run_one(port: int, io_port: int, rpi_text: str, seconds: float, workdir: Path,
            multiplier: int = TIMEOUT_MULTIPLIER) -> dict[str, Any]:
    rpi = parse_rpi(rpi_text)
    capture = workdir / f"io-{rpi_text}.pcapng"
    with class1_capture(io_port, capture):
        done = subprocess.run([sys.executable, "-m", "cipstack", "io", f"127.0.0.1:{port}", "--output", "21",
                               "--input", "71", "--rpi", rpi_text, "--duration", f"{seconds}s", "--print", "summary",
                               "--json", "--target-io-port", str(io_port), "--timeout-multiplier", str(multiplier)],
                              capture_output=True, text=True, timeout=seconds + 60)
    summary: dict[str, Any] = {}
    for line in done.stdout.splitlines():
        if line.startswith('{"summary"'):
            summary = json.loads(line)["summary"]
    ot, to = wire_times(capture, io_port)
    ot_count, ot_share = within(ot, rpi)
    to_count, to_share = within(to, rpi)
    capture.unlink(missing_ok=True)
    return {"rpi_ms": rpi * 1e3, "seconds": seconds, "exit_status": done.returncode, "multiplier": multiplier,
            "stderr": done.stderr.strip().splitlines()[-3:],
            "timed_out": done.returncode != 0 or not summary,
            "io_t_to_o_within_pct": summary.get("within_half_api_pct"), "io_received": summary.get("received"),
            "io_lost": summary.get("lost"), "io_interval_max_ms": summary.get("interval_max_ms"),
            "wire_o_to_t_intervals": ot_count, "wire_o_to_t_within_pct": ot_share,
            "wire_t_to_o_intervals": to_count, "wire_t_to_o_within_pct": to_share}


def measure(rpis: Sequence[str], seconds: float, multiplier: int = TIMEOUT_MULTIPLIER) -> list[dict[str, Any]]:
    if not can_capture():
        raise RuntimeError("dumpcap and tshark are needed (Wireshark's command-line tools)")
    with tempfile.TemporaryDirectory() as tmp:
        workdir = Path(tmp)
        os.chmod(workdir, 0o755)  # dumpcap may run as another user
        eds = fast_eds(workdir)
        port, io_port = free_port(), free_port()
        adapter = start_adapter(port, io_port, "--eds", str(eds), state=False)
        try:
            return [run_one(port, io_port, rpi, seconds, workdir, multiplier) for rpi in rpis]
        finally:
            stop_adapter(adapter)


def verdicts(results: Sequence[dict[str, Any]]) -> list[Verdict]:
    found = []
    for r in results:
        wire = [r["wire_o_to_t_within_pct"], r["wire_t_to_o_within_pct"]]
        worst = None if None in wire else min(wire)
        agree = (r["io_t_to_o_within_pct"] is not None and r["wire_t_to_o_within_pct"] is not None
                 and abs(r["io_t_to_o_within_pct"] - r["wire_t_to_o_within_pct"]) <= AGREEMENT_POINTS)
        passed = worst is not None and worst >= SHARE_TARGET and not r["timed_out"] and agree
        note = (f"wire O->T {r['wire_o_to_t_within_pct']} %, T->O {r['wire_t_to_o_within_pct']} %; cipstack io's own "
                f"T->O {r['io_t_to_o_within_pct']} % ({'agrees' if agree else 'DISAGREES'} within "
                f"{AGREEMENT_POINTS:g} point); {'TIMED OUT, ' if r['timed_out'] else 'no timeout, '}"
                f"{r['io_lost']} lost, longest T->O interval {r['io_interval_max_ms']} ms, {r['seconds']:g} s, "
                f"--timeout-multiplier {r['multiplier']}")
        if r["timed_out"] and r["stderr"]:
            note += f"; it said: {r['stderr'][-1]}"
        found.append(Verdict(f"cipstack io at RPI {r['rpi_ms']:g} ms, worst direction within +-0.5 RPI",
                             worst, SHARE_TARGET, "%", higher_is_better=True, passed=passed, note=note))
    return found


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="run time of each RPI (default 10)")
    parser.add_argument("--minutes", type=float, help="run time of each RPI in minutes (overrides --seconds)")
    parser.add_argument("--rpi", action="append", help="RPI to run, repeatable (default 1ms and 0.5ms)")
    parser.add_argument("--timeout-multiplier", type=int, default=TIMEOUT_MULTIPLIER,
                        help=f"cipstack io's --timeout-multiplier (default {TIMEOUT_MULTIPLIER})")
    parser.add_argument("--json", action="store_true", help="one JSON object instead of the text report")
    args = parser.parse_args(argv)
    seconds = args.minutes * 60 if args.minutes else args.seconds
    results = measure(args.rpi or DEFAULT_RPIS, seconds, args.timeout_multiplier)
    if args.json:
        print(json.dumps({"runs": results, "load_average": os.getloadavg(), "cpus": os.cpu_count()}))
        return 0
    for verdict in verdicts(results):
        print(verdict.line())
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
