"""The supervisor's comm-loss handling, tested against an emulated ACG drive (``cipstack.testing``).

Run with ``python3 -m pytest examples/comm_loss`` (the plugin loads itself once cipstack is
installed; from a checkout, add ``-p cipstack.testing``). The async tests run on pytest-asyncio."""

from __future__ import annotations

import asyncio

import pytest
from supervisor import supervise

from cipstack.testing import EmulatedDevice

pytestmark = pytest.mark.cip_adapter(params=["drv=4", "Frq=8"])   # run and speed from the network


async def run_supervisor(drive: EmulatedDevice, states: list[str]) -> tuple[asyncio.Task[None], asyncio.Event]:
    stop = asyncio.Event()
    task = asyncio.create_task(supervise(drive.address, drive.io_port, 900, states.append, stop))
    return task, stop


async def wait_state(states: list[str], state: str, count: int = 1, timeout: float = 5.0) -> None:
    async def until() -> None:
        while states.count(state) < count:
            await asyncio.sleep(0.01)
    await asyncio.wait_for(until(), timeout)


@pytest.mark.asyncio
async def test_comm_loss_is_seen_and_the_drive_is_driven_again(cip_adapter: EmulatedDevice) -> None:
    states: list[str] = []
    task, stop = await run_supervisor(cip_adapter, states)
    try:
        await wait_state(states, "running")
        cip_adapter.fault("stop-producing", for_=0.3)
        await wait_state(states, "comm lost")
        await wait_state(states, "running", 2)
        # The drive got its command again: it runs toward 900 rpm (30 Hz).
        assert cip_adapter.status()["drive"]["reference_hz"] == 30.0
    finally:
        stop.set()
        await task
    assert states[:3] == ["running", "comm lost", "running"]


@pytest.mark.asyncio
async def test_refused_forward_opens_are_retried(cip_adapter: EmulatedDevice) -> None:
    cip_adapter.fault("refuse-forward-open", status=0x0113, count=2)
    states: list[str] = []
    task, stop = await run_supervisor(cip_adapter, states)
    try:
        await wait_state(states, "running")
    finally:
        stop.set()
        await task
    assert states == ["refused 0x0113", "running"]
    opened = [e for e in cip_adapter.events() if e.kind == "connection opened"]
    assert len(opened) == 1


@pytest.mark.asyncio
async def test_a_pulled_cable_and_its_return(cip_adapter: EmulatedDevice) -> None:
    states: list[str] = []
    task, stop = await run_supervisor(cip_adapter, states)
    try:
        await wait_state(states, "running")
        cip_adapter.fault("unplug")
        await wait_state(states, "comm lost")
        await cip_adapter.event("connection timed out")                 # the drive saw it too
        await wait_state(states, "unreachable")
        cip_adapter.fault("plug")
        await wait_state(states, "running", 2)
    finally:
        stop.set()
        await task
    assert states == ["running", "comm lost", "unreachable", "running"]


def test_sync_tests_get_the_device_too(cip_adapter: EmulatedDevice, cip_scanner) -> None:  # type: ignore[no-untyped-def]
    assert cip_scanner.read(0x01, 1, 1) == 259
    cip_adapter.fault("error-status", status="0x08", attribute=1, **{"class": 1})
    with pytest.raises(Exception, match="0x08"):
        cip_scanner.read(0x01, 1, 1)
    cip_adapter.clear_faults()
    assert cip_scanner.read(0x01, 1, 1) == 259
