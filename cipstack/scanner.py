"""The scanner library: typed explicit messaging and class 1, by role.

``ExplicitMessaging`` is what a scanner asks and how it reads the replies, as plans; ``SyncScanner``
(here) runs them on the blocking client, with class 1 on a plain UDP socket and no event loop;
``Scanner`` (``async_scanner``, named here too) runs them on the asyncio client. Values decode by
the attribute's declaration when the catalog knows it (standard objects, device profiles), or by an
explicit type; otherwise the raw bytes are returned. Every error status raises ``CipError`` naming
the general and extended status.
"""

from __future__ import annotations

import contextlib
import struct
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple, TypeVar

from .catalog import Catalog, compact_standard_classes
from .cip.epath import PortSegment, Segment, request_path
from .cip.messages import MessageRouterRequest, MessageRouterResponse, Service
from .cip.model import AttributeSpec
from .cip.status import CipError, ExtendedStatus, GeneralStatus
from .cip.types import UINT, CipType, IntegerType
from .cip.values import Value
from .eip.originator.blocking import BlockingEncapsulationClient, SecureChannel
from .eip.originator.core import (
    OriginatorCore,
    Plan,
    decode_multiple_service,
    encode_multiple_service,
    one,
    parse_host,
)
from .eip.originator.replies import EncapsulationStatusError, MalformedReplyError
from .eip.wire.encapsulation import DEFAULT_PORT, SECURE_PORT
from .errors import BadRequest, NotFound, ProtocolError
from .logs import debug

if TYPE_CHECKING:
    # Imported where used: explicit messaging alone does not load asyncio, the EDS model or class 1.
    from .assemblies.schema import AssemblySchema
    from .async_scanner import Scanner
    from .eds.model import EdsDocument
    from .eip.originator.blocking_io import SyncIoConnection
    from .eip.originator.class1 import OtFormat
    from .eip.originator.process_image import ProcessImage
    from .eip.wire.identity_items import IdentityRecord, ServiceRecord

T = TypeVar("T")

#: Key of the bytes of a Get_Attributes_All reply after the attributes the catalog declares.
UNDECODED = "(undecoded)"


class AttributeValue(NamedTuple):
    """A read attribute: its raw bytes, and its value when the type is known (``reading`` gives it
    with its unit and scale)."""

    class_id: int
    instance: int
    attribute: int
    data: bytes
    value: Any = None
    spec: AttributeSpec | None = None
    type: CipType | None = None

    @property
    def known(self) -> bool:
        return self.type is not None

    def json_value(self) -> Any:
        if self.type is None:
            return None
        return self.type.to_json(self.value)

    @property
    def reading(self) -> Value:
        """The value with its declaration: raw, engineering value and unit (the bytes when unknown)."""
        if self.type is None:
            return Value(self.data, self.spec.name if self.spec is not None else "")
        if self.spec is None:
            return Value(self.value, "", self.type)
        return Value(self.value, self.spec.name, self.type, self.spec.scaling)


class UnknownAttributeError(NotFound, TypeError):
    """An attribute nothing declares where its type or scale is needed: the message names the
    catalog looked in (``Catalog.source``) and what to give instead."""


class ReplyDecodeError(ProtocolError, ValueError):
    """A successful reply whose data is not the type asked for: a mismatch on this side (the device
    answered status 0), so not a ``CipError``."""


class _Unsplittable(CipError):
    """A list reply the scanner cannot split for want of a declaration (not the device's fault)."""

    def __init__(self, message: str) -> None:
        super().__init__(GeneralStatus.INVALID_REPLY_RECEIVED, message=message)


@contextlib.contextmanager
def _malformed(what: str) -> Iterator[None]:
    """A reply body that does not parse is a ``MalformedReplyError`` (one line), not a device status."""
    try:
        yield
    except _Unsplittable:
        raise
    except (CipError, ValueError, struct.error, IndexError) as exc:
        raise MalformedReplyError(f"malformed {what}: {exc}") from None


