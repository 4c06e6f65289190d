"""``cipstack plant``: one HTTP API over the fleets of a plant spread over machines or pods. Three real
``cipstack fleet --shard I/3`` subprocesses of one spec, each with its HTTP API on its own loopback
address, found through a name that a resolver (the collaborator a headless Service's DNS stands for
in Kubernetes) turns into their addresses. Every device of every fleet is listed once and answers;
a killed fleet's devices and a fleet gone from the records are shown as such (503 naming why); a
fleet that comes back at another address serves its devices again; /metrics holds every shard."""

from __future__ import annotations

import asyncio
import secrets
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("aiohttp", reason="aiohttp is not installed (the http extra): pip install '.[http]'")
pytest.importorskip("prometheus_client", reason="prometheus_client is not installed (the http extra): "
                                                "pip install '.[http]'")

import aiohttp
from prometheus_client.parser import text_string_to_metric_families

from cipstack.cli import main
from cipstack.control.http_relay import RelayApi
from cipstack.control.plant import PlantView, resolve_addresses
from tests.ports import free_port
from tests.test_fleet import Fleet

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="any 127.x on loopback")

DEVICES = [f"127.83.1.{10 + n}" for n in range(6)]
#: Where each fleet's HTTP API listens (a pod's address, in a cluster).
API_HOSTS = [f"127.83.2.{1 + n}" for n in range(3)]
#: The fleets serve --http-allow-remote, which refuses a token that can be guessed: one made now.
TOKEN = secrets.token_hex(32)
AUTH = {"Authorization": f"Bearer {TOKEN}"}


def plant_spec(tmp_path: Path) -> tuple[Path, int]:
    port = free_port(*DEVICES)
    spec = tmp_path / "plant.toml"
    spec.write_text(f'addresses = "{DEVICES[0]}-{DEVICES[-1]}"\nport = {port}\nio_port = 0\nstate_dir = "state"\n'
                    f'[[device]]\nprofile = "acg"\ncount = 6\n')
    return spec, port


def start_fleet(tmp_path: Path, spec: Path, shard: int, name: str) -> tuple[Fleet, tuple[str, int]]:
    host = API_HOSTS[shard]
    http = free_port(host)
    fleet = Fleet(tmp_path, "--spec", str(spec), "--shard", f"{shard}/3", "--http", f"{host}:{http}",
                  "--http-token", TOKEN, "--http-allow-remote", name=name)
    return fleet, (host, http)


async def get(session: aiohttp.ClientSession, base: str, path: str) -> tuple[int, Any]:
    async with session.get(base + path) as reply:
        return reply.status, await (reply.json() if reply.content_type == "application/json" else reply.text())


async def until(check: Any, timeout: float = 15.0) -> None:
    deadline = time.monotonic() + timeout
    while not await check():
        assert time.monotonic() < deadline, "the plant view did not show it in time"
        await asyncio.sleep(0.1)


