"""The emulator's control channel: a local Unix socket for test rigs (inject a trip, read status).

Where it is: by default, on Linux, an abstract Unix socket named after the emulator's EtherNet/IP
address and port (``@cipstack-adapter-UID-HOST-PORT``). Abstract names belong to the network
namespace, so two emulators in two namespaces never clash, two emulators on two addresses of one
machine never clash, and a killed emulator leaves no file behind to refuse the next one. Only the
user who runs the emulator (or root) is served: the peer's credentials are checked. Elsewhere, and
with ``--control PATH``, it is a socket file (mode 0600).

It is deliberately not a CIP object: a scanner or conformance tool talking to the emulator must see
exactly the objects the manual lists, nothing added for testing. One JSON object per line each
way: ``{"command": "trip", "code": 8960}`` -> ``{"ok": true, ...}``; ``{"command": "status"}``.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import json
import logging
import os
import socket
import struct
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from .eip.limits import RateLimitedLog

log = logging.getLogger(__name__)

MAX_LINE = 4096


#: A control address: a socket file, or (a ``str`` starting with NUL) a Linux abstract socket name.
ControlAddress = Path | str


def default_control_path(port: int, host: str = "127.0.0.1") -> ControlAddress:
    """Where the emulator listening on ``host:port`` keeps its control socket (per user; on Linux per
    network namespace too)."""
    host = host or "0.0.0.0"
    if sys.platform.startswith("linux"):
        return f"\0cipstack-adapter-{os.getuid()}-{host}-{port}"
    base = os.environ.get("XDG_RUNTIME_DIR") or os.path.join(tempfile.gettempdir(), f"cipstack-{os.getuid()}")
    return Path(base) / f"cipstack-adapter-{host}-{port}.sock"


def is_abstract(address: ControlAddress) -> bool:
    return isinstance(address, str) and address.startswith("\0")


def describe(address: ControlAddress) -> str:
    """The address as a person reads it (an abstract name with ``@``, as ``ss -x`` shows it)."""
    return "@" + address[1:] if is_abstract(address) else str(address)


def _peer_uid(writer: asyncio.StreamWriter) -> int | None:
    """The connecting process's user id (SO_PEERCRED), or None where the platform does not say."""
    sock = writer.get_extra_info("socket")
    if sock is None or not hasattr(socket, "SO_PEERCRED"):
        return None
    try:
        _pid, uid, _gid = struct.unpack("3i", sock.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED,
                                                              struct.calcsize("3i")))
    except OSError:
        return None
    return uid


class ControlError(Exception):
    """A control request that failed (one line of text for the user)."""


class ControlRefused(ControlError):
    """The emulator answered and refused the request (a bad argument, e.g. an unknown trip code)."""


class ControlDenied(ControlError):
    """The emulator understood the request and its state refuses it (a trip while already tripped)."""


Handler = Callable[[dict[str, Any]], dict[str, Any]]


class ControlServer:
    def __init__(self, path: ControlAddress, handler: Handler) -> None:
        self.path = path
        self.handler = handler
        self._server: asyncio.AbstractServer | None = None
        #: Other users knocking: at most one line per 10 s per user id (``RateLimitedLog``).
        self.refused_log = RateLimitedLog(log)

    async def start(self) -> None:
        if is_abstract(self.path):
            try:
                self._server = await asyncio.start_unix_server(self._serve, path=self.path, limit=MAX_LINE)
            except OSError as exc:
                if exc.errno == errno.EADDRINUSE:
                    raise OSError(exc.errno, f"another emulator already uses {describe(self.path)}") from None
                raise
            log.info("control socket %s", describe(self.path))
            return
        path = Path(self.path)
        path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
        if path.exists():
            # A socket left by an emulator that did not stop cleanly; refuse to steal a live one.
            probe = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            try:
                probe.connect(str(path))
            except OSError:
                path.unlink()
            else:
                raise OSError(f"another emulator already uses {path}")
            finally:
                probe.close()
        self._server = await asyncio.start_unix_server(self._serve, path=str(path), limit=MAX_LINE)
        os.chmod(path, 0o600)
        log.info("control socket %s", path)

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        uid = _peer_uid(writer)
        if uid is not None and uid not in (0, os.getuid()):
            # An abstract socket has no file mode to keep other users out: their credentials do.
            self.refused_log("control socket: a process of user %d refused (only user %d or root)", uid,
                             os.getuid(), source=uid)
            writer.close()
            return
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
        if not is_abstract(self.path):
            with contextlib.suppress(FileNotFoundError):
                Path(self.path).unlink()


def control_request(path: ControlAddress, request: dict[str, Any], timeout: float = 5.0) -> dict[str, Any]:
    """Send one request to a running emulator; raises ``ControlError`` with a one-line reason."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
        sock.settimeout(timeout)
        try:
            sock.connect(path if is_abstract(path) else str(path))
        except OSError:
            raise ControlError(f"no emulator listens on {describe(path)} (is `cipstack adapter` running?)") from None
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
