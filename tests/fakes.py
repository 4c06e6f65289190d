"""Scripted peers for field-behaviour tests: a tiny EtherNet/IP target that answers with the bytes a
test gives it, and the class 1 producer such a target runs after a Forward_Open.

They are written from the wire (CIP Vol. 2, as the open
dissectors read it) with plain sockets and threads, so a
test can run the ``cipstack`` command in-process or as a subprocess against them. Nothing here
imports the emulator; the few cipstack codecs used build or split frames the test already states.
"""

from __future__ import annotations

import socket
import struct
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

HEADER = struct.Struct("<HHII8sI")
RR_PREFIX = bytes(6)  # interface handle UDINT 0, timeout UINT 0

LIST_IDENTITY = 0x63
REGISTER_SESSION = 0x65
UNREGISTER_SESSION = 0x66
SEND_RR_DATA = 0x6F

FORWARD_OPEN = 0x54
FORWARD_CLOSE = 0x4E
GET_ATTRIBUTE_SINGLE = 0x0E
GET_ATTRIBUTES_ALL = 0x01


def encapsulation_frames(conn: socket.socket, stop: threading.Event) -> Iterator[tuple[int, int, bytes, int, bytes]]:
    """Each whole encapsulation frame a peer sends on ``conn`` (a short recv timeout set), as
    (command, session, sender context, options, data), until it closes or ``stop`` is set."""
    buffer = b""
    while not stop.is_set():
        try:
            chunk = conn.recv(65536)
        except TimeoutError:
            continue
        except OSError:
            return
        if not chunk:
            return
        buffer += chunk
        while len(buffer) >= 24:
            command, length, session, _status, context, options = HEADER.unpack_from(buffer)
            if len(buffer) < 24 + length:
                break
            body, buffer = buffer[24:24 + length], buffer[24 + length:]
            yield command, session, context, options, body


def cpf(*items: tuple[int, bytes]) -> bytes:
    """A Common Packet Format: item count, then type/length/data of each item."""
    return struct.pack("<H", len(items)) + b"".join(struct.pack("<HH", t, len(d)) + d for t, d in items)


def split_cpf(raw: bytes) -> list[tuple[int, bytes]]:
    (count,) = struct.unpack_from("<H", raw)
    pos, items = 2, []
    for _ in range(count):
        item_type, length = struct.unpack_from("<HH", raw, pos)
        items.append((item_type, raw[pos + 4:pos + 4 + length]))
        pos += 4 + length
    return items


def rr_body(mr_reply: bytes, *extra: tuple[int, bytes]) -> bytes:
    """A SendRRData reply body: prefix, Null Address, Unconnected Data, any extra items."""
    return RR_PREFIX + cpf((0x0000, b""), (0x00B2, mr_reply), *extra)


def mr_reply(service: int, status: int = 0, extended: tuple[int, ...] = (), data: bytes = b"") -> bytes:
    return (bytes((service | 0x80, 0, status, len(extended))) + b"".join(struct.pack("<H", e) for e in extended)
            + data)


def sockaddr(host: str, port: int) -> bytes:
    return struct.pack(">hH4s8s", 2, port, socket.inet_aton(host), bytes(8))


@dataclass
class MrRequest:
    """A message-router request as the fake received it."""

    service: int
    path: bytes
    data: bytes
    items: list[tuple[int, bytes]]
    peer: tuple[str, int]

    @property
    def class_instance(self) -> tuple[int, int]:
        path = self.path
        return path[1], path[3]


#: A request handler returns a SendRRData reply body, or None for the fake's default answer.
Handler = Callable[[MrRequest], "bytes | None"]


