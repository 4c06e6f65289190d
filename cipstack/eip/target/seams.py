"""The declared seams of the EtherNet/IP target: where filters may act on what enters and leaves.

A core is built with its seams (DESIGN: collaborators passed in at construction, nothing patched
later). Each seam holds an ordered list of filters and calls through them; with no filter it is a
direct call to the core, bound once, so a target nobody filters runs exactly the code it runs
without seams. What a filter does (drop a datagram, answer a request with an error, hold a reply)
is the business of whoever installs it (``cipstack.faults``, ``cipstack.control.events``); a seam
knows only the order.

* ``IoSeam``: class 1, between the UDP endpoint and the core (``IoTarget``): O->T datagrams going in
  (``IoInFilter``, which may also have one consumed without its data reaching the device) and T->O
  datagrams coming out (``IoOutFilter``).
* ``RequestSeam``: explicit requests between the encapsulation target and the message router
  (``RequestFilter``); filters act first, observers last, the router answers.
* ``ReplySeam``: explicit replies between the encapsulation target and the TCP socket
  (``ReplyFilter``): a filter may hold a reply and send it later, in order.
* ``SecuredSeam``: CIP Security's listeners (TLS and DTLS on 2221): what the next handshakes present
  (``HandshakeFilter``: another certificate, suites no longer accepted) and the DTLS records that
  enter and leave the UDP socket, whole and still encrypted (``RecordFilter``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    from ...cip.router import RequestContext
    from .io_target import IoConnection

Datagram = tuple[bytes, tuple[str, int]]


# -- class 1 ---------------------------------------------------------------------------------------------
class IoInFilter(Protocol):
    """A filter of O->T datagrams: returns the datagram to pass on (changed or not), or None when it took
    it (dropped it, or consumed it itself through ``seam.withhold``). ``connection`` is the open
    connection the datagram names, if any."""

    def inbound(self, raw: bytes, source: tuple[str, int], now: float, connection: IoConnection | None,
                seam: IoSeam) -> bytes | None: ...


class IoOutFilter(Protocol):
    """A filter of the T->O datagrams due at ``now``: returns those to send now (it may hold some back,
    duplicate, change or drop them, and hand others to ``seam.send_later``)."""

    def outbound(self, datagrams: list[Datagram], now: float, seam: IoSeam) -> list[Datagram]: ...


class IoSeam:
    """The class 1 core as its UDP endpoint sees it (``io_server.IoCore``). ``receive`` and ``poll`` are
    the core's own bound methods while no filter is in place, and the filtered paths otherwise."""

    def __init__(self, core: Any, send_later: Callable[[float, list[Datagram]], None]) -> None:
        """``core``: the ``IoTarget``; ``send_later``: what sends datagrams at a later time (a delayed
        production), the UDP endpoint's ``send_later``, given by whoever builds the seam."""
        self.core = core
        self.inbound: list[IoInFilter] = []
        self.outbound: list[IoOutFilter] = []
        #: Sends datagrams at a later time (a delayed production): the filters call it.
        self.send_later = send_later
        self.next_deadline = core.next_deadline
        self.expire = core.expire
        self.receive: Callable[[bytes, tuple[str, int], float], None] = core.receive
        self.poll: Callable[..., list[Datagram]] = core.poll
        #: Whether the datagram the filters are looking at came in a DTLS session (``receive_secured``).
        self._secured = False

    def add(self, item: IoInFilter | IoOutFilter) -> None:
        if hasattr(item, "inbound"):
            self.inbound.append(item)  # type: ignore[arg-type]  # has inbound: an IoInFilter
        if hasattr(item, "outbound"):
            self.outbound.append(item)  # type: ignore[arg-type]  # has outbound: an IoOutFilter
        self._bind()

    def remove(self, item: object) -> None:
        self.inbound = [f for f in self.inbound if f is not item]
        self.outbound = [f for f in self.outbound if f is not item]
        self._bind()

    def clear(self) -> None:
        self.inbound.clear()
        self.outbound.clear()
        self._bind()

    def _bind(self) -> None:
        core = self.core
        self.receive = self._receive_filtered if self.inbound else core.receive
        self.poll = self._poll_filtered if self.outbound else core.poll

    def _receive_filtered(self, raw: bytes, source: tuple[str, int], now: float) -> None:
        core = self.core
        connection = core.connection_of(raw)
        for item in list(self.inbound):
            passed = item.inbound(raw, source, now, connection, self)
            if passed is None:
                return
            raw = passed
        core.receive(raw, source, now)

    def receive_secured(self, raw: bytes, source: tuple[str, int], now: float) -> None:
        """An O->T datagram that came in a DTLS session (``security.dtls_target``): the same filters,
        then the core, which takes it only for a connection opened in that session."""
        core = self.core
        if not self.inbound:
            core.receive(raw, source, now, True, True)
            return
        connection = core.connection_of(raw)
        self._secured = True   # what ``withhold`` passes on while the filters run (they run at once)
        try:
            for item in list(self.inbound):
                passed = item.inbound(raw, source, now, connection, self)
                if passed is None:
                    return
                raw = passed
        finally:
            self._secured = False
        core.receive(raw, source, now, True, True)

    def withhold(self, raw: bytes, source: tuple[str, int], now: float) -> None:
        """Consume ``raw`` (sequence counts, watchdog, run/idle) without handing its data to the device."""
        self.core.receive(raw, source, now, False, self._secured)

    def _poll_filtered(self, now: float, horizon: float = 0.0) -> list[Datagram]:
        out: list[Datagram] = self.core.poll(now, horizon)
        for item in list(self.outbound):
            if not out:
                break
            out = item.outbound(out, now, self)
        return out


