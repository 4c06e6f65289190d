"""CIP Security faults: what the device's TLS and DTLS listeners present and pass, through their seam
(``cipstack.eip.target.seams.SecuredSeam``) and the lab CA of its security folder
(``cipstack.runtime.runtime.CipSecurity``).

``expire-certificate`` and ``refuse-cipher-suite`` are handshake filters: each new TLS or DTLS
handshake presents the certificate re-issued with its validity ended, or no longer accepts the suite;
sessions made before keep what they had. ``revoke-certificate`` publishes a CRL of the lab CA that
lists the device's certificate, which originators check. ``drop-dtls-records`` drops whole DTLS
records on the UDP socket, before decryption or after encryption, so that the record layer and the
class 1 watchdogs above it see a lossy path. Clearing any of them puts the listener back as it was.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from ..eip.target.seams import dtls_records
from .effect import FaultContext
from .errors import FaultStateError

if TYPE_CHECKING:
    from ..runtime.runtime import CipSecurity, ReissuedCertificate


def _security(context: FaultContext) -> CipSecurity:
    security = context.runtime.security
    if security is None:
        raise FaultStateError("this device serves no CIP Security (start it with --security DIR, or configure "
                              "it over the network)")
    return security


class HandshakeFault:
    """A handshake filter in the seam from ``start`` to ``stop``."""

    def __init__(self, context: FaultContext) -> None:
        self.context = context
        self.certificate: tuple[str, str] | None = None
        self.refused: frozenset[int] = frozenset()

    def stop(self) -> None:
        security = self.context.runtime.security
        if security is not None:
            security.seam.remove(self)


class ExpireCertificate(HandshakeFault):
    def __init__(self, context: FaultContext) -> None:
        super().__init__(context)
        self._issued: ReissuedCertificate | None = None

    def start(self) -> None:
        security = _security(self.context)
        security.serving()
        self._issued = security.expired_certificate()
        self.certificate = self._issued.paths
        security.seam.add(self)

    def stop(self) -> None:
        super().stop()
        if self._issued is not None:
            self._issued.discard()
            self._issued = None


class RefuseCipherSuite(HandshakeFault):
    def start(self) -> None:
        security = _security(self.context)
        security.serving()
        self.refused = frozenset((security.suite(self.context.options.suite or ""),))
        security.seam.add(self)


class RevokeCertificate:
    """The CRL is published at ``start`` and withdrawn (the folder as it was) at ``stop``."""

    def __init__(self, context: FaultContext) -> None:
        self.context = context
        self._undo: Callable[[], None] | None = None

    def start(self) -> None:
        security = _security(self.context)
        security.serving()
        self._undo = security.revoke()

    def stop(self) -> None:
        if self._undo is not None:
            self._undo()
            self._undo = None


class DropDtlsRecords:
    """Whole DTLS records dropped as they enter (``--direction in``) or leave (``out``) the UDP socket,
    or both: a random share or every Nth, of every session or of one originator's."""

    def __init__(self, context: FaultContext) -> None:
        self.context = context
        options = context.options
        self.share: float | None = options.share
        self.every: int | None = options.every
        self.originator: str | None = options.originator
        direction = options.direction or "both"
        self.inbound = direction in ("in", "both")
        self.outbound = direction in ("out", "both")
        self.count = 0
        #: Records dropped so far.
        self.dropped = 0

    def start(self) -> None:
        security = _security(self.context)
        security.serving(datagrams=True)
        security.seam.add(self)

    def stop(self) -> None:
        security = self.context.runtime.security
        if security is not None:
            security.seam.remove(self)

    def records(self, datagram: bytes, peer: tuple[str, int], inbound: bool) -> bytes:
        if not (self.inbound if inbound else self.outbound) or (self.originator is not None
                                                                and peer[0] != self.originator):
            return datagram
        kept = []
        for record in dtls_records(datagram):
            if self._drops():
                self.dropped += 1
            else:
                kept.append(record)
        return b"".join(kept)

    def _drops(self) -> bool:
        if self.share is not None:
            return self.context.rng.random() < self.share
        self.count += 1
        return self.every is not None and self.count % self.every == 0


__all__ = ["DropDtlsRecords", "ExpireCertificate", "RefuseCipherSuite", "RevokeCertificate"]
