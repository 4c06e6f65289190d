"""``--workers N``: a fleet's devices spread over N processes, each one event loop with a share of
the addresses, under a parent that supervises them.

The parent starts the workers and waits until each says it serves (its device lines) or why it
cannot (one line, e.g. an address that is taken): then every other worker is stopped and the
fleet exits 2. While serving, a worker that ends is reported in one line, the others are stopped
and the fleet exits 1. A worker that stops answering is reported and handled the same way: the
parent pings each worker over its channel every ``HEARTBEAT_INTERVAL`` and the worker's event loop
answers; no answer for ``HEARTBEAT_TIMEOUT`` means its loop no longer runs (stopped, or stuck), and
the devices it holds no longer serve. SIGINT (Ctrl-C) and SIGTERM to the parent stop every worker
with SIGTERM (after SIGCONT, so that a stopped one can act on it); the workers ignore SIGINT
themselves, so a Ctrl-C at the terminal reaches them once, through the parent. A worker that has
not ended ``STOP_TIMEOUT`` later (``HUNG_STOP_TIMEOUT`` for one that had stopped answering) is
killed. A worker dies with its parent on Linux (PR_SET_PDEATHSIG), so even a parent that is killed
leaves no worker behind.
"""

from __future__ import annotations

import asyncio
import contextlib
import ctypes
import ctypes.util
import logging
import multiprocessing
import multiprocessing.connection
import os
import signal
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from multiprocessing.connection import Connection
from typing import Any

from ..eip.io_server import run_precise
from ..listening import ListenError
from .serve import serve_until_signalled
from .spec import FleetDevice, SpecError, describe_addresses

log = logging.getLogger(__name__)

#: How long stopping workers may take to write their last saves before they are killed: a save is
#: one small file per device, written in milliseconds.
STOP_TIMEOUT = 5.0
#: The same for a worker that had stopped answering: it is given a moment after SIGCONT, no more.
HUNG_STOP_TIMEOUT = 2.0
#: How often the parent pings each serving worker, and how long a ping may go unanswered before the
#: worker is reported as not answering. The worker answers from its event loop, which never blocks
#: for long (saves run off it), so 5 s of silence is a loop that does not run, not a busy one.
HEARTBEAT_INTERVAL = 1.0
HEARTBEAT_TIMEOUT = 5.0
PING, PONG = "ping", "pong"
_PR_SET_PDEATHSIG = 1


def shares(devices: Sequence[FleetDevice], workers: int) -> list[list[FleetDevice]]:
    """``devices`` in ``workers`` contiguous shares whose sizes differ by one at most."""
    size, extra = divmod(len(devices), workers)
    result, start = [], 0
    for index in range(workers):
        end = start + size + (1 if index < extra else 0)
        result.append(list(devices[start:end]))
        start = end
    return result


def _die_with_parent(parent: int) -> None:
    """Have the kernel send SIGTERM to this process when its parent ends (Linux)."""
    if not sys.platform.startswith("linux"):
        return
    with contextlib.suppress(OSError, AttributeError):
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)
    if os.getppid() != parent:   # the parent ended before the request was made
        os._exit(1)


async def _serve_answering(share: list[FleetDevice], port: int, io_port: int, channel: Connection) -> int:
    """Serve ``share`` until SIGTERM, answering the parent's pings from the event loop."""
    loop = asyncio.get_running_loop()
    fd = channel.fileno()

    def answer() -> None:
        try:
            while channel.poll():
                if channel.recv() == PING:
                    channel.send(PONG)
        except (EOFError, OSError):   # the parent is gone: PR_SET_PDEATHSIG ends this process
            loop.remove_reader(fd)

    loop.add_reader(fd, answer)
    try:
        return await serve_until_signalled(share, port, io_port, lambda lines: channel.send(("ready", lines)),
                                           signals=(signal.SIGTERM,))
    finally:
        loop.remove_reader(fd)


