"""Configuring a device's CIP Security over the network, as a configuration tool does it (push model).

The steps, each one request to the device's objects (``security.declarations``):

1. Begin_Config (EtherNet/IP Security 0x5E/1, 0x4B): the session opens, owned by this connection;
2. Create_CSR (Certificate Management 0x5F/1, 0x4B): the device makes a key and a signing request,
   and names the File object instance that holds it, which is read (Initiate_Upload, Upload_Transfer);
3. the lab CA of the credentials folder signs it (``provisioning.sign_csr``);
4. the CA certificate and the device certificate are downloaded (Initiate_Download,
   Download_Transfer) into the File object instances 0x5F/1 attributes 4 and 3 name, and the trust
   is written (0x5E/1 attributes 6 and 7 name 0x5F/1; 9, Verify Client Certificate, on);
5. Verify_Certificate (0x5F/1, 0x4C), then Apply_Config (0x5E/1, 0x4D).

A step the device refuses aborts the session (Abort_Config) and raises ``SecurityError`` naming the
step and the status. The requests go through ``request``, whatever client sends them.
"""

from __future__ import annotations

import contextlib
import os
import struct
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from ..cip.status import CipError, describe_status
from ..cip.types import BOOL, SHORT_STRING
from ..errors import SecurityError
from ..objects.file import FileRequest, FileTransferError, read_file, write_file
from .attributes import CERTIFICATE, OBJECT_PATH, PATH_LIST, PRE_SHARED_KEYS, decode_object_path
from .certificates import CSR_FIELDS, pem
from .configuration import DEVICE_CERTIFICATE_PATH
from .credentials import CA_FILE
from .declarations import (
    CERTIFICATE_MANAGEMENT_CLASS,
    CIPHER_SUITES,
    CRL_FILE,
    EIP_SECURITY_CLASS,
    FILE_CLASS,
    TRUSTED_IDENTITIES_FILE,
    CertificateService,
    ConfigService,
)

_SET, _GET = 0x10, 0x0E
#: The EtherNet/IP Security attributes ``configure(attributes=)`` names in its steps.
ATTRIBUTE_NAMES = {10: "Send Certificate Chain", 11: "Check Expiration", 15: "DTLS Timeout", 16: "UDP-only Policy"}
#: What a refusal most likely means, for the one line the tool prints.
HINTS = {("Begin_Config", 0x0C): "the device is configured already, or another configuration session is open "
                                 "(a Reset of 0x5E/1 returns a configured device to factory default)",
         ("Verify_Certificate", 0xD0): "the device certificate does not verify against the CA certificate pushed",
         ("Apply_Config", 0x0C): "the configuration is incomplete (extended 0x0002: no usable certificate)"}

#: Sends one request: (service, class, instance, attribute or None, data) -> (general status, extended
#: status words, reply data).
Request = Callable[[int, int, int, "int | None", bytes], tuple[int, Sequence[int], bytes]]


@dataclass(frozen=True)
class Pushed:
    """What a configuration wrote: the device certificate (DER) and its subject."""

    certificate: bytes
    subject: str


