"""Every exit of ``cipstack io`` after a successful Forward_Open sends a Forward_Close, as tshark sees
it on the wire: Ctrl-C (exit 130, statistics, no traceback), a failure after the open (an
unknown ``--set`` field, exit 2), and Ctrl-C in the library guide's class 1 example. Run in a private
network namespace with the ACG emulator on 127.0.0.2 at the default ports."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path
from typing import Any

import pytest

from .netns import require_namespace, run_in_namespace

# One capture for the whole module (its fixture), and one capturing module at a time (docs/contributing.md).
pytestmark = [pytest.mark.interop, pytest.mark.tshark, pytest.mark.xdist_group("tshark")]

ROOT = Path(__file__).resolve().parents[2]

HELPER = r'''
import json, os, signal, socket, subprocess, sys, time
from pathlib import Path

OUT = Path(sys.argv[1])
PY = sys.executable
ADAPTER = "127.0.0.2"
seen = {}


def listening():
    local = f"{socket.inet_aton(ADAPTER)[::-1].hex().upper()}:{44818:04X}"
    with open("/proc/net/tcp") as lines:
        return any(f[1] == local and f[3] == "0A" for f in (line.split() for line in lines))


def wait_for(predicate, timeout, what):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return
        time.sleep(0.05)
    raise RuntimeError(f"timed out waiting for {what}")


tshark = subprocess.Popen(["tshark", "-i", "lo", "-f", "tcp port 44818", "-w", str(OUT / "capture.pcapng"), "-q"],
                          stdout=subprocess.DEVNULL, stderr=(OUT / "tshark.log").open("wb"))
adapter = None
try:
    wait_for(lambda: "Capturing on" in (OUT / "tshark.log").read_text(errors="replace"), 30, "tshark")
    adapter = subprocess.Popen([PY, "-m", "cipstack", "adapter", "--host", ADAPTER, "--quiet",
                                "--state", str(OUT / "state.json"), "--control", str(OUT / "control.sock")],
                               stdout=(OUT / "adapter.log").open("wb"), stderr=subprocess.STDOUT)
    wait_for(listening, 20, "the adapter")
    io = subprocess.Popen([PY, "-m", "cipstack", "io", ADAPTER, "--output", "21", "--input", "71", "--duration",
                           "60s"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    first = io.stdout.readline()          # the first input line: the connection is open and running
    time.sleep(0.3)                       # the subject: Ctrl-C while the exchange runs, not at its first input
    io.send_signal(signal.SIGINT)
    out, err = io.communicate(timeout=30)
    seen["interrupt"] = {"code": io.returncode, "out": first + out, "err": err}
    failed = subprocess.run([PY, "-m", "cipstack", "io", ADAPTER, "--output", "21", "--input", "71", "--set",
                             "foo=1"], capture_output=True, text=True, timeout=60)
    seen["failure"] = {"code": failed.returncode, "out": failed.stdout, "err": failed.stderr}
    # The library guide's class 1 example, written for 127.0.0.1: here the emulator is on 127.0.0.2.
    example = (OUT / "readme_io.py").read_text()
    (OUT / "readme_io.py").write_text(example.replace('connect("127.0.0.1")', f'connect("{ADAPTER}")'))
    readme = subprocess.Popen([PY, str(OUT / "readme_io.py")], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True)
    first = readme.stdout.readline()      # the first input: the connection is open
    readme.send_signal(signal.SIGINT)
    out, err = readme.communicate(timeout=30)
    seen["readme"] = {"code": readme.returncode, "out": first + out, "err": err}
finally:
    if adapter is not None:
        adapter.send_signal(signal.SIGTERM)
        seen["adapter_exit"] = adapter.wait(10)
    time.sleep(0.5)  # the capturer reads its ring on its own time: no event says it has the last frames
    tshark.send_signal(signal.SIGINT)
    tshark.wait(20)
    (OUT / "seen.json").write_text(json.dumps(seen, indent=1))
'''


def readme_io_example() -> str:
    """The class 1 I/O example of the library guide (the python block after "Class 1 I/O, in an event loop")."""
    text = (ROOT / "docs" / "library.md").read_text()
    start = text.index("```python", text.index("Class 1 I/O, in an event loop")) + len("```python")
    return text[start:text.index("```", start)]


def tshark(capture: Path, display_filter: str, *fields: str) -> list[str]:
    command = ["tshark", "-r", str(capture), "-Y", display_filter, "-T", "fields"]
    for field in fields or ("frame.number",):
        command += ["-e", field]
    result = subprocess.run(command, capture_output=True, text=True, timeout=60, check=False)
    assert result.returncode == 0, result.stderr
    return [line for line in result.stdout.splitlines() if line.strip()]


@pytest.fixture(scope="module")
def capture(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    require_namespace()
    out = tmp_path_factory.mktemp("tshark-close")
    (out / "readme_io.py").write_text(readme_io_example())
    seen = run_in_namespace(out, "close.py", HELPER, timeout=180, env={**os.environ, "PYTHONPATH": str(ROOT)})
    return out / "capture.pcapng", seen


def test_ctrl_c_exits_130_with_statistics_and_no_traceback(capture: tuple[Path, dict[str, Any]]) -> None:
    _, seen = capture
    interrupt = seen["interrupt"]
    assert interrupt["code"] == 130, interrupt
    assert "Traceback" not in interrupt["err"] and "aclose" not in interrupt["err"], interrupt["err"]
    assert "sent " in interrupt["out"] and "received " in interrupt["out"], interrupt["out"]


def test_a_failure_after_the_open_is_one_line(capture: tuple[Path, dict[str, Any]]) -> None:
    _, seen = capture
    failure = seen["failure"]
    assert failure["code"] == 2, failure
    errors = [line for line in failure["err"].splitlines() if line.startswith("cipstack io:")]
    assert len(errors) == 1 and "no field 'foo'" in errors[0] and "run_forward" in errors[0], failure["err"]
    assert "Traceback" not in failure["err"]


def test_ctrl_c_in_the_readme_example_closes_and_exits_130(capture: tuple[Path, dict[str, Any]]) -> None:
    _, seen = capture
    readme = seen["readme"]
    assert readme["code"] == 130, readme
    assert "Traceback" not in readme["err"], readme["err"]
    assert "'sent'" in readme["out"] and "'received_rate_hz'" in readme["out"], readme["out"]


def test_each_open_is_closed_on_the_wire(capture: tuple[Path, dict[str, Any]]) -> None:
    path, _ = capture
    opens = tshark(path, "cip.service == 0x54 && cip.cm.transport_type_trigger", "frame.number",
                   "cip.cm.conn_serial_num")
    opened = tshark(path, "cip.service == 0xd4 && cip.genstat == 0", "frame.number", "cip.cm.conn_serial_num")
    closes = tshark(path, "cip.service == 0x4e", "frame.number", "cip.cm.conn_serial_num")
    closed = tshark(path, "cip.service == 0xce && cip.genstat == 0", "frame.number", "cip.cm.conn_serial_num")
    # cipstack io interrupted, cipstack io failing after the open, the README example interrupted.
    assert len(opens) == 3 and len(opened) == 3, (opens, opened)
    assert len(closes) == 3 and len(closed) == 3, (closes, closed)
    # Each Forward_Close names the connection serial of an open, and follows it.
    for open_line in opened:
        number, serial = open_line.split("\t")
        assert any(c.split("\t")[1] == serial and int(c.split("\t")[0]) > int(number) for c in closes), (opened, closes)
