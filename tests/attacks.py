"""Attack cases against a running adapter, as a hostile peer on the same network would try them.

Each case talks to the adapter over loopback sockets only (frames built here byte by byte), so the
same cases run against an in-process adapter in the suite (``tests/test_hardening.py``, small
``scale``, seconds) and against a subprocess at length (``benchmarks/soak.py``, minutes, with its
RSS and descriptor counts). A case returns its figures (a dict) and raises ``AssertionError`` when
the adapter breaks a rule: a crash, a refusal it should not make, an acceptance it should not make,
or a well-behaved client left unserved.

Cases are entries of ``CASES``: name, what the adapter must do, the function, and the options the
adapter must run with (``AttackTarget.options``). A new case (Modbus TCP, state files, ...) is one
more function and one more entry; a case that needs another listener reads it from
``AttackTarget.extra`` (e.g. ``extra["modbus_port"]``) and names it in ``Case.needs``.

Loopback sources: the attacker uses 127.0.0.2 and above, the well-behaved client 127.0.0.1, so
per-host limits are exercised as they would be between two machines.
"""

from __future__ import annotations

import random
import select
import socket
import struct
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

HEADER = struct.Struct("<HHII8sI")
HEADER_SIZE = 24
NOP, LIST_IDENTITY, REGISTER, UNREGISTER, SEND_RR = 0x0000, 0x0063, 0x0065, 0x0066, 0x006F
GET_NAME = bytes((0x0E, 3, 0x20, 0x01, 0x24, 0x01, 0x30, 0x07))  # Identity 1/1/7
IDENTITY_NAME = b"\x04CENT"

#: The limits the attack target runs with (adapter options); the cases derive their expectations from them.
OPTIONS = {"max_sessions": 32, "max_connections": 4, "max_io_connections": 8, "max_tcp_connections": 1400}


# -- wire bytes ----------------------------------------------------------------------------------------
def frame(command: int, body: bytes = b"", session: int = 0, context: bytes = b"\x00" * 8) -> bytes:
    return HEADER.pack(command, len(body), session, 0, context, 0) + body


def cpf(*items: tuple[int, bytes]) -> bytes:
    return struct.pack("<H", len(items)) + b"".join(struct.pack("<HH", t, len(d)) + d for t, d in items)


def rr_body(mr: bytes, *extra: tuple[int, bytes]) -> bytes:
    return struct.pack("<IH", 0, 10) + cpf((0x0000, b""), (0x00B2, mr), *extra)


def sockaddr_item(host: str, port: int) -> tuple[int, bytes]:
    """Sockaddr Info T->O (0x8001): where T->O data goes (big-endian fields)."""
    return 0x8001, struct.pack(">HH4s8x", 2, port, socket.inet_aton(host))


