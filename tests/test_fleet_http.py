"""``cipstack fleet --workers 2 --http``: one HTTP control API, in the parent, for every device of every
worker, run as a real subprocess and talked to with a real HTTP client (urllib) and real EtherNet/IP
peers over loopback. A fault applied through the parent reaches the device in its worker and is seen
on the wire; a keypad parameter set through it is read back with Get_Attribute_Single; the devices of
a worker that was killed, or stopped, answer 503 naming the device while the others still answer."""

from __future__ import annotations

import asyncio
import json
import os
import shutil
import signal
import socket
import stat
import sys
import tempfile
import time
import urllib.error
import urllib.request
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("aiohttp", reason="aiohttp is not installed (the http extra): pip install '.[http]'")

import aiohttp
from aiohttp import web

from cipstack.cip.status import CipError
from cipstack.control import default_control_path, peer_credentials
from cipstack.control.http import MAX_BODY, openapi_document
from cipstack.control.http_relay import Backend, RelayApi
from cipstack.scanner import SyncScanner
from tests.ports import free_port
from tests.test_fleet import Fleet, alive, children, refused_fleet
from tests.waiting import wait_for

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="any 127.x on loopback")

TOKEN = "fleet-s3cret"


def addresses(block: int, count: int) -> list[str]:
    """``count`` loopback addresses of a block of this file's own (127.79.BLOCK.x)."""
    return [f"127.79.{block}.{10 + n}" for n in range(count)]


class Api:
    """The fleet's HTTP API at ``base``, called with urllib; every answer is JSON."""

    def __init__(self, base: str, token: str | None = TOKEN) -> None:
        self.base = base
        self.token = token

    def __call__(self, method: str, path: str, body: object = None, raw: bytes | None = None,
                 headers: dict[str, str] | None = None) -> tuple[int, Any]:
        data = raw if raw is not None else (json.dumps(body).encode() if body is not None else None)
        request = urllib.request.Request(self.base + path, data=data, method=method)
        if data is not None:
            request.add_header("Content-Type", "application/json")
        for name, value in (headers or {}).items():
            request.add_header(name, value)
        if self.token is not None:
            request.add_header("Authorization", f"Bearer {self.token}")
        try:
            with urllib.request.urlopen(request, timeout=30) as response:
                assert response.headers.get_content_type() == "application/json"
                return response.status, json.loads(response.read())
        except urllib.error.HTTPError as error:
            with error:
                assert error.headers.get_content_type() == "application/json", error.headers
                return error.code, json.loads(error.read())


