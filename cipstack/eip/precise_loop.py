"""The precise event loop: asyncio's selector loop with a microsecond-precise wait and a lane
that serves sockets and timers inside the wait.

The default asyncio loop on Linux waits in epoll_wait(), whose timeout has millisecond
granularity and is rounded up, so a 1 ms RPI would jitter by up to a millisecond. select() has
microsecond timeouts but takes no descriptor numbered 1024 or above and scans every socket on
each wait. ``precise_event_loop`` keeps both strengths: sockets are registered with epoll (any
descriptor number, no scan); a wait spends its whole milliseconds in epoll_wait() and the
sub-millisecond rest in a select() on the one epoll descriptor (it becomes readable when any
registered socket is ready), and the ready events are then harvested with a non-blocking
epoll_wait(). A wait for a lane timer (a class 1 production or watchdog) is one select() to the
microsecond, whatever its length: one wake-up, not two. It also lowers the thread's timer
slack: sends then leave within tens of microseconds of their slot.

The lane (``IoLane``): the class 1 endpoints (``io_server``) and the encapsulation server's TCP
connections (``tcp_lane``) hand their sockets and timers to the selector itself, which reads the
sockets that are ready and fires the timers that are due inside its wait, before asyncio sees
anything. While only the lane has work the selector goes on waiting and serving it without
handing back to asyncio; it returns as soon as asyncio has something to do: a socket of its own,
its next timer, or work a lane callback gave it.

To know that, the selector reads the loop's queues, which are private attributes of asyncio's
``BaseEventLoop`` (``_ready``, ``_scheduled``, ``_stopping``). They are the same in every Python
of ``SUPPORTED_PYTHONS``; ``PreciseEventLoop`` refuses, with ``UnsupportedPythonError``, a Python
outside them or a loop without them, rather than run with a wait that may never return.
"""

from __future__ import annotations

import asyncio
import contextlib
import ctypes
import ctypes.util
import gc
import heapq
import itertools
import logging
import select
import selectors
import sys
import time
from collections.abc import Callable, Coroutine
from typing import Any, TypeVar

from ..errors import CipstackError

log = logging.getLogger(__name__)
T = TypeVar("T")

#: The Pythons whose asyncio has the loop attributes the selector reads (``pyproject.toml``'s
#: ``requires-python`` has the same bounds).
SUPPORTED_PYTHONS = ((3, 10), (3, 11), (3, 12), (3, 13))
#: The private attributes of asyncio's loop the selector reads.
LOOP_INTERNALS = ("_ready", "_scheduled", "_stopping")


class UnsupportedPythonError(CipstackError, RuntimeError):
    """This Python's asyncio is not one the precise loop knows the internals of."""


def check_python(version: tuple[int, ...] = tuple(sys.version_info[:2]),
                 loop: asyncio.AbstractEventLoop | None = None) -> None:
    """Refuse a Python outside ``SUPPORTED_PYTHONS``, or a ``loop`` without the queues the selector
    reads, with a message that says which and what to do."""
    if tuple(version[:2]) not in SUPPORTED_PYTHONS:
        known = ", ".join(f"{major}.{minor}" for major, minor in SUPPORTED_PYTHONS)
        raise UnsupportedPythonError(
            f"the precise event loop reads asyncio internals known in Python {known}, not in "
            f"{version[0]}.{version[1]}: run cipstack on one of those")
    missing = [name for name in LOOP_INTERNALS if loop is not None and not hasattr(loop, name)]
    if missing:
        raise UnsupportedPythonError(f"asyncio's loop has no {', '.join(missing)} in this Python "
                                     f"({sys.version.split()[0]}): the precise event loop cannot serve it")


_PR_SET_TIMERSLACK = 29


def _lower_timer_slack(nanoseconds: int = 1000) -> None:
    """Linux rounds sleeps up by the timer slack (50 us by default); 1 us keeps sends on time."""
    if not sys.platform.startswith("linux"):
        return
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        libc.prctl(_PR_SET_TIMERSLACK, nanoseconds, 0, 0, 0)
    except (OSError, AttributeError):
        pass


#: select() takes descriptors below FD_SETSIZE only (1024 on Linux).
FD_SETSIZE = 1024


#: Events taken per epoll_wait. epoll is level-triggered and hands out its ready list in turn, so
#: descriptors beyond these are served by the next call of the same wait, a moment later; a fixed
#: number spares counting the registered descriptors on every call.
HARVEST_EVENTS = 64


class LaneTimer:
    """A callback due at ``when`` on the lane; ``cancel()`` before then and it does not run."""

    __slots__ = ("callback", "cancelled", "when")

    def __init__(self, when: float, callback: Callable[[], None]) -> None:
        self.when = when
        self.callback = callback
        self.cancelled = False

    def cancel(self) -> None:
        self.cancelled = True