class ExplicitMessaging:
    """What a scanner asks a device and how it reads the replies, without I/O: each method is a
    ``Plan`` (it yields the core's transactions and is sent their results) that ``Scanner`` runs on
    its asyncio client and ``SyncScanner`` on its blocking one, so both behave alike by construction.
    It holds the declarations replies decode by (``catalog``), the ``route`` and the ``identity``."""

    def __init__(self, core: OriginatorCore, catalog: Catalog | None = None,
                 route: Sequence[Segment] | None = None) -> None:
        self.core = core
        # The standard objects' compact declarations (what decoding takes of them) until identified.
        self.catalog = catalog or Catalog(standard=compact_standard_classes())
        self.route = route
        self.identity: IdentityRecord | None = None

    def choose_catalog(self, catalog: Catalog | None, eds: str | Path | EdsDocument | None,
                       identify: bool) -> Plan[None]:
        if catalog is not None:
            return
        if eds is not None:
            from .eds.catalog import catalog_from_eds

            self.catalog = catalog_from_eds(eds)
        elif identify:
            yield from self.identify()

    def identify(self, catalogs: Callable[[int, int, int | None], Catalog] | None = None
                 ) -> Plan[IdentityRecord | None]:
        """``catalogs``: the catalog of (vendor id, product code, device type); by default the profile's,
        built from its compact declarations for cipstack's own families (``profile_catalog.decoding_catalog``:
        no device model is imported), from its declaration for a family another distribution brings."""
        if catalogs is None:
            from .profile_catalog import decoding_catalog

            catalogs = decoding_catalog

        record = None
        if not self.route:
            try:
                records = yield self.core.list_identity()
            except (EncapsulationStatusError, MalformedReplyError, TimeoutError) as exc:
                debug(__name__, "ListIdentity over TCP: %s; reading the Identity object instead", exc)
                records = []
            record = records[0] if records else None
        if record is None:
            record = yield from self._identity_attributes()
        self.identity = record
        if record is None:
            self.catalog = Catalog(source="the standard objects only: the device did not identify itself (no "
                                          "ListIdentity reply, no Identity attributes 1 and 3); give eds= or catalog=",
                                   standard=compact_standard_classes())
        else:
            # Device type 0 where the Identity attributes did not give it (``_identity_attributes``): unknown.
            self.catalog = catalogs(record.vendor_id, record.product_code, record.device_type or None)
        return record

    def _identity_attributes(self) -> Plan[IdentityRecord | None]:
        """Identity attributes 1-4 and 7 (only vendor and product code are needed)."""
        from .eip.wire.identity_items import IdentityRecord

        spec = compact_standard_classes()[0x01]   # the Identity object's declarations, as data
        values: dict[int, Any] = {}
        for attribute in (1, 3, 2, 4, 7):
            declared = spec.instance_attribute(attribute)
            try:
                reply = yield from self.request(Service.GET_ATTRIBUTE_SINGLE, 0x01, 1, attribute)
                values[attribute] = declared.type.decode(reply.data) if declared is not None else None
            except (CipError, ValueError, struct.error, MalformedReplyError) as exc:
                if attribute in (1, 3):
                    debug(__name__, "Identity attribute %d: %s", attribute, exc)
                    return None
        revision = values.get(4) or {}
        return IdentityRecord(values[1], values.get(2) or 0, values[3],
                              (revision.get("major", 0), revision.get("minor", 0)), 0, 0, values.get(7) or "")

    # -- generic ----------------------------------------------------------------------------------
    def request(self, service: int, class_id: int, instance: int | None = None, attribute: int | None = None,
                data: bytes = b"", *, check: bool = True) -> Plan[MessageRouterResponse]:
        path = request_path(class_id, instance, attribute)
        reply: MessageRouterResponse = yield self.core.request(service, path, data, route=self.route)
        if (self.route is not None and self.core.connection is None and reply.service == Service.UNCONNECTED_SEND
                and service != reply.service):
            # The Connection Manager could not route the request: its error is the answer.
            reply.raise_for_status()
        if reply.service != service & 0x7F:
            raise CipError(GeneralStatus.INVALID_REPLY_RECEIVED, message=f"reply to service 0x{reply.service:02X}")
        return reply.raise_for_status() if check else reply

    def open_connection(self, rpi: float, large: bool, connection_size: int) -> Plan[None]:
        yield self.core.forward_open(int(rpi * 1e6), connection_size, large, route=list(self.route or ()))

    def close_connection(self) -> Plan[None]:
        closing = self.core.forward_close()
        if closing is not None:
            yield closing

    # -- attributes -------------------------------------------------------------------------------
    def _type_for(self, class_id: int, instance: int, attribute: int, cip_type: CipType | None
                  ) -> tuple[CipType | None, AttributeSpec | None]:
        spec = self.catalog.attribute(class_id, instance, attribute)
        return (cip_type or (spec.type if spec is not None else None)), spec

    def get_attribute_single(self, class_id: int, instance: int, attribute: int,
                             cip_type: CipType | None = None) -> Plan[AttributeValue]:
        data, value, value_type, spec = yield from self._get_single(class_id, instance, attribute, cip_type)
        return AttributeValue(class_id, instance, attribute, data, value, spec, value_type)

    def _get_single(self, class_id: int, instance: int, attribute: int, cip_type: CipType | None
                    ) -> Plan[tuple[bytes, Any, CipType | None, AttributeSpec | None]]:
        reply = yield from self.request(Service.GET_ATTRIBUTE_SINGLE, class_id, instance, attribute)
        value_type, spec = self._type_for(class_id, instance, attribute, cip_type)
        data = reply.data
        if value_type is None:
            return data, None, None, spec
        try:
            return data, value_type.decode(data), value_type, spec
        except CipError as exc:
            where = f"0x{class_id:02X}/{instance}/{attribute}"
            if cip_type is not None:
                raise ReplyDecodeError(f"{where} answered {len(data)} bytes ({data.hex(' ') or 'none'}), "
                                       f"which do not decode as {cip_type.name}: {exc.message}") from None
            # The device differs from the declaration: tolerant as an originator, the raw bytes stand.
            debug(__name__, "%s: reply %s does not decode as declared (%s): %s", where, data.hex(), value_type, exc)
            return data, None, None, spec

    def read(self, class_id: int, instance: int, attribute: int, cip_type: CipType | None = None) -> Plan[Value]:
        data, value, value_type, spec = yield from self._get_single(class_id, instance, attribute, cip_type)
        if value_type is None:
            return Value(data, spec.name if spec is not None else "")
        if spec is None:
            return Value(value, "", value_type)
        return Value(value, spec.name, value_type, spec.scaling)

    def write(self, class_id: int, instance: int, attribute: int, value: Any, scaled: bool,
              cip_type: CipType | None) -> Plan[None]:
        value_type, spec = self._type_for(class_id, instance, attribute, cip_type)
        if isinstance(value, Value):
            value = value.raw
        where = f"0x{class_id:02X}/{instance}/{attribute}"
        if scaled:
            if spec is None:
                raise UnknownAttributeError(f"{where} is not declared in {self.catalog.source}: its scale is "
                                            "unknown, give the raw value (no scaled=True)")
            value = spec.scaling.to_raw(value)
        elif isinstance(value, float) and isinstance(value_type, IntegerType):
            if spec is not None and spec.scaling.scaled:
                raise BadRequest(f"{where} {spec.name} takes a raw integer ({spec.scaling.scale:g} {spec.unit} per "
                                 f"step): give {value!r} with scaled=True, or the raw value")
            if not value.is_integer():
                raise BadRequest(f"{where} is an integer ({value_type.name}), not {value!r}")
            value = int(value)
        yield from self.set_attribute_single(class_id, instance, attribute, value, cip_type)

    def parameter(self, code: str) -> Plan[Value]:
        """A parameter by the code its manual prints (``"ACC"``, ``"CM.24"``, ``"A004"``; an EDS file's
        ``ParamN`` or its name), read with its unit (``cipstack.parameter_codes``)."""
        from .parameter_codes import find_parameter

        return (yield from self.read(*find_parameter(self.catalog, code).path))

    def set_parameter(self, code: str, value: Any) -> Plan[Value]:
        """Write a parameter by its code, the value in its own unit (``2.5`` for 2.5 s); the value written."""
        from .parameter_codes import find_parameter, raw_of

        parameter = find_parameter(self.catalog, code)
        raw = raw_of(parameter, value)
        yield from self.write(*parameter.path, raw, False, None)
        spec = parameter.spec
        return Value(raw, spec.name, spec.type, spec.scaling)

    def set_attribute_single(self, class_id: int, instance: int, attribute: int, value: Any,
                             cip_type: CipType | None = None) -> Plan[None]:
        value_type, _ = self._type_for(class_id, instance, attribute, cip_type)
        if isinstance(value, (bytes, bytearray)):
            data = bytes(value)
        elif value_type is None:
            raise UnknownAttributeError(f"0x{class_id:02X}/{instance}/{attribute} is not declared in "
                                        f"{self.catalog.source}: its type is unknown, give cip_type or bytes")
        else:
            data = value_type.encode(value)
        yield from self.request(Service.SET_ATTRIBUTE_SINGLE, class_id, instance, attribute, data)

    def get_attributes_all(self, class_id: int, instance: int) -> Plan[tuple[bytes, dict[str, Any] | None]]:
        reply = yield from self.request(Service.GET_ATTRIBUTES_ALL, class_id, instance)
        layout = self.catalog.get_all_layout(class_id) if instance else None
        if layout is None:
            return reply.data, None
        values: dict[str, Any] = {}
        offset = 0
        try:
            for spec in layout:
                values[spec.name], offset = spec.type.decode_from(reply.data, offset)
        except (CipError, ValueError, struct.error, IndexError):
            return reply.data, None
        if offset < len(reply.data):
            values[UNDECODED] = reply.data[offset:]
        return reply.data, values

    def get_attribute_list(self, class_id: int, instance: int, attributes: Sequence[int]
                           ) -> Plan[dict[int, AttributeValue | CipError]]:
        data = UINT.encode(len(attributes)) + struct.pack(f"<{len(attributes)}H", *attributes)
        reply = yield from self.request(Service.GET_ATTRIBUTE_LIST, class_id, instance, data=data, check=False)
        if reply.general_status not in (GeneralStatus.SUCCESS, GeneralStatus.ATTRIBUTE_LIST_ERROR):
            reply.raise_for_status()
        results: dict[int, AttributeValue | CipError] = {}
        body = reply.data
        with _malformed("Get_Attribute_List reply"):
            count, offset = UINT.decode_from(body, 0)
            for _ in range(count):
                attribute_id, offset = UINT.decode_from(body, offset)
                status, offset = UINT.decode_from(body, offset)
                if status:
                    results[attribute_id] = CipError(status, message=f"attribute {attribute_id}")
                    continue
                value_type, spec = self._type_for(class_id, instance, attribute_id, None)
                if value_type is None:
                    raise _Unsplittable(f"attribute {attribute_id} is not declared in {self.catalog.source}: "
                                        "cannot split the list reply")
                value, end = value_type.decode_from(body, offset)
                results[attribute_id] = AttributeValue(class_id, instance, attribute_id, body[offset:end], value,
                                                       spec, value_type)
                offset = end
        return results

    def set_attribute_list(self, class_id: int, instance: int, values: dict[int, Any]) -> Plan[dict[int, int]]:
        out = bytearray(UINT.encode(len(values)))
        for attribute_id, value in values.items():
            value_type, _ = self._type_for(class_id, instance, attribute_id, None)
            if isinstance(value, (bytes, bytearray)):
                encoded = bytes(value)
            elif value_type is None:
                raise UnknownAttributeError(f"0x{class_id:02X}/{instance}/{attribute_id} is not declared in "
                                            f"{self.catalog.source}: its type is unknown, give bytes")
            else:
                encoded = value_type.encode(value)
            out += UINT.encode(attribute_id) + encoded
        reply = yield from self.request(Service.SET_ATTRIBUTE_LIST, class_id, instance, data=bytes(out), check=False)
        if reply.general_status not in (GeneralStatus.SUCCESS, GeneralStatus.ATTRIBUTE_LIST_ERROR):
            reply.raise_for_status()
        statuses: dict[int, int] = {}
        with _malformed("Set_Attribute_List reply"):
            count, offset = UINT.decode_from(reply.data, 0)
            for _ in range(count):
                attribute_id, offset = UINT.decode_from(reply.data, offset)
                statuses[attribute_id], offset = UINT.decode_from(reply.data, offset)
        return statuses

    def reset(self, class_id: int, instance: int, reset_type: int | None) -> Plan[None]:
        data = b"" if reset_type is None else bytes((reset_type,))
        yield from self.request(Service.RESET, class_id, instance, data=data)

    def multiple_service_packet(self, requests: Sequence[MessageRouterRequest]
                                ) -> Plan[list[MessageRouterResponse]]:
        reply = yield from self.request(Service.MULTIPLE_SERVICE_PACKET, 0x02, 1,
                                        data=encode_multiple_service(requests), check=False)
        if reply.general_status not in (GeneralStatus.SUCCESS, GeneralStatus.EMBEDDED_SERVICE_ERROR):
            reply.raise_for_status()
        return decode_multiple_service(reply.data)

    def assembly_size(self, instance: int) -> Plan[int]:
        schema = self.catalog.assemblies.get(instance)
        if schema is not None:
            return schema.size
        return int((yield from self.read(0x04, instance, 4, UINT)).raw)

    def list_identity(self) -> Plan[list[IdentityRecord]]:
        return one(self.core.list_identity())

    def list_services(self) -> Plan[list[ServiceRecord]]:
        return one(self.core.list_services())


