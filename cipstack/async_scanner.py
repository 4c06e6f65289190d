"""The async scanner: explicit messaging and class 1 I/O with one target over the asyncio client
(``Scanner``; ``cipstack.scanner`` names it too). It runs the plans of ``scanner.ExplicitMessaging``, as
the blocking ``SyncScanner`` does.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .catalog import Catalog
from .cip.epath import Segment
from .cip.messages import MessageRouterRequest, MessageRouterResponse
from .cip.status import CipError
from .cip.types import CipType
from .cip.values import Value
from .eip.originator.core import parse_host
from .eip.wire.encapsulation import DEFAULT_PORT, SECURE_PORT
from .errors import BadRequest
from .scanner import AttributeValue, EdsConnection, ExplicitMessaging, _Declarations, class1_assemblies

if TYPE_CHECKING:
    from .assemblies.schema import AssemblySchema
    from .eds.model import EdsDocument
    from .eip.originator.asyncio_client import EncapsulationClient
    from .eip.originator.blocking import SecureChannel
    from .eip.originator.class1 import OtFormat
    from .eip.originator.io_originator import IoConnectionHandle
    from .eip.wire.identity_items import IdentityRecord, ServiceRecord


class Scanner(_Declarations):
    """Explicit messaging and class 1 I/O with one target (unconnected, routed or class 3), async.

    Open one with ``await Scanner.connect(host)``: it identifies the device and decodes every
    reply by the declarations of its profile (``catalog``); ``read`` returns a ``Value`` with its
    unit, ``write`` takes a raw value or, with ``scaled=True``, an engineering one.
    """

    def __init__(self, client: EncapsulationClient, catalog: Catalog | None = None,
                 route: Sequence[Segment] | None = None) -> None:
        self.client = client
        #: With CIP Security: the DTLS session class 1 connections are opened in, made with the first
        #: of them and closed with the scanner (``_io_client``).
        self._secured_io: EncapsulationClient | None = None
        self._secured_io_lock = asyncio.Lock()
        #: What is asked and how replies are read: the same plans ``SyncScanner`` runs.
        self.explicit = ExplicitMessaging(client.core, catalog, route)

    @classmethod
    async def connect(cls, address: str, port: int | None = None, *, timeout: float = 5.0,
                      catalog: Catalog | None = None, route: Sequence[Segment] | None = None,
                      identify: bool = True, eds: str | Path | EdsDocument | None = None,
                      security: SecureChannel | None = None) -> Scanner:
        """Connect to ``address`` (``"host"`` or ``"host:port"``) and register a session; with
        ``security`` (``cipstack.security.Credentials.load(DIR)``) over TLS, to port 2221 unless the
        address or ``port`` names another; its class 1 connections then go over DTLS to the same port
        number (UDP), all in one DTLS session whose data they carry.

        The catalog replies decode by is, first match: ``catalog``; the EDS file ``eds`` (a path or
        a read ``EdsDocument``); the profile of the device's identity (``identify``, the default);
        else the standard objects alone. ``route`` sends every request through Unconnected_Send
        along that path (``backplane_route``, a CompoNet node behind a gateway: ``[PortSegment(2, b"\\x03")]``),
        and identification then asks the routed device itself.
        """
        from .eip.originator.asyncio_client import EncapsulationClient

        host, parsed_port = parse_host(address, DEFAULT_PORT if security is None else SECURE_PORT)
        client = await EncapsulationClient.connect(host, port or parsed_port, timeout, security=security)
        scanner = cls(client, catalog, route)
        try:
            await client.run(scanner.explicit.choose_catalog(catalog, eds, identify))
        except BaseException:
            await scanner.close()
            raise
        return scanner

    async def identify(self) -> IdentityRecord | None:
        """Ask the device what it is and take the catalog of its profile; returns its identity.

        ListIdentity over this TCP connection; where a device does not answer it (or when a
        ``route`` leads past the device that would), Identity attributes 1-4 and 7 (vendor,
        device type, product code, revision, product name). A device of no known profile gets
        the standard objects, and ``catalog.source`` says so; one that answers neither keeps them
        too, with the reason."""
        return await self.client.run(self.explicit.identify())

    async def close(self) -> None:
        secured, self._secured_io = self._secured_io, None
        try:
            if secured is not None:
                await secured.close()
        finally:
            await self.client.close()

    async def __aenter__(self) -> Scanner:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    # -- generic ----------------------------------------------------------------------------------
    async def request(self, service: int, class_id: int, instance: int | None = None, attribute: int | None = None,
                      data: bytes = b"", *, check: bool = True) -> MessageRouterResponse:
        """Any service by code to class/instance[/attribute]; raises ``CipError`` on an error status."""
        return await self.client.run(self.explicit.request(service, class_id, instance, attribute, data, check=check))

    async def open_connection(self, rpi: float = 2.0, large: bool = True, connection_size: int = 500) -> None:
        """Open a class 3 connection; later requests travel on it until ``close_connection``."""
        await self.client.run(self.explicit.open_connection(rpi, large, connection_size))

    async def close_connection(self) -> None:
        await self.client.run(self.explicit.close_connection())

    # -- attributes -------------------------------------------------------------------------------
    async def get_attribute_single(self, class_id: int, instance: int, attribute: int,
                                   cip_type: CipType | None = None) -> AttributeValue:
        """Get_Attribute_Single: the reply's bytes, the value decoded by the declaration (or ``cip_type``)
        and the declaration itself."""
        return await self.client.run(self.explicit.get_attribute_single(class_id, instance, attribute, cip_type))

    async def read(self, class_id: int, instance: int, attribute: int, cip_type: CipType | None = None) -> Value:
        """Get_Attribute_Single, decoded by the attribute's declaration (or ``cip_type``): a ``Value``
        whose ``raw`` is the value on the wire, ``value`` the engineering value, ``unit`` its unit
        (``str()`` gives ``5.0 s``). Undeclared and no ``cip_type``: ``raw`` is the reply's bytes."""
        return await self.client.run(self.explicit.read(class_id, instance, attribute, cip_type))

    async def write(self, class_id: int, instance: int, attribute: int, value: Any, *, scaled: bool = False,
                    cip_type: CipType | None = None) -> None:
        """Set_Attribute_Single by the attribute's declaration (or ``cip_type``).

        The rule: ``value`` is the raw value, as on the wire (an ``int`` for a scaled attribute:
        ``write(0x2A, 1, 102, 50)`` is 5.0 s at 0.1 s per step), unless ``scaled=True``: then it is the
        engineering value (``write(0x2A, 1, 102, 5.0, scaled=True)``), turned into raw steps by the
        declaration; a value between two steps raises ``ValueError``. A ``Value`` writes its raw
        value; ``bytes`` go as they are."""
        await self.client.run(self.explicit.write(class_id, instance, attribute, value, scaled, cip_type))

    async def parameter(self, code: str) -> Value:
        """A parameter by the code its manual prints (``"ACC"``, ``"CM.24"``, ``"A004"``; an EDS file's
        ``ParamN`` or its name), read with its unit: ``cipstack.parameter_codes``."""
        return await self.client.run(self.explicit.parameter(code))

    async def set_parameter(self, code: str, value: Any) -> Value:
        """Write a parameter by its code, the value in its own unit (``set_parameter("ACC", 2.5)``: 2.5 s);
        the value written, as a ``Value``."""
        return await self.client.run(self.explicit.set_parameter(code, value))

    async def set_attribute_single(self, class_id: int, instance: int, attribute: int, value: Any,
                                   cip_type: CipType | None = None) -> None:
        """Set_Attribute_Single of a raw value (or ``bytes``), encoded by the declaration or ``cip_type``."""
        await self.client.run(self.explicit.set_attribute_single(class_id, instance, attribute, value, cip_type))

    async def get_attributes_all(self, class_id: int, instance: int) -> tuple[bytes, dict[str, Any] | None]:
        """Raw reply and, when the class is declared, the values by attribute name.

        A device may carry attributes beyond the declared ones after them (its own, or a later
        revision's): the declared ones are decoded and the rest is returned as raw bytes under
        the key ``UNDECODED`` (nothing is dropped silently)."""
        return await self.client.run(self.explicit.get_attributes_all(class_id, instance))

    async def get_attribute_list(self, class_id: int, instance: int, attributes: Sequence[int]
                                 ) -> dict[int, AttributeValue | CipError]:
        """Per-attribute results; needs every attribute's declaration to split the reply."""
        return await self.client.run(self.explicit.get_attribute_list(class_id, instance, attributes))

    async def set_attribute_list(self, class_id: int, instance: int, values: dict[int, Any]) -> dict[int, int]:
        """Set several attributes; returns each attribute's status (0 = set)."""
        return await self.client.run(self.explicit.set_attribute_list(class_id, instance, values))

    async def reset(self, class_id: int = 0x01, instance: int = 1, reset_type: int | None = None) -> None:
        await self.client.run(self.explicit.reset(class_id, instance, reset_type))

    async def multiple_service_packet(self, requests: Sequence[MessageRouterRequest]) -> list[MessageRouterResponse]:
        """Several requests in one Multiple_Service_Packet; returns each reply (status unchecked)."""
        return await self.client.run(self.explicit.multiple_service_packet(requests))

    # -- class 1 --------------------------------------------------------------------------------------
    async def assembly_size(self, instance: int) -> int:
        """Size of an assembly instance: from its schema when known, else Assembly attribute 4."""
        return await self.client.run(self.explicit.assembly_size(instance))


    @contextlib.asynccontextmanager
    async def _io_client(self) -> AsyncIterator[EncapsulationClient]:
        """The client a class 1 connection is opened on: this scanner's, or with CIP Security the
        scanner's DTLS session to the same port number over UDP, where the connection's data then
        flows (a Forward_Open over TLS would open plain UDP 2222). One session carries every class 1
        connection of the scanner, as one UDP 2222 socket carries a PLC's."""
        client = self.client
        if client.security is None:
            yield client
            return
        async with self._secured_io_lock:
            if self._secured_io is None or not self._secured_io.is_open:
                from .eip.originator.asyncio_client import EncapsulationClient

                self._secured_io = await EncapsulationClient.connect(client.host, client.port, client.timeout,
                                                                     security=client.security, datagrams=True)
        yield self._secured_io

    @contextlib.asynccontextmanager
    async def io_connection(self, output: int | None = None, input: int = 0, rpi: float = 0.010, *,
                            config: int = 1, heartbeat: int | None = None, output_size: int | None = None,
                            input_size: int | None = None, output_schema: AssemblySchema | None = None,
                            input_schema: AssemblySchema | None = None, target_io_port: int | None = None,
                            local_io_port: int = 0, multicast: bool = False, timeout_multiplier: int = 2,
                            run: bool = True, keep_intervals: bool = False, config_data: bytes = b"",
                            ot_format: OtFormat | str | None = None, kernel_arrival_times: bool = False,
                            ) -> AsyncIterator[IoConnectionHandle]:
        """A class 1 connection: ``async with scanner.io_connection(output=21, input=71, rpi=0.010) as io``.

        Sizes come from the assembly schemas of a known profile, else from each assembly's
        attribute 4; fields are accessible by name when the schema is known (``io.output.run_forward``),
        raw bytes always (``io.output.raw``); ``output_schema`` / ``input_schema`` name the fields (and
        give the sizes) where the catalog does not (an EDS file's assemblies, say). ``config`` is the
        configuration instance and ``config_data`` the data sent to it; ``target_io_port`` the
        target's class 1 UDP port (default: what the reply names, else 2222), ``local_io_port`` ours
        (0: any); ``multicast`` asks for T->O multicast; ``timeout_multiplier`` (0-7) sets the timeout
        to RPI x 4 x 2^N; ``run`` the run/idle bit first sent; ``ot_format`` the O->T real-time
        format (run/idle header, heartbeat, modeless); ``keep_intervals`` and ``kernel_arrival_times``
        keep each arrival's interval (from the kernel's time stamps) for the statistics: as
        ``EncapsulationClient.io_connection`` takes them. Leaving the block by any way closes the
        connection (Forward_Close);
        ``io.statistics()`` gives the counters and how the target really produces (received rate,
        inter-arrival p50/p99/max, missed slots).
        """
        ot_size, to_size, output_schema, input_schema = await self.client.run(class1_assemblies(
            self.explicit, output, input, heartbeat, output_size, input_size, output_schema, input_schema))
        async with self._io_client() as client, client.io_connection(
                output, input, rpi, output_size=ot_size, input_size=to_size, config=config, heartbeat=heartbeat,
                output_schema=output_schema, input_schema=input_schema,
                target_io_port=target_io_port, local_io_port=local_io_port, multicast=multicast,
                timeout_multiplier=timeout_multiplier, run=run, keep_intervals=keep_intervals,
                config_data=config_data, ot_format=ot_format, kernel_arrival_times=kernel_arrival_times) as handle:
            handle.describe_schemas(self._schema_source(output, handle.output.schema),
                                    self._schema_source(input, handle.input.schema))
            yield handle

    @contextlib.asynccontextmanager
    async def io_connection_from_eds(self, doc: EdsDocument | str | Path, connection: int | str,
                                     rpi: float | None = None, **options: Any) -> AsyncIterator[IoConnectionHandle]:
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
        eds = EdsConnection(self.catalog, doc, connection, rpi, options)
        async with contextlib.AsyncExitStack() as stack:
            client = await stack.enter_async_context(self._io_client())
            try:
                handle = await stack.enter_async_context(client.io_connection(**eds.arguments()))
            except CipError as refused:
                if not eds.may_retry(refused):
                    raise
                handle = await stack.enter_async_context(client.io_connection(**eds.arguments(multicast=True)))
                handle.notes.append(eds.RETRY_NOTE)
            eds.describe(self, handle)
            yield handle

    # -- encapsulation --------------------------------------------------------------------------
    async def list_identity(self) -> list[IdentityRecord]:
        return await self.client.list_identity()

    async def list_services(self) -> list[ServiceRecord]:
        return await self.client.list_services()


