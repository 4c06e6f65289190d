"""The emulator's control channel: a local Unix socket for test rigs (trips, faults, status).

Where it is: by default, on Linux, an abstract Unix socket named after the emulator's EtherNet/IP
address and port (``@cipstack-adapter-UID-HOST-PORT``). Abstract names belong to the network
namespace, so two emulators in two namespaces never clash, two emulators on two addresses of one
machine never clash, and a killed emulator leaves no file behind to refuse the next one. Only the
user who runs the emulator (or root) is served: the peer's credentials are checked. Elsewhere, and
with ``--control PATH``, it is a socket file (mode 0600).

It is deliberately not a CIP object: a scanner or conformance tool talking to the emulator must see
exactly the objects the manual lists, nothing added for testing. One JSON object per line each
way: ``{"command": OPERATION, KEY: VALUE...}`` with an operation of the command service
(``service.OPERATIONS``: ``{"command": "trip", "code": 8960}``, ``{"command": "status"}``) ->
``{"ok": true, ...}``, or ``{"ok": false, "error": "...", "outcome": "refused"}`` (``service.OUTCOMES``).
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import inspect
import json
import logging
import os
import pwd
import socket
import struct
import sys
import tempfile
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any, TypeGuard

from ..eip.target.limits import RateLimitedLog
from ..errors import BadRequest, CipstackError, NotFound, PeerUnreachable, StateRefused

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


def is_abstract(address: ControlAddress) -> TypeGuard[str]:
    return isinstance(address, str) and address.startswith("\0")


def describe(address: ControlAddress) -> str:
    """The address as a person reads it (an abstract name with ``@``, as ``ss -x`` shows it)."""
    return "@" + address[1:] if is_abstract(address) else str(address)


def peer_credentials(sock: socket.socket) -> tuple[int, int] | None:
    """(process id, user id) of the other end of a connected Unix socket (SO_PEERCRED: for a server,
    the process that called listen()), or None where the platform does not say."""
    if not hasattr(socket, "SO_PEERCRED"):
        return None
    try:
        pid, uid, _gid = struct.unpack("3i", sock.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED,
                                                             struct.calcsize("3i")))
    except OSError:
        return None
    return pid, uid


def _peer_uid(writer: asyncio.StreamWriter) -> int | None:
    """The connecting process's user id (SO_PEERCRED), or None where the platform does not say."""
    sock = writer.get_extra_info("socket")
    credentials = peer_credentials(sock) if sock is not None else None
    return credentials[1] if credentials is not None else None


def trusted_uid(uid: int) -> bool:
    """Whether a process of user ``uid`` may be at the other end of the control channel: this user, or
    root. Both ends hold to it: the server serves no one else, the client believes no one else."""
    return uid in (0, os.getuid())


def user_text(uid: int) -> str:
    """``65534 (nobody)``: a user id and, where the system knows it, its name."""
    try:
        return f"{uid} ({pwd.getpwuid(uid).pw_name})"
    except (KeyError, OverflowError):
        return str(uid)


def holder(address: ControlAddress) -> tuple[int, int] | None:
    """(process id, user id) of whoever listens on ``address``, or None when nothing does (or the
    platform does not say)."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as probe:
        probe.settimeout(1.0)
        try:
            probe.connect(address if is_abstract(address) else str(address))
        except OSError:
            return None
        return peer_credentials(probe)


class ControlError(CipstackError):
    """A control request that failed (one line of text for the user): no emulator answered."""


class ControlUnreachable(ControlError, PeerUnreachable):
    """No emulator listens on the control socket, or it sent no reply."""


class ControlRefused(ControlError, BadRequest):
    """The emulator answered and refused the request (a bad argument, e.g. an unknown trip code)."""


class ControlNotFound(ControlError, NotFound):
    """The emulator answered: what the request names is not there (a keypad code, a fault id)."""


class ControlDenied(ControlError, StateRefused):
    """The emulator understood the request and its state refuses it (a trip while already tripped)."""


#: The error a client raises for each outcome the emulator answered (``service.OUTCOMES``).
_CLIENT_ERRORS: dict[str, type[ControlError]] = {"bad-request": ControlRefused, "not-found": ControlNotFound,
                                                 "refused": ControlDenied, "unreachable": ControlUnreachable}


#: Serves one request: its reply, or an awaitable of it (a request that waits for the loop's work).
Handler = Callable[[dict[str, Any]], dict[str, Any] | Awaitable[dict[str, Any]]]


class ControlTaken(CipstackError, OSError):
    """The control socket's address is held by another process; the text says by whom."""


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
                    raise ControlTaken(exc.errno, self._taken_by()) from None
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
                raise ControlTaken(errno.EADDRINUSE, f"another emulator already uses {path}")
            finally:
                probe.close()
        self._server = await asyncio.start_unix_server(self._serve, path=str(path), limit=MAX_LINE)
        os.chmod(path, 0o600)
        log.info("control socket %s", path)

    def _taken_by(self) -> str:
        """Who holds the address: another emulator of this user, or a process of another user."""
        held = holder(self.path)
        if held is None:
            return f"{describe(self.path)} is taken"
        pid, uid = held
        if trusted_uid(uid):
            return f"another emulator (process {pid}) already uses {describe(self.path)}"
        return (f"{describe(self.path)} is held by process {pid} of user {user_text(uid)}, not by an emulator "
                f"of yours")

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        uid = _peer_uid(writer)
        if uid is not None and not trusted_uid(uid):
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
                        raise BadRequest("a request is a JSON object")
                    answer = self.handler(request)
                    if inspect.isawaitable(answer):
                        answer = await answer
                    reply = {"ok": True, **(answer if isinstance(answer, dict) else {"result": answer})}
                except CipstackError as exc:
                    reply = {"ok": False, "error": str(exc), "outcome": outcome_name(exc)}
                except ValueError as exc:   # a line that is not JSON
                    reply = {"ok": False, "error": f"not a JSON request: {exc}", "outcome": "bad-request"}
                except Exception:  # a request must never take the control socket down
                    log.exception("control request %r", line[:200])
                    reply = {"ok": False, "error": "internal error (logged)", "outcome": "failed"}
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


def outcome_name(error: BaseException) -> str:
    from .service import outcome

    found = outcome(error)
    return found.name if found is not None else "failed"


def control_request(path: ControlAddress, request: dict[str, Any], timeout: float = 5.0) -> dict[str, Any]:
    """Send one request to a running emulator; raises ``ControlError`` with a one-line reason."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
        sock.settimeout(timeout)
        try:
            sock.connect(path if is_abstract(path) else str(path))
        except OSError:
            raise ControlUnreachable(f"no emulator listens on {describe(path)} (is `cipstack adapter` running?)") \
                from None
        # Anyone may take an abstract name first (it has no file mode): what another user listens
        # with is not believed, as the server serves no other user.
        credentials = peer_credentials(sock)
        if credentials is not None and not trusted_uid(credentials[1]):
            raise ControlUnreachable(f"{describe(path)} is held by process {credentials[0]} of user "
                               f"{user_text(credentials[1])}, not by an emulator of yours: refused")
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
        raise ControlUnreachable("the emulator sent no reply") from None
    if not reply.get("ok"):
        raise _CLIENT_ERRORS.get(str(reply.get("outcome")), ControlError)(str(reply.get("error", "refused")))
    return dict(reply)
