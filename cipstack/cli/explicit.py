"""Explicit messaging commands: discover, identity, get, set."""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING, Any

from ..cip.status import CipError
from ..cip.types import parse_int
from ..eip.originator.core import parse_host
from .common import (
    EXIT_FAILURE,
    EXIT_OK,
    UsageError,
    _emit,
    parse_number,
    parse_object_path,
    parse_type,
)

if TYPE_CHECKING:
    import argparse


# -- discovery -----------------------------------------------------------------------------------
def _identity_text(record: Any) -> str:
    address = f"{record.address.host}:{record.address.port}" if record.address else "?"
    return (f"{address}  {record.product_name!r}  vendor {record.vendor_id}  device type {record.device_type}  "
            f"product code {record.product_code}  revision {record.revision[0]}.{record.revision[1]}  "
            f"serial 0x{record.serial_number:08X}  status 0x{record.status:04X}  state {record.state}")


def cmd_discover(args: argparse.Namespace) -> int:
    import asyncio

    from ..eip.originator.discovery import discover
    from ..eip.wire.encapsulation import DEFAULT_PORT

    if args.security is not None:
        return _discover_secured(args)
    records = asyncio.run(discover(args.broadcast, DEFAULT_PORT if args.port is None else args.port, args.timeout))
    for record in records:
        _emit(args, record.as_dict(), _identity_text(record))
    if not records and not args.json:
        print("no device answered", file=sys.stderr)
    return EXIT_OK


def secured_hosts(text: str | None) -> list[str]:
    """The hosts ``discover --security`` asks (``--broadcast HOST[:PORT][,HOST[:PORT]...]``). A DTLS session has one
    peer: a broadcast (none given, the limited one, an interface's directed one) or a multicast
    address cannot be secured, and is refused in one line rather than sent in the clear."""
    import ipaddress

    from ..eip.originator.discovery_core import broadcast_addresses

    if not text:
        raise UsageError("--security asks each device over DTLS, one session each, and a broadcast cannot be "
                         "secured: give the devices with --broadcast HOST[:PORT][,...]")
    hosts = [host.strip() for host in text.split(",")]
    broadcasts = set(broadcast_addresses())
    for item in hosts:
        if not item:
            raise UsageError(f"--broadcast {text!r}: an empty host")
        host = item.rpartition(":")[0] or item
        try:
            address = ipaddress.ip_address(host)
        except ValueError:
            continue   # a name: resolved when its session opens
        # A directed broadcast of a network this host is not on cannot be told from a host's
        # address here: the system refuses to send to it without SO_BROADCAST (one line too).
        if host in broadcasts or address.is_multicast or address.is_unspecified:
            raise UsageError(f"--broadcast {host}: a DTLS session has one peer, and {host} is no one device's "
                             "address (a broadcast, multicast or unspecified one): with --security give each "
                             "device's own address")
    return hosts


def _discover_secured(args: argparse.Namespace) -> int:
    """ListIdentity in a DTLS session with each host of ``--broadcast`` (UDP 2221 unless ``--port``),
    at once: UDP as plain discovery, secured. A host that refuses the session or does not answer is
    one line on stderr naming the cause, and the exit status 1."""
    import asyncio

    from ..eip.originator.asyncio_client import EncapsulationClient
    from ..eip.wire.encapsulation import SECURE_PORT
    from ..errors import CipstackError

    hosts = secured_hosts(args.broadcast)
    security = credentials(args)
    port = SECURE_PORT if args.port is None else args.port

    async def ask(item: str) -> list[Any]:
        host, at = parse_host(item, port)
        client = await EncapsulationClient.connect(host, at, args.timeout, register=False, security=security,
                                                   datagrams=True)
        try:
            return await client.list_identity()
        finally:
            await client.close()

    async def ask_all() -> list[Any]:
        return await asyncio.gather(*(ask(host) for host in hosts), return_exceptions=True)

    status = EXIT_OK
    for host, answer in zip(hosts, asyncio.run(ask_all()), strict=True):
        if isinstance(answer, CipstackError):
            print(f"cipstack discover: {answer}", file=sys.stderr, flush=True)
            status = EXIT_FAILURE
        elif isinstance(answer, BaseException):
            raise answer
        elif not answer:
            print(f"cipstack discover: {host} answered ListIdentity with no identity", file=sys.stderr,
                  flush=True)
            status = EXIT_FAILURE
        else:
            for record in answer:
                _emit(args, record.as_dict(), _identity_text(record))
    return status


