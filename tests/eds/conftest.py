"""Driving eds-pie, the independent EDS reader, for the tests that compare it with ours."""

from __future__ import annotations

import logging
from collections.abc import Iterator
from typing import Any

import pytest

from tests.optional import needs


class EdsPieLog(logging.Handler):
    """What eds-pie logs at warning level or above."""

    def __init__(self) -> None:
        super().__init__(level=logging.WARNING)
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)


@pytest.fixture(scope="module")
def cip_eds() -> Any:
    # eds-pie calls logging.basicConfig(level=DEBUG) on import; with a handler already on the
    # root logger that call changes nothing.
    root = logging.getLogger()
    guard = logging.NullHandler()
    root.addHandler(guard)
    try:
        module = needs("eds_pie.eds_pie")
    finally:
        root.removeHandler(guard)
    return module.CIP_EDS


@pytest.fixture
def eds_pie_log() -> Iterator[EdsPieLog]:
    """What eds-pie logs at warning level or above, and nothing of its token-by-token debug."""
    logger = logging.getLogger("eds_pie")
    collector = EdsPieLog()
    level = logger.level
    logger.setLevel(logging.WARNING)
    logger.addHandler(collector)
    try:
        yield collector
    finally:
        logger.removeHandler(collector)
        logger.setLevel(level)
