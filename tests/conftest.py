"""Suite-wide isolation: every emulator the tests start, in-process or as a subprocess, keeps its state
file and control socket in temporary directories, never in the user's own (XDG base directories).

The suite runs in worker processes (pytest-xdist, ``addopts`` in pyproject.toml): each worker has
XDG directories of its own (``tmp_path_factory`` gives each worker its own base directory), every
port a test listens on comes from ``tests.ports.free_port`` (the defaults 44818, 2222 and 502 only
in a private network namespace), and the tests of an ``xdist_group`` run on one worker, one after
the other. docs/contributing.md has the rules for a new test."""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

#: Each test's CPU, the slowest tests and the time budget (``--time-budget``); a sample (``--sample K``).
pytest_plugins = ["tests.timing", "tests.sampling"]


def pytest_configure(config: pytest.Config) -> None:
    """Bytecode is cached, whatever the environment says. Some container images set
    PYTHONDONTWRITEBYTECODE: then every interpreter the suite starts (hundreds of ``cipstack``
    processes, each worker) compiles cipstack from source again, and pytest rewrites every test
    module's assertions anew in each worker: a large share of the suite's CPU time.
    Dropped here, before the workers start, it holds for them and for every process a test starts."""
    if os.environ.pop("PYTHONDONTWRITEBYTECODE", None) is not None:
        sys.dont_write_bytecode = False


def _hypothesis_profiles() -> None:
    """Under CI (``CI`` set, as .ci/run's environment has it), the property-based tests draw the same
    examples on every run, as many as elsewhere: a failure there is the code's and comes back when
    the run is repeated, never a draw's luck; and no example database is written into a clone thrown
    away after the run. Elsewhere Hypothesis draws anew and keeps what failed in ``.hypothesis/``."""
    try:
        from hypothesis import settings
    except ImportError:  # the runtime dependencies alone: no property-based test runs
        return
    settings.register_profile("ci", derandomize=True, database=None)
    if os.environ.get("CI"):
        settings.load_profile("ci")


_hypothesis_profiles()


@pytest.fixture(scope="session", autouse=True)
def isolated_user_directories(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    saved = {name: os.environ.get(name) for name in ("XDG_DATA_HOME", "XDG_RUNTIME_DIR")}
    os.environ["XDG_DATA_HOME"] = str(tmp_path_factory.mktemp("data-home"))
    runtime = tmp_path_factory.mktemp("runtime")
    runtime.chmod(0o700)
    os.environ["XDG_RUNTIME_DIR"] = str(runtime)
    yield
    for name, value in saved.items():
        if value is None:
            os.environ.pop(name, None)
        else:
            os.environ[name] = value


@pytest.fixture(scope="module", autouse=True)
def module_data_home(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """Each module's default state files (``XDG_DATA_HOME/cipstack/state/PROFILE.json``) are its own,
    its module-scoped emulators' too: parameters one module's drives save are not what another
    module's drives start with, whichever module this worker ran before."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("XDG_DATA_HOME", str(tmp_path_factory.mktemp("data-home")))
        yield


#: Modules whose tests also run on asyncio's own loop: a scanner inside an application's loop
#: serves class 1 through asyncio's datagram transport and timers, not the precise loop's lane; the TLS
#: port has a shell for each loop too.
BOTH_LOOPS = frozenset({"test_io_live", "test_io_session", "test_io_multicast", "test_acg_live", "test_faults",
                        "test_security_tls"})


def pytest_asyncio_loop_factories(config: pytest.Config, item: pytest.Item) -> dict[str, Callable[[], Any]]:
    """Async tests run on the loop the command line runs (``precise_event_loop``, with its class 1
    lane); the I/O modules of ``BOTH_LOOPS`` on asyncio's default loop as well."""
    import asyncio

    from cipstack.eip.io_server import precise_event_loop

    factories: dict[str, Callable[[], Any]] = {"lane": precise_event_loop}
    if item.module is not None and item.module.__name__.rsplit(".", 1)[-1] in BOTH_LOOPS:
        factories["asyncio"] = asyncio.new_event_loop
    return factories


#: Modules whose tests take seconds each (a process per test, property-based tests at length, the
#: attack cases, the corpus of EDS files run one by one): marked ``slow``.
SLOW_MODULES = frozenset({
    "test_benchmarks", "test_cli", "test_control_sockets", "test_eds_field_files", "test_eds_field_names",
    "test_eds_generator", "test_eds_roundtrip", "test_field_interop", "test_first_hour", "test_fleet",
    "test_fleet_http", "test_hardening", "test_http_attacks", "test_http_token", "test_io_session", "test_metrics",
    "test_plant", "test_fleet_overload",
})
#: A test with none of these is also marked ``quick``: ``pytest -m quick`` runs in a couple of minutes.
NOT_QUICK = ("slow", "interop", "tshark", "browser", "docs", "podman", "overload")


@pytest.hookimpl(tryfirst=True)  # before ``-m`` selects by the markers
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        if item.module is not None and item.module.__name__.rsplit(".", 1)[-1] in SLOW_MODULES:
            item.add_marker(pytest.mark.slow)
        if not any(item.get_closest_marker(name) for name in NOT_QUICK):
            item.add_marker(pytest.mark.quick)
    if hasattr(config, "workerinput"):  # a worker of pytest-xdist
        _long_modules_first(items)


def _long_modules_first(items: list[pytest.Item]) -> None:
    """The modules of long tests (any marker of ``NOT_QUICK``) first: the scheduler hands tests out
    in this order, and a test of a minute begun last would end the run alone. Stable, so a module's
    tests keep their order and stay together; every worker sorts alike (the scheduler checks that
    the workers collected the same list)."""
    long_modules = {item.module.__name__ for item in items
                    if item.module is not None and any(item.get_closest_marker(name) for name in NOT_QUICK)}
    items.sort(key=lambda item: item.module is None or item.module.__name__ not in long_modules)


@pytest.hookimpl(optionalhook=True)  # pytest-xdist's hook: no error where it is not loaded
def pytest_xdist_auto_num_workers(config: pytest.Config) -> int:
    """``-n auto`` (the default, pyproject.toml): two workers per CPU this process may run on, and one
    more. The tests wait far more than they compute (sockets, timers, the processes they start, the
    windows a check watches): over the suite, a test keeps a CPU busy about a third of its time
    (``--timings``), so two workers a CPU keep the CPUs about three quarters busy and the run ends
    sooner, while the load stays below what the tests that keep time (class 1 production at its RPI,
    a command's answer before a fault ends) allow for. More only adds collections (each worker
    collects the whole suite) and load."""
    return 2 * len(os.sched_getaffinity(0)) + 1


# -- the lab credentials the CIP Security tests share (``cipstack security init``, once per module) -----
@pytest.fixture(scope="module")
def lab(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from cipstack.security.provisioning import init

    folder = tmp_path_factory.mktemp("security") / "lab"
    init(folder)
    return folder


@pytest.fixture(scope="module")
def other_lab(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Credentials of another CA: neither side trusts those of ``lab``."""
    from cipstack.security.provisioning import init

    folder = tmp_path_factory.mktemp("security") / "other"
    init(folder)
    return folder