class _Declarations:
    """``catalog``, ``route`` and ``identity`` of a scanner: those of its ``ExplicitMessaging``."""

    explicit: ExplicitMessaging

    @property
    def catalog(self) -> Catalog:
        """The declarations replies decode by and class 1 fields are named by (``catalog.source`` says whose)."""
        return self.explicit.catalog

    @catalog.setter
    def catalog(self, catalog: Catalog) -> None:
        self.explicit.catalog = catalog

    @property
    def identity(self) -> IdentityRecord | None:
        """What the device said it is (``identify``), or None before (or without) identification."""
        return self.explicit.identity

    @identity.setter
    def identity(self, identity: IdentityRecord | None) -> None:
        self.explicit.identity = identity

    @property
    def route(self) -> Sequence[Segment] | None:
        """The route every request travels (Unconnected_Send), None for the target itself."""
        return self.explicit.route

    def _schema_source(self, instance: int | None, schema: AssemblySchema | None, eds: str = "") -> str:
        """Where an image's field names come from, or why it has none, for error messages."""
        if instance is None:
            return "a heartbeat connection sends no output data"
        if schema is not None:
            return f"assembly {instance} {schema.name!r} of {eds or self.catalog.source}"
        declared = self.catalog.assemblies.get(instance)
        if declared is not None:
            return (f"assembly {instance} of {self.catalog.source} is {declared.size} bytes, not the size the "
                    "connection opened with")
        return f"no schema of assembly {instance} in {eds + ' nor in ' if eds else ''}{self.catalog.source}"


