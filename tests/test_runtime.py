"""One device runtime (``cipstack.runtime``): every port follows one power and link state.

A power cycle closes every Ethernet port (EtherNet/IP TCP and UDP, Modbus TCP, the class 1 UDP
socket) and silences the RS-485 line, whose tty stays open; a ``plug`` while the power is off opens
nothing; when the power returns every port opens once and the device goes on. Each surface answers a
power cycle while the power is still off, and says so. Everything is observed from outside: sockets
that connect or are refused, a port number another socket can bind, a Modbus-RTU request on the pty
that is answered or not."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import socket
import tty
from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.control import scenario as scenarios
from cipstack.control.operations import OPERATIONS
from cipstack.devices.acg.modbus_rtu import with_crc
from cipstack.devices.acg.registers import ACG_REGISTERS
from cipstack.errors import BadRequest
from cipstack.faults import FaultStateError
from tests.optional import needs
from tests.waiting import wait_until

#: Modbus-RTU, station 1, Read Holding Registers (0x03) of ACC, one register: the PDU address is the
#: communication address minus one (as ``test_keypad`` writes it).
ACC = ACG_REGISTERS.by_code("ACC").address - 1
READ_ACC = with_crc(bytes.fromhex("01 03") + ACC.to_bytes(2, "big") + (1).to_bytes(2, "big"))


def refused(port: int) -> bool:
    try:
        socket.create_connection(("127.0.0.1", port), timeout=1).close()
    except ConnectionRefusedError:
        return True
    return False


def udp_port_free(port: int) -> bool:
    """Whether a UDP socket can bind ``127.0.0.1:port`` exclusively: nobody holds it."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


async def rtu_answer(fd: int, request: bytes, wait: float) -> bytes:
    """What comes back on the pty within ``wait`` seconds of writing ``request`` (b"" for silence)."""
    with contextlib.suppress(BlockingIOError):
        os.read(fd, 1024)                                   # whatever an earlier request left
    os.write(fd, request)
    answer = b""
    loop = asyncio.get_running_loop()
    until = loop.time() + wait
    while loop.time() < until:
        await asyncio.sleep(0.02)
        with contextlib.suppress(BlockingIOError):
            answer += os.read(fd, 1024)
        if len(answer) >= 7:                                # station, 0x03, 2, two bytes, CRC
            break
    return answer


@pytest.fixture
async def acg(tmp_path: Path) -> AsyncIterator[Adapter]:
    needs("aiohttp")  # the adapter serves its HTTP API too
    adapter = Adapter(AdapterSettings(port=0, io_port=0, modbus_port=0, rtu="pty", state_path=tmp_path / "acg.json",
                                      control_path=tmp_path / "control.sock", http="127.0.0.1:0"))
    await adapter.start_serving()
    try:
        yield adapter
    finally:
        await adapter.faults.settle()
        await adapter.stop_serving()


