"""What every command shares: exit statuses, the usage error, parsing of numbers, paths, types and
durations, and one-record output."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from ..cip.types import CipType, parse_int, type_by_name
from ..errors import CipstackError

if TYPE_CHECKING:
    import argparse

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_USAGE = 2


class UsageError(CipstackError):
    """A bad argument: reported as one line, exit status 2. Raised by the parser, it carries the
    parser's ``prog`` (``cipstack get``) and usage, which ``main`` prints before the line."""

    # Not a BadRequest: that is a ValueError, and argparse replaces the message of a ValueError
    # raised by a ``type=`` function with its own "invalid <lambda> value".

    def __init__(self, message: str, *, prog: str | None = None, usage: str = "") -> None:
        super().__init__(message)
        self.prog = prog
        self.usage = usage


def parse_number(text: str, what: str) -> int:
    try:
        return parse_int(text)
    except ValueError:
        raise UsageError(f"{what}: {text!r} is not a number (decimal or 0x hex)") from None


def parse_object_path(text: str, need_attribute: bool = False) -> tuple[int, int, int | None]:
    """``CLASS/INSTANCE[/ATTRIBUTE]`` with decimal or 0x hex numbers."""
    parts = text.strip().lstrip("@").split("/")
    if len(parts) not in (2, 3) or (need_attribute and len(parts) != 3):
        form = "CLASS/INSTANCE/ATTRIBUTE" if need_attribute else "CLASS/INSTANCE[/ATTRIBUTE]"
        raise UsageError(f"path {text!r} is not {form}")
    numbers = [parse_number(p, "path") for p in parts]
    for number, limit, name in zip(numbers, (0xFFFF, 0xFFFF, 0xFFFF), ("class", "instance", "attribute"), strict=False):
        if not 0 <= number <= limit:
            raise UsageError(f"{name} {number} out of range 0..{limit}")
    return numbers[0], numbers[1], (numbers[2] if len(numbers) == 3 else None)


def parse_type(text: str | None) -> CipType | None:
    if text is None:
        return None
    try:
        return type_by_name(text)
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def parse_duration(text: str) -> float:
    """``2``, ``2.5``, ``500ms``, ``2s``."""
    raw = text.strip().lower()
    scale = 1.0
    if raw.endswith("ms"):
        raw, scale = raw[:-2], 0.001
    elif raw.endswith("s"):
        raw = raw[:-1]
    try:
        value = float(raw) * scale
    except ValueError:
        raise UsageError(f"{text!r} is not a duration (e.g. 2, 500ms, 1.5s)") from None
    if value < 0:
        raise UsageError(f"duration {text!r} is negative")
    return value


def _emit(args: argparse.Namespace, record: dict[str, Any], text: str) -> None:
    if args.json:
        import json  # only for --json: a one-shot that prints text does without

        print(json.dumps(record), flush=True)
    else:
        print(text, flush=True)
