"""The adapter emulator: where a device meets the EtherNet/IP transport."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import signal
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .control import ControlAddress, ControlServer, ControlTaken, default_control_path
from .control.events import EventStream
from .control.service import DeviceService
from .devices.base import Device, DeviceLimits
from .devices.keypad import Keypad, NoKeypad
from .devices.profiles import (
    DEFAULT_MAC,
    DEFAULT_PROFILE,
    ProfileOptions,
    build_device,
    families_having,
    keypad_families,
)
from .eip.interfaces import interface_of
from .eip.io_core import DEFAULT_IO_PORT, ProductionGrid
from .eip.io_server import DatagramPaths, IoEndpoint, freeze_startup_objects
from .eip.target.core import EncapsulationTarget, TargetSettings
from .eip.target.io_target import IoProfile, IoTarget
from .eip.target.limits import DEFAULT_MAX_TCP_CONNECTIONS
from .eip.target.seams import IoSeam, ReplySeam, RequestSeam, SecuredSeam
from .eip.target.server import DEFAULT_PORT, EncapsulationServer
from .eip.wire.encapsulation import DEFAULT_FRAME_TIMEOUT
from .eip.wire.identity_items import CAPABILITY_CIP_TCP, CAPABILITY_CLASS01_UDP
from .errors import BadRequest
from .faults import Fault, FaultController
from .listening import ListenError, held_log_records
from .modbus.rtu_line import RtuLine, RtuPortError, open_port
from .modbus.tcp_server import ModbusTcpServer
from .objects.file import StoredFile
from .objects.tcpip import NetworkInterface
from .runtime import Class1Port, DeviceRuntime, Port, PowerLink, Rs485Port, ServerPort
from .runtime.observer import IoEventRelay, Observers, register_relay
from .runtime.runtime import DeviceClock

if TYPE_CHECKING:
    from .cip.router import RequestContext
    from .security import Credentials
    from .security.authority import LabAuthority
    from .security.configuration import Configuration, Configurator
    from .security.dtls_target import DtlsServer
    from .security.endpoint import SecureEndpoint
    from .security.tls_target import Recipe, TlsServer

#: Seconds a CIP Security configuration session lasts without Kick_Timer (``security.configuration``).
SECURITY_CONFIG_TIMEOUT = 60.0

log = logging.getLogger(__name__)


def network_interface(host: str, mac: bytes) -> NetworkInterface:
    """What the TCP/IP Interface object of a device on ``host`` reports: the address and the netmask
    of the interface it is on (an adapter on 127.0.0.2 is on loopback, 255.0.0.0; one on a /24
    reports 255.255.255.0). On every address (0.0.0.0), the object keeps one: loopback's, since its
    attribute 5 is one interface's configuration and feeds the multicast allocation, which every
    originator must compute alike; ListIdentity, per request, gives the address it arrived on."""
    ip_address = host if host not in ("", "0.0.0.0", "localhost") else "127.0.0.1"
    interface = interface_of(ip_address)
    if interface is None:
        return NetworkInterface(ip_address=ip_address, mac=mac)
    return NetworkInterface(ip_address=str(interface.ip), network_mask=str(interface.netmask), mac=mac)


@dataclass
class AdapterSettings:
    host: str = "127.0.0.1"
    port: int = DEFAULT_PORT
    profile: str = DEFAULT_PROFILE
    max_sessions: int = 32
    #: Sessions one originator address may hold (None: half of ``max_sessions``, rounded up).
    max_sessions_per_host: int | None = None
    #: Class 3 (connected explicit messaging) connections.
    max_connections: int = 32
    #: Class 1 (I/O) connections (None: the device's own limit, 64 for the ACG-ET2).
    max_io_connections: int | None = None
    #: Open TCP connections to the encapsulation port, in total and per host (None: half the total).
    max_tcp_connections: int = DEFAULT_MAX_TCP_CONNECTIONS
    max_tcp_connections_per_host: int | None = None
    max_frame_length: int = 4200
    #: Seconds a TCP frame, once begun, has to arrive whole (``TargetSettings.frame_timeout``).
    frame_timeout: float = DEFAULT_FRAME_TIMEOUT
    #: UDP port of class 1 I/O (consumed O->T datagrams, and the default T->O destination port).
    io_port: int = DEFAULT_IO_PORT
    #: Seconds: while the next class 1 production is this near, O->T datagrams do not wake the loop
    #: and the production reads them first (``IoEndpoint``'s ``gather_within``; 0: off, each is read
    #: as it comes). ``io_server.GATHER_WITHIN_S`` is the value the benchmarks use.
    io_gather: float = 0.0
    #: Unix socket of the control channel (``cipstack drive ...``); None: the default for the port.
    control_path: Path | None = None
    #: Print the device's status line on stdout whenever it changes.
    status_lines: bool = False
    #: State file of saved parameters (None: in memory only).
    state_path: Path | None = None
    #: Model of families with several models.
    model: str | None = None
    #: Modbus TCP port for a drive that also speaks Modbus TCP (None: off; 0: any free port).
    modbus_port: int | None = None
    #: MAC address of the emulated card, from which its serial number derives (None: ``DEFAULT_MAC``).
    mac: bytes | None = None
    #: Modbus-RTU on the drive's RS-485 port: a serial device path, or "pty" for a new pseudo-terminal
    #: (None: off).
    rtu: str | None = None
    #: HTTP control API (``cipstack.control.http``) on ``HOST:PORT`` (None: off); another address than
    #: loopback only with ``http_allow_remote`` and a token.
    http: str | None = None
    http_token: str | None = None
    http_allow_remote: bool = False
    #: Files the device serves through its File object (its EDS file: ``cipstack.eds.served``).
    files: tuple[StoredFile, ...] = ()
    #: Host names the HTTP API answers to besides its addresses and localhost (``--http-allow-host``).
    http_hosts: tuple[str, ...] = ()
    #: CIP Security: the folder ``cipstack security init`` writes (None: plain EtherNet/IP only). With
    #: it the device also serves the same encapsulation over TLS on ``security_port``.
    security: Path | None = None
    #: TCP port of EtherNet/IP over TLS (2221, Wireshark's ENIP_SECURE_PORT; 0: any free one).
    security_port: int = 2221
    #: Serve the CIP Security, EtherNet/IP Security and Certificate Management objects (0x5D-0x5F): a
    #: device without ``security`` starts in Factory Default and can be configured over the network.
    #: Off by default in the library (a plain adapter imports nothing of ``cipstack.security``); the
    #: ``cipstack adapter`` command turns it on unless ``--no-security-objects``.
    security_objects: bool = False
    #: Once configured, refuse explicit requests that do not arrive over TLS (``security.endpoint``).
    secure_only: bool = False
    #: Seconds a configuration session lasts without Kick_Timer (``security.configuration``).
    security_config_timeout: float = SECURITY_CONFIG_TIMEOUT


class Adapter:
    """A running emulated device: composes the device, its ports, its runtime (``cipstack.runtime``),
    its faults, its event stream and the command service every control surface calls. The one place
    collaborators are made and passed in; nothing is patched in later."""

    def __init__(self, settings: AdapterSettings | None = None, device: Device | None = None,
                 production_grid: ProductionGrid | None = None) -> None:
        """``production_grid``: where class 1 productions start, shared by the adapters of one process
        so that theirs fall due together (``ProductionGrid``); by default one of its own."""
        self.settings = settings or AdapterSettings()
        s = self.settings
        self.device = device or build_device(s.profile, network_interface(s.host, s.mac or DEFAULT_MAC),
                                             DeviceLimits(s.max_sessions, s.max_connections),
                                             ProfileOptions(s.state_path, s.model, s.files))
        self.observers = Observers()
        self.clock = DeviceClock(self.device, self.observers)
        # The ports the device's family declares beside EtherNet/IP (the ACG's Modbus TCP and RS-485).
        modbus_drive = self.device.modbus_drive()
        product = self.device.identity_info.product_name
        if s.rtu is not None and (modbus_drive is None or modbus_drive.rtu is None):
            raise BadRequest(f"profile {s.profile!r} has no RS-485 Modbus-RTU port (one has: "
                             f"{families_having(lambda profile: profile.serial_link is not None)})")
        if s.modbus_port is not None and (modbus_drive is None or modbus_drive.tcp is None):
            raise BadRequest(f"profile {s.profile!r} has no Modbus TCP (the ACG-ET2 card speaks it)")
        self.modbus_drive = modbus_drive
        self.modbus: ModbusTcpServer | None = None
        if s.modbus_port is not None and modbus_drive is not None and modbus_drive.tcp is not None:
            self.modbus = ModbusTcpServer(modbus_drive.tcp(register_relay("modbus-tcp", self.observers)), s.host,
                                          s.modbus_port, saves=modbus_drive.saves,
                                          max_connections=s.max_tcp_connections,
                                          max_connections_per_host=s.max_tcp_connections_per_host,
                                          frame_timeout=s.frame_timeout)
        #: The drive's RS-485 port with ``settings.rtu``: its line opens when the adapter starts.
        self.rs485 = Rs485Port(self._open_rtu_line) if s.rtu is not None else None
        # Class 1 first: the encapsulation target offers it to the Connection Manager (``RequestContext.class1``).
        self.io: IoTarget | None = None
        self.io_seam: IoSeam | None = None
        self.io_endpoint: IoEndpoint | None = None
        #: Where class 1 datagrams of connections opened over DTLS go instead of UDP 2222.
        self.io_paths = DatagramPaths()
        profile = self.device.io_profile()
        if profile is not None:
            if s.max_io_connections is not None:
                profile.max_connections = s.max_io_connections
            self.io_endpoint = IoEndpoint(host=s.host, port=s.io_port,
                                          multicast_ttl=lambda: int(self.device.tcpip.get(1, 8)), exclusive=True,
                                          make_core=partial(self._class1_core, profile, production_grid),
                                          gather_within=s.io_gather, paths=self.io_paths)
            assert self.io is not None   # made by _class1_core, with the endpoint
            self.device.update_io_status()
        # --secure-only: a configured device's router refuses what did not come over TLS.
        policy = None
        if s.secure_only:
            from .security.endpoint import PlainRefusal

            policy = PlainRefusal(self.device.router, self._arrived_secured, self._security_configured)
        self.requests = RequestSeam(policy or self.device.router)
        self.replies = ReplySeam()
        self.target = EncapsulationTarget(
            self.device.router, self.device.identity_record,
            TargetSettings(max_sessions=s.max_sessions, max_sessions_per_host=s.max_sessions_per_host,
                           max_connections=s.max_connections, max_frame_length=s.max_frame_length,
                           frame_timeout=s.frame_timeout,
                           inactivity_timeout=lambda: self.device.inactivity_timeout,
                           capabilities=CAPABILITY_CIP_TCP | (CAPABILITY_CLASS01_UDP if self.io is not None else 0)),
            table=self.device.connection_table, requests=self.requests, tick=self.clock.tick, class1=self.io,
        )
        self.server = EncapsulationServer(self.target, s.host, s.port, max_tcp_connections=s.max_tcp_connections,
                                          max_tcp_connections_per_host=s.max_tcp_connections_per_host,
                                          replies=self.replies)
        #: EtherNet/IP over TLS with ``settings.security`` (``cipstack.security.tls_target``).
        self.tls: TlsServer | None = None
        #: EtherNet/IP and class 1 over DTLS on the same port number, UDP (``cipstack.security.dtls_target``).
        self.dtls: DtlsServer | None = None
        #: Where the CIP Security faults act on the TLS and DTLS listeners (``cipstack.faults.security``).
        self.secured_seam = SecuredSeam()
        if s.security is not None:
            from .security import Credentials
            from .security.dtls_target import DtlsServer
            from .security.endpoint import available_suites, available_suites_context
            from .security.tls_target import TlsServer

            credentials = Credentials.load(s.security)
            # TLS 1.2 offers what the EtherNet/IP Security object lists as its Allowed Cipher Suites.
            self.tls = TlsServer(self.target, credentials, s.host, s.security_port,
                                 max_connections=s.max_tcp_connections,
                                 max_connections_per_host=s.max_tcp_connections_per_host, replies=self.replies,
                                 recipe=available_suites_context, seam=self.secured_seam)
            # DTLS 1.2 with the same suites (the library's defaults would add suites the object does not list).
            self.dtls = DtlsServer(self.target, credentials, s.host, s.security_port, io=self.io_seam,
                                   paths=self.io_paths, seam=self.secured_seam, ciphers=available_suites(credentials))
        #: CIP Security's objects, their configuration and the TLS listener that follows it.
        self.secure: SecureEndpoint | None = None
        self.configurator: Configurator | None = None
        #: The lab CA of the security folder and the listeners' seam, as the faults reach them.
        self.authority: LabAuthority | None = None
        if s.security_objects or s.security is not None:
            from .security.authority import LabAuthority
            from .security.configuration import Configurator
            from .security.endpoint import (
                SecureEndpoint,
                configuration_of,
                load_configuration,
                state_folder,
            )
            from .security.objects import register as register_security_objects

            folder = state_folder(s.state_path) if s.security is None else None
            kept = load_configuration(folder)
            # A device configured over the network serves DTLS beside TLS, as --security DIR does; the
            # folder's DTLS listener (``self.dtls``) is the endpoint's until a Reset or a configuration
            # replaces it, as its TLS listener is.
            datagrams = self._dtls_server if self.io_seam is not None else None
            self.secure = SecureEndpoint(self._tls_server, s.security_port, folder, self.tls, kept, datagrams,
                                         self.dtls)
            self.authority = LabAuthority(self.secured_seam, self._serving_tls, self._serving_dtls)
            initial = configuration_of(self.tls.credentials) if self.tls is not None else kept
            self.configurator = Configurator(self.secure.configured, initial, s.security_config_timeout)
            register_security_objects(self.device.router, self.configurator, self._csr_defaults())
        ports: list[Port] = [ServerPort("EtherNet/IP", self.server)]
        if self.secure is not None:
            ports.append(ServerPort("EtherNet/IP over TLS", self.secure))
        elif self.tls is not None:
            ports.append(ServerPort("EtherNet/IP over TLS", self.tls))
        if self.dtls is not None and self.secure is None:   # else the endpoint's, which it opens and closes
            ports.append(ServerPort("EtherNet/IP over DTLS", self.dtls))
        if self.modbus is not None:
            ports.append(ServerPort("Modbus TCP", self.modbus))
        if self.io_endpoint is not None:
            ports.append(Class1Port(self.io_endpoint, self.io_seam))
        if self.rs485 is not None:
            ports.append(self.rs485)
        self.power = PowerLink(ports)
        self.runtime = DeviceRuntime(self.device, self.clock, self.observers, self.power, self.target, self.server,
                                     self.requests, self.replies, self.io, self.io_seam, self.io_endpoint,
                                     self.rs485, self.authority)
        self.faults = FaultController(self.runtime)
        self._events = EventStream(self.runtime, self.faults)
        self.service = DeviceService(self.runtime, self.faults, self._events, product)
        self.control_server: ControlServer | None = None
        #: The HTTP control API, while serving with ``settings.http``.
        self.http_api: Any = None

    def _tls_server(self, credentials: Credentials, recipe: Recipe,
                    port: int) -> TlsServer:
        """A TLS listener for a configuration applied over the network, with this adapter's limits."""
        from .security.tls_target import TlsServer

        s = self.settings
        return TlsServer(self.target, credentials, s.host, port, max_connections=s.max_tcp_connections,
                         max_connections_per_host=s.max_tcp_connections_per_host, replies=self.replies,
                         recipe=recipe, seam=self.secured_seam)

    def _dtls_server(self, credentials: Credentials, configuration: Configuration, port: int) -> DtlsServer:
        """The DTLS listener of a configuration applied over the network: its certificate and trust, its
        Allowed Cipher Suites, client certificates as Verify Client Certificate says, secured class 1, its
        sessions' idle timeout the DTLS Timeout attribute's seconds."""
        from .security.dtls_target import DtlsServer
        from .security.endpoint import dtls_server_context

        def recipe(made: Credentials) -> Any:
            return dtls_server_context(made, configuration)

        return DtlsServer(self.target, credentials, self.settings.host, port, io=self.io_seam, paths=self.io_paths,
                          verify_client=bool(configuration.verify_client), seam=self.secured_seam, recipe=recipe,
                          idle_timeout=float(configuration.dtls_timeout))

    def _serving_tls(self) -> TlsServer | None:
        """The TLS listener serving now: ``--security DIR``'s, or the configuration's."""
        return self.secure.server if self.secure is not None else self.tls

    def _serving_dtls(self) -> bool:
        dtls = self.secure.dtls if self.secure is not None else self.dtls
        return dtls is not None and dtls.is_open

    def _arrived_secured(self, context: RequestContext) -> bool:
        """Whether a request arrived over TLS (``--secure-only``)."""
        return self.secure is not None and self.secure.secured(context)

    def _security_configured(self) -> bool:
        return self.configurator is not None and self.configurator.is_configured()

    def _csr_defaults(self) -> dict[str, str]:
        """What a Create_CSR leaves empty: the product's name, its serial number, its address."""
        info = self.device.identity_info
        return {"common name": info.product_name, "serial number": f"{info.serial_number:08X}",
                "subject alternative name": self.device.interface.ip_address}

    def _class1_core(self, profile: IoProfile, grid: ProductionGrid | None, endpoint: IoEndpoint) -> IoSeam:
        """The class 1 core and its seam, made by their UDP ``endpoint`` (``IoEndpoint.make_core``) with
        every hook they call: the device's Assembly object takes consumed data, the clock moves the
        device, the endpoint re-arms its timer when a connection opens and sends what a filter delays."""
        self.io = IoTarget(profile, IoEventRelay(self.device, self.observers), self.device.multicast_block,
                           self.settings.io_port, grid, deliver=self.device.assembly.deliver, tick=self.clock.tick,
                           changed=endpoint.wakeup)
        self.io_seam = IoSeam(self.io, endpoint.send_later)
        return self.io_seam

    @property
    def port(self) -> int:
        return self.server.port

    @property
    def rtu(self) -> RtuLine | None:
        """The RS-485 line of ``settings.rtu`` once started."""
        return self.rs485.line if self.rs485 is not None else None

    # -- faults and events (cipstack.faults, cipstack.control.events) ------------------------------------
    @property
    def events(self) -> EventStream:
        """What happened, when (``cipstack.control.events``): connections, run/idle, the drive's state and
        trips, parameter writes, faults. Watching starts on first use; nothing is paid before."""
        self._events.start()
        return self._events

    def fault(self, name: str, **options: object) -> Fault:
        """Apply the fault ``name`` now, options as the command line names them (``share=0.1``,
        ``connection=0x...``, ``for_=2.0`` or ``**{"for": 2.0}``); see ``FaultController.apply``."""
        if "for_" in options:
            options["for"] = options.pop("for_")
        return self.faults.apply(name, **options)

    def clear_faults(self, which: int | str | None = None) -> list[Fault]:
        """Clear every active fault, or one by id, or those of one name."""
        return self.faults.clear(which)

    async def start(self) -> None:
        """Listen on every port, each exclusively; a port that is taken raises ``ListenError``
        naming it, with nothing left open and nothing logged (the error is the one line to say)."""
        with held_log_records() as held:
            await self._start()
            held.release()

    async def _start(self) -> None:
        # The EtherNet/IP ports are taken first (a taken one is the error to name first) but TCP
        # accepts last: a client that finds 44818 accepting, and goes straight on to Modbus TCP or
        # to a Forward_Open, finds every other port ready.
        s = self.settings
        await self._listen(lambda: self.server.start(serve=False),
                           lambda: (f"{'UDP' if self.server.is_open else 'TCP'} "
                                    f"{s.host}:{s.port} (EtherNet/IP, --port)"))
        if self.modbus is not None:
            await self._listen(self.modbus.start, lambda: f"TCP {s.host}:{s.modbus_port} (Modbus TCP, --modbus-port)")
        if self.secure is not None:   # TLS, then DTLS on the same number (``SecureEndpoint.start``)
            await self._listen(self.secure.start, self._secure_port_named)
        if self.rs485 is not None:
            await self._open_rtu(self.rs485)
        self.clock.tick(asyncio.get_running_loop().time())
        if self.io_endpoint is not None:
            await self._listen(self.io_endpoint.start, lambda: f"UDP {s.host}:{s.io_port} (class 1 I/O, --io-port)")
            if self.io is not None:
                self.io.io_port = self.io_endpoint.port
        # Another process may have begun to listen on the port since it was bound (SO_REUSEADDR lets
        # two bind it while neither listens): then listen() is what fails.
        await self._listen(self.server.serve, lambda: f"TCP {s.host}:{self.server.port} (EtherNet/IP, --port)")

    def _secure_port_named(self) -> str:
        """The secure port that did not listen: UDP (DTLS) once TLS listens, else TCP (TLS)."""
        s, server = self.settings, self._serving_tls()
        if server is not None and server.is_open:
            return f"UDP {s.host}:{server.port} (EtherNet/IP over DTLS, --security-port)"
        return f"TCP {s.host}:{s.security_port} (EtherNet/IP over TLS, --security-port)"

    async def _listen(self, start: Callable[[], Awaitable[None]], where: Callable[[], str]) -> None:
        """``start`` one listener; if it cannot listen, close what is open and raise ``ListenError``
        naming ``where`` (asked before closing: it may tell which socket of the listener failed)."""
        try:
            await start()
        except OSError as exc:
            what = where()
            await self.close()
            raise ListenError(what, exc) from None

    async def _open_rtu(self, rs485: Rs485Port) -> None:
        """Open the drive's RS-485 port; a device that cannot be opened raises ``RtuPortError`` naming
        it, with nothing left open."""
        try:
            await rs485.open()
        except RtuPortError:
            await self.close()
            raise

    def _open_rtu_line(self) -> RtuLine:
        """The RS-485 line on ``settings.rtu`` ("pty" or a serial device) with the drive on it: what
        the RS-485 port opens when the adapter starts (``RtuPortError`` if the device cannot be opened)."""
        drive = self.modbus_drive
        # Checked when the adapter was made.
        assert drive is not None and drive.rtu is not None and self.settings.rtu is not None
        rtu = drive.rtu
        line = RtuLine(open_port(self.settings.rtu, rtu.line_settings()), rtu.max_drives, rtu.source)
        line.add(rtu.slave(line.port.paced, register_relay("modbus-rtu", self.observers)), drive.saves)
        return line

    @property
    def control_path(self) -> ControlAddress:
        """Where ``cipstack drive`` finds this emulator: ``--control``, else the default for its host and port."""
        return self.settings.control_path or default_control_path(self.port, self.settings.host)

    async def start_serving(self) -> None:
        """Listen on every port and on the control socket; what is taken raises ``ListenError`` naming
        it, with nothing left open. The caller holds the log records (``held_log_records``)."""
        await self._start()
        control = ControlServer(self.control_path, self.control)
        try:
            await control.start()
        except OSError as exc:
            await self.close()
            raise ListenError(*self._control_refusal(exc)) from None
        self.control_server = control
        if self.settings.http is not None:
            from .control.http import HttpApi, parse_listen

            host, port = parse_listen(self.settings.http)
            api = HttpApi({self.settings.host: self.service}, host, port, token=self.settings.http_token,
                          allow_remote=self.settings.http_allow_remote, hosts=self.settings.http_hosts)
            try:
                await api.start()
            except OSError as exc:
                await self.stop_serving()
                raise ListenError(f"TCP {self.settings.http} (HTTP control API, --http)", exc) from None
            self.http_api = api

    def _control_refusal(self, exc: OSError) -> tuple[str, str]:
        """Where and why the control socket cannot be had, and what to do: with ``--control``, another
        path; with the default address (named after the host and port), another host or port, or the
        holder stopped."""
        reason = str(exc.args[1]) if len(exc.args) > 1 else (exc.strerror or str(exc))
        if self.settings.control_path is not None:
            return "control socket (--control)", f"{reason}; give another --control path"
        if isinstance(exc, ControlTaken):
            return "control socket", (f"{reason}; stop that process, or serve on another --host or --port "
                                      "(the control socket is named after them)")
        return "control socket", reason

    async def stop_serving(self) -> None:
        """Close the HTTP API and the control socket, then every port; the last saves are written."""
        if self.http_api is not None:
            await self.http_api.close()
            self.http_api = None
        if self.control_server is not None:
            await self.control_server.close()
            self.control_server = None
        await self.close()

    # -- the keypad (cipstack.devices.keypad) ---------------------------------------------------------
    def keypad(self) -> Keypad:
        """The device's keypad (the ACG's keypad, the MX2/RX Digital Operator); ``NoKeypad`` for a device
        without one."""
        keypad = self.device.keypad()
        if keypad is None:
            raise NoKeypad(f"{self.device.identity_info.product_name}: this device has no keypad (keypad "
                           f"parameters are a drive's: {keypad_families()}); write its parameters over CIP")
        return keypad

    def apply_keypad_parameters(self, assignments: list[str], kept: bool = True) -> list[str]:
        """``--param CODE=VALUE``: keypad parameters set before the network connects, by the keypad's
        codes and in its unit, written with the device's rules. ``kept``: keypad entries, which a
        power-cycle keeps as the drive's keypad keeps them (``Keypad.keep``); False
        (``--param-unsaved``): written as over communication, not saved, so a power-cycle loses them.
        Returns what was set, one line each; a device without a keypad or an assignment not taken raises
        ``ValueError`` (an unknown code ``UnknownCode``, a ``LookupError``) naming it. Not an event: it
        precedes the stream."""
        # At the device's own present time: before the shell's clock moves it (a drive's power-up
        # instant is the first time the shell advances it).
        return self.keypad().assign(assignments, 0.0, kept)

    def keypad_parameter(self, code: str) -> dict[str, Any]:
        """A keypad parameter by its code (``drv``, ``ACC``, ``CM.23``; ``F001``, ``A004``, ``P044``): code,
        name, value in the keypad's unit, raw value, unit, address (the ``parameter`` operation of the
        command service). ``UnknownCode`` or ``NoKeypad`` (``cipstack.errors.NotFound``) when not there."""
        return self.service.parameter(code)

    def set_keypad_parameter(self, code: str, value: object, origin: str = "python",
                             peer: str | None = None) -> dict[str, Any]:
        """Set a keypad parameter now, ``value`` in the keypad's unit (``"2.5"``, ``4``, an enumeration's
        name), not saved; returns it as ``keypad_parameter`` does (the ``set-parameter`` operation).
        ``UnknownCode``, ``BadValue``, ``WriteRefused`` (with the device's reason, also while the power is
        off) or ``NoKeypad`` when not written. ``origin`` and ``peer`` are what the event stream's
        ``parameter write`` says of who wrote it."""
        return self.service.set_parameter(code, value, origin, peer)

    async def close(self) -> None:
        self.faults.shutdown()
        self.runtime.shutdown()
        for port in self.power.ports:
            if isinstance(port, Class1Port):
                port.shutdown()
        if self.modbus is not None:
            await self.modbus.close()
        if self.secure is not None:
            await self.secure.close()
        if self.tls is not None:
            await self.tls.close()
        if self.dtls is not None:
            await self.dtls.close()
        if self.rs485 is not None:
            await self.rs485.release()
        if self.io is not None:
            self.io.close_all()
        if self.io_endpoint is not None:
            await self.io_endpoint.close()
        await self.server.close()
        # The last saves are written off the loop: wait for them without blocking it.
        await asyncio.get_running_loop().run_in_executor(None, self.device.close)

    async def __aenter__(self) -> Adapter:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    def control(self, request: dict[str, Any]) -> Any:
        """Serve one control-socket request, ``{"command": OPERATION, KEY: VALUE...}`` (the command
        service's operations, ``cipstack.control.service``): its reply, or an awaitable of it."""
        arguments = dict(request)
        command = arguments.pop("command", None)
        if not isinstance(command, str):
            raise BadRequest("a request names its \"command\" (an operation of the command service)")
        return self.service.call(command, arguments, origin="control")

    async def _print_status_lines(self) -> None:
        last = None
        while True:
            self.clock.tick(asyncio.get_running_loop().time())
            line = self.device.status_line()
            if line is not None and line != last:
                print(line, flush=True)
                last = line
            await asyncio.sleep(0.2)

    async def serve_forever(self, until: Callable[[Adapter], Awaitable[Any]] | None = None) -> Any:
        """Serve until SIGINT or SIGTERM, or until ``until(self)`` (a scenario) is done, then close
        cleanly; returns what ``until`` returned (None when a signal came first)."""
        loop = asyncio.get_running_loop()
        stop = asyncio.Event()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
        with held_log_records() as held:
            await self.start_serving()
            held.release()
        freeze_startup_objects()
        if self.rtu is not None:   # what a client (pyserial, socat) opens
            print(f"Modbus-RTU on {self.rtu.name} ({self.rtu.slaves[0].settings.describe()})", flush=True)
        printer = asyncio.create_task(self._print_status_lines()) if self.settings.status_lines else None
        info = self.device.identity_info
        log.info("emulating %s (vendor %d, device type %d, product code %d, revision %d.%d)",
                 info.product_name, info.vendor_id, info.device_type, info.product_code, *info.revision)
        task = asyncio.ensure_future(until(self)) if until is not None else None
        if task is not None:
            task.add_done_callback(lambda _: stop.set())
        try:
            await stop.wait()
        finally:
            log.info("stopping")
            for sig in (signal.SIGINT, signal.SIGTERM):
                loop.remove_signal_handler(sig)
            if printer is not None:
                printer.cancel()
            if task is not None and not task.done():
                task.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await task
            await self.stop_serving()
        if task is None or task.cancelled():
            return None
        return task.result()
