"""An emulated device for a test: an ``Adapter`` on its own event loop in a thread of its own, on a
free loopback port, with a temporary state file, driven from a test's thread (sync or async).

The device runs beside the test, not inside its event loop: a blocking client (``SyncScanner``,
pycomm3) in a sync test and an async ``Scanner`` in an async test reach it alike, over real sockets.
Every call on the handle runs on the device's loop (``run``); faults and events are the adapter's
own, reached through its command service (``cipstack.control.service``), as every surface reaches it."""

from __future__ import annotations

import asyncio
import contextlib
import inspect
import threading
import time
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar, overload

from ..adapter import Adapter, AdapterSettings, network_interface
from ..control.events import Event
from ..control.operations import OPERATIONS, Operation
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


def operation_method(operation: Operation) -> Callable[..., Any]:
    """The method of ``EmulatedDevice`` that calls ``operation``, made from its declaration alone: its
    arguments positional in the record's order or by their JSON keys (``trip(0x4200)``,
    ``set_parameter("ACC", 2.5)``), and the options of an operation that takes free words as keywords
    (``fault("stop-producing", for_=2.0)``: a trailing underscore spares a Python keyword); its answer
    as the command service gives it."""
    free = next((a.key for a in operation.arguments if operation.free_words and a.json_type == "object"), None)
    fixed = [a for a in operation.arguments if a.key != free]
    parameters = [inspect.Parameter("self", inspect.Parameter.POSITIONAL_OR_KEYWORD)]
    parameters += [inspect.Parameter(a.key, inspect.Parameter.POSITIONAL_OR_KEYWORD,
                                     **({} if a.required else {"default": None})) for a in fixed]
    if free is not None:
        parameters.append(inspect.Parameter(free, inspect.Parameter.VAR_KEYWORD))
    signature = inspect.Signature(parameters)

    def method(self: EmulatedDevice, *args: Any, **kwargs: Any) -> Any:
        bound = signature.bind(self, *args, **kwargs)   # a wrong call is Python's own TypeError
        arguments = {a.key: bound.arguments[a.key] for a in fixed if bound.arguments.get(a.key) is not None}
        if free is not None:
            arguments[free] = {key.rstrip("_"): value for key, value in bound.arguments.get(free, {}).items()}
        return self.call(operation.name, **arguments)

    method.__name__ = method.__qualname__ = operation.python_name or operation.name
    method.__doc__ = f"{operation.summary[:1].upper()}{operation.summary[1:]} (``cipstack drive {operation.name}``)."
    method.__signature__ = signature  # type: ignore[attr-defined]  # what help() and inspect show
    return method


_Class = TypeVar("_Class", bound=type)


def with_operation_methods(cls: _Class) -> _Class:
    """``cls`` with a method for every declared operation that names one (``Operation.python_name``),
    made by ``operation_method`` when the class is made: the plugin's calls come from the declarations."""
    for operation in OPERATIONS:
        if operation.python_name is not None:
            setattr(cls, operation.python_name, operation_method(operation))
    return cls


@with_operation_methods
class EmulatedDevice:
    """A running emulated device and the calls a test makes on it; one method per declared operation
    (``with_operation_methods``) beside the calls written here."""

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

    if TYPE_CHECKING:
        # The operations' methods, made from their declarations below (``operation_method``).
        def __getattr__(self, name: str) -> Callable[..., Any]: ...

    def call(self, operation: str, **arguments: Any) -> Any:
        """Any operation of the device's command service (``cipstack.control.operations``), by its JSON
        keys, as every other surface calls it; its answer."""
        return self.run(lambda: self.adapter.service.call_async(operation, arguments))

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
                scanner = SyncScanner(self.address, catalog=catalog_for(info.vendor_id, info.product_code,
                                                                       info.device_type))
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

