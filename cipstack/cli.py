"""The ``cipstack`` command: adapter emulator, discovery, explicit messaging.

Every failure prints one line on stderr and exits non-zero: 2 for bad arguments, 1 for an
error status or a network failure. ``--json`` prints one JSON object per line on stdout.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import logging
import os
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from . import __version__
from .cip.status import CipError, describe_status
from .cip.types import CipType, parse_int, type_by_name
from .eip.originator import DEFAULT_PORT, EncapsulationStatusError, parse_host

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_USAGE = 2


class UsageError(Exception):
    """A bad argument: reported as one line, exit status 2."""


def parse_number(text: str, what: str) -> int:
    try:
        return parse_int(text)
    except ValueError:
        raise UsageError(f"{what}: {text!r} is not a number (decimal or 0x hex)") from None


def parse_object_path(text: str, need_attribute: bool = False) -> tuple[int, int, int | None]:
    """``CLASS/INSTANCE[/ATTRIBUTE]`` with decimal or 0x hex numbers."""
    parts = text.strip().lstrip("@").split("/")
    if len(parts) not in (2, 3) or (need_attribute and len(parts) != 3):
        form = "CLASS/INSTANCE/ATTRIBUTE" if need_attribute else "CLASS/INSTANCE[/ATTRIBUTE]"
        raise UsageError(f"path {text!r} is not {form}")
    numbers = [parse_number(p, "path") for p in parts]
    for number, limit, name in zip(numbers, (0xFFFF, 0xFFFF, 0xFFFF), ("class", "instance", "attribute"), strict=False):
        if not 0 <= number <= limit:
            raise UsageError(f"{name} {number} out of range 0..{limit}")
    return numbers[0], numbers[1], (numbers[2] if len(numbers) == 3 else None)


def parse_type(text: str | None) -> CipType | None:
    if text is None:
        return None
    try:
        return type_by_name(text)
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def parse_duration(text: str) -> float:
    """``2``, ``2.5``, ``500ms``, ``2s``."""
    raw = text.strip().lower()
    scale = 1.0
    if raw.endswith("ms"):
        raw, scale = raw[:-2], 0.001
    elif raw.endswith("s"):
        raw = raw[:-1]
    try:
        value = float(raw) * scale
    except ValueError:
        raise UsageError(f"{text!r} is not a duration (e.g. 2, 500ms, 1.5s)") from None
    if value < 0:
        raise UsageError(f"duration {text!r} is negative")
    return value


def _emit(args: argparse.Namespace, record: dict[str, Any], text: str) -> None:
    if args.json:
        print(json.dumps(record), flush=True)
    else:
        print(text, flush=True)


# -- adapter -----------------------------------------------------------------------------------------
def cmd_adapter(args: argparse.Namespace) -> int:
    from .adapter import Adapter, AdapterSettings
    from .devices.profiles import PROFILES
    from .devices.state import StateFileError, default_state_path

    if args.eds is not None:
        return _adapter_from_eds(args)
    if args.profile is None:
        args.profile = "acg"
    if args.profile not in PROFILES:
        raise UsageError(f"unknown profile {args.profile!r} (known: {', '.join(sorted(PROFILES))})")
    if not 0 <= args.port < 65536:
        raise UsageError(f"port {args.port} out of range")
    if args.state is None:
        # One file per profile and model: another model's saved parameters are not this one's.
        args.state = default_state_path(f"{args.profile}-{args.model}" if args.model else args.profile)
    settings = AdapterSettings(host=args.host, port=args.port, profile=args.profile, model=args.model,
                               max_sessions=args.max_sessions, max_connections=args.max_connections,
                               io_port=args.io_port, control_path=args.control,
                               status_lines=not args.quiet, state_path=args.state, modbus_port=args.modbus_port,
                               **_limit_settings(args))
    try:
        adapter = Adapter(settings)
    except (StateFileError, ValueError, KeyError) as exc:
        raise UsageError(str(exc)) from None
    return _serve(adapter, args, "adapter")


def _limit_settings(args: argparse.Namespace) -> dict[str, Any]:
    """The adapter's limits beyond sessions and class 3 connections, checked with those two (a
    connection limit may be 0: that transport class refused; every other at least 1)."""
    limits = {"max_sessions_per_host": args.max_sessions_per_host, "max_io_connections": args.max_io_connections,
              "max_tcp_connections": args.max_tcp_connections,
              "max_tcp_connections_per_host": args.max_tcp_connections_per_host}
    checked = (("max_sessions", args.max_sessions), ("max_connections", args.max_connections), *limits.items())
    for name, value in checked:
        minimum = 0 if name in ("max_connections", "max_io_connections") else 1
        if value is not None and value < minimum:
            raise UsageError(f"--{name.replace('_', '-')} {value}: must be at least {minimum}")
    return limits


def _serve(adapter: Any, args: argparse.Namespace, command: str) -> int:
    """Run an emulator until SIGINT/SIGTERM; a port it cannot listen on is one line and exit 1."""
    from .eip.io_server import run_precise

    try:
        run_precise(adapter.serve_forever())
    except OSError as exc:
        print(f"cipstack {command}: cannot listen on {args.host}:{args.port}: {exc.strerror or exc}", file=sys.stderr)
        return EXIT_FAILURE
    return EXIT_OK


def _read_eds_file(path: str) -> Any:
    """The EDS document of ``path``; an unreadable file is a usage error (one line, exit 2)."""
    from .eds.reader import EdsSyntaxError, read_eds

    try:
        return read_eds(path)
    except EdsSyntaxError as exc:
        raise UsageError(f"{path}:{exc.line}: not a readable EDS: {exc.message}") from None
    except OSError as exc:
        raise UsageError(f"{path}: cannot read: {exc.strerror or exc}") from None


def _adapter_from_eds(args: argparse.Namespace) -> int:
    """``cipstack adapter --eds FILE``: the generic device the file describes; each construct it
    cannot serve is one warning line on stderr."""
    from .adapter import Adapter, AdapterSettings
    from .devices.base import DeviceLimits
    from .devices.from_eds import EdsDeviceError, build_eds_device
    from .devices.profiles import DEFAULT_MAC
    from .objects.tcpip import NetworkInterface

    if args.model is not None or args.state is not None or args.modbus_port is not None:
        raise UsageError("--model, --state and --modbus-port belong to --profile, not --eds")
    if not 0 <= args.port < 65536:
        raise UsageError(f"port {args.port} out of range")
    doc = _read_eds_file(args.eds)
    ip_address = args.host if args.host not in ("", "0.0.0.0", "localhost") else "127.0.0.1"
    try:
        device = build_eds_device(doc, NetworkInterface(ip_address=ip_address, mac=DEFAULT_MAC),
                                  DeviceLimits(args.max_sessions, args.max_connections))
    except EdsDeviceError as exc:
        raise UsageError(f"{args.eds}: {exc}") from None
    for issue in device.issues:
        print(f"cipstack adapter: {args.eds}:{issue.line}: warning: {issue.message}", file=sys.stderr, flush=True)
    settings = AdapterSettings(host=args.host, port=args.port, max_sessions=args.max_sessions,
                               max_connections=args.max_connections, io_port=args.io_port,
                               control_path=args.control, status_lines=not args.quiet, **_limit_settings(args))
    adapter = Adapter(settings, device=device)
    return _serve(adapter, args, "adapter")


# -- discovery -----------------------------------------------------------------------------------
def _identity_text(record: Any) -> str:
    address = f"{record.address.host}:{record.address.port}" if record.address else "?"
    return (f"{address}  {record.product_name!r}  vendor {record.vendor_id}  device type {record.device_type}  "
            f"product code {record.product_code}  revision {record.revision[0]}.{record.revision[1]}  "
            f"serial 0x{record.serial_number:08X}  status 0x{record.status:04X}  state {record.state}")


def cmd_discover(args: argparse.Namespace) -> int:
    from .eip.originator import discover

    records = asyncio.run(discover(args.broadcast, args.port, args.timeout))
    for record in records:
        _emit(args, record.as_dict(), _identity_text(record))
    if not records and not args.json:
        print("no device answered", file=sys.stderr)
    return EXIT_OK


def cmd_identity(args: argparse.Namespace) -> int:
    from .eip.originator import EncapsulationClient

    host, port = parse_host(args.target)

    async def run() -> list[Any]:
        client = await EncapsulationClient.connect(host, port, args.timeout, register=False)
        try:
            return await client.list_identity()
        finally:
            await client.close()

    records = asyncio.run(run())
    if not records:
        print(f"cipstack identity: {args.target} answered ListIdentity with no identity", file=sys.stderr)
        return EXIT_FAILURE
    for record in records:
        _emit(args, record.as_dict(), _identity_text(record))
    return EXIT_OK


# -- get / set -------------------------------------------------------------------------------------
def _value_text(value: Any) -> str:
    if isinstance(value, bytes):
        return value.hex(" ")
    if isinstance(value, str):
        return repr(value)
    return json.dumps(value) if isinstance(value, (dict, list)) else str(value)


def parse_route(text: str | None) -> list[Any] | None:
    """``PORT/LINK[,PORT/LINK...]``: ``1/0`` (backplane slot 0), ``2/3`` (CompoNet node 3), ``2/10.0.0.5``."""
    from .cip.epath import PortSegment

    if not text:
        return None
    route = []
    for hop in text.split(","):
        port_text, sep, link_text = hop.strip().partition("/")
        if not sep or not link_text:
            raise UsageError(f"route hop {hop!r} is not PORT/LINK")
        port = parse_number(port_text, "route port")
        try:
            link: int | str = parse_int(link_text)
        except ValueError:
            link = link_text  # an IP address or name: the link address as text
        if isinstance(link, int) and not 0 <= link <= 255:
            raise UsageError(f"link address {link} out of range 0..255")
        if not 1 <= port <= 0xFFFF:
            raise UsageError(f"route port {port} out of range")
        route.append(PortSegment.to(port, link))
    return route


async def _connect_identified(args: argparse.Namespace) -> Any:
    """A scanner that decodes by the declarations of the device's profile when it is one we know
    (the routed device's own Identity when ``--route`` is given)."""
    from .cip.types import UINT
    from .devices.profiles import catalog_for
    from .scanner import Scanner

    scanner = await Scanner.connect(args.target, timeout=args.timeout, route=parse_route(args.route))
    try:
        if scanner.route:
            vendor, product = await scanner.read(1, 1, 1, UINT), await scanner.read(1, 1, 3, UINT)
        else:
            identities = await scanner.list_identity()
            vendor, product = (identities[0].vendor_id, identities[0].product_code) if identities else (0, 0)
    except Exception:
        await scanner.close()
        raise
    scanner.catalog = catalog_for(vendor, product)
    return scanner


def cmd_get(args: argparse.Namespace) -> int:
    class_id, instance, attribute = parse_object_path(args.path)
    cip_type = parse_type(args.type)

    async def run() -> dict[str, Any]:
        scanner = await _connect_identified(args)
        try:
            if args.connected:
                await scanner.open_connection()
            if attribute is None:
                data, values = await scanner.get_attributes_all(class_id, instance)
                record: dict[str, Any] = {"status": 0, "data": data.hex()}
                if values is not None:
                    record["value"] = {name: _jsonable(v) for name, v in values.items()}
                return record
            result = await scanner.get_attribute_single(class_id, instance, attribute, cip_type)
            record = {"status": 0, "data": result.data.hex()}
            if result.known:
                record["value"] = result.json_value()
                record["type"] = result.type.name if result.type else None
            if result.spec is not None:
                record["name"] = result.spec.name
            return record
        finally:
            await scanner.close()

    record = asyncio.run(run())
    record["path"] = args.path
    if args.json:
        print(json.dumps(record), flush=True)
    elif "value" in record:
        name = f"{record['name']} = " if "name" in record else ""
        value = record["value"]
        print(f"{name}{_value_text(value)}" if not isinstance(value, dict)
              else "\n".join(f"{k} = {_value_text(v)}" for k, v in value.items()), flush=True)
    else:
        print(bytes.fromhex(record["data"]).hex(" ") or "(no data)", flush=True)
    return EXIT_OK


def _jsonable(value: Any) -> Any:
    if isinstance(value, bytes):
        return value.hex()
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_jsonable(v) for v in value]
    return value


