"""``--workers N``: a fleet's devices spread over N processes, each one event loop with a share of
the addresses, under a parent that supervises them.

The parent starts the workers and waits until each says it serves (its device lines) or why it
cannot (one line, e.g. an address that is taken): then every other worker is stopped and the
fleet exits 2. While serving, a worker that ends is reported in one line, the others are stopped
and the fleet exits 1. A dead worker is reported and handled the same way: the parent pings each worker over
its channel every ``HEARTBEAT_INTERVAL``, and a thread of the worker's answers with its load
(``cipstack.fleet.load``); no answer for ``HEARTBEAT_TIMEOUT`` means the process no longer runs
(stopped, or stuck holding the interpreter), and an event loop that has not run for
``LOOP_STUCK_TIMEOUT`` is stuck: the devices it holds no longer serve. A worker that answers but
whose productions go late is overloaded, not dead: it is reported in one line when it goes late and
when it is on time again, and it goes on serving; the fleet never stops itself for being slow.
SIGINT (Ctrl-C) and SIGTERM to the parent stop every worker
with SIGTERM (after SIGCONT, so that a stopped one can act on it); the workers ignore SIGINT
themselves, so a Ctrl-C at the terminal reaches them once, through the parent. A worker that has
not ended ``STOP_TIMEOUT`` later (``HUNG_STOP_TIMEOUT`` for one that had stopped answering) is
killed. A worker dies with its parent on Linux (PR_SET_PDEATHSIG), so even a parent that is killed
leaves no worker behind.

With an HTTP control API (``--http``) the parent serves it for every device of every worker
(``cipstack.control.http_relay``), on its own event loop, which then also runs the supervision: each
worker serves its devices' API on a Unix socket in a directory of the parent's (mode 0700, removed at
the end), and the relay forwards each request to the worker that holds the device. There a worker
that ends or stops answering is reported in one line and its devices answer 503 (a stuck one is
stopped as above), while the others go on serving, so that a rig sees which devices are gone and why;
the fleet then exits 1 when it is stopped, and at once when no worker is left.
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
import shutil
import signal
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from multiprocessing.connection import Connection
from typing import Any

from ..eip.io_server import run_precise
from ..errors import CipstackError
from ..listening import ListenError
from .load import (
    LOOP_STUCK_TIMEOUT,
    PING,
    PONG,
    LoadReport,
    LoadSampler,
    LoadWatch,
    answer_pings,
    gauge_values,
    report_lateness,
)
from .serve import serve_until_signalled
from .spec import FleetDevice, FleetSecurity, SpecError, describe_addresses, shares

log = logging.getLogger(__name__)

#: How long stopping workers may take to write their last saves before they are killed: a save is
#: one small file per device, written in milliseconds.
STOP_TIMEOUT = 5.0
#: The same for a worker that had stopped answering: it is given a moment after SIGCONT, no more.
HUNG_STOP_TIMEOUT = 2.0
#: How often the parent pings each serving worker, and how long a ping may go unanswered before the
#: worker is reported as not answering. The worker answers from a thread of its own, which a loop busy
#: with productions does not hold up, so 5 s of silence is a process that does not run, not a busy one.
HEARTBEAT_INTERVAL = 1.0
HEARTBEAT_TIMEOUT = 5.0
_PR_SET_PDEATHSIG = 1


def _die_with_parent(parent: int) -> None:
    """Have the kernel send SIGTERM to this process when its parent ends (Linux)."""
    if not sys.platform.startswith("linux"):
        return
    with contextlib.suppress(OSError, AttributeError):
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)
    if os.getppid() != parent:   # the parent ended before the request was made
        os._exit(1)


def _worker(share: list[FleetDevice], port: int, io_port: int, parent: int, channel: Connection,
            api_path: str | None = None, security: FleetSecurity | None = None) -> None:
    """A worker process: serve ``share`` until SIGTERM; says "ready" with its lines, or "error", and
    answers each "ping" with "pong" and its load, from a thread (``answer_pings``); with ``api_path``,
    the HTTP control API of its devices on that Unix socket, for the parent's relay."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)     # Ctrl-C is the parent's to pass on
    signal.signal(signal.SIGTERM, signal.SIG_DFL)    # not the parent's handler, until the loop's own
    _die_with_parent(parent)
    sampler = LoadSampler()
    sending = threading.Lock()

    def send(message: Any) -> None:
        with sending:
            channel.send(message)

    answer_pings(channel, sampler.report, sending)
    try:
        run_precise(serve_until_signalled(share, port, io_port, lambda lines: send(("ready", lines)),
                                          signals=(signal.SIGTERM,),
                                          http={"path": api_path} if api_path is not None else None,
                                          sampler=sampler, security=security))
    except (ListenError, SpecError) as exc:
        send(("error", str(exc)))
        sys.exit(2)
    except OSError as exc:
        send(("error", f"cannot listen on {describe_addresses(d.address for d in share)}: {exc.strerror or exc}"))
        sys.exit(2)


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
    #: The Unix socket of its devices' HTTP control API (with ``--http``).
    api_path: str | None = None
    #: Why it serves no more, once reported (with ``--http``, where the others go on).
    lost: str | None = None
    #: When a worker reported as not answering is killed if it has not ended by then.
    kill_at: float | None = None
    #: Its load, from its answers.
    load: LoadWatch = field(default_factory=LoadWatch)

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


