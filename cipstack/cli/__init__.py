"""The ``cipstack`` command: adapter emulator, discovery, explicit messaging, class 1 I/O, EDS
files, capture analysis.

Every failure prints one line on stderr and exits non-zero: 2 for bad arguments (after the
command's usage when the parser finds them), 1 for an error status or a network failure; a closed
stdout ends a command quietly with 141 (``EXIT_BROKEN_PIPE``). ``--json`` prints one JSON object
per line on stdout. Each
command lives in its own module and imports what it needs when it runs."""

from __future__ import annotations

import os
import select
import sys
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

from ..cip.status import CipError, describe_status
from ..eip.originator.replies import EncapsulationStatusError
from ..eip.wire.encapsulation import EncapsulationError
from ..errors import CipstackError
from ..logs import configured_on_first_log
from . import oneshot
from .common import EXIT_FAILURE, EXIT_OK, EXIT_USAGE, UsageError, parse_duration, parse_object_path

if TYPE_CHECKING:
    from .explicit import json_key
    from .parser import build_parser

#: A command whose reader went away (``cipstack capture analyze F | head``) stops quietly with the
#: status of a process that SIGPIPE ended, 128 + 13, as ``cat`` or ``grep`` do: its output was cut
#: short, which a success would hide from ``set -o pipefail`` or a reader that failed.
EXIT_BROKEN_PIPE = 128 + 13
#: How a log record is printed on stderr.
LOG_FORMAT = "%(asctime)s %(levelname)s %(name)s: %(message)s"


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command line; the exit status (see the module docstring)."""
    try:
        status = _main(argv)
        sys.stdout.flush()  # what is still buffered meets a closed pipe here, not at interpreter exit
    except BrokenPipeError:
        _discard_stdout()
        return EXIT_BROKEN_PIPE
    return status


def _discard_stdout() -> None:
    """Point stdout at /dev/null, so that the flush at exit writes nowhere instead of raising again
    (the recipe of the Python documentation's note on SIGPIPE)."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (AttributeError, OSError, ValueError):
        sys.stdout = open(os.devnull, "w")  # noqa: SIM115 - a stdout without a descriptor


def _stdout_reader_gone() -> bool:
    """Whether stdout is a pipe whose reader has closed it (poll reports POLLERR on such a pipe): a
    broken pipe there is the reader's doing; elsewhere (a socket) it is a network failure."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):
        return False
    if not hasattr(select, "poll"):
        return True
    poller = select.poll()
    poller.register(fd, select.POLLOUT)
    return any(events & select.POLLERR for _, events in poller.poll(0))


def _timeouts() -> tuple[type[Exception], ...]:
    """The timeouts a command may raise: asyncio's is the builtin one from Python 3.11, and asyncio is
    imported only by the commands that use it (a one-shot ``get`` does not)."""
    asyncio = sys.modules.get("asyncio")
    return (TimeoutError,) if asyncio is None else (TimeoutError, asyncio.TimeoutError)


def _transport_errors() -> tuple[type[BaseException], ...]:
    """What a command's transport raises (looked at when one is raised: asyncio may have come in)."""
    return (ConnectionError, *_timeouts(), OSError)


def _configure_logging(level: str) -> None:
    import logging

    logging.basicConfig(level=getattr(logging, level), stream=sys.stderr, format=LOG_FORMAT)


def _main(argv: Sequence[str] | None) -> int:
    words = list(sys.argv[1:] if argv is None else argv)
    # A one-shot command's plain line is read without argparse; any other line, and every error, by it.
    args: Any = oneshot.parse(words)
    if args is not None:
        # A one-shot command's modules log only when something goes wrong: ``logging`` is loaded then.
        with configured_on_first_log(lambda: _configure_logging(args.log_level)):
            return _run(args)
    from .parser import build_parser, command_word

    # A command alone shows its usage when its line is wrong; only help shows the descriptions.
    parser = build_parser(command_word(words), texts=not words or any(w in ("-h", "--help") for w in words))
    try:
        args = parser.parse_args(words)
    except UsageError as exc:
        # As argparse reports it: the usage of the command the line names, then PROG: error: MESSAGE.
        print(f"{exc.usage}{exc.prog or 'cipstack'}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    if args.command is None:
        # ``cipstack`` alone: the commands and what each does, on stderr, exit 2 as argparse exits for a
        # missing argument (a script that loses its command word fails; ``cipstack --help`` is the 0 way).
        print(parser.format_help() + "\ncipstack: error: the following arguments are required: COMMAND",
              file=sys.stderr)
        return EXIT_USAGE
    _configure_logging(args.log_level)
    return _run(args)


def _run(args: Any) -> int:
    """Run the command ``args`` names; each failure it raises, one line on stderr (the module docstring)."""
    func: Callable[[Any], int] = args.func
    name = f"cipstack {args.command}"
    try:
        return func(args)
    except UsageError as exc:
        print(f"{name}: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except CipError as exc:
        if getattr(args, "json", False):
            import json

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
    except BrokenPipeError as exc:
        if _stdout_reader_gone():
            raise  # ``main`` ends quietly
        print(f"{name}: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    except _transport_errors() as exc:
        print(f"{name}: {exc or type(exc).__name__}", file=sys.stderr)
        return EXIT_FAILURE
    except KeyboardInterrupt:
        return 130
    except ValueError as exc:
        print(f"{name}: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except CipstackError as exc:   # a name that is not there (a KeyError too), a state that says no
        print(f"{name}: {exc}", file=sys.stderr)
        return EXIT_FAILURE


def __getattr__(name: str) -> Any:
    # The grammar and the JSON key helper, imported when first asked for: a one-shot line needs neither.
    if name == "build_parser":
        from . import parser

        return parser.build_parser
    if name == "json_key":
        from . import explicit

        return explicit.json_key
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["EXIT_BROKEN_PIPE", "EXIT_FAILURE", "EXIT_OK", "EXIT_USAGE", "UsageError", "build_parser", "json_key",
           "main", "parse_duration", "parse_object_path"]