def cmd_set(args: argparse.Namespace) -> int:
    from .scanner import Scanner

    class_id, instance, attribute = parse_object_path(args.path, need_attribute=True)
    assert attribute is not None
    cip_type = parse_type(args.type)
    assert cip_type is not None
    try:
        value = cip_type.parse_text(args.value)
        data = cip_type.encode(value)
    except (ValueError, CipError) as exc:
        raise UsageError(f"value {args.value!r} is not a valid {cip_type.name}: {exc}") from None

    async def run() -> None:
        scanner = await Scanner.connect(args.target, timeout=args.timeout, route=parse_route(args.route))
        try:
            if args.connected:
                await scanner.open_connection()
            await scanner.set_attribute_single(class_id, instance, attribute, data)
        finally:
            await scanner.close()

    asyncio.run(run())
    _emit(args, {"status": 0, "path": args.path, "data": data.hex(), "value": cip_type.to_json(value)},
          f"set {args.path} = {args.value}")
    return EXIT_OK


# -- class 1 ---------------------------------------------------------------------------------------------
def parse_assignment(text: str) -> tuple[str, str]:
    name, sep, value = text.partition("=")
    if not sep or not name.strip():
        raise UsageError(f"--set {text!r} is not FIELD=VALUE")
    return name.strip(), value.strip()


