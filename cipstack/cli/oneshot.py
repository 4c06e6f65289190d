"""The one-shot commands' lines read without argparse: ``get``, ``set`` and ``identity``.

A script calls ``cipstack get HOST 1/1/7`` in a loop, and importing argparse and building its
parser (with the gettext and locale it brings) is a sizeable share of such a process. A line of
one of these commands that is plainly well formed (its options spelled out whole, its values
valid, the right number of arguments, no help asked) is read here into the namespace argparse
would give; any other line (help, an abbreviated option, ``--opt=value``, a bad value, a missing
argument) returns None and goes to the argparse grammar of ``parser.py``, so that usage, help and
every error message stay argparse's. ``tests/test_cli_oneshot.py`` holds the tables below equal to
that grammar (options, destinations, defaults) and the namespaces equal line by line.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from types import SimpleNamespace
from typing import Any

from .common import UsageError, parse_duration

#: The program's levels (``--log-level``, before or after the command).
LOG_LEVELS = ("DEBUG", "INFO", "WARNING", "ERROR")
DEFAULT_LOG_LEVEL = "INFO"

#: Options with a value: option -> (destination, how its text is read).
_VALUED: dict[str, tuple[str, Callable[[str], Any]]] = {
    "--timeout": ("timeout", parse_duration),
    "--type": ("type", str),
    "--route": ("route", str),
    "--eds": ("eds", str),
    "--security": ("security", Path),
}
#: Options without a value (``store_true``): option -> destination.
_FLAGS = {"--json": "json", "--connected": "connected", "--scaled": "scaled"}


class OneShot:
    """One command's grammar: its positional arguments, its options and their defaults."""

    def __init__(self, name: str, positionals: Sequence[str], valued: Sequence[str], flags: Sequence[str],
                 timeout: float = 5.0) -> None:
        self.name = name
        self.positionals = tuple(positionals)
        self.valued = {option: _VALUED[option] for option in valued}
        self.flags = {option: _FLAGS[option] for option in flags}
        self.defaults: dict[str, Any] = {"timeout": timeout}
        self.defaults.update((dest, None) for dest, _ in self.valued.values() if dest != "timeout")
        self.defaults.update((dest, False) for dest in self.flags.values())


#: The commands read here. ``func`` is looked up when a line is read: only that command's module loads.
#: A namespace is a ``types.SimpleNamespace``: attributes by name, as ``argparse.Namespace`` has them.
COMMANDS = {
    "identity": OneShot("identity", ["target"], ["--timeout", "--security"], ["--json"]),
    "get": OneShot("get", ["target", "path"], ["--timeout", "--type", "--route", "--eds", "--security"],
                   ["--json", "--connected"]),
    "set": OneShot("set", ["target", "path", "value"], ["--timeout", "--type", "--route", "--eds", "--security"],
                   ["--json", "--scaled", "--connected"]),
}


def _log_level(text: str) -> str | None:
    level = text.upper()
    return level if level in LOG_LEVELS else None


def parse(words: Sequence[str], func: Callable[[str], Callable[..., int]] | None = None) -> SimpleNamespace | None:
    """The namespace of a plainly well-formed ``get``/``set``/``identity`` line, else None (argparse
    reads it). ``func``: the command's function by name (default: ``explicit``'s ``cmd_NAME``)."""
    values: dict[str, Any] = {"log_level": DEFAULT_LOG_LEVEL}
    rest = iter(words)
    command: OneShot | None = None
    for word in rest:  # the program's options, then the command word
        if word == "--log-level":
            level = _log_level(next(rest, "-"))
            if level is None:
                return None
            values["log_level"] = level
        elif word.startswith("-") or word not in COMMANDS:
            return None
        else:
            command = COMMANDS[word]
            break
    if command is None:
        return None
    values.update(command.defaults)
    positionals: list[str] = []
    for word in rest:
        if not word.startswith("-"):
            positionals.append(word)
        elif word in command.flags:
            values[command.flags[word]] = True
        elif word in command.valued or word == "--log-level":
            text = next(rest, None)
            if text is None or text.startswith("-"):
                return None
            if word == "--log-level":
                level = _log_level(text)
                if level is None:
                    return None
                values["log_level"] = level
                continue
            dest, read = command.valued[word]
            try:
                values[dest] = read(text)
            except (UsageError, ValueError):
                return None
        else:
            return None  # help, an abbreviation, --opt=value, ``--``, a negative number: argparse's to say
    if len(positionals) != len(command.positionals):
        return None
    values.update(zip(command.positionals, positionals, strict=True))
    values["command"] = command.name
    values["func"] = (func or _explicit)(command.name)
    return SimpleNamespace(**values)


def _explicit(name: str) -> Callable[..., int]:
    from .explicit import cmd_get, cmd_identity, cmd_set

    commands: dict[str, Callable[..., int]] = {"get": cmd_get, "set": cmd_set, "identity": cmd_identity}
    return commands[name]
