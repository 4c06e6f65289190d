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
from .eip.encapsulation import EncapsulationError
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
        args.profile = _profile_of_model(args.model) if args.model else "acg"
    if args.profile not in PROFILES:
        raise UsageError(f"unknown profile {args.profile!r} (known: {', '.join(sorted(PROFILES))})")
    if args.model and args.profile == "acg":
        raise UsageError(f"--model {args.model}: the acg profile has one model; --model names an MX2 or RX model")
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
    if args.param:
        _apply_keypad_parameters(adapter, args.param)
    return _serve(adapter, args, "adapter")


def _apply_keypad_parameters(adapter: Any, assignments: list[str]) -> None:
    """``--param CODE=VALUE``: keypad parameters set before the network connects (the ACG's codes)."""
    from .devices.acg.device import AcgDevice
    from .devices.acg.keypad import apply_parameters

    if not isinstance(adapter.device, AcgDevice):
        raise UsageError("--param sets the ACG's keypad parameters (profile acg)")
    drive = adapter.device.drive
    try:
        applied = apply_parameters(drive, assignments, drive.time)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    for line in applied:
        logging.getLogger("cipstack.adapter").info("keypad parameter %s", line)


def _profile_of_model(name: str) -> str:
    """The profile of ``--model`` given without ``--profile``: the family the model belongs to."""
    from .devices.omron.models import model

    try:
        return model(name).family.value.lower()
    except KeyError as exc:
        raise UsageError(f"--model: {exc} (`cipstack models` lists them)") from None


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
    """Run an emulator until SIGINT/SIGTERM; a port it cannot listen on (taken, or not an address of
    this machine) is one line naming the port and its option, and exit 2."""
    from .eip.io_server import run_precise
    from .listening import ListenError

    try:
        run_precise(adapter.serve_forever())
    except ListenError as exc:
        print(f"cipstack {command}: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except OSError as exc:
        print(f"cipstack {command}: cannot listen on {args.host}:{args.port}: {exc.strerror or exc}", file=sys.stderr)
        return EXIT_USAGE
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
    from .devices.profiles import DEFAULT_MAC
    from .eds.emulated_device import EdsDeviceError, build_eds_device
    from .objects.tcpip import NetworkInterface

    if args.model is not None or args.state is not None or args.modbus_port is not None or args.param:
        raise UsageError("--model, --state, --modbus-port and --param belong to --profile, not --eds")
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
                    record["value"] = {json_key(name): _jsonable(v) for name, v in values.items()}
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
              else "\n".join(_member_text(k, v) for k, v in value.items()), flush=True)
    else:
        print(bytes.fromhex(record["data"]).hex(" ") or "(no data)", flush=True)
    return EXIT_OK


def json_key(name: str) -> str:
    """An attribute's name as a JSON key, as every JSON record of the command spells fields: "Serial Number"
    -> "serial_number" (so ``get HOST 1/1 --json`` and ``identity --json`` give one Identity shape)."""
    return "_".join("".join(c if c.isalnum() else " " for c in name.lower()).split())


def _member_text(name: str, value: Any) -> str:
    """One ``name = value`` line of Get_Attributes_All; the bytes after the declared attributes as hex."""
    from .scanner import UNDECODED

    if name in (UNDECODED, json_key(UNDECODED)) and isinstance(value, str):
        raw = bytes.fromhex(value)
        return f"{UNDECODED} = {len(raw)} bytes: {raw.hex(' ')}"
    return f"{name} = {_value_text(value)}"


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


_RPI_UNITS = (("us", 1e-6), ("ms", 1e-3), ("s", 1.0))


def parse_rpi(text: str) -> float:
    """``10ms``, ``500us``, ``0.5s``: an RPI needs its unit (a bare ``5`` would be 5 s, 500 times 10 ms)."""
    raw = text.strip().lower()
    for suffix, scale in _RPI_UNITS:
        if raw.endswith(suffix):
            try:
                value = float(raw[:-len(suffix)]) * scale
            except ValueError:
                break
            if not 0.0001 <= value <= 10:
                raise UsageError(f"RPI {text} outside 0.1 ms .. 10 s")
            return value
    else:
        try:
            float(raw)
        except ValueError:
            pass
        else:
            raise UsageError(f"--rpi {text}: give a unit (e.g. {text}ms or {text}s)")
    raise UsageError(f"--rpi {text!r} is not a duration (e.g. 10ms, 500us, 0.5s)")


