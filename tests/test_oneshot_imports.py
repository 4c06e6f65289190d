"""The import budget of a one-shot command (issue 40): ``cipstack get|set|identity`` loads the
blocking originator and the profile's compact declarations, never asyncio, the device model, the
EDS tool or another command's module; by a parameter's code (``get HOST ACC``) too. The library
likewise (issue 54): ``SyncScanner`` reading and decoding an attribute, by path or by code, loads
no asyncio, nothing of the target and nothing of ``devices/`` but the generated declarations. A
whole-process timing against pycomm3 is ``benchmarks/oneshot.py``'s job (no timing asserts here);
the module count is what this guards."""

from __future__ import annotations

import functools
import json
import re
import socket
import subprocess
import sys
import time
from collections.abc import Iterator

import pytest

from tests.fakes import ScriptedTarget
from tests.ports import free_port
from tests.test_cli import adapter_process  # noqa: F401 - the fixture: the emulator in a process of its own

#: Runs the command line as ``python -m cipstack`` does, then prints the modules it loaded.
SCRIPT = """
import json, runpy, sys
sys.argv = ["cipstack", *sys.argv[1:]]
try:
    runpy.run_module("cipstack", run_name="__main__", alter_sys=True)
except SystemExit as done:
    status = done.code
print("MODULES " + json.dumps({"status": status, "modules": sorted(sys.modules)}))
"""

#: The most cipstack modules each command may load: today's count. A one-shot line is read without
#: argparse, a standard attribute decodes by the standard objects' compact data (``objects/declared.py``)
#: and a profile's by its own (``devices/declared/``).
BUDGET = {"get-standard": 28, "get-decoded": 33, "set": 33, "identity": 21, "get-code": 34, "set-code": 34}
#: Never on the one-shot path: another command's modules, the device model, the objects that serve the
#: standard classes, the command-line grammar, and what only they or a name lookup import; ``logging``
#: too, while nothing is logged (``cipstack.logs``); and ``dataclasses`` (with the ``inspect`` it
#: imports): making a dataclass compiles its methods, the records on this path are named tuples.
FORBIDDEN = ("asyncio", "logging", "dataclasses", "inspect", "construct", "cipstack.eip.originator.asyncio_client",
             "cipstack.devices.acg", "cipstack.devices.omron", "cipstack.devices.profiles", "cipstack.eds",
             "cipstack.assemblies.schema", "cipstack.cli.io", "cipstack.cli.drive", "cipstack.control",
             "cipstack.sync_io", "cipstack.objects.identity", "cipstack.objects.tcpip", "cipstack.objects.assembly",
             "cipstack.cip.router", "cipstack.cli.parser", "cipstack.cli.help_texts", "argparse", "gettext",
             "decimal", "encodings.idna",
             # CIP Security is for who asks for it: a plain one-shot loads neither TLS nor X.509 (issue 48).
             "ssl", "cipstack.security", "cryptography")

COMMANDS = {"get-standard": ["get", "{target}", "1/1/7"], "get-decoded": ["get", "{target}", "0x2A/1/102"],
            "set": ["set", "{target}", "0x2A/1/102", "50"], "identity": ["identity", "{target}"],
            # By a parameter's code: found, range-checked and decoded by the compact declarations.
            "get-code": ["get", "{target}", "ACC"], "set-code": ["set", "{target}", "ACC", "5.0"]}


@functools.cache
def interpreter_modules() -> frozenset[str]:
    """The modules loaded by the interpreter and the lines of ``SCRIPT`` around the command."""
    script = "import json, runpy, sys; print(json.dumps(sorted(sys.modules)))"
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60, check=True)
    return frozenset(json.loads(done.stdout))


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_a_one_shot_command_loads_little(name: str, adapter_process: tuple[str, subprocess.Popen[str]]  # noqa: F811
                                         ) -> None:
    address, _ = adapter_process
    arguments = [a.format(target=address) for a in COMMANDS[name]]
    done = subprocess.run([sys.executable, "-c", SCRIPT, *arguments], capture_output=True, text=True, timeout=60)
    report = json.loads(done.stdout.rsplit("MODULES ", 1)[1])
    assert report["status"] == 0, done.stderr
    modules = report["modules"]
    loaded = [m for m in modules if m.split(".")[0] == "cipstack"]
    # What the interpreter itself loads here (a site .pth may import anything) is not the command's.
    added = set(modules) - interpreter_modules()
    assert [m for m in sorted(added) if any(m == f or m.startswith(f + ".") for f in FORBIDDEN)] == []
    assert len(loaded) <= BUDGET[name], loaded
    assert "cipstack.eip.originator.blocking" in loaded or name == "identity"


