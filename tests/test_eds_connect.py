"""Connecting by EDS: ``Scanner.io_connection_from_eds`` against the ACG emulator with the file we
generate for it, and ``cipstack adapter --eds`` / ``cipstack io --eds`` run as a user runs them."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
from eds.samples import BROKEN_EDS, BROKEN_WARNINGS, GENERIC_EDS

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.cip.status import CipError, ExtendedStatus
from cipstack.devices.acg.device import build_acg_device
from cipstack.devices.acg.eds_file import acg_et2_description
from cipstack.eds.generator import eds_text
from cipstack.eds.reader import parse_eds
from cipstack.objects.tcpip import NetworkInterface
from cipstack.scanner import Scanner
from tests.cli_errors import one_line_error
from tests.ports import free_port

# -- the scanner --------------------------------------------------------------------------------------------


async def test_acg_connections_of_its_eds() -> None:
    doc = parse_eds(eds_text(acg_et2_description()))
    adapter = Adapter(AdapterSettings(host="127.0.0.1", port=0, io_port=0),
                      device=build_acg_device(NetworkInterface(ip_address="127.0.0.1")))
    await adapter.start()
    try:
        assert adapter.io_endpoint is not None
        port = adapter.io_endpoint.port
        async with await Scanner.connect(f"127.0.0.1:{adapter.port}") as scanner:
            # Connection1 is the pair of the factory settings, 21/71 (CM.24 = CM.23 = 1): it opens,
            # and so does the input only connection of input 71, by its name.
            async with scanner.io_connection_from_eds(doc, 1, target_io_port=port) as owner, \
                    scanner.io_connection_from_eds(doc, "Input Only 71", target_io_port=port) as listener:
                image = await owner.wait_input(lambda i: i.drive_state == 3, timeout=5)  # Ready (0x29/6)
                assert image.fields()["ready"] in (True, False)
                await listener.wait_input(lambda i: i.drive_state == 3, timeout=5)
                owner.output.speed_reference = 900  # the profile's names (field_name of "Speed Reference")
                connections = adapter.io.connections.values()  # type: ignore[union-attr]
                assert sorted((c.kind.value, c.consumed.instance_id if c.consumed else 198, c.produced.instance_id)
                              for c in connections) == [("exclusive owner", 21, 71), ("input only", 198, 71)]
            assert owner.stats.received > 0 and listener.stats.received > 0
            # Connection2 is 20/70: the card takes it only while CM.24 = CM.23 = 0 (its help says so);
            # at the factory settings output 20 is no connection point it consumes (0x012A).
            assert doc.entry("Connection Manager", "Connection2").value(14).endswith(  # type: ignore[union-attr]
                "accepted while CM.24 = 0 and CM.23 = 0")
            with pytest.raises(CipError) as refused:
                async with scanner.io_connection_from_eds(doc, 2, target_io_port=port):
                    pass
            assert refused.value.extended[:1] == (ExtendedStatus.INVALID_CONSUMING_PATH,)
    finally:
        await adapter.close()


# Listen only needs T->O multicast on the default I/O port: inside a private network namespace.
LISTEN_SCRIPT = textwrap.dedent('''
    import asyncio, json, sys
    from cipstack.adapter import Adapter, AdapterSettings
    from cipstack.eds.emulated_device import build_eds_device
    from cipstack.eds.reader import read_eds
    from cipstack.objects.tcpip import NetworkInterface
    from cipstack.scanner import Scanner

    async def main():
        doc = read_eds(sys.argv[1])
        device = build_eds_device(doc, NetworkInterface(ip_address="127.0.0.1"))
        adapter = Adapter(AdapterSettings(host="127.0.0.1", port=0, io_port=2222), device=device)
        await adapter.start()
        try:
            owner_scanner = await Scanner.connect(f"127.0.0.1:{adapter.port}")
            listener_scanner = await Scanner.connect(f"127.0.0.1:{adapter.port}")
            async with owner_scanner, listener_scanner, \\
                    owner_scanner.io_connection_from_eds(doc, "Control", multicast=True) as owner, \\
                    listener_scanner.io_connection_from_eds(doc, "Listen") as listener:
                owner.output.flow_setpoint = 333
                image = await listener.wait_input(lambda i: i.flow_setpoint == 333, 3)
                kinds = sorted((c.kind.value, c.multicast) for c in adapter.io.connections.values())
                print(json.dumps({"kinds": kinds, "listened": image.fields(),
                                  "shared": owner.connection.to_connection_id == listener.connection.to_connection_id}))
        finally:
            await adapter.close()

    asyncio.run(main())
''')


@pytest.mark.skipif(os.geteuid() != 0 or not shutil.which("unshare") or not shutil.which("ip"),
                    reason="needs root, unshare and ip for a private network namespace")
def test_listen_only_connection_of_an_eds_shares_the_owner_multicast(tmp_path: Path) -> None:
    eds = tmp_path / "acme-fc10.eds"
    eds.write_text(GENERIC_EDS)
    script = tmp_path / "listen.py"
    script.write_text(LISTEN_SCRIPT)
    result = subprocess.run(["unshare", "-n", "sh", "-c", f"ip link set lo up && exec {sys.executable} {script} {eds}"],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout.strip().splitlines()[-1])
    # Connection3 of the file is listen only with a multicast T->O: it shares Connection1's production.
    assert report["kinds"] == [["exclusive owner", True], ["listen only", True]]
    assert report["shared"] is True
    assert report["listened"] == {"flow_actual": 0, "flow_setpoint": 333, "valve_open": False}


# -- the command line ----------------------------------------------------------------------------------------



def run(*args: str, timeout: float = 30) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "cipstack", *args], capture_output=True, text=True,
                          timeout=timeout, stdin=subprocess.DEVNULL)


class EdsAdapter:
    """``cipstack adapter --eds FILE`` in a subprocess; its log goes to a file the test reads."""

    def __init__(self, process: subprocess.Popen[str], log: Path, port: int) -> None:
        self.process = process
        self.log = log
        self.address = f"127.0.0.1:{port}"

    def log_text(self) -> str:
        return self.log.read_text()

    @property
    def io_port(self) -> int:
        found = re.search(r"class 1 I/O on UDP 127\.0\.0\.1:(\d+)", self.log_text())
        assert found, self.log_text()
        return int(found.group(1))


@contextmanager
def eds_adapter(path: Path) -> Iterator[EdsAdapter]:
    port = free_port()
    log = path.with_suffix(".log")
    with log.open("w") as sink:
        process = subprocess.Popen([sys.executable, "-m", "cipstack", "adapter", "--eds", str(path), "--port",
                                    str(port), "--io-port", "0", "--quiet"], stdout=subprocess.DEVNULL, stderr=sink,
                                   text=True)
    running = EdsAdapter(process, log, port)
    try:
        deadline = time.monotonic() + 15
        while "emulating" not in running.log_text():
            if process.poll() is not None or time.monotonic() > deadline:
                pytest.fail(f"adapter did not start: {running.log_text()}")
            time.sleep(0.05)
        yield running
    finally:
        if process.poll() is None:
            process.send_signal(signal.SIGTERM)
            process.wait(10)
        assert process.returncode == 0, running.log_text()
        assert "Traceback" not in running.log_text()


@pytest.fixture
def generic_file(tmp_path: Path) -> Path:
    path = tmp_path / "acme-fc10.eds"
    path.write_text(GENERIC_EDS)
    return path


def test_adapter_and_io_by_eds(generic_file: Path) -> None:
    with eds_adapter(generic_file) as adapter:
        assert "warning" not in adapter.log_text()
        identity = json.loads(run("identity", adapter.address, "--json").stdout)
        assert (identity["vendor_id"], identity["product_code"], identity["product_name"]) == (1234, 77, "Acme FC-10")
        got = json.loads(run("get", adapter.address, "0x70/1/1", "--type", "UINT", "--json").stdout)
        assert got["value"] == 120  # Param1's default
        # Connection1: output 100 / input 101 of the file, field names from its parameters.
        common = ["--eds", str(generic_file), "--io-port", "0", "--target-io-port", str(adapter.io_port), "--json"]
        result = run("io", adapter.address, "--connection", "1", "--set", "flow_setpoint=420", "--set",
                     "valve_open=1", "--duration", "0.5", *common)
        assert result.returncode == 0, result.stderr
        records = [json.loads(line) for line in result.stdout.splitlines()]
        inputs = [record["input"] for record in records if "input" in record]
        assert inputs and inputs[-1] == {"flow_actual": 0, "flow_setpoint": 420, "valve_open": True}
        summary = records[-1]["summary"]
        assert summary["received"] > 5 and summary["lost"] == 0
        # Param6's default RPI is 20 ms: about 25 packets in 0.5 s, not the 50 of 10 ms.
        assert summary["sent"] < 40
        # Connection "Monitor": input only, the heartbeat point 197 of the file.
        monitor = run("io", adapter.address, "--connection", "Monitor", "--duration", "0.3", "--rpi", "5ms", *common)
        assert monitor.returncode == 0, monitor.stderr
        assert json.loads(monitor.stdout.splitlines()[0])["input"]["flow_setpoint"] == 420
        missing = run("io", adapter.address, "--connection", "9", *common)
        assert missing.returncode == 2 and "no class 1 connection '9'" in one_line_error(missing)
        both = run("io", adapter.address, "--connection", "1", "--input", "101", *common)
        assert both.returncode == 2 and "--eds takes the output, input and heartbeat" in one_line_error(both)


def test_adapter_from_broken_eds_warns_and_serves(tmp_path: Path) -> None:
    path = tmp_path / "broken.eds"
    path.write_text(BROKEN_EDS)
    with eds_adapter(path) as adapter:
        warnings = [line for line in adapter.log_text().splitlines() if ": warning: " in line]
        assert len(warnings) == len(BROKEN_WARNINGS)
        for line, (_, fragment) in zip(warnings, BROKEN_WARNINGS, strict=True):
            assert re.match(rf"cipstack adapter: {re.escape(str(path))}:\d+: warning: ", line), line
            assert fragment in line
        identity = json.loads(run("identity", adapter.address, "--json").stdout)
        assert identity["product_name"] == "Broken"


def test_unreadable_eds_is_one_line(tmp_path: Path, generic_file: Path) -> None:
    missing = run("adapter", "--eds", str(tmp_path / "nope.eds"), "--port", str(free_port()), "--io-port", "0",
                  "--quiet")
    assert missing.returncode == 2 and "nope.eds: cannot read" in one_line_error(missing)
    garbled = tmp_path / "garbled.eds"
    garbled.write_text("[Device]\n    VendCode = 1\n    ProdName = \"x\";\n[Params\n")
    result = run("adapter", "--eds", str(garbled), "--port", str(free_port()), "--io-port", "0", "--quiet")
    assert result.returncode == 2 and f"{garbled}:" in one_line_error(result)
    empty = tmp_path / "empty.eds"
    empty.write_text("[File]\n    DescText = \"no device\";\n")
    result = run("adapter", "--eds", str(empty), "--port", str(free_port()), "--io-port", "0", "--quiet")
    assert result.returncode == 2 and "no [Device] section" in one_line_error(result)
    result = run("adapter", "--eds", str(generic_file), "--profile", "acg", "--io-port", "0", "--quiet")
    assert result.returncode == 2 and "not allowed with argument" in one_line_error(result)
    result = run("io", "127.0.0.1:1", "--eds", str(tmp_path / "nope.eds"), "--connection", "1", "--io-port", "0")
    assert result.returncode == 2 and "nope.eds: cannot read" in one_line_error(result)
