"""``GET /plant``: one row of every device an API serves, for the front panel's grid of a plant. One
request a second gives a plant of a thousand devices whole (where a request per device did not keep
up); a fleet's relay asks each worker once and joins their rows (``relay_rows``).

A row is what the grid shows and sorts by: the address, product, state (with a trip), output
frequency, power and link, sessions and connections, active faults, and the class 1 productions that
went late or were missed (an overloaded worker's devices say so here)."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Awaitable, Callable, Mapping
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .service import DeviceService

#: Devices read between two returns to the event loop: a slice holds the loop well inside a class 1
#: production's tolerance, whatever the size of the plant.
DEVICES_PER_SLICE = 16


def device_row(address: str, service: DeviceService) -> dict[str, Any]:
    """The grid's row of one device, read now."""
    status = service.status()
    drive = status.get("drive") or {}
    productions = status.get("productions") or {}
    return {"address": address, "product_name": service.name,
            "state": drive.get("state") if drive else status.get("status"), "trip": drive.get("trip"),
            "output_frequency_hz": drive.get("output_frequency_hz"), "power": status.get("power"),
            "link": status.get("link"), "sessions": status.get("sessions", 0),
            "class3_connections": status.get("class3_connections", 0),
            "class1_connections": status.get("class1_connections", 0), "faults": status.get("faults", 0),
            "sent": productions.get("sent", 0), "late": productions.get("late", 0),
            "missed": productions.get("missed", 0)}


async def plant_rows(devices: Mapping[str, DeviceService]) -> list[dict[str, Any]]:
    """Every device's row, in address order, read in slices with the loop's other work between them."""
    rows = []
    for index, (address, service) in enumerate(sorted(devices.items()), start=1):
        rows.append(device_row(address, service))
        if index % DEVICES_PER_SLICE == 0:
            await asyncio.sleep(0)
    return rows


def down_rows(devices: list[dict[str, Any]], shown: Mapping[str, Any], why: str) -> list[dict[str, Any]]:
    """The rows of devices whose worker (or fleet) no longer answers: their listing, and why."""
    return [{**entry, **shown, "error": why} for entry in devices]


#: How long one reading of the rows answers every grid that asks: several open grids cost the devices'
#: processes one reading between them, not one each.
ROWS_SHARED_FOR = 0.5


class SharedRows:
    """The rows ``read`` gives, read once for every request within ``ROWS_SHARED_FOR`` (and once for
    requests that come while a reading is under way)."""

    def __init__(self, read: Callable[[], Awaitable[list[dict[str, Any]]]],
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.read = read
        self.clock = clock
        self._rows: tuple[float, list[dict[str, Any]]] | None = None
        self._reading: asyncio.Future[list[dict[str, Any]]] | None = None

    async def get(self) -> list[dict[str, Any]]:
        if self._rows is not None and self.clock() - self._rows[0] < ROWS_SHARED_FOR:
            return self._rows[1]
        if self._reading is None:
            self._reading = asyncio.ensure_future(self._read())
        return await asyncio.shield(self._reading)

    async def _read(self) -> list[dict[str, Any]]:
        try:
            rows = await self.read()
            self._rows = (self.clock(), rows)
            return rows
        finally:
            self._reading = None


__all__ = ["DEVICES_PER_SLICE", "ROWS_SHARED_FOR", "SharedRows", "device_row", "down_rows", "plant_rows"]