def worker_pid(host: str, port: int) -> int:
    """The process that serves the device at ``host:port``: the listener of its control socket
    (SO_PEERCRED), which its worker opened."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as control:
        control.connect(str(default_control_path(port, host)))
        credentials = peer_credentials(control)
    assert credentials is not None
    return credentials[0]


def spec_file(tmp_path: Path, hosts: list[str], port: int) -> Path:
    """Three ACG drives and an MX2 over two workers: worker 1 has hosts 0-1, worker 2 hosts 2-3."""
    spec = tmp_path / "plant.toml"
    spec.write_text(f'addresses = "{hosts[0]}-{hosts[-1]}"\nport = {port}\nio_port = 0\nworkers = 2\n'
                    f'state_dir = "state"\n\n[[device]]\nprofile = "acg"\ncount = 3\n\n'
                    f'[[device]]\nmodel = "MX2-A2015-E"\ncount = 1\n')
    return spec


def forward_open(host: str, port: int) -> None:
    """A Forward_Open (class 3) to the device, closed again; a refusal raises ``CipError``."""
    with SyncScanner(f"{host}:{port}", identify=False) as scanner:
        scanner.open_connection()
        scanner.close_connection()


def test_one_api_serves_every_device_of_every_worker(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                    request: pytest.FixtureRequest) -> None:
    hosts = addresses(1, 4)
    port, http = free_port(*hosts), free_port()
    # Short: the workers' sockets go in it, a Unix socket path has at most 107 bytes, and a pytest-xdist
    # worker's tmp_path is long already.
    runtime = Path(tempfile.mkdtemp(prefix="run-"))
    request.addfinalizer(lambda: shutil.rmtree(runtime, ignore_errors=True))
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(runtime))
    fleet = Fleet(tmp_path, "--spec", str(spec_file(tmp_path, hosts, port)), "--http", f"127.0.0.1:{http}",
                  "--http-token", TOKEN)
    try:
        lines = fleet.wait_ready(60)
        assert [line.split()[0] for line in lines] == [f"{h}:{port}" for h in hosts]
        api = Api(f"http://127.0.0.1:{http}")
        # The workers' own APIs: a Unix socket each, in a directory only this user reaches.
        (private,) = runtime.iterdir()
        assert stat.S_IMODE(private.stat().st_mode) == 0o700
        assert sorted(p.name for p in private.iterdir()) == ["worker-1.sock", "worker-2.sock"]
        pids = [worker_pid(host, port) for host in hosts]
        assert pids[0] == pids[1] != pids[2] == pids[3] and sorted(set(pids)) == sorted(children(fleet.process.pid))

        status, devices = api("GET", "/devices")
        assert status == 200
        assert [(d["address"], d["port"], d["worker"]) for d in devices] == [
            (hosts[0], port, 1), (hosts[1], port, 1), (hosts[2], port, 2), (hosts[3], port, 2)]
        assert [d["product_name"] for d in devices] == ["CENT"] * 3 + ["3G3AX-MX2-CRT-AB015_A2015-E"]
        for host in (hosts[0], hosts[3]):                                    # one device of each worker
            status, body = api("GET", f"/devices/{host}/status")
            assert status == 200 and body["drive"]["state"].upper() == "READY" and body["faults"] == 0, body

        # A fault applied through the parent, to a device of worker 2, seen on the wire by a peer.
        status, fault = api("POST", f"/devices/{hosts[2]}/faults",
                            {"name": "refuse-forward-open", "options": {"status": "0x0113", "count": 1}})
        assert status == 201 and fault["name"] == "refuse-forward-open", fault
        assert api("GET", f"/devices/{hosts[2]}/faults")[1][0]["id"] == fault["id"]
        assert api("GET", f"/devices/{hosts[3]}/faults") == (200, [])
        with pytest.raises(CipError) as refused:
            forward_open(hosts[2], port)
        assert (refused.value.general, refused.value.extended[:1]) == (0x01, (0x0113,))
        forward_open(hosts[0], port)                                         # the others accept
        forward_open(hosts[3], port)
        forward_open(hosts[2], port)                                         # --count 1: used up
        # Events of a device in each worker.
        status, events = api("GET", f"/devices/{hosts[2]}/events?since=0")
        assert status == 200 and [e["kind"] for e in events] == ["fault applied", "fault used up"], events
        assert api("GET", f"/devices/{hosts[2]}/events?since={events[-1]['number']}") == (200, [])
        status, applied = api("POST", f"/devices/{hosts[0]}/faults", {"name": "error-status",
                                                                        "options": {"status": "0x08", "class": 1}})
        assert status == 201, applied
        status, cleared = api("DELETE", f"/devices/{hosts[0]}/faults")
        assert status == 200 and [f["id"] for f in cleared] == [applied["id"]]
        status, events = api("GET", f"/devices/{hosts[0]}/events?since=0")
        assert status == 200 and [e["kind"] for e in events] == ["fault applied", "fault cleared"], events

        # A keypad parameter set through the parent, read back from the device with Get_Attribute_Single.
        with SyncScanner(f"{hosts[1]}:{port}", identify=False) as scanner:
            before = scanner.get_attribute_single(0x2A, 1, 103).data          # dEC, in 0.1 s
            assert int.from_bytes(before, "little") != 55
            status, written = api("PUT", f"/devices/{hosts[1]}/parameters/dEC", {"value": "5.5"})
            assert status == 200 and (written["code"], written["raw"]) == ("dEC", 55), written
            assert scanner.get_attribute_single(0x2A, 1, 103).data == (55).to_bytes(len(before), "little")
        with SyncScanner(f"{hosts[2]}:{port}", identify=False) as scanner:   # and only on that device
            assert scanner.get_attribute_single(0x2A, 1, 103).data == before
        assert api("GET", f"/devices/{hosts[1]}/parameters/dEC")[1]["value"] == "5.5"

        # The errors the API of one process gives, given through the parent.
        status, missing = api("GET", "/devices/127.79.1.99/status")
        assert status == 404 and missing == {"error": "no device '127.79.1.99'", "devices": hosts}
        status, unaddressed = api("GET", "/status")
        assert status == 404 and unaddressed["devices"] == hosts and "/devices/ADDRESS" in unaddressed["error"]
        assert api("POST", f"/devices/{hosts[3]}/faults", raw=b"{not json") == (400, {"error": "the body is not JSON"})
        status, body = api("POST", f"/devices/{hosts[3]}/faults", raw=b"x" * (MAX_BODY + 1))
        assert status == 413 and "error" in body
        # A page of another origin, and a rebinding name, are refused by the relay as by one process.
        fault = {"name": "stop-producing"}
        assert api("POST", f"/devices/{hosts[3]}/faults", fault, headers={"Origin": "http://evil.example"})[0] == 403
        assert api("POST", f"/devices/{hosts[3]}/faults", fault, headers={"Content-Type": "text/plain"})[0] == 415
        assert api("GET", f"/devices/{hosts[3]}/status", headers={"Host": "evil.example"})[0] == 403
        assert api("POST", f"/devices/{hosts[3]}/faults", raw=b'{"name": "delay", "options": {"by": ' + b"9" * 400
                   + b"}}")[0] == 400
        assert api("GET", f"/devices/{hosts[3]}/faults") == (200, [])
        status, body = api("GET", f"/devices/{hosts[3]}/nowhere")
        assert status == 404 and "error" in body
        status, body = api("POST", f"/devices/{hosts[3]}/faults",
                           {"name": "stop-producing", "options": {"connection": "0x12345678"}})
        assert status == 404 and body["error"].startswith("no class 1 connection 0x12345678"), body
        status, body = Api(api.base, token=None)("GET", "/devices")
        assert status == 401 and "Bearer" in body["error"]
        assert api("GET", "/openapi.json") == (200, json.loads(json.dumps(openapi_document())))

        # Worker 2 killed: its devices answer 503 naming the device; worker 1's still answer.
        os.kill(pids[2], signal.SIGKILL)
        wait_for(lambda: not alive(pids[2]), 10, "worker 2 to end")
        for host in hosts[2:]:
            status, body = api("GET", f"/devices/{host}/status")
            assert status == 503 and body["device"] == host, body
            assert body["error"] == (f"device {host} is not served: worker 2 ({hosts[2]}-{hosts[3]}) ended: "
                                     "killed by SIGKILL"), body
        status, body = api("GET", f"/devices/{hosts[0]}/status")
        assert status == 200 and body["drive"]["state"] == "READY"
        assert api("POST", f"/devices/{hosts[1]}/faults", {"name": "error-status",
                                                            "options": {"status": "0x08", "class": 1}})[0] == 201
        status, devices = api("GET", "/devices")
        assert status == 200 and [d["address"] for d in devices] == hosts
        assert ["error" in d for d in devices] == [False, False, True, True]
        forward_open(hosts[0], port)                                         # and on the wire as before
        wait_for(lambda: "ended: killed by SIGKILL; its devices answer 503" in fleet.err.read_text(), 10,
                 "the line that reports it")

        assert fleet.stop(signal.SIGTERM) == 1                               # a worker was lost: it says so
        err = fleet.err.read_text()
        assert "Traceback" not in err
        assert err.splitlines()[-1] == (f"cipstack fleet: stopped; 1 of 2 workers had ended: worker 2 "
                                        f"({hosts[2]}-{hosts[3]}) ended: killed by SIGKILL")
        assert not any(alive(pid) for pid in pids)
        assert list(runtime.iterdir()) == []                                 # the private directory is gone
    finally:
        fleet.kill()


def test_a_stopped_worker_answers_503_and_the_others_go_on(tmp_path: Path) -> None:
    """A worker that stops answering its parent (SIGSTOP) is reported within the heartbeat's deadline
    and stopped; its devices answer 503, the other worker's go on answering."""
    from cipstack.fleet.workers import HEARTBEAT_INTERVAL, HEARTBEAT_TIMEOUT, HUNG_STOP_TIMEOUT

    hosts = addresses(2, 4)
    port, http = free_port(*hosts), free_port()
    fleet = Fleet(tmp_path, "--addresses", f"{hosts[0]}-{hosts[-1]}", "--device", "acg*4", "--port", str(port),
                  "--io-port", "0", "--workers", "2", "--state-dir", str(tmp_path / "state"),
                  "--http", f"127.0.0.1:{http}")
    try:
        fleet.wait_ready()
        api = Api(f"http://127.0.0.1:{http}", token=None)
        stopped = worker_pid(hosts[0], port)
        os.kill(stopped, signal.SIGSTOP)
        wait_for(lambda: "stopped answering" in fleet.err.read_text(),
                 HEARTBEAT_TIMEOUT + HEARTBEAT_INTERVAL + 5, "the parent to report the stopped worker")
        wait_for(lambda: not alive(stopped), HUNG_STOP_TIMEOUT + 5, "the stopped worker to be ended")
        status, body = api("GET", f"/devices/{hosts[1]}/faults")
        assert status == 503 and body["device"] == hosts[1]
        assert f"worker 1 ({hosts[0]}-{hosts[1]}) stopped answering" in body["error"], body
        assert api("GET", f"/devices/{hosts[2]}/faults") == (200, [])
        assert fleet.stop(signal.SIGINT) == 1
        assert "Traceback" not in fleet.err.read_text()
    finally:
        fleet.kill()


