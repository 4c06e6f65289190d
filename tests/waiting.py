"""Waiting for a condition another process or thread brings about, bounded in time."""

from __future__ import annotations

import time
from collections.abc import Callable


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
