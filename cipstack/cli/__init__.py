"""The ``cipstack`` command: adapter emulator, discovery, explicit messaging, class 1 I/O, EDS
files, capture analysis.

Every failure prints one line on stderr and exits non-zero: 2 for bad arguments, 1 for an
error status or a network failure. ``--json`` prints one JSON object per line on stdout. Each
command lives in its own module and imports what it needs when it runs."""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import os
import sys
from collections.abc import Callable, Sequence

from ..cip.status import CipError, describe_status
from ..eip.encapsulation import EncapsulationError
from ..eip.replies import EncapsulationStatusError
from .common import EXIT_FAILURE, EXIT_OK, EXIT_USAGE, UsageError, parse_duration, parse_object_path
from .explicit import json_key
from .parser import build_parser, command_word


def main(argv: Sequence[str] | None = None) -> int:
    words = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser(command_word(words))
    try:
        args = parser.parse_args(words)
    except UsageError as exc:
        print(f"cipstack: {exc}", file=sys.stderr)
        return EXIT_USAGE
    logging.basicConfig(level=getattr(logging, args.log_level), stream=sys.stderr,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    func: Callable[[argparse.Namespace], int] = args.func
    name = f"cipstack {args.command}"
    try:
        return func(args)
    except UsageError as exc:
        print(f"{name}: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except CipError as exc:
        if getattr(args, "json", False):
            print(json.dumps({"status": exc.general, "extended_status": list(exc.extended),
                              "error": describe_status(exc.general, exc.extended),
                              "path": getattr(args, "path", None)}), flush=True)
        print(f"{name}: error status {exc}", file=sys.stderr)
        return EXIT_FAILURE
    except EncapsulationStatusError as exc:
        print(f"{name}: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    except EncapsulationError as exc:
        # A reply this side cannot read (the originator's decoders raise it): the peer's, one line.
        print(f"{name}: malformed reply from the target: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    except (ConnectionError, asyncio.TimeoutError, TimeoutError, OSError) as exc:
        print(f"{name}: {exc or type(exc).__name__}", file=sys.stderr)
        return EXIT_FAILURE
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        # The reader went away (``cipstack models | head``): not an error of ours.
        sys.stdout = open(os.devnull, "w")  # noqa: SIM115 - silences the flush at exit
        return EXIT_OK
    except ValueError as exc:
        print(f"{name}: {exc}", file=sys.stderr)
        return EXIT_USAGE


__all__ = ["EXIT_FAILURE", "EXIT_OK", "EXIT_USAGE", "UsageError", "build_parser", "json_key", "main",
           "parse_duration", "parse_object_path"]
