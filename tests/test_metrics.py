"""``GET /metrics``: a fleet's devices' counters in the Prometheus text format, read by
prometheus_client's own parser after real traffic over loopback (explicit requests, a refused one,
Forward_Opens, a class 1 connection held then closed, a trip), through one process's API and through
the relay of a fleet spread over workers, where a killed worker's devices stop counting as up; and an
adapter's RS-485 line over a real pty."""

from __future__ import annotations

import asyncio
import os
import shutil
import signal
import sys
import tempfile
import urllib.request
from pathlib import Path

import pytest

pytest.importorskip("prometheus_client", reason="prometheus_client is not installed (the http extra): "
                                                "pip install '.[http]'")

from prometheus_client.parser import text_string_to_metric_families

from cipstack.cip.status import CipError
from cipstack.control.metrics import merge_families, render
from cipstack.devices.acg.modbus_rtu import with_crc
from cipstack.devices.profiles import PROFILES
from cipstack.eip.io_server import run_precise
from cipstack.scanner import Scanner
from tests.ports import free_port
from tests.test_fleet import Fleet
from tests.test_fleet_http import TOKEN, Api, worker_pid
from tests.test_rtu_live import adapter, pdu, serial_client
from tests.waiting import wait_for, wait_until

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="any 127.x on loopback")

Samples = dict[tuple[str, tuple[tuple[str, str], ...]], float]


def addresses(block: int, count: int) -> list[str]:
    """``count`` loopback addresses of a block of this file's own (127.81.BLOCK.x)."""
    return [f"127.81.{block}.{10 + n}" for n in range(count)]


def scrape(base: str) -> tuple[str, Samples]:
    """``GET /metrics``: its content type, and every sample by name and labels, as Prometheus's parser reads them."""
    request = urllib.request.Request(base + "/metrics", headers={"Authorization": f"Bearer {TOKEN}"})
    with urllib.request.urlopen(request, timeout=30) as response:
        kind = response.headers["Content-Type"]
        text = response.read().decode()
    samples: Samples = {}
    for family in text_string_to_metric_families(text):
        for sample in family.samples:
            key = (sample.name, tuple(sorted(sample.labels.items())))
            assert key not in samples, f"{key} twice"
            samples[key] = sample.value
    return kind, samples


def value(samples: Samples, name: str, **labels: str) -> float:
    return samples[(name, tuple(sorted(labels.items())))]


async def _traffic(host: str, port: int, io_port: int) -> None:
    """Reads, one refused request, a class 3 connection and a class 1 connection held for 0.5 s."""
    catalog = PROFILES["acg"].catalog
    assert catalog is not None
    async with await Scanner.connect(f"{host}:{port}", timeout=5, catalog=catalog()) as scanner:
        for _ in range(3):
            await scanner.read(0x01, 1, 7)                      # Identity product name
        with pytest.raises(CipError):
            await scanner.get_attribute_single(0x77, 1, 1)      # no such class: 0x05
        async with scanner.io_connection(output=21, input=71, rpi=0.010, timeout_multiplier=5,
                                         target_io_port=io_port) as handle:
            # Past the 20 packets each way the device's counters are checked for (a few in flight at the close).
            await wait_until(lambda: handle.stats.received >= 25 and handle.stats.sent >= 25, 10, "25 packets each way")


def test_one_process_counts_traffic_faults_and_its_shard(tmp_path: Path) -> None:
    hosts = addresses(1, 4)
    port, io_port, http = free_port(*hosts), free_port(*hosts), free_port()
    spec = tmp_path / "plant.toml"
    spec.write_text(f'addresses = "{hosts[0]}-{hosts[-1]}"\nport = {port}\nio_port = {io_port}\n'
                    f'state_dir = "s"\n[[device]]\nprofile = "acg"\ncount = 4\n')
    fleet = Fleet(tmp_path, "--spec", str(spec), "--shard", "1/2", "--http", f"127.0.0.1:{http}",
                  "--http-token", TOKEN)
    try:
        fleet.wait_ready()
        base, (busy, idle) = f"http://127.0.0.1:{http}", hosts[2:]
        kind, before = scrape(base)
        assert kind.startswith("text/plain; version=")
        assert value(before, "cipstack_fleet_devices", shard="1/2") == 2
        assert value(before, "cipstack_fleet_devices_up", shard="1/2") == 2
        assert {labels for name, labels in before if name == "cipstack_powered"} == {
            (("device", busy),), (("device", idle),)}
        run_precise(_traffic(busy, port, io_port))
        api = Api(base)
        assert api("POST", f"/devices/{busy}/trip", {"code": "OverHeat"})[0] == 200
        assert api("POST", f"/devices/{idle}/power", {"action": "cycle", "off": "30s"})[0] == 200
        _, after = scrape(base)
        # Replies by service and status: Get_Attribute_Single answered 0x00 (the reads) and 0x05 (the
        # class that is not there); nothing on the idle device.
        assert value(after, "cipstack_requests_total", device=busy, service="0x0E", status="0x00") >= 3
        assert value(after, "cipstack_requests_total", device=busy, service="0x0E", status="0x05") == 1
        assert not any(name == "cipstack_requests_total" and ("device", idle) in labels for name, labels in after)
        assert value(after, "cipstack_forward_opens_total", device=busy) >= 1
        assert value(after, "cipstack_forward_opens_refused_total", device=busy, reason="other") == 0
        # The class 1 connection is closed: its packets stay counted.
        assert value(after, "cipstack_class1_connections", device=busy) == 0
        assert value(after, "cipstack_class1_packets_sent_total", device=busy) >= 20
        assert value(after, "cipstack_class1_packets_received_total", device=busy) >= 20
        assert value(after, "cipstack_class1_packets_sent_total", device=idle) == 0
        assert value(after, "cipstack_sessions_opened_total", device=busy) >= 1
        assert value(after, "cipstack_encapsulation_frames_total", device=busy) > value(
            before, "cipstack_encapsulation_frames_total", device=busy)
        assert value(after, "cipstack_connection_timeouts_total", device=busy, transport_class="1") == 0
        assert value(after, "cipstack_trips_total", device=busy) == 1
        assert value(after, "cipstack_tripped", device=busy) == 1
        assert value(after, "cipstack_tripped", device=idle) == 0
        # The power-cycle is a fault in effect, and its device is not up until the power comes back.
        assert value(after, "cipstack_faults_active", device=idle) == 1
        assert value(after, "cipstack_powered", device=idle) == 0
        assert value(after, "cipstack_fleet_devices_up", shard="1/2") == 1
    finally:
        assert fleet.stop() == 0, fleet.err.read_text()


