"""Class 1 connections for synchronous code: a private event loop in a background thread.

``SyncScanner.io_connection`` opens the connection on that loop (the precise loop the command line
runs, so a 1 ms RPI keeps the async handle's figures) and hands back a ``SyncIoConnection``: plain
methods, callable from any thread. Output fields are written into the buffer the loop produces
from, all of an ``update`` at once; input is the latest data the loop consumed. Leaving the ``with``
block, by any way, or ``close()``, sends the Forward_Close and waits for it.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import threading
from collections.abc import Callable, Coroutine
from typing import TYPE_CHECKING, Any, TypeVar

from .errors import NoReply, TimedOut, WrongState

if TYPE_CHECKING:
    from .eip.originator.io_originator import IoConnectionHandle, ProcessImage

T = TypeVar("T")

#: How long closing waits for the Forward_Close and the loop to stop, in seconds.
CLOSE_TIMEOUT = 10.0


class LoopThread:
    """An event loop (the precise one) running in a daemon thread, for blocking callers."""

    def __init__(self, name: str = "cipstack-io") -> None:
        from .eip.io_server import precise_event_loop

        self.loop = precise_event_loop()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        asyncio.set_event_loop(self.loop)
        self.loop.run_forever()

    def run(self, coroutine: Coroutine[Any, Any, T], timeout: float | None = None) -> T:
        """Run ``coroutine`` on the loop and wait for its result (from any other thread)."""
        if threading.current_thread() is self._thread:
            coroutine.close()
            raise WrongState("a blocking call from the connection's own loop would wait for itself")
        future = asyncio.run_coroutine_threadsafe(coroutine, self.loop)
        try:
            return future.result(timeout)
        except concurrent.futures.TimeoutError:
            future.cancel()
            raise NoReply(f"no result within {timeout} s") from None

    def stop(self) -> None:
        if self.loop.is_closed():
            return
        self.loop.call_soon_threadsafe(self.loop.stop)
        self._thread.join(CLOSE_TIMEOUT)
        if not self._thread.is_alive():
            self.loop.close()


class SyncIoConnection:
    """An open class 1 connection for synchronous code (``SyncScanner.io_connection``).

    ``io.update(run_forward=True, speed_reference=900)`` sets output fields (all at once, between two
    productions); ``io.input.speed_actual`` reads the latest input; ``io.wait_input(lambda i:
    i.at_reference, timeout=5)`` blocks until the input says so; ``io.statistics()`` gives the
    counters. Use it in a ``with`` block, or call ``close()``: either sends the Forward_Close.
    """

    def __init__(self, runner: LoopThread, opener: Callable[[contextlib.AsyncExitStack], Coroutine[Any, Any, Any]],
                 on_close: Callable[[SyncIoConnection], None] | None = None) -> None:
        self._runner = runner
        self._stack = contextlib.AsyncExitStack()
        self._on_close = on_close
        self._closed = False
        self._handle: IoConnectionHandle = runner.run(self._open(opener))

    async def _open(self, opener: Callable[[contextlib.AsyncExitStack], Coroutine[Any, Any, Any]]
                    ) -> IoConnectionHandle:
        try:
            return await opener(self._stack)  # type: ignore[no-any-return]
        except BaseException:
            await self._stack.aclose()
            raise

    # -- data ------------------------------------------------------------------------------------
    @property
    def handle(self) -> IoConnectionHandle:
        """The async handle on the background loop (for its statistics objects; do not await it here)."""
        return self._handle

    @property
    def output(self) -> ProcessImage:
        """The output data: fields by name (``io.output.speed_reference = 900``) and ``raw``."""
        return self._handle.output

    @property
    def input(self) -> ProcessImage:
        """The latest input data: fields by name and ``raw``; ``IoTimeoutError`` once the target went silent."""
        return self._handle.input

    def update(self, **fields: Any) -> None:
        """Set output fields by name, all in the same production."""
        self._handle.output.update(**fields)

    def set_run(self, run: bool) -> None:
        """Run (True) or idle (False) in the O->T run/idle header."""
        self._handle.set_run(run)

    def wait_input(self, predicate: Callable[[ProcessImage], Any], timeout: float) -> ProcessImage:
        """Block until ``predicate(input)`` is true and return that input; ``TimeoutError`` after
        ``timeout`` seconds, ``IoTimeoutError`` if the target goes silent. ``predicate`` runs on the
        connection's loop: keep it short."""
        try:
            return self._runner.run(self._handle.wait_input(predicate, timeout), timeout + CLOSE_TIMEOUT)
        except asyncio.TimeoutError:
            raise TimedOut(f"input did not satisfy the condition within {timeout} s") from None

    def statistics(self) -> dict[str, Any]:
        """Counters and T->O arrival figures (``IoConnectionHandle.statistics``)."""
        return self._handle.statistics()

    @property
    def notes(self) -> list[str]:
        """What opening had to adapt to, one line each."""
        return self._handle.notes

    @property
    def timed_out(self) -> bool:
        return self._handle.timed_out

    # -- life cycle --------------------------------------------------------------------------------
    @property
    def closed(self) -> bool:
        return self._closed

    def close(self) -> None:
        """Send the Forward_Close and close the connection's session (once; later calls do nothing)."""
        if self._closed:
            return
        self._closed = True
        try:
            self._runner.run(self._stack.aclose(), CLOSE_TIMEOUT)
        finally:
            if self._on_close is not None:
                self._on_close(self)

    def __enter__(self) -> SyncIoConnection:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def run_in_private_loop(coroutine: Coroutine[Any, Any, T]) -> T:
    """Run ``coroutine`` to completion from blocking code, even when the calling thread already runs
    an event loop (a notebook): then in a thread of its own."""
    try:
        asyncio.get_running_loop()
    except RuntimeError:
        return asyncio.run(coroutine)
    with concurrent.futures.ThreadPoolExecutor(1) as pool:
        return pool.submit(asyncio.run, coroutine).result()


__all__ = ["LoopThread", "SyncIoConnection", "run_in_private_loop"]
