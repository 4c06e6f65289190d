"""cipstack fleet: many emulated devices, each on its own address (see ``cipstack.fleet``)."""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path
from typing import Any

from ..eip.io_core import DEFAULT_IO_PORT
from ..eip.wire.encapsulation import DEFAULT_PORT
from .common import EXIT_OK, EXIT_USAGE, UsageError

#: Worker processes when neither --workers nor the spec file says.
DEFAULT_WORKERS = 1

log = logging.getLogger("cipstack.fleet")


def _fleet_spec(args: argparse.Namespace) -> Any:
    """The spec of the command line, over the spec file's (an option given wins over the file's key)."""
    from ..devices.state import data_directory
    from ..fleet.spec import (
        FleetSpec,
        SpecError,
        assign,
        assign_stations,
        check_port,
        check_workers,
        make_group,
        parse_addresses,
        parse_group,
        read_spec_file,
    )

    settings: dict[str, Any] = {}
    groups = []
    if args.spec is not None:
        if args.device:
            raise UsageError("give the devices with --device or in --spec FILE, not both")
        settings, groups = read_spec_file(args.spec)
        where = str(args.spec)
    else:
        where = "--device"
    if args.param and args.spec is not None:
        raise UsageError("--param goes with --device; in a spec file, a [[device]] has params")
    groups += [parse_group(text) for text in args.device or []]
    if args.param:   # every ACG of the command line gets them
        if not any(g.profile == "acg" for g in groups):
            raise UsageError("--param sets the ACG's keypad parameters, and the fleet has no acg device")
        groups = [make_group(g.profile, g.model, g.count, str(g.first) if g.first else None, args.param, g.text)
                  if g.profile == "acg" else g for g in groups]
    addresses = args.addresses if args.addresses is not None else settings.get("addresses")
    pool = parse_addresses(addresses, "--addresses" if args.addresses is not None else f"{where}: addresses") \
        if addresses is not None else None
    state_dir = args.state_dir or settings.get("state_dir") or data_directory() / "fleet"
    devices = assign(groups, pool, Path(state_dir))
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
    return FleetSpec(devices, port, io_port, workers, Path(state_dir), rtu)


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
    addresses = describe_addresses(d.address for d in spec.devices)
    from .emulators import _http_settings

    http = _http_settings(args)

    def ready(lines: list[str]) -> None:
        for line in lines:
            print(line, flush=True)
        processes = "1 process" if spec.workers == 1 else f"{spec.workers} worker processes"
        log.info("emulating %d devices on %s (%s); Ctrl-C or SIGTERM stops them", len(spec.devices), addresses,
                 processes)

    try:
        if spec.workers == 1:
            run_precise(serve_until_signalled(spec.devices, spec.port, spec.io_port, ready, rtu=spec.rtu,
                                              http=http or None))
        else:
            supervisor = Supervisor(spec.devices, spec.port, spec.io_port, spec.workers, http=http or None)
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


__all__ = ["cmd_fleet"]
