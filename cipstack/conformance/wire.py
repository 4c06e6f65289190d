"""The battery's own view of the wire: blocking sockets that send exactly the bytes a check
builds (well formed or not) and return exactly what came back, every exchange recorded.

The scanner's clients are tolerant by design and would hide what a check looks for (a status in
the header, a reply that should not exist, a connection the target closed), so the battery builds
its requests itself, byte by byte, and sees every reply frame. What it shares with them is the
originator core's reading of the stream: frames cut by ``FrameBuffer``, SendRRData replies read
by ``rr_reply_items``. Requests are spaced by ``MIN_GAP`` so that the battery never floods a device.
"""

from __future__ import annotations

import contextlib
import select
import socket
import time
from collections.abc import Iterator
from dataclasses import dataclass

from ..cip.messages import MessageRouterRequest, MessageRouterResponse
from ..eip.originator.core import FrameBuffer, rr_reply_items, rr_request_body
from ..eip.originator.replies import MalformedReplyError
from ..eip.wire.cpf import Item
from ..eip.wire.encapsulation import HEADER, HEADER_SIZE, REGISTER_SESSION_DATA, Command, EncapsulationHeader
from ..errors import PeerUnreachable
from .model import Exchange

#: At most one request every 2 ms from one probe: the battery's rate bound.
MIN_GAP = 0.002
#: A target that does not answer is asked once more this long after, before it is called silent.
SILENCE_RETRY_S = 0.5


class TargetUnreachable(PeerUnreachable):
    """The target cannot be reached, or does not speak EtherNet/IP: reported in one line."""


@dataclass
class Frame:
    """A reply frame: its header, its data and the whole frame as received."""

    header: EncapsulationHeader
    body: bytes
    raw: bytes


def frame(command: int, data: bytes = b"", session: int = 0, status: int = 0, context: bytes = b"cipconf\x00",
          options: int = 0, length: int | None = None) -> bytes:
    """An encapsulation frame; ``length`` overrides the length field (a wrong length)."""
    return HEADER.pack(command, len(data) if length is None else length, session, status, context, options) + data


def rr_data(request: bytes, extra: tuple[Item, ...] = ()) -> bytes:
    """SendRRData data: interface handle, timeout, Null Address + Unconnected Data (+ extra items)."""
    return rr_request_body(request, extra)


class Liveness:
    """Whether the target still answers at all, asked on a TCP connection of its own (ListIdentity,
    which needs no session): after every check, and within one whenever a request goes unanswered or
    a connection drops. A target that fails to answer twice, ``SILENCE_RETRY_S`` apart, is *silent*
    for the rest of the run: every probe then fails at once, so that the check running ends in
    bounded time and the runner names it, rather than each later check waiting out its timeouts.

    ``hold()`` suspends the question while the target may refuse on purpose: a stress check that
    exhausts its sessions, a reset device that is away for a while."""

    def __init__(self, host: str, port: int, timeout: float) -> None:
        self.host, self.port, self.timeout = host, port, timeout
        #: Why the target is called silent ("" while it answers).
        self.silent = ""
        self._held = 0

    def answers(self) -> str:
        """"" when the target answers ListIdentity on a new TCP connection, else what happened."""
        try:
            with Probe(self.host, self.port, self.timeout) as probe:
                reply = probe.exchange(frame(Command.LIST_IDENTITY))
        except TargetUnreachable as exc:
            return f"no TCP connection: {exc}"
        except ConnectionError as exc:
            return f"a new TCP connection was closed on ListIdentity ({exc})"
        if reply is None:
            return f"no reply to ListIdentity on a new TCP connection within {self.timeout:g} s"
        return ""

    def confirm(self) -> bool:
        """Whether the target is silent, asked now (twice) unless known or held."""
        if self.silent or self._held:
            return bool(self.silent)
        problem = self.answers()
        if problem:
            time.sleep(SILENCE_RETRY_S)
            if self.answers():
                self.silent = problem
        return bool(self.silent)

    @contextlib.contextmanager
    def hold(self) -> Iterator[None]:
        """No question asked within the block (a refusal there may be on purpose)."""
        self._held += 1
        try:
            yield
        finally:
            self._held -= 1


