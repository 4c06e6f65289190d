"""What the front panel reads, through a real HTTP client on loopback: the operations it calls
(parameters, connections, fault-table, trips), its files with their headers, and its live stream of
Server-Sent Events, on an ACG, an MX2 and an EDS-emulated device."""

from __future__ import annotations

import asyncio
import json
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("aiohttp", reason="aiohttp is not installed (the http extra): pip install '.[http]'")

import aiohttp

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.control.panel_app import MAX_STREAMS
from cipstack.eds.emulated_device import build_eds_device
from cipstack.eds.reader import read_eds
from cipstack.eip.originator.io_originator import IoConnectionHandle
from cipstack.faults import FAULTS
from cipstack.objects.tcpip import NetworkInterface
from cipstack.scanner import Scanner
from tests.waiting import wait_until

EDS = Path(__file__).parent / "eds" / "files" / "vendor_drive_own_data.eds"


@pytest.fixture
async def served(tmp_path: Path, request: pytest.FixtureRequest) -> AsyncIterator[tuple[Adapter, str]]:
    """An adapter with its HTTP API: the ACG, or the profile or EDS file the test's parameter names."""
    which = getattr(request, "param", "acg")
    settings = AdapterSettings(port=0, io_port=0, http="127.0.0.1:0", control_path=tmp_path / "c.sock",
                               state_path=tmp_path / "state.json",
                               profile=which if which in ("acg", "mx2") else "acg",
                               http_token="t0ken" if which == "token" else None)
    device = build_eds_device(read_eds(EDS), NetworkInterface(ip_address="127.0.0.1")) if which == "eds" else None
    adapter = Adapter(settings, device=device)
    await adapter.start_serving()
    try:
        yield adapter, f"http://127.0.0.1:{adapter.http_api.port}"
    finally:
        await adapter.faults.settle()
        await adapter.stop_serving()


async def get(url: str, **headers: str) -> tuple[int, Any]:
    async with aiohttp.ClientSession() as session, session.get(url, headers=headers) as reply:
        return reply.status, await reply.json()


async def test_the_acg_parameters_trips_and_fault_table(served: tuple[Adapter, str]) -> None:
    _, base = served
    status, found = await get(base + "/parameters")
    assert status == 200 and found["keypad"] == "the ACG keypad"
    groups = {group["group"]: {p["code"]: p for p in group["parameters"]} for group in found["groups"]}
    assert next(iter(groups)) == "operation" and {"dr", "bA", "CM", "Pr"} <= set(groups)
    acc = groups["operation"]["ACC"]
    assert (acc["value"], acc["unit"], acc["minimum"], acc["maximum"], acc["writable"]) == ("5.0", "s", "0.0",
                                                                                           "6000.0", True)
    assert groups["operation"]["Cur"]["writable"] is False
    assert groups["operation"]["drv"]["choices"].startswith("0 Keypad")
    status, trips = await get(base + "/trips")
    assert status == 200 and {"code": "OverHeat", "label": "OverHeat", "fault_code": 0x4200} in trips
    status, table = await get(base + "/fault-table")
    assert status == 200 and [kind["name"] for kind in table] == list(FAULTS)
    drop = next(kind for kind in table if kind["name"] == "drop")
    assert [o["name"] for o in drop["options"]] == ["connection", "originator", "share", "every", "for"]
    share = drop["options"][2]                                   # one of share and every, neither required
    assert share["required"] is False and share["one_of"] == ["share", "every"]
    refuse = next(kind for kind in table if kind["name"] == "refuse-forward-open")
    assert refuse["options"][0] == {"name": "status", "metavar": "STATUS", "required": True,
                                    "help": refuse["options"][0]["help"]}


@pytest.mark.parametrize("served", ["mx2"], indirect=True)
async def test_the_mx2_digital_operator_monitor_and_function_codes(served: tuple[Adapter, str]) -> None:
    _, base = served
    _, found = await get(base + "/parameters")
    groups = [group["group"] for group in found["groups"]]
    assert groups[0] == "d" and "MX2 Digital Operator" in found["keypad"]
    monitors = {p["code"]: p for p in found["groups"][0]["parameters"]}
    assert monitors["d001"]["writable"] is False and monitors["d001"]["unit"] == "Hz"
    _, trips = await get(base + "/trips")
    assert trips[0]["code"] == "E01" and trips[0]["fault_code"] == 0x2200


