"""What a running device tells whoever watches it (the event stream), and the relays that tell it.

Observers are a list the runtime holds; with none, each relay costs one look at an empty list, and
only where the device is told something (a connection opened or closed, run/idle, a register a
Modbus request wrote, the device moved to a new time)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    from ..devices.base import RegisterWritten
    from ..eip.target.io_target import IoConnection, IoEvents


class RuntimeObserver(Protocol):
    def ticked(self, now: float) -> None:
        """The device was moved to ``now`` (its state may have changed: a ramp, a trip)."""

    def io_opened(self, connection: IoConnection) -> None: ...

    def io_closed(self, connection: IoConnection, timed_out: bool) -> None: ...

    def io_run_idle(self, connection: IoConnection, run: bool) -> None: ...

    def register_written(self, port: str, drive: Any, address: int, raw: int, source: object) -> None:
        """A Modbus request on ``port`` ("modbus-tcp", "modbus-rtu") wrote ``raw`` at ``address``."""


class Observers(list["RuntimeObserver"]):
    """The observers of one running device. ``watched`` says whether there is any: a flag the hot
    paths test (a bool is the cheapest test there is), kept by ``add`` and ``remove``."""

    watched = False

    def add(self, observer: RuntimeObserver) -> None:
        self.append(observer)
        self.watched = True

    def remove(self, observer: RuntimeObserver) -> None:
        super().remove(observer)
        self.watched = bool(self)


class IoEventRelay:
    """The class 1 target's ``events``: the observers hear of it, then the device."""

    def __init__(self, device: IoEvents, observers: Observers) -> None:
        self.device = device
        self.observers = observers

    def io_opened(self, connection: IoConnection) -> None:
        for observer in self.observers:
            observer.io_opened(connection)
        self.device.io_opened(connection)

    def io_closed(self, connection: IoConnection, timed_out: bool) -> None:
        for observer in self.observers:
            observer.io_closed(connection, timed_out)
        self.device.io_closed(connection, timed_out)

    def io_run_idle(self, connection: IoConnection, run: bool) -> None:
        for observer in self.observers:
            observer.io_run_idle(connection, run)
        self.device.io_run_idle(connection, run)


def register_relay(port: str, observers: Observers) -> RegisterWritten:
    """What a Modbus port's core calls with each register a request wrote (``ModbusCore.written``)."""
    def written(drive: Any, address: int, raw: int, now: float, source: object) -> None:
        for observer in observers:
            observer.register_written(port, drive, address, raw, source)
    return written


__all__ = ["IoEventRelay", "Observers", "RuntimeObserver", "register_relay"]