def cmd_io(args: argparse.Namespace) -> int:
    from .devices.profiles import catalog_for_identity
    from .eip.io_server import run_precise
    from .eip.originator import EncapsulationClient
    from .scanner import Scanner

    doc = None
    if args.eds is not None:
        if args.connection is None:
            raise UsageError("--eds needs --connection N (a ConnectionN of the file, by number or name)")
        if args.output is not None or args.input is not None or args.heartbeat is not None:
            raise UsageError("--eds takes the output, input and heartbeat from the file: give none of them")
        doc = _read_eds_file(args.eds)
        from .eds.interpret import read_view

        try:
            read_view(doc).connection(args.connection)
        except KeyError as exc:
            raise UsageError(f"{args.eds}: {exc.args[0]}") from None
    elif args.connection is not None:
        raise UsageError("--connection needs --eds FILE")
    elif args.input is None:
        raise UsageError("give --input (or --eds FILE --connection N)")
    # Without --rpi: the RPI the EDS proposes (None lets the scanner take it), else 10 ms.
    rpi: float | None = 0.010
    if args.rpi is not None:
        rpi = parse_duration(args.rpi)
    elif doc is not None:
        rpi = None
    if rpi is not None and not 0.0001 <= rpi <= 10:
        raise UsageError(f"RPI {args.rpi} outside 0.1 ms .. 10 s")
    assignments = [parse_assignment(a) for a in args.set or []]
    host, port = parse_host(args.target)

    async def run() -> int:
        probe = await EncapsulationClient.connect(host, port, args.timeout, register=False)
        try:
            identities = await probe.list_identity()
        finally:
            await probe.close()
        catalog = catalog_for_identity(identities[0]) if identities else None
        scanner = await Scanner.connect(args.target, timeout=args.timeout, catalog=catalog)
        options: dict[str, Any] = {"target_io_port": args.target_io_port, "local_io_port": args.io_port}
        loop = asyncio.get_running_loop()
        started = loop.time()
        if doc is not None:
            opened = scanner.io_connection_from_eds(doc, args.connection, rpi, **options)
        else:
            assert rpi is not None  # set above when no EDS is given
            opened = scanner.io_connection(output=args.output, input=args.input, rpi=rpi, heartbeat=args.heartbeat,
                                           **options)
        async with scanner, opened as io:
            for name, value in assignments:
                try:
                    if name == "raw":
                        io.output.raw = bytes.fromhex(value)
                    else:
                        setattr(io.output, name, parse_int(value))
                except (AttributeError, ValueError) as exc:
                    raise UsageError(f"--set {name}={value}: {exc}") from None
            io.set_run(not args.idle)

            def show(image: Any) -> None:
                elapsed = round(loop.time() - started, 4)
                try:
                    values: Any = image.fields()
                except AttributeError:
                    values = {"raw": image.raw.hex()}
                if args.json:
                    print(json.dumps({"t": elapsed, "input": values}), flush=True)
                else:
                    print(f"{elapsed:9.3f}s  " + "  ".join(f"{k}={v}" for k, v in values.items()), flush=True)

            async def follow() -> None:
                async for image in io.updates():
                    show(image)

            with contextlib.suppress(asyncio.TimeoutError):
                await asyncio.wait_for(follow(), args.duration)
            stats = io.stats.as_dict()
        summary = {"summary": {"duration_s": round(loop.time() - started, 3), **stats}}
        if args.json:
            print(json.dumps(summary), flush=True)
        else:
            print("sent {sent}  received {received}  late {late}  lost {lost}  duplicates {duplicates}  "
                  "max lateness {max_lateness:.6f} s".format(**stats), flush=True)
        return EXIT_OK

    return run_precise(run())