class Probe:
    """One TCP connection to the target; ``exchanges`` records everything sent and received.
    ``liveness``: asked whenever a request goes unanswered or the connection drops; once it calls
    the target silent, nothing more is sent or waited for."""

    def __init__(self, host: str, port: int, timeout: float, liveness: Liveness | None = None) -> None:
        self.host, self.port, self.timeout = host, port, timeout
        self.liveness = liveness
        if liveness is not None and liveness.silent:
            raise TargetUnreachable(f"{host}:{port} stopped answering: {liveness.silent}")
        self.session = 0
        #: The target closed (or reset) this TCP connection: nothing more can be sent on it.
        self.closed_by_peer = False
        self.exchanges: list[Exchange] = []
        self._frames = FrameBuffer()
        self._received: list[bytes] = []
        self._last_send = 0.0
        try:
            self.sock: socket.socket | None = socket.create_connection((host, port), timeout)
        except OSError as exc:
            self._confirm()
            raise TargetUnreachable.connecting(host, port, exc) from None
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    # -- life cycle ---------------------------------------------------------------------------------------
    def close(self) -> None:
        if self.sock is not None:
            try:
                if self.session:
                    self.sock.sendall(frame(Command.UNREGISTER_SESSION, session=self.session))
            except OSError:
                pass
            self.sock.close()
            self.sock = None

    def __enter__(self) -> Probe:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def alive(self) -> bool:
        """Open on both ends, as far as this side has seen."""
        return self.sock is not None and not self.closed_by_peer

    @property
    def local_host(self) -> str:
        assert self.sock is not None
        return str(self.sock.getsockname()[0])

    def _confirm(self) -> None:
        """Something went unanswered: ask whether the target is there at all."""
        if self.liveness is not None:
            self.liveness.confirm()

    def _not_silent(self) -> None:
        if self.liveness is not None and self.liveness.silent:
            self.closed_by_peer = True
            raise TargetUnreachable(f"the target stopped answering: {self.liveness.silent}")

    # -- frames -------------------------------------------------------------------------------------------
    def send(self, raw: bytes) -> None:
        if self.sock is None:
            raise TargetUnreachable("probe closed")
        self._not_silent()
        wait = self._last_send + MIN_GAP - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        self._last_send = time.monotonic()
        try:
            self.sock.sendall(raw)
        except OSError as exc:
            self.closed_by_peer = True
            self._confirm()
            raise TargetUnreachable(f"send failed: {exc}") from None

    def receive(self, timeout: float | None = None) -> Frame | None:
        """The next whole frame; None on timeout; ``ConnectionError`` when the target closed."""
        if self.sock is None:
            raise TargetUnreachable("probe closed")
        self._not_silent()
        deadline = time.monotonic() + (self.timeout if timeout is None else timeout)
        while True:
            if self._received:
                raw = self._received.pop(0)
                return Frame(EncapsulationHeader.decode(raw), raw[HEADER_SIZE:], raw)
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            ready, _, _ = select.select([self.sock], [], [], left)
            if not ready:
                return None
            try:
                chunk = self.sock.recv(65536)
            except OSError as exc:
                self.closed_by_peer = True
                self._confirm()
                raise TargetUnreachable(f"connection reset: {exc}") from None
            if not chunk:
                self.closed_by_peer = True
                self._confirm()
                raise TargetUnreachable("connection closed by the target")
            self._received += self._frames.feed(chunk)

    def exchange(self, raw: bytes, timeout: float | None = None) -> Frame | None:
        """Send ``raw`` and wait for one reply frame (None: no reply in time). A closed connection
        raises ``ConnectionError``; either way the exchange is recorded."""
        record = Exchange(raw, None)
        self.exchanges.append(record)
        self.send(raw)
        reply = self.receive(timeout)
        record.received = None if reply is None else reply.raw
        if reply is None:
            self._confirm()
        return reply

    def closed_by_target(self, timeout: float) -> bool:
        """Whether the target closes the connection within ``timeout`` (frames before it are dropped)."""
        try:
            while True:
                if self.receive(timeout) is None:
                    return False
        except ConnectionError:
            return True

    # -- sessions and requests ----------------------------------------------------------------------------
    def register(self) -> int:
        """RegisterSession (version 1, options 0); the handle, or ``TargetUnreachable``."""
        try:
            reply = self.exchange(frame(Command.REGISTER_SESSION, REGISTER_SESSION_DATA.pack(1, 0)))
        except ConnectionError as exc:
            raise TargetUnreachable(f"{self.host}:{self.port} closed the connection on RegisterSession: "
                                    f"not an EtherNet/IP target? ({exc})") from None
        if reply is None:
            raise TargetUnreachable(f"{self.host}:{self.port} does not answer RegisterSession: "
                                    "not an EtherNet/IP target?")
        if reply.header.command != Command.REGISTER_SESSION or reply.header.status != 0 or not reply.header.session:
            raise TargetUnreachable(f"{self.host}:{self.port} answers RegisterSession with "
                                    f"{reply.raw[:HEADER_SIZE].hex()}: not an EtherNet/IP target?")
        self.session = reply.header.session
        return self.session

    def request(self, service: int, path: bytes, data: bytes = b"", extra: tuple[Item, ...] = (),
                raw_request: bytes | None = None, timeout: float | None = None) -> Reply:
        """A message-router request over SendRRData; ``raw_request`` sends those bytes as the request."""
        request = raw_request if raw_request is not None else MessageRouterRequest(service, path, data).encode()
        try:
            reply = self.exchange(frame(Command.SEND_RR_DATA, rr_data(request, extra), self.session), timeout)
        except ConnectionError as exc:
            return Reply(None, None, f"the target closed the connection ({exc})")
        return Reply.of(reply)