#: Sessions and Forward_Opens under way at once by default in ``open_io_connections``. Each step of an
#: open waits for a turn of the target's event loop; a fleet carrying the connections already open
#: turns slowly, so the opens under way at once, not the round trips, set how fast a plant opens
#: (1,024 drives at RPI 10 ms on two workers: 512 at once opened them in 7 s, 64 in 30 s).
OPENS_IN_FLIGHT = 512


@contextlib.asynccontextmanager
async def open_io_connections(targets: Sequence[str], output: int | None = None, input: int = 0,
                              rpi: float = 0.010, *, in_flight: int = OPENS_IN_FLIGHT, timeout: float = 10.0,
                              catalog: Catalog | None = None,
                              **options: Any) -> AsyncIterator[list[IoConnectionHandle]]:
    """One class 1 connection to each of ``targets`` (``"host"`` or ``"host:port"``), opened with up to
    ``in_flight`` sessions and Forward_Opens under way at once, not one round trip after another:
    ``async with open_io_connections(hosts, output=21, input=71, rpi=0.010) as handles``. The handles
    are in the order of ``targets``; ``options`` are ``Scanner.io_connection``'s. Give a ``catalog`` for
    a plant of one profile: each target is then not asked who it is first (one round trip less each).

    All or nothing: the first target that cannot be reached or refuses raises its error once every
    connection already open is closed again. Leaving the block closes them all (Forward_Close each).
    """
    if in_flight < 1:
        raise BadRequest(f"in_flight {in_flight}: at least one Forward_Open must be under way")
    slots = asyncio.Semaphore(in_flight)
    closing = asyncio.Event()
    handles: list[IoConnectionHandle | None] = [None] * len(targets)
    opened = [asyncio.get_running_loop().create_future() for _ in targets]

    async def hold(index: int, target: str) -> None:
        try:
            async with contextlib.AsyncExitStack() as stack:
                async with slots:
                    scanner = await stack.enter_async_context(
                        await Scanner.connect(target, timeout=timeout, catalog=catalog, identify=catalog is None))
                    handles[index] = await stack.enter_async_context(scanner.io_connection(output, input, rpi,
                                                                                             **options))
                opened[index].set_result(None)
                await closing.wait()
        except BaseException as exc:
            if not opened[index].done():
                opened[index].set_exception(exc)
            raise

    tasks = [asyncio.create_task(hold(index, target)) for index, target in enumerate(targets)]
    try:
        for future in asyncio.as_completed(opened):
            await future   # the first failure ends the wait, and the block below closes the others
        yield [handle for handle in handles if handle is not None]
    finally:
        closing.set()   # the open ones close (Forward_Close); those still opening are given up
        for task, future in zip(tasks, opened, strict=True):
            if not future.done():
                task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        for future in opened:   # a failure after the first is retrieved, not left to the loop's log
            if future.done() and not future.cancelled():
                future.exception()


__all__ = ["OPENS_IN_FLIGHT", "Scanner", "open_io_connections"]
