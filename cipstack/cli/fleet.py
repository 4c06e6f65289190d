"""cipstack fleet: many emulated devices, each on its own address (see ``cipstack.fleet``)."""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path
from typing import Any

from ..eip.io_core import DEFAULT_IO_PORT
from ..eip.wire.encapsulation import DEFAULT_PORT, SECURE_PORT
from .common import EXIT_OK, EXIT_USAGE, UsageError

#: Worker processes when neither --workers nor the spec file says.
DEFAULT_WORKERS = 1

log = logging.getLogger("cipstack.fleet")


def _fleet_spec(args: argparse.Namespace) -> Any:
    """The spec of the command line, over the spec file's (an option given wins over the file's key)."""
    from ..devices.state import data_directory
    from ..fleet.serve import check_open_files
    from ..fleet.spec import (
        MAX_DEVICES,
        DeviceGroup,
        FleetSecurity,
        FleetSpec,
        SpecError,
        assign,
        assign_stations,
        check_max_devices,
        check_port,
        check_workers,
        make_group,
        parse_addresses,
        parse_group,
        parse_shard,
        read_spec_file,
        select_shard,
    )

    settings: dict[str, Any] = {}
    groups: list[DeviceGroup] = []
    given_limit = check_max_devices(args.max_devices) if args.max_devices is not None else None
    if args.spec is not None:
        if args.device:
            raise UsageError("give the devices with --device or in --spec FILE, not both")
        settings, groups = read_spec_file(args.spec, given_limit)
        where = str(args.spec)
    else:
        where = "--device"
    limit = given_limit or settings.get("max_devices", MAX_DEVICES)
    if args.param and args.spec is not None:
        raise UsageError("--param goes with --device; in a spec file, a [[device]] has params")
    groups += [parse_group(text, limit) for text in args.device or []]
    if args.param:   # every device of the command line whose keypad takes them all gets them
        taking = [g for g in groups if _keypad_takes(g.profile, args.param)]
        if not taking:
            raise UsageError(f"--param {' '.join(args.param)}: no device of the fleet has a keypad with these "
                             f"codes (profiles {', '.join(sorted({g.profile for g in groups}))})")
        groups = [make_group(g.profile, g.model, g.count, str(g.first) if g.first else None, args.param, g.text,
                             limit=limit) if g in taking else g for g in groups]
    addresses = args.addresses if args.addresses is not None else settings.get("addresses")
    pool = parse_addresses(addresses, "--addresses" if args.addresses is not None else f"{where}: addresses",
                           limit) if addresses is not None else None
    state_dir: Path | None = Path(args.state_dir or settings.get("state_dir") or data_directory() / "fleet")
    if args.factory:
        if args.state_dir is not None:
            raise UsageError("--factory reads and writes no state file: drop --state-dir DIR")
        state_dir = None   # every device from factory settings; its saves last until the fleet stops
    devices = assign(groups, pool, state_dir, limit)
    # The shard is cut from the whole plant, before anything that depends on the process (workers, the
    # RS-485 line), so that every pod reading one spec agrees on who serves which device.
    shard = parse_shard(args.shard) if args.shard is not None else None
    if shard is not None:
        devices = select_shard(devices, shard)
    port = check_port(args.port if args.port is not None else settings.get("port", DEFAULT_PORT), "port")
    io_port = check_port(args.io_port if args.io_port is not None else settings.get("io_port", DEFAULT_IO_PORT),
                         "io port")
    workers = check_workers(args.workers if args.workers is not None else settings.get("workers", DEFAULT_WORKERS),
                            len(devices))
    rtu = args.rtu if args.rtu is not None else settings.get("rtu")
    if rtu is not None:
        devices = assign_stations(devices, workers, "--rtu" if args.rtu is not None else f"{where}: rtu")
    elif any(d.station is not None for d in devices):
        raise SpecError(f"{where}: a station ID puts a drive on the fleet's RS-485 line: give --rtu (rtu = \"pty\")")
    folder = args.security if args.security is not None else settings.get("security")
    secure_port = args.security_port if args.security_port is not None else settings.get("security_port")
    security = None
    if folder is not None:
        security = FleetSecurity(Path(folder), check_port(SECURE_PORT if secure_port is None else secure_port,
                                                          "security port"))
        if not args.list_addresses:
            from ..security import Credentials

            Credentials.load(security.folder)   # a folder it cannot read: one line, before any device starts
    elif secure_port is not None:
        raise UsageError("--security-port goes with --security DIR (or security in the spec file)")
    if not args.list_addresses:   # a pod's init container lists them where the fleet will not run
        check_open_files(len(devices), workers, security is not None)
    return FleetSpec(devices, port, io_port, workers, state_dir, rtu, shard, security)



