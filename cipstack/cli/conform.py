"""``cipstack conform``: the conformance battery against a target, with its reports."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..eip.originator.asyncio_client import parse_host
from .common import EXIT_FAILURE, EXIT_OK, EXIT_USAGE, UsageError


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("target", metavar="HOST[:PORT]", help="target address (default port 44818)")
    p.add_argument("--eds", metavar="FILE", help="the target's EDS file: enables group eds and the connection "
                                                  "checks of groups cm and class1")
    p.add_argument("--eds-dir", metavar="DIR", help="without --eds: a directory of EDS files, the one matching the "
                                                     "device's vendor, product code and revision is used")
    p.add_argument("--connection-points", metavar="O,T[,C]",
                   help="the class 1 connection points to test: output (O->T), input (T->O) and configuration "
                        "instance (default 1), instead of finding them")
    p.add_argument("--only", metavar="GROUP,...",
                   help="run these groups only: encap, router, objects, cm, class1, eds, profile, security (final "
                        "runs after any that opens a connection or writes)")
    p.add_argument("--allow-writes", action="store_true",
                   help="also run checks that write (a set of a read-only attribute)")
    p.add_argument("--allow-reset", action="store_true", help="also reset the device (Identity Reset type 0)")
    p.add_argument("--allow-motion", action="store_true",
                   help="also run the AC drive profile's motion checks: they RUN THE MOTOR (forward at a low "
                        "speed reference, stop, fault reset, NetCtrl/NetRef, idle); the drive is stopped and its "
                        "sources restored at the end")
    p.add_argument("--allow-stress", action="store_true",
                   help="also run the checks that exhaust the device's resources on purpose (encap.session_limit "
                        "opens 40 TCP connections and sessions at once): a device with fewer may stop or crash")
    p.add_argument("--security", metavar="DIR", type=Path,
                   help="CIP Security: the folder of `cipstack security init` whose CA the device trusts; enables "
                        "group security (the security objects, the configuration session, the TLS and DTLS ports, "
                        "and the pre-shared key of its psk.txt)")
    p.add_argument("--security-port", type=int, default=2221, metavar="N",
                   help="the device's TLS port (TCP) and DTLS port (UDP) for group security (default %(default)s)")
    p.add_argument("--strict", action="store_true",
                   help="warnings are failures: in the exit status and the JUnit report")
    p.add_argument("--json", action="store_true", help="the report as one JSON object on stdout")
    p.add_argument("--junit", metavar="FILE", type=Path, help="also write the report as JUnit XML")
    p.add_argument("--html", metavar="FILE", type=Path, help="also write the report as one self-contained HTML page")
    p.add_argument("--timeout", type=_duration, default=5.0, metavar="DURATION",
                   help="reply timeout: 2, 500ms, 1.5s (default %(default)s s)")
    p.set_defaults(func=cmd_conform)


def _duration(text: str) -> float:
    from .common import parse_duration

    value = parse_duration(text)
    if value <= 0:
        raise UsageError(f"timeout {text!r} must be positive")
    return value


def cmd_conform(args: argparse.Namespace) -> int:
    from ..conformance import TargetUnreachable, Verdict, parse_groups, run
    from ..conformance.report import to_html, to_json, to_junit, to_text

    host, port = parse_host(args.target)
    try:
        groups = parse_groups(args.only)
    except ValueError as exc:
        raise UsageError(f"--only: {exc}") from None
    if args.eds is not None and not Path(args.eds).is_file():
        raise UsageError(f"--eds: no such file: {args.eds}")
    if args.security is not None and not args.security.is_dir():
        raise UsageError(f"--security: no such folder: {args.security}")
    if not 0 < args.security_port < 65536:
        raise UsageError(f"--security-port {args.security_port} out of range")
    if args.eds_dir is not None and not Path(args.eds_dir).is_dir():
        raise UsageError(f"--eds-dir: no such directory: {args.eds_dir}")
    points = None
    if args.connection_points is not None:
        from ..conformance.discovery import parse_points

        try:
            points = parse_points(args.connection_points)
        except ValueError as exc:
            raise UsageError(f"--connection-points {exc}") from None
    eds = None
    if args.eds is not None:
        from ..eds.reader import EdsSyntaxError, read_eds

        try:
            eds = read_eds(args.eds)
        except (EdsSyntaxError, OSError, UnicodeError) as exc:
            raise UsageError(f"--eds {args.eds}: {exc}") from None
    try:
        report = run(host, port, eds=eds, groups=groups, allow_writes=args.allow_writes,
                     allow_reset=args.allow_reset, timeout=args.timeout, connection_points=points,
                     eds_dir=args.eds_dir, allow_motion=args.allow_motion,
                     allow_stress=args.allow_stress, security=args.security, security_port=args.security_port)
    except TargetUnreachable as exc:
        print(f"cipstack conform: {exc}", file=sys.stderr)
        return EXIT_USAGE
    if args.eds is not None:
        report.options["eds"] = args.eds
    report.options["strict"] = args.strict
    if args.junit is not None:
        args.junit.write_text(to_junit(report, strict=args.strict), encoding="utf-8")
    if args.html is not None:
        args.html.write_text(to_html(report), encoding="utf-8")
    print(to_json(report) if args.json else to_text(report), flush=True)
    warned = args.strict and any(o.verdict is Verdict.WARNING for o in report)
    return EXIT_OK if report.passed and not warned else EXIT_FAILURE
