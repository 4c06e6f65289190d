"""The CIP Security (0x5D), EtherNet/IP Security (0x5E) and Certificate Management (0x5F) objects, served.

Each is the runtime of its declaration (``security.declarations``) over one ``Configurator``, which
holds the device's configuration and its one configuration session; the objects add the wire: what
each attribute reads, what a Set may write, and the services' request and reply layouts. Any device
can serve them (``register``): the adapter adds them to whatever device it runs, a profile's or one
emulated from an EDS file.

Refused requests get the status the object's rules give (0x0C outside the session or for another
connection, 0x09 for a value the device cannot take, 0x13/0x15 for a request too short or too long,
0xD0 for a certificate that fails Verify_Certificate) and are logged once per source per 10 s.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from functools import partial
from typing import Any

from ..cip.epath import ApplicationPath
from ..cip.messages import MessageRouterRequest
from ..cip.model import AttributeSpec, CipObject, ClassSpec, Instance
from ..cip.router import MessageRouter, RequestContext
from ..cip.status import CipError, GeneralStatus
from ..cip.types import SHORT_STRING
from ..errors import BadRequest
from ..objects.file import FileObject, StoredFile
from . import certificates
from .attributes import encode_object_path
from .configuration import DEVICE_CERTIFICATE_PATH, Configuration, Configurator, Refused
from .declarations import (
    AVAILABLE_CIPHER_SUITES,
    CA_CERTIFICATE_FILE,
    CERTIFICATE_MANAGEMENT_SPEC,
    CIP_SECURITY_SPEC,
    CONFIDENTIALITY_PROFILE,
    CRL_FILE,
    CSR_FILE,
    DEVICE_CERTIFICATE_FILE,
    EIP_SECURITY_SPEC,
    FILE_CLASS,
    PSK_SUITE_NAMES,
    TRUSTED_IDENTITIES_FILE,
    VERIFICATION_FAILED,
    CertificateService,
    CertificateState,
    CertificateStatus,
    CipSecurityState,
    ConfigService,
    SecurityState,
)

#: EtherNet/IP Security attributes held in the configuration, by id -> ``Configuration`` field.
EIP_SECURITY_FIELDS = {4: "allowed_suites", 5: "pre_shared_keys", 6: "active_device_certificates",
                       7: "trusted_authorities", 8: "revocation_list", 9: "verify_client", 10: "send_chain",
                       11: "check_expiration", 12: "trusted_identities", 13: "pull_model_enable",
                       15: "dtls_timeout", 16: "udp_only_policy"}
#: Certificate Management attributes 3 and 4 -> (certificate field, status field), and their files.
CERTIFICATE_FIELDS = {3: ("device_certificate", "device_status"), 4: ("ca_certificate", "ca_status")}
CERTIFICATE_PATHS = {3: (FILE_CLASS, DEVICE_CERTIFICATE_FILE), 4: (FILE_CLASS, CA_CERTIFICATE_FILE)}
_APPLY_ARGUMENTS = struct.Struct("<HH")


class _SecurityObject(CipObject):
    """What the three share: the session timer checked at each request, refusals logged."""

    def __init__(self, spec: ClassSpec, configurator: Configurator) -> None:
        super().__init__(spec)
        self.configurator = configurator
        self.add_instance(1)

    def handle(self, path: ApplicationPath, request: MessageRouterRequest, context: RequestContext) -> bytes:
        self.configurator.expire(context.now)
        try:
            return super().handle(path, request, context)
        except Refused:
            raise
        except CipError as exc:
            raise self.configurator.refuse(
                context.origin, exc.general,
                f"{self.spec.name} service 0x{request.service:02X} from {context.origin} refused: {exc}",
                exc.extended, exc.data) from None

    def _session_change(self, context: RequestContext | None, what: str, **changes: Any) -> None:
        if context is None:
            raise CipError(GeneralStatus.OBJECT_STATE_CONFLICT, message=f"{what}: over the network only")
        self.configurator.change(context.transport, context.origin, context.now, what, **changes)


class CipSecurityObject(_SecurityObject):
    """Class 0x5D: the device's security state and profiles, read-only here. Its own Begin_Config...
    services (OpENer's 0x4B to 0x4E on this class) are not served: 0x08."""

    def __init__(self, configurator: Configurator) -> None:
        super().__init__(CIP_SECURITY_SPEC, configurator)

    def read_attribute(self, instance: Instance, spec: AttributeSpec) -> Any:
        state = self.configurator.state
        if spec.id == 1:
            return {SecurityState.CONFIGURATION_IN_PROGRESS: CipSecurityState.CONFIGURATION_IN_PROGRESS,
                    SecurityState.CONFIGURED: CipSecurityState.CONFIGURED}.get(state, CipSecurityState.FACTORY_DEFAULT)
        if spec.id == 3:
            return CONFIDENTIALITY_PROFILE if state == SecurityState.CONFIGURED else 0
        return super().read_attribute(instance, spec)


class EipSecurityObject(_SecurityObject):
    """Class 0x5E, instance 1: the TLS settings and the configuration session's services."""

    extra_services = {ConfigService.BEGIN_CONFIG: "begin_config", ConfigService.KICK_TIMER: "kick_timer",
                      ConfigService.APPLY_CONFIG: "apply_config", ConfigService.ABORT_CONFIG: "abort_config"}

    def __init__(self, configurator: Configurator) -> None:
        super().__init__(EIP_SECURITY_SPEC, configurator)

    def read_attribute(self, instance: Instance, spec: AttributeSpec) -> Any:
        if spec.id == 1:
            return int(self.configurator.state)
        field = EIP_SECURITY_FIELDS.get(spec.id)
        if field is not None:
            return getattr(self.configurator.configuration, field)
        return super().read_attribute(instance, spec)

    def write_attribute(self, instance: Instance, spec: AttributeSpec, value: Any,
                        context: RequestContext | None = None) -> None:
        value = spec.validate(value)
        if spec.id == 4 and not set(value) <= set(AVAILABLE_CIPHER_SUITES):
            unknown = ", ".join(f"0x{s:04X}" for s in value if s not in AVAILABLE_CIPHER_SUITES)
            raise CipError(GeneralStatus.INVALID_ATTRIBUTE_VALUE, message=f"suites not available here: {unknown}")
        if spec.id in (6, 7) and any(path != DEVICE_CERTIFICATE_PATH for path in value):
            raise CipError(GeneralStatus.INVALID_ATTRIBUTE_VALUE,
                           message="a certificate path names Certificate Management instance 1 (0x5F/1)")
        if spec.id == 12 and any(path != (FILE_CLASS, TRUSTED_IDENTITIES_FILE) for path in value):
            raise CipError(GeneralStatus.INVALID_ATTRIBUTE_VALUE,
                           message=f"trusted identities are kept in File object instance {TRUSTED_IDENTITIES_FILE}")
        if spec.id == 8 and value not in ((), (FILE_CLASS, CRL_FILE)):
            raise CipError(GeneralStatus.INVALID_ATTRIBUTE_VALUE,
                           message=f"a certificate revocation list is kept in File object instance {CRL_FILE}")
        self._session_change(context, f"Set_Attribute_Single {spec.name}", **{EIP_SECURITY_FIELDS[spec.id]: value})

    # -- the configuration services ---------------------------------------------------------------------
    @staticmethod
    def _no_data(request: MessageRouterRequest) -> None:
        if request.data:
            raise CipError(GeneralStatus.TOO_MUCH_DATA, message="this service takes no data")

    def begin_config(self, instance: Instance | None, path: ApplicationPath, request: MessageRouterRequest,
                     context: RequestContext) -> bytes:
        self._no_data(request)
        self.configurator.begin(context.transport, context.origin, context.now)
        return b""

    def kick_timer(self, instance: Instance | None, path: ApplicationPath, request: MessageRouterRequest,
                   context: RequestContext) -> bytes:
        self._no_data(request)
        self.configurator.kick(context.transport, context.origin, context.now)
        return b""

    def abort_config(self, instance: Instance | None, path: ApplicationPath, request: MessageRouterRequest,
                     context: RequestContext) -> bytes:
        self._no_data(request)
        self.configurator.abort(context.transport, context.origin, context.now)
        return b""

    def apply_config(self, instance: Instance | None, path: ApplicationPath, request: MessageRouterRequest,
                     context: RequestContext) -> bytes:
        """Apply Behavior Flags (WORD) and Close Delay (UINT), both optional together. Neither bit is
        acted on here: existing connections stay open, and there is no orphan object to clean up."""
        if request.data:
            if len(request.data) < _APPLY_ARGUMENTS.size:
                raise CipError(GeneralStatus.NOT_ENOUGH_DATA, message="Apply_Config takes a WORD and a UINT")
            if len(request.data) > _APPLY_ARGUMENTS.size:
                raise CipError(GeneralStatus.TOO_MUCH_DATA, message="Apply_Config takes a WORD and a UINT")
        configurator, peer, owner = self.configurator, context.origin, context.transport
        pending = configurator.require(owner, peer, context.now, "Apply_Config")
        if keys_only(pending):   # no certificate to check: TLS with the pre-shared keys alone
            configurator.apply(owner, peer, context.now, lambda _: None)
            return b""
        why = usable(pending)
        if why is None:
            configurator.change(owner, peer, context.now, "Apply_Config", device_status=CertificateStatus.VERIFIED,
                                ca_status=CertificateStatus.VERIFIED)
        configurator.apply(owner, peer, context.now, lambda _: why)
        return b""

    def reset(self, instance: Instance | None, path: ApplicationPath, request: MessageRouterRequest,
              context: RequestContext) -> bytes:
        """Back to Factory Default; the optional BOOL sets Pull Model Enable (Volume 8 5-4.5.1)."""
        if len(request.data) > 1:
            raise CipError(GeneralStatus.TOO_MUCH_DATA, message="Reset takes one BOOL at most")
        pull_model = request.data[0] if request.data else None
        if pull_model is not None and pull_model > 1:
            raise CipError(GeneralStatus.INVALID_PARAMETER, message=f"Reset's BOOL is 0 or 1, not {pull_model}")
        self.configurator.reset(context.transport, context.origin, context.now, pull_model)
        return b""


def keys_only(configuration: Configuration) -> bool:
    """A configuration of pre-shared keys alone: no active device certificate, a key, and a PSK suite
    allowed (chosen here: a device that names no certificate serves the PSK suites alone)."""
    return (not configuration.active_device_certificates and bool(configuration.pre_shared_keys)
            and any(suite in PSK_SUITE_NAMES for suite in configuration.allowed_suites))


def usable(configuration: Configuration) -> str | None:
    """Why a configuration's device certificate cannot serve TLS, or None when it can."""
    if DEVICE_CERTIFICATE_PATH not in configuration.active_device_certificates:
        return "no active device certificate (EtherNet/IP Security attribute 6 names none)"
    if DEVICE_CERTIFICATE_PATH not in configuration.trusted_authorities:
        return "no trusted authority (EtherNet/IP Security attribute 7 names none)"
    why = certificates.verify(configuration.device_certificate, configuration.ca_certificate,
                              configuration.device_key, check_expiration=bool(configuration.check_expiration))
    if why is None and configuration.revocation_list:
        why = certificates.revocation_list_problem(configuration.crl, configuration.ca_certificate)
    if why is None and configuration.trusted_identities and not configuration.identity_certificates:
        why = "the Trusted Identities name a file that holds no certificate"
    return why


class CertificateManagementObject(_SecurityObject):
    """Class 0x5F, instance 1: the device's certificate and its CA's; Create_CSR, Verify_Certificate.

    The certificates and the CSR live in File object instances (class 0x37: ``CSR_FILE``,
    ``DEVICE_CERTIFICATE_FILE``, ``CA_CERTIFICATE_FILE``), as the branch keeps them: attributes 3 and 4
    give a status and the path to their file; Create_CSR replies with the path to the CSR's. A tool
    downloads a certificate into its file (Initiate_Download, Download_Transfer), within its session."""

    extra_services = {CertificateService.CREATE_CSR: "create_csr",
                      CertificateService.VERIFY_CERTIFICATE: "verify_certificate"}

    def __init__(self, configurator: Configurator, csr_defaults: dict[str, str], files: FileObject) -> None:
        super().__init__(CERTIFICATE_MANAGEMENT_SPEC, configurator)
        #: The subject fields a Create_CSR leaves empty take (``certificates.CSR_FIELDS`` names).
        self.csr_defaults = dict(csr_defaults)
        files.serve(StoredFile(CSR_FILE, "Certificate Signing Request", "device.csr", (1, 0), self._csr_file),
                    live=True)
        files.serve(StoredFile(DEVICE_CERTIFICATE_FILE, "Device Certificate", "device.pem", (1, 0),
                               partial(self._certificate_file, 3)), partial(self._downloaded, 3), live=True)
        files.serve(StoredFile(CA_CERTIFICATE_FILE, "CA Certificate", "ca.pem", (1, 0),
                               partial(self._certificate_file, 4)), partial(self._downloaded, 4), live=True)
        # The EtherNet/IP Security object's Certificate Revocation List (attribute 8) names this file.
        files.serve(StoredFile(CRL_FILE, "Certificate Revocation List", "crl.pem", (1, 0), self._crl_file),
                    self._crl_downloaded, live=True)
        # Its Trusted Identities (attribute 12) name this one.
        files.serve(StoredFile(TRUSTED_IDENTITIES_FILE, "Trusted Identities", "identities.pem", (1, 0),
                               lambda: self.configurator.configuration.identity_certificates),
                    self._identities_downloaded, live=True)

    def _csr_file(self) -> bytes:
        return certificates.pem(self.configurator.configuration.certificate_request, "CERTIFICATE REQUEST")

    def _certificate_file(self, attribute: int) -> bytes:
        return certificates.pem(getattr(self.configurator.configuration, CERTIFICATE_FIELDS[attribute][0]))

    def _crl_file(self) -> bytes:
        return certificates.pem(self.configurator.configuration.crl, "X509 CRL")

    def _crl_downloaded(self, data: bytes, context: RequestContext) -> None:
        """A CRL downloaded into its file: the session's owner only; 0x09 for no CRL."""
        what = "a download of the certificate revocation list"
        self._change(context, what, crl=self._take(data, context, what, certificates.revocation_list_der))

    def _identities_downloaded(self, data: bytes, context: RequestContext) -> None:
        """The Trusted Identities' certificates downloaded: the session's owner only; 0x09 for none."""
        what = "a download of the trusted identities"
        self._change(context, what, identity_certificates=self._take(data, context, what,
                                                                     certificates.identity_bundle))

    def _downloaded(self, attribute: int, data: bytes, context: RequestContext) -> None:
        """A certificate downloaded into its file: the session's owner only; 0x09 for no certificate."""
        certificate, status = CERTIFICATE_FIELDS[attribute]
        what = f"a download of the {certificate.replace('_', ' ')}"
        der = self._take(data, context, what, certificates.certificate_der)
        self._change(context, what, **{certificate: der, status: CertificateStatus.NOT_VERIFIED})

    def _take(self, data: bytes, context: RequestContext, what: str, parse: Callable[[bytes], Any]) -> Any:
        """What a download into a file holds, parsed, once the configuration session's owner is the one
        downloading; a refusal (the parser's status, 0x09) naming ``what`` otherwise."""
        self.configurator.require(context.transport, context.origin, context.now, what)
        try:
            return parse(data)
        except CipError as exc:
            raise self.configurator.refuse(context.origin, exc.general, f"{what} from {context.origin} refused: "
                                                                         f"{exc}") from None

    def _change(self, context: RequestContext, what: str, **changes: Any) -> None:
        self.configurator.change(context.transport, context.origin, context.now, what, **changes)

    def read_attribute(self, instance: Instance, spec: AttributeSpec) -> Any:
        configuration = self.configurator.configuration
        if spec.id == 2:
            statuses = (configuration.device_status, configuration.ca_status)
            if CertificateStatus.INVALID in statuses:
                return CertificateState.INVALID
            if statuses == (CertificateStatus.VERIFIED, CertificateStatus.VERIFIED):
                return CertificateState.VERIFIED
            if self.configurator.state == SecurityState.CONFIGURATION_IN_PROGRESS:
                return CertificateState.CONFIGURING
            return CertificateState.CREATED
        fields = CERTIFICATE_FIELDS.get(spec.id)
        if fields is not None:
            return getattr(configuration, fields[1]), CERTIFICATE_PATHS[spec.id]
        return super().read_attribute(instance, spec)

    def write_attribute(self, instance: Instance, spec: AttributeSpec, value: Any,
                        context: RequestContext | None = None) -> None:
        """A Set names the file of the certificate: this device keeps each in its own (0x09 for another);
        the certificate is marked not verified, to be verified again."""
        _, path = spec.validate(value)
        if path != CERTIFICATE_PATHS[spec.id]:
            file = CERTIFICATE_PATHS[spec.id]
            raise CipError(GeneralStatus.INVALID_ATTRIBUTE_VALUE,
                           message=f"{spec.name} is kept in File object instance {file[1]}")
        self._session_change(context, f"Set_Attribute_Single {spec.name}",
                             **{CERTIFICATE_FIELDS[spec.id][1]: CertificateStatus.NOT_VERIFIED})

    def create_csr(self, instance: Instance | None, path: ApplicationPath, request: MessageRouterRequest,
                   context: RequestContext) -> bytes:
        """Nine SHORT_STRINGs (``certificates.CSR_FIELDS``); the reply is the path to the File object
        instance that holds the CSR (PEM). A new key is made for it; the session's owner only."""
        fields, offset = [], 0
        for _ in certificates.CSR_FIELDS:
            text, offset = SHORT_STRING.decode_from(request.data, offset)
            fields.append(text)
        if offset != len(request.data):
            raise CipError(GeneralStatus.TOO_MUCH_DATA, message="Create_CSR takes nine SHORT_STRINGs")
        self.configurator.require(context.transport, context.origin, context.now, "Create_CSR")
        key = certificates.new_key()
        csr = certificates.certificate_signing_request(key, fields, self.csr_defaults)
        self._session_change(context, "Create_CSR", device_key=key, certificate_request=csr,
                             device_status=CertificateStatus.NOT_VERIFIED)
        return encode_object_path((FILE_CLASS, CSR_FILE))

    def verify_certificate(self, instance: Instance | None, path: ApplicationPath, request: MessageRouterRequest,
                           context: RequestContext) -> bytes:
        """Verify the device certificate against the CA certificate and the device's key. In a session its
        status becomes Verified or Invalid; a failure is 0xD0 (Volume 8 5-5.8.1)."""
        if request.data:
            raise CipError(GeneralStatus.TOO_MUCH_DATA, message="Verify_Certificate takes no data here")
        configuration = self.configurator.configuration
        why = certificates.verify(configuration.device_certificate, configuration.ca_certificate,
                                  configuration.device_key, check_expiration=bool(configuration.check_expiration))
        if self.configurator.owned_by(context.transport):
            status = CertificateStatus.VERIFIED if why is None else CertificateStatus.INVALID
            self._session_change(context, "Verify_Certificate", device_status=status, ca_status=status)
        if why is not None:
            raise CipError(VERIFICATION_FAILED, message=why)
        return b""


def register(router: MessageRouter, configurator: Configurator, csr_defaults: dict[str, str]) -> None:
    """Serve the three objects on ``router`` over ``configurator``, and their files on the device's File
    object (one is made for a device that has none)."""
    files = router.objects.get(FILE_CLASS)
    if files is None:
        files = router.register(FileObject(()))
    if not isinstance(files, FileObject):
        raise BadRequest(f"class 0x{FILE_CLASS:02X} is not a File object here: the certificates have no files")
    router.register(CipSecurityObject(configurator))
    router.register(EipSecurityObject(configurator))
    router.register(CertificateManagementObject(configurator, csr_defaults, files))


__all__ = ["CertificateManagementObject", "CipSecurityObject", "EipSecurityObject", "register", "usable"]