async def test_a_power_cycle_closes_every_port_and_silences_rs485(acg: Adapter) -> None:
    assert acg.modbus is not None and acg.rtu is not None and acg.io_endpoint is not None
    port, modbus, io_port = acg.port, acg.modbus.port, acg.io_endpoint.port
    fd = os.open(acg.rtu.name, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    tty.setraw(fd)
    try:
        answer = await rtu_answer(fd, READ_ACC, 2.0)
        assert answer[:3] == bytes.fromhex("01 03 02")                          # powered: answered
        await acg.service.call_async("power", {"action": "cycle", "off": "30s"})   # answers within 2 s
        assert acg.service.status()["power"] == "off"
        assert refused(port) and refused(modbus)                                # TCP: nobody listens
        assert udp_port_free(port) and udp_port_free(io_port)                   # UDP 44818 and class 1: gone
        assert await rtu_answer(fd, READ_ACC, 0.5) == b""                       # RS-485: silent, tty open
        await acg.service.call_async("clear", {})                               # ends the off period
        await acg.faults.settle()                                               # the power is back
        assert acg.service.status()["power"] == "on"
        assert not refused(port) and not refused(modbus)
        assert not udp_port_free(io_port) and acg.io_endpoint.port == io_port    # the same numbers again
        assert (await rtu_answer(fd, READ_ACC, 2.0))[:3] == bytes.fromhex("01 03 02")
    finally:
        os.close(fd)


async def test_unplug_closes_the_ethernet_ports_and_rs485_goes_on(acg: Adapter) -> None:
    assert acg.rtu is not None and acg.io_endpoint is not None
    fd = os.open(acg.rtu.name, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    tty.setraw(fd)
    try:
        await acg.service.call_async("link", {"state": "unplug"})
        status = acg.service.status()
        assert (status["power"], status["link"]) == ("on", "unplugged")
        assert refused(acg.port) and udp_port_free(acg.io_endpoint.port)
        assert (await rtu_answer(fd, READ_ACC, 2.0))[:3] == bytes.fromhex("01 03 02")   # the cable is Ethernet's
        await acg.service.call_async("link", {"state": "plug"})
        assert not refused(acg.port) and acg.service.status()["link"] == "plugged"
    finally:
        os.close(fd)


async def test_plug_while_the_power_is_off_opens_nothing_and_the_power_opens_each_port_once(
        acg: Adapter, caplog: pytest.LogCaptureFixture) -> None:
    assert acg.modbus is not None
    acg.fault("unplug")
    await acg.faults.settle()
    acg.fault("power-cycle", off="0.6s")
    await wait_until(lambda: acg.service.status()["power"] == "off", 5, "the power off")
    caplog.clear()
    with caplog.at_level(logging.INFO):
        acg.fault("plug")                                                   # while the power is off
        await asyncio.sleep(0.1)       # the subject: the plug opens nothing meanwhile
        assert refused(acg.port) and refused(acg.modbus.port)              # no power: still closed
        await acg.faults.settle()
    opened = [r.getMessage() for r in caplog.records if r.getMessage().startswith(
        ("EtherNet/IP target listening", "Modbus TCP on", "class 1 I/O on"))]
    assert len(opened) == 3, opened                                         # each port once
    assert not [r for r in caplog.records if r.levelno >= logging.ERROR]   # no EADDRINUSE, nothing failed
    assert not refused(acg.port) and not refused(acg.modbus.port)


async def test_http_answers_a_long_power_cycle_while_the_power_is_off_and_clear_ends_it(acg: Adapter) -> None:
    aiohttp = needs("aiohttp")
    base = f"http://127.0.0.1:{acg.http_api.port}"
    async with aiohttp.ClientSession() as session:
        async with session.post(base + "/faults", json={"name": "power-cycle", "options": {"off": "60s"}}) as reply:
            assert reply.status == 201
            fault = await reply.json()
        async with session.get(base + "/status") as reply:
            assert (await reply.json())["power"] == "off"                   # answered while off
        async with session.get(base + "/faults") as reply:
            listed = await reply.json()
        assert [f["name"] for f in listed] == ["power-cycle"] and listed[0]["remaining_s"] > 50
        async with session.delete(base + f"/faults/{fault['id']}") as reply:
            assert reply.status == 200
        await acg.faults.settle()
        async with session.get(base + "/status") as reply:
            assert (await reply.json())["power"] == "on"                    # clearing ended the off period
    assert not refused(acg.port)
    kinds = [r["event"] for r in acg.faults.history]
    assert kinds == ["fault applied", "fault cleared"]


async def test_an_absurd_off_time_is_refused_and_a_second_cycle_while_off_too(acg: Adapter) -> None:
    with pytest.raises(BadRequest, match="3600s the power may stay off"):
        acg.fault("power-cycle", off="4000s")
    acg.fault("power-cycle", off="0.3s")
    with pytest.raises(FaultStateError, match="powered off already"):
        acg.fault("power-cycle")


async def test_a_scenario_line_carries_the_time_its_step_fired(acg: Adapter, tmp_path: Path) -> None:
    """A power cycle of 3 s fired at 0.2 s is said at 0.2 s, not when its ports settled."""
    path = tmp_path / "cycle.toml"
    path.write_text('[[step]]\nname = "cycle"\nat = "0.2s"\nfault = "power-cycle"\noptions = { off = "3s" }\n\n'
                    '[[step]]\nname = "back"\nat = "0.5s"\nclear = true\n', encoding="utf-8")
    lines: list[str] = []
    assert await scenarios.run(acg.service, scenarios.load(path), lines.append)
    fired = next(line for line in lines if "cycle fired" in line)
    assert 0.2 <= float(fired.split("s", 1)[0]) < 2.0, lines


async def test_every_operation_is_on_every_surface(acg: Adapter, capsys: pytest.CaptureFixture[str]) -> None:
    """The HTTP routes, the OpenAPI document and the command line's subcommands are the operations."""
    aiohttp = needs("aiohttp")
    from cipstack.cli.parser import build_parser
    from cipstack.control.http import openapi_document

    document = openapi_document()
    operation_ids = {op["operationId"] for path in document["paths"].values() for op in path.values()}
    async with aiohttp.ClientSession() as session:
        for operation in OPERATIONS:
            assert operation.name in operation_ids
            with pytest.raises(SystemExit) as shown:                     # `cipstack drive OPERATION --help`
                build_parser("drive").parse_args(["drive", operation.name, "--help"])
            assert shown.value.code == 0
            assert f"drive {operation.name}" in capsys.readouterr().out
            path = operation.path.replace("{code}", "ACC").replace("{fault}", "1")
            async with session.request("OPTIONS", f"http://127.0.0.1:{acg.http_api.port}{path}") as reply:
                assert reply.status != 404, (operation.name, path)


async def test_a_trip_and_its_reset_on_each_family(tmp_path: Path) -> None:
    """``reset``: the ACG's Drive Fault Reset, the MX2/RX operator's STOP/RESET key; the trip is gone
    from the drive's own status, and a reset with no trip says so."""
    for profile, code in (("acg", "OverHeat"), ("mx2", "E05"), ("rx", "E05")):
        adapter = Adapter(AdapterSettings(port=0, io_port=0, profile=profile, state_path=tmp_path / f"{profile}.json"))
        await adapter.start()
        try:
            tripped = adapter.service.call("trip", {"code": code})
            assert adapter.service.status()["drive"]["trip"] is not None, tripped
            reset = adapter.service.call("reset", {})
            assert reset["cleared"] == tripped["trip"] and adapter.service.status()["drive"]["trip"] is None
            assert adapter.service.call("reset", {})["result"] == "reset: no trip to clear"
        finally:
            await adapter.close()


async def test_arguments_are_checked_against_the_declaration_on_every_surface(acg: Adapter) -> None:
    """A key the operation does not take, a missing one and a value of the wrong JSON type are each a bad
    request naming the JSON key, from the service and through HTTP and the control socket alike."""
    aiohttp = needs("aiohttp")
    from cipstack.control import ControlRefused, control_request

    for arguments, said in (({"code": [1]}, '"code" is a string or integer'), ({}, 'needs "code"'),
                            ({"code": 1, "cod": 2}, "unknown key 'cod'")):
        with pytest.raises(BadRequest, match=said):
            acg.service.call("trip", arguments)
        async with aiohttp.ClientSession() as session, \
                session.post(f"http://127.0.0.1:{acg.http_api.port}/trip", json=arguments) as reply:
            assert reply.status == 400 and said in (await reply.json())["error"]
        with pytest.raises(ControlRefused, match=said):
            await asyncio.to_thread(control_request, acg.control_path, {"command": "trip", **arguments})
    async with aiohttp.ClientSession() as session, \
            session.get(f"http://127.0.0.1:{acg.http_api.port}/events?since=x") as reply:
        assert reply.status == 400 and "since" in (await reply.json())["error"]


async def test_an_interrupted_scenario_says_so_and_which_steps_did_not_fire(acg: Adapter, tmp_path: Path) -> None:
    """SIGINT or SIGTERM cancels the scenario's task: its last line says it was interrupted and names
    the steps still waiting, never that every step fired; no fault is left active."""
    path = tmp_path / "long.toml"
    path.write_text('[[step]]\nname = "first"\nat = "0s"\nfault = "stop-producing"\n\n'
                    '[[step]]\nname = "later"\nat = "60s"\nclear = true\n\n'
                    '[[step]]\nname = "last"\nat = "61s"\ntrip = "OverHeat"\n', encoding="utf-8")
    lines: list[str] = []
    task = asyncio.create_task(scenarios.run(acg.service, scenarios.load(path), lines.append))
    while not any("first fired" in line for line in lines):
        await asyncio.sleep(0.01)
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task
    assert lines[-1].endswith("scenario interrupted: 2 step(s) did not fire (later, last); no fault left active")
    assert acg.faults.faults() == []
