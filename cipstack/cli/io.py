"""The class 1 command: cipstack io."""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import sys
from typing import Any

from ..cip.types import BOOL, parse_int
from ..eip.originator.asyncio_client import parse_host
from ..errors import BadRequest
from .common import EXIT_OK, UsageError, parse_duration
from .emulators import _read_eds_file


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


#: ``--print``'s modes and what each prints: its help and ``parse_print`` both say these.
PRINT_MODES = {
    "changes": "every change of the input",
    "summary": "the statistics and the last input only",
    "every:DURATION": "the latest input at most once per DURATION (every:1s)",
}


def parse_print(text: str) -> tuple[str, float]:
    """One of ``PRINT_MODES``: ``changes``, ``summary``, ``every:DURATION`` (also ``every=DURATION``
    or ``"every DURATION"``)."""
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
    raise UsageError(f"--print {text!r} is not one of {', '.join(PRINT_MODES)} (e.g. every:1s)")


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
    """One ``--set``; an unknown field names the valid ones, or says that ``raw=HEX`` is the only way."""
    try:
        if name == "raw":
            try:
                data = bytes.fromhex(value)
            except ValueError:
                size = len(io.output.raw)
                raise BadRequest(f"not hex: raw takes the {size} bytes in hex (e.g. {'00' * size})") from None
            io.output.raw = data
        elif not io.output.field_names:
            raise UsageError(f"--set {name}={value}: {_unnamed(io.output.schema, len(io.output.raw))}: give "
                             f"raw=HEX ({len(io.output.raw)} bytes, e.g. raw={'00' * len(io.output.raw)})")
        else:
            schema = io.output.schema
            flag = schema is not None and name in schema.field_names and schema.field(name).bits == 1
            # A flag takes true/false/on/off/1/0, as a BOOL attribute does (`cipstack set`).
            setattr(io.output, name, BOOL.parse_text(value) if flag else parse_int(value))
    except AttributeError as exc:
        raise UsageError(f"--set {name}={value}: {exc}; or raw=HEX") from None
    except ValueError as exc:
        raise UsageError(f"--set {name}={value}: {exc}") from None


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
            + "  within +-0.5 API " + ("-" if stats.get("within_half_api_pct") is None
                                       else f"{stats['within_half_api_pct']:.1f}%")
            + "  missed slots " + ("-" if missed is None else f"{100 * missed:.1f}%")
            + f"  input changes {stats['input_changes']}")


def _unnamed(schema: Any, size: int) -> str:
    """Why an assembly's data has no field names: no declaration, or one that names no member."""
    if schema is None:
        return "no field names are known for this assembly"
    return f"assembly {schema.instance} {schema.name!r} ({size} bytes) declares no field names"


def image_values(image: Any) -> dict[str, Any]:
    """What a printed input shows: every field by name, or ``raw`` (hex) when no field names the data."""
    if not image.field_names:
        return {"raw": image.raw.hex()}
    values: dict[str, Any] = image.fields()
    return values


def _field_lines(direction: str, schema: Any, instance: int | None) -> list[str]:
    """One line per field of an assembly: name, offset, width or type, and the unit of a raw value
    (what ``--set`` takes: ``[0.01 Hz]`` for a frequency word, from the field's declaration). An
    assembly without field names says that ``raw=HEX`` is the way: to write it, and in what is printed."""
    how = "write it with --set raw=HEX" if direction.startswith("output") else "printed as raw=HEX"
    if schema is None:
        what = "no data (heartbeat)" if instance is None else f"assembly {instance}: no field names known ({how})"
        return [f"{direction}: {what}"]
    lines = [f"{direction}: assembly {schema.instance} {schema.name!r}, {schema.size} bytes"]
    if not schema.fields:
        return [f"{lines[0]}: no field names ({how})"]
    for item in schema.fields:
        place = f"byte {item.offset} bit {item.bit}" + (f"-{item.bit + item.bits - 1}" if item.bits > 1 else "") \
            if item.bits else f"byte {item.offset} {item.type.name}"
        unit = f" [{item.count_unit}]" if item.count_unit else ""
        lines.append(f"  {item.name:<28} {place}{unit}")
    return lines


def _list_fields(args: argparse.Namespace, view: Any, names_from: Any = None) -> int:
    """``--list-fields``: the output and input fields of the connection, by the names ``--set`` and the
    printed input take; from the EDS alone (``view``, the file read), or from the profile of the device's
    identity."""
    if names_from is not None:
        output = None if args.heartbeat is not None else args.output
        schemas = (names_from.schema(output) if output is not None else None, names_from.schema(args.input))
        points = (output, args.input)
    elif view is not None:
        connection = view.connection(args.connection)
        output = None if connection.heartbeat else connection.o_t_point
        schemas = (view.schema(output) if output is not None else None, view.schema(connection.t_o_point))
        points = (output, connection.t_o_point)
    else:
        from ..scanner import Scanner

        async def identify() -> Any:
            scanner = await Scanner.connect(args.target, timeout=args.timeout)  # identifies the device
            await scanner.close()
            return scanner.catalog

        catalog = asyncio.run(identify())
        output = None if args.heartbeat is not None else args.output
        assemblies = catalog.assemblies
        schemas = (assemblies.get(output) if output is not None else None, assemblies.get(args.input))
        points = (output, args.input)
    for direction, schema, point in zip(("output (O->T)", "input (T->O)"), schemas, points, strict=True):
        print("\n".join(_field_lines(direction, schema, point)), flush=True)
    return EXIT_OK


