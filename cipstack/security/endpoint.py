"""The shell of a device's CIP Security configuration: the TLS listener that follows it, where it is
kept, and the policy that refuses plain explicit messaging once it is configured.

``SecureEndpoint`` is the listener of the adapter's "EtherNet/IP over TLS" port. A device configured
over the wire (Apply_Config) gets a TLS listener on the secure port with the certificate, trust and
pre-shared keys just written, built from them, and a DTLS listener on the UDP port of the same number
(secured class 1, as ``--security DIR`` serves it) with the same; a new Apply_Config replaces both,
and Reset closes both (a device started with ``--security DIR`` included: the folder's listeners are
the first configuration's). The configuration
is written into a folder (the adapter's ``<state>.security``, or a private temporary one) off the event
loop, and read back when the adapter starts, so a configured device stays configured.

``PlainRefusal`` is the ``--secure-only`` policy: the router every explicit request reaches through
the request seam (``RequestSeam``), in front of the device's own. Once the device is Configured, a
CIP request that arrived on a plain TCP connection (not on the TLS port) is answered with general
status 0x0F (privilege violation) and not served; encapsulation commands (ListIdentity,
ListServices, RegisterSession) still answer, so the device can be found and told to be secured.
While the device is not configured, plain requests are served: a factory-default device must be
configurable (Volume 8's push model goes over 44818).
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import logging
import os
import shutil
import ssl
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..cip.messages import MessageRouterResponse
from ..cip.router import RequestContext
from ..cip.status import GeneralStatus
from ..eip.target.limits import RateLimitedLog
from ..errors import SecurityError
from .certificates import pem
from .configuration import Configuration
from .credentials import CA_FILE, DEVICE_CERTIFICATE, DEVICE_KEY, Credentials
from .declarations import CERTIFICATE_SUITE_NAMES, CIPHER_SUITE_NAMES, PSK_SUITE_NAMES

if TYPE_CHECKING:
    from .dtls_target import DtlsServer
    from .tls_psk import PskTlsContext
    from .tls_target import Recipe, TlsServer

log = logging.getLogger(__name__)

#: The configuration's own file in the folder, beside ca.pem, device.pem and device.key.
CONFIGURATION_FILE = "configuration.json"
#: Tries at a TCP and UDP pair of one number for TLS and DTLS on a secure port of 0 (any free one).
FREE_PORT_TRIES = 20

#: How a listener of a configuration is made: from its credentials, the recipe of its TLS context, and
#: its port.
ServerFactory = Callable[[Credentials, "Recipe", int], "TlsServer"]
#: How the DTLS listener of a configuration is made: from its credentials, the configuration, its port.
DatagramFactory = Callable[[Credentials, Configuration, int], "DtlsServer"]


def state_folder(state_path: Path | None) -> Path | None:
    """Where a device keeps its security configuration: beside its state file (``drive.json`` ->
    ``drive.json.security``); None when the adapter keeps no state."""
    return None if state_path is None else state_path.with_name(state_path.name + ".security")


def load_configuration(folder: Path | None) -> Configuration | None:
    """The configuration a device kept in ``folder``, or None (factory default); ``SecurityError``
    naming the file when one is there but does not read."""
    if folder is None or not (folder / CONFIGURATION_FILE).exists():
        return None
    try:
        text = (folder / CONFIGURATION_FILE).read_text(encoding="utf-8")
        key = (folder / DEVICE_KEY).read_bytes() if (folder / DEVICE_KEY).exists() else b""
    except OSError as exc:
        raise SecurityError(f"{folder}: unreadable ({exc.strerror or exc})") from None
    return Configuration.from_json(text, key)


def configuration_of(credentials: Credentials) -> Configuration:
    """What the objects show for a device started with ``--security DIR``: configured with DIR's
    certificate, key and CA, client certificates verified (the listener's own rule)."""
    from .certificates import der_of_pem
    from .configuration import DEVICE_CERTIFICATE_PATH
    from .declarations import CertificateStatus

    keys = ((credentials.psk.identity, credentials.psk.key),) if credentials.psk is not None else ()
    if credentials.device is None or credentials.ca is None:
        if keys:   # a PSK-only device: configured with its key, no certificate
            return Configuration(pre_shared_keys=keys)
        raise SecurityError(f"{credentials.folder}: no device certificate and CA to serve")
    device, ca = credentials.device.certificate.path, credentials.ca.path
    # The folder's listeners verify client certificates and their dates and send the chain (OpenSSL's
    # defaults there): the attributes show it.
    return Configuration(active_device_certificates=(DEVICE_CERTIFICATE_PATH,),
                         trusted_authorities=(DEVICE_CERTIFICATE_PATH,), verify_client=1, check_expiration=1,
                         send_chain=1,
                         device_certificate=der_of_pem(device.read_bytes()), device_status=CertificateStatus.VERIFIED,
                         ca_certificate=der_of_pem(ca.read_bytes()), ca_status=CertificateStatus.VERIFIED,
                         device_key=credentials.device.key.read_bytes(), pre_shared_keys=keys)


def available_suites(credentials: Credentials) -> str:
    """The suites the EtherNet/IP Security object lists as available that ``credentials`` can serve, as
    OpenSSL's cipher list: the PSK suites with the folder's key, the certificate suites with its
    certificates."""
    names = list(PSK_SUITE_NAMES.values()) if credentials.psk is not None else []
    if credentials.device is not None and credentials.ca is not None:
        names += CERTIFICATE_SUITE_NAMES.values()
    return ":".join(names)


def available_suites_context(credentials: Credentials) -> ssl.SSLContext | PskTlsContext:
    """The TLS context of a device started with ``--security DIR``: TLS 1.2 with the suites its
    EtherNet/IP Security object lists (Available = Allowed), and TLS 1.3 as before (its suites are
    the TLS library's; Python's ``ssl`` cannot narrow them). With the folder's PSK, a pyOpenSSL
    context of TLS 1.2 only that accepts the PSK suites too (``tls_psk``)."""
    if credentials.psk is not None:
        from .dtls import check_crl
        from .tls_psk import psk_context

        made = psk_context(credentials, server=True, keys=[(credentials.psk.identity, credentials.psk.key)],
                           suites=tuple(CIPHER_SUITE_NAMES.values()))
        if credentials.device is not None and credentials.ca is not None:
            check_crl(made.context, credentials)   # the clients' certificates, as without a PSK
        return made
    context = credentials.server_context()
    context.set_ciphers(":".join(CERTIFICATE_SUITE_NAMES.values()))
    return context


def server_context(credentials: Credentials, configuration: Configuration) -> PskTlsContext:
    """The TLS context of a configured device: TLS 1.2 with the Allowed Cipher Suites only (a device
    whose suites were chosen does not offer 1.3, whose suites are the library's), through pyOpenSSL
    (``tls_psk``): client certificates as Verify Client Certificate says, their dates as Check
    Expiration says, the chain as Send Certificate Chain says (``peer_policy``). With Pre-Shared Keys
    (attribute 5), the PSK suites with those keys too: the keys written over the wire are the ones the
    next handshake uses."""
    from .peer_policy import apply
    from .tls_psk import psk_context

    names = [CIPHER_SUITE_NAMES[s] for s in configuration.allowed_suites
             if s in CERTIFICATE_SUITE_NAMES or configuration.pre_shared_keys]
    if not names:   # Apply_Config refuses such a configuration (``Configurator.apply``)
        raise SecurityError("no certificate suite allowed, and no pre-shared key for a PSK suite")
    context = psk_context(credentials, server=True, keys=configuration.pre_shared_keys, suites=names,
                          verify_client=bool(configuration.verify_client))
    apply(context.context, credentials, configuration)
    return context


def dtls_server_context(credentials: Credentials, configuration: Configuration) -> Any:
    """The DTLS context (pyOpenSSL's) of a configuration applied over the network: the Allowed Cipher
    Suites, the certificate and the pre-shared keys it holds, and the checks of ``peer_policy``, as
    ``server_context`` for TLS."""
    from .peer_policy import apply
    from .tls_psk import openssl_context

    context, _, _ = openssl_context(credentials, server=True, keys=configuration.pre_shared_keys,
                                    suites=[CIPHER_SUITE_NAMES[s] for s in configuration.allowed_suites],
                                    verify_client=bool(configuration.verify_client), datagram=True)
    apply(context, credentials, configuration)
    return context


def _write(folder: Path, configuration: Configuration | None) -> None:
    """Write (or, for None, remove) the configuration's files; the key 0600. Runs off the event loop."""
    folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    names = (CONFIGURATION_FILE, CA_FILE, DEVICE_CERTIFICATE, DEVICE_KEY)
    if configuration is None:
        for name in names:
            with contextlib.suppress(FileNotFoundError):
                (folder / name).unlink()
        return
    files: tuple[tuple[str, bytes, int], ...] = ((CA_FILE, pem(configuration.ca_certificate), 0o644),
             (DEVICE_CERTIFICATE, pem(configuration.device_certificate), 0o644),
             (DEVICE_KEY, configuration.device_key, 0o600),
             # The configuration holds the pre-shared keys: as private as the device's key.
             (CONFIGURATION_FILE, configuration.to_json().encode(), 0o600))
    if not configuration.active_device_certificates:   # pre-shared keys alone: no certificate files
        for name in (CA_FILE, DEVICE_CERTIFICATE, DEVICE_KEY):
            with contextlib.suppress(FileNotFoundError):
                (folder / name).unlink()
        files = files[3:]
    for name, data, mode in files:
        temporary = folder / f".{name}.new"
        with contextlib.suppress(FileNotFoundError):
            temporary.unlink()
        descriptor = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL, mode)
        with os.fdopen(descriptor, "wb") as file:
            file.write(data)
        temporary.replace(folder / name)