def credentials(args: argparse.Namespace) -> Any:
    """CIP Security's credentials of ``--security DIR`` (``Credentials.load``), or None without it: the
    requests then go over TLS, to port 2221 unless the target names one. Loaded only when asked for:
    a plain one-shot imports neither TLS nor X.509."""
    folder = getattr(args, "security", None)
    if folder is None:
        return None
    from ..security import Credentials

    return Credentials.load(folder)


def cmd_identity(args: argparse.Namespace) -> int:
    from ..eip.originator.blocking import BlockingEncapsulationClient
    from ..eip.wire.encapsulation import DEFAULT_PORT, SECURE_PORT

    security = credentials(args)
    host, port = parse_host(args.target, DEFAULT_PORT if security is None else SECURE_PORT)
    with BlockingEncapsulationClient.connect(host, port, args.timeout, register=False, security=security) as client:
        records = client.perform(client.core.list_identity())
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
    if isinstance(value, (dict, list)):
        import json

        return json.dumps(value)
    return str(value)


def parse_route(text: str | None) -> list[Any] | None:
    """``PORT/LINK[,PORT/LINK...]``: ``1/0`` (backplane slot 0), ``2/3`` (CompoNet node 3), ``2/10.0.0.5``."""
    from ..cip.epath import PortSegment

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


def eds_document(args: argparse.Namespace) -> Any:
    """The EDS file ``--eds`` names, read (None without ``--eds``)."""
    eds = getattr(args, "eds", None)
    if eds is None:
        return None
    from .emulators import _read_eds_file

    return _read_eds_file(eds)


#: CIP Security, EtherNet/IP Security, Certificate Management (``cipstack.security.declarations``).
SECURITY_CLASS_IDS = frozenset({0x5D, 0x5E, 0x5F})


def _connect_identified(args: argparse.Namespace, standard: tuple[int, int, int] | None = None) -> Any:
    """A blocking scanner that decodes by the declarations of the device's profile when it is one we
    know (the routed device's own Identity when ``--route`` is given). ``standard``: the (class,
    attribute) asked for, which when a standard class declares it decodes by that declaration
    alone, as every profile's does: no identity is asked, and no profile loaded."""
    from ..catalog import Catalog, compact_standard_classes
    from ..scanner import SyncScanner

    eds = getattr(args, "eds", None)
    doc = eds_document(args)
    # Without an EDS file, the standard objects' compact declarations: a one-shot command does not
    # import the objects that serve them. CIP Security's objects decode by their own declarations,
    # loaded only when one of their classes is asked for.
    standard_specs = compact_standard_classes()
    if standard is not None and standard[0] in SECURITY_CLASS_IDS:
        from ..security.declarations import SECURITY_CLASSES

        standard_specs = {**standard_specs, **SECURITY_CLASSES}
    scanner = SyncScanner(args.target, timeout=args.timeout, route=parse_route(args.route), identify=False, eds=doc,
                          catalog=None if doc is not None else Catalog(standard=standard_specs),
                          security=credentials(args))
    if doc is not None:
        scanner.catalog.source = f"EDS file {eds}"
        return scanner
    if standard is not None and standard[0] in standard_specs and scanner.catalog.attribute(*standard):
        return scanner
    try:
        # The library's own identification: the profile's compact declarations, no device model.
        scanner.identify()
    except BaseException:
        scanner.close()
        raise
    return scanner


def _is_code(text: str) -> bool:
    """A parameter's code (``ACC``, ``CM.24``, ``A004``, ``Param4``), not a path: paths begin with a number."""
    return text.strip()[:1].isalpha()


