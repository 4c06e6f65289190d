"""``cipstack.control.plant_grid``: one reading of a plant's rows is shared by every grid that asks
within half a second, and by those that ask while it is under way."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from cipstack.control.plant_grid import ROWS_SHARED_FOR, SharedRows


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


async def test_grids_asking_together_or_soon_after_share_one_reading() -> None:
    readings: list[int] = []
    release = asyncio.Event()

    async def read() -> list[dict[str, Any]]:
        readings.append(len(readings) + 1)
        await release.wait()
        return [{"address": "127.0.0.1", "reading": len(readings)}]

    clock = Clock()
    rows = SharedRows(read, clock)
    waiting = [asyncio.ensure_future(rows.get()) for _ in range(3)]
    await asyncio.sleep(0)
    release.set()
    answers = await asyncio.gather(*waiting)
    assert readings == [1] and all(answer == [{"address": "127.0.0.1", "reading": 1}] for answer in answers)
    clock.now += ROWS_SHARED_FOR / 2
    assert await rows.get() == answers[0] and readings == [1]
    clock.now += ROWS_SHARED_FOR
    assert await rows.get() == [{"address": "127.0.0.1", "reading": 2}] and readings == [1, 2]


async def test_a_failed_reading_is_not_kept() -> None:
    calls = 0

    async def read() -> list[dict[str, Any]]:
        nonlocal calls
        calls += 1
        if calls == 1:
            raise ConnectionError("a worker went away")
        return []

    rows = SharedRows(read, Clock())
    with pytest.raises(ConnectionError, match="a worker went away"):
        await rows.get()
    assert await rows.get() == [] and calls == 2
