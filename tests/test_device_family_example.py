"""examples/device-family, a device family in a distribution of its own, as a user installs it: cipstack
and the example pip-installed (editable, no dependencies, no build isolation: nothing is downloaded) into a
throwaway venv, then every surface, each a process of that venv: `cipstack models`, `cipstack adapter
--profile dio` with `identity`, `get`, `set` and `io` against the block, `cipstack eds generate`, the
front panel (its HTTP API, and its page in a headless Chromium where there is one), `cipstack drive`, a
fleet of blocks, `cipstack conform`, and the pytest plugin in an inner pytest run. One venv for the
module, one adapter process per surface at most."""

from __future__ import annotations

import contextlib
import importlib.util
import json
import os
import socket
import subprocess
import sys
import sysconfig
import textwrap
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.ports import free_port
from tests.waiting import wait_for

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "device-family"

pytestmark = pytest.mark.skipif(importlib.util.find_spec("hatchling") is None,
                                reason="hatchling (the test extra) builds the editable installs offline")


@pytest.fixture(scope="module")
def venv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A venv with cipstack from this tree and the example installed by pip. The running interpreter's
    site-packages are on its path (a ``.pth``) for cipstack's dependencies and the build backend, whose
    ``.pth`` files it does not read: the cipstack installed there does not hide this one."""
    where = tmp_path_factory.mktemp("family") / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(where)], check=True, timeout=120)
    python = where / "bin" / "python"
    purelib = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                             capture_output=True, text=True, check=True, timeout=60).stdout.strip()
    ours = sorted({sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"],
                   *(p for p in sys.path if p.endswith("site-packages"))})
    Path(purelib, "zz_parent_site.pth").write_text("".join(f"{p}\n" for p in ours), encoding="utf-8")
    installed = subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install", "--quiet",
                                "--no-deps", "--no-build-isolation", "--no-index", "--disable-pip-version-check",
                                "-e", str(ROOT), "-e", str(EXAMPLE)],
                               capture_output=True, text=True, env=_environment(), timeout=300)
    assert installed.returncode == 0, installed.stdout + installed.stderr
    return where


def _environment() -> dict[str, str]:
    # Not this tree on PYTHONPATH: the venv's installs are what is tested.
    return {key: value for key, value in os.environ.items() if key not in ("PYTHONPATH", "PIP_FIND_LINKS")}


def cipstack(venv: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(venv / "bin" / "cipstack"), *args], capture_output=True, text=True,
                          env=_environment(), timeout=60, cwd=venv)


def test_the_installed_family_is_listed_with_its_distribution(venv: Path) -> None:
    shown = cipstack(venv, "models")
    assert shown.returncode == 0, shown.stderr
    assert shown.stdout.splitlines()[-1].split() == ["dio", "DIO-4", "product", "code", "4", "DIO-4", "-",
                                                     "cipstack-dio"]
    assert shown.stdout.splitlines()[0].split()[-1] == "cipstack"


def _listening_at(address: tuple[str, int]) -> bool:
    try:
        socket.create_connection(address, timeout=0.2).close()
    except OSError:
        return False
    return True


def _listening(process: subprocess.Popen[str], *addresses: tuple[str, int]) -> bool:
    assert process.poll() is None, process.stderr.read() if process.stderr else ""
    return all(_listening_at(address) for address in addresses)


@contextlib.contextmanager
def serving(venv: Path, command: str, *args: str, at: tuple[tuple[str, int], ...]) -> Iterator[None]:
    """``cipstack COMMAND ARGS`` (an adapter or a fleet) running until the block ends, once every address
    of ``at`` accepts a TCP connection."""
    process = subprocess.Popen([str(venv / "bin" / "cipstack"), command, *args], stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE, text=True, env=_environment(), cwd=venv)
    try:
        wait_for(lambda: _listening(process, *at), 30, f"cipstack {command} to listen")
        yield
    finally:
        process.terminate()
        _, errors = process.communicate(timeout=15)
    # What it served, refused or was stopped by never ended in a traceback.
    assert "Traceback" not in errors, errors


@contextlib.contextmanager
def adapter(venv: Path, *args: str) -> Iterator[str]:
    """A dio adapter from factory settings on a port of its own; its ``HOST:PORT``."""
    port = free_port()
    with serving(venv, "adapter", "--profile", "dio", "--port", str(port), "--factory", "--quiet", *args,
                 at=(("127.0.0.1", port),)):
        yield f"127.0.0.1:{port}"


def test_the_adapter_serves_the_block_and_a_scanner_reads_and_writes_it(venv: Path, tmp_path: Path) -> None:
    io_port = free_port()
    with adapter(venv, "--io-port", str(io_port)) as address:
        identity = cipstack(venv, "identity", address, "--json")
        assert identity.returncode == 0, identity.stderr
        assert '"vendor_id": 65520' in identity.stdout and '"product_code": 4' in identity.stdout
        assert '"device_type": 7' in identity.stdout and '"product_name": "DIO-4"' in identity.stdout
        # Output point 2 on: input point 2 (wired to it) reads on, and the input assembly has bit 1 set. The
        # scanner knows the block by its identity: each value by its declaration (name, enumeration).
        assert cipstack(venv, "get", address, "8/2/3").stdout == "Value = 0 (off)\n"
        written = cipstack(venv, "set", address, "9/2/3", "1", "--type", "BOOL")
        assert written.returncode == 0, written.stderr
        assert cipstack(venv, "get", address, "8/2/3").stdout == "Value = 1 (on)\n"
        inputs = cipstack(venv, "get", address, "4/100/3", "--json")
        assert inputs.returncode == 0 and '"data": "02"' in inputs.stdout, inputs.stdout + inputs.stderr
        # The Discrete Input Point's Value is the device's, not the network's (CIP Vol 1, section 5-9).
        refused = cipstack(venv, "set", address, "8/2/3", "0", "--type", "BOOL")
        assert refused.returncode == 1 and "0x0E (attribute not settable)" in refused.stderr, refused.stderr
        # Class 1 by the family's EDS file: output 3 set in the output assembly, input 3 reads it back.
        assert cipstack(venv, "eds", "generate", "--profile", "dio", "-o", str(tmp_path)).returncode == 0
        io = cipstack(venv, "io", address, "--eds", str(tmp_path / "DIO-4_1.01.eds"), "--connection", "1",
                      "--set", "output_3=1", "--duration", "1", "--io-port", "0", "--target-io-port", str(io_port))
        assert io.returncode == 0 and "input_3=True" in io.stdout, io.stdout + io.stderr
    # The ports a drive has beside EtherNet/IP: the block has none, one line each.
    _one_line_refusal(cipstack(venv, "adapter", "--profile", "dio", "--port", "0", "--rtu", "pty", "--factory"),
                      "cipstack adapter: profile 'dio' has no RS-485 Modbus-RTU port (one has: profile acg)")
    _one_line_refusal(cipstack(venv, "adapter", "--profile", "dio", "--port", "0", "--modbus-port", "0",
                               "--factory"), "cipstack adapter: profile 'dio' has no Modbus TCP")
    _one_line_refusal(cipstack(venv, "adapter", "--profile", "dio", "--port", "0", "--param", "X=1", "--factory"),
                      "cipstack adapter: DIO-4: this device has no keypad")


#: Run in the venv against a running block: a scanner given no catalog, and the capture analyzer's
#: choice of declarations for the block's identity.
RECOGNISED = """
import sys
from cipstack.capture.command import declarations_for_identity
from cipstack.scanner import SyncScanner