async def test_one_view_of_every_fleet_and_one_that_is_gone(tmp_path: Path) -> None:
    spec, _ = plant_spec(tmp_path)
    started = [start_fleet(tmp_path, spec, shard, f"fleet{shard}") for shard in range(3)]
    fleets = [fleet for fleet, _ in started]
    present = [where for _, where in started]
    asked: list[tuple[str, int]] = []

    async def resolver(name: str, port: int) -> list[tuple[str, int]]:
        asked.append((name, port))
        return list(present)

    view = None
    try:
        for fleet in fleets:
            await asyncio.to_thread(fleet.wait_ready)
        relay = RelayApi([], "127.0.0.1", 0, token=TOKEN, shard=None)
        view = PlantView([("cipstack-fleet", 8080)], relay, resolver, token=TOKEN, refresh=0.2)
        await view.start()
        base = f"http://127.0.0.1:{relay.port}"
        async with aiohttp.ClientSession(headers=AUTH) as session:
            status, listed = await get(session, base, "/devices")
            assert status == 200 and asked[0] == ("cipstack-fleet", 8080)
            assert [(d["address"], d["fleet"]) for d in listed] == [
                (address, f"{present[n // 2][0]}:{present[n // 2][1]}") for n, address in enumerate(DEVICES)]
            assert not any("error" in d for d in listed)
            for address in (DEVICES[0], DEVICES[3], DEVICES[5]):
                status, body = await get(session, base, f"/devices/{address}/status")
                assert status == 200 and body["power"] == "on", body
            status, text = await get(session, base, "/metrics")
            families = {f.name: f for f in text_string_to_metric_families(text)}
            assert sorted((s.labels["shard"], s.value) for s in families["cipstack_fleet_devices"].samples) == [
                ("0/3", 2), ("1/3", 2), ("2/3", 2)]
            assert sorted(s.labels["device"] for s in families["cipstack_powered"].samples) == DEVICES

            # A fleet that is killed: its devices are listed with why, and answer 503 naming it.
            fleets[1].kill()

            async def killed_shown() -> bool:
                _, listed = await get(session, base, "/devices")
                return all("does not answer" in d.get("error", "") for d in listed if d["address"] in DEVICES[2:4])
            await until(killed_shown)
            status, body = await get(session, base, f"/devices/{DEVICES[2]}/status")
            assert status == 503 and body["device"] == DEVICES[2]
            assert f"fleet {present[1][0]}:{present[1][1]}" in body["error"], body
            status, body = await get(session, base, f"/devices/{DEVICES[0]}/status")
            assert status == 200

            # A fleet no longer in the records (its pod deleted): shown as gone.
            gone = present.pop(2)

            async def gone_shown() -> bool:
                _, listed = await get(session, base, "/devices")
                return all("is gone" in d.get("error", "") for d in listed if d["address"] in DEVICES[4:])
            await until(gone_shown)
            status, body = await get(session, base, f"/devices/{DEVICES[4]}/status")
            assert status == 503 and f"fleet {gone[0]}:{gone[1]} is gone" in body["error"], body

            # The killed shard comes back at another address (a new pod): its devices are served again, once.
            fleet, where = start_fleet(tmp_path, spec, 1, "fleet1-again")
            fleets.append(fleet)
            await asyncio.to_thread(fleet.wait_ready)
            present[1] = where

            async def back() -> bool:
                _, listed = await get(session, base, "/devices")
                mine = [d for d in listed if d["address"] in DEVICES[2:4]]
                return len(mine) == 2 and all(d["fleet"] == f"{where[0]}:{where[1]}" and "error" not in d
                                              for d in mine)
            await until(back)
            _, listed = await get(session, base, "/devices")
            assert sorted(d["address"] for d in listed) == DEVICES   # each once
            status, body = await get(session, base, f"/devices/{DEVICES[3]}/status")
            assert status == 200, body
    finally:
        if view is not None:
            await view.close()
        for fleet in fleets:
            fleet.stop()
            fleet.kill()


async def test_the_system_resolver_gives_every_address_of_a_name() -> None:
    assert await resolve_addresses("127.83.2.1", 8080) == [("127.83.2.1", 8080)]
    assert ("127.0.0.1", 9) in await resolve_addresses("localhost", 9)
    assert await resolve_addresses("no-such-fleet.invalid", 8080) == []


def test_the_command_serves_the_fleets_it_names(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["plant", "--fleet", "cipstack-fleet", "--http", "127.0.0.1:0"]) == 2
    assert "--fleet 'cipstack-fleet' is not NAME:PORT" in capsys.readouterr().err
    spec, _ = plant_spec(tmp_path)
    fleet, (host, http) = start_fleet(tmp_path, spec, 0, "fleet0")
    plant_port = free_port()
    plant = None
    try:
        fleet.wait_ready()
        err = (tmp_path / "plant.err").open("w")
        plant = subprocess.Popen([sys.executable, "-m", "cipstack", "plant", "--fleet", f"{host}:{http}", "--http",
                                  f"127.0.0.1:{plant_port}", "--http-token", TOKEN], stderr=err,
                                 stdout=subprocess.DEVNULL, stdin=subprocess.DEVNULL)
        deadline = time.monotonic() + 30
        while "plant view of" not in (tmp_path / "plant.err").read_text():
            assert plant.poll() is None and time.monotonic() < deadline, (tmp_path / "plant.err").read_text()
            time.sleep(0.05)
        assert "2 devices in 1 fleets" in (tmp_path / "plant.err").read_text()

        async def listed() -> list[str]:
            async with aiohttp.ClientSession(headers=AUTH) as session:
                status, devices = await get(session, f"http://127.0.0.1:{plant_port}", "/devices")
                assert status == 200
                return [d["address"] for d in devices]
        assert asyncio.run(listed()) == DEVICES[:2]
        plant.terminate()
        assert plant.wait(15) == 0
    finally:
        if plant is not None and plant.poll() is None:
            plant.kill()
        fleet.stop()
        fleet.kill()
