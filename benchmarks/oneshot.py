"""One-shot commands: ``cipstack get|set|identity`` against pycomm3 scripts doing the same.

Starts the adapter emulator (the ACG drive) on a free loopback port, then runs, interleaved,
``--rounds`` times each (default 9), each pair a whole process (interpreter, imports, session,
the request, the close):

* ``get``: ``cipstack get HOST 1/1/7`` against a pycomm3 script that opens a ``CIPDriver`` and
  reads 1/1/7 unconnected with ``generic_message``;
* ``get-decoded``: ``cipstack get HOST 0x2A/1/102`` (the ACG's Acceleration Time: the drive
  identified, the value decoded by its declaration, printed with its unit) against pycomm3 reading
  it with ``data_type=UINT``;
* ``set``: ``cipstack set HOST 0x2A/1/102 50`` against pycomm3 writing it;
* ``identity``: ``cipstack identity HOST`` against ``CIPDriver.list_identity`` (both ListIdentity
  over TCP);
* ``get-code``: ``cipstack get HOST ACC`` (the same attribute by the parameter's code, found in the
  profile's declarations) against the pycomm3 script of ``get-decoded`` (pycomm3 knows no codes);
* ``script-code``: a Python script as the library's guide writes it, ``SyncScanner(HOST)`` (the drive
  identified) and ``.parameter("ACC")`` printed, against the same pycomm3 script;
* ``python``: ``python -c pass``, the interpreter alone (the floor both pay).

Wall time of each process, medians printed, and each ratio cipstack / pycomm3 against its target
(<= 1.2). Also the modules ``cipstack get`` imports, cipstack's and all. The machine's load moves
the figures: both sides are measured in the same run, interleaved, and only their ratio is judged.

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

TARGET_RATIO = 1.2

PYCOMM3 = {
    "get": """
import sys
from pycomm3 import CIPDriver
with CIPDriver(sys.argv[1]) as driver:
    print(driver.generic_message(service=0x0E, class_code=1, instance=1, attribute=7, connected=False,
                                 route_path=False).value)
""",
    "get-decoded": """
import sys
from pycomm3 import CIPDriver, UINT
with CIPDriver(sys.argv[1]) as driver:
    print(driver.generic_message(service=0x0E, class_code=0x2A, instance=1, attribute=102, data_type=UINT,
                                 connected=False, route_path=False).value)
""",
    "set": """
import sys
from pycomm3 import CIPDriver, UINT
with CIPDriver(sys.argv[1]) as driver:
    print(driver.generic_message(service=0x10, class_code=0x2A, instance=1, attribute=102,
                                 request_data=UINT.encode(50), connected=False, route_path=False).error)
""",
    "identity": """
import sys
from pycomm3 import CIPDriver
print(CIPDriver.list_identity(sys.argv[1]))
""",
}

CIPSTACK = {
    "get": ["get", "{target}", "1/1/7"],
    "get-decoded": ["get", "{target}", "0x2A/1/102"],
    "set": ["set", "{target}", "0x2A/1/102", "50"],
    "identity": ["identity", "{target}"],
    "get-code": ["get", "{target}", "ACC"],
}

#: Pairs whose cipstack side is a script of the library (run as ``python -c SCRIPT HOST``).
CIPSTACK_SCRIPTS = {
    "script-code": """
import sys
from cipstack import SyncScanner
with SyncScanner(sys.argv[1]) as drive:
    print(drive.parameter("ACC"))