class FleetFailure(CipstackError):
    """The fleet could not start or a worker ended: one line, and the exit status."""

    def __init__(self, message: str, status: int) -> None:
        super().__init__(message)
        self.status = status


class Supervisor:
    """The parent of the worker processes (see the module docstring)."""

    def __init__(self, devices: Sequence[FleetDevice], port: int, io_port: int, workers: int,
                 http: dict[str, Any] | None = None, security: FleetSecurity | None = None) -> None:
        """``http``: the settings of the fleet's HTTP control API (``http``, ``http_token``,
        ``http_allow_remote``, ``http_hosts``), or None for none; ``security``: TLS and DTLS at every
        device (``FleetSecurity``), or None."""
        self.devices = list(devices)
        self.port = port
        self.io_port = io_port
        self.security = security
        self.workers_wanted = workers
        self.http = http
        self.workers: list[_Worker] = []
        self.stop_signal: int | None = None
        #: The directory of the workers' API sockets (with ``http``).
        self._runtime: str | None = None
        self._wake: Callable[[], None] | None = None

    @property
    def lost(self) -> list[str]:
        """What ended each worker that no longer serves (with ``http``; without, the first one stops the fleet)."""
        return [worker.lost for worker in self.workers if worker.lost is not None]

    def _on_signal(self, sig: int, _frame: Any) -> None:
        if self.stop_signal is None:
            self.stop_signal = sig
        if self._wake is not None:
            self._wake()

    def run(self, on_ready: Callable[[list[str]], None]) -> int:
        """Start, serve until SIGINT/SIGTERM, stop; returns the signal that stopped the fleet.
        Raises ``FleetFailure`` when a worker cannot start or ends on its own."""
        previous = {sig: signal.signal(sig, self._on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
        try:
            self._start()
            self._wait_ready()
            if self.stop_signal is None:
                lines = [line for worker in self.workers for line in worker.lines or []]
                if self.http is None:
                    on_ready(lines)
                    self._supervise()
                else:
                    asyncio.run(self._serve_http(lambda: on_ready(lines)))
            return self.stop_signal or signal.SIGTERM
        finally:
            self._stop_all()
            if self._runtime is not None:
                shutil.rmtree(self._runtime, ignore_errors=True)
            for sig, handler in previous.items():
                signal.signal(sig, handler)

    def _start(self) -> None:
        # fork where there is one: the parent holds no thread and no loop yet, and a forked worker
        # starts without importing cipstack again.
        context: multiprocessing.context.ForkContext | multiprocessing.context.SpawnContext = (
            multiprocessing.get_context("fork") if "fork" in multiprocessing.get_all_start_methods()
            else multiprocessing.get_context("spawn"))
        if self.http is not None:   # mkdtemp: mode 0700, so only this user (and root) reaches the sockets
            runtime = os.environ.get("XDG_RUNTIME_DIR")
            self._runtime = tempfile.mkdtemp(prefix="cipstack-fleet-",
                                             dir=runtime if runtime and os.path.isdir(runtime) else None)
        for number, share in enumerate(shares(self.devices, self.workers_wanted), start=1):
            ours, theirs = context.Pipe(duplex=True)
            api_path = os.path.join(self._runtime, f"worker-{number}.sock") if self._runtime is not None else None
            process = context.Process(target=_worker, args=(share, self.port, self.io_port, os.getpid(), theirs,
                                                            api_path, self.security),
                                      name=f"cipstack fleet worker {number}", daemon=True)
            process.start()
            theirs.close()
            self.workers.append(_Worker(number, share, process, ours, api_path=api_path))

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
            next_ping = self._ping_when_due(next_ping)
            handles = [w.process.sentinel for w in self.workers] + [w.channel for w in self.workers]
            multiprocessing.connection.wait(handles, timeout=max(0.0, min(0.5, next_ping - time.monotonic())))
            self._check_workers()

    def _ping_when_due(self, next_ping: float) -> float:
        """Ping every serving worker when ``next_ping`` has come; returns when the next pings are due."""
        now = time.monotonic()
        if now < next_ping:
            return next_ping
        for worker in self._serving():
            self._ping(worker, now)
        return now + HEARTBEAT_INTERVAL

    def _serving(self) -> list[_Worker]:
        return [worker for worker in self.workers if worker.lost is None]

    def _check_workers(self) -> None:
        """Read the workers' answers; one that ended or stopped answering is lost (``_lose``)."""
        for worker in self._serving():
            self._read_answers(worker)
            if self.stop_signal is not None:
                return
            if not worker.process.is_alive():
                worker.process.join()
                self._lose(worker, f"{worker.name} ended: {worker.how_it_ended()}")
            elif worker.waiting_since is not None and time.monotonic() - worker.waiting_since > HEARTBEAT_TIMEOUT:
                worker.hung = True
                self._lose(worker, f"{worker.name} stopped answering (no reply in {HEARTBEAT_TIMEOUT:.0f} s: "
                                   "stopped or stuck)")
            elif worker.load.stuck:
                worker.hung = True
                self._lose(worker, f"{worker.name} is stuck (its event loop has not run for "
                                   f"{LOOP_STUCK_TIMEOUT:.0f} s)")

    def _lose(self, worker: _Worker, what: str) -> None:
        """Without ``--http``, a lost worker stops the fleet (``FleetFailure``). With it, it is reported
        and the others go on (a hung one is stopped as ``_stop_all`` would); none left stops the fleet."""
        if self.http is None:
            raise FleetFailure(f"{what}; stopping the fleet", 1)
        worker.lost = what
        if worker.hung:
            self._terminate(worker)
            worker.kill_at = time.monotonic() + HUNG_STOP_TIMEOUT
        if not self._serving():
            raise FleetFailure(f"{what}; no worker left, stopping the fleet", 1)
        log.error("%s; its devices answer 503 on the HTTP API, the other workers go on serving", what)

    def _kill_overdue(self) -> None:
        """Kill a worker reported as not answering that SIGTERM has not ended in ``HUNG_STOP_TIMEOUT``."""
        for worker in self.workers:
            if worker.kill_at is not None and time.monotonic() >= worker.kill_at:
                worker.kill_at = None
                if worker.process.is_alive():
                    log.warning("%s did not stop in %.0f s: killed", worker.name, HUNG_STOP_TIMEOUT)
                    worker.process.kill()

    def _why_down(self, worker: _Worker) -> str | None:
        """Why ``worker`` serves no more, as soon as it has ended (before the supervision's next look)."""
        if worker.lost is None and worker.process.exitcode is not None:
            return f"{worker.name} ended: {worker.how_it_ended()}"
        return worker.lost

    async def _serve_http(self, on_ready: Callable[[], None]) -> None:
        """Serve the fleet's HTTP API and supervise the workers, both on this event loop, until a signal
        (or ``FleetFailure``). The API listens before ``on_ready``: a port it cannot take is a
        ``ListenError`` while the devices' lines are still unprinted."""
        from ..control.http import parse_listen
        from ..control.http_relay import Backend, RelayApi

        assert self.http is not None
        loop = asyncio.get_running_loop()
        wake = asyncio.Event()
        host, port = parse_listen(self.http["http"])
        relay = RelayApi([Backend(w.name, w.api_path or "", partial(self._why_down, w), w.number,
                                  load=partial(gauge_values, w.load))
                          for w in self.workers], host, port, token=self.http.get("http_token"),
                         allow_remote=self.http.get("http_allow_remote", False),
                         hosts=tuple(self.http.get("http_hosts", ())), shard=self.http.get("shard", "0/1"))
        watched: dict[int, _Worker] = {}
        self._wake = wake.set
        for sig in (signal.SIGINT, signal.SIGTERM):   # the loop's own handling, which wakes its wait
            loop.add_signal_handler(sig, self._on_signal, sig, None)
        try:
            try:
                await relay.start()
            except ConnectionError as exc:
                raise FleetFailure(str(exc), 1) from None
            except OSError as exc:
                raise ListenError(f"TCP {self.http['http']} (HTTP control API, --http)", exc) from None
            for worker in self.workers:
                for fd in (worker.channel.fileno(), worker.process.sentinel):
                    loop.add_reader(fd, wake.set)
                    watched[fd] = worker
            on_ready()
            next_ping = time.monotonic()
            while self.stop_signal is None:
                next_ping = self._ping_when_due(next_ping)
                wake.clear()
                with contextlib.suppress(asyncio.TimeoutError):
                    await asyncio.wait_for(wake.wait(), max(0.0, min(0.5, next_ping - time.monotonic())))
                self._check_workers()
                self._kill_overdue()
                for fd, worker in list(watched.items()):   # an ended worker's sentinel stays readable
                    if worker.lost is not None:
                        loop.remove_reader(fd)
                        del watched[fd]
        finally:
            self._wake = None
            for fd in watched:
                loop.remove_reader(fd)
            await relay.close()
            for sig in (signal.SIGINT, signal.SIGTERM):   # back to this supervisor's, for the stop
                loop.remove_signal_handler(sig)
                signal.signal(sig, self._on_signal)

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
                message = worker.channel.recv()
                if isinstance(message, tuple) and message[0] == PONG:
                    worker.waiting_since = None
                    report_lateness(worker.name, worker.load,
                                    worker.load.answered(LoadReport(*message[1]), time.monotonic()))
        except (EOFError, OSError):
            pass   # the worker is gone: its sentinel says so

    def _stop_all(self) -> None:
        """SIGCONT and SIGTERM to every worker still running (a stopped process acts on no signal but
        SIGKILL until it is continued); those that have not ended after ``STOP_TIMEOUT`` (one that had
        stopped answering: ``HUNG_STOP_TIMEOUT``) are killed. None is left behind."""
        for worker in self.workers:
            self._terminate(worker)
        started = time.monotonic()
        for worker in self.workers:
            timeout = HUNG_STOP_TIMEOUT if worker.hung else STOP_TIMEOUT
            worker.process.join(max(0.0, started + timeout - time.monotonic()))
            if worker.process.is_alive():
                log.warning("%s did not stop in %.0f s: killed", worker.name, timeout)
                worker.process.kill()
                worker.process.join()
            worker.channel.close()

    @staticmethod
    def _terminate(worker: _Worker) -> None:
        if worker.process.is_alive():
            with contextlib.suppress(ProcessLookupError):
                os.kill(worker.process.pid, signal.SIGCONT)
                worker.process.terminate()


__all__ = ["FleetFailure", "Supervisor", "shares"]