@dataclass
class ScriptedTarget:
    """An EtherNet/IP target on loopback whose SendRRData replies a test scripts.

    ``handler`` sees each message-router request; what it returns is sent as the reply body
    (the header echoes the request's command and sender context). Without an answer from
    it: Get_Attribute_Single of Assembly attribute 4 answers from ``assembly_sizes``,
    Forward_Close succeeds, anything else is 0x08. ListIdentity answers ``identity`` (an
    item's data; none: no item)."""

    handler: Handler | None = None
    identity: bytes | None = None
    assembly_sizes: dict[int, int] = field(default_factory=dict)
    host: str = "127.0.0.1"
    requests: list[MrRequest] = field(default_factory=list)
    errors: list[str] = field(default_factory=list)
    port: int = 0

    def __post_init__(self) -> None:
        self._listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self._listener.bind((self.host, 0))
        self._listener.listen(8)
        self.port = self._listener.getsockname()[1]
        self._stop = threading.Event()
        self._threads = [threading.Thread(target=self._accept, daemon=True)]
        self._threads[0].start()

    @property
    def address(self) -> str:
        return f"{self.host}:{self.port}"

    def services(self, service: int) -> list[MrRequest]:
        return [r for r in self.requests if r.service == service]

    def close(self) -> None:
        # Stop and join every thread before closing a socket: a socket closed under a thread
        # blocked on it frees its descriptor number for the next test's socket while the thread
        # still uses the number.
        self._stop.set()
        for thread in self._threads:
            thread.join(5)
        self._listener.close()

    def __enter__(self) -> ScriptedTarget:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _accept(self) -> None:
        self._listener.settimeout(0.05)
        while not self._stop.is_set():
            try:
                conn, peer = self._listener.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            conn.settimeout(0.05)
            thread = threading.Thread(target=self._serve, args=(conn, peer), daemon=True)
            self._threads.append(thread)
            thread.start()

    def _serve(self, conn: socket.socket, peer: tuple[str, int]) -> None:
        with conn:
            for command, session, context, _options, body in encapsulation_frames(conn, self._stop):
                try:
                    reply = self._answer(command, body, peer)
                except Exception as exc:  # a broken script: say so, the test then fails on the reset
                    self.errors.append(f"{type(exc).__name__}: {exc}")
                    raise
                if reply is None:
                    continue
                session = session or 0x11223344
                try:
                    conn.sendall(HEADER.pack(command, len(reply), session, 0, context, 0) + reply)
                except OSError:
                    return

    def _answer(self, command: int, body: bytes, peer: tuple[str, int]) -> bytes | None:
        if command == REGISTER_SESSION:
            return body
        if command == LIST_IDENTITY:
            return cpf((0x000C, self.identity)) if self.identity is not None else struct.pack("<H", 0)
        if command != SEND_RR_DATA:
            return None
        items = split_cpf(body[6:])
        raw = next(d for t, d in items if t == 0x00B2)
        request = MrRequest(raw[0], raw[2:2 + 2 * raw[1]], raw[2 + 2 * raw[1]:], items, peer)
        self.requests.append(request)
        if self.handler is not None:
            scripted = self.handler(request)
            if scripted is not None:
                return scripted
        if request.service == GET_ATTRIBUTE_SINGLE and request.path[:2] == b"\x20\x04":
            instance = request.path[3]
            if instance in self.assembly_sizes:
                return rr_body(mr_reply(request.service, data=struct.pack("<H", self.assembly_sizes[instance])))
            return rr_body(mr_reply(request.service, 0x05))
        if request.service == FORWARD_CLOSE:
            triad = request.data[2:10]
            return rr_body(mr_reply(FORWARD_CLOSE, data=triad + b"\x00\x00"))
        return rr_body(mr_reply(request.service, 0x08))


def forward_open_fields(request: MrRequest) -> dict[str, int | bytes]:
    """The fields of a (small) Forward_Open request a fake needs to answer it."""
    data = request.data
    (_tick, _ticks, _ot_id, to_id, _serial, _vendor, _originator, _mult, ot_rpi, ot_params, to_rpi, to_params,
     transport, words) = struct.unpack_from("<BBIIHHIB3xIHIHBB", data)
    return {"ot_rpi": ot_rpi, "to_rpi": to_rpi, "ot_size": ot_params & 0x1FF, "to_size": to_params & 0x1FF,
            "to_id": to_id, "triad": data[10:18], "path": data[36:36 + 2 * words], "transport": transport,
            "timeout_multiplier": _mult}


def to_port(request: MrRequest) -> int | None:
    """The originator's T->O port from the request's Sockaddr Info T->O item."""
    for item_type, data in request.items:
        if item_type == 0x8001:
            return struct.unpack_from(">H", data, 2)[0]
    return None


class ClassOneProducer:
    """The class 1 side of a scripted target: a UDP socket that records the O->T datagrams it
    receives and sends T->O datagrams of one connection at a fixed period."""

    def __init__(self, host: str = "127.0.0.1") -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((host, 0))
        self.sock.settimeout(0.05)
        self.port = self.sock.getsockname()[1]
        self.received: list[bytes] = []
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._start(self._receive)

    def _start(self, target: Callable[[], None]) -> None:
        thread = threading.Thread(target=target, daemon=True)
        self._threads.append(thread)
        thread.start()

    def _receive(self) -> None:
        while not self._stop.is_set():
            try:
                data, _ = self.sock.recvfrom(2048)
            except TimeoutError:
                continue
            except OSError:
                return
            self.received.append(data)

    def produce(self, to_id: int, destination: tuple[str, int], payload: bytes | Callable[[int], bytes],
                period: float, count: int = 100_000) -> None:
        """Send ``payload`` (or ``payload(sequence)``) on connection ``to_id`` every ``period`` seconds
        (at most ``count`` packets)."""
        def run() -> None:
            start = time.monotonic()
            for sequence in range(1, count + 1):
                if self._stop.is_set():
                    return
                data = payload(sequence) if callable(payload) else payload
                datagram = (struct.pack("<HHHIIHHH", 2, 0x8002, 8, to_id, sequence, 0x00B1, 2 + len(data),
                                        sequence & 0xFFFF) + data)
                try:
                    self.sock.sendto(datagram, destination)
                except OSError:
                    return
                delay = start + sequence * period - time.monotonic()
                if delay > 0:
                    time.sleep(delay)

        self._start(run)

    def ot_payload_sizes(self, ot_id: int) -> set[int]:
        """Connected Data item lengths of the O->T datagrams received on ``ot_id``."""
        sizes = set()
        for data in self.received:
            if len(data) >= 18 and struct.unpack_from("<I", data, 6)[0] == ot_id:
                sizes.add(struct.unpack_from("<H", data, 16)[0])
        return sizes

    def close(self) -> None:
        self._stop.set()
        for thread in self._threads:
            thread.join(5)
        self.sock.close()
