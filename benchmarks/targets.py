"""Every target of issue 16 in one run, PASS or FAIL, each figure beside its floor measured in the same run.

Runs, one after another on this machine:

* ``explicit.py``: the adapter's CPU per Get_Attribute_Single (user with one client; user + system
  with eight; what 100 idle sessions add), beside the asyncio echo server's for the same clients
  (the least an asyncio server spends: it stands in for the C stack the targets come from);
* ``io_scale.py``: the class 1 ladder, 10 ms up to 512 connections and 1 ms up to 64, and where
  one adapter process stops;
* ``io_cli.py``: ``cipstack io`` at 1 ms and 0.5 ms against a capture of the same run;
* ``oneshot.py``: ``cipstack get|set|identity`` as whole processes against pycomm3 one-shot scripts.

    python benchmarks/targets.py [--quick] [--minutes M] [--json]

A FAIL is a figure that missed its target on this run: the targets of microseconds come from a C
stack and may be out of reach for Python; the line says how far, and the floor says what the
machine itself allows an asyncio server. The machine's load moves every figure: the load average
and the core count are printed with the table; compare runs made alike.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict
from typing import Any

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import explicit
import io_cli
import io_scale
import oneshot
from io_common import Verdict


def run(quick: bool, minutes: float | None, originators: int) -> tuple[list[Verdict], dict[str, Any]]:
    figures: dict[str, Any] = {"cpus": os.cpu_count(), "load_average_before": os.getloadavg()}
    found: list[Verdict] = []
    started = time.monotonic()

    # Nine rounds of 1 s (five when quick); the idle-sessions pair goes on to 25 rounds (9), which
    # bound the median of its differences at 96 % between the 8th smallest and the 8th largest (the
    # 2nd of each).
    runs = explicit.run_all(seconds=1.0, rounds=5 if quick else 9, warmup=0.2, pycomm3=False,
                            scanners=False, idle_rounds=9 if quick else 25)
    summary = explicit.summarise(runs)
    figures["explicit"] = {"runs": [asdict(r) for r in runs], "summary": summary}
    found += explicit.verdicts(summary)

    steps = io_scale.run_ladder(io_scale.DEFAULT_LADDER, seconds=3.0 if quick else 5.0, originators=originators)
    figures["class1_ladder"] = [asdict(s) for s in steps]
    found += io_scale.verdicts(steps)

    seconds = minutes * 60 if minutes else (4.0 if quick else 10.0)
    io_runs = io_cli.measure(io_cli.DEFAULT_RPIS, seconds)
    figures["cipstack_io"] = io_runs
    found += io_cli.verdicts(io_runs)

    one = oneshot.measure(5 if quick else 9)
    figures["oneshot"] = one
    for name, pair in one["commands"].items():
        found.append(Verdict(f"cipstack {name} one-shot / pycomm3 one-shot (whole processes)", pair["ratio"],
                             oneshot.TARGET_RATIO, "x", note=f"{pair['cipstack_ms']} ms vs {pair['pycomm3_ms']} ms; "
                                                             f"python alone {one['python_ms']} ms"))
    figures["load_average_after"] = os.getloadavg()
    figures["minutes"] = round((time.monotonic() - started) / 60, 1)
    return found, figures


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="shorter runs and fewer rounds (about 2 minutes)")
    parser.add_argument("--minutes", type=float, help="run cipstack io this many minutes per RPI (the issue: 10)")
    parser.add_argument("--originators", type=int, default=2, help="scanner processes of the class 1 ladder")
    parser.add_argument("--json", action="store_true", help="the verdicts and every figure as one JSON object")
    args = parser.parse_args(argv)
    found, figures = run(args.quick, args.minutes, args.originators)
    if args.json:
        print(json.dumps({"verdicts": [{**asdict(v), "line": v.line()} for v in found], "figures": figures}))
    else:
        print("\n".join(v.line() for v in found))
        print(f"{sum(1 for v in found if v.passed)} of {len(found)} targets met; {figures['cpus']} CPUs, load average "
              f"{figures['load_average_before'][0]:.2f} before and {figures['load_average_after'][0]:.2f} after; "
              f"{figures['minutes']} min")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
