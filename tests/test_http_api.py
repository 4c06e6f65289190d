"""The HTTP control API (cipstack.control.http) of a running ACG emulator, with a real HTTP client
(aiohttp's) over loopback: status, faults, events and keypad parameters as JSON; bad requests get a
JSON body with the status that says why, and the API goes on serving."""

from __future__ import annotations

import json
from collections.abc import AsyncIterator
from pathlib import Path

import pytest

pytest.importorskip("aiohttp", reason="aiohttp is not installed (the http extra): pip install '.[http]'")

import aiohttp

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.control.http import (
    DEVICE_PREFIX,
    DEVICE_ROUTES,
    MAX_BODY,
    HttpApi,
    HttpApiError,
    check_settings,
    openapi_document,
)
from cipstack.control.http_relay import RelayApi
from cipstack.scanner import Scanner
from tests.http_client import call


@pytest.fixture
async def adapter(tmp_path: Path) -> AsyncIterator[Adapter]:
    running = Adapter(AdapterSettings(port=0, io_port=0, state_path=tmp_path / "acg.json",
                                      control_path=tmp_path / "control.sock", http="127.0.0.1:0"))
    await running.start_serving()
    yield running
    await running.faults.settle()
    await running.stop_serving()


@pytest.fixture
async def http(adapter: Adapter) -> AsyncIterator[tuple[aiohttp.ClientSession, str]]:
    async with aiohttp.ClientSession() as session:
        yield session, f"http://127.0.0.1:{adapter.http_api.port}"


async def test_status_faults_and_events(adapter: Adapter, http: tuple[aiohttp.ClientSession, str]) -> None:
    status, body = await call(http, "GET", "/status")
    assert status == 200 and body["drive"]["state"] == "READY" and body["faults"] == 0  # type: ignore[index]
    status, fault = await call(http, "POST", "/faults", json={"name": "error-status",
                                                              "options": {"status": "0x08", "class": 1}})
    assert status == 201 and fault["name"] == "error-status" and fault["options"]["status"] == "0x08"  # type: ignore[index]
    async with await Scanner.connect(f"127.0.0.1:{adapter.port}") as scanner:
        with pytest.raises(Exception, match="0x08"):
            await scanner.read(0x01, 1, 1)
    status, listed = await call(http, "GET", "/faults")
    assert status == 200 and [f["id"] for f in listed] == [fault["id"]]  # type: ignore[index, union-attr]
    status, cleared = await call(http, "DELETE", f"/faults/{fault['id']}")  # type: ignore[index]
    assert status == 200 and len(cleared) == 1  # type: ignore[arg-type]
    status, events = await call(http, "GET", "/events?since=0")
    assert status == 200 and [e["kind"] for e in events][-2:] == ["fault applied", "fault cleared"]  # type: ignore[index, union-attr]
    last = events[-1]["number"]  # type: ignore[index]
    status, none = await call(http, "GET", f"/events?since={last}")
    assert (status, none) == (200, [])
    # The same routes under the device's address; another address is not here.
    assert (await call(http, "GET", "/devices/127.0.0.1/faults")) == (200, [])
    status, missing = await call(http, "GET", "/devices/127.0.0.9/status")
    assert status == 404 and missing["devices"] == ["127.0.0.1"]  # type: ignore[index]
    status, devices = await call(http, "GET", "/devices")
    assert status == 200 and devices[0]["address"] == "127.0.0.1" and devices[0]["port"] == adapter.port  # type: ignore[index]


async def test_bad_requests_get_json_and_the_api_goes_on(adapter: Adapter,
                                                         http: tuple[aiohttp.ClientSession, str]) -> None:
    status, body = await call(http, "POST", "/faults", data=b"{not json", headers={"Content-Type": "application/json"})
    assert status == 400 and body == {"error": "the body is not JSON"}
    status, body = await call(http, "POST", "/faults", json=["stop-producing"])
    assert status == 400 and body == {"error": "the body is a JSON object"}
    status, body = await call(http, "POST", "/faults", json={"name": "stop"})
    assert status == 400 and body["error"].startswith("unknown fault 'stop'; valid: stop-producing, drop")  # type: ignore[index]
    status, body = await call(http, "POST", "/faults", json={"name": "drop", "share": 0.1})
    assert status == 400 and body["error"].startswith("unknown key 'share': the body is")  # type: ignore[index]
    status, body = await call(http, "POST", "/faults", json={"name": "drop", "options": {"shar": 0.1}})
    # A JSON API's errors name its JSON keys, never the command line's options.
    assert status == 400 and body["error"] == (  # type: ignore[index]
        'unknown option "shar" for drop; valid: "connection", "originator", "share", "every", "for"')
    status, body = await call(http, "POST", "/faults", json={"name": "stop-producing",
                                                             "options": {"connection": "0x12345678"}})
    assert status == 404 and body["error"].startswith("no class 1 connection 0x12345678")  # type: ignore[index]
    status, body = await call(http, "DELETE", "/faults/41")
    assert status == 404 and "no active fault 41" in body["error"]  # type: ignore[index]
    status, body = await call(http, "POST", "/faults", data=b"x" * (MAX_BODY + 1),
                              headers={"Content-Type": "application/json"})
    assert status == 413 and "error" in body  # type: ignore[operator]
    status, body = await call(http, "GET", "/events?since=x")
    assert status == 400
    status, body = await call(http, "GET", "/nowhere")
    assert status == 404 and "error" in body  # type: ignore[operator]
    status, body = await call(http, "POST", "/faults", json={"name": "plug"})
    assert status == 409 and body == {"error": "the device is not unplugged"}
    assert (await call(http, "GET", "/faults")) == (200, [])                 # still serving, nothing applied


