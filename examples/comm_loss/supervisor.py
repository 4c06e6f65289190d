"""A small scanner program: it runs a drive at a speed over class 1 and rides out losing it.

``supervise`` keeps a class 1 connection (assemblies 21/71, RPI 10 ms, timeout 80 ms) to the drive
and reports each change of its own state to ``report``: ``running`` while the drive answers,
``comm lost`` when the connection times out, ``refused 0x....`` when a Forward_Open is refused,
``unreachable`` when nothing answers; after a loss it tries again every ``retry`` seconds and, once
connected, commands the same speed again. The example suite next to it (test_supervisor.py) tests
this handling against an emulated drive whose faults it injects."""

from __future__ import annotations

import asyncio
from collections.abc import Callable

from cipstack.cip.status import CipError
from cipstack.devices.profiles import catalog_for
from cipstack.eip.originator.io_originator import IoTimeoutError
from cipstack.scanner import Scanner

CATALOG = catalog_for(259, 100)   # the ACG-ET2's assemblies


async def _until_lost_or_stopped(io: object, stop: asyncio.Event) -> None:
    """Follow the input until the connection times out (``IoTimeoutError``) or ``stop`` is set."""
    async def follow() -> None:
        async for _ in io.updates():  # type: ignore[attr-defined]
            pass

    following = asyncio.create_task(follow())
    stopping = asyncio.create_task(stop.wait())
    done, _ = await asyncio.wait({following, stopping}, return_when=asyncio.FIRST_COMPLETED)
    stopping.cancel()
    if following in done:
        following.result()
    else:
        following.cancel()


async def supervise(address: str, io_port: int, speed_rpm: int, report: Callable[[str], None],
                    stop: asyncio.Event, retry: float = 0.1) -> None:
    last = None

    def say(state: str) -> None:
        nonlocal last
        if state != last:
            last = state
            report(state)

    while not stop.is_set():
        try:
            scanner = await Scanner.connect(address, catalog=CATALOG, timeout=1.0)
        except (OSError, asyncio.TimeoutError):
            say("unreachable")
            await asyncio.sleep(retry)
            continue
        try:
            async with scanner, scanner.io_connection(output=21, input=71, rpi=0.010, timeout_multiplier=1,
                                                      target_io_port=io_port) as io:
                io.output.speed_reference = speed_rpm
                io.output.run_forward = True
                await io.wait_input(lambda image: True, 2)
                say("running")
                await _until_lost_or_stopped(io, stop)
        except IoTimeoutError:
            say("comm lost")
        except CipError as exc:
            say(f"refused 0x{exc.extended[0]:04X}" if exc.extended else f"refused 0x{exc.general:02X}")
        except (OSError, asyncio.TimeoutError):
            say("unreachable")
        if not stop.is_set():
            await asyncio.sleep(retry)