@dataclass
class Reply:
    """A SendRRData reply read for a check: the message-router reply, or what went wrong."""

    frame: Frame | None
    response: MessageRouterResponse | None
    problem: str = ""
    items: tuple[Item, ...] = ()

    @classmethod
    def of(cls, reply: Frame | None) -> Reply:
        if reply is None:
            return cls(None, None, "no reply")
        if reply.header.status != 0:
            return cls(reply, None, f"encapsulation status 0x{reply.header.status:04X}")
        try:
            data, items = rr_reply_items(reply.body)
            return cls(reply, MessageRouterResponse.decode(data), "", tuple(items))
        except (MalformedReplyError, ValueError) as exc:
            return cls(reply, None, f"malformed reply ({exc})")

    @property
    def status(self) -> int | None:
        return None if self.response is None else self.response.general_status

    @property
    def extended(self) -> int | None:
        if self.response is None or not self.response.extended_status:
            return None
        return self.response.extended_status[0]

    @property
    def data(self) -> bytes:
        return b"" if self.response is None else self.response.data

    def describe(self) -> str:
        if self.response is None:
            return self.problem
        text = f"general status 0x{self.response.general_status:02X}"
        if self.response.extended_status:
            text += " extended " + " ".join(f"0x{w:04X}" for w in self.response.extended_status)
        if self.response.data and self.response.general_status == 0:
            text += f", {len(self.response.data)} data bytes"
        return text


def udp_exchange(host: str, port: int, raw: bytes, timeout: float) -> tuple[bytes | None, float]:
    """Send one datagram, return the first reply datagram and how long it took (None: none came)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        start = time.monotonic()
        sock.sendto(raw, (host, port))
        deadline = start + timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                return None, time.monotonic() - start
            ready, _, _ = select.select([sock], [], [], left)
            if ready:
                data, _ = sock.recvfrom(65536)
                return data, time.monotonic() - start
