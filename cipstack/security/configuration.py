"""A device's CIP Security configuration and the configuration session that changes it (push model).

Sans-I/O: every call takes the present time; nothing here touches a socket, a file or a clock.

The session follows the EtherNet/IP Security object's services (Volume 8 5-4.7.1 to 5-4.7.4, as
OpENer's CIP Security branch names them): Begin_Config opens it, from Factory Default only (else
0x0C, Object State Conflict), for the connection that sent it; Kick_Timer restarts its timer;
Apply_Config makes the pending configuration the device's (state Configured); Abort_Config drops it;
a timer that runs out drops it too. While it is open, its owner alone may change the objects'
settable attributes or call the configuration services: anyone else gets 0x0C (chosen here: no
public source gives the status for another connection). The timer is checked at each request to the
objects (time as an argument); a session nobody touches again expires at its next request.

``Configurator.on_configured`` is called with the configuration after Apply_Config, and with None after
Reset: the device's shell (``security.endpoint``) starts, reloads or stops its TLS listener then, and
writes the configuration where the adapter keeps its state.
"""

from __future__ import annotations

import dataclasses
import json
import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from ..cip.status import CipError, GeneralStatus
from ..eip.target.limits import RateLimitedLog
from .declarations import (
    AVAILABLE_CIPHER_SUITES,
    CERTIFICATE_MANAGEMENT_CLASS,
    CERTIFICATE_SUITE_NAMES,
    DTLS_TIMEOUT,
    NO_CERTIFICATES_CONFIGURED,
    NO_CIPHER_SUITES_CONFIGURED,
    PSK_SUITE_NAMES,
    CertificateStatus,
    SecurityState,
)

log = logging.getLogger(__name__)

#: Seconds a configuration session lasts from Begin_Config or the last Kick_Timer (chosen here: no
#: public source gives it; ``cipstack adapter --security-config-timeout`` sets another). The adapter's
#: ``SECURITY_CONFIG_TIMEOUT`` is the same number (it names no security module until one is asked for).
CONFIG_TIMEOUT = 60.0


@dataclass(frozen=True)
class Configuration:
    """What the three objects hold, in one record: the EtherNet/IP Security object's settable
    attributes and the device's certificate (Certificate Management instance 1) and key."""

    allowed_suites: tuple[int, ...] = AVAILABLE_CIPHER_SUITES
    pre_shared_keys: tuple[tuple[bytes, bytes], ...] = ()
    active_device_certificates: tuple[tuple[int, int], ...] = ()
    trusted_authorities: tuple[tuple[int, int], ...] = ()
    revocation_list: tuple[int, ...] = ()
    verify_client: int = 0
    send_chain: int = 0
    check_expiration: int = 0
    trusted_identities: tuple[tuple[int, int], ...] = ()
    pull_model_enable: int = 1
    dtls_timeout: int = DTLS_TIMEOUT
    udp_only_policy: int = 0
    #: Certificate Management instance 1: the device's and its CA's certificates (DER), their status.
    device_certificate: bytes = b""
    device_status: int = CertificateStatus.NOT_VERIFIED
    ca_certificate: bytes = b""
    ca_status: int = CertificateStatus.NOT_VERIFIED
    #: The certificate revocation list (DER) downloaded into its File object instance (``CRL_FILE``),
    #: checked when ``revocation_list`` names that file.
    crl: bytes = b""
    #: The certificates (PEM, one or more) downloaded into the Trusted Identities' File object instance
    #: (``TRUSTED_IDENTITIES_FILE``): their subjects are the identities, when ``trusted_identities`` names it.
    identity_certificates: bytes = b""
    #: The last Create_CSR's request (DER), which the CSR's File object instance serves.
    certificate_request: bytes = b""
    #: The private key of the last Create_CSR (PEM, PKCS#8): never readable over the network.
    device_key: bytes = field(default=b"", repr=False)

    def with_changes(self, **changes: Any) -> Configuration:
        return dataclasses.replace(self, **changes)

    # -- a file of its own (the adapter's state folder) -------------------------------------------------
    def to_json(self) -> str:
        """The configuration as JSON (octets in hexadecimal); the key stays in its own 0600 file."""
        record = {name: _jsonable(getattr(self, name)) for name in self._fields() if name != "device_key"}
        return json.dumps(record, indent=1)

    @classmethod
    def from_json(cls, text: str, device_key: bytes = b"") -> Configuration:
        """Back from ``to_json``: ``BadConfiguration`` (a ``CipstackError``) when it does not read."""
        from ..errors import SecurityError

        try:
            record = json.loads(text)
            values = {name: _from_jsonable(cls.__dataclass_fields__[name].default, record[name])
                      for name in cls._fields() if name != "device_key" and name in record}
            return cls(**values, device_key=device_key)
        except (ValueError, KeyError, TypeError) as exc:
            raise SecurityError(f"security configuration does not read: {exc}") from None

    @classmethod
    def _fields(cls) -> list[str]:
        return [f.name for f in dataclasses.fields(cls)]