# -- explicit requests -----------------------------------------------------------------------------------
Handle = Callable[[bytes, "RequestContext"], bytes]


class RequestFilter(Protocol):
    """A filter of explicit requests: answers ``raw`` itself, or calls ``call_next`` for the rest of the
    chain (and may look at what it answered)."""

    def request(self, raw: bytes, context: RequestContext, call_next: Handle) -> bytes: ...


class RequestSeam:
    """The message router as the encapsulation target calls it (``entry.handle``): ``entry`` is the
    router itself while nothing is in place, so an unfiltered request costs what it did without a
    seam; otherwise a chain whose ``handle`` runs the ``filters`` first (they may answer in the
    router's stead), then the ``observers`` (they see what reaches the router and what it answered)."""

    def __init__(self, router: Any) -> None:
        self.router = router
        self.filters: list[RequestFilter] = []
        self.observers: list[RequestFilter] = []
        self.entry: Any = router

    def add(self, item: RequestFilter, observer: bool = False) -> None:
        (self.observers if observer else self.filters).append(item)
        self._bind()

    def remove(self, item: object) -> None:
        self.filters = [f for f in self.filters if f is not item]
        self.observers = [f for f in self.observers if f is not item]
        self._bind()

    @property
    def handle(self) -> Handle:
        """What a request reaches: the first filter, or the router."""
        return self.entry.handle  # type: ignore[no-any-return]  # the router or a _Link, both Handle

    def _bind(self) -> None:
        entry: Any = self.router
        for item in reversed([*self.filters, *self.observers]):
            entry = _Link(item, entry.handle)
        self.entry = entry


class _Link:
    """One filter of the chain and what comes after it."""

    def __init__(self, item: RequestFilter, call_next: Handle) -> None:
        self.item = item
        self.call_next = call_next

    def handle(self, raw: bytes, context: RequestContext) -> bytes:
        return self.item.request(raw, context, self.call_next)


# -- explicit replies ------------------------------------------------------------------------------------
class ReplySender(Protocol):
    """A served TCP connection: what sends a reply taken from its connection earlier."""

    def send_reply(self, out: bytes) -> None: ...


class ReplyFilter(Protocol):
    """A filter of TCP replies: sends ``out`` on ``served`` now or later (``served.send_reply``)."""

    def reply(self, served: ReplySender, out: bytes) -> None: ...