def test_a_taken_http_port_is_one_line_and_nothing_is_left(tmp_path: Path) -> None:
    hosts = addresses(3, 2)
    port = free_port(*hosts)
    http = free_port()
    fleet = refused_fleet(tmp_path, ("127.0.0.1", http), "--addresses", f"{hosts[0]}-{hosts[1]}", "--device", "acg*2",
                          "--port", str(port), "--io-port", "0", "--workers", "2",
                          "--state-dir", str(tmp_path / "state"), "--http", f"127.0.0.1:{http}")
    assert fleet.err.read_text().splitlines() == [
        f"cipstack fleet: cannot listen on TCP 127.0.0.1:{http} (HTTP control API, --http): Address already in use"]
    assert children(fleet.process.pid) == []
    for host in hosts:                                                      # every device's port free again
        with socket.socket() as probe:
            probe.bind((host, port))


# -- the relay alone, over a scripted worker ------------------------------------------------------------
async def test_the_relay_streams_a_body_as_it_comes_and_a_silent_worker_is_503(tmp_path: Path) -> None:
    """A worker's answer of no announced length (a stream of events) reaches the client chunk by chunk,
    not once it is whole; a worker whose socket no longer answers makes its device 503."""
    went_on = asyncio.Event()

    async def listing(request: web.Request) -> web.Response:
        return web.json_response([{"address": "127.79.9.10", "port": 44818, "product_name": "CENT"}])

    async def events(request: web.Request) -> web.StreamResponse:
        response = web.StreamResponse(headers={"Content-Type": "application/x-ndjson"})
        await response.prepare(request)
        await response.write(b'{"number": 1}\n')
        await asyncio.wait_for(went_on.wait(), 10)     # the client must have the first line by now
        await response.write(b'{"number": 2}\n')
        await response.write_eof()
        return response

    worker = web.Application()
    worker.router.add_get("/devices", listing)
    worker.router.add_get("/devices/{device}/events", events)
    runner = web.AppRunner(worker)
    await runner.setup()
    path = str(tmp_path / "worker-1.sock")
    await web.UnixSite(runner, path).start()
    relay = RelayApi([Backend("worker 1 (127.79.9.10)", path, number=1)], "127.0.0.1", 0)
    await relay.start()
    try:
        async with aiohttp.ClientSession() as session:
            url = f"http://127.0.0.1:{relay.port}/devices/127.79.9.10/events"
            async with session.get(url) as response:
                assert response.status == 200 and response.content_type == "application/x-ndjson"
                assert await asyncio.wait_for(response.content.readline(), 10) == b'{"number": 1}\n'
                went_on.set()
                assert await response.content.readline() == b'{"number": 2}\n'
            await runner.cleanup()                                           # the worker is gone
            async with session.get(url) as response:
                body = await response.json()
                assert response.status == 503 and body["device"] == "127.79.9.10", body
                assert body["error"].startswith("device 127.79.9.10 is not served: worker 1 (127.79.9.10) does "
                                                "not answer"), body
    finally:
        await relay.close()
        await runner.cleanup()


