"""Starting servers on ports that may be taken: the error that names the port, and log lines held
back until every port is open (so that a start that fails says one line, the error)."""

from __future__ import annotations

import contextlib
import logging
import os
from collections.abc import Iterator

from .errors import CipstackError


class ListenError(CipstackError, OSError):
    """A port (or the control socket) the adapter cannot listen on: ``where`` names it and its option."""

    def __init__(self, where: str, cause: OSError | str) -> None:
        self.where = where
        # asyncio's bind error carries the address in its text: the reason alone is the errno's.
        self.reason = cause if isinstance(cause, str) else (os.strerror(cause.errno) if cause.errno else str(cause))
        super().__init__(f"cannot listen on {where}: {self.reason}")


class _HeldRecords:
    """The log records of a start that may still fail; emitted only once ``release`` is called."""

    def __init__(self) -> None:
        self.records: list[tuple[logging.Handler, logging.LogRecord]] = []
        self.released = False

    def release(self) -> None:
        self.released = True


class _Hold(logging.Filter):
    def __init__(self, handler: logging.Handler, held: _HeldRecords) -> None:
        super().__init__()
        self.handler = handler
        self.held = held

    def filter(self, record: logging.LogRecord) -> bool:
        self.held.records.append((self.handler, record))
        return False


@contextlib.contextmanager
def held_log_records() -> Iterator[_HeldRecords]:
    """Hold back what the root logger's handlers would print until the caller releases it."""
    held = _HeldRecords()
    holds = [_Hold(handler, held) for handler in logging.getLogger().handlers]
    for hold in holds:
        hold.handler.addFilter(hold)
    try:
        yield held
    finally:
        for hold in holds:
            hold.handler.removeFilter(hold)
        if held.released:
            for handler, record in held.records:
                handler.handle(record)


__all__ = ["ListenError", "held_log_records"]