def _eds_ot_format(doc: EdsDocument, number: int) -> OtFormat | None:
    """The O->T real-time format ``ConnectionN`` declares (field 2, bits 8-10: 0 modeless,
    3 heartbeat, 4 run/idle header; eds.md), or None when the file gives none we know."""
    from .eds.model import FieldKind
    from .eip.originator.io_originator import OtFormat

    section = doc.get("Connection Manager")
    entry = section.get(f"Connection{number}") if section is not None else None
    parameters = entry.field(2) if entry is not None else None
    if parameters is None or parameters.kind is not FieldKind.INT:
        return None
    return OtFormat.from_eds((int(parameters.value) >> 8) & 0x7)


def class1_assemblies(explicit: ExplicitMessaging, output: int | None, input: int, heartbeat: int | None,
                      output_size: int | None, input_size: int | None, output_schema: AssemblySchema | None,
                      input_schema: AssemblySchema | None
                      ) -> Plan[tuple[int, int, AssemblySchema | None, AssemblySchema | None]]:
    """The sizes and schemas of a class 1 connection's assemblies, both scanners': those given, else the
    catalog's schemas, else each assembly's attribute 4 (asked of the device)."""
    if output is None and heartbeat is None:
        raise BadRequest("give an output assembly, or a heartbeat point for input-only / listen-only")
    if output_schema is None and output is not None:
        output_schema = explicit.catalog.assemblies.get(output)
    if input_schema is None:
        input_schema = explicit.catalog.assemblies.get(input)
    if output_size is None:
        output_size = 0 if output is None else (
            output_schema.size if output_schema is not None else (yield from explicit.assembly_size(output)))
    if input_size is None:
        input_size = input_schema.size if input_schema is not None else (yield from explicit.assembly_size(input))
    return output_size, input_size, output_schema if output is not None else None, input_schema