def _by_code(args: argparse.Namespace, value: str | None) -> int:
    """``get|set HOST CODE [VALUE]``: a parameter by the code its manual prints, its value in its unit
    (``cipstack.parameter_codes``), over the scanner identified as for a path."""
    from ..parameter_codes import find_parameter

    if args.type is not None:
        raise UsageError(f"--type: {args.path} is a parameter's code, whose type is its declaration")

    from ..scanner import SyncScanner

    doc = eds_document(args)
    # By code: the profile's compact declarations know its parameters' codes and ranges.
    with SyncScanner(args.target, timeout=args.timeout, route=parse_route(args.route), identify=doc is None,
                     eds=doc, security=credentials(args)) as scanner:
        if args.connected:
            scanner.open_connection()
        try:
            parameter = find_parameter(scanner.catalog, args.path)
            reading = scanner.read(*parameter.path) if value is None else \
                scanner.set_parameter(parameter.code, value)
        except (KeyError, ValueError) as exc:
            raise UsageError(str(exc)) from None
    path = f"0x{parameter.class_id:02X}/{parameter.instance}/{parameter.attribute}"
    record = {"status": 0, "code": parameter.code, "name": parameter.spec.name, "path": path, **reading.json()}
    text = f"{parameter.code} {parameter.spec.name} = {_reading_text(reading)}"
    _emit(args, record, text if value is None else f"set {text}")
    return EXIT_OK


def cmd_get(args: argparse.Namespace) -> int:
    if _is_code(args.path):
        return _by_code(args, None)
    class_id, instance, attribute = parse_object_path(args.path)
    cip_type = parse_type(args.type)
    with _connect_identified(args, None if attribute is None else (class_id, instance, attribute)) as scanner:
        if args.connected:
            scanner.open_connection()
        if attribute is None:
            data, values = scanner.get_attributes_all(class_id, instance)
            record: dict[str, Any] = {"status": 0, "data": data.hex()}
            if values is not None:
                record["value"] = {json_key(name): _jsonable(v) for name, v in values.items()}
            text = ""
            worded = False
        else:
            result = scanner.get_attribute_single(class_id, instance, attribute, cip_type)
            record = {"status": 0, "data": result.data.hex()}
            reading = result.reading
            if result.known:
                record.update(reading.json())
                record["type"] = result.type.name if result.type else None
            if result.spec is not None:
                record["name"] = result.spec.name
            text = _reading_text(reading)
            worded = isinstance(reading.raw, tuple)   # a type that words its value (CIP Security's lists)
    record["path"] = args.path
    if args.json:
        import json  # only for --json: a one-shot that prints text does without

        print(json.dumps(record), flush=True)
    elif "value" in record:
        name = f"{record['name']} = " if "name" in record else ""
        value = record["value"]
        print(f"{name}{text}" if worded or not isinstance(value, dict)
              else "\n".join(_member_text(k, v) for k, v in value.items()), flush=True)
    else:
        print(bytes.fromhex(record["data"]).hex(" ") or "(no data)", flush=True)
    return EXIT_OK


def _reading_text(reading: Any) -> str:
    """``5.0 s (50)``: the engineering value and unit, then the raw value when a scale makes them differ;
    a string quoted, as Python writes it."""
    if isinstance(reading.raw, str):
        return repr(reading.raw)
    text = getattr(reading.type, "text", None)
    if isinstance(reading.raw, tuple) and callable(text):   # a list or record type that words itself
        return str(text(reading.raw))
    return f"{reading} ({reading.raw})" if reading.scaled else str(reading)


def json_key(name: str) -> str:
    """An attribute's name as a JSON key, as every JSON record of the command spells fields: "Serial Number"
    -> "serial_number" (so ``get HOST 1/1 --json`` and ``identity --json`` give one Identity shape)."""
    return "_".join("".join(c if c.isalnum() else " " for c in name.lower()).split())