def test_the_relay_merges_its_workers_and_a_killed_worker_is_not_up(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, request: pytest.FixtureRequest) -> None:
    hosts = addresses(2, 4)
    port, http = free_port(*hosts), free_port()
    runtime = Path(tempfile.mkdtemp(prefix="run-"))   # short: Unix socket paths
    request.addfinalizer(lambda: shutil.rmtree(runtime, ignore_errors=True))
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(runtime))
    fleet = Fleet(tmp_path, "--addresses", f"{hosts[0]}-{hosts[-1]}", "--device", "acg*3", "--device",
                  "mx2:MX2-A2015-E", "--port", str(port), "--io-port", "0", "--workers", "2", "--state-dir",
                  str(tmp_path / "s"), "--http", f"127.0.0.1:{http}", "--http-token", TOKEN)
    try:
        fleet.wait_ready(60)
        base = f"http://127.0.0.1:{http}"
        _, samples = scrape(base)   # the parser's own check: each family once, each sample once
        assert {dict(labels)["device"] for name, labels in samples if name == "cipstack_powered"} == set(hosts)
        assert value(samples, "cipstack_fleet_devices", shard="0/1") == 4
        assert value(samples, "cipstack_fleet_devices_up", shard="0/1") == 4
        os.kill(worker_pid(hosts[3], port), signal.SIGKILL)
        wait_for(lambda: Api(base)("GET", f"/devices/{hosts[3]}/status")[0] == 503, 10)
        _, samples = scrape(base)
        assert {dict(labels)["device"] for name, labels in samples if name == "cipstack_powered"} == set(hosts[:2])
        assert value(samples, "cipstack_fleet_devices", shard="0/1") == 4
        assert value(samples, "cipstack_fleet_devices_up", shard="0/1") == 2
    finally:
        fleet.stop()
        fleet.kill()


def test_an_adapter_counts_the_frames_of_its_rs485_line(tmp_path: Path) -> None:
    """The RS-485 port's counters (ACG RS-485 manual, the drive's Modbus-RTU port): a request answered,
    and a frame whose CRC is wrong, which the drive ignores and counts."""
    http = free_port()
    with adapter(tmp_path, "--http", f"127.0.0.1:{http}") as path:
        client = serial_client(path)
        try:
            assert client.read_holding_registers(pdu("Pr.12"), count=1, device_id=1).registers
        finally:
            client.close()
        with open(path, "wb", buffering=0) as line:
            frame = with_crc(bytes([1, 3, 0, 0, 0, 1]))
            line.write(frame[:-1] + bytes([frame[-1] ^ 0xFF]))   # the CRC's last byte wrong
        base = f"http://127.0.0.1:{http}"
        wait_for(lambda: value(scrape(base)[1], "cipstack_rtu_errors_total", device="127.0.0.1",
                               kind="crc_errors") == 1, 10)
        _, samples = scrape(base)
        assert value(samples, "cipstack_rtu_frames_total", device="127.0.0.1") == 2
        assert value(samples, "cipstack_rtu_errors_total", device="127.0.0.1", kind="truncated") == 0
        assert not any(name.startswith("cipstack_fleet_") for name, _ in samples)   # an adapter is no fleet shard


def test_merged_expositions_add_up_a_sample_two_processes_give() -> None:
    """Two fleets that are not shards of one plant both say shard="0/1": the plant view's answer adds
    them up rather than giving one sample twice (which a scraper refuses)."""
    first = ('# HELP cipstack_fleet_devices devices\n# TYPE cipstack_fleet_devices gauge\n'
             'cipstack_fleet_devices{shard="0/1"} 2.0\n# HELP cipstack_trips trips\n# TYPE cipstack_trips counter\n'
             'cipstack_trips_total{device="10.0.0.1"} 1.0\n')
    second = first.replace("2.0", "3.0").replace("10.0.0.1", "10.0.0.2")
    families = merge_families([first, second])
    text = asyncio.run(render(list(families.values()))).decode()
    parsed = {(s.name, tuple(sorted(s.labels.items()))): s.value
              for f in text_string_to_metric_families(text) for s in f.samples}
    assert parsed == {("cipstack_fleet_devices", (("shard", "0/1"),)): 5.0,
                      ("cipstack_trips_total", (("device", "10.0.0.1"),)): 1.0,
                      ("cipstack_trips_total", (("device", "10.0.0.2"),)): 1.0}
    assert text.count("# TYPE cipstack_fleet_devices gauge") == 1
