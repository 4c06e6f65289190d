"""The narrow interface of a running device: what faults, the event stream and the command service
may do to it and ask of it, without knowing the ``Adapter`` that composed it."""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol

from .observer import Observers, RuntimeObserver
from .power import PowerLink

if TYPE_CHECKING:
    from ..devices.base import Device
    from ..eip.io_server import IoEndpoint
    from ..eip.target.core import EncapsulationTarget
    from ..eip.target.io_target import IoConnection, IoTarget
    from ..eip.target.seams import IoSeam, ReplySeam, RequestSeam, SecuredSeam
    from ..eip.target.server import EncapsulationServer
    from ..modbus.rtu_line import RtuLine
    from .ports import Rs485Port


class DeviceClock:
    """Moves the device to the time of each request and datagram (the cores call ``tick``), and keeps a
    timer at its next deadline (lost-command timers, the end of a ramp), so it changes on time even
    when nobody asks; its observers hear of each move."""

    def __init__(self, device: Device, observers: Observers) -> None:
        self.device = device
        self.observers = observers
        self._timer: asyncio.TimerHandle | None = None
        self._timer_at: float | None = None
        #: No timer armed and nobody watching: a tick that finds no deadline has nothing else to do.
        self._quiet = not observers.watched

    def tick(self, now: float) -> None:
        deadline = self.device.tick(now)
        if deadline is None and self._quiet:
            return   # the common case, a device at rest that nobody watches, in one test
        if deadline is None:
            if self._timer_at is not None:
                self._arm(None, now)
        elif deadline != self._timer_at or self._timer is None:
            self._arm(deadline, now)
        if self.observers.watched:
            for observer in self.observers:
                observer.ticked(now)

    def watch(self, observer: RuntimeObserver) -> None:
        self.observers.add(observer)
        self._quiet = False

    def unwatch(self, observer: RuntimeObserver) -> None:
        self.observers.remove(observer)
        self._quiet = self._timer_at is None and not self.observers.watched

    def _arm(self, deadline: float | None, now: float) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        self._timer_at = deadline
        self._quiet = deadline is None and not self.observers.watched
        if deadline is not None:
            self._timer = asyncio.get_running_loop().call_at(max(deadline, now), self._on_timer)

    def _on_timer(self) -> None:
        self._timer = None
        self._timer_at = None
        self.tick(asyncio.get_running_loop().time())

    def stop(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        self._arm(None, 0.0)


class ReissuedCertificate(Protocol):
    """A certificate made for a fault: its PEM certificate and key files, and how they go away."""

    paths: tuple[str, str]

    def discard(self) -> None: ...


class CipSecurity(Protocol):
    """The device's CIP Security as faults reach it (``cipstack.security.authority.LabAuthority``): the
    seam of its listeners, and the lab CA of its security folder. Each call raises ``StateRefused``
    naming the reason when the device serves no CIP Security now, or its folder holds no CA key."""

    seam: SecuredSeam

    def serving(self, datagrams: bool = False) -> None:
        """Nothing, when the device serves TLS (and DTLS with ``datagrams``) now."""

    def expired_certificate(self) -> ReissuedCertificate:
        """The device's certificate re-issued (same subject and key) with its validity ended."""

    def revoke(self) -> Callable[[], None]:
        """Publish a CRL of the lab CA that lists the device's certificate; returns what undoes it."""

    def suite(self, name: str) -> int:
        """The IANA id of a suite the device accepts now, by IANA name, OpenSSL name or 0x id
        (``BadRequest`` naming those it accepts)."""


class DeviceRuntime:
    """A device running behind its ports: its clock, its power and link (``power``), the seams where
    faults act (``requests``, ``replies``, ``class1``) and its observers."""

    def __init__(self, device: Device, clock: DeviceClock, observers: Observers, power: PowerLink,
                 target: EncapsulationTarget, server: EncapsulationServer, requests: RequestSeam,
                 replies: ReplySeam, io: IoTarget | None = None, class1: IoSeam | None = None,
                 endpoint: IoEndpoint | None = None, rs485: Rs485Port | None = None,
                 security: CipSecurity | None = None) -> None:
        self.device = device
        self.clock = clock
        self.observers = observers
        self.power = power
        self.target = target
        self.server = server
        self.requests = requests
        self.replies = replies
        self.io = io
        self.class1 = class1
        self.endpoint = endpoint
        self.rs485 = rs485
        #: CIP Security (None: a device without it, which imports nothing of ``cipstack.security``).
        self.security = security

    @property
    def rtu(self) -> RtuLine | None:
        """The RS-485 line, once its port has opened it."""
        return self.rs485.line if self.rs485 is not None else None

    # -- time ---------------------------------------------------------------------------------------------
    @staticmethod
    def now() -> float:
        return asyncio.get_running_loop().time()

    def tick(self, now: float | None = None) -> float:
        """Move the device to ``now`` (the loop's time by default); returns it."""
        now = self.now() if now is None else now
        self.clock.tick(now)
        return now

    def watch(self, observer: RuntimeObserver) -> None:
        """Tell ``observer`` what the device does from now on (``RuntimeObserver``)."""
        self.clock.watch(observer)

    def unwatch(self, observer: RuntimeObserver) -> None:
        self.clock.unwatch(observer)

    # -- what faults do ---------------------------------------------------------------------------------
    def close_tcp(self) -> int:
        return self.server.close_connections()

    def drop_sessions(self) -> int:
        return self.target.drop_sessions()

    def class1_connections(self) -> list[IoConnection]:
        return list(self.io.connections.values()) if self.io is not None else []

    def productions(self) -> tuple[int, int, int]:
        """(sent, late, missed): the class 1 productions of every connection since the device started,
        closed ones included; missed are the slots skipped because the loop came too late for them
        (an overloaded process produces fewer packets, it never bursts to catch up)."""
        io = self.io
        if io is None:
            return 0, 0, 0
        every = [io.closed_stats, *(c.stats for c in list(io.connections.values()))]
        return (sum(s.sent for s in every), sum(s.late for s in every), sum(s.skipped_slots for s in every))

    async def lose_power(self) -> None:
        """The power goes: every port closes (``power``) and every connection with it (no Forward_Close
        and no FIN would come from a device without power, but the peer's socket is gone either way);
        the device restarts from what it keeps over a power loss (``Device.power_cycle``, each family
        from its manual), and a save it had handed to its memory before is written (or failed)."""
        loop = asyncio.get_running_loop()
        if self.power.powered:
            self.power.power_off()
        await self.power.settled()
        if self.io is not None:
            self.io.close_all()
        self.device.power_cycle(loop.time())
        self.tick(loop.time())
        await loop.run_in_executor(None, self.device.flush_saves, 10.0)

    async def restore_power(self) -> None:
        self.power.power_on()
        await self.power.settled()

    # -- what the command service reads -------------------------------------------------------------------
    def status(self) -> dict[str, Any]:
        """The device's state, its power and link, its sessions and connections, and what its RS-485
        port made of its line."""
        device = self.device
        status: dict[str, Any] = {"status": device.status_line(), "drive": device.status_fields(),
                                  **self.power.as_json(),
                                  "sessions": len(self.target.sessions),
                                  "class3_connections": len(device.connection_table.connections),
                                  "class1_connections": len(self.io.connections) if self.io is not None else 0}
        sent, late, missed = self.productions()
        status["productions"] = {"sent": sent, "late": late, "missed": missed}
        if self.rtu is not None:
            status["rtu"] = {"device": self.rtu.name, **self.rtu.slaves[0].counters.as_dict()}
        return status

    def shutdown(self) -> None:
        """The device stops: no port opens again and no timer of the device fires."""
        self.power.shutdown()
        self.clock.stop()


__all__ = ["CipSecurity", "DeviceClock", "DeviceRuntime", "ReissuedCertificate"]