def cmd_models(args: argparse.Namespace) -> int:
    from .devices.omron.models import MODELS

    for m in MODELS:
        family = m.family.value.lower()
        if args.profile and family != args.profile:
            continue
        _emit(args, {"profile": family, "model": m.name, "product_code": m.product_code,
                     "product_name": m.product_name, "eds_file": m.eds_file},
              f"{family:3}  {m.name:14}  product code {m.product_code:5}  {m.product_name:32}  {m.eds_file}")
    return EXIT_OK


def cmd_componet(args: argparse.Namespace) -> int:
    from .adapter import Adapter, AdapterSettings
    from .devices.omron.device import build_componet_gateway, parse_nodes
    from .devices.profiles import DEFAULT_MAC
    from .objects.tcpip import NetworkInterface

    try:
        nodes = parse_nodes(args.nodes)
        if not nodes:
            raise ValueError("--nodes names no node")
        gateway = build_componet_gateway(nodes, NetworkInterface(ip_address=args.host, mac=DEFAULT_MAC))
    except (ValueError, KeyError) as exc:
        raise UsageError(str(exc)) from None
    settings = AdapterSettings(host=args.host, port=args.port, io_port=args.io_port, control_path=args.control,
                               status_lines=not args.quiet)
    adapter = Adapter(settings, device=gateway)
    return _serve(adapter, args, "componet")


