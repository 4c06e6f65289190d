"""The scanner library: typed explicit messaging over an ``EncapsulationClient``.

``Scanner`` is async; ``SyncScanner`` is a thin wrapper that runs it on a private event
loop for scripts. Values decode by the attribute's declaration when the catalog knows it
(standard objects, device profiles), or by an explicit type; otherwise the raw bytes are
returned. Every error status raises ``CipError`` naming the general and extended status.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import struct
from collections.abc import AsyncIterator, Iterator, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypeVar

from .catalog import Catalog
from .cip.epath import PortSegment, Segment, request_path
from .cip.messages import MessageRouterRequest, MessageRouterResponse, Service
from .cip.model import AttributeSpec
from .cip.status import CipError, ExtendedStatus, GeneralStatus
from .cip.types import UINT, CipType
from .eip.identity_items import IdentityRecord, ServiceRecord
from .eip.originator import (
    BlockingEncapsulationClient,
    EncapsulationClient,
    ExplicitClient,
    MalformedReplyError,
    discover,
    list_services_udp,
    parse_host,
    run_blocking,
)

if TYPE_CHECKING:
    # Imported where used: explicit messaging alone does not load the EDS model or class 1.
    from .assemblies.schema import AssemblySchema
    from .eds.model import EdsDocument
    from .eip.io_originator import IoConnectionHandle, OtFormat

T = TypeVar("T")
log = logging.getLogger(__name__)

#: Key of the bytes of a Get_Attributes_All reply after the attributes the catalog declares.
UNDECODED = "(undecoded)"


@dataclass(frozen=True)
class AttributeValue:
    """A read attribute: its raw bytes, and its value when the type is known."""

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


class ReplyDecodeError(ValueError):
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


def _decode(cip_type: CipType | None, data: bytes) -> Any:
    if cip_type is None:
        return None
    return cip_type.decode(data)


class Scanner:
    """Explicit messaging to one target (unconnected, routed or class 3)."""

    def __init__(self, client: ExplicitClient, catalog: Catalog | None = None,
                 route: Sequence[Segment] | None = None) -> None:
        self.client = client
        self.catalog = catalog or Catalog()
        self.route = route

    @classmethod
    async def connect(cls, address: str, port: int | None = None, *, timeout: float = 5.0,
                      catalog: Catalog | None = None, route: Sequence[Segment] | None = None) -> Scanner:
        host, parsed_port = parse_host(address)
        client = await EncapsulationClient.connect(host, port or parsed_port, timeout)
        return cls(client, catalog, route)

    async def close(self) -> None:
        await self.client.close()

    async def __aenter__(self) -> Scanner:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    # -- generic ----------------------------------------------------------------------------------
    async def request(self, service: int, class_id: int, instance: int | None = None, attribute: int | None = None,
                      data: bytes = b"", *, check: bool = True) -> MessageRouterResponse:
        """Any service by code to class/instance[/attribute]; raises ``CipError`` on an error status."""
        path = request_path(class_id, instance, attribute)
        reply = await self.client.request(service, path, data, route=self.route)
        if (self.route is not None and self.client.connection is None and reply.service == Service.UNCONNECTED_SEND
                and service != reply.service):
            # The Connection Manager could not route the request: its error is the answer.
            reply.raise_for_status()
        if reply.service != service & 0x7F:
            raise CipError(GeneralStatus.INVALID_REPLY_RECEIVED, message=f"reply to service 0x{reply.service:02X}")
        return reply.raise_for_status() if check else reply

    async def open_connection(self, rpi: float = 2.0, large: bool = True, connection_size: int = 500) -> None:
        """Open a class 3 connection; later requests travel on it until ``close_connection``."""
        route: Sequence[Segment] = self.route or ()
        await self.client.forward_open(int(rpi * 1e6), connection_size, large, route=list(route))

    async def close_connection(self) -> None:
        await self.client.forward_close()

    # -- attributes -------------------------------------------------------------------------------
    def _type_for(self, class_id: int, instance: int, attribute: int, cip_type: CipType | None
                  ) -> tuple[CipType | None, AttributeSpec | None]:
        spec = self.catalog.attribute(class_id, instance, attribute)
        return (cip_type or (spec.type if spec is not None else None)), spec

    async def get_attribute_single(self, class_id: int, instance: int, attribute: int,
                                   cip_type: CipType | None = None) -> AttributeValue:
        reply = await self.request(Service.GET_ATTRIBUTE_SINGLE, class_id, instance, attribute)
        value_type, spec = self._type_for(class_id, instance, attribute, cip_type)
        try:
            value = _decode(value_type, reply.data)
        except CipError as exc:
            where = f"0x{class_id:02X}/{instance}/{attribute}"
            if cip_type is not None:
                raise ReplyDecodeError(f"{where} answered {len(reply.data)} bytes ({reply.data.hex(' ') or 'none'}), "
                                       f"which do not decode as {cip_type.name}: {exc.message}") from None
            # The device differs from the declaration: tolerant as an originator, the raw bytes stand.
            log.debug("%s: reply %s does not decode as declared (%s): %s", where, reply.data.hex(), value_type, exc)
            return AttributeValue(class_id, instance, attribute, reply.data, None, spec, None)
        return AttributeValue(class_id, instance, attribute, reply.data, value, spec, value_type)

    async def read(self, class_id: int, instance: int, attribute: int, cip_type: CipType | None = None) -> Any:
        """The decoded value (raw bytes when the type is unknown)."""
        result = await self.get_attribute_single(class_id, instance, attribute, cip_type)
        return result.value if result.known else result.data

    async def set_attribute_single(self, class_id: int, instance: int, attribute: int, value: Any,
                                   cip_type: CipType | None = None) -> None:
        value_type, _ = self._type_for(class_id, instance, attribute, cip_type)
        if isinstance(value, (bytes, bytearray)):
            data = bytes(value)
        elif value_type is None:
            raise TypeError(f"type of 0x{class_id:02X}/{instance}/{attribute} unknown: give cip_type or bytes")
        else:
            data = value_type.encode(value)
        await self.request(Service.SET_ATTRIBUTE_SINGLE, class_id, instance, attribute, data)

    async def get_attributes_all(self, class_id: int, instance: int) -> tuple[bytes, dict[str, Any] | None]:
        """Raw reply and, when the class is declared, the values by attribute name.

        A device may carry attributes beyond the declared ones after them (its own, or a later
        revision's): the declared ones are decoded and the rest is returned as raw bytes under
        the key ``UNDECODED`` (nothing is dropped silently)."""
        reply = await self.request(Service.GET_ATTRIBUTES_ALL, class_id, instance)
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

    async def get_attribute_list(self, class_id: int, instance: int, attributes: Sequence[int]
                                 ) -> dict[int, AttributeValue | CipError]:
        """Per-attribute results; needs every attribute's declaration to split the reply."""
        data = UINT.encode(len(attributes)) + struct.pack(f"<{len(attributes)}H", *attributes)
        reply = await self.request(Service.GET_ATTRIBUTE_LIST, class_id, instance, data=data, check=False)
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
                    raise _Unsplittable(f"attribute {attribute_id} has no known type: cannot split the list reply")
                value, end = value_type.decode_from(body, offset)
                results[attribute_id] = AttributeValue(class_id, instance, attribute_id, body[offset:end], value,
                                                       spec, value_type)
                offset = end
        return results

    async def set_attribute_list(self, class_id: int, instance: int, values: dict[int, Any]) -> dict[int, int]:
        """Set several attributes; returns each attribute's status (0 = set)."""
        out = bytearray(UINT.encode(len(values)))
        for attribute_id, value in values.items():
            value_type, _ = self._type_for(class_id, instance, attribute_id, None)
            if isinstance(value, (bytes, bytearray)):
                encoded = bytes(value)
            elif value_type is None:
                raise TypeError(f"type of attribute {attribute_id} unknown: give bytes")
            else:
                encoded = value_type.encode(value)
            out += UINT.encode(attribute_id) + encoded
        reply = await self.request(Service.SET_ATTRIBUTE_LIST, class_id, instance, data=bytes(out), check=False)
        if reply.general_status not in (GeneralStatus.SUCCESS, GeneralStatus.ATTRIBUTE_LIST_ERROR):
            reply.raise_for_status()
        statuses: dict[int, int] = {}
        with _malformed("Set_Attribute_List reply"):
            count, offset = UINT.decode_from(reply.data, 0)
            for _ in range(count):
                attribute_id, offset = UINT.decode_from(reply.data, offset)
                statuses[attribute_id], offset = UINT.decode_from(reply.data, offset)
        return statuses

    async def reset(self, class_id: int = 0x01, instance: int = 1, reset_type: int | None = None) -> None:
        data = b"" if reset_type is None else bytes((reset_type,))
        await self.request(Service.RESET, class_id, instance, data=data)

    async def multiple_service_packet(self, requests: Sequence[MessageRouterRequest]) -> list[MessageRouterResponse]:
        """Several requests in one Multiple_Service_Packet; returns each reply (status unchecked)."""
        encoded = [r.encode() for r in requests]
        table = bytearray(UINT.encode(len(encoded)))
        offset = 2 + 2 * len(encoded)
        for item in encoded:
            table += UINT.encode(offset)
            offset += len(item)
        reply = await self.request(Service.MULTIPLE_SERVICE_PACKET, 0x02, 1, data=bytes(table) + b"".join(encoded),
                                   check=False)
        if reply.general_status not in (GeneralStatus.SUCCESS, GeneralStatus.EMBEDDED_SERVICE_ERROR):
            reply.raise_for_status()
        body = reply.data
        with _malformed("Multiple_Service_Packet reply"):
            count, _ = UINT.decode_from(body, 0)
            offsets = [UINT.decode_from(body, 2 + 2 * i)[0] for i in range(count)] + [len(body)]
            return [MessageRouterResponse.decode(body[offsets[i]:offsets[i + 1]]) for i in range(count)]
        raise AssertionError("unreachable")  # pragma: no cover - the block returns or raises

    # -- class 1 --------------------------------------------------------------------------------------
    async def assembly_size(self, instance: int) -> int:
        """Size of an assembly instance: from its schema when known, else Assembly attribute 4."""
        schema = self.catalog.assemblies.get(instance)
        if schema is not None:
            return schema.size
        return int(await self.read(0x04, instance, 4, UINT))

    @contextlib.asynccontextmanager
    async def io_connection(self, output: int | None = None, input: int = 0, rpi: float = 0.010, *,
                            config: int = 1, heartbeat: int | None = None, output_size: int | None = None,
                            input_size: int | None = None, output_schema: AssemblySchema | None = None,
                            input_schema: AssemblySchema | None = None,
                            **options: Any) -> AsyncIterator[IoConnectionHandle]:
        """A class 1 connection: ``async with scanner.io_connection(output=21, input=71, rpi=0.010) as io``.

        Sizes come from the assembly schemas of a known profile, else from each assembly's
        attribute 4; fields are accessible by name when the schema is known (``io.output.run_forward``),
        raw bytes always (``io.output.raw``); ``output_schema`` / ``input_schema`` name the fields (and
        give the sizes) where the catalog does not (an EDS file's assemblies, say). ``config`` is the
        configuration instance; ``options`` go
        to ``EncapsulationClient.io_connection`` (``config_data``, ``ot_format``, ``target_io_port``,
        ``local_io_port``, ``multicast``, ``timeout_multiplier``, ``run``, ``keep_intervals``,
        ``kernel_arrival_times``). Leaving the block by any way closes the connection (Forward_Close);
        ``io.statistics()`` gives the counters and how the target really produces (received rate,
        inter-arrival p50/p99/max, missed slots).
        """
        if output is None and heartbeat is None:
            raise ValueError("give an output assembly, or a heartbeat point for input-only / listen-only")
        if not isinstance(self.client, EncapsulationClient):
            raise TypeError("class 1 connections need the asyncio client (Scanner.connect)")
        if output_schema is None and output is not None:
            output_schema = self.catalog.assemblies.get(output)
        if input_schema is None:
            input_schema = self.catalog.assemblies.get(input)
        if output_size is None:
            output_size = 0 if output is None else (
                output_schema.size if output_schema is not None else await self.assembly_size(output))
        if input_size is None:
            input_size = input_schema.size if input_schema is not None else await self.assembly_size(input)
        context = self.client.io_connection(
            output, input, rpi, output_size=output_size, input_size=input_size, config=config, heartbeat=heartbeat,
            output_schema=output_schema if output is not None else None, input_schema=input_schema, **options)
        async with context as handle:
            yield handle

    @contextlib.asynccontextmanager
    async def io_connection_from_eds(self, doc: EdsDocument, connection: int | str, rpi: float | None = None,
                                     **options: Any) -> AsyncIterator[IoConnectionHandle]:
        """The class 1 connection ``ConnectionN`` of an EDS describes, by number N or by name (field 13):
        ``async with scanner.io_connection_from_eds(doc, 1) as io``.

        Its path gives the configuration instance and the connection points; the sizes are those of
        the assemblies it names (else its size fields); input only and listen only send the
        heartbeat point; T->O is multicast when the file allows only multicast (listen only), unless
        ``multicast`` is given; the O->T real-time format is the file's (field 2), unless ``ot_format``
        is given. ``rpi`` (seconds) defaults to the RPI the file proposes, else 10 ms.
        Fields are named after the parameters the assembly members refer to, when every member can
        be a field; else the catalog's schema, else raw bytes. ``options`` as for ``io_connection``.
        A connection the file does not describe raises ``KeyError``.
        """
        from .eds.description import DEFAULT_RPI_US
        from .eds.interpret import read_view

        if not isinstance(self.client, EncapsulationClient):
            raise TypeError("class 1 connections need the asyncio client (Scanner.connect)")
        view = read_view(doc)
        found = view.connection(connection)
        if rpi is None:
            rpi = (found.rpi_us or DEFAULT_RPI_US) / 1e6
        # T->O as the file allows: multicast when it allows only that; when it allows both,
        # point-to-point, and multicast when the target refuses that with 0x0108 (a listen-only
        # point, say). An explicit ``multicast`` is asked as given.
        may_retry = "multicast" not in options and found.t_o_multicast and found.t_o_point_to_point
        options.setdefault("multicast", found.t_o_multicast and not found.t_o_point_to_point)
        eds_format = _eds_ot_format(doc, found.number)
        if eds_format is not None:
            options.setdefault("ot_format", eds_format)
        output = None if found.heartbeat else found.o_t_point
        output_schema = None if output is None else (view.schema(output) or self.catalog.assemblies.get(output))
        input_schema = view.schema(found.t_o_point) or self.catalog.assemblies.get(found.t_o_point)
        client = self.client

        def context(multicast: bool) -> Any:
            return client.io_connection(
                output, found.t_o_point, rpi, output_size=found.o_t_size, input_size=found.t_o_size,
                config=found.config, heartbeat=found.o_t_point if found.heartbeat else None,
                output_schema=output_schema, input_schema=input_schema, **{**options, "multicast": multicast})

        async with contextlib.AsyncExitStack() as stack:
            try:
                handle = await stack.enter_async_context(context(options["multicast"]))
            except CipError as refused:
                if not (may_retry and refused.general == GeneralStatus.CONNECTION_FAILURE
                        and refused.extended[:1] == (ExtendedStatus.INVALID_NETWORK_CONNECTION_PARAMETER,)):
                    raise
                handle = await stack.enter_async_context(context(True))
                handle.notes.append("the target refused point-to-point T->O (0x0108): multicast asked, which the "
                                    "file allows")
            yield handle

    # -- encapsulation --------------------------------------------------------------------------
    async def list_identity(self) -> list[IdentityRecord]:
        return await self.client.list_identity()

    async def list_services(self) -> list[ServiceRecord]:
        return await self.client.list_services()


def _eds_ot_format(doc: EdsDocument, number: int) -> OtFormat | None:
    """The O->T real-time format ``ConnectionN`` declares (field 2, bits 8-10: 0 modeless,
    3 heartbeat, 4 run/idle header; eds.md), or None when the file gives none we know."""
    from .eds.model import FieldKind
    from .eip.io_originator import OtFormat

    section = doc.get("Connection Manager")
    entry = section.get(f"Connection{number}") if section is not None else None
    parameters = entry.field(2) if entry is not None else None
    if parameters is None or parameters.kind is not FieldKind.INT:
        return None
    return OtFormat.from_eds((int(parameters.value) >> 8) & 0x7)


def backplane_route(slot: int = 0) -> list[Segment]:
    """Route path "port 1 (backplane), link = slot": with slot 0, the target itself."""
    return [PortSegment(1, bytes((slot,)))]


class SyncScanner:
    """Blocking twin of ``Scanner`` for scripts: the same methods, called without ``await``.

    It runs the same scanner code over a blocking socket (``BlockingEncapsulationClient``), with
    no event loop in between, so a call costs little more than the socket round trip. Class 1
    connections need an event loop: use the async ``Scanner`` for them.
    """

    def __init__(self, address: str, port: int | None = None, *, timeout: float = 5.0,
                 catalog: Catalog | None = None, route: Sequence[Segment] | None = None) -> None:
        host, parsed_port = parse_host(address)
        client = BlockingEncapsulationClient.connect(host, port or parsed_port, timeout)
        self._scanner = Scanner(client, catalog, route)

    @property
    def scanner(self) -> Scanner:
        return self._scanner

    def __getattr__(self, name: str) -> Any:
        if name == "io_connection":
            raise AttributeError("class 1 connections need an event loop: use the async Scanner")
        attribute = getattr(self._scanner, name)
        if not asyncio.iscoroutinefunction(attribute):
            return attribute

        def call(*args: Any, **kwargs: Any) -> Any:
            return run_blocking(attribute(*args, **kwargs))

        call.__doc__ = attribute.__doc__
        setattr(self, name, call)  # later calls find it directly, without this lookup
        return call

    def close(self) -> None:
        run_blocking(self._scanner.close())

    def __enter__(self) -> SyncScanner:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


__all__ = ["UNDECODED", "AttributeValue", "ReplyDecodeError", "Scanner", "SyncScanner", "backplane_route", "discover",
           "list_services_udp"]
