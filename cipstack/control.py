"""The emulator's control channel: a local Unix socket for test rigs (inject a trip, read status).

It is deliberately not a CIP object: a scanner or conformance tool talking to the emulator must see
exactly the objects the manual lists, nothing added for testing. One JSON object per line each
way: ``{"command": "trip", "code": 8960}`` -> ``{"ok": true, ...}``; ``{"command": "status"}``.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import os
import socket
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

MAX_LINE = 4096


def default_control_path(port: int) -> Path:
    """Where the emulator listening on ``port`` keeps its control socket (per user)."""
    base = os.environ.get("XDG_RUNTIME_DIR") or os.path.join(tempfile.gettempdir(), f"cipstack-{os.getuid()}")
    return Path(base) / f"cipstack-adapter-{port}.sock"


class ControlError(Exception):
    """A control request that failed (one line of text for the user)."""


class ControlRefused(ControlError):
    """The emulator answered and refused the request (a bad argument, e.g. an unknown trip code)."""


class ControlDenied(ControlError):
    """The emulator understood the request and its state refuses it (a trip while already tripped)."""


Handler = Callable[[dict[str, Any]], dict[str, Any]]


class ControlServer:
    def __init__(self, path: Path, handler: Handler) -> None:
        self.path = path
        self.handler = handler
        self._server: asyncio.AbstractServer | None = None

    async def start(self) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
        if self.path.exists():
            # A socket left by an emulator that did not stop cleanly; refuse to steal a live one.
            probe = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            try:
                probe.connect(str(self.path))
            except OSError:
                self.path.unlink()
            else:
                raise OSError(f"another emulator already uses {self.path}")
            finally:
                probe.close()
        self._server = await asyncio.start_unix_server(self._serve, path=str(self.path), limit=MAX_LINE)
        os.chmod(self.path, 0o600)
        log.info("control socket %s", self.path)

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            while line := await reader.readline():
                try:
                    request = json.loads(line)
                    if not isinstance(request, dict):
                        raise ControlError("a request is a JSON object")
                    reply = {"ok": True, **self.handler(request)}
                except (ControlError, ValueError, KeyError, TypeError) as exc:
                    reply = {"ok": False, "error": str(exc), "denied": isinstance(exc, ControlDenied)}
                writer.write(json.dumps(reply).encode() + b"\n")
                await writer.drain()
        except (ConnectionError, asyncio.LimitOverrunError, ValueError):
            pass
        finally:
            writer.close()

    async def close(self) -> None:
        if self._server is not None:
            self._server.close()
            await self._server.wait_closed()
            self._server = None
        with contextlib.suppress(FileNotFoundError):
            self.path.unlink()


def control_request(path: Path, request: dict[str, Any], timeout: float = 5.0) -> dict[str, Any]:
    """Send one request to a running emulator; raises ``ControlError`` with a one-line reason."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
        sock.settimeout(timeout)
        try:
            sock.connect(str(path))
        except OSError:
            raise ControlError(f"no emulator listens on {path} (is `cipstack adapter` running?)") from None
        sock.sendall(json.dumps(request).encode() + b"\n")
        data = b""
        while not data.endswith(b"\n"):
            chunk = sock.recv(MAX_LINE)
            if not chunk:
                break
            data += chunk
    try:
        reply = json.loads(data)
    except ValueError:
        raise ControlError("the emulator sent no reply") from None
    if not reply.get("ok"):
        if reply.get("denied"):
            raise ControlDenied(str(reply.get("error", "denied")))
        raise ControlRefused(str(reply.get("error", "refused")))
    return dict(reply)