class EdsConnection:
    """What an EDS file's ``ConnectionN`` asks for, as both scanners' ``io_connection_from_eds`` open it:
    the arguments of the client's ``io_connection``, whether a refusal earns the multicast retry, and
    where the field names come from."""

    RETRY_NOTE = "the target refused point-to-point T->O (0x0108): multicast asked, which the file allows"

    def __init__(self, catalog: Catalog, doc: EdsDocument | str | Path, connection: int | str, rpi: float | None,
                 options: dict[str, Any]) -> None:
        from .eds.description import DEFAULT_RPI_US
        from .eds.interpret import read_view
        from .eds.model import EdsDocument
        from .eds.reader import read_eds

        if not isinstance(doc, EdsDocument):
            doc = read_eds(doc)
        view = read_view(doc)
        found = self.found = view.connection(connection)
        if rpi is None:
            rpi = (found.rpi_us or DEFAULT_RPI_US) / 1e6
        options = dict(options)
        # T->O as the file allows: multicast when it allows only that; when it allows both,
        # point-to-point, and multicast when the target refuses that with 0x0108 (a listen-only
        # point, say). An explicit ``multicast`` is asked as given.
        self._may_retry = "multicast" not in options and found.t_o_multicast and found.t_o_point_to_point
        options.setdefault("multicast", found.t_o_multicast and not found.t_o_point_to_point)
        eds_format = _eds_ot_format(doc, found.number)
        if eds_format is not None:
            options.setdefault("ot_format", eds_format)
        self.output = None if found.heartbeat else found.o_t_point
        output_schema = None if self.output is None else (view.schema(self.output)
                                                          or catalog.assemblies.get(self.output))
        input_schema = view.schema(found.t_o_point) or catalog.assemblies.get(found.t_o_point)
        self._arguments: dict[str, Any] = {
            "output": self.output, "input": found.t_o_point, "rpi": rpi, "output_size": found.o_t_size,
            "input_size": found.t_o_size, "config": found.config,
            "heartbeat": found.o_t_point if found.heartbeat else None, "output_schema": output_schema,
            "input_schema": input_schema, **options}

    def arguments(self, multicast: bool | None = None) -> dict[str, Any]:
        """The client's ``io_connection`` arguments (``multicast`` for the retry)."""
        return self._arguments if multicast is None else {**self._arguments, "multicast": multicast}

    def may_retry(self, refused: CipError) -> bool:
        """Whether ``refused`` is a point-to-point T->O refusal (0x0108) the file lets multicast answer."""
        return bool(self._may_retry and refused.general == GeneralStatus.CONNECTION_FAILURE
                    and refused.extended[:1] == (ExtendedStatus.INVALID_NETWORK_CONNECTION_PARAMETER,))

    def describe(self, scanner: _Declarations, handle: Any) -> None:
        source = f"the EDS file's Connection{self.found.number}"
        handle.describe_schemas(scanner._schema_source(self.output, handle.output.schema, source),
                                scanner._schema_source(self.found.t_o_point, handle.input.schema, source))


