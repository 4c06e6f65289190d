"""``cipstack capture analyze FILE``: what happened on the wire, in the device's own words."""

from __future__ import annotations

import argparse
import json
import sys
import time as clock
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, TextIO, runtime_checkable

from ..errors import BadRequest


@runtime_checkable
class DeclaringDevice(Protocol):
    """A device that lists the classes and assemblies it serves (the Omron inverters): what a capture
    of it is decoded by."""

    def catalog_classes(self) -> tuple[ClassSpec, ...]: ...

    def schemas(self) -> Mapping[int, AssemblySchema]: ...


if TYPE_CHECKING:  # the analysis modules load when the command runs, not when the parser is built
    from ..assemblies.schema import AssemblySchema
    from ..cip.model import ClassSpec
    from .analyzer import Connection
    from .decoding import Declarations

EXIT_OK, EXIT_FAILURE, EXIT_USAGE = 0, 1, 2
#: Explicit exchanges and anomalies kept for the human summary (all of them stream with --json).
KEEP = 200
ROUTINE = 5


def connection_id(text: str) -> int:
    try:
        return int(text, 0)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a connection number or id (decimal or 0x hex)") from None


def add_arguments(sub: Any) -> None:
    """Register ``capture analyze`` on the top-level subparsers (cli.build_parser, whose parsers give
    each command its help, description and examples)."""
    p = sub.add_parser("capture")
    capture = p.add_subparsers(dest="capture_command", metavar="COMMAND", title="commands", required=True,
                               parser_class=type(p))
    q = capture.add_parser("analyze")
    q.add_argument("file", type=Path, help="pcap or pcapng file").complete = {
        "bash": "_shtab_compgen_files", "zsh": "_files", "tcsh": "f"}
    q.add_argument("--profile", help="decode every target by this profile (acg, mx2, rx) instead of its identity")
    q.add_argument("--model", help="the model of an mx2/rx profile (see `cipstack models`)")
    q.add_argument("--eds", type=Path, action="append", default=[], metavar="FILE",
                   help="decode by this EDS file's parameters (by link path) and assemblies (repeatable)")
    q.add_argument("--json", action="store_true", help="one JSON object per line")
    q.add_argument("--csv", type=Path, metavar="DIR", help="write per-connection timing rows into DIR")
    q.add_argument("--plot", type=Path, metavar="FILE.png", help="plot inter-arrival times (needs cipstack[plot])")
    q.add_argument("--connection", type=connection_id, metavar="ID",
                   help="only this connection (its number in the summary, or its O->T or T->O id)")
    q.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    q.set_defaults(func=run)


class UsageProblem(BadRequest):
    pass


def fixed_declarations(profile: str | None, model: str | None, eds: list[Path]) -> Declarations | None:
    from .decoding import Declarations

    if model and not profile:
        raise UsageProblem("--model needs --profile")
    if profile and eds:
        raise UsageProblem("give --profile or --eds, not both")
    if profile:
        from ..catalog import Catalog
        from ..devices.profiles import PROFILES, ProfileOptions, build_device, check_model

        if profile not in PROFILES:
            raise UsageProblem(f"unknown profile {profile!r} (known: {', '.join(sorted(PROFILES))})")
        chosen = PROFILES[profile]
        try:
            check_model(chosen, model)
        except BadRequest as exc:
            raise UsageProblem(str(exc)) from None
        if model is None and chosen.catalog is not None:
            return Declarations(chosen.catalog(), source=f"profile {profile}")
        try:
            device = build_device(profile, options=ProfileOptions(model=model))
        except (KeyError, ValueError) as exc:
            raise UsageProblem(str(exc.args[0]) if exc.args else str(exc)) from None
        if not isinstance(device, DeclaringDevice):
            raise UsageProblem(f"profile {profile} declares no classes to decode by")
        return Declarations(Catalog(device.catalog_classes(), device.schemas().values()),
                            source=f"profile {profile} {model}")
    if eds:
        from ..eds.interpret import read_view
        from ..eds.reader import read_eds

        out = Declarations(source="EDS " + ", ".join(p.name for p in eds))
        for path in eds:
            try:
                view = read_view(read_eds(path))
            except OSError as exc:
                raise UsageProblem(f"{path}: {exc.strerror or exc}") from None
            except ValueError as exc:
                raise UsageProblem(f"{path}: {exc}") from None
            for param in view.params.values():
                if param.link is not None:
                    # The first parameter of a link names the attribute, as ``adapter --eds`` serves the first:
                    # a later one is an assembly member's name for the same value ("Faulted" for "Drive Fault").
                    out.eds_params.setdefault(param.link, param)
            for info in view.assemblies.values():
                schema = view.schema(info.instance) if info.instance is not None else None
                if info.instance is not None and schema is not None:
                    out.eds_schemas[info.instance] = schema
        return out
    return None