class SecureEndpoint:
    """The secure port of one device: no listener until the device is configured, then a TLS listener
    and a DTLS listener with the configuration's certificate, trust, keys and suites."""

    def __init__(self, make_server: ServerFactory, port: int, folder: Path | None, initial: TlsServer | None = None,
                 initial_configuration: Configuration | None = None,
                 make_datagrams: DatagramFactory | None = None, initial_datagrams: DtlsServer | None = None) -> None:
        """``make_server(credentials, recipe, port)``: a TLS listener (the adapter's, with its limits and
        reply seam); ``make_datagrams(credentials, configuration, port)``: the DTLS listener beside it
        (None: TLS only). ``initial``, ``initial_datagrams``: the listeners of ``--security DIR``, which
        a configuration applied over the network replaces and a Reset closes, as its own;
        ``initial_configuration``: the one read back from ``folder``, served from the start."""
        self.make_server = make_server
        self.make_datagrams = make_datagrams
        self.port = port
        self.folder = folder
        #: The listener serving now (zero or one).
        self.servers: list[TlsServer] = [initial] if initial is not None else []
        #: The DTLS listener serving now beside it (zero or one).
        self.datagram_servers: list[DtlsServer] = [initial_datagrams] if initial_datagrams is not None else []
        self._pending: list[Configuration | None] = [initial_configuration] if initial_configuration else []
        self._temporary: list[str] = []
        self._tasks: set[asyncio.Task[None]] = set()
        self._open = False
        #: Configurations applied (and resets) since the start whose listener is in place.
        self.reloads = 0

    @property
    def is_open(self) -> bool:
        return self._open

    @property
    def server(self) -> TlsServer | None:
        return self.servers[0] if self.servers else None

    @property
    def dtls(self) -> DtlsServer | None:
        """The DTLS listener serving now, if any."""
        return self.datagram_servers[0] if self.datagram_servers else None

    def secured(self, context: RequestContext) -> bool:
        """Whether a request arrived over TLS: on a connection to the secure listener's port."""
        server = self.server
        local = getattr(context.transport, "local", None)
        return server is not None and server.is_open and local is not None and local.port == server.port

    async def start(self) -> None:
        self._open = True
        for configuration in self._pending:
            await self._reload(configuration)
        self._pending.clear()
        server = self.server
        if server is not None and not server.is_open:
            await self._listen(server, self.dtls)

    async def _listen(self, server: TlsServer, dtls: DtlsServer | None) -> None:
        """TLS, then DTLS on the UDP port of the same number. On a port of 0, a TCP number taken in UDP
        makes TLS take another, as the plain target does for its pair (``EncapsulationServer.start``).
        A DTLS port that cannot listen otherwise raises with TLS left listening: the caller tells which
        port failed, and closes what it must."""
        any_port = server.port == 0
        for attempt in range(FREE_PORT_TRIES if any_port else 1):
            await server.start()
            self.port = server.port
            if dtls is None:
                return
            dtls.port = server.port
            try:
                await dtls.start()
                return
            except OSError as exc:
                if not any_port or exc.errno != errno.EADDRINUSE or attempt == FREE_PORT_TRIES - 1:
                    raise
            await server.close()
            server.port = 0

    async def close(self) -> None:
        self._open = False
        for task in list(self._tasks):
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        for server in self.servers:
            await server.close()
        for dtls in self.datagram_servers:
            await dtls.close()
        for folder in self._temporary:
            shutil.rmtree(folder, ignore_errors=True)
        self._temporary.clear()

    def configured(self, configuration: Configuration | None) -> None:
        """``Configurator.on_configured``: reload for a new configuration, stop for None (Reset)."""
        try:
            loop = asyncio.get_running_loop()
        except RuntimeError:   # no loop yet: the adapter starts with it
            self._pending[:] = [configuration]
            return
        task = loop.create_task(self._reload(configuration))
        self._tasks.add(task)
        task.add_done_callback(self._done)

    def _done(self, task: asyncio.Task[None]) -> None:
        self._tasks.discard(task)
        if not task.cancelled() and task.exception() is not None:
            log.error("security configuration not put in place: %s", task.exception())

    async def _reload(self, configuration: Configuration | None) -> None:
        loop = asyncio.get_running_loop()
        folder = self.folder
        if folder is None and configuration is not None:
            if not self._temporary:
                self._temporary.append(await loop.run_in_executor(None, tempfile.mkdtemp, "", "cipstack-security-"))
            folder = Path(self._temporary[0])
        if folder is not None:
            await loop.run_in_executor(None, _write, folder, configuration)
        for server in self.servers:
            if server.is_open:
                self.port = server.port
            await server.close()
        self.servers.clear()
        for dtls in self.datagram_servers:
            await dtls.close()
        self.datagram_servers.clear()
        if configuration is not None and folder is not None:
            if configuration.active_device_certificates:
                credentials = await loop.run_in_executor(None, Credentials.load, folder)
            else:   # pre-shared keys alone, from the configuration
                credentials = Credentials.keys_only(folder)
            applied = configuration

            def recipe(made: Credentials) -> PskTlsContext:
                return server_context(made, applied)

            server = self.make_server(credentials, recipe, self.port)
            self.servers.append(server)
            datagrams = self._datagrams(credentials, configuration)
            if datagrams is not None:
                self.datagram_servers.append(datagrams)
            if self._open:
                await self._listen(server, datagrams)
                log.info("EtherNet/IP over TLS%s serves the configuration applied over the network (port %d)",
                         " and DTLS" if datagrams is not None else "", server.port)
        self.reloads += 1

    def _datagrams(self, credentials: Credentials, configuration: Configuration) -> DtlsServer | None:
        """The DTLS listener of a configuration, or None: without a factory, or when DTLS cannot serve
        it (a warning: TLS serves on)."""
        if self.make_datagrams is None:
            return None
        try:
            return self.make_datagrams(credentials, configuration, self.port)
        except SecurityError as exc:
            log.warning("EtherNet/IP over DTLS not served: %s", exc)
            return None


