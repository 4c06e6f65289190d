"""Many devices in one event loop: each is what ``cipstack adapter`` builds (``Adapter``), on its own
address, with its own identity, state file, control socket and class 1 endpoint.

Starting is all or nothing: a port or control socket that is taken stops every device already
started and raises ``ListenError`` naming it; the per-device start-up log lines are dropped (the
device lines and one summary say the same), warnings kept.
"""

from __future__ import annotations

import asyncio
import logging
import resource
import signal
from collections.abc import Callable, Sequence
from typing import Any

from ..adapter import Adapter, AdapterSettings
from ..control import describe
from ..control.service import DeviceService
from ..devices.profiles import mac_for_address
from ..devices.state import StateFileError
from ..eds.served import profile_eds_files
from ..eip.io_core import ProductionGrid
from ..eip.io_server import freeze_startup_objects
from ..eip.wire.encapsulation import SECURE_PORT
from ..errors import SecurityError
from ..listening import held_log_records
from ..modbus.rtu_line import RtuLine, open_port
from ..runtime.observer import register_relay
from .load import LoadSampler, LoadWatch, gauge_values, watch_own_load
from .spec import FleetDevice, FleetSecurity, SpecError, describe_addresses

log = logging.getLogger(__name__)


#: Descriptors a device holds before any connection: TCP listener, UDP, broadcast UDP, class 1 UDP,
#: control socket; with room for a few connections each.
DESCRIPTORS_PER_DEVICE = 12
#: What CIP Security adds to a device (``--security``): its TLS listener and its DTLS socket.
DESCRIPTORS_PER_SECURED_DEVICE = DESCRIPTORS_PER_DEVICE + 2
#: Descriptors a process holds besides its devices': the interpreter's, the HTTP API's, the parent's channel.
RESERVED_DESCRIPTORS = 256