def backplane_route(slot: int = 0) -> list[Segment]:
    """Route path "port 1 (backplane), link = slot": with slot 0, the target itself."""
    return [PortSegment(1, bytes((slot,)))]


class SyncScanner(_Declarations):
    """Blocking twin of ``Scanner`` for scripts: the same methods, called without ``await``.

    It runs the same plans as ``Scanner`` (``ExplicitMessaging``) over a blocking socket
    (``BlockingEncapsulationClient``), with no event loop in between, so a call costs little more
    than the socket round trip. It identifies the device as ``Scanner.connect`` does (``catalog=``,
    ``eds=``, ``identify=``). Class 1 connections (``io_connection``, ``io_connection_from_eds``) run
    on a plain UDP socket, served by the calling thread (``eip.originator.blocking_io``), each with a
    TCP session of its own; no event loop either.
    """

    def __init__(self, address: str, port: int | None = None, *, timeout: float = 5.0,
                 catalog: Catalog | None = None, route: Sequence[Segment] | None = None,
                 identify: bool = True, eds: str | Path | EdsDocument | None = None,
                 security: SecureChannel | None = None) -> None:
        """``security``: CIP Security's credentials (``cipstack.security.Credentials.load(DIR)``): the
        requests go over TLS, to port 2221 unless the address or ``port`` names another, and each
        class 1 connection over DTLS to the same port number (UDP), its data in that DTLS session."""
        host, parsed_port = parse_host(address, DEFAULT_PORT if security is None else SECURE_PORT)
        #: The blocking client requests travel on (``client.connection``: the class 3 connection, if open).
        self.client = BlockingEncapsulationClient.connect(host, port or parsed_port, timeout, security=security)
        self._address = (host, port or parsed_port, timeout)
        self._security = security
        self.explicit = ExplicitMessaging(self.client.core, catalog, route)
        self._io: set[SyncIoConnection] = set()
        try:
            self.client.run(self.explicit.choose_catalog(catalog, eds, identify))
        except BaseException:
            self.close()
            raise

    @property
    def scanner(self) -> SyncScanner:
        """This scanner (``sync.scanner.client`` is ``sync.client``), for scripts written when it
        wrapped an async one."""
        return self

    def identify(self) -> IdentityRecord | None:
        """``Scanner.identify``: ask the device again and take its profile's catalog."""
        return self.client.run(self.explicit.identify())

    def request(self, service: int, class_id: int, instance: int | None = None, attribute: int | None = None,
                data: bytes = b"", *, check: bool = True) -> MessageRouterResponse:
        """``Scanner.request``: any service by code; ``CipError`` on an error status (unless ``check=False``)."""
        return self.client.run(self.explicit.request(service, class_id, instance, attribute, data, check=check))

    def open_connection(self, rpi: float = 2.0, large: bool = True, connection_size: int = 500) -> None:
        """``Scanner.open_connection``: later requests travel on a class 3 connection."""
        self.client.run(self.explicit.open_connection(rpi, large, connection_size))

    def close_connection(self) -> None:
        self.client.run(self.explicit.close_connection())

    def read(self, class_id: int, instance: int, attribute: int, cip_type: CipType | None = None) -> Value:
        """``Scanner.read``: the attribute's ``Value`` (raw, engineering value, unit)."""
        return self.client.run(self.explicit.read(class_id, instance, attribute, cip_type))

    def write(self, class_id: int, instance: int, attribute: int, value: Any, *, scaled: bool = False,
              cip_type: CipType | None = None) -> None:
        """``Scanner.write``: the raw value, or the engineering value with ``scaled=True``."""
        self.client.run(self.explicit.write(class_id, instance, attribute, value, scaled, cip_type))

    def parameter(self, code: str) -> Value:
        """``Scanner.parameter``: a parameter by its code (``"ACC"``), read with its unit."""
        return self.client.run(self.explicit.parameter(code))

    def set_parameter(self, code: str, value: Any) -> Value:
        """``Scanner.set_parameter``: write a parameter by its code, in its own unit (``2.5`` for 2.5 s)."""
        return self.client.run(self.explicit.set_parameter(code, value))

    def get_attribute_single(self, class_id: int, instance: int, attribute: int,
                             cip_type: CipType | None = None) -> AttributeValue:
        """``Scanner.get_attribute_single``: the reply's bytes with the decoded value and declaration."""
        return self.client.run(self.explicit.get_attribute_single(class_id, instance, attribute, cip_type))

    def set_attribute_single(self, class_id: int, instance: int, attribute: int, value: Any,
                             cip_type: CipType | None = None) -> None:
        """``Scanner.set_attribute_single``: a raw value (or bytes)."""
        self.client.run(self.explicit.set_attribute_single(class_id, instance, attribute, value, cip_type))

    def get_attributes_all(self, class_id: int, instance: int) -> tuple[bytes, dict[str, Any] | None]:
        """``Scanner.get_attributes_all``: the raw reply and the values by attribute name."""
        return self.client.run(self.explicit.get_attributes_all(class_id, instance))

    def get_attribute_list(self, class_id: int, instance: int, attributes: Sequence[int]
                           ) -> dict[int, AttributeValue | CipError]:
        """``Scanner.get_attribute_list``: per-attribute results."""
        return self.client.run(self.explicit.get_attribute_list(class_id, instance, attributes))

    def set_attribute_list(self, class_id: int, instance: int, values: dict[int, Any]) -> dict[int, int]:
        """``Scanner.set_attribute_list``: each attribute's status (0 = set)."""
        return self.client.run(self.explicit.set_attribute_list(class_id, instance, values))

    def reset(self, class_id: int = 0x01, instance: int = 1, reset_type: int | None = None) -> None:
        self.client.run(self.explicit.reset(class_id, instance, reset_type))

    def multiple_service_packet(self, requests: Sequence[MessageRouterRequest]) -> list[MessageRouterResponse]:
        """``Scanner.multiple_service_packet``: each reply (status unchecked)."""
        return self.client.run(self.explicit.multiple_service_packet(requests))

    def assembly_size(self, instance: int) -> int:
        """``Scanner.assembly_size``: from the schema when known, else Assembly attribute 4."""
        return self.client.run(self.explicit.assembly_size(instance))

    def list_identity(self) -> list[IdentityRecord]:
        return self.client.run(self.explicit.list_identity())

    def list_services(self) -> list[ServiceRecord]:
        return self.client.run(self.explicit.list_services())

    # -- class 1 ---------------------------------------------------------------------------------------
    def io_connection(self, output: int | None = None, input: int = 0, rpi: float = 0.010, *,
                      config: int = 1, heartbeat: int | None = None, output_size: int | None = None,
                      input_size: int | None = None, output_schema: AssemblySchema | None = None,
                      input_schema: AssemblySchema | None = None, target_io_port: int | None = None,
                      local_io_port: int = 0, multicast: bool = False, timeout_multiplier: int = 2,
                      run: bool = True, keep_intervals: bool = False, config_data: bytes = b"",
                      ot_format: OtFormat | str | None = None, kernel_arrival_times: bool = False,
                      on_input: Callable[[ProcessImage], Any] | None = None) -> SyncIoConnection:
        """A class 1 connection for blocking code, without an event loop:
        ``with scanner.io_connection(output=21, input=71, rpi=0.010) as io: io.update(run_forward=True)``.

        Arguments as for ``Scanner.io_connection``; fields are named by this scanner's catalog. The
        connection runs while it is called (``io.input``, ``io.update``, ``io.wait_input``,
        ``io.sleep``: wait with ``io.sleep`` rather than ``time.sleep``); with ``on_input``, a callback
        for each input change, on a thread of its own that serves it. It has a TCP session of its own;
        leaving the ``with`` block, ``close()`` on it, or closing this scanner sends the Forward_Close.
        ``kernel_arrival_times`` is the asyncio shell's: packets are timed here when read."""
        ot_size, to_size, output_schema, input_schema = self.client.run(class1_assemblies(
            self.explicit, output, input, heartbeat, output_size, input_size, output_schema, input_schema))
        opened = self._open_io(
            output=output, input=input, rpi=rpi, output_size=ot_size, input_size=to_size, config=config,
            heartbeat=heartbeat, output_schema=output_schema, input_schema=input_schema,
            target_io_port=target_io_port, local_io_port=local_io_port, multicast=multicast,
            timeout_multiplier=timeout_multiplier, run=run, keep_intervals=keep_intervals, config_data=config_data,
            ot_format=ot_format, kernel_arrival_times=kernel_arrival_times, on_input=on_input)
        opened.describe_schemas(self._schema_source(output, opened.output.schema),
                                self._schema_source(input, opened.input_schema))
        return opened

    def io_connection_from_eds(self, doc: EdsDocument | str | Path, connection: int | str, rpi: float | None = None,
                               **options: Any) -> SyncIoConnection:
        """``Scanner.io_connection_from_eds`` for synchronous code (``doc``: an EDS file or its path)."""
        eds = EdsConnection(self.catalog, doc, connection, rpi, options)
        try:
            opened = self._open_io(**eds.arguments())
        except CipError as refused:
            if not eds.may_retry(refused):
                raise
            opened = self._open_io(**eds.arguments(multicast=True))
            opened.notes.append(eds.RETRY_NOTE)
        eds.describe(self, opened)
        return opened

    def _open_io(self, **arguments: Any) -> SyncIoConnection:
        from .eip.originator.blocking_io import io_connection

        host, port, timeout = self._address
        if self._security is not None:
            # CIP Security: class 1 flows in a DTLS session on the device's UDP port 2221, where its
            # Forward_Open is sent too (a Forward_Open over TLS would open plain UDP 2222).
            client = BlockingEncapsulationClient.connect_dtls(host, port, timeout, self._security)
        else:
            client = BlockingEncapsulationClient.connect(host, port, timeout)
        try:
            opened = io_connection(client, **arguments, on_close=self._io.discard)
        except BaseException:
            client.close()
            raise
        self._io.add(opened)
        return opened

    def close(self) -> None:
        """Close every class 1 connection opened here (Forward_Close), then the session."""
        try:
            for opened in list(self._io):
                with contextlib.suppress(Exception):
                    opened.close()
        finally:
            self.client.close()

    def __enter__(self) -> SyncScanner:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @staticmethod
    def discover(address: str | Sequence[str] | None = None, port: int = DEFAULT_PORT,
                 timeout: float = 2.0) -> list[IdentityRecord]:
        """``discover_blocking``: who answers ListIdentity over UDP, without an event loop of yours."""
        return discover_blocking(address, port, timeout)


