"""Saved drive parameters: the drive's non-volatile memory, as a JSON file.

Every drive family follows the same rule (ACG: ACG RS-485 manual, "Saving Parameters Defined by
Communication"): a value written over the network takes effect at once but is lost at the
next power cycle unless it has been saved; a saved value survives. A drive keeps its saved
values in a ``ParameterStore``; restarting an emulated drive on the same file is a power cycle.

The file is JSON::

    {"format": "cipstack.drive-state", "version": 1, "family": "acg", "model": "ACG-ET2",
     "parameters": {"0x1F01": 50, "0x1F03": 4}}

It is written atomically (a temporary file in the same directory, fsync, then ``os.replace``),
so a crash leaves either the old file or the new one; the temporary files a killed save leaves
behind are removed at the next start (``ParameterStore.load``). A file that is truncated, corrupt,
too deep or too large to decode, of another format or version, or of another drive family raises
``StateFileError`` with a one-line message naming the file: an emulated drive never falls back
silently to its factory values.

A drive model does no file I/O: it hands each save to its shell, and a running emulator writes
it with a ``StateWriter``, on a thread of its own (never on the event loop's thread), coalescing
back-to-back saves. A write that fails (a read-only directory, a full disk) keeps the old file,
logs one line naming the file and the reason, and refuses the save to the client that asked.
"""

from __future__ import annotations

import contextlib
import glob
import json
import logging
import os
import re
import tempfile
import threading
from collections.abc import Mapping
from concurrent.futures import Future
from pathlib import Path

from ..errors import BadRequest, StateRefused

log = logging.getLogger(__name__)

STATE_FORMAT = "cipstack.drive-state"
STATE_VERSION = 1

_PROFILE_PATTERN = re.compile(r"^[A-Za-z0-9_-][A-Za-z0-9._-]*$")
_ADDRESS_PATTERN = re.compile(r"^0x[0-9A-Fa-f]{1,8}$")


class StateFileError(StateRefused):
    """A state file that cannot be used as it is; the message is one line and names the file."""


def data_directory() -> Path:
    """The user's data directory for cipstack (platformdirs if installed, else ~/.local/share)."""
    try:
        import platformdirs
    except ImportError:
        return Path.home() / ".local" / "share" / "cipstack"
    return Path(platformdirs.user_data_dir("cipstack", appauthor=False))


def default_state_path(profile: str) -> Path:
    """Where the emulated drive of ``profile`` (e.g. "acg") keeps its saved parameters."""
    if not _PROFILE_PATTERN.match(profile):
        raise BadRequest(f"profile name {profile!r} must be letters, digits, '.', '_' or '-'")
    return data_directory() / "state" / f"{profile}.json"


def _format_address(address: int) -> str:
    return f"0x{address:04X}"


def encode_state(family: str, model: str, values: Mapping[int, int]) -> str:
    document = {
        "format": STATE_FORMAT,
        "version": STATE_VERSION,
        "family": family,
        "model": model,
        "parameters": {_format_address(a): int(values[a]) for a in sorted(values)},
    }
    return json.dumps(document, indent=2) + "\n"


def decode_state(text: str, family: str, *, origin: str = "state file") -> dict[int, int]:
    """The saved values of a state document, checked to be ``family``'s."""
    try:
        document = json.loads(text)
    except json.JSONDecodeError as exc:
        raise StateFileError(f"{origin}: not valid JSON, truncated or corrupt ({exc.msg} at line {exc.lineno}, "
                             f"column {exc.colno})") from None
    except RecursionError:
        raise StateFileError(f"{origin}: nested too deeply to be a state file, corrupt") from None
    except ValueError as exc:   # e.g. an integer of more digits than Python converts (4300)
        raise StateFileError(f"{origin}: corrupt ({_one_line(exc)})") from None
    if not isinstance(document, dict) or document.get("format") != STATE_FORMAT:
        raise StateFileError(f"{origin}: not a cipstack drive state file (no \"format\": \"{STATE_FORMAT}\")")
    version = document.get("version")
    if version != STATE_VERSION:
        raise StateFileError(f"{origin}: state format version {version!r}, this cipstack reads version "
                             f"{STATE_VERSION}")
    if document.get("family") != family:
        raise StateFileError(f"{origin}: holds the parameters of a {document.get('family')!r} drive, "
                             f"not of a {family!r} drive")
    parameters = document.get("parameters")
    if not isinstance(parameters, dict):
        raise StateFileError(f"{origin}: \"parameters\" is missing or not an object")
    values: dict[int, int] = {}
    for key, value in parameters.items():
        if not _ADDRESS_PATTERN.match(key) or isinstance(value, bool) or not isinstance(value, int):
            raise StateFileError(f"{origin}: malformed parameter entry {key!r}: {value!r}")
        values[int(key, 16)] = value
    return values


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())


