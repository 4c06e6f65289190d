"""cipstack eds: check, generate, show."""

from __future__ import annotations

import argparse
from typing import Any


# -- EDS ----------------------------------------------------------------------------------------------------
def cmd_eds_check(args: argparse.Namespace) -> int:
    from ..eds.commands import run_check

    if not args.against:
        if args.security is not None:
            from .common import UsageError

            raise UsageError("--security goes with --against HOST: the check of a file alone reads no device")
        return run_check(args)
    import asyncio

    from ..eds.against import compare_with_device
    from ..eds.commands import EXIT_UNREADABLE, load_quietly
    from ..scanner import Scanner
    from .explicit import credentials

    security = credentials(args)

    async def compare() -> dict[str, Any]:
        reports = {}
        async with await Scanner.connect(args.against, timeout=args.timeout, security=security) as scanner:
            for path in args.files:
                doc = load_quietly(path)
                if doc is not None:
                    reports[path] = await compare_with_device(doc, scanner, target_io_port=args.target_io_port,
                                                              connections=not args.no_connections)
        return reports

    reports = asyncio.run(compare())
    status = run_check(args, live={path: report.findings for path, report in reports.items()},
                       identities={path: report.identity for path, report in reports.items()},
                       live_summaries={path: report.summary(args.against) for path, report in reports.items()})
    return status if status != EXIT_UNREADABLE or reports else EXIT_UNREADABLE


def cmd_eds_fetch(args: argparse.Namespace) -> int:
    """Read the device's own EDS file from its File object (class 0x37, instance 0xC8)."""
    import sys
    from pathlib import Path

    from ..objects.file import CLASS_ID, EDS_INSTANCE, FileTransferError, read_file
    from ..scanner import SyncScanner
    from .common import EXIT_FAILURE, EXIT_OK
    from .explicit import credentials

    with SyncScanner(args.host, timeout=args.timeout, identify=False, security=credentials(args)) as scanner:
        def request(service: int, data: bytes) -> tuple[int, bytes]:
            reply = scanner.request(service, CLASS_ID, EDS_INSTANCE, data=data, check=False)
            return int(reply.general_status), bytes(reply.data)

        try:
            content = read_file(request)
        except FileTransferError as exc:
            print(f"cipstack eds fetch: {args.host} serves no EDS file through its File object (class 0x37, "
                  f"instance 0xC8): {exc}", file=sys.stderr)
            return EXIT_FAILURE
    if args.output == "-":
        sys.stdout.buffer.write(content)
        sys.stdout.flush()
    else:
        Path(args.output).write_bytes(content)
        print(f"{args.output}: {len(content)} bytes", flush=True)
    return EXIT_OK


def cmd_eds_generate(args: argparse.Namespace) -> int:
    from ..eds.commands_generate import run_generate

    return run_generate(args)


def cmd_eds_show(args: argparse.Namespace) -> int:
    from ..eds.commands import run_show

    return run_show(args)