def _member_text(name: str, value: Any) -> str:
    """One ``name = value`` line of Get_Attributes_All; the bytes after the declared attributes as hex."""
    from ..scanner import UNDECODED

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
    """Set_Attribute_Single. The value is raw (as on the wire) unless ``--scaled`` (the engineering value,
    5.0 for 5.0 s); its type is the attribute's declaration, else ``--type``."""
    if _is_code(args.path):
        return _by_code(args, args.value)
    class_id, instance, attribute = parse_object_path(args.path, need_attribute=True)
    assert attribute is not None
    given_type = parse_type(args.type)
    if given_type is not None and not args.scaled:
        _parse_value(args, given_type, None)  # a bad value is refused before connecting

    with _connect_identified(args, (class_id, instance, attribute)) as scanner:
        spec = scanner.catalog.attribute(class_id, instance, attribute)
        cip_type = given_type or (spec.type if spec is not None else None)
        if cip_type is None:
            raise UsageError(f"{args.path} is not declared in {scanner.catalog.source}: give --type (UINT, INT, "
                             "REAL, ...)" + (" or --eds FILE" if getattr(args, "eds", None) is None else ""))
        raw = _parse_value(args, cip_type, spec)
        data = cip_type.encode(raw)
        if args.connected:
            scanner.open_connection()
        scanner.set_attribute_single(class_id, instance, attribute, data)
    from ..cip.values import Scaling, Value

    reading = Value(cip_type.decode(data), spec.name if spec is not None else "", cip_type,
                    spec.scaling if spec is not None else Scaling())
    name = f" {spec.name}" if spec is not None else ""
    _emit(args, {"status": 0, "path": args.path, "data": data.hex(), **reading.json()},
          f"set {args.path}{name} = {_reading_text(reading)}")
    return EXIT_OK


def _parse_value(args: argparse.Namespace, cip_type: Any, spec: Any) -> Any:
    """The raw value of ``args.value``: as ``cip_type`` reads text (BOOL: true/false/on/off/1/0), or with
    ``--scaled`` an engineering value turned into raw steps by the declaration."""
    try:
        if getattr(args, "scaled", False):
            if spec is None:
                raise UsageError(f"--scaled: {args.path} has no declared scale (give the raw value)")
            value = spec.scaling.to_raw(float(args.value))
        else:
            if spec is not None and spec.scaling.scaled:
                _refuse_engineering_value(args, spec)
            value = cip_type.parse_text(args.value)
        if spec is not None and args.type is None:
            _refuse_out_of_range(args, spec, value)
        cip_type.encode(value)
        return value
    except (ValueError, CipError, TypeError) as exc:
        raise UsageError(f"value {args.value!r} is not a valid {cip_type.name}: {exc}") from None


def _refuse_out_of_range(args: argparse.Namespace, spec: Any, raw: Any) -> None:
    """A value outside the attribute's declared range is refused before it is sent, in the attribute's
    unit (``AttributeSpec.out_of_range``, the check a write by code makes), with the raw bounds where the
    value was given raw; ``--type`` sends it anyway (the declaration set aside)."""
    refusal = spec.out_of_range(raw, f"{args.path} ({spec.name})")
    if refusal is None:
        return
    if spec.scaling.scaled and not getattr(args, "scaled", False):
        low, high = spec.minimum, spec.maximum
        if low is not None and high is not None:
            refusal += f" (raw {low}..{high})"
    raise UsageError(f"{refusal}; --type {spec.type.name} sends {args.value} anyway")


def _refuse_engineering_value(args: argparse.Namespace, spec: Any) -> None:
    """A value with a fraction for an attribute counted in steps (2.5 for Accel Time, 0.1 s per step)
    is an engineering value given without ``--scaled``: say so, as the library's ``write`` does."""
    try:
        engineering = float(args.value)
    except ValueError:
        return
    if engineering.is_integer() and "." not in args.value:
        return  # a raw count, as the rule says
    scaling = spec.scaling
    what = f"{args.path} {spec.name} takes a raw integer ({scaling.scale:g} {spec.unit} per step)"
    try:
        raw = scaling.to_raw(engineering)
    except ValueError as exc:
        raise UsageError(f"{what}, and {exc}") from None
    raise UsageError(f"{what}: give {args.value} with --scaled, or the raw value {raw}")
