"""An emulated device for a test: an ``Adapter`` on its own event loop in a thread of its own, on a
free loopback port, with a temporary state file, driven from a test's thread (sync or async).

The device runs beside the test, not inside its event loop: a blocking client (``SyncScanner``,
pycomm3) in a sync test and an async ``Scanner`` in an async test reach it alike, over real sockets.
Every call on the handle runs on the device's loop (``run``); faults and events are the adapter's
own, reached through its command service (``cipstack.control.service``), as every surface reaches it."""

from __future__ import annotations

import asyncio
import contextlib
import threading
import time
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar, overload

from ..adapter import Adapter, AdapterSettings, network_interface
from ..control.events import Event
from ..devices.profiles import DEFAULT_PROFILE
from ..eds.served import profile_eds_files
from ..errors import UnknownField
from ..scanner import SyncScanner

T = TypeVar("T")

#: How long a call on the device's loop may take before the test is told.
CALL_TIMEOUT = 30.0
#: How long ``EmulatedDevice.scanner`` waits for the device to answer (its power back, its link plugged).
CONNECT_TIMEOUT = 10.0


@dataclass
class DeviceOptions:
    """What device a test wants: a profile (and model) with keypad parameters, or an EDS file."""

    profile: str = DEFAULT_PROFILE
    model: str | None = None
    eds: str | Path | None = None
    #: Keypad parameters set at start, as ``cipstack adapter --param`` takes them: the ACG's codes
    #: (``drv=4``), an MX2/RX Digital Operator's function codes (``A004=60``).
    params: Sequence[str] = ()
    #: True: the ``params`` are written as over communication, not saved, so a power-cycle loses them
    #: (``cipstack adapter --param-unsaved``); by default they are keypad entries, which it keeps.
    params_unsaved: bool = False
    host: str = "127.0.0.1"
    state_path: Path | None = None
    settings: dict[str, Any] = field(default_factory=dict)