async def test_keypad_parameters_and_trip(adapter: Adapter, http: tuple[aiohttp.ClientSession, str]) -> None:
    status, acc = await call(http, "GET", "/parameters/ACC")
    assert status == 200 and acc["code"] == "ACC" and acc["unit"] == "s"  # type: ignore[index]
    status, acc = await call(http, "PUT", "/parameters/ACC", json={"value": "2.5"})
    assert status == 200 and (acc["value"], acc["raw"]) == ("2.5", 25)  # type: ignore[index]
    status, drv = await call(http, "PUT", "/parameters/drv", json={"value": 4})
    assert status == 200 and drv["raw"] == 4  # type: ignore[index]
    status, body = await call(http, "GET", "/parameters/XYZ")
    assert status == 404 and "error" in body  # type: ignore[operator]
    status, body = await call(http, "PUT", "/parameters/ACC", json={"value": "lots"})
    assert status == 400 and "error" in body  # type: ignore[operator]
    status, body = await call(http, "PUT", "/parameters/ACC", json={})
    assert status == 400
    status, bad = await call(http, "POST", "/trip", json={"code": "0x9999"})
    assert status == 400 and "valid codes" in bad["error"]  # type: ignore[index]
    status, tripped = await call(http, "POST", "/trip", json={"code": "0x4200"})
    assert status == 200 and tripped["trip"] == "OverHeat"  # type: ignore[index]
    status, again = await call(http, "POST", "/trip", json={"code": "0x4200"})
    assert status == 409 and "already tripped" in again["error"]  # type: ignore[index]


async def test_openapi_and_token(adapter: Adapter) -> None:
    async with aiohttp.ClientSession() as session, \
            session.get(f"http://127.0.0.1:{adapter.http_api.port}/openapi.json") as response:
        document = await response.json()
    assert document == json.loads(json.dumps(openapi_document()))
    assert {"/status", "/faults", "/faults/{fault}", "/events", "/parameters/{code}", "/trip", "/devices",
            "/devices/{device}/faults"} <= set(document["paths"])
    api = HttpApi({"127.0.0.1": adapter.service}, "127.0.0.1", 0, token="s3cret")
    await api.start()
    try:
        async with aiohttp.ClientSession() as session:
            url = f"http://127.0.0.1:{api.port}/status"
            async with session.get(url) as response:
                assert response.status == 401 and "Bearer" in (await response.json())["error"]
            async with session.get(url, headers={"Authorization": "Bearer s3cret"}) as response:
                assert response.status == 200
    finally:
        await api.close()


def test_the_description_has_every_route_the_api_serves(adapter: Adapter) -> None:
    """The route table (``DEVICE_ROUTES``), ``/openapi.json`` and a fleet's relay name the same
    routes, at the top and under a device's address; the front panel's files besides."""
    paths = openapi_document()["paths"]
    served = {(method.lower(), prefix + path) for method, path, _ in DEVICE_ROUTES for prefix in ("", DEVICE_PREFIX)}
    described = {(method, path) for path, operations in paths.items() for method in operations}
    assert described == served | {("get", "/devices"), ("get", "/stream"), ("get", "/devices/{device}/stream"),
                                  ("get", "/metrics"), ("get", "/plant")}
    relay = RelayApi([], "127.0.0.1", 0)
    for app in (adapter.http_api.app, relay.app):                            # a fleet's relay serves the same
        routes = {(route.method.lower(), route.resource.canonical) for route in app.router.routes()
                  if route.resource is not None and route.method != "HEAD"}
        assert routes == described | {("get", "/openapi.json"), ("get", "/"), ("get", "/panel/{name}")}


def test_settings_refuse_other_addresses_without_a_token() -> None:
    assert check_settings("127.0.0.1:8080", None, False) == ("127.0.0.1", 8080)
    with pytest.raises(HttpApiError, match="not a loopback address"):
        check_settings("0.0.0.0:8080", None, False)
    with pytest.raises(HttpApiError, match="needs --http-token"):
        check_settings("0.0.0.0:8080", None, True)
    with pytest.raises(HttpApiError, match="not HOST:PORT"):
        check_settings("localhost", None, False)