async def both_ways(adapter: Adapter, io: IoConnectionHandle, output: bytes) -> None:
    """Until data went both ways on the one class 1 connection and the device consumed ``output``."""
    [connection] = adapter.runtime.class1_connections()
    consumed = connection.consumed
    assert consumed is not None
    await wait_until(lambda: io.stats.received > 0 and connection.stats.received > 0
                     and adapter.device.assembly.data(consumed.instance_id) == output, 5, "data both ways")


async def test_a_class1_connection_with_its_data_by_field_names(served: tuple[Adapter, str]) -> None:
    adapter, base = served
    assert adapter.io_endpoint is not None
    async with await Scanner.connect(f"127.0.0.1:{adapter.port}") as scanner, \
            scanner.io_connection(output=21, input=71, rpi=0.01, timeout_multiplier=5,
                                  target_io_port=adapter.io_endpoint.port) as io:
        io.output.speed_reference = 900
        await both_ways(adapter, io, bytes.fromhex("00008403"))
        status, found = await get(base + "/connections")
    assert status == 200 and len(found["sessions"]) == 1 and found["class3"] == []
    [connection] = found["class1"]
    assert connection["output"] == 21 and connection["input"] == 71 and connection["ot_rpi_us"] == 10_000
    assert connection["run"] is True and connection["received"] > 0 and connection["sent"] > 0
    assert connection["output_data"]["fields"]["speed_reference"] == 900
    assert connection["output_data"]["hex"] == "00 00 84 03"
    assert set(connection["input_data"]["fields"]) >= {"running_forward", "drive_state", "speed_actual"}


@pytest.mark.parametrize("served", ["eds"], indirect=True)
async def test_an_eds_device_s_data_without_field_names_is_hex(served: tuple[Adapter, str]) -> None:
    adapter, base = served
    assert adapter.io_endpoint is not None
    async with await Scanner.connect(f"127.0.0.1:{adapter.port}") as scanner, \
            scanner.io_connection(output=100, input=150, rpi=0.01, timeout_multiplier=5,
                                  target_io_port=adapter.io_endpoint.port) as io:
        io.output.raw = bytes(range(1, 9))
        await both_ways(adapter, io, bytes(range(1, 9)))
        _, found = await get(base + "/connections")
    [connection] = found["class1"]
    assert connection["output_data"] == {"hex": "01 02 03 04 05 06 07 08", "fields": {}}
    assert connection["input_data"]["hex"].count(" ") == 11
    _, trips = await get(base + "/trips")
    assert trips == []


@pytest.mark.parametrize("served", ["eds"], indirect=True)
async def test_an_eds_device_s_parameters_from_its_file(served: tuple[Adapter, str]) -> None:
    """The ParamN that link attributes the device serves, in the file's unit, written through the
    attribute's own checks."""
    _, base = served
    status, found = await get(base + "/parameters")
    assert status == 200 and found["keypad"] == "the parameters of its EDS (KV-400 EIP-KV)"
    [group] = found["groups"]
    params = {p["code"]: p for p in group["parameters"]}
    assert (params["Param4"]["name"], params["Param4"]["value"], params["Param4"]["unit"]) == ("Accel Time",
                                                                                             "10000", "ms")
    assert params["Param2"]["writable"] is False and params["Param4"]["maximum"] == "65535"
    async with aiohttp.ClientSession() as session:
        async with session.put(base + "/parameters/Param4", json={"value": "2500"}) as reply:
            assert reply.status == 200 and (await reply.json())["value"] == "2500"
        async with session.put(base + "/parameters/accel time", json={"value": "70000"}) as reply:
            assert reply.status == 400 and "takes 0..65535" in (await reply.json())["error"]
        async with session.put(base + "/parameters/Param2", json={"value": "1"}) as reply:
            assert reply.status == 409 and "read-only" in (await reply.json())["error"]
    async with await Scanner.connect(base.replace("http://", "").split(":")[0] + f":{served[0].port}") as scanner:
        assert (await scanner.read(0x2A, 1, 18)).raw == (2500).to_bytes(2, "little")   # the attribute itself