def configure(request: Request, folder: str | os.PathLike[str], common_name: str = "",
              allowed_suites: Sequence[int] | None = None, verify_client: bool = True,
              step: Callable[[str], None] | None = None,
              pre_shared_keys: Sequence[tuple[bytes, bytes]] = (),
              attributes: Mapping[int, bytes] | None = None, revocation_list: bytes = b"",
              trusted_identities: bytes = b"") -> Pushed:
    """Configure the device ``request`` reaches with the CA of ``folder``; ``step`` hears each step's
    name. ``pre_shared_keys``: (identity, key) pairs written to the Pre-Shared Keys attribute (0x5E
    attribute 5), which the device's TLS port then accepts beside its certificate; ``attributes``:
    other EtherNet/IP Security attributes written as they are given (id -> the Set's data, e.g.
    ``{11: BOOL.encode(1)}`` for Check Expiration), after the ones above; ``revocation_list``: a CRL of
    the CA (PEM) downloaded into the device's CRL file, which Certificate Revocation List (attribute 8)
    then names; ``trusted_identities``: client certificates (PEM) downloaded into the device's Trusted
    Identities file, which attribute 12 then names: only clients of their subjects are served."""
    from .certificates import der_of_pem
    from .provisioning import sign_csr

    path = Path(folder)
    try:
        ca_der = der_of_pem((path / CA_FILE).read_bytes())
    except (OSError, ValueError) as exc:
        raise SecurityError(f"{path / CA_FILE}: not a usable CA certificate ({exc})") from None

    def send(what: str, service: int, class_id: int, attribute: int | None, data: bytes = b"") -> bytes:
        if step is not None:
            step(what)
        status, extended, reply = request(service, class_id, 1, attribute, data)
        if status != 0:
            hint = HINTS.get((what, status))
            line = f"{what} refused: {describe_status(status, tuple(extended))}"
            raise _Refused(f"{line}; {hint}" if hint else line)
        return reply

    def file(what: str, path: tuple[int, ...]) -> FileRequest:
        """The File object instance ``path`` names, as read_file and write_file call it."""
        if len(path) != 2 or path[0] != FILE_CLASS:
            raise _Refused(f"{what}: the device names no File object instance ({path})")

        def request_file(service: int, data: bytes) -> tuple[int, bytes]:
            status, _, reply = request(service, path[0], path[1], None, data)
            return status, reply
        return request_file

    def download(what: str, attribute: int, data: bytes) -> None:
        reply = send(f"Get {what}", _GET, CERTIFICATE_MANAGEMENT_CLASS, attribute)
        try:
            _, path = CERTIFICATE.decode(reply)
        except CipError as exc:
            raise _Refused(f"{what} reads {reply.hex()}: {exc}") from None
        if step is not None:
            step(f"download {what}")
        try:
            write_file(file(what, path), data, name=f"{what}.pem")
        except FileTransferError as exc:
            raise _Refused(f"download of the {what}: {exc}") from None

    send("Begin_Config", ConfigService.BEGIN_CONFIG, EIP_SECURITY_CLASS, None)
    try:
        fields = [common_name if name == "common name" else "" for name in CSR_FIELDS]
        reply = send("Create_CSR", CertificateService.CREATE_CSR, CERTIFICATE_MANAGEMENT_CLASS, None,
                     b"".join(SHORT_STRING.encode(text) for text in fields))
        try:
            csr_path, _ = decode_object_path(reply, 0)
        except CipError as exc:
            raise _Refused(f"Create_CSR reply {reply.hex()} is no path: {exc}") from None
        if step is not None:
            step("upload CSR")
        try:
            csr = read_file(file("the CSR", csr_path or ()))
        except FileTransferError as exc:
            raise _Refused(f"upload of the CSR: {exc}") from None
        certificate = sign_csr(path, csr)
        download("CA Certificate", 4, pem(ca_der))
        download("Device Certificate", 3, pem(certificate))
        own = PATH_LIST.encode((DEVICE_CERTIFICATE_PATH,))
        send("Set Active Device Certificates", _SET, EIP_SECURITY_CLASS, 6, own)
        send("Set Trusted Authorities", _SET, EIP_SECURITY_CLASS, 7, own)
        send("Set Verify Client Certificate", _SET, EIP_SECURITY_CLASS, 9, BOOL.encode(int(verify_client)))
        if allowed_suites is not None:
            send("Set Allowed Cipher Suites", _SET, EIP_SECURITY_CLASS, 4, CIPHER_SUITES.encode(tuple(allowed_suites)))
        if pre_shared_keys:
            send("Set Pre-Shared Keys", _SET, EIP_SECURITY_CLASS, 5, PRE_SHARED_KEYS.encode(tuple(pre_shared_keys)))
        if revocation_list:
            if step is not None:
                step("download Certificate Revocation List")
            try:
                write_file(file("the CRL", (FILE_CLASS, CRL_FILE)), revocation_list, name="crl.pem")
            except FileTransferError as exc:
                raise _Refused(f"download of the certificate revocation list: {exc}") from None
            send("Set Certificate Revocation List", _SET, EIP_SECURITY_CLASS, 8,
                 OBJECT_PATH.encode((FILE_CLASS, CRL_FILE)))
        if trusted_identities:
            if step is not None:
                step("download Trusted Identities")
            try:
                write_file(file("the trusted identities", (FILE_CLASS, TRUSTED_IDENTITIES_FILE)), trusted_identities,
                           name="identities.pem")
            except FileTransferError as exc:
                raise _Refused(f"download of the trusted identities: {exc}") from None
            send("Set Trusted Identities", _SET, EIP_SECURITY_CLASS, 12,
                 PATH_LIST.encode(((FILE_CLASS, TRUSTED_IDENTITIES_FILE),)))
        for attribute, data in (attributes or {}).items():
            send(f"Set {ATTRIBUTE_NAMES.get(attribute, f'attribute {attribute}')}", _SET, EIP_SECURITY_CLASS,
                 attribute, data)
        send("Verify_Certificate", CertificateService.VERIFY_CERTIFICATE, CERTIFICATE_MANAGEMENT_CLASS, None)
        send("Apply_Config", ConfigService.APPLY_CONFIG, EIP_SECURITY_CLASS, None, struct.pack("<HH", 0, 0))
    except BaseException:
        # The device or the connection may be gone: then the session's timer ends it.
        with contextlib.suppress(Exception):
            request(ConfigService.ABORT_CONFIG, EIP_SECURITY_CLASS, 1, None, b"")
        raise
    from cryptography import x509

    subject = x509.load_der_x509_certificate(certificate).subject.rfc4514_string()
    return Pushed(certificate, subject)


class _Refused(SecurityError):
    """A step of the configuration the device refused."""


__all__ = ["Pushed", "Request", "configure"]
