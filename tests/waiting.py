"""Waiting for a condition another process or thread brings about, bounded in time."""

from __future__ import annotations

import asyncio
import signal
import subprocess
import time
from collections.abc import Callable
from typing import Any


def wait_for(predicate: Callable[[], object], timeout: float, what: str = "the condition",
             interval: float = 0.01) -> bool:
    """Poll ``predicate`` until it is true (returns True) or ``timeout`` seconds have passed
    (raises ``TimeoutError`` naming ``what``)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(interval)
    if predicate():
        return True
    raise TimeoutError(f"timed out after {timeout:g} s waiting for {what}")


async def wait_until(predicate: Callable[[], object], timeout: float, what: str = "the condition",
                     interval: float = 0.01) -> None:
    """``wait_for`` inside the event loop the condition depends on: it polls between ``asyncio.sleep``s,
    so the loop goes on serving (raises ``TimeoutError`` naming ``what``)."""
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() >= deadline:
            raise TimeoutError(f"timed out after {timeout:g} s waiting for {what}")
        await asyncio.sleep(interval)


def wait_listening(process: subprocess.Popen[Any], port: int, what: str, timeout: float = 30) -> None:
    """Wait until ``process`` accepts TCP on 127.0.0.1:``port``, or has exited (the caller then says
    why: its ``poll()`` is not None)."""
    import socket

    def listening() -> bool:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
        except OSError:
            return process.poll() is not None
        return True

    wait_for(listening, timeout, what)


def stop_process(process: subprocess.Popen[Any], timeout: float = 10) -> None:
    """End a process a test started: SIGTERM, as a user's service manager would, and SIGKILL if it
    has not exited after ``timeout`` seconds."""
    if process.poll() is None:
        process.send_signal(signal.SIGTERM)
        try:
            process.wait(timeout)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