class ReplySeam:
    """Replies on their way to the TCP socket. While ``filter`` is None (the common case) the shell
    writes each reply at once; otherwise the filter sends it."""

    def __init__(self) -> None:
        self.filter: ReplyFilter | None = None


# -- CIP Security's listeners -----------------------------------------------------------------------------
#: The header of a DTLS 1.2 record (RFC 6347, 4.1): type, version, epoch, sequence number, then the
#: length of its fragment as the last two octets.
DTLS_RECORD_HEADER = 13


class HandshakeFilter(Protocol):
    """What the next TLS and DTLS handshakes of the device change (sessions already made keep theirs):
    ``certificate``, the PEM certificate and key files presented instead of the device's own (None:
    its own); ``refused``, the IANA ids of the suites no longer accepted."""

    certificate: tuple[str, str] | None
    refused: frozenset[int]


class RecordFilter(Protocol):
    """A filter of the DTLS records of one UDP datagram, before decryption (``inbound``) or after
    encryption (``outbound``): returns the datagram with the records it keeps (empty: none)."""

    def records(self, datagram: bytes, peer: tuple[str, int], inbound: bool) -> bytes: ...


def dtls_records(datagram: bytes) -> list[bytes]:
    """The whole records of a datagram by their headers (RFC 6347, 4.1.1: a datagram carries whole
    records, never part of one); bytes after the last whole record come as one more piece."""
    records = []
    offset = 0
    while offset + DTLS_RECORD_HEADER <= len(datagram):
        end = offset + DTLS_RECORD_HEADER + int.from_bytes(datagram[offset + 11:offset + 13], "big")
        records.append(datagram[offset:end])
        offset = end
    if offset < len(datagram):
        records.append(datagram[offset:])
    return records


class SecuredSeam:
    """CIP Security's listeners as faults reach them. The TLS and DTLS listeners read ``handshake`` at
    each new handshake (with none, their own context, unchanged) and pass each DTLS datagram through
    ``inbound`` and ``outbound`` while ``records`` holds a filter. ``generation`` moves on whenever
    ``handshake`` changes, so a listener rebuilds what it derived from it once."""

    def __init__(self) -> None:
        self.handshake: list[HandshakeFilter] = []
        self.records: list[RecordFilter] = []
        self.generation = 0

    def add(self, item: HandshakeFilter | RecordFilter) -> None:
        if hasattr(item, "records"):
            self.records.append(item)  # type: ignore[arg-type]  # has records: a RecordFilter
        else:
            self.handshake.append(item)
            self.generation += 1

    def remove(self, item: object) -> None:
        before = len(self.handshake)
        self.handshake = [f for f in self.handshake if f is not item]
        self.records = [f for f in self.records if f is not item]
        if len(self.handshake) != before:
            self.generation += 1

    def certificate(self) -> tuple[str, str] | None:
        """The certificate and key the next handshakes present instead of the device's (the last filter's)."""
        chosen = None
        for item in self.handshake:
            chosen = item.certificate or chosen
        return chosen

    def refused(self) -> frozenset[int]:
        """The suites (IANA ids) the next handshakes do not accept."""
        return frozenset().union(*(item.refused for item in self.handshake))

    def inbound(self, datagram: bytes, peer: tuple[str, int]) -> bytes:
        for item in list(self.records):
            if not datagram:
                break
            datagram = item.records(datagram, peer, True)
        return datagram

    def outbound(self, datagram: bytes, peer: tuple[str, int]) -> bytes:
        for item in list(self.records):
            if not datagram:
                break
            datagram = item.records(datagram, peer, False)
        return datagram


__all__ = ["DTLS_RECORD_HEADER", "Datagram", "HandshakeFilter", "IoInFilter", "IoOutFilter", "IoSeam", "RecordFilter",
           "ReplyFilter", "ReplySeam", "ReplySender", "RequestFilter", "RequestSeam", "SecuredSeam", "dtls_records"]
