"""A JSON call to an emulator's HTTP API, for the tests of its routes."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import aiohttp


async def call(http: tuple[aiohttp.ClientSession, str], method: str, path: str, **kwargs: object) -> tuple[int, object]:
    session, base = http
    async with session.request(method, base + path, **kwargs) as response:  # type: ignore[arg-type]
        assert response.content_type == "application/json"
        return response.status, await response.json()