def forward_open(serial: int, *, transport: int, ot_params: int, to_params: int, rpi_us: int, path: bytes,
                 multiplier: int = 0, vendor: int = 0x1234, originator_serial: int = 0xC0FFEE) -> bytes:
    data = struct.pack("<BBIIHHIB3xIHIHBB", 0x0A, 0x0E, 0, 0x2000 + serial, serial, vendor, originator_serial,
                       multiplier, rpi_us, ot_params, rpi_us, to_params, transport, len(path) // 2) + path
    return bytes((0x54, 2, 0x20, 0x06, 0x24, 0x01)) + data


def class3_open(serial: int) -> bytes:
    return forward_open(serial, transport=0xA3, ot_params=0x43F4, to_params=0x43F4, rpi_us=1_000_000,
                        path=b"\x20\x02\x24\x01", multiplier=3)


#: ACG-ET2 exclusive owner 21 -> 71 (4 data bytes each way): O->T 4 + 6, T->O 4 + 2, point-to-point.
ACG_OWNER_PATH = b"\x20\x04\x24\x01\x2C\x15\x2C\x47"
ACG_INPUT_ONLY_PATH = b"\x20\x04\x24\x01\x2C\xC6\x2C\x47"


def class1_open(serial: int, rpi_us: int = 10_000, multiplier: int = 0, path: bytes = ACG_OWNER_PATH,
                ot_size: int = 10) -> bytes:
    return forward_open(serial, transport=0x01, ot_params=0x4000 | ot_size, to_params=0x4000 | 6,
                        rpi_us=rpi_us, path=path, multiplier=multiplier)


def forward_close(serial: int, path: bytes) -> bytes:
    data = struct.pack("<BBHHIBB", 0x0A, 0x0E, serial, 0x1234, 0xC0FFEE, len(path) // 2, 0) + path
    return bytes((0x4E, 2, 0x20, 0x06, 0x24, 0x01)) + data


def io_datagram(connection_id: int, sequence: int, payload: bytes) -> bytes:
    """Class 1 O->T: Sequenced Address (id, encapsulation sequence) + Connected Data (CIP sequence, payload)."""
    return struct.pack("<HHHIIHHH", 2, 0x8002, 8, connection_id, sequence, 0x00B1, 2 + len(payload),
                       sequence & 0xFFFF) + payload


def cip_reply(frame_body: bytes) -> tuple[int, tuple[int, ...], bytes]:
    """(general status, extended words, data) of the message-router reply in a SendRRData reply."""
    (count,) = struct.unpack_from("<H", frame_body, 6)
    position = 8
    mr = b""
    for _ in range(count):
        item_type, length = struct.unpack_from("<HH", frame_body, position)
        if item_type == 0x00B2:
            mr = frame_body[position + 4:position + 4 + length]
        position += 4 + length
    words = mr[3]
    return mr[2], struct.unpack_from(f"<{words}H", mr, 4), mr[4 + 2 * words:]


# -- clients -------------------------------------------------------------------------------------------
class Client:
    """A blocking encapsulation client from a chosen loopback source address."""

    def __init__(self, port: int, source: str = "127.0.0.1", register: bool = True, timeout: float = 5.0) -> None:
        self.sock = socket.socket()
        self.sock.settimeout(timeout)
        self.sock.bind((source, 0))
        self.sock.connect(("127.0.0.1", port))
        self.session = 0
        if register:
            status, session, _ = self.exchange(REGISTER, b"\x01\x00\x00\x00")
            assert status == 0, f"RegisterSession refused with 0x{status:04X}"
            self.session = session

    def exchange(self, command: int, body: bytes = b"") -> tuple[int, int, bytes]:
        """Send one frame, read its reply: (encapsulation status, session, body)."""
        self.sock.sendall(frame(command, body, self.session))
        head = self._read(HEADER_SIZE)
        _command, length, session, status, _context, _options = HEADER.unpack(head)
        return status, session, self._read(length)

    def request(self, mr: bytes, *extra: tuple[int, bytes]) -> tuple[int, tuple[int, ...], bytes]:
        status, _, body = self.exchange(SEND_RR, rr_body(mr, *extra))
        assert status == 0, f"SendRRData answered 0x{status:04X}"
        return cip_reply(body)

    def _read(self, n: int) -> bytes:
        out = b""
        while len(out) < n:
            chunk = self.sock.recv(n - len(out))
            if not chunk:
                raise ConnectionError("closed by the adapter")
            out += chunk
        return out

    def close(self) -> None:
        self.sock.close()

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass
class AttackTarget:
    """Where the adapter listens, and how to look at it from outside."""

    port: int
    io_port: int
    #: RSS (bytes) and open descriptors of the adapter process, when it is another process.
    rss: Callable[[], int] = lambda: 0
    fds: Callable[[], int] = lambda: 0
    #: Lines the adapter has logged so far (stderr), when visible.
    log_lines: Callable[[], list[str]] = list
    extra: dict[str, Any] = field(default_factory=dict)


def served(target: AttackTarget, client: Client) -> None:
    """The well-behaved client's request is answered, right."""
    status, _extended, data = client.request(GET_NAME)
    assert status == 0 and data == IDENTITY_NAME, f"Identity 1/1/7 answered {status:#x} {data!r}"


def wait_for(condition: Callable[[], bool], timeout: float = 3.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.02)
    return condition()


# -- cases ---------------------------------------------------------------------------------------------
#: Connection attempts of a flood in flight at once: fewer than the adapter accepts in one pass (32),
#: so that the well-behaved client's answer after each burst means the burst has left the listen
#: backlog; a backlog kept full drops SYNs, which the client sends again only a second later.
FLOOD_BURST = 20


def connection_flood(target: AttackTarget, scale: int, rng: random.Random) -> dict[str, Any]:
    """``scale`` connection attempts from 127.0.0.2, ``FLOOD_BURST`` of them at once (each held
    briefly, a few kept open), while a well-behaved client at 127.0.0.1 is served after every burst
    and a new one can still connect."""
    per_host = (OPTIONS["max_tcp_connections"] + 1) // 2
    held: list[socket.socket] = []
    refused = 0
    linger = struct.pack("ii", 1, 0)
    with Client(target.port) as good:
        for first in range(0, scale, FLOOD_BURST):
            burst: list[socket.socket] = []
            for _ in range(min(FLOOD_BURST, scale - first)):
                sock = socket.socket()
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, linger)
                sock.bind(("127.0.0.2", 0))
                sock.setblocking(False)
                sock.connect_ex(("127.0.0.1", target.port))
                burst.append(sock)
            deadline = time.monotonic() + 5.0
            pending = list(burst)
            while pending and time.monotonic() < deadline:
                _readable, writable, _ = select.select([], pending, [], 0.1)
                pending = [sock for sock in pending if sock not in writable]
            for sock in burst:
                if sock in pending or sock.getsockopt(socket.SOL_SOCKET, socket.SO_ERROR):
                    refused += 1
                    sock.close()
                elif len(held) < 64 and rng.random() < 0.01:
                    held.append(sock)
                else:
                    sock.close()
            served(target, good)
        with Client(target.port) as newcomer:
            served(target, newcomer)
        served(target, good)
    for sock in held:
        sock.close()
    return {"attempts": scale, "held": len(held), "connect_errors": refused, "per_host_limit": per_host}


def descriptors_above_1024(target: AttackTarget, scale: int, rng: random.Random) -> dict[str, Any]:
    """``scale`` idle connections held at once (from two attacker addresses, under the per-host
    limit): the adapter's descriptors pass 1,024 and it still serves, old and new clients alike."""
    per_host = (OPTIONS["max_tcp_connections"] + 1) // 2
    held: list[socket.socket] = []
    try:
        for index in range(scale):
            sock = socket.socket()
            sock.bind((f"127.0.0.{2 + index // per_host}", 0))
            sock.connect(("127.0.0.1", target.port))
            held.append(sock)
        # The last ones are real sessions: their replies come over descriptors above 1,024.
        with Client(target.port, source="127.0.0.9") as late:
            served(target, late)
        fds_held = target.fds()
        with Client(target.port) as good:
            served(target, good)
    finally:
        for sock in held:
            sock.close()
    return {"connections_held": len(held), "adapter_fds_while_held": fds_held}


def excess_connections_closed(target: AttackTarget, scale: int, rng: random.Random) -> dict[str, Any]:
    """One host opens more connections than its per-host limit: the excess is closed at once
    (a read sees the end), the admitted ones are served, and the refusals are one log line per 10 s."""
    per_host = (OPTIONS["max_tcp_connections"] + 1) // 2
    lines_before = len(target.log_lines())
    held: list[socket.socket] = []
    closed = 0
    try:
        for _ in range(per_host + scale):
            sock = socket.socket()
            sock.bind(("127.0.0.3", 0))
            sock.connect(("127.0.0.1", target.port))
            held.append(sock)
        for sock in held[per_host:]:
            sock.settimeout(3.0)
            try:
                closed += sock.recv(1) == b""
            except ConnectionResetError:
                closed += 1
    finally:
        for sock in held:
            sock.close()
    assert closed == scale, f"{scale} connections over the per-host limit, {closed} closed"
    refused_lines = [line for line in target.log_lines()[lines_before:] if "refused" in line]
    assert len(refused_lines) <= 2, refused_lines
    return {"over_limit": scale, "closed_at_accept": closed, "log_lines": len(refused_lines)}


def wrong_size_datagrams(target: AttackTarget, scale: int, rng: random.Random) -> dict[str, Any]:
    """Wrong-size class 1 datagrams neither feed the watchdog nor move the sequence window:
    (a) after one good datagram, 5-byte-data datagrams only: the connection times out; (b) one
    wrong-size datagram with sequence 0x80000000 between good ones: the good ones keep it alive."""
    udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    udp.bind(("127.0.0.1", 0))
    io = ("127.0.0.1", target.io_port)
    results = {}
    try:
        with Client(target.port) as client:
            # (a) RPI 10 ms, multiplier 0: 40 ms timeout.
            status, extended, data = client.request(class1_open(0x0A01), sockaddr_item("127.0.0.1",
                                                                                       udp.getsockname()[1]))
            assert status == 0, (status, extended)
            (ot_id,) = struct.unpack_from("<I", data)
            udp.sendto(io_datagram(ot_id, 1, b"\x01\x00\x00\x00" + bytes(4)), io)
            for sequence in range(2, 2 + max(scale, 30)):
                udp.sendto(io_datagram(ot_id, sequence, b"\x01\x00\x00\x00" + bytes(5)), io)
                time.sleep(0.01)
            status, extended, _ = client.request(forward_close(0x0A01, ACG_OWNER_PATH))
            assert (status, extended) == (0x01, (0x0107,)), (
                f"wrong-size datagrams kept the connection alive: Forward_Close answered {status:#x} {extended}")
            results["a_timed_out"] = True
            # (b) a poisoning sequence number in a wrong-size datagram, then good datagrams.
            status, extended, data = client.request(class1_open(0x0A02), sockaddr_item("127.0.0.1",
                                                                                       udp.getsockname()[1]))
            assert status == 0, (status, extended)
            (ot_id,) = struct.unpack_from("<I", data)
            udp.sendto(io_datagram(ot_id, 1, b"\x01\x00\x00\x00" + bytes(4)), io)
            udp.sendto(io_datagram(ot_id, 0x80000000, b"\x01\x00\x00\x00" + bytes(5)), io)
            for sequence in range(2, 2 + max(scale, 30)):
                udp.sendto(io_datagram(ot_id, sequence, b"\x01\x00\x00\x00" + bytes(4)), io)
                time.sleep(0.01)
            status, extended, _ = client.request(forward_close(0x0A02, ACG_OWNER_PATH))
            assert status == 0, f"good datagrams after a wrong-size one were refused: close answered {extended}"
            results["b_alive"] = True
    finally:
        udp.close()
    return results


def list_identity_flood(target: AttackTarget, scale: int, rng: random.Random) -> dict[str, Any]:
    """``scale`` UDP ListIdentity asking for the longest delay (0xFFFF ms) from 4 source addresses:
    few replies per source (no amplification), every reply within 2 s, memory back near the start."""
    rss_before = target.rss()
    sockets = []
    for index in range(4):
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind((f"127.0.0.{10 + index}", 0))
        sock.setblocking(False)
        sockets.append(sock)
    request = frame(LIST_IDENTITY, context=b"\xff\xff" + bytes(6))
    replies = 0
    started = time.monotonic()
    try:
        for count in range(scale):
            sock = sockets[count % len(sockets)]
            try:
                sock.sendto(request, ("127.0.0.1", target.port))
            except BlockingIOError:
                time.sleep(0.001)
            if count % 256 == 0:
                replies += _drain(sockets)
        rss_peak = target.rss()
        flood_seconds = time.monotonic() - started
        deadline = time.monotonic() + 2.2  # every reply is due within 2 s of its request
        while time.monotonic() < deadline:
            replies += _drain(sockets)
            time.sleep(0.05)
        time.sleep(1.0)
        late = _drain(sockets)
        with Client(target.port) as good:
            served(target, good)
    finally:
        for sock in sockets:
            sock.close()
    assert late == 0, f"{late} replies more than 2 s after the last request"
    # 4 sources x at most 4 pending each; a slot frees when its reply leaves, after 1 s on average
    # (uniform 0..2 s): about 4 replies a second per source, twice that as the bound.
    bound = len(sockets) * 4 * 2 * (int(flood_seconds) + 3)
    assert replies <= bound, f"{replies} replies to {scale} requests (bound {bound})"
    rss_after = target.rss()
    if rss_before:  # the adapter in another process: its own memory is back near the start
        assert rss_after - rss_before < 16 * 2**20, f"RSS {rss_before} -> {rss_after} bytes"
    return {"requests": scale, "replies": replies, "flood_seconds": round(flood_seconds, 2),
            "rss_before": rss_before, "rss_peak": rss_peak, "rss_after": rss_after}


def _drain(sockets: list[socket.socket]) -> int:
    n = 0
    for sock in sockets:
        while True:
            try:
                data = sock.recv(2048)
            except BlockingIOError:
                break
            assert data[:2] == b"\x63\x00", data[:24].hex()
            n += 1
    return n


def forward_close_from_elsewhere(target: AttackTarget, scale: int, rng: random.Random) -> dict[str, Any]:
    """A Forward_Close, or a duplicate Forward_Open, with another originator's triad from another
    address is "connection not found" (0x0107) and touches nothing; the owner's own close works."""
    udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    udp.bind(("127.0.0.1", 0))
    try:
        with Client(target.port) as owner, Client(target.port, source="127.0.0.5") as intruder:
            status, extended, _ = owner.request(class3_open(0x0B01))
            assert status == 0, (status, extended)
            status, extended, _ = owner.request(class1_open(0x0B02, rpi_us=100_000, multiplier=3),
                                                   sockaddr_item("127.0.0.1", udp.getsockname()[1]))
            assert status == 0, (status, extended)
            for serial, path in ((0x0B01, b"\x20\x02\x24\x01"), (0x0B02, ACG_OWNER_PATH)):
                status, extended, _ = intruder.request(forward_close(serial, path))
                assert (status, extended) == (0x01, (0x0107,)), (serial, status, extended)
            # A duplicate Forward_Open of the owner's triads from the intruder's address: not found.
            status, extended, _ = intruder.request(class3_open(0x0B01))
            assert (status, extended) == (0x01, (0x0107,)), ("class 3 triad reused elsewhere", status, extended)
            status, extended, _ = intruder.request(class1_open(0x0B02, rpi_us=100_000, multiplier=3))
            assert (status, extended) == (0x01, (0x0107,)), ("class 1 triad reused elsewhere", status, extended)
            # The owner's connections are untouched: its duplicate is "in use", its closes succeed.
            status, extended, _ = owner.request(class3_open(0x0B01))
            assert (status, extended) == (0x01, (0x0100,)), ("the owner's duplicate", status, extended)
            for serial, path in ((0x0B01, b"\x20\x02\x24\x01"), (0x0B02, ACG_OWNER_PATH)):
                status, extended, _ = owner.request(forward_close(serial, path))
                assert status == 0, ("the owner's own close", serial, extended)
            # Once the owner closed them, the triads are free for anyone.
            status, extended, _ = intruder.request(class3_open(0x0B01))
            assert status == 0, ("a free triad", status, extended)
            status, extended, _ = intruder.request(forward_close(0x0B01, b"\x20\x02\x24\x01"))
            assert status == 0, ("the intruder's own class 3 connection", extended)
    finally:
        udp.close()
    return {"closes_refused": 2}


def sessions_per_host(target: AttackTarget, scale: int, rng: random.Random) -> dict[str, Any]:
    """One address registers sessions until refused (0x0002) at half the session limit; another
    address still gets one."""
    per_host = (OPTIONS["max_sessions"] + 1) // 2
    clients: list[Client] = []
    try:
        statuses = []
        for _ in range(per_host + max(scale, 1)):
            client = Client(target.port, source="127.0.0.6", register=False)
            clients.append(client)
            status, _, _ = client.exchange(REGISTER, b"\x01\x00\x00\x00")
            statuses.append(status)
        assert statuses[:per_host] == [0] * per_host and set(statuses[per_host:]) == {0x0002}, statuses
        with Client(target.port) as other:
            served(target, other)
    finally:
        for client in clients:
            client.close()
    return {"sessions_held": per_host, "refused": len(statuses) - per_host}


def connection_limits(target: AttackTarget, scale: int, rng: random.Random) -> dict[str, Any]:
    """--max-connections bounds class 3 and --max-io-connections class 1: one more is 0x0113."""
    results = {}
    with Client(target.port) as client:
        for kind, limit, opener, path in (
                ("class3", OPTIONS["max_connections"], class3_open, b"\x20\x02\x24\x01"),
                ("class1", OPTIONS["max_io_connections"],
                 lambda s: class1_open(s, rpi_us=100_000, multiplier=7, path=ACG_INPUT_ONLY_PATH, ot_size=2),
                 ACG_INPUT_ONLY_PATH)):
            opened = []
            for serial in range(0x0C00, 0x0C00 + limit + 2):
                status, extended, _ = client.request(opener(serial))
                if status:
                    assert (status, extended[:1]) == (0x01, (0x0113,)), (kind, status, extended)
                    break
                opened.append(serial)
            assert len(opened) == limit, f"{kind}: {len(opened)} opened, limit {limit}"
            for serial in opened:
                assert client.request(forward_close(serial, path))[0] == 0
            results[kind] = len(opened)
    return results


def random_frames(target: AttackTarget, scale: int, rng: random.Random) -> dict[str, Any]:
    """``scale`` random and mutated encapsulation frames over TCP and datagrams over UDP 44818 and
    the I/O port; the adapter answers a well-behaved client after every batch."""
    seeds = [frame(LIST_IDENTITY), frame(SEND_RR, rr_body(GET_NAME)), frame(REGISTER, b"\x01\x00\x00\x00"),
             frame(SEND_RR, rr_body(class3_open(0x0D01))), io_datagram(1, 1, bytes(8)), frame(NOP, bytes(8))]
    udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    udp.bind(("127.0.0.7", 0))
    cases = closed = 0
    try:
        with Client(target.port) as good:
            attacker: Client | None = None
            for count in range(scale):
                data = bytearray(rng.choice(seeds))
                for _ in range(rng.randint(1, 4)):
                    position = rng.randrange(len(data))
                    data[position] = rng.randrange(256)
                if rng.random() < 0.2:
                    tail = bytes(rng.randrange(256) for _ in range(rng.randrange(8)))
                    data = data[:rng.randrange(len(data) + 1)] + tail
                where = rng.random()
                if where < 0.5:
                    if attacker is None:
                        attacker = Client(target.port, source="127.0.0.7", timeout=1.0)
                    try:
                        attacker.sock.sendall(bytes(data))
                    except OSError:
                        closed += 1
                        attacker.close()
                        attacker = None
                else:
                    port = target.port if where < 0.75 else target.io_port
                    udp.sendto(bytes(data), ("127.0.0.1", port))
                cases += 1
                if count % 200 == 199:
                    served(target, good)
                    if attacker is not None:
                        attacker.close()
                        attacker = None
            if attacker is not None:
                attacker.close()
            served(target, good)
    finally:
        udp.close()
    return {"cases": cases, "attacker_connections_closed": closed}


def modbus_frames(target: AttackTarget, scale: int, rng: random.Random) -> dict[str, Any]:
    """Modbus TCP (issue items 1 and 8): a request with bytes beyond its function's PDU is refused with
    exception 0x03 and writes nothing; ``scale`` connections of random and mutated MBAP frames, and
    more connections from one address than its share, leave the port serving a well-behaved client."""
    port = target.extra["modbus_port"]
    read_acc = bytes.fromhex("0009 0000 0006 01 03 1f01 0001")

    def read_value(sock: socket.socket) -> bytes:
        sock.sendall(read_acc)
        reply = b""
        while len(reply) < 11:
            chunk = sock.recv(11 - len(reply))
            assert chunk, "the Modbus port closed a well-behaved connection"
            reply += chunk
        return reply

    def well_formed(reply: bytes) -> bool:
        """A read of one register answered: transaction echoed, 5 bytes follow, function 03, 2 data bytes
        (the value itself may have been written by a mutated frame: a valid write is no attack)."""
        return reply[:9] == bytes.fromhex("0009 0000 0005 01 03 02")

    with socket.create_connection(("127.0.0.1", port), timeout=3) as good:
        before = read_value(good)
        good.sendall(bytes.fromhex("0001 0000 0008 01 06 1f01 0064 abcd"))      # the frame
        assert good.recv(64) == bytes.fromhex("0001 0000 0003 01 86 03"), "bytes beyond the PDU not refused"
        assert read_value(good) == before, "a refused write changed the register"
        closed = 0
        valid = [bytes.fromhex("0002 0000 0006 01 03 0300 0001"), bytes.fromhex("0003 0000 0006 01 04 0300 0002"),
                 bytes.fromhex("0004 0000 0009 01 10 1f01 0001 02 0032")]
        for attempt in range(scale):
            data = bytearray(rng.choice(valid))
            for _ in range(rng.randint(0, 4)):
                data[rng.randrange(len(data))] = rng.randrange(256)
            if rng.random() < 0.3:
                data = bytearray(rng.randbytes(rng.randint(1, 300)))
            with socket.socket() as sock:
                sock.settimeout(0.05)   # a frame the port waits to complete: move on, it closes on our close
                sock.bind(("127.0.0.2", 0))
                try:
                    sock.connect(("127.0.0.1", port))
                    sock.sendall(bytes(data))
                    closed += sock.recv(512) == b""
                except (TimeoutError, ConnectionError):
                    pass
            if attempt % 50 == 0:
                assert well_formed(read_value(good)), "the well-behaved client got no proper reply"
        # One address holding more than its share of connections: the excess is closed at accept.
        per_host = (OPTIONS["max_tcp_connections"] + 1) // 2
        held = []
        try:
            for _ in range(min(per_host, 64)):
                held.append(socket.create_connection(("127.0.0.1", port), timeout=3, source_address=("127.0.0.3", 0)))
            assert well_formed(read_value(good)), "the well-behaved client got no proper reply"
        finally:
            for sock in held:
                sock.close()
        assert well_formed(read_value(good)), "the well-behaved client got no proper reply"
    return {"frames": scale, "closed_by_the_port": closed}


@dataclass(frozen=True)
class Case:
    name: str
    run: Callable[[AttackTarget, int, random.Random], dict[str, Any]]
    #: Scale in the suite (seconds in all) and in the soak (minutes in all).
    ci_scale: int
    soak_scale: int
    #: Listeners the case needs beyond EtherNet/IP (keys of ``AttackTarget.extra``).
    needs: tuple[str, ...] = ()


CASES: list[Case] = [
    Case("connection_flood", connection_flood, 10_000, 100_000),
    Case("descriptors_above_1024", descriptors_above_1024, 1_100, 1_300),
    Case("excess_connections_closed", excess_connections_closed, 20, 500),
    Case("wrong_size_datagrams", wrong_size_datagrams, 30, 300),
    Case("list_identity_flood", list_identity_flood, 5_000, 500_000),
    Case("forward_close_from_elsewhere", forward_close_from_elsewhere, 1, 1),
    Case("sessions_per_host", sessions_per_host, 2, 50),
    Case("connection_limits", connection_limits, 1, 1),
    Case("random_frames", random_frames, 2_000, 200_000),
    Case("modbus_frames", modbus_frames, 300, 5_000, needs=("modbus",)),
]

__all__ = ["CASES", "OPTIONS", "AttackTarget", "Case", "Client"]
