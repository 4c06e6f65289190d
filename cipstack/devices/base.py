"""A device made of CIP objects: the standard objects every EtherNet/IP adapter has.

Device families (ACG-ET2, MX2, RX) build on ``Device``: they add their own objects and
assemblies to the same message router. The transport (EtherNet/IP, CompoNet) never sees a
device, only its router and its identity.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from ..assemblies.schema import AssemblySchema
from ..cip.epath import ElectronicKey
from ..cip.router import MessageRouter
from ..cip.status import CipError, ExtendedStatus, GeneralStatus
from ..eip.target.connection_manager import ConnectionManagerObject, ConnectionTable
from ..eip.target.io_target import CIP_MULTICAST_BASE, ConnectionKind, IoConnection, IoProfile
from ..eip.wire.identity_items import IdentityRecord
from ..errors import BadRequest, StateRefused
from ..objects.assembly import AssemblyObject
from ..objects.file import FileObject, StoredFile
from ..objects.identity import ExtendedDeviceStatus, IdentityInfo, IdentityObject, IdentityStatus
from ..objects.message_router import MessageRouterObject
from ..objects.tcpip import EthernetLinkObject, NetworkInterface, TcpIpObject
from .state import StateWriter

if TYPE_CHECKING:
    from .keypad import Keypad

log = logging.getLogger(__name__)



class NoDrive(BadRequest, NotImplementedError):
    """A drive's operation (a trip, a reset) asked of a device that simulates no drive. Still a
    ``NotImplementedError``, as it was before it was a ``CipstackError``."""


class TripRefused(StateRefused, ValueError):
    """A trip the device's present state does not take (it is tripped already and keeps its first trip):
    the request was understood, the device said no."""

@dataclass(frozen=True)
class TripReport:
    """A trip as every surface reports it, whatever the family's own record of it: how the emulator's
    messages name it and the CIP fault code it reports (None where the family has none)."""

    label: str
    fault_code: int | None = None


@dataclass(frozen=True)
class DriveTrips:
    """What a device that simulates a drive declares of its trips (``Device.drive_trips``): a device
    without a drive declares none, and the command service refuses a trip or a reset from that."""

    #: Trip the drive now with a fault code (or name) of its manual: the trip, as reported.
    #: ``KeyError`` or ``ValueError`` (a ``BadRequest``) for a code it does not take, ``TripRefused``
    #: when its present state does not take one.
    inject: Callable[[int | str], TripReport]
    #: Raise what ``inject`` would for a code it does not take; nothing for one it takes.
    check: Callable[[int | str], None]
    #: A fault reset, now: the trip it cleared, None when there was none; ``TripRefused`` when it holds.
    reset: Callable[[], TripReport | None]
    #: The codes ``inject`` takes, as one line for an error message.
    codes: Callable[[], str]
    #: Each trip ``inject`` takes, as a front panel offers it: ``code`` (what to send), ``label``, the CIP
    #: ``fault_code``.
    choices: Callable[[], list[dict[str, object]]]


#: Told of one register a Modbus request wrote: the drive, the address, the raw value, the time, and the
#: request's source (a TCP peer's ``host:port``, the RTU station addressed).
RegisterWritten = Callable[[Any, int, int, float, object], None]


@dataclass(frozen=True)
class RtuPort:
    """A drive's RS-485 port as the line's shell (``cipstack.modbus.rtu_line``) serves it, declared by the
    family: the shell knows no family's Modbus-RTU slave or register map."""

    #: The drive's sans-I/O slave on a line: ``slave(paced, written)`` (``rtu_line.Slave``).
    slave: Callable[[bool, RegisterWritten | None], Any]
    #: The line settings the drive's registers give now (``rtu_line.LineSettings``): what the port opens at.
    line_settings: Callable[[], Any]
    #: The most drives one line takes, and where that bound comes from (for the message).
    max_drives: int
    source: str


@dataclass(frozen=True)
class ModbusDrive:
    """What a device hands its Modbus ports: the present drive (a device may replace its drive, on an
    Identity reset or a power cycle), the writer of its saves, and its RS-485 port if it has one."""

    drive: Callable[[], Any]
    saves: StateWriter | None = None
    rtu: RtuPort | None = None
    #: Its Modbus TCP: ``tcp(written)`` makes the sans-I/O core (``tcp_server.TcpCore``) the server's shell
    #: runs; None for a drive without Modbus TCP.
    tcp: Callable[[RegisterWritten | None], Any] | None = None
    #: The device's name for a one-line error (``--modbus-port`` on a device without Modbus).


@dataclass
class DeviceLimits:
    max_sessions: int = 32
    max_connections: int = 32


