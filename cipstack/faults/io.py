"""Class 1 faults, applied to datagrams where they enter or leave the device.

``IoFaultLayer`` stands in for the class 1 core (``IoTarget``) in the endpoint while at least one
class 1 fault is active: the endpoint reads and sends through it, it passes what the faults let
through to the core and changes what the core produced before it goes out. With no fault active
the endpoint holds the core itself again, and the layer costs nothing.

Datagrams are read and changed by their bytes (CIP Vol. 2, 3-2: a Sequenced Address item, the
connection id at offset 6 and the encapsulation sequence number at 10, a Connected Data item whose
length is at 16, the CIP sequence count at 18, then O->T the 32-bit run/idle header at 20 and the
data). The core's own counters never see a fault: after ``clear`` it produces what it would have.
"""

from __future__ import annotations

import asyncio
import random
import struct
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from .model import FaultRequest

if TYPE_CHECKING:
    from ..eip.io_target import IoConnection, IoTarget

_CONNECTION_ID = struct.Struct("<I")
_UINT = struct.Struct("<H")
#: Bytes before the data of a class 1 datagram: CPF count, Sequenced Address item, Connected Data
#: item header and the CIP sequence count (``io_core.IO_HEAD_SIZE``).
HEAD = 20
DEFAULT_DELAY = 0.010

Datagram = tuple[bytes, tuple[str, int]]


class ActiveIoFault:
    """One class 1 fault in force, with what it remembers between packets."""

    def __init__(self, fault_id: int, request: FaultRequest, rng: random.Random) -> None:
        self.id = fault_id
        self.name = request.name
        options = request.options
        self.connection: int | None = options.get("connection")
        self.originator: str | None = options.get("originator")
        self.share: float | None = options.get("share")
        self.every: int = options.get("every", 1)
        self.by: float = options.get("by", DEFAULT_DELAY)
        self.jitter: float = options.get("jitter", 0.0)
        self.size: int | None = options.get("size")
        self.rng = rng
        self.count = 0
        #: Per connection: the packet held back (reorder), the frozen CIP sequence count.
        self.held: dict[int, Datagram] = {}
        self.frozen: dict[int, bytes] = {}

    def matches(self, connection: IoConnection | None) -> bool:
        if connection is None:
            return self.connection is None and self.originator is None
        if self.connection is not None and self.connection not in (connection.ot_connection_id,
                                                                   connection.to_connection_id):
            return False
        return self.originator is None or connection.peer == self.originator

    def every_nth(self) -> bool:
        self.count += 1
        return self.count % self.every == 0


class IoFaultLayer:
    """The class 1 core as the endpoint sees it while faults are active (see the module docstring)."""

    def __init__(self, core: IoTarget, send_later: Callable[[float, list[Datagram]], None],
                 rng: random.Random | None = None) -> None:
        self.core = core
        self.send_later = send_later
        self.rng = rng or random.Random()
        self.faults: list[ActiveIoFault] = []
        #: Set while the core consumes a datagram whose data the device must not get (ignore-output).
        self._withhold = False
        self._deliver = core.deliver

    # -- what the fault controller does --------------------------------------------------------------
    def add(self, fault_id: int, request: FaultRequest) -> None:
        self.faults.append(ActiveIoFault(fault_id, request, self.rng))

    def remove(self, fault_id: int) -> None:
        self.faults = [f for f in self.faults if f.id != fault_id]

    def install(self, endpoint: Any) -> None:
        self._deliver = self.core.deliver
        self.core.deliver = self._deliver_unless_withheld
        endpoint.core = self

    def uninstall(self, endpoint: Any) -> None:
        endpoint.core = self.core
        self.core.deliver = self._deliver

    # -- the core's interface (``io_server.IoCore``) ----------------------------------------------------
    def receive(self, raw: bytes, source: tuple[str, int], now: float) -> None:
        core = self.core
        connection = core.connections.get(_CONNECTION_ID.unpack_from(raw, 6)[0]) if len(raw) >= HEAD else None
        withhold = False
        for fault in self.faults:
            if fault.name != "unplug" and not fault.matches(connection):
                continue
            name = fault.name
            if name == "unplug":
                return
            if name == "ignore-output":
                withhold = True
            elif name == "idle" and connection is not None and connection.ot_payload_size >= 4 and len(raw) > HEAD:
                raw = raw[:HEAD] + bytes((raw[HEAD] & 0xFE,)) + raw[HEAD + 1:]
        if not withhold:
            core.receive(raw, source, now)
            return
        self._withhold = True
        try:
            core.receive(raw, source, now)
        finally:
            self._withhold = False

    def _deliver_unless_withheld(self, instance_id: int, data: bytes, now: float) -> None:
        if not self._withhold:
            self._deliver(instance_id, data, now)

    def poll(self, now: float, horizon: float = 0.0) -> list[Datagram]:
        out = self.core.poll(now, horizon)
        if not out or not self.faults:
            return out
        by_to_id = {c.to_connection_id: c for c in self.core.connections.values()}
        for fault in self.faults:
            out = self._apply(fault, out, by_to_id, now)
        return out

    def next_deadline(self) -> float | None:
        return self.core.next_deadline()

    def expire(self, now: float) -> list[Any]:
        return self.core.expire(now)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.core, name)

    # -- T->O ------------------------------------------------------------------------------------------
    def _apply(self, fault: ActiveIoFault, datagrams: list[Datagram], by_to_id: dict[int, IoConnection],
               now: float) -> list[Datagram]:
        name = fault.name
        out: list[Datagram] = []
        for datagram in datagrams:
            raw = datagram[0]
            to_id = _CONNECTION_ID.unpack_from(raw, 6)[0]
            if name != "unplug" and not fault.matches(by_to_id.get(to_id)):
                out.append(datagram)
                continue
            if name in ("stop-producing", "unplug"):
                continue
            if name == "drop":
                dropped = fault.rng.random() < fault.share if fault.share is not None else fault.every_nth()
                if not dropped:
                    out.append(datagram)
            elif name == "duplicate":
                out.append(datagram)
                if fault.every_nth():
                    out.append(datagram)
            elif name == "reorder":
                held = fault.held.pop(to_id, None)
                if held is None:
                    fault.held[to_id] = datagram
                else:
                    out += (datagram, held)
            elif name == "delay":
                at = now + max(0.0, fault.by + (fault.rng.uniform(-fault.jitter, fault.jitter) if fault.jitter else 0))
                self.send_later(at, [datagram])
            elif name == "freeze-sequence":
                frozen = fault.frozen.setdefault(to_id, raw[HEAD - 2:HEAD])
                out.append((raw[:HEAD - 2] + frozen + raw[HEAD:], datagram[1]))
            elif name == "wrong-size":
                data = raw[HEAD:]
                size = len(data) - 1 if fault.size is None else fault.size
                data = data[:size] if size <= len(data) else data + bytes(size - len(data))
                out.append((raw[:16] + _UINT.pack(2 + len(data)) + raw[18:HEAD] + data, datagram[1]))
            else:
                out.append(datagram)
        return out


def send_later_on(loop: asyncio.AbstractEventLoop, endpoint: Any) -> Callable[[float, list[Datagram]], None]:
    """Send datagrams from ``endpoint`` at a later time (a delayed production), if it is still open."""
    def send_later(at: float, datagrams: list[Datagram]) -> None:
        def send() -> None:
            if endpoint.is_open:
                endpoint._send(datagrams)
        loop.call_at(at, send)
    return send_later