class IoLane:
    """Sockets read and timers fired inside the selector's wait (see the module docstring), on
    the selector's own epoll set.

    Callbacks run on the loop's thread between two rounds of asyncio callbacks, as asyncio's own
    would; one that raises is logged and the rest go on."""

    def __init__(self, epoll: select.epoll) -> None:
        self._epoll = epoll
        self.readers: dict[int, Callable[[], None]] = {}
        #: The timers' heap: (when, order, timer); the wait looks at its head to see whether one is due.
        self.timers: list[tuple[float, int, LaneTimer]] = []
        self._order = itertools.count()

    def add_reader(self, fd: int, callback: Callable[[], None], events: int = select.EPOLLIN) -> None:
        """Serve ``fd``'s readiness with ``callback`` in the wait; asyncio never sees the descriptor.
        ``events``: the epoll events watched (readable by default); errors and hang-ups always are."""
        self._epoll.register(fd, events)
        self.readers[fd] = callback

    def watch(self, fd: int, events: int) -> None:
        """Change the events watched on a reader's ``fd`` (writable instead of readable, say)."""
        self._epoll.modify(fd, events)

    def remove_reader(self, fd: int) -> None:
        if self.readers.pop(fd, None) is not None:
            # A socket closed already has left the epoll set with it.
            with contextlib.suppress(OSError, ValueError):
                self._epoll.unregister(fd)

    def call_at(self, when: float, callback: Callable[[], None]) -> LaneTimer:
        timer = LaneTimer(when, callback)
        heapq.heappush(self.timers, (when, next(self._order), timer))
        return timer

    def next_deadline(self) -> float | None:
        timers = self.timers
        while timers and timers[0][2].cancelled:
            heapq.heappop(timers)
        return timers[0][0] if timers else None

    def run_due(self, now: float) -> bool:
        """Run the timers due at ``now``; whether any ran."""
        timers = self.timers
        ran = False
        while timers and timers[0][0] <= now:
            timer = heapq.heappop(timers)[2]
            if not timer.cancelled:
                timer.cancelled = True  # ran: a late cancel() is harmless
                ran = True
                _run_guarded(timer.callback)
        return ran


def _run_guarded(callback: Callable[[], None]) -> None:
    try:
        callback()
    except Exception:  # one callback must never take the loop down
        log.exception("lane callback %r", callback)


