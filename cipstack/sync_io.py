"""Asyncio for blocking callers: an event loop in a background thread (``LoopThread``) and a coroutine
run to completion from blocking code (``run_in_private_loop``, what ``discover_blocking`` runs on).

Class 1 for synchronous code no longer runs here: ``SyncScanner.io_connection`` returns a
``SyncIoConnection`` of ``eip.originator.blocking_io``, with no event loop (its name is exported from
here as it was).
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import threading
from collections.abc import Coroutine
from typing import Any, TypeVar

from .errors import NoReply, WrongState

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


def run_in_private_loop(coroutine: Coroutine[Any, Any, T]) -> T:
    """Run ``coroutine`` to completion from blocking code, even when the calling thread already runs
    an event loop (a notebook): then in a thread of its own."""
    try:
        asyncio.get_running_loop()
    except RuntimeError:
        return asyncio.run(coroutine)
    with concurrent.futures.ThreadPoolExecutor(1) as pool:
        return pool.submit(asyncio.run, coroutine).result()


from .eip.originator.blocking_io import SyncIoConnection  # noqa: E402 - the name's old home

__all__ = ["LoopThread", "SyncIoConnection", "run_in_private_loop"]