def parse_print(text: str) -> tuple[str, float]:
    """``changes`` (every input change), ``summary`` (statistics only), ``every:DURATION``
    (also ``every=DURATION`` or ``"every DURATION"``): the latest input at most once per DURATION."""
    raw = text.strip().lower()
    if raw in ("changes", "summary"):
        return raw, 0.0
    for separator in (":", "=", " "):
        head, sep, tail = raw.partition(separator)
        if sep and head == "every":
            period = parse_duration(tail.strip())
            if period <= 0:
                raise UsageError(f"--print {text}: the period must be positive")
            return "every", period
    raise UsageError(f"--print {text!r} is not changes, summary or every:DURATION (e.g. every:1s)")


def parse_config_data(text: str | None) -> bytes:
    if not text:
        return b""
    try:
        data = bytes.fromhex(text.replace(":", "").replace("_", ""))
    except ValueError:
        raise UsageError(f"--config-data {text!r} is not hex bytes (e.g. 0102ff00)") from None
    if len(data) > 510:
        raise UsageError(f"--config-data is {len(data)} bytes, at most 510")
    return data


def _set_output(io: Any, name: str, value: str) -> None:
    """One ``--set``; an unknown field names the valid ones."""
    try:
        if name == "raw":
            io.output.raw = bytes.fromhex(value)
        else:
            setattr(io.output, name, parse_int(value))
    except (AttributeError, ValueError) as exc:
        fields = io.output.field_names
        hint = (f" (output fields: {', '.join(sorted(fields))}, raw)" if fields
                else " (no field names known: use raw=HEX)")
        raise UsageError(f"--set {name}={value}: {exc}{hint}") from None


def _statistics_text(stats: dict[str, Any]) -> str:
    def ms(key: str) -> str:
        return "-" if stats.get(key) is None else f"{stats[key]:.3f} ms"

    rate = stats.get("received_rate_hz")
    missed = stats.get("missed_slots")
    return ("sent {sent}  received {received}  late {late}  lost {lost}  duplicates {duplicates}  "
            "max lateness {max_lateness:.6f} s\n".format(**stats)
            + f"T->O API {stats['api_ms']:.3f} ms ({stats['api_rate_hz'] or 0:.1f}/s)  received "
            + ("-" if rate is None else f"{rate:.1f}/s")
            + f"  interval p50 {ms('interval_p50_ms')}  p99 {ms('interval_p99_ms')}  max {ms('interval_max_ms')}"
            + "  missed slots " + ("-" if missed is None else f"{100 * missed:.1f}%")
            + f"  input changes {stats['input_changes']}")


