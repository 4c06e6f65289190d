"""One HTTP API for a plant spread over machines or Kubernetes pods: ``cipstack plant``.

Each fleet (``cipstack fleet --http``, one shard of the plant each) serves its own devices' API; the
plant view finds the fleets by name, a DNS name whose A records are every fleet (a Kubernetes headless
Service lists every pod of its StatefulSet), and relays to them as a fleet's parent relays to its
workers (``http_relay.RelayApi``): every device of every fleet by its address, ``/devices`` with the
fleet each device is on, ``/metrics`` of every fleet in one.

Every ``refresh`` seconds it resolves the names again and asks each fleet for its devices: a fleet that
is new is added; one that does not answer, or is no longer in the records (its pod was deleted), is
shown as such, its devices still listed with ``error`` and answering 503 naming it, as a lost worker's
do; a fleet that lists a device another fleet listed before (a pod that came back at another
address) serves it from then on.

The resolver is a collaborator (``Resolver``): ``resolve_addresses`` asks the system's resolver
(``getaddrinfo``); a test or a site with its own directory passes another.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
from collections.abc import Awaitable, Callable, Sequence

from yarl import URL

from ..errors import BadRequest
from .http import one_line_records
from .http_relay import Backend, RelayApi
from .service import is_whole_number

log = logging.getLogger(__name__)
one_line_records(log)

#: How often the plant view looks for fleets and asks each for its devices, by default.
DEFAULT_REFRESH = 5.0

#: ``(name, port)`` -> the ``(address, port)`` of each fleet it names.
Resolver = Callable[[str, int], Awaitable[list[tuple[str, int]]]]


class PlantError(BadRequest):
    """A plant view's setting that cannot be served (one line)."""


async def resolve_addresses(name: str, port: int) -> list[tuple[str, int]]:
    """The IPv4 addresses of ``name`` (its A records, or itself when it is an address), each with ``port``;
    none when the name does not resolve (a headless Service with no pod yet)."""
    loop = asyncio.get_running_loop()
    try:
        found = await loop.getaddrinfo(name, port, family=socket.AF_INET, type=socket.SOCK_STREAM)
    except socket.gaierror:
        return []
    return sorted({(str(info[4][0]), port) for info in found})


def parse_fleet(text: str) -> tuple[str, int]:
    """``--fleet NAME:PORT``: a DNS name (or an address) and the port of its fleets' HTTP API."""
    name, sep, port_text = text.rpartition(":")
    # ASCII digits: ``isdigit()`` alone takes a superscript two, which ``int()`` then refuses with a traceback.
    if not sep or not name or not is_whole_number(port_text) or not 0 < int(port_text) < 65536:
        raise PlantError(f"--fleet {text!r} is not NAME:PORT (e.g. cipstack-fleet:8080)")
    return name, int(port_text)


class _Fleet:
    """A fleet's API as the plant view found it: its relay backend, which asks it why it is down."""

    def __init__(self, where: tuple[str, int], token: str | None) -> None:
        host, port = where
        self.where = where
        #: Why it is shown as not serving, or None.
        self.lost: str | None = None
        self.backend = Backend(f"fleet {_text(where)}", None, down=self.why_lost,
                               url=URL.build(scheme="http", host=host, port=port),
                               headers={"Authorization": f"Bearer {token}"} if token else {},
                               shown={"fleet": _text(where)})

    def why_lost(self) -> str | None:
        return self.lost


class PlantView:
    """The relay of a plant's fleets, found through ``resolver`` (see the module docstring)."""

    def __init__(self, fleets: Sequence[tuple[str, int]], relay: RelayApi, resolver: Resolver = resolve_addresses,
                 token: str | None = None, refresh: float = DEFAULT_REFRESH) -> None:
        """``fleets``: the names (and ports) to resolve; ``relay``: the API it serves them with (no backend
        yet, no shard: each fleet says its own); ``token``: what each fleet's API asks for."""
        self.names = list(fleets)
        self.relay = relay
        self.resolver = resolver
        self.token = token
        self.refresh_every = refresh
        self.fleets: dict[tuple[str, int], _Fleet] = {}
        self._task: asyncio.Task[None] | None = None

    async def start(self) -> None:
        """Listen, find the fleets there are now, then look again every ``refresh`` seconds."""
        await self.relay.start()
        try:
            await self.refresh()
        except BaseException:
            await self.relay.close()
            raise
        self._task = asyncio.get_running_loop().create_task(self._refreshing())

    async def close(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None
        await self.relay.close()

    async def _refreshing(self) -> None:
        while True:
            await asyncio.sleep(self.refresh_every)
            try:
                await self.refresh()
            except Exception:   # a surprise must not end the plant view: it is logged, the next round retries
                log.exception("looking for the plant's fleets failed")

    async def refresh(self) -> None:
        """Resolve the names, add the fleets that are new, and ask each known one for its devices."""
        present: set[tuple[str, int]] = set()
        for name, port in self.names:
            present.update(await self.resolver(name, port))
        for where in sorted(present - set(self.fleets)):
            await self._add(where)
        for where, fleet in sorted(self.fleets.items()):
            if where not in present:
                self._lose(fleet, f"fleet {_text(where)} is gone (no longer in the DNS records of "
                                  f"{', '.join(name for name, _ in self.names)})")
                continue
            try:
                devices = await self.relay.listing(fleet.backend)
            except ConnectionError as exc:
                self._lose(fleet, str(exc))
                continue
            if fleet.lost is not None or devices != fleet.backend.devices:   # back, or restarted with others
                fleet.backend.devices = devices
                self.relay.routes.update((entry["address"], fleet.backend) for entry in devices)
                if fleet.lost is not None:
                    log.info("fleet %s serves again", _text(where))
                fleet.lost = None
        await self._forget()

    async def _forget(self) -> None:
        """Drop the lost fleets none of whose devices is routed to them any more (each came back elsewhere),
        so that a plant whose pods restart for days keeps no trace of each address they had."""
        routed = {id(backend) for backend in self.relay.routes.values()}
        for where, fleet in list(self.fleets.items()):
            if fleet.lost is not None and id(fleet.backend) not in routed:
                del self.fleets[where]
                self.relay.backends.remove(fleet.backend)
                await fleet.backend.close()

    async def _add(self, where: tuple[str, int]) -> None:
        fleet = _Fleet(where, self.token)
        backend = fleet.backend
        try:
            await self.relay.add(backend)
        except ConnectionError as exc:   # not answering yet (a pod starting): the next round asks again
            log.info("%s", exc)
            return
        self.fleets[where] = fleet
        log.info("fleet %s: %d devices", _text(where), len(backend.devices))

    @staticmethod
    def _lose(fleet: _Fleet, why: str) -> None:
        if fleet.lost is None:
            log.warning("%s; its devices answer 503 on the plant's HTTP API", why)
        fleet.lost = why


def _text(where: tuple[str, int]) -> str:
    return f"{where[0]}:{where[1]}"


__all__ = ["DEFAULT_REFRESH", "PlantError", "PlantView", "Resolver", "parse_fleet", "resolve_addresses"]