async def test_a_stream_whose_worker_went_silent_does_not_hold_the_relays_stop(tmp_path: Path) -> None:
    """A worker's stream that sends a first event and then nothing more (no end, no tick: a worker that
    broke in the middle of an answer) is ended by the relay's stop at once: the relay closes within
    2 s, as a fleet must stop, and the client sees its stream end."""
    async def listing(request: web.Request) -> web.Response:
        return web.json_response([{"address": "127.79.9.11", "port": 44818, "product_name": "CENT"}])

    async def silent(request: web.Request) -> web.StreamResponse:
        response = web.StreamResponse(headers={"Content-Type": "text/event-stream"})
        await response.prepare(request)
        await response.write(b"event: status\ndata: {}\n\n")
        await asyncio.sleep(3600)
        return response

    worker = web.Application()
    worker.router.add_get("/devices", listing)
    worker.router.add_get("/devices/{device}/stream", silent)
    runner = web.AppRunner(worker, shutdown_timeout=0.1)
    await runner.setup()
    path = str(tmp_path / "worker-1.sock")
    await web.UnixSite(runner, path).start()
    relay = RelayApi([Backend("worker 1 (127.79.9.11)", path, number=1)], "127.0.0.1", 0)
    await relay.start()
    try:
        async with aiohttp.ClientSession() as session, \
                session.get(f"http://127.0.0.1:{relay.port}/devices/127.79.9.11/stream") as reply:
            assert reply.status == 200
            assert await asyncio.wait_for(reply.content.readline(), 10) == b"event: status\n"
            started = asyncio.get_running_loop().time()
            await asyncio.wait_for(relay.close(), 10)
            assert asyncio.get_running_loop().time() - started < 2.0
            await asyncio.wait_for(reply.read(), 5)          # the stream ends with the relay
    finally:
        await relay.close()
        await runner.cleanup()


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_the_fleet_stops_within_2s_during_a_long_power_cycle(tmp_path: Path, sig: int) -> None:
    """A power-cycle of 50 minutes applied through the relay to a device of a worker does not hold the
    fleet: SIGINT or SIGTERM ends the parent and every worker within 2 s, without a traceback."""
    hosts = addresses(5 if sig == signal.SIGINT else 6, 2)
    port, http = free_port(*hosts), free_port()
    fleet = Fleet(tmp_path, "--addresses", f"{hosts[0]}-{hosts[-1]}", "--device", "acg*2", "--port", str(port),
                  "--io-port", "0", "--workers", "2", "--state-dir", str(tmp_path / "state"),
                  "--http", f"127.0.0.1:{http}")
    try:
        fleet.wait_ready()
        workers = children(fleet.process.pid)
        assert len(workers) == 2
        api = Api(f"http://127.0.0.1:{http}", token=None)
        status, body = api("POST", f"/devices/{hosts[0]}/power", {"action": "cycle", "off": "3000s"})
        assert status == 200, body
        assert api("GET", f"/devices/{hosts[0]}/status")[1]["power"] == "off"
        fleet.process.send_signal(sig)
        started = time.monotonic()
        code = fleet.process.wait(30)
        took = time.monotonic() - started
        assert code == 0 and "Traceback" not in fleet.err.read_text(), fleet.err.read_text()
        assert took < 2.0, took
        assert not any(alive(pid) for pid in workers)
    finally:
        fleet.kill()