@contextlib.asynccontextmanager
async def _explained(opened: Any, args: argparse.Namespace) -> Any:
    """The connection; a refusal that needs another connection first says which."""
    from ..cip.status import CipError, ExtendedStatus

    try:
        handle = await opened.__aenter__()
    except CipError as exc:
        if exc.extended[:1] == (ExtendedStatus.NON_LISTEN_ONLY_NOT_OPENED,):
            raise CipError(exc.general, exc.extended, message=(
                f"{exc.message + ': ' if exc.message else ''}a listen-only connection receives the multicast of a "
                "connection that already produces its input: an owner (exclusive owner or input only, opened with "
                "--multicast) must produce first")) from None
        raise
    try:
        yield handle
    except BaseException:
        if not await opened.__aexit__(*sys.exc_info()):
            raise
    else:
        await opened.__aexit__(None, None, None)


def cmd_io(args: argparse.Namespace) -> int:
    import signal

    from ..eip.io_server import freeze_startup_objects, run_precise
    from ..eip.originator.class1 import OtFormat
    from ..scanner import Scanner

    doc = view = None
    names_from = None   # --eds FILE --output N --input M: the file gives the field names only
    if args.eds is not None and args.connection is None and args.input is not None:
        from ..eds.interpret import read_view

        names_from = read_view(_read_eds_file(args.eds))
    elif args.eds is not None:
        if args.connection is None:
            raise UsageError("--eds needs --connection N (a ConnectionN of the file, by number or name), or "
                             "--output N --input M to take only the field names from the file")
        if args.output is not None or args.input is not None or args.heartbeat is not None:
            raise UsageError("--eds takes the output, input and heartbeat from the file: give none of them")
        if args.config is not None:
            raise UsageError("--eds takes the configuration instance from the file: drop --config")
        doc = _read_eds_file(args.eds)
        from ..eds.interpret import read_view

        view = read_view(doc)
        try:
            view.connection(args.connection)
        except KeyError as exc:
            raise UsageError(f"{args.eds}: {exc.args[0]}") from None
    elif args.connection is not None:
        raise UsageError("--connection needs --eds FILE")
    elif args.input is None:
        raise UsageError("give --input (or --eds FILE --connection N)")
    if args.list_fields:
        return _list_fields(args, view, names_from)
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
    security = None
    if args.security is not None:
        from ..eip.wire.encapsulation import SECURE_PORT
        from ..security import Credentials

        security = Credentials.load(args.security)
        host, port = parse_host(args.target, SECURE_PORT)
    else:
        host, port = parse_host(args.target)

    async def session(loop: asyncio.AbstractEventLoop, stop: asyncio.Event, state: dict[str, bool]) -> int:
        # Identifies the device and takes its profile's declarations, or those of the EDS file given.
        scanner = await Scanner.connect(f"{host}:{port}", timeout=args.timeout, eds=doc, security=security)
        options: dict[str, Any] = {"target_io_port": args.target_io_port, "local_io_port": args.io_port,
                                   "config_data": config_data}
        if args.ot_format is not None:
            options["ot_format"] = args.ot_format
        if args.timeout_multiplier is not None:
            options["timeout_multiplier"] = args.timeout_multiplier
        if args.multicast:
            options["multicast"] = True
        started = loop.time()
        if doc is not None:
            opened = scanner.io_connection_from_eds(doc, args.connection, rpi, **options)
        else:
            assert rpi is not None  # set above when no EDS is given
            schemas: dict[str, Any] = {}
            if names_from is not None:
                output = None if args.heartbeat is not None else args.output
                schemas = {"output_schema": names_from.schema(output) if output is not None else None,
                           "input_schema": names_from.schema(args.input)}
            opened = scanner.io_connection(output=args.output, input=args.input, rpi=rpi, heartbeat=args.heartbeat,
                                           config=1 if args.config is None else args.config, **schemas, **options)
        latest: dict[str, Any] = {"image": None, "dirty": False}
        async with scanner, _explained(opened, args) as io:
            state["opened"] = True
            for note in io.notes:
                print(f"cipstack io: {note}", file=sys.stderr, flush=True)
            if io.multicast_group is not None:
                print(f"cipstack io: T->O multicast from {io.multicast_group}", file=sys.stderr, flush=True)
            for name, value in assignments:
                _set_output(io, name, value)
            io.set_run(not args.idle)
            # Set-up is done: a full collection must not stall the receive path for longer than a short RPI.
            freeze_startup_objects()

            def show(image: Any) -> None:
                elapsed = round(loop.time() - started, 4)
                values = image_values(image)
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
            failure = tasks[0].exception() if tasks[0] in done and not tasks[0].cancelled() else None
            if failure is not None:
                raise failure
            if print_mode == "every" and latest["dirty"]:
                show(latest["image"])
            if print_mode == "summary" and io.connection.input:
                show(io.input)
            stats = io.statistics()
            # A T->O of no data (a heartbeat: an owner that only writes) has no input to change.
            outputs_set = bool(assignments) and any(io.output.raw) and not args.idle and bool(io.input.raw)
        summary = {"summary": {"duration_s": round(loop.time() - started, 3), **stats}}
        if args.json:
            print(json.dumps(summary), flush=True)
        else:
            print(_statistics_text(stats), flush=True)
        if outputs_set and stats["received"] > 1 and stats["input_changes"] == 0:
            print("cipstack io: warning: the input never changed while outputs were set: the target may not be "
                  f"receiving them (is {io.connection.target_io_port} its class 1 port? see --target-io-port)",
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