class PlainRefusal:
    """``--secure-only``: the message router as the encapsulation target reaches it, in front of the
    device's own. Once the device is configured, an explicit request that did not arrive over TLS is
    answered with general status 0x0F and not served; refusals are logged once per source per 10 s."""

    def __init__(self, router: Any, secured: Callable[[RequestContext], bool], configured: Callable[[], bool]) -> None:
        """``secured(context)``: whether a request arrived over TLS (``SecureEndpoint.secured``);
        ``configured()``: whether the device is configured (``Configurator.is_configured``)."""
        self.router = router
        self.secured = secured
        self.configured = configured
        self.refusals = RateLimitedLog(log)
        #: Plain requests refused since the start.
        self.refused = 0

    def handle(self, raw: bytes, context: RequestContext) -> bytes:
        if context.depth or not self.configured() or self.secured(context):
            return self.router.handle(raw, context)   # type: ignore[no-any-return]  # the router's bytes
        self.refused += 1
        self.refusals("plain request from %s refused: the device is secured (--secure-only): use TLS",
                      context.origin, source=context.origin.rpartition(":")[0])
        service = raw[0] & 0x7F if raw else 0
        return MessageRouterResponse(service, GeneralStatus.PRIVILEGE_VIOLATION).encode()


__all__ = ["CONFIGURATION_FILE", "DatagramFactory", "PlainRefusal", "SecureEndpoint", "ServerFactory",
           "available_suites", "available_suites_context", "configuration_of", "dtls_server_context",
           "load_configuration", "server_context", "state_folder"]
