"""One-shot command line: ``cipstack get HOST 1/1/7`` against a pycomm3 one-shot script.

Starts the adapter emulator on a free loopback port, then runs, interleaved, ``--rounds`` times
each (default 9):

* ``cipstack``: ``python -m cipstack get 127.0.0.1:PORT 1/1/7`` (a whole process: interpreter,
  imports, session, ListIdentity for the profile's names, the request, the close);
* ``pycomm3``: a script that opens a ``CIPDriver``, reads 1/1/7 unconnected and prints it;
* ``python``: ``python -c pass``, the interpreter alone (the floor both pay).

Wall time of each process, medians printed, and the ratio cipstack / pycomm3 against its target
(<= 2.0). Also the number of cipstack modules ``get`` imports. The machine's load moves the
figures: both are measured in the same run, interleaved, and only their ratio is judged.

    python benchmarks/oneshot.py [--rounds N] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from collections.abc import Sequence
from typing import Any

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from io_common import free_port, start_adapter, stop_adapter

TARGET_RATIO = 2.0

PYCOMM3_SCRIPT = """
import sys
from pycomm3 import CIPDriver
with CIPDriver(sys.argv[1]) as driver:
    print(driver.generic_message(service=0x0E, class_code=1, instance=1, attribute=7, connected=False,
                                 route_path=False).value)
"""


#: Bytecode caching as an installed package has it: with PYTHONDONTWRITEBYTECODE set, every run
#: compiles every module it imports again, which is most of a one-shot's time.
ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


def timed(command: list[str]) -> float:
    started = time.perf_counter()
    done = subprocess.run(command, capture_output=True, timeout=60, env=ENV)
    elapsed = time.perf_counter() - started
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} failed: {done.stderr.decode(errors='replace').strip()}")
    return elapsed


def imported_modules(target: str) -> list[str]:
    done = subprocess.run([sys.executable, "-X", "importtime", "-m", "cipstack", "get", target, "1/1/7"],
                          capture_output=True, text=True, timeout=60)
    return [line.rsplit("|", 1)[1].strip() for line in done.stderr.splitlines() if line.startswith("import time:")
            and line.rsplit("|", 1)[1].strip().startswith("cipstack")]


def measure(rounds: int) -> dict[str, Any]:
    port, io_port = free_port(), free_port()
    adapter = start_adapter(port, io_port)
    target = f"127.0.0.1:{port}"
    commands = {
        "cipstack": [sys.executable, "-m", "cipstack", "get", target, "1/1/7"],
        "pycomm3": [sys.executable, "-c", PYCOMM3_SCRIPT, target],
        "python": [sys.executable, "-c", "pass"],
    }
    times: dict[str, list[float]] = {name: [] for name in commands}
    try:
        for command in commands.values():  # warm the page cache once
            timed(command)
        for _ in range(rounds):
            for name, command in commands.items():
                times[name].append(timed(command))
        modules = imported_modules(target)
    finally:
        stop_adapter(adapter)
    medians = {name: statistics.median(values) for name, values in times.items()}
    ratio = medians["cipstack"] / medians["pycomm3"]
    return {"rounds": rounds, **{f"{name}_ms": round(m * 1e3, 1) for name, m in medians.items()},
            "ratio": round(ratio, 2), "target_ratio": TARGET_RATIO, "pass": ratio <= TARGET_RATIO,
            "cipstack_modules": len(modules),
            "eds_or_omron_imported": sorted(m for m in modules
                                            if m.startswith(("cipstack.eds", "cipstack.devices.omron.d")))}


def report(result: dict[str, Any]) -> list[str]:
    verdict = "PASS" if result["pass"] else "FAIL"
    return [f"[{verdict}] cipstack get one-shot {result['cipstack_ms']} ms vs pycomm3 {result['pycomm3_ms']} ms: "
            f"{result['ratio']}x (target <= {result['target_ratio']}x; python alone {result['python_ms']} ms; "
            f"{result['cipstack_modules']} cipstack modules imported)"]


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=9, help="runs of each command (default 9)")
    parser.add_argument("--json", action="store_true", help="one JSON object instead of the text report")
    args = parser.parse_args(argv)
    result = measure(args.rounds)
    print(json.dumps(result) if args.json else "\n".join(report(result)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