def load_state(path: str | os.PathLike[str], family: str) -> dict[int, int]:
    """The saved values in ``path``: address -> raw value; {} if nothing has been saved yet."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return {}
    except OSError as exc:
        raise StateFileError(f"{path}: cannot be read ({exc.strerror})") from None
    if not data.strip():
        raise StateFileError(f"{path}: empty file (truncated)")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise StateFileError(f"{path}: not UTF-8 text, corrupt") from None
    return decode_state(text, family, origin=str(path))


def save_state(path: str | os.PathLike[str], family: str, model: str, values: Mapping[int, int]) -> None:
    """Write ``values`` to ``path`` atomically: temporary file, fsync, rename, fsync the directory."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    text = encode_state(family, model, values)
    fd, temporary = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as stream:
            stream.write(text)
            stream.flush()
            os.fsync(stream.fileno())
        os.replace(temporary, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(temporary)
        raise
    _fsync_directory(path.parent)


def remove_stale_temporaries(path: str | os.PathLike[str]) -> list[Path]:
    """Remove the temporary files of saves of ``path`` that never finished (a killed process);
    the ones that could be removed are returned. Call it at start, before any save of ``path``."""
    path = Path(path)
    removed: list[Path] = []
    try:
        candidates = list(path.parent.glob(f".{glob.escape(path.name)}.*.tmp"))
    except OSError:
        return removed
    for candidate in candidates:
        with contextlib.suppress(OSError):
            candidate.unlink()
            removed.append(candidate)
    return removed


def _fsync_directory(directory: Path) -> None:
    # The rename is durable once the directory entry is; not every platform can open a directory.
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


class ParameterStore:
    """The saved parameters of one emulated drive, kept in one state file."""

    def __init__(self, path: str | os.PathLike[str], family: str, model: str) -> None:
        self.path = Path(path)
        self.family = family
        self.model = model

    def load(self) -> dict[int, int]:
        """The saved values, at start: temporary files of saves a killed process left are removed first."""
        removed = remove_stale_temporaries(self.path)
        if removed:
            log.info("%s: removed %d temporary file(s) of unfinished saves", self.path, len(removed))
        return load_state(self.path, self.family)

    def save(self, values: Mapping[int, int]) -> None:
        """Write ``values`` now, on the caller's thread (a ``StateWriter`` calls it off the event loop).
        A failure raises ``StateFileError`` with one line naming the file; the file keeps its old values."""
        try:
            save_state(self.path, self.family, self.model, values)
        except (OSError, ValueError) as exc:
            reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else _one_line(exc)
            raise StateFileError(f"{self.path}: parameters not saved ({reason}); "
                                 f"the file keeps the ones saved before") from None

    def __repr__(self) -> str:
        return f"ParameterStore({str(self.path)!r}, family={self.family!r}, model={self.model!r})"


class StateWriter:
    """Writes the saves of one ``ParameterStore`` on a thread of its own.

    ``submit`` returns at once with a ``Future`` of the write. Saves coalesce: while one is being
    written, the saves that follow replace each other and only the latest is written next, so a
    save storm costs at most two writes in flight and never blocks the caller. ``error`` is the
    last write's failure (None once a write succeeds): a shell refuses a save while it is set.
    """

    def __init__(self, store: ParameterStore, written: Mapping[int, int] | None = None) -> None:
        """``written``: what the file holds now (what ``store.load()`` returned at start)."""
        self.store = store
        self.error: StateFileError | None = None
        self._written: dict[int, int] = dict(written or {})
        #: Saves submitted and files written (the difference: the saves coalesced away).
        self.submitted = 0
        self.written = 0
        self.last: Future[None] | None = None
        self._condition = threading.Condition()
        self._pending: dict[int, int] | None = None
        self._waiters: list[Future[None]] = []
        self._busy = False
        self._closed = False
        self._thread: threading.Thread | None = None

    @property
    def path(self) -> Path:
        return self.store.path

    def submit(self, values: Mapping[int, int]) -> Future[None]:
        """Have ``values`` written; the latest values submitted are the ones the file ends with."""
        future: Future[None] = Future()
        with self._condition:
            if self._closed:
                raise StateFileError(f"{self.path}: parameters not saved (the emulator is stopping)")
            self._pending = dict(values)
            self._waiters.append(future)
            self.submitted += 1
            self.last = future
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name=f"state writer {self.path.name}",
                                                daemon=True)
                self._thread.start()
            self._condition.notify_all()
        return future

    def request(self, values: Mapping[int, int]) -> Future[None]:
        """A drive's save: submitted, or refused with the last failure (``StateFileError``) while
        the file is known not to take a write. A refused save is not written; the file is written
        again with what it already holds instead, to find out whether it takes writes again."""
        with self._condition:
            error = self.error
        if error is not None:
            self.submit(self._written)
            raise error
        return self.submit(values)

    def _run(self) -> None:
        while True:
            with self._condition:
                while self._pending is None and not self._closed:
                    self._condition.wait()
                if self._pending is None:
                    return
                values, waiters = self._pending, self._waiters
                self._pending, self._waiters = None, []
                self._busy = True
            error: StateFileError | None = None
            try:
                self.store.save(values)
            except StateFileError as exc:
                error = exc
                log.error("%s", exc)
            except Exception as exc:   # a bug must not kill the writer: one line, the file as it was
                error = StateFileError(f"{self.path}: parameters not saved ({_one_line(exc)})")
                log.error("%s", error)
            with self._condition:
                self._busy = False
                self.error = error
                self.written += 1
                if error is None:
                    self._written = values
                self._condition.notify_all()
            for waiter in waiters:
                if error is None:
                    waiter.set_result(None)
                else:
                    waiter.set_exception(error)

    def flush(self, timeout: float | None = None) -> bool:
        """Wait until every save submitted so far is written (or has failed); False on timeout."""
        with self._condition:
            return self._condition.wait_for(lambda: self._pending is None and not self._busy, timeout)

    def close(self, timeout: float | None = 10.0) -> None:
        """Write what is pending, then stop the thread."""
        with self._condition:
            self._closed = True
            self._condition.notify_all()
            thread = self._thread
        if thread is not None:
            thread.join(timeout)
