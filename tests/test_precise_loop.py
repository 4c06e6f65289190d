"""The precise event loop reads asyncio's private loop queues: it refuses, in one clear line, a
Python whose asyncio it does not know, and ``requires-python`` says the same bounds."""

from __future__ import annotations

import asyncio
import re
import sys

import pytest

from cipstack.eip.precise_loop import (
    LOOP_INTERNALS,
    SUPPORTED_PYTHONS,
    PreciseEventLoop,
    UnsupportedPythonError,
    check_python,
)
from cipstack.errors import CipstackError
from tests.library_support import ROOT


def test_this_python_is_supported_and_its_loop_has_the_queues() -> None:
    assert tuple(sys.version_info[:2]) in SUPPORTED_PYTHONS
    loop = PreciseEventLoop()
    try:
        check_python(loop=loop)
        assert all(hasattr(loop, name) for name in LOOP_INTERNALS)
    finally:
        loop.close()


def test_an_unknown_python_is_refused_clearly() -> None:
    with pytest.raises(UnsupportedPythonError, match=r"known in Python 3\.10, .*3\.13, not in 3\.14: run cipstack"):
        check_python((3, 14))
    assert issubclass(UnsupportedPythonError, CipstackError)


def test_a_loop_without_the_queues_is_refused() -> None:
    """A loop that keeps its ready queue elsewhere, as a later asyncio might."""
    loop = asyncio.SelectorEventLoop()
    ready = loop._ready  # type: ignore[attr-defined]  # internals: the private queue check_python looks for
    try:
        del loop._ready  # type: ignore[attr-defined]  # internals: a Python without it, as check_python fears
        with pytest.raises(UnsupportedPythonError, match="asyncio's loop has no _ready in this Python"):
            check_python(loop=loop)
    finally:
        loop._ready = ready  # type: ignore[attr-defined]  # internals: put back for close()
        loop.close()


def test_requires_python_has_the_same_bounds() -> None:
    found = re.search(r'^requires-python = "([^"]+)"', (ROOT / "pyproject.toml").read_text(encoding="utf-8"), re.M)
    low, high = SUPPORTED_PYTHONS[0], SUPPORTED_PYTHONS[-1]
    assert found is not None and found.group(1) == f">={low[0]}.{low[1]},<{high[0]}.{high[1] + 1}"
    assert [(low[0], minor) for minor in range(low[1], high[1] + 1)] == list(SUPPORTED_PYTHONS)