def _keypad_takes(profile: str, params: list[str]) -> bool:
    """Whether the keypad of ``profile`` knows the code of every ``CODE=VALUE`` of ``params`` (the values
    are checked with the group, each refusal in its own words)."""
    from ..devices.profiles import PROFILES

    keypad = PROFILES[profile].keypad
    if keypad is None:
        return False
    codes = keypad()
    try:
        for text in params:
            codes.register(text.partition("=")[0])
    except LookupError:
        return False
    return True

def cmd_fleet(args: argparse.Namespace) -> int:
    from ..eip.io_server import run_precise
    from ..fleet.serve import serve_until_signalled
    from ..fleet.spec import SpecError, describe_addresses
    from ..fleet.workers import FleetFailure, Supervisor
    from ..listening import ListenError
    from ..modbus.rtu_line import RtuPortError

    try:
        spec = _fleet_spec(args)
    except SpecError as exc:
        raise UsageError(str(exc)) from None
    if args.list_addresses:   # what a pod's init container adds to the plant interface, then nothing else
        for device in spec.devices:
            print(device.address)
        return EXIT_OK
    addresses = describe_addresses(d.address for d in spec.devices)
    from .emulators import _http_settings

    http = _http_settings(args)
    if http:   # the fleet's gauges of itself on /metrics carry its shard (0/1: the whole plant)
        http["shard"] = str(spec.shard or "0/1")

    def ready(lines: list[str]) -> None:
        for line in lines:
            print(line, flush=True)
        processes = "1 process" if spec.workers == 1 else f"{spec.workers} worker processes"
        shard = f", shard {spec.shard} of the plant" if spec.shard is not None else ""
        log.info("emulating %d devices on %s (%s%s); Ctrl-C or SIGTERM stops them", len(spec.devices), addresses,
                 processes, shard)

    try:
        if spec.workers == 1:
            run_precise(serve_until_signalled(spec.devices, spec.port, spec.io_port, ready, rtu=spec.rtu,
                                              http=http or None, security=spec.security))
        else:
            supervisor = Supervisor(spec.devices, spec.port, spec.io_port, spec.workers, http=http or None,
                                    security=spec.security)
            supervisor.run(ready)
            if supervisor.lost:   # --http: the fleet went on without them, and says so at the end
                print(f"cipstack fleet: stopped; {len(supervisor.lost)} of {spec.workers} workers had ended: "
                      + "; ".join(supervisor.lost), file=sys.stderr)
                return 1
    except (ListenError, SpecError, RtuPortError) as exc:
        print(f"cipstack fleet: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except FleetFailure as exc:
        print(f"cipstack fleet: {exc}", file=sys.stderr)
        return exc.status
    except OSError as exc:
        print(f"cipstack fleet: cannot listen on {addresses}: {exc.strerror or exc}", file=sys.stderr)
        return EXIT_USAGE
    log.info("stopped")
    return EXIT_OK


def cmd_plant(args: argparse.Namespace) -> int:
    """``cipstack plant``: one HTTP API for every device of the fleets a name resolves to."""
    from ..control.plant import PlantError, parse_fleet
    from .emulators import _http_settings

    if args.http is None:
        raise UsageError("cipstack plant serves an HTTP API: give --http HOST:PORT")
    try:
        fleets = [parse_fleet(text) for text in args.fleet]
    except PlantError as exc:
        raise UsageError(str(exc)) from None
    if args.refresh <= 0:
        raise UsageError(f"--refresh {args.refresh:g}: not a positive duration")
    http = _http_settings(args)
    from ..eip.io_server import run_precise

    try:
        run_precise(_serve_plant(fleets, http, args.refresh))
    except OSError as exc:
        print(f"cipstack plant: cannot listen on {args.http}: {exc.strerror or exc}", file=sys.stderr)
        return EXIT_USAGE
    log.info("stopped")
    return EXIT_OK


async def _serve_plant(fleets: list[tuple[str, int]], http: dict[str, Any], refresh: float) -> None:
    """The plant view until SIGINT or SIGTERM."""
    import asyncio
    import signal

    from ..control.http import parse_listen
    from ..control.http_relay import RelayApi
    from ..control.plant import PlantView

    host, port = parse_listen(http["http"])
    relay = RelayApi([], host, port, token=http.get("http_token"), allow_remote=http.get("http_allow_remote", False),
                     hosts=tuple(http.get("http_hosts", ())), shard=None)
    view = PlantView(fleets, relay, token=http.get("http_token"), refresh=refresh)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    try:
        await view.start()
        log.info("plant view of %s: %d devices in %d fleets; Ctrl-C or SIGTERM stops it",
                 ", ".join(f"{name}:{p}" for name, p in fleets), len(relay.routes), len(view.fleets))
        await stop.wait()
    finally:
        await view.close()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(sig)


__all__ = ["cmd_fleet", "cmd_plant"]
