"""cipstack eds: check, generate, show."""

from __future__ import annotations

import argparse
from typing import Any


# -- EDS ----------------------------------------------------------------------------------------------------
def cmd_eds_check(args: argparse.Namespace) -> int:
    from ..eds.commands import run_check

    if not args.against:
        return run_check(args)
    import asyncio

    from ..eds.against import compare_with_device
    from ..eds.commands import EXIT_UNREADABLE, load_quietly
    from ..scanner import Scanner

    async def compare() -> dict[str, Any]:
        reports = {}
        async with await Scanner.connect(args.against, timeout=args.timeout) as scanner:
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


def cmd_eds_generate(args: argparse.Namespace) -> int:
    from ..eds.commands_generate import run_generate

    return run_generate(args)


def cmd_eds_show(args: argparse.Namespace) -> int:
    from ..eds.commands import run_show

    return run_show(args)
