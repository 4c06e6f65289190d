"""The ports of a running device, each a thing with a name, a medium, and open/close.

The EtherNet/IP encapsulation port (TCP and UDP 44818), the class 1 endpoint (UDP 2222), Modbus TCP
and the RS-485 line of Modbus-RTU. Ethernet ports need power and link; the RS-485 port needs power
only (``power.PowerLink`` decides; nothing else opens or closes a port once the device runs).
Closing a port and opening it again keeps its number, also one the OS chose.
"""

from __future__ import annotations

import asyncio
import enum
from collections.abc import Callable
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from ..eip.io_server import IoCore, IoEndpoint
    from ..modbus.rtu_line import RtuLine


class Medium(enum.Enum):
    ETHERNET = "ethernet"
    SERIAL = "serial"


class Port(Protocol):
    name: str
    medium: Medium

    @property
    def is_open(self) -> bool: ...

    async def open(self) -> None: ...

    async def close(self) -> None: ...


class Listener(Protocol):
    """A server that listens on its port: ``start`` takes the port (the one it had, after a ``close``),
    ``close`` gives it back with every connection."""

    @property
    def is_open(self) -> bool: ...

    async def start(self) -> None: ...

    async def close(self) -> None: ...


class ServerPort:
    """A listening server as a port: the EtherNet/IP encapsulation server (TCP and UDP 44818, or
    ``--port``: sessions, explicit messages, ListIdentity) or the card's Modbus TCP (``--modbus-port``)."""

    medium = Medium.ETHERNET

    def __init__(self, name: str, server: Listener) -> None:
        self.name = name
        self.server = server

    @property
    def is_open(self) -> bool:
        return self.server.is_open

    async def open(self) -> None:
        await self.server.start()

    async def close(self) -> None:
        await self.server.close()


class Class1Port:
    """The class 1 UDP endpoint. Closed, its socket is gone but the device's side of each connection
    goes on as if every datagram were lost on the cable: productions fall due and go nowhere, and a
    connection whose O->T data stops coming times out on its own watchdog (a device whose cable is
    pulled still runs its connections' timers)."""

    medium = Medium.ETHERNET

    def __init__(self, endpoint: IoEndpoint, core: IoCore) -> None:
        self.endpoint = endpoint
        self.core = core
        self.name = "class 1 I/O"
        self._dark: asyncio.TimerHandle | None = None

    @property
    def is_open(self) -> bool:
        return self.endpoint.is_open

    async def open(self) -> None:
        self._stop_dark()
        await self.endpoint.start()

    async def close(self) -> None:
        await self.endpoint.close()
        self._run_dark()

    def shutdown(self) -> None:
        """The device stops: no timer of a closed port fires after it."""
        self._stop_dark()

    def _stop_dark(self) -> None:
        if self._dark is not None:
            self._dark.cancel()
            self._dark = None

    def _run_dark(self) -> None:
        self._stop_dark()
        deadline = self.core.next_deadline()
        if deadline is not None:
            self._dark = asyncio.get_running_loop().call_at(deadline, self._on_dark)

    def _on_dark(self) -> None:
        self._dark = None
        now = asyncio.get_running_loop().time()
        self.core.poll(now)        # produced, and lost on the wire
        self.core.expire(now)
        self._run_dark()


class Rs485Port:
    """The drive's RS-485 line (Modbus-RTU). The tty is opened once, the first time the port opens, when
    the device starts (a pty's client must not see it vanish): ``open_line`` opens it and puts the
    drives on it, raising ``RtuPortError`` for a device that cannot be opened. The port is open while
    the drives on it have power, and closed it is silent: whatever comes is read and dropped."""

    medium = Medium.SERIAL

    def __init__(self, open_line: Callable[[], RtuLine]) -> None:
        self.open_line = open_line
        self.name = "RS-485"
        #: The line this port opened (None before its first ``open`` and after ``release``).
        self.line: RtuLine | None = None

    @property
    def is_open(self) -> bool:
        return self.line is not None and self.line.powered

    async def open(self) -> None:
        if self.line is None:
            line = self.open_line()
            await line.start()
            self.line = line
        self.line.power_on()

    async def close(self) -> None:
        if self.line is not None:
            self.line.power_off()

    async def release(self) -> None:
        """The device stops: the tty is closed."""
        line, self.line = self.line, None
        if line is not None:
            await line.close()


__all__ = ["Class1Port", "Listener", "Medium", "Port", "Rs485Port", "ServerPort"]
