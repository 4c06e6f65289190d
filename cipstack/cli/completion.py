"""``cipstack completion bash|zsh``: the shell completion script, generated from the parser by shtab."""

from __future__ import annotations

import argparse

from .common import EXIT_OK, UsageError


def cmd_completion(args: argparse.Namespace) -> int:
    try:
        import shtab
    except ImportError:
        raise UsageError('shell completion needs shtab: pip install "cipstack[completion]"') from None
    from .parser import build_parser

    # The whole parser, the eds and capture commands' arguments included.
    print(shtab.complete(build_parser(None), shell=args.shell), flush=True)
    return EXIT_OK
