"""Parameter recipes: cipstack params dump / load / diff (the library's ``cipstack.params``)."""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
from typing import Any

from .common import EXIT_FAILURE, EXIT_OK, UsageError
from .explicit import credentials, eds_document, parse_route


async def _scanner(args: argparse.Namespace) -> Any:
    """An asyncio scanner with the whole catalog of the device's profile (its parameters), or the
    EDS file's (``--eds``)."""
    from ..scanner import Scanner

    doc = eds_document(args)
    scanner = await Scanner.connect(args.target, timeout=args.timeout, route=parse_route(getattr(args, "route", None)),
                                    eds=doc, security=credentials(args))
    if doc is not None:
        scanner.catalog.source = f"EDS file {args.eds}"
    if not scanner.catalog.parameters:
        await scanner.close()
        raise UsageError(f"no parameters are declared in {scanner.catalog.source}: give --eds FILE")
    return scanner


def _recipe(path: str) -> list[Any]:
    from ..params import read_recipe

    try:
        return read_recipe(path)
    except OSError as exc:
        raise UsageError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except ValueError as exc:
        raise UsageError(f"{path}: {exc}") from None


def cmd_params_dump(args: argparse.Namespace) -> int:
    from ..params import device_record, dump_params, recipe_text

    async def run() -> tuple[list[Any], dict[str, Any]]:
        scanner = await _scanner(args)
        try:
            return await dump_params(scanner), device_record(scanner)
        finally:
            await scanner.close()

    values, device = asyncio.run(run())
    text = recipe_text(values, device)
    if args.output is None or args.output == "-":
        sys.stdout.write(text)
    else:
        try:
            with open(args.output, "w", encoding="utf-8") as out:
                out.write(text)
        except OSError as exc:
            raise UsageError(f"{args.output}: cannot write: {exc.strerror or exc}") from None
        print(f"{len(values)} parameters written to {args.output}", file=sys.stderr, flush=True)
    return EXIT_OK


def cmd_params_load(args: argparse.Namespace) -> int:
    from ..params import DriveRunningError, load_params

    recipe = _recipe(args.file)

    async def run() -> Any:
        scanner = await _scanner(args)
        try:
            return await load_params(scanner, recipe, force=args.force, save=not args.no_save)
        finally:
            await scanner.close()

    try:
        report = asyncio.run(run())
    except DriveRunningError as exc:
        print(f"cipstack params: {exc} (--force)", file=sys.stderr, flush=True)
        return EXIT_FAILURE
    for item in report.written:
        _line(args, {"written": item.path_text, "code": item.code, "raw": item.raw},
              f"set {item.code or item.path_text} {item.name} = {item.text()}")
    for item, why in report.refused:
        print(f"cipstack params: {item.code or item.path_text} {item.name} = {item.text()} refused: {why}",
              file=sys.stderr, flush=True)
    for item, why in report.skipped:
        print(f"cipstack params: {item.code or item.path_text} {item.name} skipped: {why}", file=sys.stderr,
              flush=True)
    summary = (f"{len(report.written)} written, {report.unchanged} unchanged, {len(report.refused)} refused"
               + (", saved" if report.saved else ""))
    _line(args, {"written": len(report.written), "unchanged": report.unchanged, "refused": len(report.refused),
                 "saved": report.saved}, summary)
    return EXIT_FAILURE if report.refused else EXIT_OK


def cmd_params_diff(args: argparse.Namespace) -> int:
    from ..params import diff_params

    recipe = _recipe(args.file)

    async def run() -> list[Any]:
        scanner = await _scanner(args)
        try:
            return await diff_params(scanner, recipe)
        finally:
            await scanner.close()

    differences = asyncio.run(run())
    for item in differences:
        _line(args, {"path": item.recipe.path_text, "code": item.recipe.code, "file": item.recipe.raw,
                     "device": None if item.device is None else item.device.raw}, item.text())
    if not differences and not args.json:
        print(f"no differences ({len(recipe)} parameters)", flush=True)
    return EXIT_FAILURE if differences else EXIT_OK


def _line(args: argparse.Namespace, record: dict[str, Any], text: str) -> None:
    print(json.dumps(record) if args.json else text, flush=True)


def add_arguments(sub: Any, parser_class: Any, common: Any) -> None:
    """``params`` and its subcommands; ``common(parser, secured=True)`` adds the target, ``--timeout``,
    ``--json`` and ``--security``."""
    p = sub.add_parser("params", help="drive parameter recipes: dump, load, diff (TOML files)")
    commands = p.add_subparsers(dest="params_command", required=True, parser_class=parser_class)
    q = commands.add_parser("dump", help="write every declared parameter (code, name, raw and engineering "
                                         "value, unit) to a TOML file")
    common(q, secured=True)
    q.add_argument("-o", "--output", metavar="FILE", help="the recipe file (default: standard output)")
    q.set_defaults(func=cmd_params_dump)
    q = commands.add_parser("load", help="write a recipe's settable parameters that differ, in a safe order, "
                                         "and save them where the device has a save command")
    common(q, secured=True)
    q.add_argument("file", metavar="FILE")
    q.add_argument("--force", action="store_true", help="load even while the drive runs")
    q.add_argument("--no-save", action="store_true", help="write without saving (lost at the next power cycle)")
    q.set_defaults(func=cmd_params_load)
    q = commands.add_parser("diff", help="the recipe's parameters whose value on the device differs "
                                         "(exit status 1 when any does)")
    common(q, secured=True)
    q.add_argument("file", metavar="FILE")
    q.set_defaults(func=cmd_params_diff)
    for q in (commands.choices["dump"], commands.choices["load"], commands.choices["diff"]):
        q.add_argument("--eds", metavar="FILE", help="take the parameters from this EDS file")
        q.add_argument("--route", metavar="PORT/LINK[,...]", help="route through the target (Unconnected_Send)")