@dataclass
class Device:
    identity_info: IdentityInfo
    interface: NetworkInterface = field(default_factory=NetworkInterface)
    limits: DeviceLimits = field(default_factory=DeviceLimits)
    #: TCP/IP Interface and Ethernet Link objects: an EtherNet/IP device has them, a CompoNet slave not.
    ethernet: bool = True

    def __post_init__(self) -> None:
        self.router = MessageRouter()
        self.connection_table = ConnectionTable(self.limits.max_connections)
        #: Reset types requested over the network, for the shell to act on.
        self.pending_reset: int | None = None
        self.identity = IdentityObject(self.identity_info, on_reset=self._on_reset)
        self.router.register(self.identity)
        self.router.register(MessageRouterObject(self.router, self.limits.max_connections))
        self.assembly = AssemblyObject()
        self.router.register(self.assembly)
        self.connection_manager = ConnectionManagerObject(self.connection_table, key_check=self.check_key)
        self.router.register(self.connection_manager)
        self.tcpip = TcpIpObject(self.interface)
        self.ethernet_link = EthernetLinkObject(self.interface)
        if self.ethernet:
            self.router.register(self.tcpip)
            self.router.register(self.ethernet_link)
        if self.files:
            self.router.register(FileObject(self.files))
        self._io_connections: dict[int, IoConnection] = {}
        self._io_faulted = False

    # -- identity -------------------------------------------------------------------------------
    def identity_record(self) -> IdentityRecord:
        info = self.identity_info
        return IdentityRecord(info.vendor_id, info.device_type, info.product_code, info.revision,
                              self.identity.status, info.serial_number, info.product_name, self.identity.state)

    def check_key(self, key: ElectronicKey) -> None:
        """Electronic key check of a connection path (0x0114 / 0x0115 / 0x0116); zero fields match anything."""
        info = self.identity_info
        if (key.vendor_id and key.vendor_id != info.vendor_id) or (
                key.product_code and key.product_code != info.product_code):
            raise CipError(GeneralStatus.CONNECTION_FAILURE, (ExtendedStatus.VENDOR_OR_PRODUCT_CODE_MISMATCH,))
        if key.device_type and key.device_type != info.device_type:
            raise CipError(GeneralStatus.CONNECTION_FAILURE, (ExtendedStatus.DEVICE_TYPE_MISMATCH,))
        major, minor = info.revision
        if key.major_revision:
            if key.major_revision != major:
                raise CipError(GeneralStatus.CONNECTION_FAILURE, (ExtendedStatus.REVISION_MISMATCH,))
            # Compatible: any minor revision the device can emulate (not newer than its own).
            too_new = key.minor_revision > minor
            if key.minor_revision and ((key.compatibility and too_new)
                                       or (not key.compatibility and key.minor_revision != minor)):
                raise CipError(GeneralStatus.CONNECTION_FAILURE, (ExtendedStatus.REVISION_MISMATCH,))

    def _on_reset(self, reset_type: int) -> None:
        log.info("Identity Reset type %d requested", reset_type)
        self.pending_reset = reset_type
        self.reset(reset_type)

    def reset(self, reset_type: int) -> None:
        """Identity Reset over the network: type 0 (as a power cycle, as far as the device's manual says
        its Identity does one) or 1 (return to defaults); families override."""

    def power_cycle(self, now: float) -> None:
        """The whole device loses its power and gets it back at ``now``: it keeps what its family keeps
        in non-volatile memory and nothing else. The shell ends every connection first (the
        ``power-cycle`` fault, ``cipstack.faults``); the device never sees a socket. Here, what any
        device holds only while powered: the data last written to its assemblies (zeros at power-on)
        and the I/O connection bits of Identity attribute 5 (no I/O connection, none faulted).
        Families extend it with their own rules (``AcgDevice``, ``OmronDevice``, ``EdsDevice``)."""
        for store in self.assembly.stores.values():
            store[:] = bytes(len(store))
        self._io_connections.clear()
        self._io_faulted = False
        self.update_io_status()

    # -- emulator control (test rigs) -------------------------------------------------------------
    def drive_trips(self) -> DriveTrips | None:
        """The trips of the simulated drive, as the command service's ``trip``, ``reset`` and ``trips``
        operations use them; None for a device that simulates no drive (the declaration lacks them,
        so those operations are refused from it)."""
        return None

    def data_schema(self, instance: int) -> AssemblySchema | None:
        """The declaration an assembly instance's data decodes by (its field names), None where the
        device declares none for it (an EDS file's vendor assembly; an instance it does not serve)."""
        return None

    def status_line(self) -> str | None:
        """A compact line of the device's state for the emulator's console, or None."""
        return None

    def status_fields(self) -> dict[str, object] | None:
        """The state ``status_line`` shows, field by field (``cipstack drive status --json``), or None."""
        return None

    def keypad(self) -> Keypad | None:
        """The drive's keypad (``cipstack.devices.keypad``): its parameters by code, in the keypad's
        unit; None for a device without one."""
        return None

    # -- ports the family declares ------------------------------------------------------------------
    def modbus_drive(self) -> ModbusDrive | None:
        """The drive this device serves over Modbus (TCP on its network card, RTU on its RS-485 port),
        or None for a device that speaks no Modbus. The shells (``cipstack.modbus``) serve it as ports
        of the running device; the device never sees their sockets or tty."""
        return None

    # -- saved parameters -------------------------------------------------------------------------
    #: Where the device's saves are written off the event loop (``state.StateWriter``), or None.
    saves: StateWriter | None = field(default=None, kw_only=True)
    #: Files the device serves through a File object (class 0x37): its EDS file, as EtherNet/IP
    #: devices that carry theirs do. None registers no File object.
    files: tuple[StoredFile, ...] = field(default=(), kw_only=True)

    def flush_saves(self, timeout: float | None = None) -> bool:
        """Wait until the saves handed to the state file are written (or failed); False on timeout."""
        return self.saves.flush(timeout) if self.saves is not None else True

    def close(self) -> None:
        """Write the pending saves and stop the state writer: the shell calls it when it stops."""
        if self.saves is not None:
            self.saves.close()

    # -- time -----------------------------------------------------------------------------------
    def advance(self, now: float) -> None:
        """Move the device's simulation to ``now`` (ramps, timers); families with behaviour override."""

    def next_deadline(self) -> float | None:
        """When the simulation next changes by itself, or None; the adapter calls ``advance`` then."""
        return None

    def tick(self, now: float) -> float | None:
        """``advance(now)``, then ``next_deadline()``: the adapter's call before every request and
        datagram, one call so that a family can make the common case (a drive at rest) cheap."""
        self.advance(now)
        return self.next_deadline()

    @property
    def inactivity_timeout(self) -> float:
        return float(self.tcpip.inactivity_timeout)

    # -- class 1 ----------------------------------------------------------------------------------
    def io_profile(self) -> IoProfile | None:
        """What this device offers for class 1 I/O: any pair of its output (consumed) and input
        (produced) assemblies, read at each Forward_Open; None when it has no input assembly (nothing
        to produce). A family that offers only some pairs, or other RPIs, overrides this."""
        points = self.assembly.points
        if not any(not point.consumed for point in points.values()):
            return None
        return IoProfile(consumed=lambda: {i: p for i, p in points.items() if p.consumed},
                         produced=lambda: {i: p for i, p in points.items() if not p.consumed})

    def multicast_block(self) -> tuple[int, int]:
        """T->O multicast addresses from TCP/IP attribute 9: the CIP default algorithm
        (239.192.1.0 + 32 x ((host id - 1) mod 1024), 32 addresses) unless configured."""
        config = self.tcpip.get(1, 9)
        if config["alloc_control"] == 1 and config["num_mcast"]:
            return config["mcast_start_addr"], config["num_mcast"]
        interface = self.tcpip.get(1, 5)
        host_id = interface["ip_address"] & ~interface["network_mask"] & 0xFFFFFFFF
        return CIP_MULTICAST_BASE + ((host_id - 1) & 0x3FF) * 32, 32

    def update_io_status(self) -> None:
        """Identity status: bit 0 owned, bits 4-7 the extended device status of the I/O connections."""
        connections = list(self._io_connections.values())
        owned = any(c.kind is ConnectionKind.EXCLUSIVE_OWNER for c in connections)
        if self._io_faulted and not connections:
            extended = ExtendedDeviceStatus.IO_CONNECTION_FAULTED
        elif not connections:
            extended = ExtendedDeviceStatus.NO_IO_CONNECTION
        elif any(c.run for c in connections if c.kind is ConnectionKind.EXCLUSIVE_OWNER):
            extended = ExtendedDeviceStatus.IO_CONNECTION_RUNNING
        elif owned:
            extended = ExtendedDeviceStatus.IO_CONNECTION_IDLE
        else:
            extended = ExtendedDeviceStatus.IO_CONNECTION_RUNNING
        status = int(self.identity.get(1, 5)) & ~(0x00F0 | IdentityStatus.OWNED)
        status |= (extended << 4) | (IdentityStatus.OWNED if owned else 0)
        self.identity.set(1, 5, status)

    def io_opened(self, connection: IoConnection) -> None:
        self._io_connections[connection.ot_connection_id] = connection
        self._io_faulted = False
        self.update_io_status()

    def io_closed(self, connection: IoConnection, timed_out: bool) -> None:
        self._io_connections.pop(connection.ot_connection_id, None)
        self._io_faulted = timed_out
        self.update_io_status()

    def io_run_idle(self, connection: IoConnection, run: bool) -> None:
        self.update_io_status()