with SyncScanner(sys.argv[1]) as scanner:
    print(scanner.catalog.profile, scanner.catalog.source.split(" (")[0])
    print(scanner.catalog.attribute(0x09, 1, 5).name, scanner.read(0x09, 2, 3))
declarations = declarations_for_identity({"vendor_id": 0xFFF0, "device_type": 7, "product_code": 4})
print(declarations.source, declarations.catalog.profile)
other = declarations_for_identity({"vendor_id": 0xFFF0, "device_type": 12, "product_code": 4})
print(other.source, other.catalog.profile)
"""


def test_a_scanner_and_the_capture_analyzer_recognise_the_block_by_its_identity(venv: Path) -> None:
    """As cipstack's own families are: by the vendor id, product code and device type its declaration
    gives, with no ``catalog=`` (its declarations are read from what its device model serves); a device
    of another device type is not taken for it."""
    with adapter(venv) as address:
        done = subprocess.run([str(venv / "bin" / "python"), "-c", RECOGNISED, address], capture_output=True,
                              text=True, env=_environment(), timeout=60, cwd=venv)
        assert done.returncode == 0, done.stderr
        assert done.stdout.splitlines() == ["dio profile dio", "Fault Action 0 (off)", "profile dio dio",
                                            "standard objects None"], done.stdout


def test_eds_generate_writes_the_file_the_family_describes(venv: Path, tmp_path: Path) -> None:
    made = cipstack(venv, "eds", "generate", "--profile", "dio", "-o", str(tmp_path))
    assert made.returncode == 0, made.stderr
    assert made.stdout == f"{tmp_path / 'DIO-4_1.01.eds'}\n"
    text = (tmp_path / "DIO-4_1.01.eds").read_bytes().decode("ascii")
    assert "ProdType = 7;" in text and 'ProdName = "DIO-4";' in text and "VendCode = 65520;" in text
    # The points' Values are the assembly members: one parameter each, linked to its attribute.
    assert '"Output 2",' in text and '6, "20 09 24 02 30 03",' in text and "Assem150 =" in text
    checked = cipstack(venv, "eds", "check", str(tmp_path / "DIO-4_1.01.eds"))
    assert checked.returncode == 0 and "0 errors, 0 warnings" in checked.stdout, checked.stdout + checked.stderr
    one_model = cipstack(venv, "eds", "generate", "--profile", "dio", "--model", "X", "-o", str(tmp_path))
    assert (one_model.returncode, one_model.stderr) == (2, "cipstack eds generate: profile dio has one model; give "
                                                           "no --model\n")


def _http(method: str, url: str, body: dict[str, Any] | None = None) -> tuple[int, str]:
    data = json.dumps(body).encode() if body is not None else None
    request = urllib.request.Request(url, data=data, method=method,
                                     headers={"Content-Type": "application/json"} if data is not None else {})
    try:
        with urllib.request.urlopen(request, timeout=10) as reply:
            return int(reply.status), reply.read().decode()
    except urllib.error.HTTPError as error:
        with error:
            return int(error.code), error.read().decode()


@pytest.fixture(scope="module")
def panel(venv: Path) -> Iterator[tuple[str, str]]:
    """One dio adapter with the HTTP API (the front panel's surface): its ``HOST:PORT`` and the API's."""
    http = free_port()
    with adapter(venv, "--io-port", "0", "--http", f"127.0.0.1:{http}") as address:
        wait_for(lambda: _listening_at(("127.0.0.1", http)), 30, "the HTTP API to listen")
        yield address, f"127.0.0.1:{http}"


@pytest.mark.browser
def test_the_front_panel_page_shows_the_block_in_a_browser(panel: tuple[str, str], tmp_path: Path) -> None:
    from tests.browser import chromium

    _, base = panel
    with chromium(tmp_path / "profile") as browser:
        browser.get(f"http://{base}/")
        wait_for(lambda: browser.find_element("id", "link-state").text == "live", 20, "the panel's stream")
        shown = {name: browser.find_element("id", name).text for name in ("display", "state", "trip", "power")}
        assert shown == {"display": "-----", "state": "-", "trip": "none", "power": "on"}
        # The parameters' section says why there are none: the device's own one-line refusal.
        wait_for(lambda: "this device has no keypad" in browser.find_element("id", "parameters-note")
                 .get_attribute("textContent"), 20, "the parameters' note")
        errors = [entry for entry in browser.get_log("browser") if entry.get("source") == "javascript"]
        assert errors == []


def test_the_front_panel_shows_the_block_and_refuses_what_only_a_drive_does(venv: Path,
                                                                            panel: tuple[str, str]) -> None:
    address, base = panel
    status, page = _http("GET", f"http://{base}/")
    assert status == 200 and "<title>cipstack front panel</title>" in page
    status, body = _http("GET", f"http://{base}/status")
    shown = json.loads(body)
    assert status == 200 and shown["drive"] is None and shown["power"] == "on" and shown["faults"] == 0, body
    status, body = _http("GET", f"http://{base}/devices")
    assert status == 200 and json.loads(body) == [{"address": "127.0.0.1", "port": int(address.split(":")[1]),
                                                   "product_name": "DIO-4"}]
    status, body = _http("GET", f"http://{base}/plant")
    (row,) = json.loads(body)
    assert status == 200 and row["product_name"] == "DIO-4" and row["trip"] is None, body
    status, body = _http("GET", f"http://{base}/trips")
    assert (status, json.loads(body)) == (200, [])
    # What only a drive has: a one-line JSON error, and the device keeps serving.
    status, body = _http("POST", f"http://{base}/trip", {"code": 1})
    assert (status, json.loads(body)) == (400, {"error": "DIO-4: this profile simulates no drive"})
    status, body = _http("GET", f"http://{base}/parameters")
    error = json.loads(body)["error"]
    assert status == 404 and error.startswith("DIO-4: this device has no keypad"), body
    assert "profile acg, mx2 or rx" in error   # the families that have one, read from the registry
    status, body = _http("POST", f"http://{base}/power", {"action": "cycle"})
    assert status == 200 and json.loads(body)["name"] == "power-cycle", body
    status, body = _http("GET", f"http://{base}/metrics")
    assert status == 200 and 'cipstack_powered{device="127.0.0.1"}' in body
    identity = cipstack(venv, "identity", address, "--json")
    assert identity.returncode == 0 and '"product_name": "DIO-4"' in identity.stdout, identity.stderr


def _one_line_refusal(done: subprocess.CompletedProcess[str], says: str) -> None:
    assert done.returncode != 0 and done.stdout == "", done.stdout
    assert done.stderr.count("\n") == 1 and says in done.stderr and "Traceback" not in done.stderr, done.stderr


def test_drive_commands_serve_the_block_and_refuse_a_drive_s_in_one_line(venv: Path) -> None:
    with adapter(venv, "--io-port", "0") as address:
        port = address.split(":")[1]
        status = cipstack(venv, "drive", "status", "--port", port)
        assert (status.returncode, status.stdout) == (0, "(no drive)  sessions 0  class 3 0  class 1 0\n"), status
        _one_line_refusal(cipstack(venv, "drive", "trip", "1", "--port", port),
                          "cipstack drive: DIO-4: this profile simulates no drive")
        _one_line_refusal(cipstack(venv, "drive", "reset", "--port", port),
                          "cipstack drive: DIO-4: this profile simulates no drive")
        _one_line_refusal(cipstack(venv, "drive", "parameters", "--port", port),
                          "cipstack drive: DIO-4: this device has no keypad")
        _one_line_refusal(cipstack(venv, "drive", "set-parameter", "X", "1", "--port", port),
                          "cipstack drive: DIO-4: this device has no keypad")
        connections = cipstack(venv, "drive", "connections", "--port", port)
        assert (connections.returncode, connections.stdout) == (0, "sessions 0\n"), connections
        table = cipstack(venv, "drive", "fault-table", "--port", port)
        assert table.returncode == 0 and "power-cycle" in table.stdout and "unplug" in table.stdout, table.stderr
        trips = cipstack(venv, "drive", "trips", "--port", port)
        assert (trips.returncode, trips.stdout) == (0, "this device simulates no drive\n")
        # What any EtherNet/IP device has: its network faults and its power.
        unplugged = cipstack(venv, "drive", "fault", "unplug", "--port", port)
        assert unplugged.returncode == 0 and "unplug" in unplugged.stdout, unplugged.stderr
        assert "unplug" in cipstack(venv, "drive", "faults", "--port", port).stdout
        assert cipstack(venv, "drive", "clear", "--port", port).stdout == "cleared 1 fault(s)\n"
        cycled = cipstack(venv, "drive", "power", "cycle", "--port", port)
        assert cycled.returncode == 0 and "power-cycle" in cycled.stdout, cycled.stderr
        # The block comes back from its power cycle with its outputs off (nothing is saved of them).
        assert cipstack(venv, "get", address, "9/1/3").stdout == "Value = 0 (off)\n"


def test_a_fleet_of_blocks_serves_each_on_its_address(venv: Path) -> None:
    hosts = ("127.0.0.81", "127.0.0.82")
    port = free_port(*hosts)
    with serving(venv, "fleet", "--device", "dio*2", "--addresses", f"{hosts[0]}-{hosts[1]}", "--port", str(port),
                 "--io-port", "0", "--factory", at=tuple((host, port) for host in hosts)):
        for host in hosts:
            identity = cipstack(venv, "identity", f"{host}:{port}", "--json")
            assert identity.returncode == 0 and '"product_name": "DIO-4"' in identity.stdout, identity.stderr
        assert cipstack(venv, "set", f"{hosts[0]}:{port}", "9/4/3", "1", "--type", "BOOL").returncode == 0
        # Each block is a device of its own: the other's point 4 stays off.
        assert cipstack(venv, "get", f"{hosts[0]}:{port}", "8/4/3").stdout == "Value = 1 (on)\n"
        assert cipstack(venv, "get", f"{hosts[1]}:{port}", "8/4/3").stdout == "Value = 0 (off)\n"
        status = cipstack(venv, "drive", "status", "--host", hosts[1], "--port", str(port))
        assert status.returncode == 0 and status.stdout.startswith("(no drive)"), status.stderr
    # A family of one model takes no model name.
    _one_line_refusal(cipstack(venv, "fleet", "--device", "dio:DIO-4*2", "--addresses", "127.0.0.81-127.0.0.82"),
                      "cipstack fleet: --device dio:DIO-4*2: profile dio has one model; give no model")


def test_the_conformance_battery_passes_every_check_that_applies(venv: Path) -> None:
    with adapter(venv, "--io-port", str(free_port())) as address:
        done = cipstack(venv, "conform", address, "--allow-writes", "--allow-reset", "--allow-stress", "--json")
    report = json.loads(done.stdout)
    verdicts = {check["id"]: check["verdict"] for check in report["checks"]}
    assert done.returncode == 0 and report["counts"]["fail"] == 0, done.stdout[-2000:] + done.stderr
    assert report["counts"]["warning"] == 0
    # Class 1 takes its connection points from the EDS file the block serves (its family's description).
    assert report["options"]["connection_points"].startswith("the device's own EDS file")
    for group in ("encap", "router", "cm", "class1"):
        assert {v for k, v in verdicts.items() if k.startswith(f"{group}.")} == {"pass"}, group
    assert {v for k, v in verdicts.items() if k.startswith("eds.")} <= {"pass", "n/a"}
    assert verdicts["eds.device.identity"] == "pass"
    # Not a drive: the AC drive profile's checks do not apply, motion ones included (not "needs --allow-motion").
    assert {v for k, v in verdicts.items() if k.startswith("profile.")} == {"n/a"}
    # CIP Security needs --security and a device configured for it: not run, which is no failure.
    assert {k for k, v in verdicts.items() if v == "not run"} == {k for k in verdicts if k.startswith("security.")}


def test_the_pytest_plugin_starts_the_block(venv: Path, tmp_path: Path) -> None:
    (tmp_path / "test_block.py").write_text(textwrap.dedent("""\
        import pytest

        from cipstack.cip.types import BOOL


        @pytest.mark.cip_adapter(profile="dio")
        def test_the_bench_wiring(cip_adapter, cip_scanner):
            assert cip_scanner.identify().product_name == "DIO-4"
            cip_scanner.write(0x09, 3, 3, 1, cip_type=BOOL)
            assert cip_scanner.read(0x08, 3, 3, BOOL).raw == 1
            assert cip_scanner.read(0x04, 100, 3).raw == bytes([0b100])
            assert cip_adapter.status()["drive"] is None
    """), encoding="utf-8")
    inner = subprocess.run([str(venv / "bin" / "python"), "-m", "pytest", "-q", "-p", "no:cacheprovider",
                            "-p", "no:xdist", "-p", "no:randomly", "test_block.py"], capture_output=True, text=True,
                           env={k: v for k, v in _environment().items() if k != "PYTEST_ADDOPTS"}, timeout=120,
                           cwd=tmp_path)
    assert inner.returncode == 0 and "1 passed" in inner.stdout, inner.stdout[-3000:] + inner.stderr[-2000:]