def check_open_files(devices: int, workers: int, secured: bool = False) -> None:
    """Refuse (``SpecError``, one line) a fleet whose busiest process would need more descriptors than
    the hard open-file limit lets any process of this user have: it would fail part way through its
    start, or later at a connection; say how many workers would fit instead. ``secured``: every
    device serves TLS and DTLS too."""
    try:
        _, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    except (OSError, ValueError):
        return
    busiest = -(-devices // workers)
    needed = descriptors_needed(busiest, secured)
    if hard == resource.RLIM_INFINITY or needed <= hard:
        return
    per_process = max(1, (hard - RESERVED_DESCRIPTORS) // _per_device(secured))
    raise SpecError(f"{devices} devices on {workers} worker(s): {busiest} in one process need about {needed} open "
                    f"files, and the hard limit here is {hard} (ulimit -Hn): give --workers "
                    f"{-(-devices // per_process)} or more, or raise the limit")


def _per_device(secured: bool) -> int:
    return DESCRIPTORS_PER_SECURED_DEVICE if secured else DESCRIPTORS_PER_DEVICE


def descriptors_needed(devices: int, secured: bool = False) -> int:
    return RESERVED_DESCRIPTORS + devices * _per_device(secured)


def raise_open_file_limit(devices: int, secured: bool = False) -> None:
    """Raise the soft open-file limit toward the hard one for ``devices`` devices (one process may
    serve hundreds); where it cannot be raised, a device that cannot open a socket says so at start."""
    try:
        soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
        needed = descriptors_needed(devices, secured)
        if soft != resource.RLIM_INFINITY and soft < needed:
            resource.setrlimit(resource.RLIMIT_NOFILE, (needed if hard == resource.RLIM_INFINITY
                                                        else min(needed, hard), hard))
    except (OSError, ValueError):
        pass


def build_adapter(device: FleetDevice, port: int, io_port: int, grid: ProductionGrid | None = None,
                  security: FleetSecurity | None = None) -> Adapter:
    """The emulator of one device; a state file, parameter or credentials folder it cannot take
    raises ``SpecError``. ``grid``: the process's class 1 slots, which its devices share (one wake-up
    for all that are due); ``security``: TLS and DTLS at the device's address too, as ``cipstack
    adapter --security`` serves them."""
    # Each device carries its EDS file in its File object, as the single adapter's does.
    settings = AdapterSettings(host=device.address, port=port, io_port=io_port, profile=device.profile,
                               model=device.model, state_path=device.state_path, mac=mac_for_address(device.address),
                               files=profile_eds_files(device.profile, device.model),
                               security=security.folder if security is not None else None,
                               security_port=security.port if security is not None else SECURE_PORT)
    try:
        adapter = Adapter(settings, production_grid=grid)
    except (StateFileError, SecurityError, ValueError, KeyError) as exc:
        raise SpecError(f"{device.address}: {exc}") from None
    if device.params:
        try:
            adapter.apply_keypad_parameters(list(device.params))
        except ValueError as exc:
            adapter.device.close()
            raise SpecError(f"{device.address}: {exc}") from None
    return adapter


def device_line(device: FleetDevice, adapter: Adapter) -> str:
    """What the fleet prints for a device once it serves: where, what, who, where its state and control are."""
    info = adapter.device.identity_info
    kind = f"{device.profile}:{device.model}" if device.model else device.profile
    state = str(device.state_path) if device.state_path else "(in memory)"
    secured = f"  TLS/DTLS {adapter.tls.port}" if adapter.tls is not None else ""
    return (f"{device.address}:{adapter.port}  {kind}  {info.product_name!r}  serial 0x{info.serial_number:08X}  "
            f"state {state}  control {describe(adapter.control_path)}{secured}")


class DeviceSet:
    """The running adapters of one process's share of a fleet; with ``rtu`` ("pty" or a serial
    device), its ACG drives on one RS-485 line as well, each at the station ID of its device; with
    ``security``, every device serves TLS and DTLS at its address too."""

    def __init__(self, devices: Sequence[FleetDevice], port: int, io_port: int, rtu: str | None = None,
                 security: FleetSecurity | None = None) -> None:
        self.devices = list(devices)
        self.port = port
        self.io_port = io_port
        self.rtu = rtu
        self.security = security
        #: The RS-485 line once started.
        self.line: RtuLine | None = None
        self.adapters: list[Adapter] = []
        #: The class 1 slots every device of this process produces in.
        self.production_grid = ProductionGrid()

    async def start(self) -> list[str]:
        """Build and start every device; returns their lines. All or nothing (see the module docstring)."""
        raise_open_file_limit(len(self.devices), self.security is not None)
        built: list[Adapter] = []
        try:
            for device in self.devices:
                built.append(build_adapter(device, self.port, self.io_port, self.production_grid, self.security))
        except SpecError:
            for adapter in built:
                adapter.device.close()
            raise
        with held_log_records() as held:
            try:
                for adapter in built:
                    await adapter.start_serving()
                    self.adapters.append(adapter)
            except BaseException:
                started = len(self.adapters)
                await self.stop()
                for adapter in built[started:]:   # built, never serving: their state writers only
                    adapter.device.close()
                raise
            held.records = [(h, r) for h, r in held.records if r.levelno >= logging.WARNING]
            held.release()
        lines = [device_line(d, a) for d, a in zip(self.devices, self.adapters, strict=True)]
        if self.rtu is not None:
            try:
                lines.append(await self._open_line(self.rtu))
            except BaseException:
                await self.stop()
                raise
        return lines

    async def _open_line(self, device: str) -> str:
        """The ACG drives on one RS-485 line; the line that says where it is and who is on it."""
        drives = [(d, a, a.modbus_drive, a.modbus_drive.rtu) for d, a in zip(self.devices, self.adapters, strict=True)
                  if a.modbus_drive is not None and a.modbus_drive.rtu is not None]
        first = drives[0][3]
        port = open_port(device, first.line_settings())
        line = RtuLine(port, first.max_drives, first.source)
        for _, adapter, modbus, rtu in drives:
            line.add(rtu.slave(port.paced, register_relay("modbus-rtu", adapter.observers)), modbus.saves)
        self.line = line
        await line.start()
        stations = ", ".join(f"{d.address} station {s.settings.station}"
                             for (d, _, _, _), s in zip(drives, line.slaves, strict=True))
        return f"Modbus-RTU on {line.name} ({line.slaves[0].settings.describe().split(', ', 1)[1]}): {stations}"

    async def stop(self) -> None:
        """Stop every started device, at once; each writes its last saves."""
        if self.line is not None:
            line, self.line = self.line, None
            await line.close()
        adapters, self.adapters = self.adapters, []
        await asyncio.gather(*(adapter.stop_serving() for adapter in adapters))


async def serve_until_signalled(devices: Sequence[FleetDevice], port: int, io_port: int,
                                on_ready: Callable[[list[str]], None],
                                signals: Sequence[int] = (signal.SIGINT, signal.SIGTERM),
                                rtu: str | None = None, http: dict[str, Any] | None = None,
                                sampler: LoadSampler | None = None, security: FleetSecurity | None = None) -> int:
    """Serve ``devices`` until one of ``signals``; returns the signal that stopped them. ``rtu``:
    the RS-485 line their ACG drives share, ``security`` their TLS and DTLS (``DeviceSet``); ``http``:
    the settings of one HTTP control API for every device (``http``, ``http_token``,
    ``http_allow_remote``, ``http_hosts``; or ``path``, a fleet worker's Unix socket); ``sampler``:
    what sums the devices' productions for a worker's heartbeat."""
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    received: list[int] = []

    def stop_on(sig: int) -> None:
        received.append(sig)
        stop.set()

    for sig in signals:
        loop.add_signal_handler(sig, stop_on, sig)
    fleet = DeviceSet(devices, port, io_port, rtu, security)
    api = None
    tasks: list[asyncio.Task[None]] = []
    # A worker's parent judges its load; a fleet of one process judges its own, the same way.
    watch = LoadWatch() if sampler is None else None
    sampler = sampler or LoadSampler()
    try:
        lines = await fleet.start()
        if http is not None:
            api = await _start_http(fleet.adapters, http, watch)
        tasks.append(asyncio.create_task(sampler.run([adapter.runtime for adapter in fleet.adapters])))
        if watch is not None:
            name = f"the fleet ({describe_addresses(d.address for d in fleet.devices)})"
            tasks.append(asyncio.create_task(watch_own_load(name, sampler, watch)))
        freeze_startup_objects()  # every device built: a full collection would stop them all at once
        on_ready(lines)
        await stop.wait()
    finally:
        for task in tasks:
            task.cancel()
        if api is not None:
            await api.close()
        await fleet.stop()
        for sig in signals:
            loop.remove_signal_handler(sig)
    return received[0] if received else signal.SIGTERM


def api_addresses(adapters: Sequence[Adapter]) -> dict[str, DeviceService]:
    """The devices of an HTTP control API (their command services) by address: the host of each,
    ``host:port`` where hosts repeat."""
    hosts = [adapter.settings.host for adapter in adapters]
    return {(host if hosts.count(host) == 1 else f"{host}:{adapter.port}"): adapter.service
            for host, adapter in zip(hosts, adapters, strict=True)}


async def _start_http(adapters: Sequence[Adapter], http: dict[str, Any], watch: LoadWatch | None = None) -> Any:
    """One HTTP control API for every device, each by its address (``api_addresses``): on ``http["http"]``
    (``HOST:PORT``), or for a worker of a fleet on the Unix socket ``http["path"]``, which only the
    fleet's relay reaches (``cipstack.control.http_relay``)."""
    from ..control.http import HttpApi, parse_listen
    from ..control.metrics import ShardGauges, WorkerGauges
    from ..listening import ListenError

    path = http.get("path")
    if path is not None:
        api = HttpApi(api_addresses(adapters), path=path)
        where = f"Unix socket {path} (the worker's HTTP control API)"
    else:
        host, port = parse_listen(http["http"])
        shard = http.get("shard")
        workers = WorkerGauges(lambda: [(1, load)] if watch is not None and (load := gauge_values(watch)) else [])
        gauges = ShardGauges(shard, lambda: (len(adapters), sum(a.runtime.power.powered for a in adapters)),
                             workers) if shard is not None else None
        api = HttpApi(api_addresses(adapters), host, port, token=http.get("http_token"),
                      allow_remote=http.get("http_allow_remote", False), hosts=tuple(http.get("http_hosts", ())),
                      shard=gauges)
        where = f"TCP {http['http']} (HTTP control API, --http)"
    try:
        await api.start()
    except OSError as exc:
        raise ListenError(where, exc) from None
    return api


__all__ = ["DeviceSet", "api_addresses", "build_adapter", "check_open_files", "device_line", "serve_until_signalled"]
