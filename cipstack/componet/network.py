"""A simulated CompoNet network: a master and its word slaves, sans-I/O and time-driven.

Node addresses are 0-63 (section 2-1-4; the option board takes its address from the rotary
switches, or from P190 when they are set to 64-99). A word slave occupies one word of the
master's OUT area per output word and one word of its IN area per input word, starting at the
word of its node address; the data of the slaves is so "allocated strictly in order of node
address in the areas" (section 3-3). A word mixed slave such as the option board has the same
node address in both areas. Two slaves whose words overlap have duplicated addresses: the one
that joins second detects it (Table 26, "node address is already in use") and stays off the
network, and its inverter trips E61/E71 (Table D-5).

Each communications cycle the master refreshes every slave that answers: its OUT words go to
the slave, its IN words come back. Until the OUT area is first written (``run``; the PLC still in
program mode) the master sends no output data, only collects the inputs: the slaves see network
idle (P048), and explicit messages alone control them. A slave that stops answering is lost after ``lost_after``
cycles (the master clears its IN words and records the event); the slave side notices the
silence after ``slave_timeout`` seconds (Table 26, connection time-out) and applies P045.

Explicit messages (appendix E) travel as frames of ``explicit``: ``exchange(frame, now)`` takes
the master's request frame and returns the slave's response frame.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from enum import Enum
from typing import Protocol

from ..cip.router import MessageRouter, RequestContext
from ..errors import BadRequest, PeerUnreachable, UnknownKey
from .explicit import ExplicitRequest, serve_explicit

log = logging.getLogger(__name__)

NODE_ADDRESSES = 64
AREA_WORDS = NODE_ADDRESSES
#: CompoNet Link attribute 2 codes (Table C-16).
BAUD_4M = 4


class WordSlave(Protocol):
    """What the network needs from a word slave."""

    router: MessageRouter

    @property
    def node_address(self) -> int: ...

    def componet_sizes(self) -> tuple[int, int]: ...

    def componet_refresh(self, output: bytes | None, now: float) -> bytes: ...

    def componet_lost(self, now: float) -> None: ...

    def componet_duplicate(self, now: float) -> None: ...

    def componet_baud_rate(self, code: int) -> None: ...

    def advance(self, now: float) -> None: ...

    def next_deadline(self) -> float | None: ...


class NodeState(Enum):
    ONLINE = "online"
    DUPLICATE = "node address duplicated"
    LOST = "communication lost"


class NoResponse(PeerUnreachable):
    """No slave answers at that node address."""


def words(size: int) -> int:
    return (size + 1) // 2


@dataclass
class Participant:
    slave: WordSlave
    node: int
    out_words: int
    in_words: int
    state: NodeState = NodeState.ONLINE
    #: The simulated cable: False when the slave is disconnected.
    present: bool = True
    missed: int = 0
    last_refresh: float | None = None
    slave_timed_out: bool = False

    @property
    def out_range(self) -> range:
        return range(self.node, self.node + self.out_words)

    @property
    def in_range(self) -> range:
        return range(self.node, self.node + self.in_words)


@dataclass(frozen=True)
class NetworkEvent:
    time: float
    node: int
    kind: str


@dataclass
class CompoNetNetwork:
    """The master and its slaves; drive it with ``advance(now)`` and ``next_deadline()``."""

    #: Communications cycle time, seconds.
    cycle: float = 0.01
    #: Cycles without answer after which the master reports a slave lost.
    lost_after: int = 3
    #: Silence after which a slave detects communication lost, seconds.
    slave_timeout: float = 0.1
    baud_rate: int = BAUD_4M
    #: The master sends output data (False: idle, inputs only).
    run: bool = False
    participants: list[Participant] = field(default_factory=list)
    events: list[NetworkEvent] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.out_area = bytearray(2 * AREA_WORDS)
        self.in_area = bytearray(2 * AREA_WORDS)
        self._next_cycle: float | None = None
        self.cycles = 0

    # -- membership -----------------------------------------------------------------------------
    def attach(self, slave: WordSlave, now: float) -> Participant:
        """A slave joins: its words are allocated from its node address; a clash is a duplicate."""
        node = slave.node_address
        out_bytes, in_bytes = slave.componet_sizes()
        participant = Participant(slave, node, words(out_bytes), words(in_bytes))
        if not 0 <= node < NODE_ADDRESSES or node + max(participant.out_words, participant.in_words) > AREA_WORDS:
            raise BadRequest(f"node {node} with {participant.out_words}/{participant.in_words} words does not fit "
                             f"the {AREA_WORDS}-word areas")
        slave.componet_baud_rate(self.baud_rate)
        clash = self._clash(participant)
        if clash is not None:
            participant.state = NodeState.DUPLICATE
            self._event(now, node, f"duplicate node address (words of node {clash.node})")
            slave.componet_duplicate(now)
        else:
            self._event(now, node, "joined")
        self.participants.append(participant)
        if self._next_cycle is None:
            self._next_cycle = now
        return participant

    def _clash(self, new: Participant) -> Participant | None:
        for other in self.participants:
            if other.state is NodeState.DUPLICATE:
                continue
            if set(other.out_range) & set(new.out_range) or set(other.in_range) & set(new.in_range):
                return other
        return None

    def participant(self, node: int) -> Participant | None:
        """The slave that owns node address ``node`` (not a rejected duplicate)."""
        return next((p for p in self.participants if p.node == node and p.state is not NodeState.DUPLICATE), None)

    def online(self) -> Iterator[Participant]:
        return (p for p in sorted(self.participants, key=lambda p: p.node) if p.state is NodeState.ONLINE)

    def disconnect(self, node: int) -> None:
        """Pull the slave's cable (simulation)."""
        participant = self._need(node)
        participant.present = False

    def reconnect(self, node: int) -> None:
        participant = self._need(node)
        participant.present = True

    def _need(self, node: int) -> Participant:
        participant = self.participant(node)
        if participant is None:
            raise UnknownKey(f"no slave at node {node}")
        return participant

    def _event(self, now: float, node: int, kind: str) -> None:
        log.info("CompoNet node %d: %s", node, kind)
        self.events.append(NetworkEvent(now, node, kind))

    # -- I/O areas ---------------------------------------------------------------------------------
    def out_words(self, node: int) -> bytes:
        participant = self._need(node)
        return bytes(self.out_area[2 * node: 2 * (node + participant.out_words)])

    def in_words(self, node: int) -> bytes:
        participant = self._need(node)
        return bytes(self.in_area[2 * node: 2 * (node + participant.in_words)])

    def set_out_words(self, node: int, data: bytes) -> None:
        participant = self._need(node)
        if len(data) != 2 * participant.out_words:
            raise BadRequest(f"node {node} has {participant.out_words} output words")
        self.out_area[2 * node: 2 * node + len(data)] = data
        self.run = True

    def write_out_area(self, data: bytes) -> None:
        """The whole OUT area at once (what the gateway's output assembly carries); the master runs."""
        if len(data) != len(self.out_area):
            raise BadRequest(f"the OUT area is {len(self.out_area)} bytes")
        self.out_area[:] = data
        self.run = True

    # -- time ------------------------------------------------------------------------------------
    def advance(self, now: float) -> None:
        """Run the communications cycles due by ``now``, then bring every slave to ``now``."""
        if self._next_cycle is not None and now >= self._next_cycle:
            due = math.floor((now - self._next_cycle) / self.cycle) + 1
            # A shell that fell behind runs the latest cycle once; absent slaves miss all of them.
            self._refresh(self._next_cycle + (due - 1) * self.cycle, due)
            self._next_cycle += due * self.cycle
        for participant in self.participants:
            self._slave_watchdog(participant, now)
            participant.slave.advance(now)

    def next_deadline(self) -> float | None:
        times = [p.slave.next_deadline() for p in self.participants]
        times.append(self._next_cycle)
        times.extend(p.last_refresh + self.slave_timeout for p in self.participants
                     if p.last_refresh is not None and not p.slave_timed_out)
        known = [t for t in times if t is not None]
        return min(known) if known else None

    def _refresh(self, t: float, cycles: int) -> None:
        self.cycles += cycles
        for participant in sorted(self.participants, key=lambda p: p.node):
            if participant.state is NodeState.DUPLICATE:
                continue
            node = participant.node
            if not participant.present:
                participant.missed += cycles
                if participant.state is NodeState.ONLINE and participant.missed >= self.lost_after:
                    participant.state = NodeState.LOST
                    self.in_area[2 * node: 2 * (node + participant.in_words)] = bytes(2 * participant.in_words)
                    self._event(t, node, "lost")
                continue
            if participant.state is NodeState.LOST:
                self._event(t, node, "rejoined")
            participant.state = NodeState.ONLINE
            participant.missed = 0
            participant.slave_timed_out = False
            output = self.out_words(node) if self.run else None
            data = participant.slave.componet_refresh(output, t)
            data = data.ljust(2 * participant.in_words, b"\x00")
            self.in_area[2 * node: 2 * (node + participant.in_words)] = data
            participant.last_refresh = t

    def _slave_watchdog(self, participant: Participant, now: float) -> None:
        last = participant.last_refresh
        if participant.present or last is None or participant.slave_timed_out:
            return
        expiry = last + self.slave_timeout
        if now >= expiry:
            participant.slave_timed_out = True
            participant.slave.componet_lost(expiry)

    # -- explicit messages ---------------------------------------------------------------------------
    def exchange(self, frame: bytes, now: float) -> bytes:
        """Deliver the master's explicit request frame; returns the slave's response frame."""
        request = ExplicitRequest.decode(frame)
        participant = self.participant(request.node)
        if participant is None or not participant.present:
            raise NoResponse(f"no slave answers at node {request.node}")
        slave = participant.slave
        slave.advance(now)
        response = serve_explicit(slave.router, request, RequestContext(slave.router, now, "CompoNet master"))
        return response.encode()

    def status_lines(self) -> list[str]:
        return [f"node {p.node:2d}: {p.state.value}, OUT words {p.out_range.start}-{p.out_range.stop - 1}, "
                f"IN words {p.in_range.start}-{p.in_range.stop - 1}" + ("" if p.present else " (disconnected)")
                for p in sorted(self.participants, key=lambda p: p.node)]


__all__ = ["AREA_WORDS", "CompoNetNetwork", "NetworkEvent", "NoResponse", "NodeState", "Participant", "WordSlave"]