def _jsonable(value: Any) -> Any:
    if isinstance(value, bytes):
        return value.hex()
    if isinstance(value, tuple):
        return [_jsonable(v) for v in value]
    return value


def _from_jsonable(default: Any, value: Any) -> Any:
    if isinstance(default, bytes):
        return bytes.fromhex(value)
    if isinstance(default, tuple):
        return tuple(tuple(bytes.fromhex(x) if isinstance(x, str) else x for x in v) if isinstance(v, list) else v
                     for v in value)
    return value


def usable_suites(configuration: Configuration) -> tuple[int, ...]:
    """The allowed suites a handshake can use: the certificate suites, and the PSK suites when a key
    is set."""
    return tuple(s for s in configuration.allowed_suites
                 if s in CERTIFICATE_SUITE_NAMES or (s in PSK_SUITE_NAMES and configuration.pre_shared_keys))


#: The device's own certificate instance, the path every default list names.
DEVICE_CERTIFICATE_PATH = (CERTIFICATE_MANAGEMENT_CLASS, 1)


class Configurator:
    """The configuration state of one device and its one configuration session."""

    def __init__(self, on_configured: Callable[[Configuration | None], None],
                 initial: Configuration | None = None, timeout: float = CONFIG_TIMEOUT,
                 refusals: RateLimitedLog | None = None) -> None:
        """``initial``: a configuration the device starts with (Configured); None: Factory Default."""
        self.on_configured = on_configured
        self.timeout = timeout
        #: Refusals of the objects' requests: logged once per source per 10 s.
        self.refusals = refusals or RateLimitedLog(log)
        #: [state, configuration in effect, pending configuration or None, owner, deadline]: one record
        #: of plain values, changed by accepted requests only.
        self._now = _Session(SecurityState.CONFIGURED if initial is not None else SecurityState.FACTORY_DEFAULT,
                             initial or Configuration())
        #: Requests refused since the start.
        self.refused = 0

    # -- reading ----------------------------------------------------------------------------------------
    @property
    def state(self) -> SecurityState:
        return self._now.state

    @property
    def configuration(self) -> Configuration:
        """What the objects show: the pending configuration during a session, else the one in effect."""
        return self._now.pending if self._now.pending is not None else self._now.active

    @property
    def active(self) -> Configuration:
        return self._now.active

    def is_configured(self) -> bool:
        return self._now.state == SecurityState.CONFIGURED

    def owned_by(self, owner: object) -> bool:
        return self._now.pending is not None and self._now.owner is owner

    def expire(self, now: float) -> None:
        """End a session whose timer ran out: its changes are dropped, as Abort_Config drops them."""
        session = self._now
        if session.pending is not None and now >= session.deadline:
            log.warning("configuration session of %s expired after %g s without Kick_Timer; changes dropped",
                        session.peer, self.timeout)
            self._now = _Session(session.before, session.active)

    # -- the services -------------------------------------------------------------------------------------
    def begin(self, owner: object, peer: str, now: float) -> None:
        self.expire(now)
        session = self._now
        if session.pending is not None:
            raise self.refuse(peer, GeneralStatus.OBJECT_STATE_CONFLICT,
                              f"Begin_Config from {peer} refused: a configuration session of {session.peer} is open")
        if session.state != SecurityState.FACTORY_DEFAULT:
            raise self.refuse(peer, GeneralStatus.OBJECT_STATE_CONFLICT,
                              f"Begin_Config from {peer} refused: state {session.state.name.lower()} "
                              "(Reset returns the device to Factory Default first)")
        self._now = _Session(SecurityState.CONFIGURATION_IN_PROGRESS, session.active, session.active, owner, peer,
                             now + self.timeout, session.state)
        log.info("configuration session opened by %s (%g s, Kick_Timer extends it)", peer, self.timeout)

    def require(self, owner: object, peer: str, now: float, what: str) -> Configuration:
        """The pending configuration, for its owner only; 0x0C for anyone else or outside a session."""
        self.expire(now)
        session = self._now
        if session.pending is None:
            raise self.refuse(peer, GeneralStatus.OBJECT_STATE_CONFLICT,
                              f"{what} from {peer} refused: no configuration session (Begin_Config opens one)")
        if session.owner is not owner:
            raise self.refuse(peer, GeneralStatus.OBJECT_STATE_CONFLICT,
                              f"{what} from {peer} refused: the configuration session is {session.peer}'s")
        return session.pending

    def change(self, owner: object, peer: str, now: float, what: str, **changes: Any) -> None:
        """Change the pending configuration (a Set, a Create_CSR), for the session's owner only."""
        pending = self.require(owner, peer, now, what)
        self._now = dataclasses.replace(self._now, pending=pending.with_changes(**changes))

    def kick(self, owner: object, peer: str, now: float) -> None:
        self.require(owner, peer, now, "Kick_Timer")
        self._now = dataclasses.replace(self._now, deadline=now + self.timeout)

    def abort(self, owner: object, peer: str, now: float) -> None:
        self.require(owner, peer, now, "Abort_Config")
        session = self._now
        self._now = _Session(session.before, session.active)
        log.info("configuration session of %s aborted; changes dropped", peer)

    def apply(self, owner: object, peer: str, now: float, problem: Callable[[Configuration], str | None]) -> None:
        """Make the pending configuration the device's. ``problem`` says why its certificate is not
        usable (None when it is): then 0x0C with extended status 0x0002 (no certificates configured,
        Volume 8 5-4.8.1), and the session stays open to be fixed."""
        pending = self.require(owner, peer, now, "Apply_Config")
        if not pending.allowed_suites:
            raise self.refuse(peer, GeneralStatus.OBJECT_STATE_CONFLICT,
                              f"Apply_Config from {peer} refused: no allowed cipher suite",
                              (NO_CIPHER_SUITES_CONFIGURED,))
        if not usable_suites(pending):
            raise self.refuse(peer, GeneralStatus.OBJECT_STATE_CONFLICT,
                              f"Apply_Config from {peer} refused: the allowed cipher suites are pre-shared key "
                              "suites and no pre-shared key is set", (NO_CIPHER_SUITES_CONFIGURED,))
        why = problem(pending)
        if why is not None:
            raise self.refuse(peer, GeneralStatus.OBJECT_STATE_CONFLICT, f"Apply_Config from {peer} refused: {why}",
                              (NO_CERTIFICATES_CONFIGURED,))
        self._now = _Session(SecurityState.CONFIGURED, pending)
        log.info("security configuration applied by %s", peer)
        self.on_configured(pending)

    def reset(self, owner: object, peer: str, now: float, pull_model: int | None) -> None:
        """Back to Factory Default (Volume 8 5-4.5.1); ``pull_model``: the optional BOOL argument. During
        another connection's session, 0x0C."""
        self.expire(now)
        session = self._now
        if session.pending is not None and session.owner is not owner:
            raise self.refuse(peer, GeneralStatus.OBJECT_STATE_CONFLICT,
                              f"Reset from {peer} refused: the configuration session is {session.peer}'s")
        factory = Configuration()
        if pull_model is not None:
            factory = factory.with_changes(pull_model_enable=pull_model)
        self._now = _Session(SecurityState.FACTORY_DEFAULT, factory)
        log.info("security configuration reset to factory default by %s", peer)
        self.on_configured(None)

    def refuse(self, peer: str, status: int, line: str, extended: tuple[int, ...] = (), data: bytes = b"") -> Refused:
        """Count and log (once per source per 10 s) a refused request; the error to raise (``data``: what
        the error reply carries, a list service's per-attribute statuses)."""
        self.refused += 1
        self.refusals("%s", line, source=peer.rpartition(":")[0] or peer)
        return Refused(status, extended, message=line, data=data)


class Refused(CipError):
    """A request to a security object refused, already counted and logged."""


@dataclass(frozen=True)
class _Session:
    state: SecurityState
    active: Configuration
    pending: Configuration | None = None
    owner: object = None
    peer: str = ""
    deadline: float = 0.0
    #: The state a session returns to when it is aborted or expires.
    before: SecurityState = SecurityState.FACTORY_DEFAULT


__all__ = ["CONFIG_TIMEOUT", "DEVICE_CERTIFICATE_PATH", "Configuration", "Configurator", "Refused", "usable_suites"]