def cmd_io(args: argparse.Namespace) -> int:
    import signal

    from .devices.profiles import catalog_for_identity
    from .eip.io_originator import OtFormat
    from .eip.io_server import run_precise
    from .eip.originator import EncapsulationClient
    from .scanner import Scanner

    doc = None
    if args.eds is not None:
        if args.connection is None:
            raise UsageError("--eds needs --connection N (a ConnectionN of the file, by number or name)")
        if args.output is not None or args.input is not None or args.heartbeat is not None:
            raise UsageError("--eds takes the output, input and heartbeat from the file: give none of them")
        if args.config is not None:
            raise UsageError("--eds takes the configuration instance from the file: drop --config")
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
    if args.ot_format == OtFormat.HEARTBEAT.value and doc is None and args.heartbeat is None:
        raise UsageError("--ot-format heartbeat sends no data: give --heartbeat POINT instead of --output")
    if args.config is not None and not 0 <= args.config <= 0xFFFF:
        raise UsageError(f"--config {args.config} out of range 0..65535")
    # Without --rpi: the RPI the EDS proposes (None lets the scanner take it), else 10 ms.
    rpi: float | None = 0.010
    if args.rpi is not None:
        rpi = parse_rpi(args.rpi)
    elif doc is not None:
        rpi = None
    print_mode, print_every = parse_print(args.print)
    config_data = parse_config_data(args.config_data)
    assignments = [parse_assignment(a) for a in args.set or []]
    host, port = parse_host(args.target)

    async def session(loop: asyncio.AbstractEventLoop, stop: asyncio.Event, state: dict[str, bool]) -> int:
        probe = await EncapsulationClient.connect(host, port, args.timeout, register=False)
        try:
            identities = await probe.list_identity()
        finally:
            await probe.close()
        catalog = catalog_for_identity(identities[0]) if identities else None
        scanner = await Scanner.connect(args.target, timeout=args.timeout, catalog=catalog)
        options: dict[str, Any] = {"target_io_port": args.target_io_port, "local_io_port": args.io_port,
                                   "config_data": config_data}
        if args.ot_format is not None:
            options["ot_format"] = args.ot_format
        started = loop.time()
        if doc is not None:
            opened = scanner.io_connection_from_eds(doc, args.connection, rpi, **options)
        else:
            assert rpi is not None  # set above when no EDS is given
            opened = scanner.io_connection(output=args.output, input=args.input, rpi=rpi, heartbeat=args.heartbeat,
                                           config=1 if args.config is None else args.config, **options)
        latest: dict[str, Any] = {"image": None, "dirty": False}
        async with scanner, opened as io:
            state["opened"] = True
            for note in io.notes:
                print(f"cipstack io: {note}", file=sys.stderr, flush=True)
            for name, value in assignments:
                _set_output(io, name, value)
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
                    if print_mode == "changes":
                        show(image)
                    else:
                        latest["image"], latest["dirty"] = image, True

            async def ticker() -> None:
                while True:
                    await asyncio.sleep(print_every)
                    if latest["dirty"]:
                        latest["dirty"] = False
                        show(latest["image"])

            tasks = [asyncio.ensure_future(follow()), asyncio.ensure_future(stop.wait())]
            if print_mode == "every":
                tasks.append(asyncio.ensure_future(ticker()))
            try:
                done, _ = await asyncio.wait(tasks, timeout=args.duration, return_when=asyncio.FIRST_COMPLETED)
            finally:
                for task in tasks:
                    task.cancel()
                await asyncio.gather(*tasks, return_exceptions=True)
            if tasks[0] in done and not tasks[0].cancelled() and tasks[0].exception() is not None:
                raise tasks[0].exception()  # type: ignore[misc]
            if print_mode == "every" and latest["dirty"]:
                show(latest["image"])
            if print_mode == "summary" and io.connection.input:
                show(io.input)
            stats = io.statistics()
            outputs_set = bool(assignments) and any(io.output.raw) and not args.idle
        summary = {"summary": {"duration_s": round(loop.time() - started, 3), **stats}}
        if args.json:
            print(json.dumps(summary), flush=True)
        else:
            print(_statistics_text(stats), flush=True)
        if outputs_set and stats["received"] > 1 and stats["input_changes"] == 0:
            print("cipstack io: warning: the input never changed while outputs were set: the target may not be "
                  f"receiving them (is {args.target_io_port} its class 1 port? see --target-io-port)",
                  file=sys.stderr, flush=True)
        return 130 if state["interrupted"] else EXIT_OK

    async def guarded() -> int:
        loop = asyncio.get_running_loop()
        stop = asyncio.Event()
        state = {"opened": False, "interrupted": False}
        main_task = asyncio.current_task()

        def on_interrupt() -> None:
            # Ctrl-C: stop following, close the connection (Forward_Close), print the statistics.
            state["interrupted"] = True
            stop.set()
            with contextlib.suppress(NotImplementedError, RuntimeError, ValueError):
                loop.remove_signal_handler(signal.SIGINT)  # a second Ctrl-C stops at once
            if not state["opened"] and main_task is not None:
                main_task.cancel()  # still opening: give up (an open in flight is closed by the context)

        with contextlib.suppress(NotImplementedError, RuntimeError, ValueError):
            loop.add_signal_handler(signal.SIGINT, on_interrupt)
        try:
            return await session(loop, stop, state)
        except asyncio.CancelledError:
            if state["interrupted"]:
                print("cipstack io: interrupted", file=sys.stderr, flush=True)
                return 130
            raise
        finally:
            with contextlib.suppress(NotImplementedError, RuntimeError, ValueError):
                loop.remove_signal_handler(signal.SIGINT)

    return run_precise(guarded())


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
    from .control import ControlError, ControlRefused, control_request, default_control_path

    path = args.control or default_control_path(args.port, args.host)
    try:
        reply = control_request(path, request, args.timeout)
    except ControlRefused as exc:
        raise UsageError(str(exc)) from None    # the emulator named what is wrong with the argument
    except ControlError as exc:
        raise ConnectionError(str(exc)) from None   # no emulator there, no answer, or its state says no: exit 1
    reply.pop("ok", None)
    return reply


