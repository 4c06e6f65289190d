"""The one power and link state of a running device, and the one place its ports follow it.

Power is on or off, the link plugged or unplugged. An Ethernet port is open exactly while the power
is on and the link plugged; the RS-485 port while the power is on. ``unplug``, ``plug``,
``power_off`` and ``power_on`` change the state; each change is followed by one reconciliation that
opens or closes what differs, one at a time, so a port is never opened twice (a ``plug`` while the
power is off opens nothing; the power's return then opens every port once).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Sequence

from ..errors import StateRefused
from .ports import Medium, Port

log = logging.getLogger(__name__)


class PowerLink:
    def __init__(self, ports: Sequence[Port] = ()) -> None:
        """``ports`` in the order they close; they open in the reverse order (the encapsulation port
        first to close and last to open: a client that finds it accepting finds every other port
        ready)."""
        self.ports: list[Port] = list(ports)
        self.powered = True
        self.plugged = True
        self._shut = False
        self._lock: asyncio.Lock | None = None
        self._pending: list[asyncio.Task[None]] = []

    # -- the state ----------------------------------------------------------------------------------
    def wants_open(self, port: Port) -> bool:
        return not self._shut and self.powered and (self.plugged or port.medium is Medium.SERIAL)

    def as_json(self) -> dict[str, str]:
        return {"power": "on" if self.powered else "off", "link": "plugged" if self.plugged else "unplugged"}

    def unplug(self) -> None:
        if not self.plugged:
            raise StateRefused("the device is unplugged already")
        self.plugged = False
        self._changed()

    def plug(self) -> None:
        if self.plugged:
            raise StateRefused("the device is not unplugged")
        self.plugged = True
        self._changed()

    def power_off(self) -> None:
        if not self.powered:
            raise StateRefused("the device is powered off already")
        self.powered = False
        self._changed()

    def power_on(self) -> None:
        if not self.powered:
            self.powered = True
            self._changed()

    def shutdown(self) -> None:
        """The device stops: no port opens again, whatever the state says."""
        self._shut = True

    # -- the ports follow it --------------------------------------------------------------------------
    def _changed(self) -> None:
        if self._shut:
            return
        self._pending[:] = [task for task in self._pending if not task.done()]
        self._pending.append(asyncio.get_running_loop().create_task(self.reconcile()))

    async def reconcile(self) -> None:
        """Close every port the state does not want open, then open every one it wants, in order."""
        if self._lock is None:
            self._lock = asyncio.Lock()
        async with self._lock:
            for port in self.ports:
                if port.is_open and not self.wants_open(port):
                    await port.close()
            for port in reversed(self.ports):
                if not port.is_open and self.wants_open(port):
                    try:
                        await port.open()
                    except OSError as exc:   # taken meanwhile by another process: said, the rest go on
                        log.error("%s cannot open again: %s", port.name, exc.strerror or exc)

    async def settled(self) -> None:
        """Wait until the ports follow every change made so far."""
        await settle_tasks(self._pending)


async def settle_tasks(tasks: list[asyncio.Task[None]]) -> None:
    """Wait until every task of ``tasks`` is done, those added meanwhile too; each waiter waits for all
    (a waiter that gave up leaves the others to wait), and the done ones leave the list. A task's
    error is raised to its waiters."""
    while True:
        pending = [task for task in tasks if not task.done()]
        if not pending:
            break
        await asyncio.wait(pending)
    done = [task for task in tasks if task.done()]
    tasks[:] = [task for task in tasks if not task.done()]
    for task in done:
        if not task.cancelled() and task.exception() is not None:
            raise task.exception()  # type: ignore[misc]  # not None: tested on the line above


__all__ = ["PowerLink"]