def declarations_for_identity(identity: dict[str, Any]) -> Declarations:
    from ..devices.profiles import catalog_for, profile_for
    from .decoding import Declarations

    device_type = identity.get("device_type")
    profile = profile_for(identity["vendor_id"], identity["product_code"], device_type)
    catalog = catalog_for(identity["vendor_id"], identity["product_code"], device_type)
    return Declarations(catalog, source=f"profile {profile.name}" if profile else "standard objects")


class Progress:
    """A one-line bar on stderr, redrawn at most 5 times a second."""

    def __init__(self, total: int, stream: TextIO) -> None:
        self.total = max(1, total)
        self.stream = stream
        self.next_draw = 0.0

    def update(self, done: int, frames: int) -> None:
        now = clock.monotonic()
        if now < self.next_draw:
            return
        self.next_draw = now + 0.2
        share = min(1.0, done / self.total)
        bar = "#" * int(share * 30)
        self.stream.write(f"\r[{bar:<30}] {share * 100:5.1f} % {frames} frames")
        self.stream.flush()

    def close(self) -> None:
        self.stream.write("\r" + " " * 60 + "\r")
        self.stream.flush()


def run(args: argparse.Namespace) -> int:
    from .analyzer import Analyzer
    from .reader import CaptureFormatError, read_records

    name = "cipstack capture analyze"
    try:
        fixed = fixed_declarations(args.profile, args.model, args.eds)
    except UsageProblem as exc:
        print(f"{name}: {exc}", file=sys.stderr)
        return EXIT_USAGE
    if args.plot is not None:
        try:
            import matplotlib  # noqa: F401
        except ImportError:
            print(f'{name}: --plot needs matplotlib: pip install "cipstack[plot]"', file=sys.stderr)
            return EXIT_USAGE
    try:
        stream = args.file.open("rb")
    except OSError as exc:
        print(f"{name}: {args.file}: {exc.strerror or exc}", file=sys.stderr)
        return EXIT_FAILURE
    explicit: list[dict[str, Any]] = []
    routine: list[dict[str, Any]] = []
    anomalies: list[dict[str, Any]] = []
    connections: list[Connection] = []
    out = sys.stdout

    def sink(record: dict[str, Any]) -> None:
        kind = record["type"]
        if kind == "connection":
            connection = record.pop("_connection")
            connections.append(connection)
        elif kind == "explicit":
            # The summary lists the first few exchanges and the notable ones: errors, unanswered
            # requests, replies without a request, routed requests.
            notable = any(k in record for k in ("error", "unanswered", "unmatched_reply")) or (
                "route" in record.get("request", {}))
            if notable and len(explicit) < KEEP:
                explicit.append(record)
            elif not notable and len(routine) < ROUTINE:
                routine.append(record)
        elif kind == "anomaly" and len(anomalies) < KEEP:
            anomalies.append(record)
        if args.json:
            if args.connection is not None and kind != "connection":
                return
            out.write(json.dumps(record, default=_jsonable) + "\n")

    analyzer = Analyzer(sink, fixed, args.connection, declarations_for_identity)
    size = args.file.stat().st_size
    progress = Progress(size, sys.stderr) if sys.stderr.isatty() and not args.no_progress else None
    try:
        with stream:
            for number, record in enumerate(read_records(stream), 1):
                analyzer.feed(record.time, number, record.linktype, record.data)
                if progress is not None and not number & 0x3FF:
                    progress.update(stream.tell(), number)
    except CaptureFormatError as exc:
        if progress is not None:
            progress.close()
        print(f"{name}: {args.file}: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    if progress is not None:
        progress.close()
    totals = analyzer.finish()
    connections.sort(key=lambda c: c.number)
    if args.json:
        out.write(json.dumps({"type": "summary", "file": str(args.file), **_totals(totals)}) + "\n")
    else:
        from .report import summary_text

        sources = {t: analyzer._declarations(t).source for t in analyzer.identities}
        shown = sorted(explicit + routine, key=lambda r: r.get("time", r.get("reply_time", 0.0)))
        print(summary_text(args.file.name, totals, analyzer.identities,
                           [] if args.connection is not None else shown, anomalies, connections, sources))
    if args.csv is not None:
        from .report import write_csv

        write_csv(args.csv, connections)
    if args.plot is not None:
        from .report import write_plot

        write_plot(args.plot, connections, totals.first_time or 0.0)
    return EXIT_OK


def _totals(totals: Any) -> dict[str, Any]:
    return {k: getattr(totals, k) for k in ("frames", "enip_frames", "explicit", "errors", "unanswered",
                                            "io_frames", "anomalies", "connections", "first_time", "last_time",
                                            "services")}


def _jsonable(value: Any) -> Any:
    if isinstance(value, bytes):
        return value.hex()
    return str(value)
