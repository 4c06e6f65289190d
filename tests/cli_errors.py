"""How a failed ``cipstack`` command reports: one line on stderr, after the command's usage when the
parser found the problem (``usage:`` and its indented continuation lines, as argparse shows it)."""

from __future__ import annotations

import subprocess


def one_line_error(result: subprocess.CompletedProcess[str]) -> str:
    """The error line of ``result``, checked to be the only line besides a parser's usage."""
    assert "Traceback" not in result.stderr, result.stderr
    lines = result.stderr.strip().splitlines()
    if lines and lines[0].startswith("usage: "):
        lines = lines[1:]
        while lines and lines[0].startswith(" "):
            lines = lines[1:]
        assert lines and ": error: " in lines[0], result.stderr
    assert len(lines) == 1, result.stderr
    return lines[0]