def _trip_code(text: str) -> int | str:
    try:
        return parse_int(text)
    except ValueError:
        return text.strip()


def cmd_drive_trip(args: argparse.Namespace) -> int:
    reply = _control(args, {"command": "trip", "code": args.code})
    _emit(args, reply, f"{reply['result']}" + (f"\n{reply['status']}" if reply.get("status") else ""))
    return EXIT_OK


def cmd_drive_status(args: argparse.Namespace) -> int:
    reply = _control(args, {"command": "status"})
    if args.json:
        # Fields, not the console line: the drive's state, then the emulator's sessions and connections.
        # A device without one drive (the CompoNet gateway) has its status lines instead.
        fields = reply.get("drive") or {"status": reply.get("status")}
        record = {**fields, "sessions": reply["sessions"],
                  "class3_connections": reply["class3_connections"], "class1_connections": reply["class1_connections"]}
        print(json.dumps(record), flush=True)
        return EXIT_OK
    print(f"{reply['status'] or '(no drive)'}  sessions {reply['sessions']}  class 3 "
          f"{reply['class3_connections']}  class 1 {reply['class1_connections']}", flush=True)
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
    parser.add_argument("--log-level", default="INFO", choices=levels, type=str.upper,
                        help="log level on stderr (default INFO)")
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
    p.add_argument("--port", type=lambda t: parse_number(t, "port"), default=DEFAULT_PORT,
                   help=f"EtherNet/IP port, TCP and UDP (default {DEFAULT_PORT})")
    device = p.add_mutually_exclusive_group()
    device.add_argument("--profile", help="device profile: acg (default), mx2, rx")
    device.add_argument("--eds", metavar="FILE",
                        help="emulate the generic device an EDS file describes (identity, parameters as "
                             "attributes, assemblies, connections)")
    p.add_argument("--model", help="model of the mx2/rx profiles (e.g. MX2-A2015-E, RX-A4055-E)")
    p.add_argument("--max-sessions", type=lambda t: parse_number(t, "max sessions"), default=32,
                   help="encapsulation sessions at once; one more is refused with 0x0002 (default 32)")
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
    p.add_argument("--param", action="append", metavar="CODE=VALUE",
                   help="set an ACG keypad parameter at start, in the keypad's unit; repeatable "
                        "(drv=4 Frq=8: run from the network)")
    p.add_argument("--quiet", action="store_true", help="no status line on stdout")
    p.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
    p.set_defaults(func=cmd_adapter)

    p = sub.add_parser("models", help="the MX2/RX models the mx2/rx profiles emulate (Tables 2/3)")
    p.add_argument("--profile", choices=["mx2", "rx"], help="one family only (default: both)")
    p.add_argument("--json", action="store_true", help="one JSON object per line")
    p.set_defaults(func=cmd_models)

    p = sub.add_parser("componet", help="run a CompoNet network of MX2/RX slaves behind an EtherNet/IP gateway")
    p.add_argument("--nodes", required=True, metavar="PROFILE:MODEL@NODE,...",
                   help="slaves, e.g. mx2:MX2-A2015-E@3,rx:RX-A4055-E@5 (node addresses 0-63)")
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    p.add_argument("--port", type=lambda t: parse_number(t, "port"), default=DEFAULT_PORT,
                   help=f"EtherNet/IP port, TCP and UDP (default {DEFAULT_PORT})")
    p.add_argument("--io-port", type=lambda t: parse_number(t, "io port"), default=2222,
                   help="UDP port of class 1 I/O (default 2222; 0 picks a free one)")
    p.add_argument("--control", type=Path, help="control socket (default: per port)")
    p.add_argument("--quiet", action="store_true", help="no status line on stdout")
    p.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
    p.set_defaults(func=cmd_componet)

    p = sub.add_parser("discover", help="ListIdentity over UDP")
    p.add_argument("--broadcast", metavar="ADDRESS",
                   help="broadcast or unicast address (default: 255.255.255.255 and every interface's broadcast "
                        "address, loopback's 127.255.255.255 included)")
    p.add_argument("--port", type=lambda t: parse_number(t, "port"), default=DEFAULT_PORT,
                   help=f"UDP port to ask (default {DEFAULT_PORT})")
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
    p.add_argument("--rpi", metavar="DURATION",
                   help="requested packet interval with its unit: 10ms, 500us, 0.5s (default: the EDS's with "
                        "--eds, else 10ms)")
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
    p.add_argument("--config", type=lambda t: parse_number(t, "config"), metavar="N",
                   help="configuration assembly instance of the connection path (default 1)")
    p.add_argument("--config-data", metavar="HEX", help="configuration data sent in the Forward_Open (hex bytes)")
    p.add_argument("--ot-format", choices=["run-idle", "heartbeat", "modeless"],
                   help="O->T real-time format: run-idle header (default), heartbeat (sequence count only, "
                        "size 2), modeless (no header); with --eds: the file's")
    p.add_argument("--print", default="changes", metavar="changes|summary|every:DURATION",
                   help="input lines: every change (default), none (statistics only), or the latest at most "
                        "once per DURATION (every:1s)")
    p.set_defaults(func=cmd_io)

    p = sub.add_parser("drive", help="control a running emulator: inject a trip, read its status")
    drive = p.add_subparsers(dest="drive_command", required=True, parser_class=_Parser)
    for name, func, text in (("trip", cmd_drive_trip, "trip the emulated drive with a fault code"),
                             ("status", cmd_drive_status, "the emulated drive's status line")):
        q = drive.add_parser(name, help=text)
        if name == "trip":
            q.add_argument("code", type=_trip_code,
                           help="fault code of the drive's manual (decimal or 0x hex: 0x4200 on the ACG, 5 on "
                                "the MX2/RX) or its name (OverHeat, E05)")
        q.add_argument("--host", default="127.0.0.1",
                       help="the emulator's address (its --host), which with --port finds its control socket "
                            "(default 127.0.0.1)")
        q.add_argument("--port", type=lambda t: parse_number(t, "port"), default=DEFAULT_PORT,
                       help=f"the emulator's EtherNet/IP port, which finds its control socket (default {DEFAULT_PORT})")
        q.add_argument("--control", type=Path, help="the emulator's control socket")
        q.add_argument("--timeout", type=parse_duration, default=5.0, help="reply timeout (default 5 s)")
        q.add_argument("--json", action="store_true", help="one JSON object per line")
        q.set_defaults(func=func)

    from .eds.commands import add_check_arguments, add_show_arguments
    from .eds.commands_generate import add_generate_arguments

    p = sub.add_parser("eds", help="EDS files: generate, check, show")
    eds = p.add_subparsers(dest="eds_command", required=True, parser_class=_Parser)
    q = eds.add_parser("check", help="check EDS files against the rules a configuration tool relies on")
    add_check_arguments(q)
    q.add_argument("--against", metavar="HOST[:PORT]", help="also compare [Device] with a live device's Identity")
    q.add_argument("--timeout", type=parse_duration, default=5.0, help="reply timeout with --against (default 5 s)")
    q.set_defaults(func=cmd_eds_check)
    q = eds.add_parser("generate", help="write the EDS files of emulated models")
    add_generate_arguments(q)
    q.set_defaults(func=cmd_eds_generate)
    q = eds.add_parser("show", help="a readable summary: identity, assemblies, connections")
    add_show_arguments(q)
    q.set_defaults(func=cmd_eds_show)

    from .capture.command import add_arguments as add_capture_arguments

    add_capture_arguments(sub)

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
    except EncapsulationError as exc:
        # A reply this side cannot read (the originator's decoders raise it): the peer's, one line.
        print(f"{name}: malformed reply from the target: {exc}", file=sys.stderr)
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