class PreciseEpollSelector(selectors.EpollSelector):
    """epoll for registration and readiness, with a microsecond-precise wait and the class 1
    lane (see the module docstring)."""

    def __init__(self) -> None:
        super().__init__()
        epoll = self._selector  # type: ignore[attr-defined]
        self.lane = IoLane(epoll)
        self._poll = epoll.poll
        self._epoll_fd: int = epoll.fileno()
        #: The loop this selector serves (set by ``PreciseEventLoop``); None: return to the caller
        #: after every wait, as any selector does.
        self.loop: PreciseEventLoop | None = None

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        """Wait as asyncio asks (until ``timeout``), serving the lane meanwhile; return when asyncio
        has something to do: a socket of its own is ready, its timeout has come, or what a lane
        callback did gave it work (a callback to run, an earlier timer). While only the lane has
        work (every request of an explicit-messaging client, every class 1 packet), the selector
        waits again without handing back to asyncio: a round of asyncio's loop costs more than the
        lane's own work on a small request, and a round of this wait is kept short for the same
        reason (one clock reading serves the end of a round and the start of the next; the lane's
        timers are looked at, not called, when none is due)."""
        lane = self.lane
        timers = lane.timers
        monotonic = time.monotonic
        now = monotonic()
        until = None if timeout is None else now + max(timeout, 0.0)
        first_timer = self._first_timer()  # the timer asyncio's timeout was taken from, or None
        # Lane timers that fell due while asyncio's callbacks ran; what they gave asyncio makes the
        # first wait a look. Later rounds end with the lane's timers run and asyncio's work looked at.
        busy = False
        if timers and timers[0][0] <= now and lane.run_due(now):
            busy = self._asyncio_has_work(first_timer)
            now = monotonic()
        while True:
            wait = 0.0 if busy else None if until is None else until - now
            on_lane_timer = False
            if timers:
                head = timers[0]
                lane_at = lane.next_deadline() if head[2].cancelled else head[0]
                if lane_at is not None and (wait is None or lane_at - now < wait):
                    wait = lane_at - now
                    on_lane_timer = self._epoll_fd < FD_SETSIZE
            # epoll_wait() counts whole milliseconds (rounded up): a wait of a millisecond or more
            # waits those there, and an event that ends it comes in that call (one system call, the
            # common case); only the sub-millisecond rest of a wait is ``_wait_rest``'s. A wait that
            # ends on a lane timer (a production, a watchdog) is one select() to the microsecond
            # instead: its timer, not an event, usually ends it, and sleeping twice (the whole
            # milliseconds, then the rest) costs a second wake-up, which costs more than a class 1
            # packet's own work.
            if wait is None or (wait >= 0.001 and not on_lane_timer):
                ready, seen = self._harvest(-1.0 if wait is None else int(wait * 1000) / 1000)
                if not seen and wait is not None:
                    ready = self._wait_rest(now + wait)
            else:
                ready = self._wait_rest(now + wait)
            now = monotonic()
            if timers and timers[0][0] <= now and lane.run_due(now):
                now = monotonic()
            if busy or ready or (until is not None and now >= until) or self._asyncio_has_work(first_timer):
                return ready

    # The loop's queues are asyncio's own attributes (``LOOP_INTERNALS``, checked by ``check_python``);
    # only ``PreciseEventLoop`` sets ``loop``.
    def _first_timer(self) -> asyncio.TimerHandle | None:
        loop = self.loop
        scheduled = loop._scheduled if loop is not None else None  # type: ignore[attr-defined]
        return scheduled[0] if scheduled else None

    def _asyncio_has_work(self, first_timer: asyncio.TimerHandle | None) -> bool:
        """Whether the loop has a callback ready, is stopping, or has a timer earlier than
        ``first_timer`` (the earliest it had when it asked for the wait): then ``select`` must return
        to it. Within a wait asyncio's timer heap only grows (it drops timers in its own round), so
        a head that is no longer ``first_timer`` is an earlier timer."""
        loop = self.loop
        if loop is None or loop._ready or loop._stopping:  # type: ignore[attr-defined]
            return True
        scheduled = loop._scheduled  # type: ignore[attr-defined]
        return bool(scheduled) and scheduled[0] is not first_timer

    def _wait_rest(self, until: float) -> list[tuple[selectors.SelectorKey, int]]:
        """A wait to ``until``, to the microsecond: a select() on the epoll descriptor, which returns at
        once if something is ready (or, when that descriptor is numbered too high for select, a look
        and then a sleep); then what is ready is harvested (nothing, when the select ran out). A wait
        already over is the harvest alone."""
        remainder = until - time.monotonic()
        if remainder > 0:
            if self._epoll_fd < FD_SETSIZE:
                if not select.select((self._epoll_fd,), (), (), remainder)[0]:
                    return []   # the time ran out with nothing ready: no harvest to make
            else:
                ready, seen = self._harvest(0)
                if seen:
                    return ready
                time.sleep(remainder)  # events wait at most this remainder
        return self._harvest(0)[0]

    def _harvest(self, epoll_timeout: float) -> tuple[list[tuple[selectors.SelectorKey, int]], bool]:
        """One epoll_wait: lane descriptors are served here, the others returned for asyncio (as
        ``EpollSelector.select`` does); also whether anything at all was ready."""
        readers = self.lane.readers
        try:
            events = self._poll(epoll_timeout, HARVEST_EVENTS)
        except InterruptedError:
            return [], False
        ready = []
        for fd, event in events:
            # A lane descriptor an earlier callback of this wake-up removed is no longer here, nor
            # asyncio's: it is skipped below.
            reader = readers.get(fd)
            if reader is not None:
                try:
                    reader()
                except Exception:  # one callback must never take the loop down
                    log.exception("lane callback %r", reader)
                continue
            # The base selector's own table (``_key_from_fd``, which read it, is gone in Python 3.13).
            key = self._fd_to_key.get(fd)  # type: ignore[attr-defined]  # private to BaseSelector, untyped
            if key:
                mask = (selectors.EVENT_WRITE if event & ~select.EPOLLIN else 0) | (
                    selectors.EVENT_READ if event & ~select.EPOLLOUT else 0)
                ready.append((key, mask & key.events))
        return ready, bool(events)


class PreciseEventLoop(asyncio.SelectorEventLoop):
    """The loop of ``precise_event_loop``: its selector carries the lane."""

    def __init__(self) -> None:
        check_python()
        self.selector = PreciseEpollSelector()
        super().__init__(self.selector)
        check_python(loop=self)
        self.selector.loop = self


def lane_of(loop: asyncio.AbstractEventLoop) -> IoLane | None:
    """The lane of a ``PreciseEventLoop``; None on any other loop."""
    return loop.selector.lane if isinstance(loop, PreciseEventLoop) else None


def precise_event_loop() -> asyncio.AbstractEventLoop:
    """An event loop whose timers fire within tens of microseconds and that takes any number of sockets."""
    _lower_timer_slack()
    return PreciseEventLoop()


def freeze_startup_objects() -> None:
    """Put what start-up built (object tables, schemas, registers, parameter catalogs) out of the
    cyclic collector's reach. A full collection walks every tracked object with the loop stopped:
    about 8 ms for one ACG drive's 28,000 objects and 42 ms for a fleet of 64 (126,000), longer
    than a class 1 watchdog at RPI 10 ms allows. Reference counting still frees them."""
    gc.collect()
    gc.freeze()


def run_precise(coroutine: Coroutine[Any, Any, T]) -> T:
    """``asyncio.run`` on a precise event loop."""
    loop = precise_event_loop()
    asyncio.set_event_loop(loop)
    try:
        return loop.run_until_complete(coroutine)
    finally:
        try:
            loop.run_until_complete(loop.shutdown_asyncgens())
        finally:
            asyncio.set_event_loop(None)
            loop.close()


__all__ = ["FD_SETSIZE", "LOOP_INTERNALS", "SUPPORTED_PYTHONS", "IoLane", "LaneTimer", "PreciseEpollSelector",
           "PreciseEventLoop", "UnsupportedPythonError", "check_python", "freeze_startup_objects", "lane_of",
           "precise_event_loop", "run_precise"]
