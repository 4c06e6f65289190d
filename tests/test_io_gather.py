"""Datagrams gathered for the next firing (``IoEndpoint``'s ``gather_within``): while a firing is
near, an arriving datagram does not wake the loop; the firing reads every datagram that came before
it produces. A firing far off, or none, and the socket wakes the loop as before."""

from __future__ import annotations

import asyncio
import socket
from typing import Any

from cipstack.eip.io_server import GATHER_WITHIN_S, IoEndpoint
from cipstack.eip.precise_loop import precise_event_loop


class LoggingCore:
    """An ``IoCore`` that logs, in order, each datagram it is given and each production firing; it
    fires every ``period`` from ``deadline`` on, ``firings`` times (then it has no deadline)."""

    def __init__(self, period: float, firings: int) -> None:
        self.period = period
        self.firings = firings
        self.log: list[tuple[str, bytes | int]] = []
        self.deadline: float | None = None

    def receive(self, raw: bytes, source: tuple[str, int], now: float) -> None:
        self.log.append(("datagram", raw))

    def poll(self, now: float, horizon: float = 0.0) -> list[tuple[bytes, tuple[str, int]]]:
        if self.deadline is None or now < self.deadline:
            return []
        fired = sum(1 for kind, _ in self.log if kind == "firing") + 1
        self.log.append(("firing", fired))
        self.deadline = self.deadline + self.period if fired < self.firings else None
        return []

    def next_deadline(self) -> float | None:
        return self.deadline

    def expire(self, now: float) -> list[Any]:
        return []

    def firings_done(self) -> int:
        return sum(1 for kind, _ in self.log if kind == "firing")


async def _until(check: Any, limit: float = 5.0) -> None:
    loop = asyncio.get_running_loop()
    end = loop.time() + limit
    while not check():
        assert loop.time() < end, "the condition never came"
        await asyncio.sleep(0.005)


def _run(scenario: Any) -> Any:
    loop = precise_event_loop()
    try:
        return loop.run_until_complete(scenario())
    finally:
        loop.close()


def test_a_datagram_waits_for_the_near_firing_and_is_read_before_it_produces() -> None:
    # A firing every 0.4 s, gathered within 1 s: after the first firing, a datagram sent at once is
    # still unread 0.1 s later (nothing woke the loop for it), and the next firing reads it first.
    async def scenario() -> list[tuple[str, bytes | int]]:
        core = LoggingCore(period=0.4, firings=3)
        endpoint = IoEndpoint(core, "127.0.0.1", 0, gather_within=1.0)
        await endpoint.start()
        out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            core.deadline = asyncio.get_running_loop().time()
            endpoint.wakeup()
            await _until(lambda: core.firings_done() == 1)
            out.sendto(b"first", ("127.0.0.1", endpoint.port))
            out.sendto(b"second", ("127.0.0.1", endpoint.port))
            await asyncio.sleep(0.1)
            unread = list(core.log)
            await _until(lambda: core.firings_done() == 2)
            assert unread == [("firing", 1)], unread
            return core.log
        finally:
            out.close()
            await endpoint.close()

    assert _run(scenario) == [("firing", 1), ("datagram", b"first"), ("datagram", b"second"), ("firing", 2)]


def test_a_datagram_wakes_the_loop_when_the_next_firing_is_far_or_there_is_none() -> None:
    # Gathered within 10 ms, firings 5 s apart: a datagram is read as it comes, between firings;
    # after the last firing (no deadline left) too.
    async def scenario() -> list[tuple[str, bytes | int]]:
        core = LoggingCore(period=5.0, firings=2)
        endpoint = IoEndpoint(core, "127.0.0.1", 0, gather_within=0.010)
        await endpoint.start()
        out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            core.deadline = asyncio.get_running_loop().time()
            endpoint.wakeup()
            await _until(lambda: core.firings_done() == 1)
            out.sendto(b"between", ("127.0.0.1", endpoint.port))
            await _until(lambda: len(core.log) == 2)
            return core.log
        finally:
            out.close()
            await endpoint.close()

    assert _run(scenario) == [("firing", 1), ("datagram", b"between")]

    async def after_the_last() -> list[tuple[str, bytes | int]]:
        core = LoggingCore(period=0.001, firings=1)
        endpoint = IoEndpoint(core, "127.0.0.1", 0, gather_within=1.0)
        await endpoint.start()
        out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            core.deadline = asyncio.get_running_loop().time()
            endpoint.wakeup()
            await _until(lambda: core.firings_done() == 1)
            out.sendto(b"after", ("127.0.0.1", endpoint.port))
            await _until(lambda: len(core.log) == 2)
            return core.log
        finally:
            out.close()
            await endpoint.close()

    assert _run(after_the_last) == [("firing", 1), ("datagram", b"after")]


def test_the_adapter_gathers_when_told_and_asyncio_own_loop_reads_each_datagram() -> None:
    from cipstack.adapter import Adapter, AdapterSettings

    default, gathering = Adapter(), Adapter(AdapterSettings(io_gather=GATHER_WITHIN_S))
    assert default.io_endpoint is not None and gathering.io_endpoint is not None
    assert (default.io_endpoint.gather_within, gathering.io_endpoint.gather_within) == (0.0, GATHER_WITHIN_S)

    async def off_the_lane() -> float:
        endpoint = IoEndpoint(LoggingCore(0.01, 1), "127.0.0.1", 0, gather_within=GATHER_WITHIN_S)
        await endpoint.start()
        try:
            return endpoint.gather_within
        finally:
            await endpoint.close()

    loop = asyncio.new_event_loop()
    try:
        assert loop.run_until_complete(off_the_lane()) == 0.0
    finally:
        loop.close()


async def test_a_gathering_adapter_serves_a_scanner_both_ways_at_rpi_2ms() -> None:
    # The adapter with io_gather, a scanner at RPI 2 ms: the drive's input comes, the output reaches
    # the drive, nothing is lost and no watchdog runs out on either side.
    from cipstack.adapter import Adapter, AdapterSettings
    from cipstack.devices.profiles import PROFILES
    from cipstack.scanner import Scanner

    adapter = Adapter(AdapterSettings(host="127.0.0.1", port=0, io_port=0, io_gather=GATHER_WITHIN_S))
    await adapter.start()
    make_catalog = PROFILES["acg"].catalog
    assert make_catalog is not None and adapter.io_endpoint is not None and adapter.io is not None
    try:
        async with await Scanner.connect(f"127.0.0.1:{adapter.port}", catalog=make_catalog()) as scanner, \
                scanner.io_connection(output=21, input=71, rpi=0.002, timeout_multiplier=5,
                                      target_io_port=adapter.io_endpoint.port) as io:
            io.output.run_forward = True
            io.output.speed_reference = 900
            assert (await io.wait_input(lambda i: i.ready, timeout=5)).ready
            await _until(lambda: io.stats.sent > 200 and io.stats.received > 200)
            # What the drive holds in its output assembly (4/21/3) is what the scanner sends.
            assert (await scanner.get_attribute_single(4, 21, 3)).data == bytes.fromhex("01008403")
            assert io.stats.lost == 0 and not io.timed_out
            assert adapter.io.timeouts == 0
    finally:
        await adapter.close()


def test_a_bad_io_gather_is_one_line_and_no_traceback() -> None:
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-m", "cipstack", "adapter", "--io-gather", "soon"], capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert done.stderr.strip().splitlines()[-1] == \
        "cipstack adapter: error: 'soon' is not a duration (e.g. 2, 500ms, 1.5s)"
