"""The command-line reference, rendered from the parser the ``cipstack`` command runs.

``docs/command-line/reference.md`` holds the marker ``<!-- cli-reference -->``; at build time
MkDocs calls :func:`on_page_markdown`, which puts there the ``--help`` of ``cipstack`` and of every
command and subcommand, as ``cipstack.cli.parser.build_parser()`` formats it. Nothing of the
reference is written by hand, so it cannot drift from the command line; ``tests/test_docs.py``
checks that every subcommand the parser has appears in it.

The hook lives outside ``docs_dir``, so that the site does not publish it as a page asset. Each help
block carries the class ``cli-help``: ``docs/stylesheets/cli-reference.css`` wraps its lines within the
content column (the examples of a few commands are longer than the help's width).
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
MARKER = "<!-- cli-reference -->"
#: The width the help is formatted to, whatever the terminal that builds the docs: the width the
#: descriptions are written to (``cipstack.cli.help_texts``).
WIDTH = 80


def _subcommands(parser: argparse.ArgumentParser) -> Iterator[tuple[str, argparse.ArgumentParser]]:
    for action in parser._actions:  # argparse keeps subparsers only there
        if isinstance(action, argparse._SubParsersAction):
            yield from action.choices.items()


def commands(parser: argparse.ArgumentParser | None = None,
             prefix: tuple[str, ...] = ()) -> Iterator[tuple[tuple[str, ...], argparse.ArgumentParser]]:
    """Every command line of the parser, depth first: ``()`` for ``cipstack`` itself, then
    ``("adapter",)``, ..., ``("drive", "trip")``, ..."""
    if parser is None:
        if str(ROOT) not in sys.path:
            sys.path.insert(0, str(ROOT))  # this checkout's cipstack, not another installed one
        from cipstack.cli.parser import build_parser

        parser = build_parser()  # no command: every command's arguments, eds and capture included
    yield prefix, parser
    for name, sub in _subcommands(parser):
        yield from commands(sub, (*prefix, name))


def render() -> str:
    """The reference as Markdown: one section per command, its help in a text block."""
    saved = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = str(WIDTH)
    try:
        parts = []
        for words, parser in commands():
            name = " ".join(("cipstack", *words))
            level = "#" * min(2 + max(len(words) - 1, 0), 4)
            parts.append(f"{level} `{name}`\n\n``` {{.text .cli-help}}\n{parser.format_help().rstrip()}\n```\n")
        return "\n".join(parts)
    finally:
        if saved is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = saved


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    if MARKER in markdown:
        return markdown.replace(MARKER, render())
    return markdown