""",
}

#: The pairs whose pycomm3 side is another pair's script (one command, timed once a round).
PYCOMM3_OF = {"get-code": "get-decoded", "script-code": "get-decoded"}
PAIRS = [*CIPSTACK, *CIPSTACK_SCRIPTS]

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


def imported_modules(arguments: list[str]) -> list[str]:
    """Every module a Python command line imports, in order (``-X importtime``; a module imported by
    ``importlib.import_module`` after its package, a profile's declarations, is not listed)."""
    done = subprocess.run([sys.executable, "-X", "importtime", *arguments],
                          capture_output=True, text=True, timeout=60, env=ENV)
    return [line.rsplit("|", 1)[1].strip() for line in done.stderr.splitlines() if line.startswith("import time:")
            and "|" in line and not line.rstrip().endswith("| package")]


def measure(rounds: int) -> dict[str, Any]:
    port, io_port = free_port(), free_port()
    adapter = start_adapter(port, io_port)
    target = f"127.0.0.1:{port}"
    commands: dict[str, list[str]] = {"python": [sys.executable, "-c", "pass"]}
    for name, arguments in CIPSTACK.items():
        commands[f"cipstack {name}"] = [sys.executable, "-m", "cipstack",
                                        *(a.format(target=target) for a in arguments)]
    for name, script in CIPSTACK_SCRIPTS.items():
        commands[f"cipstack {name}"] = [sys.executable, "-c", script, target]
    for name, script in PYCOMM3.items():
        commands[f"pycomm3 {name}"] = [sys.executable, "-c", script, target]
    times: dict[str, list[float]] = {name: [] for name in commands}
    try:
        for command in commands.values():  # warm the page cache and the bytecode once
            timed(command)
        for _ in range(rounds):
            for name, command in commands.items():
                times[name].append(timed(command))
        modules = imported_modules(["-m", "cipstack", *(a.format(target=target) for a in CIPSTACK["get-decoded"])])
        script_modules = imported_modules(["-c", CIPSTACK_SCRIPTS["script-code"], target])
        python_modules = imported_modules(["-c", "pass"])
    finally:
        stop_adapter(adapter)
    medians = {name: statistics.median(values) for name, values in times.items()}
    pairs = {}
    for name in PAIRS:
        theirs = medians[f"pycomm3 {PYCOMM3_OF.get(name, name)}"]
        ratio = medians[f"cipstack {name}"] / theirs
        pairs[name] = {"cipstack_ms": round(medians[f"cipstack {name}"] * 1e3, 1),
                       "pycomm3_ms": round(theirs * 1e3, 1), "ratio": round(ratio, 2), "pass": ratio <= TARGET_RATIO}
    ours = [m for m in modules if m.startswith("cipstack")]
    return {"rounds": rounds, "python_ms": round(medians["python"] * 1e3, 1), "target_ratio": TARGET_RATIO,
            "commands": pairs, "pass": all(p["pass"] for p in pairs.values()),
            "get_decoded_modules": len(modules), "get_decoded_cipstack_modules": len(ours),
            "python_modules": len(python_modules),
            "eds_or_asyncio_imported": sorted(m for m in modules if m.startswith(("cipstack.eds", "asyncio"))),
            "script_code_modules": len(script_modules),
            "script_code_cipstack_modules": len([m for m in script_modules if m.startswith("cipstack")]),
            "script_code_asyncio_or_device_model": sorted(
                m for m in script_modules if m.startswith(("asyncio", "cipstack.eip.target"))
                or (m.startswith("cipstack.devices.") and not m.startswith("cipstack.devices.declared")))}


def report(result: dict[str, Any]) -> list[str]:
    lines = []
    for name, pair in result["commands"].items():
        verdict = "PASS" if pair["pass"] else "FAIL"
        lines.append(f"[{verdict}] cipstack {name} one-shot {pair['cipstack_ms']} ms vs pycomm3 {pair['pycomm3_ms']} "
                     f"ms: {pair['ratio']}x (target <= {result['target_ratio']}x)")
    lines.append(f"python alone {result['python_ms']} ms; `get` decoded imports {result['get_decoded_modules']} "
                 f"modules, {result['get_decoded_cipstack_modules']} of cipstack (python alone: "
                 f"{result['python_modules']}); EDS or asyncio modules among them: "
                 f"{result['eds_or_asyncio_imported'] or 'none'}")
    lines.append(f"the `script-code` script imports {result['script_code_modules']} modules, "
                 f"{result['script_code_cipstack_modules']} of cipstack; asyncio, target or device model modules "
                 f"among them: {result['script_code_asyncio_or_device_model'] or 'none'}")
    return lines


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