def __getattr__(name: str) -> Any:
    """``discover`` and ``list_services_udp`` (asyncio, UDP), and ``Scanner`` (the async scanner, in
    ``async_scanner``), imported when first used: the blocking scanner does not load asyncio, and a
    one-shot command loads neither."""
    if name in ("discover", "list_services_udp"):
        from .eip.originator import discovery

        return getattr(discovery, name)
    if name == "Scanner":
        from .async_scanner import Scanner

        return Scanner
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def discover_blocking(address: str | Sequence[str] | None = None, port: int = DEFAULT_PORT,
                      timeout: float = 2.0) -> list[IdentityRecord]:
    """``discover`` for synchronous code: every device that answers ListIdentity over UDP within
    ``timeout`` seconds (``address`` None: every interface's broadcast address, loopback included), on
    a plain UDP socket with no event loop (the same query as ``discover``: ``discovery_core``)."""
    from .eip.originator import blocking_discovery

    return blocking_discovery.discover_blocking(address, port, timeout)


def componet_route(node: int) -> list[Segment]:
    """Route path to CompoNet node ``node`` (0-63) behind a CompoNet gateway: port 2, link = node."""
    if not 0 <= node <= 63:
        raise BadRequest(f"CompoNet node {node} out of range 0..63")
    return [PortSegment(2, bytes((node,)))]


__all__ = [  # noqa: F822 - discover, list_services_udp and Scanner come from ``__getattr__``
    "UNDECODED", "AttributeValue", "ReplyDecodeError", "Scanner", "SyncScanner", "UnknownAttributeError",
    "Value", "backplane_route", "componet_route", "discover", "discover_blocking", "list_services_udp",
]
