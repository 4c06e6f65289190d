"""The capture analysis core: frames in, findings out, no file or clock of its own (sans-I/O).

``Analyzer.feed(time, number, linktype, data)`` takes one link-layer frame; explicit exchanges
and anomalies go to ``sink`` as they are found (so ``--json`` streams), class 1 connections are
kept with bounded statistics and go to ``sink`` when they end or at ``finish(end_time)``.

Memory is bounded whatever the file size: TCP reassembly keeps at most ``MAX_TCP_BUFFER`` bytes
per direction (a stream that outgrows it, or has a hole, is resynchronised and reported); at most
``MAX_PENDING`` unanswered requests per TCP connection; per-connection lists (data changes,
run/idle changes) keep their first ``MAX_EVENTS`` entries and count the rest; inter-arrival
times go into a log histogram and a fixed-size reservoir.
"""

from __future__ import annotations

import builtins
import struct
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from socket import inet_aton, inet_ntoa
from typing import Any

from ..cip.messages import MessageRouterResponse, Service
from ..eip.io_core import DEFAULT_IO_PORT, IoDatagramError, connection_timeout, decode_io_datagram, seq32_newer
from ..eip.wire.cm_messages import ForwardCloseRequest, ForwardOpenReply, ForwardOpenRequest
from ..eip.wire.cpf import ItemType, SockAddr, decode_items
from ..eip.wire.encapsulation import HEADER, HEADER_SIZE, RR_PREFIX, Command, EncapsulationError
from ..eip.wire.identity_items import decode_list_identity
from .decoding import (
    CONNECTION_MANAGER,
    Declarations,
    connection_points,
    decode_reply,
    decode_request,
    field_changes,
)
from .reader import Segment, decode_segment, ip_offset
from .stats import LogHistogram, Reservoir, Worst

ENIP_PORT = 44818
MAX_TCP_BUFFER = 1 << 18
MAX_PENDING = 64
MAX_EVENTS = 200
#: TCP streams (and their pending requests) followed at once; the least recently opened goes first.
MAX_STREAMS = 4096
#: Out-of-order segments held per stream while the gap before them may still fill.
MAX_AHEAD = 32
#: Unknown connection ids remembered (each reported once).
MAX_UNKNOWN = 4096
#: Largest encapsulation frame accepted from a stream (header + 65,535-byte length field).
MAX_FRAME = HEADER_SIZE + 0xFFFF
#: The tolerance the project measures I/O timing with (benchmarks/io.py): an interval within
#: +-0.5 ms of the RPI is on time; a packet more than half an RPI after its due time is late.
ON_TIME_S = 0.0005

Sink = Callable[[dict[str, Any]], None]


def _command_name(code: int) -> str:
    try:
        return Command(code).name
    except ValueError:
        return f"0x{code:04X}"


@dataclass
class Direction:
    """One direction of a class 1 connection: what arrived and how regularly."""

    rpi_us: int
    size: int
    frames: int = 0
    bytes: int = 0
    first_time: float | None = None
    last_time: float | None = None
    last_sequence: int | None = None
    last_cip_sequence: int | None = None
    lost: int = 0
    duplicates: int = 0
    stale: int = 0
    new_data: int = 0
    on_time: int = 0
    late: int = 0
    intervals: LogHistogram = field(default_factory=LogHistogram)
    reservoir: Reservoir = field(default_factory=Reservoir)
    worst: Worst = field(default_factory=Worst)
    last_payload: builtins.bytes | None = None  # ``bytes`` above is this class's byte count
    last_fields: dict[str, Any] | None = None
    timeout: float | None = None

    def summary(self) -> dict[str, Any]:
        hist = self.intervals

        def ms(value: float | None) -> float | None:
            return None if value is None else round(value * 1e3, 3)

        return {"rpi_ms": self.rpi_us / 1000, "size": self.size, "frames": self.frames, "bytes": self.bytes,
                "lost": self.lost, "duplicates": self.duplicates, "stale": self.stale, "new_data": self.new_data,
                "intervals": hist.count, "p50_ms": ms(hist.quantile(0.5)), "p99_ms": ms(hist.quantile(0.99)),
                "max_ms": ms(hist.maximum if hist.count else None),
                "within_0.5ms_pct": round(100.0 * self.on_time / hist.count, 2) if hist.count else None,
                "late": self.late}