# -- emulator control ---------------------------------------------------------------------------------------
def _control(args: argparse.Namespace, request: dict[str, Any]) -> dict[str, Any]:
    from .control import ControlError, control_request, default_control_path

    path = args.control or default_control_path(args.port)
    try:
        return control_request(path, request, args.timeout)
    except ControlError as exc:
        raise UsageError(str(exc)) if "no emulator" in str(exc) else ConnectionError(str(exc)) from None


def cmd_drive_trip(args: argparse.Namespace) -> int:
    reply = _control(args, {"command": "trip", "code": args.code})
    _emit(args, reply, f"{reply['result']}" + (f"\n{reply['status']}" if reply.get("status") else ""))
    return EXIT_OK


def cmd_drive_status(args: argparse.Namespace) -> int:
    reply = _control(args, {"command": "status"})
    _emit(args, reply, f"{reply['status'] or '(no drive)'}  sessions {reply['sessions']}  class 3 "
                       f"{reply['class3_connections']}  class 1 {reply['class1_connections']}")
    return EXIT_OK


# -- EDS ----------------------------------------------------------------------------------------------------
def cmd_eds_check(args: argparse.Namespace) -> int:
    from .eds.commands import run_check

    identity = None
    if args.against:
        from .scanner import SyncScanner

        with SyncScanner(args.against, timeout=args.timeout) as scanner:
            _, values = scanner.get_attributes_all(0x01, 1)
        if values is None:
            raise CipError(0x1F, message=f"{args.against}: Identity reply could not be decoded")
        identity = {"vendor_id": values["Vendor ID"], "device_type": values["Device Type"],
                    "product_code": values["Product Code"],
                    "revision": (values["Revision"]["major"], values["Revision"]["minor"]),
                    "product_name": values["Product Name"]}
    return run_check(args, identity)


