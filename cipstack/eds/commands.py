"""The ``cipstack eds check`` and ``cipstack eds show`` commands.

Each command is a pair of functions, one that adds its arguments to an argparse parser and
one that runs it and returns the exit status, so the ``cipstack`` command can mount them.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, TextIO

from .model import EdsDocument, Entry, FieldKind, Section, format_epath
from .reader import EdsSyntaxError, read_eds

if TYPE_CHECKING:
    from .checker import Finding

EXIT_OK = 0
EXIT_FINDINGS = 1
EXIT_UNREADABLE = 2


def add_check_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("files", nargs="+", metavar="FILE", help="EDS files to check")
    parser.add_argument("--json", action="store_true",
                        help="one JSON object per file (its findings and counts), one per line, then the summary")
    parser.add_argument("--strict", action="store_true", help="warnings fail the check too (exit 1)")


def add_show_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", metavar="FILE", help="EDS file to summarize")
    parser.add_argument("--json", action="store_true", help="the summary as one JSON object")


def _load(path: str, command: str, stderr: TextIO) -> EdsDocument | None:
    """The document, or None after one line on stderr saying why it cannot be had."""
    try:
        return read_eds(path)
    except EdsSyntaxError as exc:
        print(f"{path}:{exc.line}: syntax error: {exc.message}", file=stderr)
    except OSError as exc:
        print(f"cipstack eds {command}: {path}: cannot read: {exc.strerror or exc}", file=stderr)
    return None


def load_quietly(path: str) -> EdsDocument | None:
    """The document, or None when it cannot be read (``run_check`` says why, once)."""
    try:
        return read_eds(path)
    except (EdsSyntaxError, OSError):
        return None


def run_check(
    args: argparse.Namespace,
    identity: Mapping[str, Any] | None = None,
    stdout: TextIO | None = None,
    stderr: TextIO | None = None,
    live: Mapping[str, list[Finding]] | None = None,
    identities: Mapping[str, Mapping[str, Any] | None] | None = None,
    live_summaries: Mapping[str, str] | None = None,
) -> int:
    """Check every file, print its findings and one summary line; 0 when none has an error (with
    ``--strict``: nor a warning), 1 when one has, 2 when one cannot be read. ``identity`` is a
    live device's Identity (see :func:`check_eds`) the files must match; ``live`` holds, per file,
    what was found comparing it with the device (``eds check --against``)."""
    # The checker is loaded by the command that checks (the parser takes this module for every command).
    from .checker import ERROR, INFO, WARNING, check_eds

    stdout = stdout or sys.stdout
    stderr = stderr or sys.stderr
    strict = bool(getattr(args, "strict", False))
    as_json = bool(getattr(args, "json", False))
    status = EXIT_OK
    totals = {ERROR: 0, WARNING: 0, INFO: 0, "unreadable": 0}
    for path in args.files:
        doc = _load(path, "check", stderr)
        if doc is None:
            status = EXIT_UNREADABLE
            totals["unreadable"] += 1
            if as_json:
                print(json.dumps({"file": path, "readable": False, "errors": 0, "warnings": 0, "notes": 0,
                                  "findings": []}, sort_keys=True), file=stdout)
            continue
        findings = check_eds(doc, identities.get(path) if identities is not None else identity)
        if live is not None:
            findings = sorted([*findings, *live.get(path, [])], key=lambda finding: finding.line)
        counts = {severity: sum(f.severity == severity for f in findings) for severity in (ERROR, WARNING, INFO)}
        for severity, count in counts.items():
            totals[severity] += count
        against = (live_summaries or {}).get(path)
        if as_json:
            record = {"file": path, "readable": True, "errors": counts[ERROR], "warnings": counts[WARNING],
                      "notes": counts[INFO], "findings": [f.to_dict() for f in findings]}
            if against is not None:
                record["against"] = against
            print(json.dumps(record, sort_keys=True), file=stdout)
        else:
            if against is not None:
                print(f"{path}: {against}", file=stdout)
            for finding in findings:
                print(_format_finding(path, finding), file=stdout)
        failing = counts[ERROR] or (strict and counts[WARNING])
        if status == EXIT_OK and failing:
            status = EXIT_FINDINGS
    summary = summary_line(len(args.files), totals[ERROR], totals[WARNING], totals[INFO], totals["unreadable"])
    if as_json:
        print(json.dumps({"summary": {"files": len(args.files), "errors": totals[ERROR],
                                      "warnings": totals[WARNING], "notes": totals[INFO],
                                      "unreadable": totals["unreadable"], "strict": strict}},
                         sort_keys=True), file=stdout)
    else:
        print(summary, file=stdout)
    return status


def _plural(count: int, word: str) -> str:
    return f"{count} {word}" + ("" if count == 1 else "s")


def summary_line(files: int, errors: int, warnings: int, notes: int = 0, unreadable: int = 0) -> str:
    """``56 files: 0 errors, 3 warnings`` (notes and unreadable files added when there are any)."""
    parts = [_plural(errors, "error"), _plural(warnings, "warning")]
    if notes:
        parts.append(_plural(notes, "note"))
    if unreadable:
        parts.append(f"{unreadable} unreadable")
    return f"{_plural(files, 'file')}: {', '.join(parts)}"


def _format_finding(path: str, finding: Finding) -> str:
    return f"{path}:{finding.line}: {finding.severity} {finding.rule}: {finding.message}"


def run_show(args: argparse.Namespace, stdout: TextIO | None = None, stderr: TextIO | None = None) -> int:
    """Print what a file describes: identity, assemblies and their members, connections."""
    stdout = stdout or sys.stdout
    stderr = stderr or sys.stderr
    doc = _load(args.file, "show", stderr)
    if doc is None:
        return EXIT_UNREADABLE
    for line, what in doc.reader_notes:   # read, but not as the specification writes it
        print(f"{args.file}:{line}: warning: {what}", file=stderr)
    summary = summarize(doc)
    if args.json:
        print(json.dumps(summary, indent=2, sort_keys=True), file=stdout)
    else:
        print(render_summary(summary), file=stdout)
    return EXIT_OK


# -- the summary ------------------------------------------------------------------------------

_DEVICE_KEYS = {
    "VendCode": "vendor_id", "VendName": "vendor_name", "ProdType": "device_type", "ProdTypeStr": "device_type_name",
    "ProdCode": "product_code", "ProdName": "product_name", "Catalog": "catalog",
}
_APPLICATION_TYPES = ((24, "listen only"), (25, "input only"), (26, "exclusive owner"), (27, "redundant owner"))
_TRIGGERS = ((16, "cyclic"), (17, "change of state"), (18, "application triggered"))
_CONNECTION_TYPES = {1: "null", 2: "multicast", 4: "point-to-point"}
_REAL_TIME = {0: "modeless", 1: "zero length data", 3: "heartbeat", 4: "run/idle header"}


def _plain(value: Any, kind: FieldKind) -> Any:
    """A field value as JSON holds it."""
    if kind is FieldKind.EPATH:
        return format_epath(value)
    if kind is FieldKind.REVISION:
        return "{}.{}".format(*value)
    if kind in (FieldKind.DATE, FieldKind.TIME, FieldKind.DATASET):
        return str(value)
    return value


def _value(entry: Entry | None, number: int = 1) -> Any:
    item = None if entry is None else entry.field(number)
    return None if item is None else _plain(item.value, item.kind)


_ASSEMBLY = re.compile(r"Assem(?:Exa)?[0-9]+")
_CONNECTION = re.compile(r"Connection[0-9]+")


def summarize(doc: EdsDocument) -> dict[str, Any]:
    """Identity, assemblies and connections of a document, as plain data."""
    device = doc.get("Device")
    identity: dict[str, Any] = {}
    if device is not None:
        identity = {name: _value(device.get(keyword)) for keyword, name in _DEVICE_KEYS.items()}
        major, minor = _value(device.get("MajRev")), _value(device.get("MinRev"))
        identity["revision"] = None if major is None or minor is None else f"{major}.{minor}"
    classification = doc.get("Device Classification")
    networks = [_value(entry) for entry in classification] if classification else []
    params = doc.get("Params")
    assembly_section = doc.get("Assembly")
    # Only AssemN entries are assemblies; the section also holds the Assembly class's keywords
    # (Revision, Object_Name, Number_Of_Static_Instances, ...).
    assembly_entries = [entry for entry in assembly_section if _ASSEMBLY.fullmatch(entry.keyword)] \
        if assembly_section else []
    # Sizes as the emulator reads them: a ParamN's default, the members' sum (AssemExaN, modular).
    from .interpret import assembly_sizes, read_view

    view = read_view(doc)
    sizes: dict[str, Any] = {entry.keyword: _value(entry, 3) for entry in assembly_entries}
    sizes.update(assembly_sizes(doc))
    # An assembly of empty size sized by its connections, as the emulator sizes it.
    sizes.update({keyword: info.size for keyword, info in view.assemblies.items() if sizes.get(keyword) is None})
    assemblies = [_assembly(entry, params, sizes) for entry in assembly_entries]
    manager = doc.get("Connection Manager")
    connections = [_connection(entry, sizes, params) for entry in manager
                   if _CONNECTION.fullmatch(entry.keyword)] if manager else []
    # The sizes the emulator offers (a size parameter that defaults to 0 at its smallest non-zero size).
    read = {f"Connection{c.number}": c for c in view.connections}
    for connection in connections:
        found = read.get(connection["keyword"])
        if found is not None:
            connection["o_to_t"]["size"] = 0 if found.heartbeat else found.o_t_size
            connection["t_to_o"]["size"] = found.t_o_size
    return {"identity": identity, "networks": networks, "assemblies": assemblies, "connections": connections}


def _assembly(entry: Entry, params: Section | None, sizes: Mapping[str, Any]) -> dict[str, Any]:
    members = []
    for size_item, member in zip(entry.fields[6::2], entry.fields[7::2], strict=False):
        reference = member.value if member.kind is FieldKind.KEYWORD else None
        bits = size_item.value if size_item.kind is FieldKind.INT else None
        if bits is None and reference is not None and isinstance(sizes.get(reference), int):
            bits = sizes[reference] * 8   # an assembly member (its own: the instance's whole data)
        name = None
        if reference is not None and params is not None and (param := params.get(reference)) is not None:
            name = _value(param, 7)
            data_size = param.field(6)
            if bits is None and data_size is not None and data_size.kind is FieldKind.INT:
                bits = data_size.value * 8
        members.append({"bits": bits, "reference": reference, "name": name})
    return {
        "keyword": entry.keyword,
        "name": _value(entry, 1),
        "path": _value(entry, 2),
        "size": sizes.get(entry.keyword, _value(entry, 3)),
        "members": members,
    }


def _connection_size(entry: Entry, size_number: int, format_number: int, sizes: dict[str, Any],
                     params: Section | None) -> Any:
    """A connection's size as the file determines it: the number given; else the default of the
    ParamN the size field names; else the size of the AssemN the format field names."""
    size = _value(entry, size_number)
    if isinstance(size, int):
        return size
    if isinstance(size, str) and params is not None and (param := params.get(size)) is not None:
        default = _value(param, 12)
        if isinstance(default, int):
            return default
    assembly = _value(entry, format_number)
    known = sizes.get(assembly) if isinstance(assembly, str) else None
    return known if isinstance(known, int) else size


def _connection(entry: Entry, sizes: dict[str, Any], params: Section | None) -> dict[str, Any]:
    trigger, parameters = _value(entry, 1), _value(entry, 2)
    description: dict[str, Any] = {
        "keyword": entry.keyword,
        "name": _value(entry, 13),
        "path": _value(entry, 15),
        "o_to_t": {"rpi": _value(entry, 3), "size": _connection_size(entry, 4, 5, sizes, params),
                   "assembly": _value(entry, 5)},
        "t_to_o": {"rpi": _value(entry, 6), "size": _connection_size(entry, 7, 8, sizes, params),
                   "assembly": _value(entry, 8)},
    }
    if isinstance(trigger, int):
        description["types"] = [name for bit, name in _APPLICATION_TYPES if trigger >> bit & 1]
        description["triggers"] = [name for bit, name in _TRIGGERS if trigger >> bit & 1]
        description["transport_classes"] = [bit for bit in range(16) if trigger >> bit & 1]
    if isinstance(parameters, int):
        for key, shift_type, shift_format in (("o_to_t", 16, 8), ("t_to_o", 20, 12)):
            kinds = [name for bit, name in _CONNECTION_TYPES.items() if parameters >> shift_type & bit]
            description[key]["connection_types"] = kinds
            real_time = parameters >> shift_format & 0x7
            description[key]["format"] = _REAL_TIME.get(real_time, f"real-time format {real_time}")
    return description


def render_summary(summary: dict[str, Any]) -> str:
    lines: list[str] = []
    identity = summary["identity"]
    if identity:
        catalog = f" ({identity['catalog']})" if identity.get("catalog") else ""   # Catalog is optional
        lines.append(f"Device: {identity['product_name']}{catalog}, revision {identity['revision']}")
        lines.append(f"  vendor {identity['vendor_id']} {identity['vendor_name']}")
        lines.append(f"  device type {identity['device_type']} {identity['device_type_name']}")
        lines.append(f"  product code {identity['product_code']}")
    if summary["networks"]:
        lines.append(f"Network: {', '.join(str(network) for network in summary['networks'])}")
    if summary["assemblies"]:
        lines.append("Assemblies:")
    for assembly in summary["assemblies"]:
        lines.append(
            f"  {assembly['keyword']} {assembly['name']!r}: {assembly['size']} bytes, "
            f"path {assembly['path'] or '(none: the connection paths name it)'}"
        )
        for member in assembly["members"]:
            bits = "?" if member["bits"] is None else member["bits"]
            what = member["reference"] or "(padding)"
            name = f" {member['name']!r}" if member["name"] else ""
            lines.append(f"    {bits:>4} bits  {what}{name}")
    if summary["connections"]:
        lines.append("Connections:")
    for connection in summary["connections"]:
        kinds = ", ".join(connection.get("types", [])) or "unspecified"
        lines.append(f"  {connection['keyword']} {connection['name']!r} ({kinds}), path {connection['path']}")
        for key, label in (("o_to_t", "O->T"), ("t_to_o", "T->O")):
            part = connection[key]
            size = "?" if part["size"] is None else part["size"]
            details = [f"{size} bytes"]
            if part["assembly"]:
                details.append(str(part["assembly"]))
            if part.get("connection_types"):
                details.append("/".join(part["connection_types"]))
            if "format" in part:
                details.append(part["format"])
            if part["rpi"] is not None:
                details.append(f"RPI {part['rpi']}")
            lines.append(f"    {label}: {', '.join(details)}")
    return "\n".join(lines)