@dataclass
class Connection:
    """A class 1 connection from its Forward_Open to its end."""

    number: int
    originator: str
    target: str
    opened: float
    request: ForwardOpenRequest
    reply: ForwardOpenReply | None
    config: int | None
    o_t_point: int | None
    t_o_point: int | None
    o_t: Direction
    t_o: Direction
    declarations: Declarations
    ended: float | None = None
    end_reason: str | None = None
    run: bool | None = None
    run_changes: list[dict[str, Any]] = field(default_factory=list)
    run_change_count: int = 0
    data_changes: list[dict[str, Any]] = field(default_factory=list)
    data_change_count: int = 0
    frame_numbers: tuple[int, int] = (0, 0)

    @property
    def ot_id(self) -> int:
        return self.reply.ot_connection_id if self.reply else self.request.ot_connection_id

    @property
    def to_id(self) -> int:
        return self.reply.to_connection_id if self.reply else self.request.to_connection_id

    def timeout_s(self, direction: Direction) -> float:
        """RPI x 4 x 2^multiplier of that direction, computed once per connection."""
        if direction.timeout is None:
            direction.timeout = connection_timeout(direction.rpi_us, self.request.timeout_multiplier)
        return direction.timeout

    def as_dict(self) -> dict[str, Any]:
        triad = self.request.triad
        return {
            "type": "connection", "number": self.number, "originator": self.originator, "target": self.target,
            "opened": self.opened, "ended": self.ended, "end_reason": self.end_reason,
            "triad": {"connection_serial": triad.connection_serial, "vendor_id": triad.vendor_id,
                      "originator_serial": triad.originator_serial},
            "o_t_id": self.ot_id, "t_o_id": self.to_id,
            "config": self.config, "o_t_point": self.o_t_point, "t_o_point": self.t_o_point,
            "transport_class": self.request.transport.transport_class,
            "trigger": self.request.transport.trigger.name.lower(),
            "o_t_type": self.request.ot_parameters.type.name.lower(),
            "t_o_type": self.request.to_parameters.type.name.lower(),
            "timeout_multiplier": self.request.timeout_multiplier,
            "o_t_api_ms": self.reply.ot_api_us / 1000 if self.reply else None,
            "t_o_api_ms": self.reply.to_api_us / 1000 if self.reply else None,
            "o_t": self.o_t.summary(), "t_o": self.t_o.summary(),
            "run_idle_changes": self.run_changes, "run_idle_change_count": self.run_change_count,
            "data_changes": self.data_changes, "data_change_count": self.data_change_count,
            "declarations": self.declarations.source,
        }


@dataclass
class _Stream:
    """One direction of a TCP connection, reassembled by sequence number."""

    next_seq: int = 0
    buffer: bytearray = field(default_factory=bytearray)
    #: Segments that arrived ahead of a gap, by sequence number (at most MAX_AHEAD of them).
    ahead: dict[int, bytes] = field(default_factory=dict)


@dataclass
class _Pending:
    time: float
    frame: int
    command: int
    context: bytes
    session: int
    request: dict[str, Any]
    connected_id: int | None = None
    cip_sequence: int | None = None
    forward_open: ForwardOpenRequest | None = None
    forward_close: ForwardCloseRequest | None = None
    sockaddrs: tuple[SockAddr, ...] = ()


@dataclass
class Totals:
    frames: int = 0
    enip_frames: int = 0
    explicit: int = 0
    errors: int = 0
    unanswered: int = 0
    io_frames: int = 0
    anomalies: int = 0
    connections: int = 0
    first_time: float | None = None
    last_time: float | None = None
    #: Count of explicit exchanges per service name.
    services: dict[str, int] = field(default_factory=dict)