async def test_the_panel_files_cannot_be_framed_and_the_page_needs_no_token(served: tuple[Adapter, str]) -> None:
    _, base = served
    async with aiohttp.ClientSession() as session:
        for path, kind in (("/", "text/html"), ("/panel/panel.js", "text/javascript"),
                           ("/panel/panel.css", "text/css")):
            async with session.get(base + path) as reply:
                assert reply.status == 200 and reply.content_type == kind
                assert reply.headers["X-Frame-Options"] == "DENY"
                assert "frame-ancestors 'none'" in reply.headers["Content-Security-Policy"]
        async with session.get(base + "/panel/secret.txt") as reply:
            assert reply.status == 404 and "error" in await reply.json()


@pytest.mark.parametrize("served", ["token"], indirect=True)
async def test_with_a_token_the_page_loads_and_every_call_needs_it(served: tuple[Adapter, str]) -> None:
    _, base = served
    async with aiohttp.ClientSession() as session:
        async with session.get(base + "/") as reply:
            assert reply.status == 200
        for path in ("/status", "/parameters", "/stream", "/devices"):
            async with session.get(base + path) as reply:
                assert reply.status == 401, path
        async with session.post(base + "/panel/panel.js", json={}) as reply:
            assert reply.status == 401                                # only the page's GETs are public
    status, _ = await get(base + "/status", Authorization="Bearer t0ken")
    assert status == 200


async def read_events(reply: aiohttp.ClientResponse, wanted: int) -> list[tuple[str, Any]]:
    """The first ``wanted`` named events of a stream: (event name, its JSON)."""
    found: list[tuple[str, Any]] = []
    pending = b""
    while len(found) < wanted:
        pending += await asyncio.wait_for(reply.content.readany(), 5)
        while b"\n\n" in pending:
            block, pending = pending.split(b"\n\n", 1)
            lines = block.decode().splitlines()
            name = next((line[7:] for line in lines if line.startswith("event: ")), None)
            if name is not None:
                found.append((name, json.loads("".join(line[6:] for line in lines if line.startswith("data: ")))))
    return found


async def test_the_stream_sends_state_then_changes_and_events_once(served: tuple[Adapter, str]) -> None:
    _, base = served
    async with aiohttp.ClientSession() as session:
        async with session.get(base + "/stream") as reply:
            assert reply.status == 200 and reply.content_type == "text/event-stream"
            first = await read_events(reply, 3)
            assert [name for name, _ in first] == ["status", "faults", "connections"]
            assert first[0][1]["drive"]["state"] == "READY"
            async with session.post(base + "/trip", json={"code": "OverHeat"}) as tripped:
                assert tripped.status == 200
            changed = dict(await read_events(reply, 2))
            assert changed["status"]["drive"]["trip"] == "OverHeat"
            assert [e["kind"] for e in changed["events"]] == ["trip", "drive state"]
            last = changed["events"][-1]["number"]
        # A panel that comes back after event ``last`` gets only what came after it.
        async with session.post(base + "/reset") as reset:
            assert reset.status == 200
        async with session.get(base + f"/stream?since={last}") as reply:
            again = dict(await read_events(reply, 4))
            assert [e["kind"] for e in again["events"]] == ["trip reset", "drive state"]


async def test_streams_are_bounded_and_end_when_the_api_closes(served: tuple[Adapter, str]) -> None:
    adapter, base = served
    async with aiohttp.ClientSession() as session:
        streams = [await session.get(base + "/stream") for _ in range(MAX_STREAMS)]
        assert all(reply.status == 200 for reply in streams)
        async with session.get(base + "/stream") as refused:
            assert refused.status == 503 and "panels are open" in (await refused.json())["error"]
        closing = asyncio.get_running_loop().time()
        await adapter.http_api.close()
        for reply in streams:
            await asyncio.wait_for(reply.read(), 5)                      # each one ends, at once
            reply.release()
        assert asyncio.get_running_loop().time() - closing < 2.0
