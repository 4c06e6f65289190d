"""Faults of the whole device: its link and its power, through the runtime's one power/link state
(``cipstack.runtime.PowerLink``), which opens and closes every port."""

from __future__ import annotations

import asyncio

from .effect import FaultContext
from .errors import FaultStateError


class Unplug:
    """The cable is pulled: every Ethernet port closes until ``plug`` (or ``--for``); the RS-485 port
    goes on."""

    def __init__(self, context: FaultContext) -> None:
        self.power = context.runtime.power

    def start(self) -> None:
        if not self.power.plugged:
            raise FaultStateError("the device is unplugged already")
        self.power.unplug()

    def stop(self) -> None:
        if not self.power.plugged:
            self.power.plug()


class Plug:
    """Ends an unplug: the controller clears the active ``unplug`` (``FaultKind.ends``); nothing else."""

    def __init__(self, context: FaultContext) -> None:
        pass

    def start(self) -> None:
        pass

    def stop(self) -> None:
        pass


class PowerCycle:
    """A power loss: the device is off from ``start`` until the fault ends, after ``--off`` or when it is
    cleared (a long ``--off`` can always be ended); then every port opens once (or the Serial one only,
    when the device was unplugged meanwhile)."""

    def __init__(self, context: FaultContext) -> None:
        self.context = context
        self.runtime = context.runtime
        self._restore = asyncio.Event()

    def start(self) -> None:
        if not self.runtime.power.powered:
            raise FaultStateError("the device is powered off already (a power-cycle is under way)")
        self.runtime.power.power_off()   # now: whatever comes next finds the power off
        self.context.start_work(self._cycle())

    def stop(self) -> None:
        self._restore.set()

    async def _cycle(self) -> None:
        await self.runtime.lose_power()
        await self._restore.wait()
        await self.runtime.restore_power()


__all__ = ["Plug", "PowerCycle", "Unplug"]