class Analyzer:
    def __init__(self, sink: Sink, declarations: Declarations | None = None,
                 connection_filter: int | None = None,
                 declarations_for: Callable[[Any], Declarations] | None = None) -> None:
        self.sink = sink
        #: Fixed declarations (``--profile``/``--eds``): used for every target.
        self.fixed = declarations
        #: How to pick declarations from an identity the capture shows.
        self.declarations_for = declarations_for
        self.connection_filter = connection_filter
        self.totals = Totals()
        self.targets: dict[str, Declarations] = {}
        self.identities: dict[str, dict[str, Any]] = {}
        self.io_ports: set[int] = {DEFAULT_IO_PORT}
        self._streams: dict[tuple[str, int, str, int], _Stream] = {}
        self._pending: dict[tuple[str, int, str, int], deque[_Pending]] = {}
        #: Open connections by (target address, connection id) -> (connection, "o_t" | "t_o").
        #: Keyed by the raw 4-byte address: the class 1 path compares bytes, it formats no address.
        self._by_id: dict[tuple[bytes, int], tuple[Connection, str]] = {}
        self.connections: list[Connection] = []
        self._numbers = 0
        self._unknown: dict[tuple[bytes, int], int] = {}

    @property
    def buffered_bytes(self) -> int:
        """Bytes of TCP streams held for reassembly: frames still incomplete and segments that came
        ahead of a gap, over every stream (what a long capture costs in memory beyond its records)."""
        return sum(len(s.buffer) + sum(map(len, s.ahead.values())) for s in self._streams.values())

    # -- frames ------------------------------------------------------------------------------------

    def feed(self, time: float, number: int, linktype: int, data: bytes) -> None:
        totals = self.totals
        totals.frames += 1
        if totals.first_time is None:
            totals.first_time = time
        totals.last_time = time
        # Hot path: an IPv4 UDP datagram off 44818 (class 1 I/O), read in place without a Segment.
        ip = ip_offset(linktype, data)
        if ip is not None and len(data) >= ip + 28 and data[ip] == 0x45 and data[ip + 9] == 17 and not (
                data[ip + 6] & 0x1F or data[ip + 7]):
            sport = (data[ip + 20] << 8) | data[ip + 21]
            dport = (data[ip + 22] << 8) | data[ip + 23]
            if sport != ENIP_PORT and dport != ENIP_PORT:
                if dport in self.io_ports or sport in self.io_ports or self._by_id:
                    length = (data[ip + 24] << 8) | data[ip + 25]
                    self._io(time, number, data[ip + 12:ip + 16], sport, data[ip + 16:ip + 20], dport,
                             data[ip + 28:ip + 20 + length])
                return
        segment = decode_segment(linktype, data)
        if segment is None:
            return
        if segment.protocol == 17:
            if segment.sport == ENIP_PORT or segment.dport == ENIP_PORT:
                self._udp_encapsulation(time, number, segment)
            elif segment.dport in self.io_ports or segment.sport in self.io_ports or self._by_id:
                self._io(time, number, inet_aton(segment.src), segment.sport, inet_aton(segment.dst), segment.dport,
                         segment.payload)
        elif segment.sport == ENIP_PORT or segment.dport == ENIP_PORT:
            self._tcp(time, number, segment)

    def _tcp(self, time: float, number: int, segment: Any) -> None:
        key = (segment.src, segment.sport, segment.dst, segment.dport)
        stream = self._streams.get(key)
        if segment.flags & 0x02:  # SYN: a new stream starts after it
            self._new_stream(key, (segment.seq + 1) & 0xFFFFFFFF)
            return
        if stream is None:
            # Capture started mid-connection: take the stream from here.
            stream = self._new_stream(key, segment.seq)
        payload = segment.payload
        if payload:
            if self._take(stream, segment.seq, payload):
                while stream.ahead and self._take_ahead(stream):
                    pass
            elif len(stream.ahead) < MAX_AHEAD:  # out of order: hold it while the gap may fill
                stream.ahead[segment.seq] = payload
            else:  # a hole that never filled (bytes not captured): resynchronise after it
                first = min(stream.ahead, key=lambda seq: (seq - stream.next_seq) & 0xFFFFFFFF)
                missing = (first - stream.next_seq) & 0xFFFFFFFF
                self._anomaly(time, number, segment, "tcp", f"{missing} stream bytes missing; "
                              f"{len(stream.buffer)} buffered bytes dropped", None)
                stream.buffer.clear()
                stream.next_seq = first
                stream.ahead[segment.seq] = payload
                while stream.ahead and self._take_ahead(stream):
                    pass
            self._frames_from_stream(time, number, segment, stream)
        if segment.flags & 0x05:  # FIN or RST
            self._streams.pop(key, None)
            if segment.sport == ENIP_PORT:
                self._drop_pending((segment.dst, segment.dport, segment.src, segment.sport), "TCP connection closed")

    @staticmethod
    def _take(stream: _Stream, seq: int, payload: bytes) -> bool:
        """Append the part of a segment that continues the stream; False when it starts after a gap."""
        offset = (seq - stream.next_seq) & 0xFFFFFFFF
        if offset == 0:
            stream.buffer += payload
        elif offset >= 0x80000000:  # a retransmission, maybe with new bytes at its end
            behind = 0x100000000 - offset
            if behind >= len(payload):
                return True
            stream.buffer += payload[behind:]
        else:
            return False
        stream.next_seq = (seq + len(payload)) & 0xFFFFFFFF
        return True

    def _take_ahead(self, stream: _Stream) -> bool:
        """Move one held segment that the stream has now reached; False when none has."""
        for seq in list(stream.ahead):
            if (seq - stream.next_seq) & 0xFFFFFFFF >= 0x80000000 or seq == stream.next_seq:
                self._take(stream, seq, stream.ahead.pop(seq))
                return True
        return False

    def _new_stream(self, key: tuple[str, int, str, int], next_seq: int) -> _Stream:
        self._streams.pop(key, None)
        if len(self._streams) >= MAX_STREAMS:
            oldest = next(iter(self._streams))
            del self._streams[oldest]
            if oldest[3] == ENIP_PORT:
                self._drop_pending(oldest, "stream no longer followed (too many TCP streams)")
        stream = self._streams[key] = _Stream(next_seq=next_seq)
        return stream

    def _frames_from_stream(self, time: float, number: int, segment: Any, stream: _Stream) -> None:
        buffer = stream.buffer
        start = 0
        while len(buffer) - start >= HEADER_SIZE:
            length = buffer[start + 2] | (buffer[start + 3] << 8)
            end = start + HEADER_SIZE + length
            if end > len(buffer):
                break
            self._encapsulation(time, number, segment, bytes(buffer[start:end]), "tcp")
            start = end
        if start:
            del buffer[:start]
        if len(buffer) > MAX_TCP_BUFFER:
            self._anomaly(time, number, segment, "tcp", f"{len(buffer)} bytes without a complete frame; dropped", 0)
            buffer.clear()

    def _udp_encapsulation(self, time: float, number: int, segment: Any) -> None:
        data = segment.payload
        if len(data) < HEADER_SIZE:
            self._anomaly(time, number, segment, "enip", "shorter than the encapsulation header", len(data))
            return
        self._encapsulation(time, number, segment, data, "udp")

    # -- encapsulation -----------------------------------------------------------------------------

    def _encapsulation(self, time: float, number: int, segment: Any, frame: bytes, transport: str) -> None:
        self.totals.enip_frames += 1
        command, length, session, status, context, _options = HEADER.unpack_from(frame)
        body = frame[HEADER_SIZE:]
        if len(body) != length:
            self._anomaly(time, number, segment, "enip", f"length field {length}, {len(body)} bytes follow", 2)
            return
        from_target = segment.sport == ENIP_PORT
        client = (segment.dst, segment.dport) if from_target else (segment.src, segment.sport)
        server = (segment.src, segment.sport) if from_target else (segment.dst, segment.dport)
        key = (*client, *server)
        if command == Command.LIST_IDENTITY and from_target and body:
            self._identity(segment.src, body, time, number, segment)
            return
        if command not in (Command.SEND_RR_DATA, Command.SEND_UNIT_DATA) or not body:
            return
        prefix = RR_PREFIX.size
        if len(body) < prefix:
            self._anomaly(time, number, segment, "enip", "SendRRData/SendUnitData shorter than its prefix",
                          HEADER_SIZE + len(body))
            return
        try:
            items = decode_items(body, prefix)
        except EncapsulationError as exc:
            offset = HEADER_SIZE + exc.offset if exc.offset is not None else None
            extra = self._items_after_count(body, prefix)
            if extra is not None:
                items, surplus = extra
                self._anomaly(time, number, segment, "cpf", f"{surplus} byte(s) of items after the declared count",
                              offset)
            else:
                self._anomaly(time, number, segment, "cpf", str(exc), offset)
                return
        data_item = next((i for i in items if i.type in (ItemType.UNCONNECTED_DATA, ItemType.CONNECTED_DATA)), None)
        if data_item is None:
            self._anomaly(time, number, segment, "cpf", "no data item", HEADER_SIZE + prefix)
            return
        address = next((i for i in items if i.type == ItemType.CONNECTED_ADDRESS), None)
        sockaddrs = tuple(SockAddr.decode(i.data) for i in items
                          if i.type in (ItemType.SOCKADDR_O_T, ItemType.SOCKADDR_T_O) and len(i.data) >= 16)
        for sockaddr in sockaddrs:
            self.io_ports.add(sockaddr.port)
        message = data_item.data
        cip_sequence = None
        connected_id = None
        if data_item.type == ItemType.CONNECTED_DATA:
            if len(message) < 2 or address is None or len(address.data) < 4:
                self._anomaly(time, number, segment, "cpf", "connected data without address or sequence count", None)
                return
            cip_sequence = int.from_bytes(message[:2], "little")
            connected_id = int.from_bytes(address.data[:4], "little")
            message = message[2:]
        if not message:
            self._anomaly(time, number, segment, "cip", "empty message router message", None)
            return
        decl = self._declarations(server[0])
        if message[0] & 0x80:
            if not from_target:
                self._anomaly(time, number, segment, "cip", "a reply sent to the target", None)
                return
            self._reply(time, number, key, command, session, context, status, message, connected_id, cip_sequence,
                        sockaddrs, decl, [i.type for i in items])
        else:
            if from_target:
                self._anomaly(time, number, segment, "cip", "a request sent by the target", None)
                return
            try:
                request = decode_request(message, decl)
            except Exception as exc:
                self._anomaly(time, number, segment, "cip", f"request: {exc}", None)
                request = {"service": message[0], "service_name": f"Service 0x{message[0]:02X}", "malformed": True}
            pending = _Pending(time, number, command, context, session, request, connected_id, cip_sequence,
                               sockaddrs=sockaddrs)
            if request.get("class") == CONNECTION_MANAGER and not request.get("malformed"):
                raw = message[2 + 2 * message[1]:]
                try:
                    if request["service"] in (Service.FORWARD_OPEN, Service.LARGE_FORWARD_OPEN):
                        pending.forward_open = ForwardOpenRequest.decode(
                            raw, request["service"] == Service.LARGE_FORWARD_OPEN)
                    elif request["service"] == Service.FORWARD_CLOSE:
                        pending.forward_close = ForwardCloseRequest.decode(raw)
                except Exception as exc:
                    self._anomaly(time, number, segment, "cip", f"{request['service_name']}: {exc}", None)
            queue = self._pending.setdefault(key, deque())
            if len(queue) >= MAX_PENDING:
                self._unanswered(queue.popleft(), key, "more than 64 requests outstanding")
            queue.append(pending)

    @staticmethod
    def _items_after_count(body: bytes, offset: int) -> tuple[list[Any], int] | None:
        """The declared items and how many bytes follow them, when the declared ones decode."""
        count = int.from_bytes(body[offset:offset + 2], "little")
        pos = offset + 2
        for _ in range(count):
            if pos + 4 > len(body):
                return None
            pos += 4 + int.from_bytes(body[pos + 2:pos + 4], "little")
        if pos >= len(body):
            return None
        try:
            return decode_items(body[:pos], offset), len(body) - pos
        except EncapsulationError:
            return None

    def _reply(self, time: float, number: int, key: tuple[str, int, str, int], command: int, session: int,
               context: bytes, status: int, message: bytes, connected_id: int | None, cip_sequence: int | None,
               sockaddrs: tuple[SockAddr, ...], decl: Declarations, item_types: list[int]) -> None:
        queue = self._pending.get(key)
        pending = None
        if queue:
            for candidate in queue:
                if candidate.command != command:
                    continue
                if command == Command.SEND_UNIT_DATA and candidate.cip_sequence != cip_sequence:
                    continue
                if command == Command.SEND_RR_DATA and candidate.context != context:
                    continue
                pending = candidate
                break
            if pending is None and command == Command.SEND_RR_DATA:
                pending = next((c for c in queue if c.command == command), None)
            if pending is not None:
                queue.remove(pending)
        try:
            reply = decode_reply(message, pending.request if pending else None, decl)
        except Exception as exc:
            self._anomaly(time, number, None, "cip", f"reply: {exc}", None, key)
            return
        record: dict[str, Any] = {
            "type": "explicit", "client": f"{key[0]}:{key[1]}", "target": f"{key[2]}:{key[3]}",
            "session": session, "command": _command_name(command), "reply_frame": number, "reply_time": time,
            "reply": reply, "reply_items": [f"0x{t:04X}" for t in item_types],
        }
        if connected_id is not None:
            record["connection_id"] = connected_id
        if pending is None:
            record["unmatched_reply"] = True
        else:
            record.update(request_frame=pending.frame, time=pending.time,
                          latency_ms=round((time - pending.time) * 1e3, 3), request=pending.request)
        request = pending.request if pending else {}
        name = request.get("service_name") or f"reply 0x{reply['service']:02X}"
        self.totals.explicit += 1
        self.totals.services[name] = self.totals.services.get(name, 0) + 1
        if reply["status"] not in (0, 6):
            self.totals.errors += 1
            record["error"] = True
        self._learn_identity(key[2], request, message)
        if pending is not None and pending.forward_open is not None:
            self._forward_open(time, number, key, pending, message, sockaddrs, reply)
        elif pending is not None and pending.forward_close is not None and reply["status"] == 0:
            self._forward_close(time, key[2], pending.forward_close)
        self.sink(record)

    def _learn_identity(self, target: str, request: dict[str, Any], message: bytes) -> None:
        """Identity Get_Attributes_All (class 1, instance 1): picks the target's profile."""
        if request.get("class") != 0x01 or request.get("instance") != 1 or request.get("service") != 0x01:
            return
        response = MessageRouterResponse.decode(message)
        data = response.data
        if not response.ok or len(data) < 15:
            return
        vendor, device_type, product = struct.unpack_from("<HHH", data)
        self._set_identity(target, {"vendor_id": vendor, "device_type": device_type, "product_code": product,
                                    "revision": f"{data[6]}.{data[7]}",
                                    "product_name": data[15:15 + data[14]].decode("latin-1")})

    def _identity(self, target: str, body: bytes, time: float, number: int, segment: Any) -> None:
        try:
            records = decode_list_identity(body)
        except Exception as exc:
            self._anomaly(time, number, segment, "enip", f"ListIdentity reply: {exc}", HEADER_SIZE)
            return
        for record in records:
            self._set_identity(target, {"vendor_id": record.vendor_id, "device_type": record.device_type,
                                        "product_code": record.product_code,
                                        "revision": f"{record.revision[0]}.{record.revision[1]}",
                                        "product_name": record.product_name})

    def _set_identity(self, target: str, identity: dict[str, Any]) -> None:
        if self.identities.get(target) == identity:
            return
        self.identities[target] = identity
        if self.fixed is None and self.declarations_for is not None:
            self.targets[target] = self.declarations_for(identity)
        self.sink({"type": "identity", "target": target, **identity,
                   "declarations": self._declarations(target).source})

    def _declarations(self, target: str) -> Declarations:
        if self.fixed is not None:
            return self.fixed
        found = self.targets.get(target)
        if found is None:
            found = self.targets[target] = Declarations()
        return found

    # -- class 1 connections -------------------------------------------------------------------------

    def _forward_open(self, time: float, number: int, key: tuple[str, int, str, int], pending: _Pending,
                      message: bytes, sockaddrs: tuple[SockAddr, ...], reply: dict[str, Any]) -> None:
        request = pending.forward_open
        assert request is not None
        if request.transport.transport_class not in (0, 1):
            return
        originator, target = key[0], key[2]
        embedded = pending.request.get("embedded")
        if embedded is not None:  # routed: the connection is with a node behind the target
            target = f"{target} via {pending.request.get('route')}"
        config, o_t_point, t_o_point = connection_points(request.connection_path)
        decl = self._declarations(key[2])
        self._numbers += 1
        fo_reply = None
        if reply["status"] == 0:
            try:
                fo_reply = ForwardOpenReply.decode(MessageRouterResponse.decode(message).data)
            except ValueError as exc:
                self._anomaly(time, number, None, "cip", f"Forward_Open reply: {exc}", None, key)
                return
        connection = Connection(
            self._numbers, originator, target, pending.time, request, fo_reply, config, o_t_point, t_o_point,
            Direction(fo_reply.ot_api_us if fo_reply else request.ot_rpi_us, request.ot_parameters.size),
            Direction(fo_reply.to_api_us if fo_reply else request.to_rpi_us, request.to_parameters.size),
            decl, frame_numbers=(pending.frame, number))
        self.totals.connections += 1
        if fo_reply is None:
            connection.ended = time
            connection.end_reason = f"refused: {reply['status_name']}"
            self._emit_connection(connection)
            return
        self.connections.append(connection)
        address = inet_aton(key[2])
        self._by_id[(address, fo_reply.ot_connection_id)] = (connection, "o_t")
        self._by_id[(address, fo_reply.to_connection_id)] = (connection, "t_o")

    def _forward_close(self, time: float, target: str, close: ForwardCloseRequest) -> None:
        for connection in list(self.connections):
            if connection.request.triad == close.triad and connection.target.split(" ")[0] == target:
                self._end(connection, time, "Forward_Close")

    def _end(self, connection: Connection, time: float, reason: str) -> None:
        connection.ended = time
        connection.end_reason = reason
        target = inet_aton(connection.target.split(" ")[0])
        for conn_id in (connection.ot_id, connection.to_id):
            if self._by_id.get((target, conn_id), (None,))[0] is connection:
                del self._by_id[(target, conn_id)]
        self.connections.remove(connection)
        self._emit_connection(connection)

    def _emit_connection(self, connection: Connection) -> None:
        if self.connection_filter is not None and self.connection_filter not in (
                connection.number, connection.ot_id, connection.to_id):
            return
        self.sink(connection.as_dict() | {"_connection": connection})

    def _io(self, time: float, number: int, src: bytes, sport: int, dst: bytes, dport: int, data: bytes) -> None:
        try:
            datagram = decode_io_datagram(data)
        except IoDatagramError as exc:
            if dport in self.io_ports or sport in self.io_ports:
                segment = Segment(17, inet_ntoa(src), sport, inet_ntoa(dst), dport, data)
                self._anomaly(time, number, segment, "class1", str(exc), exc.offset)
            return
        found = self._by_id.get((dst, datagram.connection_id)) or self._by_id.get((src, datagram.connection_id))
        if found is None:
            if dport in self.io_ports or sport in self.io_ports:
                unknown = (dst, datagram.connection_id)
                seen = self._unknown.get(unknown, 0)
                if seen or len(self._unknown) < MAX_UNKNOWN:
                    self._unknown[unknown] = seen + 1
                if seen == 0:  # reported once per id, counted in the totals
                    segment = Segment(17, inet_ntoa(src), sport, inet_ntoa(dst), dport, data)
                    self._anomaly(time, number, segment, "class1",
                                  f"frame for unknown connection 0x{datagram.connection_id:08X}", 6)
                else:
                    self.totals.anomalies += 1
            return
        connection, which = found
        direction = connection.o_t if which == "o_t" else connection.t_o
        timeout = direction.timeout or connection.timeout_s(direction)
        if direction.last_time is not None and time - direction.last_time > timeout:
            self._end(connection, direction.last_time + timeout,
                      f"timeout: {which.replace('_', '->').upper()} silent for more than {timeout * 1e3:g} ms")
            self._io(time, number, src, sport, dst, dport, data)  # now a frame of an unknown connection
            return
        self.totals.io_frames += 1
        direction.frames += 1
        direction.bytes += len(data)
        sequence = datagram.encap_sequence
        last = direction.last_sequence
        if last is not None:
            if sequence == last:
                direction.duplicates += 1
                return
            if not seq32_newer(sequence, last):
                direction.stale += 1
                return
            direction.lost += (sequence - last - 1) & 0xFFFFFFFF
        direction.last_sequence = sequence
        if direction.last_time is not None:
            interval = time - direction.last_time
            direction.intervals.add(interval)
            rpi = direction.rpi_us / 1e6
            if abs(interval - rpi) <= ON_TIME_S:
                direction.on_time += 1
            if interval > 1.5 * rpi:
                direction.late += 1
            direction.reservoir.add((time, interval))
            worst = direction.worst
            if interval > worst.floor:
                worst.add(interval, time)
        else:
            direction.first_time = time
        direction.last_time = time
        if datagram.cip_sequence != direction.last_cip_sequence:
            direction.new_data += 1
            direction.last_cip_sequence = datagram.cip_sequence
        payload = datagram.payload
        if payload == direction.last_payload:
            return
        direction.last_payload = payload
        point = connection.o_t_point if which == "o_t" else connection.t_o_point
        schema = connection.declarations.schema(point)
        if which == "o_t" and len(payload) >= 4 and (schema is None or len(payload) == schema.size + 4):
            run = bool(payload[0] & 1)
            if run != connection.run:
                if connection.run is not None or not run:
                    connection.run_change_count += 1
                    if len(connection.run_changes) < MAX_EVENTS:
                        connection.run_changes.append({"time": time, "frame": number,
                                                       "mode": "run" if run else "idle"})
                connection.run = run
            payload = payload[4:]
        if schema is None or len(payload) != schema.size:
            return
        try:
            fields = schema.decode(payload)
        except Exception:
            return
        previous = direction.last_fields
        direction.last_fields = fields
        if previous is None:
            return
        changes = field_changes(previous, fields)
        if changes:
            connection.data_change_count += 1
            if len(connection.data_changes) < MAX_EVENTS:
                connection.data_changes.append({"time": time, "frame": number, "direction": which,
                                                "assembly": point, "changes": changes})

    # -- findings ------------------------------------------------------------------------------------

    def _anomaly(self, time: float, number: int, segment: Any, layer: str, reason: str, offset: int | None,
                 key: tuple[str, int, str, int] | None = None) -> None:
        self.totals.anomalies += 1
        record: dict[str, Any] = {"type": "anomaly", "frame": number, "time": time, "layer": layer, "reason": reason,
                                  "offset": offset}
        if segment is not None:
            record.update(source=f"{segment.src}:{segment.sport}", destination=f"{segment.dst}:{segment.dport}")
        elif key is not None:
            record.update(source=f"{key[2]}:{key[3]}", destination=f"{key[0]}:{key[1]}")
        self.sink(record)

    def _unanswered(self, pending: _Pending, key: tuple[str, int, str, int], why: str) -> None:
        self.totals.unanswered += 1
        self.sink({"type": "explicit", "client": f"{key[0]}:{key[1]}", "target": f"{key[2]}:{key[3]}",
                   "session": pending.session, "command": _command_name(pending.command),
                   "request_frame": pending.frame, "time": pending.time, "request": pending.request,
                   "unanswered": why})

    def _drop_pending(self, key: tuple[str, int, str, int], why: str) -> None:
        for pending in self._pending.pop(key, ()):
            self._unanswered(pending, key, why)

    def finish(self, end_time: float | None = None) -> Totals:
        """End of the capture: unanswered requests and connections still open (or silent too long)."""
        end = end_time if end_time is not None else (self.totals.last_time or 0.0)
        for key in list(self._pending):
            self._drop_pending(key, "no reply in the capture")
        for connection in list(self.connections):
            lasts = [(d.last_time, d) for d in (connection.o_t, connection.t_o) if d.last_time is not None]
            silent = [(t + connection.timeout_s(d), d) for t, d in lasts if end - t > connection.timeout_s(d)]
            if lasts and silent:
                when, direction = min(silent, key=lambda s: s[0])
                which = "O->T" if direction is connection.o_t else "T->O"
                self._end(connection, when, f"timeout: {which} silent for more than "
                          f"{connection.timeout_s(direction) * 1e3:g} ms")
            else:
                self._end(connection, end, "open at the end of the capture")
        return self.totals
