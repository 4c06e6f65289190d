"""Saved drive parameters: the drive's non-volatile memory, as a JSON file.

Every drive family follows the same rule (ACG: seed 001, "Saving Parameters Defined by
Communication"): a value written over the network takes effect at once but is lost at the
next power cycle unless it has been saved; a saved value survives. A drive keeps its saved
values in a ``ParameterStore``; restarting an emulated drive on the same file is a power cycle.

The file is JSON::

    {"format": "cipstack.drive-state", "version": 1, "family": "acg", "model": "ACG-ET2",
     "parameters": {"0x1F01": 50, "0x1F03": 4}}

It is written atomically (a temporary file in the same directory, fsync, then ``os.replace``),
so a crash leaves either the old file or the new one. A file that is truncated, corrupt, of
another format or version, or of another drive family raises ``StateFileError`` with a one-line
message: an emulated drive never falls back silently to its factory values.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import tempfile
from collections.abc import Mapping
from pathlib import Path

STATE_FORMAT = "cipstack.drive-state"
STATE_VERSION = 1

_PROFILE_PATTERN = re.compile(r"^[A-Za-z0-9_-][A-Za-z0-9._-]*$")
_ADDRESS_PATTERN = re.compile(r"^0x[0-9A-Fa-f]{1,8}$")


class StateFileError(Exception):
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
        raise ValueError(f"profile name {profile!r} must be letters, digits, '.', '_' or '-'")
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
        return load_state(self.path, self.family)

    def save(self, values: Mapping[int, int]) -> None:
        save_state(self.path, self.family, self.model, values)

    def __repr__(self) -> str:
        return f"ParameterStore({str(self.path)!r}, family={self.family!r}, model={self.model!r})"
