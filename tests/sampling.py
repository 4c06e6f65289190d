"""``--sample K``: every module of the selection, each with one test in K, and the modules that meet what
differs between Pythons whole.

CI runs the whole suite on one Python and the quick tests on every other supported one
(tools/other_pythons.sh). What moves between Pythons is a small part of the code: asyncio's and
selectors' private state, which the precise event loop reads; the standard library's small
changes (``str()`` of an IntEnum member, the loop's socket methods, named tuples); the modules an
import pulls in. The modules of ``VERSION_SENSITIVE`` meet those and run whole; of every other
module one test in K runs, the first among them, so each module is still imported and exercised
on each Python. The sample is the same on every run and every xdist worker (by position, not by
chance)."""

from __future__ import annotations

import pytest

#: Test modules run whole under ``--sample``, and why.
VERSION_SENSITIVE = frozenset({
    "test_precise_loop",       # the precise loop: asyncio's and selectors' private attributes, check_python
    "test_io_lane",            # class 1 on the precise loop's lane
    "test_tcp_lane",           # TCP on the lane: the loop's reader callbacks and sockets
    "test_io_live",            # class 1 on both loops, asyncio's datagram transport among them
    "test_broadcast",          # UDP sockets and the interface table
    "test_oneshot_imports",    # the modules a one-shot command imports, which each Python's stdlib changes
    "test_declaration_types",  # named tuples and slotted classes
    "test_cip_codecs",         # enums and integers on the wire
    "test_eds_reader",         # an EnumN value written from an IntEnum member (str() differs on 3.10)
    "test_layering",           # the import graph, read with the standard library's ast
    "test_errors",             # exception classes that keep builtins as bases
})


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--sample", type=int, default=1, metavar="K",
                     help="run one test in K of each module, the modules that meet what differs between "
                          "Pythons whole (tests/sampling.py)")


@pytest.hookimpl(trylast=True)  # after ``-m`` and ``-k`` have selected
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    every = config.getoption("--sample")
    if every < 1:
        raise pytest.UsageError(f"--sample {every}: give 1 or more")
    if every == 1:
        return
    kept: list[pytest.Item] = []
    dropped: list[pytest.Item] = []
    position: dict[str, int] = {}
    for item in items:
        module = item.module.__name__.rsplit(".", 1)[-1] if item.module is not None else ""
        index = position.get(module, 0)
        position[module] = index + 1
        (kept if module in VERSION_SENSITIVE or index % every == 0 else dropped).append(item)
    if dropped:
        config.hook.pytest_deselected(items=dropped)
        items[:] = kept
