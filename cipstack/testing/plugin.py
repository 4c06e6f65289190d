"""The fixtures and markers of ``cipstack.testing`` (see the package docstring)."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from ..devices.profiles import DEFAULT_PROFILE
from ..scanner import SyncScanner
from .device import DeviceOptions, EmulatedDevice

_OPTION_NAMES = ("profile", "model", "eds", "params", "params_unsaved", "host", "settings")


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", f"cip_adapter(profile={DEFAULT_PROFILE!r}, model=None, eds=None, params=(), "
                                       "params_unsaved=False, host, settings): the device the cip_adapter fixture "
                                       "starts")
    config.addinivalue_line("markers", "cip_fleet(count=2, ...): how many devices cip_fleet starts, and which")


def _options(request: pytest.FixtureRequest, marker: str, directory: Path, name: str,
             overrides: dict[str, Any] | None = None) -> DeviceOptions:
    found = request.node.get_closest_marker(marker)
    given = dict(found.kwargs) if found is not None else {}
    given.update(overrides or {})
    unknown = sorted(set(given) - set(_OPTION_NAMES) - {"count"})
    if unknown:
        raise pytest.UsageError(f"{marker}: unknown option {', '.join(unknown)}; valid: {', '.join(_OPTION_NAMES)}")
    given.pop("count", None)
    options = DeviceOptions(**given)
    if options.state_path is None and options.eds is None:
        options.state_path = directory / f"{name}.json"
    return options


@pytest.fixture
def cip_adapter_factory(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[Callable[..., EmulatedDevice]]:
    """Start emulated devices (``factory(profile=..., params=[...])``), each stopped after the test."""
    started: list[EmulatedDevice] = []

    def start(**options: Any) -> EmulatedDevice:
        device = EmulatedDevice(_options(request, "__none__", tmp_path, f"device{len(started)}", options))
        started.append(device)
        return device

    yield start
    for device in reversed(started):
        device.close()


@pytest.fixture
def cip_adapter(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[EmulatedDevice]:
    """The emulated device the ``cip_adapter`` marker names (the ACG drive by default)."""
    device = EmulatedDevice(_options(request, "cip_adapter", tmp_path, "adapter"))
    try:
        yield device
    finally:
        device.close()


@pytest.fixture
def cip_fleet(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[list[EmulatedDevice]]:
    """``count`` emulated devices (the ``cip_fleet`` marker; 2 by default), each on its own port."""
    found = request.node.get_closest_marker("cip_fleet")
    count = int(found.kwargs.get("count", 2)) if found is not None else 2
    devices: list[EmulatedDevice] = []
    try:
        for index in range(count):
            devices.append(EmulatedDevice(_options(request, "cip_fleet", tmp_path, f"device{index}")))
        yield devices
    finally:
        for device in reversed(devices):
            device.close()


@pytest.fixture
def cip_scanner(cip_adapter: EmulatedDevice) -> Iterator[SyncScanner]:
    """A blocking scanner connected to ``cip_adapter``, with its device's assemblies by name.

    It does not reconnect: a power-cycle or an unplug ends its session, as it ends a real drive's.
    ``cip_adapter.scanner()`` gives a new one once the device answers again."""
    scanner = cip_adapter.scanner()
    try:
        yield scanner
    finally:
        scanner.close()