def _worker(share: list[FleetDevice], port: int, io_port: int, parent: int, channel: Connection) -> None:
    """A worker process: serve ``share`` until SIGTERM; says "ready" with its lines, or "error", and
    answers each "ping" with "pong"."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)     # Ctrl-C is the parent's to pass on
    signal.signal(signal.SIGTERM, signal.SIG_DFL)    # not the parent's handler, until the loop's own
    _die_with_parent(parent)
    try:
        run_precise(_serve_answering(share, port, io_port, channel))
    except (ListenError, SpecError) as exc:
        channel.send(("error", str(exc)))
        sys.exit(2)
    except OSError as exc:
        channel.send(("error", f"cannot listen on {describe_addresses(d.address for d in share)}: "
                               f"{exc.strerror or exc}"))
        sys.exit(2)
    finally:
        channel.close()


@dataclass
class _Worker:
    number: int
    share: list[FleetDevice]
    process: Any
    channel: Connection
    lines: list[str] | None = None
    #: When the oldest unanswered ping went out (None: every ping answered).
    waiting_since: float | None = None
    #: Reported as not answering: stopped with ``HUNG_STOP_TIMEOUT``.
    hung: bool = False

    @property
    def name(self) -> str:
        return f"worker {self.number} ({describe_addresses(d.address for d in self.share)})"

    def how_it_ended(self) -> str:
        code = self.process.exitcode
        if code is None:
            return "still running"
        if code < 0:
            try:
                return f"killed by {signal.Signals(-code).name}"
            except ValueError:
                return f"killed by signal {-code}"
        return f"exit status {code}"


class FleetFailure(Exception):
    """The fleet could not start or a worker ended: one line, and the exit status."""

    def __init__(self, message: str, status: int) -> None:
        super().__init__(message)
        self.status = status


class Supervisor:
    """The parent of the worker processes (see the module docstring)."""

    def __init__(self, devices: Sequence[FleetDevice], port: int, io_port: int, workers: int) -> None:
        self.devices = list(devices)
        self.port = port
        self.io_port = io_port
        self.workers_wanted = workers
        self.workers: list[_Worker] = []
        self.stop_signal: int | None = None

    def _on_signal(self, sig: int, _frame: Any) -> None:
        if self.stop_signal is None:
            self.stop_signal = sig

    def run(self, on_ready: Callable[[list[str]], None]) -> int:
        """Start, serve until SIGINT/SIGTERM, stop; returns the signal that stopped the fleet.
        Raises ``FleetFailure`` when a worker cannot start or ends on its own."""
        previous = {sig: signal.signal(sig, self._on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
        try:
            self._start()
            self._wait_ready()
            if self.stop_signal is None:
                on_ready([line for worker in self.workers for line in worker.lines or []])
                self._supervise()
            return self.stop_signal or signal.SIGTERM
        finally:
            self._stop_all()
            for sig, handler in previous.items():
                signal.signal(sig, handler)

    def _start(self) -> None:
        # fork where there is one: the parent holds no thread and no loop yet, and a forked worker
        # starts without importing cipstack again.
        context = multiprocessing.get_context("fork" if "fork" in multiprocessing.get_all_start_methods()
                                              else "spawn")
        for number, share in enumerate(shares(self.devices, self.workers_wanted), start=1):
            ours, theirs = context.Pipe(duplex=True)
            process = context.Process(target=_worker, args=(share, self.port, self.io_port, os.getpid(), theirs),
                                      name=f"cipstack fleet worker {number}", daemon=True)
            process.start()
            theirs.close()
            self.workers.append(_Worker(number, share, process, ours))

    def _wait_ready(self) -> None:
        waiting = list(self.workers)
        while waiting and self.stop_signal is None:
            handles = [w.channel for w in waiting] + [w.process.sentinel for w in waiting]
            multiprocessing.connection.wait(handles, timeout=0.2)
            for worker in list(waiting):
                message = None
                if worker.channel.poll():
                    try:
                        message = worker.channel.recv()
                    except EOFError:
                        message = None
                if message is not None and message[0] == "ready":
                    worker.lines = message[1]
                    waiting.remove(worker)
                elif message is not None and message[0] == "error":
                    raise FleetFailure(message[1], 2)
                elif not worker.process.is_alive():
                    worker.process.join()
                    raise FleetFailure(f"{worker.name} ended while starting: {worker.how_it_ended()}", 1)

    def _supervise(self) -> None:
        next_ping = time.monotonic()
        while self.stop_signal is None:
            now = time.monotonic()
            if now >= next_ping:
                for worker in self.workers:
                    self._ping(worker, now)
                next_ping = now + HEARTBEAT_INTERVAL
            handles = [w.process.sentinel for w in self.workers] + [w.channel for w in self.workers]
            multiprocessing.connection.wait(handles, timeout=max(0.0, min(0.5, next_ping - time.monotonic())))
            for worker in self.workers:
                self._read_answers(worker)
                if self.stop_signal is not None:
                    return
                if not worker.process.is_alive():
                    worker.process.join()
                    raise FleetFailure(f"{worker.name} ended: {worker.how_it_ended()}; stopping the fleet", 1)
                if worker.waiting_since is not None and time.monotonic() - worker.waiting_since > HEARTBEAT_TIMEOUT:
                    worker.hung = True
                    raise FleetFailure(f"{worker.name} stopped answering (no reply in {HEARTBEAT_TIMEOUT:.0f} s: "
                                       f"stopped or stuck); stopping the fleet", 1)

    @staticmethod
    def _ping(worker: _Worker, now: float) -> None:
        try:
            worker.channel.send(PING)
        except OSError:
            return   # the worker is gone: its sentinel says so
        if worker.waiting_since is None:
            # The deadline runs from the first ping it has not answered, so a parent that was itself
            # held up (and sent nothing) never takes its own delay for the worker's.
            worker.waiting_since = now

    @staticmethod
    def _read_answers(worker: _Worker) -> None:
        try:
            while worker.channel.poll():
                if worker.channel.recv() == PONG:
                    worker.waiting_since = None
        except (EOFError, OSError):
            pass   # the worker is gone: its sentinel says so

    def _stop_all(self) -> None:
        """SIGCONT and SIGTERM to every worker still running (a stopped process acts on no signal but
        SIGKILL until it is continued); those that have not ended after ``STOP_TIMEOUT`` (one that had
        stopped answering: ``HUNG_STOP_TIMEOUT``) are killed. None is left behind."""
        for worker in self.workers:
            if worker.process.is_alive():
                with contextlib.suppress(ProcessLookupError):
                    os.kill(worker.process.pid, signal.SIGCONT)
                    worker.process.terminate()
        started = time.monotonic()
        for worker in self.workers:
            timeout = HUNG_STOP_TIMEOUT if worker.hung else STOP_TIMEOUT
            worker.process.join(max(0.0, started + timeout - time.monotonic()))
            if worker.process.is_alive():
                log.warning("%s did not stop in %.0f s: killed", worker.name, timeout)
                worker.process.kill()
                worker.process.join()
            worker.channel.close()


__all__ = ["FleetFailure", "Supervisor", "shares"]
