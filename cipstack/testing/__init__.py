"""The pytest plugin of cipstack (entry point ``pytest11``): emulated devices as fixtures.

Fixtures:

* ``cip_adapter``: an emulated device (``EmulatedDevice``) on a free loopback port with a temporary
  state file, started for the test and stopped after it. Which device: the ``cip_adapter`` marker,
  ``@pytest.mark.cip_adapter(profile="acg", model=None, eds=None, params=["drv=4", "Frq=8"])``
  (``params`` by the device's keypad codes: ``profile="mx2", params=["A004=60"]`` for an MX2's Digital
  Operator); by default the ACG drive. It has a method for every operation of the command service
  (``fault``, ``clear_faults``, ``faults``, ``trip``, ``reset``, ``power``, ``link``, ``parameter``,
  ``set_parameter``, ...), made from the operations' declarations (``cipstack.control.operations``),
  and its events (``events``, ``wait_for``, ``await event``) are the in-process adapter's.
* ``cip_adapter_factory``: starts more devices, ``cip_adapter_factory(profile="mx2", params=...)``,
  each stopped after the test.
* ``cip_fleet``: several devices (the ``cip_fleet`` marker: ``count``, and the options of
  ``cip_adapter``), each on its own loopback port.
* ``cip_scanner``: a ``SyncScanner`` connected to ``cip_adapter``, decoding its assemblies by name.

The devices run on an event loop of their own, in a thread: sync tests and async tests (any
pytest-asyncio loop) reach them alike over real sockets.
"""

from .device import DeviceOptions, EmulatedDevice
from .plugin import cip_adapter, cip_adapter_factory, cip_fleet, cip_scanner, pytest_configure

__all__ = ["DeviceOptions", "EmulatedDevice", "cip_adapter", "cip_adapter_factory", "cip_fleet", "cip_scanner",
           "pytest_configure"]
