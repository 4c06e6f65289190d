"""The class 1 lane of the precise event loop: sockets read and timers fired inside the selector's
wait, beside asyncio's own sockets and timers on the same loop (``cipstack.eip.io_server``)."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
import threading
import time
from collections.abc import Coroutine, Iterator
from pathlib import Path
from typing import Any, TypeVar

import pytest

from cipstack.eip.io_server import DRAIN_LIMIT, RECEIVE_BUFFER, IoEndpoint
from cipstack.eip.precise_loop import FD_SETSIZE, HARVEST_EVENTS, PreciseEventLoop, precise_event_loop
from tests.waiting import wait_until

T = TypeVar("T")


class RecordingCore:
    """An ``IoCore`` that keeps what it receives and sends one datagram per firing to ``send_to``."""

    def __init__(self, period: float = 0.002, send_to: tuple[str, int] | None = None) -> None:
        self.period = period
        self.send_to = send_to
        self.received: list[bytes] = []
        #: The time each datagram was given with.
        self.times: list[float] = []
        self.polls: list[float] = []
        self.deadline: float | None = None
        self.fail_on: bytes | None = None

    def receive(self, raw: bytes, source: tuple[str, int], now: float) -> None:
        if raw == self.fail_on:
            raise RuntimeError("a core that fails on this datagram")
        self.received.append(raw)
        self.times.append(now)

    def poll(self, now: float, horizon: float = 0.0) -> list[tuple[bytes, tuple[str, int]]]:
        if self.deadline is None or now < self.deadline:
            return []
        self.polls.append(now)
        self.deadline += self.period
        return [(b"tick %d" % len(self.polls), self.send_to)] if self.send_to is not None else []

    def next_deadline(self) -> float | None:
        return self.deadline

    def expire(self, now: float) -> list[Any]:
        return []


def run_on(loop: asyncio.AbstractEventLoop, coroutine: Coroutine[Any, Any, T]) -> T:
    try:
        return loop.run_until_complete(coroutine)
    finally:
        loop.close()


def sender() -> socket.socket:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    return sock


async def started(core: RecordingCore) -> IoEndpoint:
    endpoint = IoEndpoint(core, "127.0.0.1", 0)
    await endpoint.start()
    return endpoint


def test_lane_timers_fire_in_order_never_early_and_a_cancelled_one_never() -> None:
    async def scenario() -> list[tuple[str, float, float]]:
        loop = asyncio.get_running_loop()
        assert isinstance(loop, PreciseEventLoop)
        lane = loop.selector.lane
        fired: list[tuple[str, float, float]] = []
        start = loop.time()
        for name, delay in (("c", 0.006), ("a", 0.002), ("b", 0.004)):
            when = start + delay
            lane.call_at(when, lambda name=name, when=when: fired.append((name, when, loop.time())))
        # Due with "a" and behind it in the heap: run_due meets it, not only next_deadline.
        lane.call_at(start + 0.002, lambda: fired.append(("cancelled", 0.0, 0.0))).cancel()
        await asyncio.sleep(0.05)
        return fired

    fired = run_on(precise_event_loop(), scenario())
    assert [name for name, _, _ in fired] == ["a", "b", "c"]
    assert all(at >= when for _, when, at in fired), fired


def test_lane_endpoint_reads_every_datagram_beside_asyncio_streams_on_the_same_loop() -> None:
    """More datagrams than one wake-up drains (``DRAIN_LIMIT``) arrive in order, while a TCP echo
    served by asyncio on the same loop goes on answering."""
    count = 3 * DRAIN_LIMIT + 5

    async def echo(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        writer.write(await reader.readexactly(4))
        await writer.drain()
        writer.close()

    async def scenario() -> tuple[list[bytes], bytes, bool]:
        core = RecordingCore()
        endpoint = await started(core)
        server = await asyncio.start_server(echo, "127.0.0.1", 0)
        out = sender()
        try:
            assert endpoint.transport is None                       # on the lane, no transport
            for index in range(count):
                out.sendto(b"datagram %d" % index, ("127.0.0.1", endpoint.port))
            reader, writer = await asyncio.open_connection(*server.sockets[0].getsockname()[:2])
            writer.write(b"ping")
            answer = await reader.readexactly(4)
            writer.close()
            for _ in range(200):
                if len(core.received) == count:
                    break
                await asyncio.sleep(0.01)
            return core.received, answer, endpoint.is_open
        finally:
            out.close()
            server.close()
            await endpoint.close()

    received, answer, was_open = run_on(precise_event_loop(), scenario())
    assert received == [b"datagram %d" % index for index in range(count)]
    assert answer == b"ping" and was_open


def test_lane_production_timer_sends_on_schedule_and_stops_at_close() -> None:
    async def scenario() -> tuple[list[float], list[bytes], int, bool]:
        listener = sender()
        listener.setblocking(False)
        core = RecordingCore(period=0.002, send_to=listener.getsockname())
        loop = asyncio.get_running_loop()
        core.deadline = loop.time() + 0.002
        endpoint = await started(core)
        await wait_until(lambda: len(core.polls) >= 5, 5, "five firings")
        await endpoint.close()
        polls_at_close = len(core.polls)
        await asyncio.sleep(0.02)
        received = []
        while True:
            try:
                received.append(listener.recv(100))
            except BlockingIOError:
                break
        listener.close()
        lane = loop.selector.lane  # type: ignore[attr-defined]
        return core.polls, received, polls_at_close, bool(lane.readers)

    polls, received, polls_at_close, readers_left = run_on(precise_event_loop(), scenario())
    assert len(polls) >= 5 and len(polls) == polls_at_close     # nothing fires after close()
    assert received == [b"tick %d" % (index + 1) for index in range(len(polls))]
    assert not readers_left


def test_lane_callback_that_raises_is_logged_and_the_loop_goes_on(caplog: pytest.LogCaptureFixture) -> None:
    async def scenario() -> tuple[list[bytes], list[str]]:
        loop = asyncio.get_running_loop()
        lane = loop.selector.lane  # type: ignore[attr-defined]
        core = RecordingCore()
        core.fail_on = b"bad"
        endpoint = await started(core)
        fired: list[str] = []

        def broken() -> None:
            raise RuntimeError("a timer callback that fails")

        lane.call_at(loop.time() + 0.001, broken)
        lane.call_at(loop.time() + 0.002, lambda: fired.append("after"))
        out = sender()
        for payload in (b"first", b"bad", b"second"):
            out.sendto(payload, ("127.0.0.1", endpoint.port))
        for _ in range(200):
            if len(core.received) == 2 and fired:
                break
            await asyncio.sleep(0.01)
        out.close()
        await endpoint.close()
        return core.received, fired

    with caplog.at_level(logging.ERROR, logger="cipstack"):
        received, fired = run_on(precise_event_loop(), scenario())
    assert received == [b"first", b"second"] and fired == ["after"]
    messages = [record.getMessage() for record in caplog.records]
    assert any(message.startswith("class 1 datagram from ('127.0.0.1'") for message in messages), messages
    assert any(message.startswith("lane callback") for message in messages), messages


def test_endpoint_on_asyncio_own_loop_uses_a_datagram_transport() -> None:
    async def scenario() -> tuple[bool, list[bytes]]:
        core = RecordingCore()
        endpoint = await started(core)
        uses_transport = endpoint.transport is not None
        out = sender()
        out.sendto(b"over the transport", ("127.0.0.1", endpoint.port))
        for _ in range(200):
            if core.received:
                break
            await asyncio.sleep(0.01)
        out.close()
        await endpoint.close()
        return uses_transport, core.received

    uses_transport, received = run_on(asyncio.new_event_loop(), scenario())
    assert uses_transport and received == [b"over the transport"]


def test_lane_works_when_the_epoll_descriptor_is_numbered_above_select_range() -> None:
    """Made after 1,024 files are open, the loop waits in epoll and sleeps the rest: lane timers
    still fire in order and lane sockets are still read."""
    held = [socket.socket() for _ in range(FD_SETSIZE + 16)]
    try:
        loop = precise_event_loop()
        assert isinstance(loop, PreciseEventLoop)
        assert loop.selector.fileno() >= FD_SETSIZE

        async def scenario() -> tuple[list[float], list[bytes]]:
            listener = sender()
            core = RecordingCore(period=0.0015, send_to=listener.getsockname())
            core.deadline = asyncio.get_running_loop().time() + 0.0015
            endpoint = await started(core)
            out = sender()
            out.sendto(b"high", ("127.0.0.1", endpoint.port))
            await asyncio.sleep(0.03)
            out.close()
            listener.close()
            await endpoint.close()
            return core.polls, core.received

        polls, received = run_on(loop, scenario())
        assert len(polls) >= 5 and polls == sorted(polls) and received == [b"high"]
    finally:
        for sock in held:
            sock.close()


def test_asyncio_work_given_by_a_lane_timer_before_the_wait_is_not_held_by_it() -> None:
    """A lane timer that fell due while asyncio's callbacks ran fires before the next wait; what it
    schedules in asyncio (here a timer 10 ms on, with nothing else pending) must count for that
    wait, or the loop would sleep until some unrelated event (the thread's wake-up, 3 s later)."""
    loop = precise_event_loop()
    assert isinstance(loop, PreciseEventLoop)
    waker = threading.Timer(3.0, lambda: loop.call_soon_threadsafe(lambda: None))

    async def scenario() -> float:
        done = loop.create_future()
        start = loop.time()

        def from_lane() -> None:
            loop.call_later(0.01, lambda: done.done() or done.set_result(loop.time()))

        loop.selector.lane.call_at(start + 0.002, from_lane)
        time.sleep(0.005)  # an asyncio callback running long: the lane timer falls due meanwhile
        return await done - start

    waker.start()
    try:
        elapsed = run_on(loop, scenario())
    finally:
        waker.cancel()
    assert elapsed < 1.5, elapsed


def test_class1_socket_asks_for_a_receive_buffer_that_outlasts_a_stall() -> None:
    """Linux doubles what is asked, capped at net.core.rmem_max: the default (208 KiB) holds 256
    small datagrams, 5 ms of 512 connections at RPI 10 ms."""
    rmem_max = int(Path("/proc/sys/net/core/rmem_max").read_text())

    async def scenario() -> int:
        endpoint = await started(RecordingCore())
        try:
            size = endpoint.receive_buffer_size
            assert size is not None
            return size
        finally:
            await endpoint.close()

    assert run_on(precise_event_loop(), scenario()) == 2 * min(RECEIVE_BUFFER, rmem_max)


def test_a_datagram_ends_a_long_wait_at_once() -> None:
    """A wait of many milliseconds (the next timer 500 ms away) is epoll_wait() itself: a datagram
    arriving meanwhile is read when it arrives, not at the timer."""

    async def scenario() -> float:
        loop = asyncio.get_running_loop()
        core = RecordingCore()
        endpoint = await started(core)
        fired: list[float] = []
        loop.selector.lane.call_at(loop.time() + 0.5, lambda: fired.append(loop.time()))  # type: ignore[attr-defined]
        out = sender()
        sent_at: list[float] = []

        def send() -> None:
            sent_at.append(time.monotonic())
            out.sendto(b"wake", ("127.0.0.1", endpoint.port))

        arrived: asyncio.Future[float] = loop.create_future()
        receive = core.receive

        def receive_and_tell(raw: bytes, source: tuple[str, int], now: float) -> None:
            receive(raw, source, now)
            arrived.set_result(time.monotonic())

        core.receive = receive_and_tell  # type: ignore[method-assign]
        threading.Timer(0.05, send).start()
        received_at = await arrived  # nothing else to do: the loop waits in the selector
        out.close()
        await endpoint.close()
        assert not fired
        return received_at - sent_at[0]

    assert run_on(precise_event_loop(), scenario()) < 0.25



@contextlib.contextmanager
def nudged(loop: asyncio.AbstractEventLoop, every: float = 2.0) -> Iterator[None]:
    """Wake ``loop`` from another thread every ``every`` seconds, so that a selector that failed to
    return to asyncio makes a test fail by its timeouts instead of hanging it."""
    stop = threading.Event()

    def nudge() -> None:
        while not stop.wait(every):
            with contextlib.suppress(RuntimeError):  # closed meanwhile
                loop.call_soon_threadsafe(lambda: None)

    thread = threading.Thread(target=nudge, daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join()


@pytest.mark.parametrize("gives", ["nothing for 19 datagrams, then a callback", "a callback", "an earlier timer"])
def test_the_wait_returns_to_asyncio_for_what_a_lane_reader_gives_it(gives: str) -> None:
    """While only the lane has work the selector waits again without returning to asyncio; a lane
    reader that gives asyncio work (a callback, a timer earlier than any it had) ends the wait at
    once, though asyncio's own next timer is 5 s away."""
    count = 20 if gives.startswith("nothing") else 1

    async def scenario() -> float:
        loop = asyncio.get_running_loop()
        far = loop.call_later(5.0, lambda: None)  # asyncio's timeout: 5 s
        core = RecordingCore()
        endpoint = await started(core)
        done: asyncio.Future[float] = loop.create_future()
        received = core.receive

        def set_done() -> None:
            if not done.done():
                done.set_result(time.monotonic())

        def on_datagram(raw: bytes, source: tuple[str, int], now: float) -> None:
            received(raw, source, now)
            if len(core.received) < count:
                return  # nothing for asyncio: the selector keeps serving the lane
            if gives == "an earlier timer":
                loop.call_later(0.01, set_done)
            else:
                loop.call_soon(set_done)

        core.receive = on_datagram  # type: ignore[method-assign]
        out = sender()
        start = time.monotonic()
        for _ in range(count):
            out.sendto(b"x", ("127.0.0.1", endpoint.port))
        try:
            return await asyncio.wait_for(done, 3.0) - start
        finally:
            out.close()
            far.cancel()
            await endpoint.close()
            assert len(core.received) == count

    loop = precise_event_loop()
    with nudged(loop):
        assert run_on(loop, scenario()) < 1.0


def test_more_ready_sockets_than_one_epoll_wait_takes_are_all_served_in_the_same_wait() -> None:
    """Each epoll_wait takes at most HARVEST_EVENTS events; the descriptors beyond them are served by
    the next call of the same wait, each once per datagram."""
    loop = precise_event_loop()
    selector = loop.selector  # type: ignore[attr-defined]
    count = 2 * HARVEST_EVENTS + 22
    pairs = [socket.socketpair(socket.AF_UNIX, socket.SOCK_DGRAM) for _ in range(count)]
    served: list[int] = []
    try:
        for index, (ours, theirs) in enumerate(pairs):
            ours.setblocking(False)

            def read(index: int = index, sock: socket.socket = ours) -> None:
                sock.recv(64)
                served.append(index)

            selector.lane.add_reader(ours.fileno(), read)
            theirs.send(b"x")
        ready = selector.select(0.05)
    finally:
        for ours, theirs in pairs:
            selector.lane.remove_reader(ours.fileno())
            ours.close()
            theirs.close()
        loop.close()
    assert ready == []  # nothing of asyncio's
    assert sorted(served) == list(range(count))


def test_a_later_asyncio_timer_given_by_a_lane_reader_does_not_end_the_wait() -> None:
    """Only a timer earlier than asyncio's first ends the wait early; one after it (or beside it)
    leaves the selector serving the lane until asyncio's own timeout."""
    loop = precise_event_loop()
    selector = loop.selector  # type: ignore[attr-defined]
    ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_DGRAM)
    ours.setblocking(False)
    first = loop.call_later(0.3, lambda: None)
    later: list[asyncio.TimerHandle] = []

    def read() -> None:
        ours.recv(64)
        later.append(loop.call_later(10.0 + len(later), lambda: None))

    selector.lane.add_reader(ours.fileno(), read)
    writer = threading.Timer(0.05, lambda: (theirs.send(b"a"), theirs.send(b"b")))
    writer.start()
    try:
        start = time.monotonic()
        ready = selector.select(0.3)
        elapsed = time.monotonic() - start
    finally:
        writer.join()
        selector.lane.remove_reader(ours.fileno())
        ours.close()
        theirs.close()
        first.cancel()
        for handle in later:
            handle.cancel()
        loop.close()
    assert ready == []
    assert len(later) == 2  # both datagrams read inside the one wait
    assert elapsed >= 0.25, elapsed


def test_a_stop_asked_by_a_lane_reader_ends_run_forever_at_once() -> None:
    loop = precise_event_loop()
    core = RecordingCore()
    endpoint = loop.run_until_complete(started(core))
    core.receive = lambda raw, source, now: loop.stop()  # type: ignore[method-assign]
    out = sender()
    far = loop.call_later(5.0, loop.stop)
    threading.Timer(0.05, lambda: out.sendto(b"stop", ("127.0.0.1", endpoint.port))).start()
    start = time.monotonic()
    try:
        with nudged(loop):
            loop.run_forever()
        elapsed = time.monotonic() - start
        far.cancel()
        loop.run_until_complete(endpoint.close())
    finally:
        out.close()
        loop.close()
    assert elapsed < 1.0, elapsed


@pytest.mark.parametrize("stamped", [True, False])
def test_kernel_arrival_times_are_when_the_datagram_came_not_when_the_loop_read_it(stamped: bool) -> None:
    """With ``stamp_arrivals``, a datagram is given to the core
    with the time the kernel received it: the loop busy for 80 ms meanwhile does not move it. Without,
    the time is when the loop read it, 80 ms later."""
    stall = 0.08

    async def scenario() -> tuple[list[float], list[float], bool]:
        core = RecordingCore()
        endpoint = await started(core)
        if stamped:
            assert endpoint.stamp_arrivals() and endpoint.stamp_arrivals()  # asking twice is the same
        out = sender()
        sent: list[float] = []
        try:
            for index in range(3):
                await asyncio.sleep(0.01)
                sent.append(time.monotonic())
                out.sendto(b"datagram %d" % index, ("127.0.0.1", endpoint.port))
                time.sleep(stall)  # the loop is busy: the datagram waits in the socket
            for _ in range(200):
                if len(core.received) == 3:
                    break
                await asyncio.sleep(0.01)
            return sent, core.times, endpoint.kernel_arrival_times
        finally:
            out.close()
            await endpoint.close()

    sent, times, kernel = run_on(precise_event_loop(), scenario())
    assert kernel is stamped and len(times) == 3
    delays = [given - at for at, given in zip(sent, times, strict=True)]
    if stamped:
        assert all(-0.005 < delay < stall / 2 for delay in delays), delays
    else:
        assert all(delay >= stall for delay in delays), delays


def test_kernel_arrival_times_are_not_taken_off_the_lane() -> None:
    async def scenario() -> tuple[bool, bool]:
        endpoint = await started(RecordingCore())
        try:
            return endpoint.stamp_arrivals(), endpoint.kernel_arrival_times
        finally:
            await endpoint.close()

    assert run_on(asyncio.new_event_loop(), scenario()) == (False, False)


class WatchingCore(RecordingCore):
    """A core whose connection is judged at each firing: it keeps how many datagrams it had by then."""

    def __init__(self) -> None:
        super().__init__(period=0.002)
        self.judged_with: list[int] = []

    def expire(self, now: float) -> list[Any]:
        if self.deadline is not None and now >= self.deadline - self.period:
            self.judged_with.append(len(self.received))
        return []


@pytest.mark.parametrize("loop_kind", ["lane", "lane stamped", "asyncio"])
def test_after_a_stall_every_waiting_datagram_is_read_before_a_watchdog_judges(loop_kind: str) -> None:
    """The loop stalls while far more datagrams than one wake-up reads (``DRAIN_LIMIT``; asyncio's
    transport reads one per round) come in, and a firing is due when it resumes: the firing reads
    what waits before it judges (expire), so a connection whose datagrams came in time is never
    taken for silent."""
    stamped = loop_kind == "lane stamped"
    count = 5 * DRAIN_LIMIT + 3

    async def scenario() -> tuple[list[int], int]:
        core = WatchingCore()
        endpoint = await started(core)
        if stamped:
            assert endpoint.stamp_arrivals()
        out = sender()
        try:
            core.deadline = asyncio.get_running_loop().time() + 0.02
            endpoint.wakeup()
            for index in range(count):
                out.sendto(b"datagram %d" % index, ("127.0.0.1", endpoint.port))
            time.sleep(0.05)  # the loop stalls past the firing; every datagram waits in the socket
            await asyncio.sleep(0.01)
            return core.judged_with, len(core.received)
        finally:
            out.close()
            await endpoint.close()

    loop = asyncio.new_event_loop() if loop_kind == "asyncio" else precise_event_loop()
    judged_with, received = run_on(loop, scenario())
    assert received == count
    assert judged_with and judged_with[0] == count, judged_with


class LoggingCore(RecordingCore):
    """A core that writes each reception and production to a log it shares with other cores, and has a
    watchdog of its own at ``watchdog`` (part of its next deadline, as a real core's is)."""

    def __init__(self, name: str, log: list[tuple[str, str]], watchdog: float) -> None:
        super().__init__(period=1.0)
        self.name = name
        self.log = log
        self.watchdog = watchdog
        self.judged = 0

    def receive(self, raw: bytes, source: tuple[str, int], now: float) -> None:
        super().receive(raw, source, now)
        self.log.append(("received", self.name))

    def poll(self, now: float, horizon: float = 0.0) -> list[tuple[bytes, tuple[str, int]]]:
        before = len(self.polls)
        out = super().poll(now, horizon)
        if len(self.polls) > before:
            self.log.append(("produced", self.name))
        return out

    def next_deadline(self) -> float | None:
        return None if self.deadline is None else min(self.deadline, self.watchdog)

    def expire(self, now: float) -> list[Any]:
        if now >= self.watchdog:
            self.judged += 1
            self.watchdog = now + 10.0
        return []


def test_endpoints_due_together_and_woken_late_all_produce_before_reading_what_judges_nothing() -> None:
    """A fleet's drives on one grid: many endpoints due at one instant, each with a datagram waiting,
    the loop held up past that instant. The wake-up produces for every endpoint first; the datagrams
    are read after, by the lane, since no firing judges a watchdog (each a few milliseconds behind
    its slot once the others ran, which once made each read its socket again for nothing). An
    endpoint whose watchdog is due reads its socket first, then judges."""
    count = 24

    async def scenario() -> tuple[list[tuple[str, str]], list[int]]:
        loop = asyncio.get_running_loop()
        log: list[tuple[str, str]] = []
        due = loop.time() + 0.02
        cores = [LoggingCore(f"drive {n}", log, due + 10.0 if n else due) for n in range(count)]
        endpoints = [await started(core) for core in cores]
        out = sender()
        try:
            for core, endpoint in zip(cores, endpoints, strict=True):
                core.deadline = due
                endpoint.wakeup()
                out.sendto(b"output data", ("127.0.0.1", endpoint.port))
            time.sleep(0.05)   # the loop held up past the slot, every datagram waiting in its socket
            await wait_until(lambda: len(log) == 2 * count, 5, "every production and every datagram")
            return log, [core.judged for core in cores]
        finally:
            out.close()
            for endpoint in endpoints:
                await endpoint.close()

    log, judged = run_on(precise_event_loop(), scenario())
    assert judged == [1] + [0] * (count - 1)
    # drive 0's watchdog was due: its datagram read before it judged, right after it produced
    first = log.index(("produced", "drive 0"))
    assert log[first + 1] == ("received", "drive 0"), log
    others = [entry for entry in log if entry[1] != "drive 0"]
    assert [kind for kind, _ in others] == ["produced"] * (count - 1) + ["received"] * (count - 1), others


def test_a_socket_read_one_datagram_at_a_time_still_delivers_every_datagram_in_order() -> None:
    """A socket that held one datagram at each reading is read one at a time (no read that finds it
    empty); when several come together, every one is still given to the core, in order."""
    async def scenario() -> list[bytes]:
        core = RecordingCore()
        endpoint = await started(core)
        out = sender()
        try:
            for index in range(3):   # one at a time: the socket is read one datagram at a time from now on
                out.sendto(b"alone %d" % index, ("127.0.0.1", endpoint.port))
                await wait_until(lambda count=index + 1: len(core.received) == count, 5, f"datagram {index}")
            for index in range(DRAIN_LIMIT + 5):
                out.sendto(b"together %d" % index, ("127.0.0.1", endpoint.port))
            await wait_until(lambda: len(core.received) == 3 + DRAIN_LIMIT + 5, 5, "every datagram")
            return core.received
        finally:
            out.close()
            await endpoint.close()

    received = run_on(precise_event_loop(), scenario())
    assert received == [b"alone %d" % i for i in range(3)] + [b"together %d" % i for i in range(DRAIN_LIMIT + 5)]
