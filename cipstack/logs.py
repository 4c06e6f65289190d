"""Debug records of the one-shot commands' modules, with ``logging`` imported at the first one.

Those modules log only when something goes wrong (a reply nothing waits for, a value that does
not decode as declared). Importing ``logging`` costs a one-shot ``cipstack get`` about 8 ms of a
process of about 100 (it brings ``traceback``, ``string``, ``threading`` and more), so these modules
call ``debug(__name__, ...)`` instead of holding ``logging.getLogger(__name__)``: the same logger,
looked up at the first record. ``configured_on_first_log`` defers the command line's
``basicConfig`` to the same moment, so that a record is formatted as it would have been.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import logging

#: The command line's logging configuration, until the first record needs it.
_pending_configuration: Callable[[], None] | None = None


def debug(name: str, message: str, *args: object) -> None:
    """``logging.getLogger(name).debug(message, *args)``, with ``logging`` imported at the first call;
    the record names the caller's line, as a logger's own method does."""
    _logger(name).debug(message, *args, stacklevel=2)


@contextmanager
def configured_on_first_log(configure: Callable[[], None]) -> Iterator[None]:
    """Within the block, run ``configure`` before the first record made through ``debug``; at once if
    ``logging`` is already loaded (a module that imported it may log at any time)."""
    global _pending_configuration
    if "logging" in sys.modules:
        configure()
        yield
        return
    _pending_configuration = configure
    try:
        yield
    finally:
        _pending_configuration = None


def _logger(name: str) -> logging.Logger:
    global _pending_configuration
    import logging

    configure, _pending_configuration = _pending_configuration, None
    if configure is not None:
        configure()
    return logging.getLogger(name)


__all__ = ["configured_on_first_log", "debug"]