class EmulatedDevice:
    """A running emulated device and the calls a test makes on it."""

    def __init__(self, options: DeviceOptions) -> None:
        self.options = options
        self.loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self.loop.run_forever, name="cipstack-device", daemon=True)
        self._thread.start()
        self._scanners: list[SyncScanner] = []
        try:
            self.adapter: Adapter = self.run(self._start)
        except BaseException:
            self._stop_loop()
            raise

    async def _start(self) -> Adapter:
        options = self.options
        settings = AdapterSettings(host=options.host, port=0, io_port=0, profile=options.profile,
                                   model=options.model, state_path=options.state_path,
                                   # The device carries its EDS file (File object), as the adapter's does.
                                   **{"files": profile_eds_files(options.profile, options.model),
                                      **options.settings})
        device = None
        if options.eds is not None:
            from ..devices.base import DeviceLimits
            from ..devices.profiles import DEFAULT_MAC
            from ..eds.emulated_device import build_eds_device
            from ..eds.reader import read_eds

            device = build_eds_device(read_eds(str(options.eds)), network_interface(options.host, DEFAULT_MAC),
                                      DeviceLimits(settings.max_sessions, settings.max_connections))
        adapter = Adapter(settings, device=device)
        if options.params:
            adapter.apply_keypad_parameters(list(options.params), kept=not options.params_unsaved)
        await adapter.start()
        adapter.events  # noqa: B018 (watching starts now, so every event of the test is kept)
        return adapter

    # -- where it is ------------------------------------------------------------------------------------
    @property
    def host(self) -> str:
        return self.options.host

    @property
    def port(self) -> int:
        return self.adapter.port

    @property
    def address(self) -> str:
        """``HOST:PORT``, as a scanner takes it."""
        return f"{self.host}:{self.port}"

    @property
    def io_port(self) -> int:
        """The class 1 UDP port (``target_io_port`` of a scanner's class 1 connection)."""
        endpoint = self.adapter.io_endpoint
        if endpoint is None:
            raise UnknownField("this device has no class 1 I/O")
        return endpoint.port

    # -- calls on the device's loop -------------------------------------------------------------------------
    @overload
    def run(self, function: Callable[[], Awaitable[T]], timeout: float = CALL_TIMEOUT) -> T: ...

    @overload
    def run(self, function: Callable[[], T], timeout: float = CALL_TIMEOUT) -> T: ...

    def run(self, function: Callable[[], Any], timeout: float = CALL_TIMEOUT) -> Any:
        """Run ``function`` on the device's loop (awaited if it returns an awaitable); its result."""
        async def call() -> Any:
            result = function()
            if asyncio.iscoroutine(result) or isinstance(result, asyncio.Future):
                return await result
            return result

        return asyncio.run_coroutine_threadsafe(call(), self.loop).result(timeout)

    def call(self, operation: str, **arguments: Any) -> Any:
        """Any operation of the device's command service (``cipstack.control.operations``), by its JSON
        keys, as every other surface calls it; its answer."""
        return self.run(lambda: self.adapter.service.call_async(operation, arguments))

    def fault(self, name: str, **options: Any) -> dict[str, Any]:
        """Apply a fault (``cipstack.faults``; ``for_=2.0`` for ``--for``), once its ports are closed or
        opened (or, for a long power-cycle, while the power is still off); its record (id, name, options)."""
        if "for_" in options:
            options["for"] = options.pop("for_")
        return dict(self.call("fault", name=name, options=options))

    def clear_faults(self, which: int | str | None = None) -> list[dict[str, Any]]:
        return list(self.call("clear", **({"fault": which} if which is not None else {})))

    def faults(self) -> list[dict[str, Any]]:
        """The faults active now."""
        return list(self.call("faults"))

    def events(self, since: int = 0) -> list[Event]:
        """The events since event number ``since``, oldest first."""
        return self.run(lambda: self.adapter.events.since(since))

    def wait_for(self, kind: str | Callable[[Event], bool], timeout: float = 10.0, after: int = 0) -> Event:
        """Block until an event of ``kind`` (after event number ``after``); for sync tests."""
        return self.run(lambda: self.adapter.events.wait_for(kind, timeout, after), timeout + 5)

    async def event(self, kind: str | Callable[[Event], bool], timeout: float = 10.0, after: int = 0) -> Event:
        """Await an event of ``kind`` without blocking the test's own loop; for async tests."""
        future = asyncio.run_coroutine_threadsafe(self.adapter.events.wait_for(kind, timeout, after), self.loop)
        return await asyncio.wrap_future(future)

    def status(self) -> dict[str, Any]:
        """What ``cipstack drive status`` reports: the drive's fields, power and link, sessions and
        connections."""
        return dict(self.call("status"))

    def trip(self, code: int | str) -> dict[str, Any]:
        return dict(self.call("trip", code=code))

    def parameter(self, code: str) -> dict[str, Any]:
        """A keypad parameter by its code (the ACG's ``ACC``, an MX2/RX function code ``A004``): code, name,
        value in the keypad's unit, raw value, unit, address."""
        return dict(self.call("parameter", code=code))

    def set_parameter(self, code: str, value: object) -> dict[str, Any]:
        """Set a keypad parameter now, in the keypad's unit, not saved; a ``parameter write`` event with
        origin "python"."""
        return dict(self.call("set-parameter", code=code, value=value))

    # -- a scanner --------------------------------------------------------------------------------------------
    def scanner(self, timeout: float = CONNECT_TIMEOUT) -> SyncScanner:
        """A new blocking scanner connected to this device, decoding its assemblies by name, as soon as
        the device accepts a connection (within ``timeout`` seconds); closed with the device if the test
        does not close it first.

        A power-cycle or an unplug ends every session with the device, as on a real drive, so a scanner
        from before (``cip_scanner`` too) fails from then on; this one is the session a program would
        open again once the power is back."""
        from ..devices.profiles import catalog_for

        info = self.adapter.device.identity_info
        deadline = time.monotonic() + timeout
        while True:
            try:
                scanner = SyncScanner(self.address, catalog=catalog_for(info.vendor_id, info.product_code))
                break
            except OSError:  # refused or reset while the power is off or the link unplugged
                if time.monotonic() >= deadline:
                    raise
                time.sleep(0.05)
        self._scanners.append(scanner)
        return scanner

    # -- the end ------------------------------------------------------------------------------------------
    def close(self) -> None:
        if self.loop.is_closed():
            return
        for scanner in self._scanners:
            with contextlib.suppress(Exception):   # one whose session the test ended, or the power did
                scanner.close()
        try:
            async def stop() -> None:
                await self.adapter.faults.settle()
                await self.adapter.close()

            self.run(stop)
        finally:
            self._stop_loop()

    def _stop_loop(self) -> None:
        self.loop.call_soon_threadsafe(self.loop.stop)
        self._thread.join(10)
        self.loop.close()

    def __enter__(self) -> EmulatedDevice:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
