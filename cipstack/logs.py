"""Loggers made when a module first logs, for the modules of the one-shot commands' path.

Those modules log only when something goes wrong (a reply nothing waits for, a value that does
not decode as declared). Importing ``logging`` costs a one-shot ``cipstack get`` about 8 ms of a
process of about 100 (it brings ``traceback``, ``string``, ``threading`` and more), so these modules
hold a ``logger(__name__)`` instead of ``logging.getLogger(__name__)``: the same logger, looked up
the first time one of its methods is used. ``configured_on_first_log`` defers the command line's
``basicConfig`` to the same moment, so that a record is formatted as it would have been.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any, cast

if TYPE_CHECKING:
    import logging

#: The command line's logging configuration, until the first record of a logger on demand needs it.
_pending_configuration: Callable[[], None] | None = None


class _LoggerOnDemand:
    """Stands for ``logging.getLogger(name)``; every attribute is the logger's, looked up on use."""

    __slots__ = ("_name",)

    def __init__(self, name: str) -> None:
        self._name = name

    def __getattr__(self, attribute: str) -> Any:
        # Reached for every Logger attribute (this class defines none of them); the bound method is
        # the logger's own, so a record names the caller's line as usual.
        return getattr(_logger(self._name), attribute)

    def __repr__(self) -> str:
        return f"<logger {self._name} (on demand)>"


def logger(name: str) -> logging.Logger:
    """The logger ``name``, with ``logging`` imported when the module first logs."""
    return cast("logging.Logger", _LoggerOnDemand(name))


@contextmanager
def configured_on_first_log(configure: Callable[[], None]) -> Iterator[None]:
    """Within the block, run ``configure`` before the first record of a logger on demand; at once if
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


__all__ = ["configured_on_first_log", "logger"]