def cmd_eds_generate(args: argparse.Namespace) -> int:
    from .eds.commands_generate import run_generate

    return run_generate(args)


def cmd_eds_show(args: argparse.Namespace) -> int:
    from .eds.commands import run_show

    return run_show(args)


# -- parser ------------------------------------------------------------------------------------------
class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> Any:  # one line, exit 2, no usage dump
        raise UsageError(message)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="cipstack", description="CIP for AC drives over EtherNet/IP and CompoNet")
    parser.add_argument("--version", action="version", version=f"cipstack {__version__}")
    levels = ["DEBUG", "INFO", "WARNING", "ERROR"]
    parser.add_argument("--log-level", default="INFO", choices=levels, type=str.upper)
    # Also accepted after the command name (``cipstack adapter --log-level WARNING``).
    logging_options = _Parser(add_help=False)
    logging_options.add_argument("--log-level", default=argparse.SUPPRESS, choices=levels, type=str.upper,
                                 help="log level on stderr (default INFO)")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    _add_parser = sub.add_parser

    def add_parser(name: str, **kwargs: Any) -> argparse.ArgumentParser:
        return _add_parser(name, parents=[logging_options], **kwargs)

    sub.add_parser = add_parser  # type: ignore[method-assign]

    def common(p: argparse.ArgumentParser, target: bool = True) -> None:
        if target:
            p.add_argument("target", metavar="HOST[:PORT]", help=f"target address (default port {DEFAULT_PORT})")
        p.add_argument("--timeout", type=parse_duration, default=5.0, help="reply timeout (default 5 s)")
        p.add_argument("--json", action="store_true", help="one JSON object per line")

    p = sub.add_parser("adapter", help="run the adapter emulator")
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    p.add_argument("--port", type=lambda t: parse_number(t, "port"), default=DEFAULT_PORT)
    device = p.add_mutually_exclusive_group()
    device.add_argument("--profile", help="device profile: acg (default), mx2, rx")
    device.add_argument("--eds", metavar="FILE",
                        help="emulate the generic device an EDS file describes (identity, parameters as "
                             "attributes, assemblies, connections)")
    p.add_argument("--model", help="model of the mx2/rx profiles (e.g. MX2-A2015-E, RX-A4055-E)")
    p.add_argument("--max-sessions", type=lambda t: parse_number(t, "max sessions"), default=32,
                   help="encapsulation sessions (default 32)")
    p.add_argument("--max-sessions-per-host", type=lambda t: parse_number(t, "max sessions per host"),
                   help="sessions one originator address may hold (default: half of --max-sessions)")
    p.add_argument("--max-connections", type=lambda t: parse_number(t, "max connections"), default=32,
                   help="class 3 (connected explicit) connections (default 32)")
    p.add_argument("--max-io-connections", type=lambda t: parse_number(t, "max io connections"),
                   help="class 1 (I/O) connections (default: the device's, 64 for the ACG-ET2)")
    p.add_argument("--max-tcp-connections", type=lambda t: parse_number(t, "max tcp connections"), default=256,
                   help="open TCP connections to the encapsulation port; more are closed at accept (default 256)")
    p.add_argument("--max-tcp-connections-per-host", type=lambda t: parse_number(t, "max tcp connections per host"),
                   help="open TCP connections from one address (default: half of --max-tcp-connections)")
    p.add_argument("--io-port", type=lambda t: parse_number(t, "io port"), default=2222,
                   help="UDP port of class 1 I/O (default 2222; 0 picks a free one)")
    p.add_argument("--control", type=Path, help="control socket for `cipstack drive` (default: per port)")
    p.add_argument("--state", type=Path,
                   help="state file of saved parameters (default: in the user's data directory, per profile)")
    p.add_argument("--modbus-port", type=lambda t: parse_number(t, "modbus port"),
                   help="also serve Modbus TCP on this port (ACG)")
    p.add_argument("--quiet", action="store_true", help="no status line on stdout")
    p.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
    p.set_defaults(func=cmd_adapter)

    p = sub.add_parser("models", help="the MX2/RX models the mx2/rx profiles emulate (Tables 2/3)")
    p.add_argument("--profile", choices=["mx2", "rx"])
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_models)

    p = sub.add_parser("componet", help="run a CompoNet network of MX2/RX slaves behind an EtherNet/IP gateway")
    p.add_argument("--nodes", required=True, metavar="PROFILE:MODEL@NODE,...",
                   help="slaves, e.g. mx2:MX2-A2015-E@3,rx:RX-A4055-E@5 (node addresses 0-63)")
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    p.add_argument("--port", type=lambda t: parse_number(t, "port"), default=DEFAULT_PORT)
    p.add_argument("--io-port", type=lambda t: parse_number(t, "io port"), default=2222)
    p.add_argument("--control", type=Path, help="control socket (default: per port)")
    p.add_argument("--quiet", action="store_true", help="no status line on stdout")
    p.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
    p.set_defaults(func=cmd_componet)

    p = sub.add_parser("discover", help="ListIdentity over UDP")
    p.add_argument("--broadcast", default="255.255.255.255", help="broadcast or unicast address")
    p.add_argument("--port", type=lambda t: parse_number(t, "port"), default=DEFAULT_PORT)
    common(p, target=False)
    p.set_defaults(func=cmd_discover, timeout=2.0)

    p = sub.add_parser("identity", help="ListIdentity over TCP")
    common(p)
    p.set_defaults(func=cmd_identity)

    p = sub.add_parser("get", help="Get_Attribute_Single (or Get_Attributes_All without an attribute)")
    common(p)
    p.add_argument("path", metavar="CLASS/INSTANCE[/ATTRIBUTE]")
    p.add_argument("--type", help="CIP type to decode the value (UINT, SHORT_STRING, ...)")
    p.add_argument("--connected", action="store_true", help="use a class 3 connection")
    p.add_argument("--route", metavar="PORT/LINK[,...]",
                   help="route through the target (Unconnected_Send), e.g. 1/0 or 2/3 (CompoNet node 3)")
    p.set_defaults(func=cmd_get)

    p = sub.add_parser("io", help="open a class 1 connection, print input changes by field name")
    common(p)
    p.add_argument("--output", type=lambda t: parse_number(t, "output"), help="output (O->T) assembly instance")
    p.add_argument("--input", type=lambda t: parse_number(t, "input"), help="input assembly instance")
    p.add_argument("--heartbeat", type=lambda t: parse_number(t, "heartbeat"),
                   help="O->T heartbeat point instead of an output (input only: e.g. 198, listen only: 199)")
    p.add_argument("--rpi", help="requested packet interval (default: the EDS's with --eds, else 10ms)")
    p.add_argument("--eds", metavar="FILE", help="open a connection this EDS file describes (with --connection)")
    p.add_argument("--connection", metavar="N",
                   help="the ConnectionN of --eds to open, by number N or by name")
    p.add_argument("--set", action="append", metavar="FIELD=VALUE",
                   help="output field to set (or raw=HEX); repeatable")
    p.add_argument("--duration", type=parse_duration, default=5.0, help="how long to run (default 5s)")
    p.add_argument("--idle", action="store_true", help="send idle instead of run in the run/idle header")
    p.add_argument("--io-port", type=lambda t: parse_number(t, "io port"), default=0,
                   help="local UDP port for T->O data (default: any free port, announced to the target)")
    p.add_argument("--target-io-port", type=lambda t: parse_number(t, "target io port"), default=2222,
                   help="the target's class 1 UDP port (default 2222)")
    p.set_defaults(func=cmd_io)

    p = sub.add_parser("drive", help="control a running emulator: inject a trip, read its status")
    drive = p.add_subparsers(dest="drive_command", required=True, parser_class=_Parser)
    for name, func, text in (("trip", cmd_drive_trip, "trip the emulated drive with a fault code"),
                             ("status", cmd_drive_status, "the emulated drive's status line")):
        q = drive.add_parser(name, help=text)
        if name == "trip":
            q.add_argument("code", type=lambda t: parse_number(t, "fault code"),
                           help="fault code of the drive's manual (decimal or 0x hex)")
        q.add_argument("--port", type=lambda t: parse_number(t, "port"), default=DEFAULT_PORT,
                       help="the emulator's EtherNet/IP port (finds its control socket)")
        q.add_argument("--control", type=Path, help="the emulator's control socket")
        q.add_argument("--timeout", type=parse_duration, default=5.0)
        q.add_argument("--json", action="store_true")
        q.set_defaults(func=func)

    from .eds.commands import add_check_arguments, add_show_arguments
    from .eds.commands_generate import add_generate_arguments

    p = sub.add_parser("eds", help="EDS files: check, show")
    eds = p.add_subparsers(dest="eds_command", required=True, parser_class=_Parser)
    q = eds.add_parser("check", help="check EDS files against the rules a configuration tool relies on")
    add_check_arguments(q)
    q.add_argument("--against", metavar="HOST[:PORT]", help="also compare [Device] with a live device's Identity")
    q.add_argument("--timeout", type=parse_duration, default=5.0)
    q.set_defaults(func=cmd_eds_check)
    q = eds.add_parser("generate", help="write the EDS files of emulated models")
    add_generate_arguments(q)
    q.set_defaults(func=cmd_eds_generate)
    q = eds.add_parser("show", help="a readable summary: identity, assemblies, connections")
    add_show_arguments(q)
    q.set_defaults(func=cmd_eds_show)

    p = sub.add_parser("set", help="Set_Attribute_Single")
    common(p)
    p.add_argument("path", metavar="CLASS/INSTANCE/ATTRIBUTE")
    p.add_argument("value")
    p.add_argument("--type", required=True, help="CIP type of the value (UINT, INT, REAL, SHORT_STRING, ...)")
    p.add_argument("--connected", action="store_true", help="use a class 3 connection")
    p.add_argument("--route", metavar="PORT/LINK[,...]", help="route through the target (Unconnected_Send)")
    p.set_defaults(func=cmd_set)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except UsageError as exc:
        print(f"cipstack: {exc}", file=sys.stderr)
        return EXIT_USAGE
    logging.basicConfig(level=getattr(logging, args.log_level), stream=sys.stderr,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    func: Callable[[argparse.Namespace], int] = args.func
    name = f"cipstack {args.command}"
    try:
        return func(args)
    except UsageError as exc:
        print(f"{name}: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except CipError as exc:
        if getattr(args, "json", False):
            print(json.dumps({"status": exc.general, "extended_status": list(exc.extended),
                              "error": describe_status(exc.general, exc.extended),
                              "path": getattr(args, "path", None)}), flush=True)
        print(f"{name}: error status {exc}", file=sys.stderr)
        return EXIT_FAILURE
    except EncapsulationStatusError as exc:
        print(f"{name}: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    except (ConnectionError, asyncio.TimeoutError, TimeoutError, OSError) as exc:
        print(f"{name}: {exc or type(exc).__name__}", file=sys.stderr)
        return EXIT_FAILURE
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        # The reader went away (``cipstack models | head``): not an error of ours.
        sys.stdout = open(os.devnull, "w")  # noqa: SIM115 - silences the flush at exit
        return EXIT_OK
    except ValueError as exc:
        print(f"{name}: {exc}", file=sys.stderr)
        return EXIT_USAGE


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
