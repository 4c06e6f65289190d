"""Calls to an emulator's HTTP API, for the tests of its routes: a JSON call (aiohttp), and the status
of a GET with or without the bearer token (the standard library)."""

from __future__ import annotations

import urllib.error
import urllib.request
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import aiohttp


async def call(http: tuple[aiohttp.ClientSession, str], method: str, path: str, **kwargs: object) -> tuple[int, object]:
    session, base = http
    async with session.request(method, base + path, **kwargs) as response:  # type: ignore[arg-type]
        assert response.content_type == "application/json"
        return response.status, await response.json()


def status(url: str, token: str | None) -> int:
    """The HTTP status of ``GET url``, with ``Authorization: Bearer token`` when a token is given."""
    request = urllib.request.Request(url)
    if token is not None:
        request.add_header("Authorization", f"Bearer {token}")
    try:
        with urllib.request.urlopen(request, timeout=10) as reply:
            return int(reply.status)
    except urllib.error.HTTPError as error:
        with error:
            return int(error.code)