#: A script as a user writes it: connect (the device identified), read by path (a profile's attribute
#: and a standard one), by code, write by code and have a value out of range refused, then the
#: modules it loaded. ``{target}``, ``{path}``, ``{code}``, ``{value}``, ``{too_big}``: the test's.
LIBRARY_SCRIPT = """
import json, sys
from cipstack import SyncScanner
from cipstack.parameter_codes import ParameterValueError
with SyncScanner("{target}") as drive:
    read = [str(drive.read({path})), str(drive.read(1, 1, 7)), str(drive.parameter("{code}")),
            str(drive.set_parameter("{code}", {value})), drive.get_attribute_single({path}).spec.name]
    try:
        drive.set_parameter("{code}", {too_big})
        refused = None
    except ParameterValueError as exc:
        refused = str(exc)
    profile = drive.catalog.profile
print("MODULES " + json.dumps({{"read": read, "refused": refused, "profile": profile, "modules": sorted(sys.modules)}}))
"""

#: What the library never loads to decode: the event loop, the target side, the device model (of
#: ``devices/``, only the generated declarations), the EDS tool, the objects that serve the standard classes.
LIBRARY_FORBIDDEN = ("asyncio", "cipstack.eip.target", "cipstack.eds", "cipstack.assemblies", "cipstack.sync_io",
                     "cipstack.objects.identity", "cipstack.objects.tcpip", "cipstack.objects.assembly",
                     "cipstack.cip.router", "cipstack.eip.originator.asyncio_client",
                     "ssl", "cipstack.security", "cryptography")


@pytest.fixture(scope="module")
def mx2_process() -> Iterator[str]:
    """An Omron MX2 emulator in a process of its own."""
    port = free_port()
    process = subprocess.Popen([sys.executable, "-m", "cipstack", "adapter", "--host", "127.0.0.1", "--port",
                                str(port), "--io-port", "0", "--profile", "mx2"], stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)
    try:
        wait_for_port("127.0.0.1", port, process)
        yield f"127.0.0.1:{port}"
    finally:
        process.terminate()
        process.wait(10)


def wait_for_port(host: str, port: int, process: subprocess.Popen[bytes]) -> None:
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and process.poll() is None:
        try:
            socket.create_connection((host, port), timeout=0.2).close()
            return
        except OSError:
            time.sleep(0.05)
    pytest.fail("the emulator did not start")


#: Per profile: an attribute path, a parameter code, a value in its unit, one past its declared range, and
#: the generated declarations it decodes by.
LIBRARY_CASES = {
    "acg": ("0x2A, 1, 102", "ACC", 5.0, 7000, "Acceleration Time", "cipstack.devices.declared.acg"),
    "mx2": ("0x65, 19, 138", "F002", 10.0, -1, "F002 Acceleration time 1", "cipstack.devices.declared.mx2"),
}


@pytest.mark.parametrize("profile", sorted(LIBRARY_CASES))
def test_the_library_decodes_by_path_and_by_code_without_the_device_model(profile: str,
                                                                          request: pytest.FixtureRequest) -> None:
    # Each profile's emulator: the ACG's of the command tests, the MX2's of its own.
    target = request.getfixturevalue("adapter_process")[0] if profile == "acg" else \
        request.getfixturevalue("mx2_process")
    path, code, value, too_big, name, declared = LIBRARY_CASES[profile]
    script = LIBRARY_SCRIPT.format(target=target, path=path, code=code, value=value, too_big=too_big)
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout.rsplit("MODULES ", 1)[1])
    assert report["profile"] == profile
    assert report["read"][4] == name
    assert report["refused"] is not None and report["refused"].startswith(code), report
    modules = set(report["modules"])
    added = modules - interpreter_modules()
    assert sorted(m for m in added if any(m == f or m.startswith(f + ".") for f in LIBRARY_FORBIDDEN)) == []
    # Of ``devices/``, the generated declarations alone (and the package that holds them).
    assert sorted(m for m in modules if m.startswith("cipstack.devices")) == \
        ["cipstack.devices", "cipstack.devices.declared", declared]
    assert "cipstack.eip.originator.blocking" in modules


def test_the_blocking_scanner_imports_no_asyncio() -> None:
    script = "import sys, cipstack.scanner; print('asyncio' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True,
                          timeout=60).stdout.strip() == "False"


@pytest.mark.parametrize("level", ["DEBUG", "INFO"])
def test_a_one_shot_command_that_logs_loads_logging_configured_as_asked(level: str) -> None:
    """A target that answers no Identity request: the scanner logs that it could not identify it (a
    DEBUG record), the moment ``logging`` is loaded and configured with the level and format the line
    gives, as every other command has them from the start."""
    with ScriptedTarget() as target:
        done = subprocess.run([sys.executable, "-m", "cipstack", "--log-level", level, "get", target.address,
                               "0x2A/1/102"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 1 and done.stdout == "", done.stderr
    lines = done.stderr.splitlines()
    assert lines[-1] == "cipstack get: error status service 0x0E: 0x08 (service not supported)", lines
    logged = [line for line in lines if " cipstack.scanner: " in line]
    if level == "DEBUG":
        assert re.fullmatch(r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d,\d{3} DEBUG cipstack\.scanner: Identity attribute 1: "
                            r".*0x08.*", logged[0]), lines
    else:
        assert logged == [], lines
