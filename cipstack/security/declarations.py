"""The three CIP Security objects, declared once: class codes, attributes, services, states.

Volume 8 (CIP Security) is not public. Every number here is as OpENer's CIP Security branch
declares it (``cipsecurity.h``, ``ethernetipsecurity.h``, ``certificatemanagement.h``; the Volume 8
section each cites is given beside it); a value no public source gives is marked "chosen here" and
docs/security.md names it.
"""

from __future__ import annotations

from enum import IntEnum

from ..cip.messages import Service
from ..cip.model import Access, AttributeSpec, ClassSpec
from ..cip.types import BOOL, DWORD, SHORT_STRING, UINT, USINT, WORD
from .attributes import CERTIFICATE, OBJECT_PATH, PATH_LIST, PRE_SHARED_KEYS, CipherSuiteList

CIP_SECURITY_CLASS = 0x5D
EIP_SECURITY_CLASS = 0x5E
CERTIFICATE_MANAGEMENT_CLASS = 0x5F


class ConfigService(IntEnum):
    """The EtherNet/IP Security object's configuration services (Volume 8 5-4.7.1 to 5-4.7.4)."""

    BEGIN_CONFIG = 0x4B
    KICK_TIMER = 0x4C
    APPLY_CONFIG = 0x4D
    ABORT_CONFIG = 0x4E


class CertificateService(IntEnum):
    """The Certificate Management object's services (Volume 8 5-5.7)."""

    CREATE_CSR = 0x4B
    VERIFY_CERTIFICATE = 0x4C


class SecurityState(IntEnum):
    """EtherNet/IP Security attribute 1 (Volume 8 5-4.4.1)."""

    FACTORY_DEFAULT = 0
    CONFIGURATION_IN_PROGRESS = 1
    CONFIGURED = 2
    PULL_MODEL_IN_PROGRESS = 3
    PULL_MODEL_COMPLETED = 4
    PULL_MODEL_DISABLED = 5


class CipSecurityState(IntEnum):
    """CIP Security attribute 1 (Volume 8 5-3.4.1)."""

    FACTORY_DEFAULT = 0
    CONFIGURATION_IN_PROGRESS = 1
    CONFIGURED = 2
    INCOMPLETE_CONFIGURATION = 3


class CertificateState(IntEnum):
    """Certificate Management attribute 2 (Volume 8 5-5.4.2)."""

    NON_EXISTENT = 0
    CREATED = 1
    CONFIGURING = 2
    VERIFIED = 3
    INVALID = 4


class CertificateStatus(IntEnum):
    """The status octet of attributes 3 and 4 (Volume 8 5-5.4.3)."""

    NOT_VERIFIED = 0
    VERIFIED = 1
    INVALID = 2


#: Security Profiles bit of the EtherNet/IP Confidentiality Profile (Volume 8 5-3.4.2).
CONFIDENTIALITY_PROFILE = 0x0002
#: Capability Flags bit 0: secure renegotiation (RFC 5746), which OpenSSL offers (Volume 8 5-4.4.2).
SECURE_RENEGOTIATION = 0x01
#: Certificate Management class attribute 8: push model (Volume 8 5-5.3.1); attribute 10: PEM (5-5.3.3).
PUSH_MODEL = 0x01
ENCODING_PEM_SUPPORTED = 0x01
#: Object-specific general status of Verify_Certificate when verification fails (Volume 8 5-5.8.1).
VERIFICATION_FAILED = 0xD0
#: Apply_Config's extended status (Volume 8 5-4.8.1).
NO_CERTIFICATES_CONFIGURED = 0x0002
NO_CIPHER_SUITES_CONFIGURED = 0x0004
#: The File object (class 0x37) instances of the certificate signing request, the device certificate
#: and the CA certificate (chosen here: after the EDS file's 0xC8; the branch creates its own at start).
FILE_CLASS = 0x37
CSR_FILE, DEVICE_CERTIFICATE_FILE, CA_CERTIFICATE_FILE = 0xC9, 0xCA, 0xCB
#: The File object instance a configuration tool downloads a certificate revocation list into, which
#: the Certificate Revocation List attribute (0x5E attribute 8) then names (chosen here: the next one).
CRL_FILE = 0xCC
#: The File object instance a tool downloads the certificates of the Trusted Identities into (PEM, one
#: or more), which that attribute (0x5E attribute 12) then names (chosen here, as ``CRL_FILE``).
TRUSTED_IDENTITIES_FILE = 0xCD
#: DTLS Timeout default, seconds (the branch's default).
DTLS_TIMEOUT = 12

#: The certificate suites this device offers over TLS 1.2, by IANA id, with OpenSSL's names: the
#: ECDHE-ECDSA suites with AES-128 the EtherNet/IP Confidentiality Profile names (CBC-SHA256 and
#: GCM-SHA256), and AES-256-GCM. The NULL suites are not offered (chosen here: they need OpenSSL's
#: security level 0, and nothing here carries I/O over TLS).
CERTIFICATE_SUITE_NAMES: dict[int, str] = {
    0xC023: "ECDHE-ECDSA-AES128-SHA256",
    0xC02B: "ECDHE-ECDSA-AES128-GCM-SHA256",
    0xC02C: "ECDHE-ECDSA-AES256-GCM-SHA384",
}
#: The pre-shared key suites (``psk.PSK_SUITES``; ids of RFC 5489, RFC 7905 and RFC 5487):
#: ECDHE-PSK-AES128-CBC-SHA256, the one the profile's public write-ups name, then the PSK AEAD
#: suites. Offered when the device holds a key and Allowed Cipher Suites lists them.
PSK_SUITE_NAMES: dict[int, str] = {
    0xC037: "ECDHE-PSK-AES128-CBC-SHA256",
    0xCCAC: "ECDHE-PSK-CHACHA20-POLY1305",
    0x00A8: "PSK-AES128-GCM-SHA256",
    0x00A9: "PSK-AES256-GCM-SHA384",
}
CIPHER_SUITE_NAMES: dict[int, str] = {**CERTIFICATE_SUITE_NAMES, **PSK_SUITE_NAMES}
#: The same suites by their IANA names (RFC 5289, 3.1 and 3.2; RFC 5489, RFC 7905 and RFC 5487 for
#: the PSK suites), as a user may name them.
CIPHER_SUITE_IANA_NAMES: dict[int, str] = {
    0xC023: "TLS_ECDHE_ECDSA_WITH_AES_128_CBC_SHA256",
    0xC02B: "TLS_ECDHE_ECDSA_WITH_AES_128_GCM_SHA256",
    0xC02C: "TLS_ECDHE_ECDSA_WITH_AES_256_GCM_SHA384",
    0xC037: "TLS_ECDHE_PSK_WITH_AES_128_CBC_SHA256",
    0xCCAC: "TLS_ECDHE_PSK_WITH_CHACHA20_POLY1305_SHA256",
    0x00A8: "TLS_PSK_WITH_AES_128_GCM_SHA256",
    0x00A9: "TLS_PSK_WITH_AES_256_GCM_SHA384",
}
AVAILABLE_CIPHER_SUITES = tuple(CIPHER_SUITE_NAMES)
CIPHER_SUITES = CipherSuiteList(names=CIPHER_SUITE_NAMES)

_STATE_NAMES = {s.value: s.name.replace("_", " ").title() for s in SecurityState}

CIP_SECURITY_SPEC = ClassSpec(
    CIP_SECURITY_CLASS, "CIP Security", revision=1,
    instance_attributes=(
        AttributeSpec(1, "State", USINT, enum={s.value: s.name.replace("_", " ").title() for s in CipSecurityState}),
        AttributeSpec(2, "Security Profiles", WORD, default=CONFIDENTIALITY_PROFILE),
        AttributeSpec(3, "Security Profiles Configured", WORD, default=0),
    ),
    class_services=frozenset({Service.GET_ATTRIBUTE_SINGLE}),
    instance_services=frozenset({Service.GET_ATTRIBUTES_ALL, Service.GET_ATTRIBUTE_SINGLE}),
)

#: The EtherNet/IP Security object, instance 1 (Volume 8 5-4.4.x); class revision as the branch's last.
EIP_SECURITY_SPEC = ClassSpec(
    EIP_SECURITY_CLASS, "EtherNet/IP Security", revision=7,
    instance_attributes=(
        AttributeSpec(1, "State", USINT, enum=_STATE_NAMES),
        AttributeSpec(2, "Capability Flags", DWORD, default=SECURE_RENEGOTIATION),
        AttributeSpec(3, "Available Cipher Suites", CIPHER_SUITES, default=AVAILABLE_CIPHER_SUITES),
        AttributeSpec(4, "Allowed Cipher Suites", CIPHER_SUITES, Access.GET_SET, default=AVAILABLE_CIPHER_SUITES),
        AttributeSpec(5, "Pre-Shared Keys", PRE_SHARED_KEYS, Access.SET, default=(), in_get_all=False),
        AttributeSpec(6, "Active Device Certificates", PATH_LIST, Access.GET_SET, default=()),
        AttributeSpec(7, "Trusted Authorities", PATH_LIST, Access.GET_SET, default=()),
        AttributeSpec(8, "Certificate Revocation List", OBJECT_PATH, Access.GET_SET, default=()),
        AttributeSpec(9, "Verify Client Certificate", BOOL, Access.GET_SET, default=0),
        AttributeSpec(10, "Send Certificate Chain", BOOL, Access.GET_SET, default=0),
        AttributeSpec(11, "Check Expiration", BOOL, Access.GET_SET, default=0),
        AttributeSpec(12, "Trusted Identities", PATH_LIST, Access.GET_SET, default=()),
        AttributeSpec(13, "Pull Model Enable", BOOL, Access.GET_SET, default=1),
        AttributeSpec(14, "Pull Model Status", UINT, default=0),
        AttributeSpec(15, "DTLS Timeout", UINT, Access.GET_SET, default=DTLS_TIMEOUT, unit="s", minimum=1),
        AttributeSpec(16, "UDP-only Policy", USINT, Access.GET_SET, default=0),
    ),
    extra_class_attributes=(AttributeSpec(8, "Number of PSKs Supported", UINT, default=1),),
    class_services=frozenset({Service.GET_ATTRIBUTE_SINGLE}),
    instance_services=frozenset({Service.GET_ATTRIBUTES_ALL, Service.RESET, Service.GET_ATTRIBUTE_SINGLE,
                                 Service.SET_ATTRIBUTE_SINGLE, *ConfigService}),
)

#: The Certificate Management object (Volume 8 5-5.4.x); instance 1 holds the device's certificate.
CERTIFICATE_MANAGEMENT_SPEC = ClassSpec(
    CERTIFICATE_MANAGEMENT_CLASS, "Certificate Management", revision=2,
    instance_attributes=(
        AttributeSpec(1, "Name", SHORT_STRING, default="Default Device Certificate"),
        AttributeSpec(2, "State", USINT, default=CertificateState.CREATED,
                      enum={s.value: s.name.replace("_", " ").title() for s in CertificateState}),
        AttributeSpec(3, "Device Certificate", CERTIFICATE, Access.GET_SET, default=(0, ())),
        AttributeSpec(4, "CA Certificate", CERTIFICATE, Access.GET_SET, default=(0, ())),
        AttributeSpec(5, "Certificate Encoding", USINT, default=0, enum={0: "PEM", 1: "PKCS#7"}),
    ),
    extra_class_attributes=(AttributeSpec(8, "Capability Flags", DWORD, default=PUSH_MODEL),
                            AttributeSpec(10, "Certificate Encodings Flag", DWORD, default=ENCODING_PEM_SUPPORTED)),
    class_services=frozenset({Service.GET_ATTRIBUTE_SINGLE}),
    instance_services=frozenset({Service.GET_ATTRIBUTES_ALL, Service.GET_ATTRIBUTE_SINGLE,
                                 Service.SET_ATTRIBUTE_SINGLE, *CertificateService}),
)

#: Declarations by class code, for whoever decodes replies.
SECURITY_CLASSES: dict[int, ClassSpec] = {spec.class_id: spec for spec in
                                          (CIP_SECURITY_SPEC, EIP_SECURITY_SPEC, CERTIFICATE_MANAGEMENT_SPEC)}

__all__ = ["AVAILABLE_CIPHER_SUITES", "CA_CERTIFICATE_FILE", "CERTIFICATE_MANAGEMENT_CLASS",
           "CERTIFICATE_MANAGEMENT_SPEC", "CERTIFICATE_SUITE_NAMES", "CIPHER_SUITES", "CIPHER_SUITE_IANA_NAMES",
           "CIPHER_SUITE_NAMES", "CIP_SECURITY_CLASS", "CIP_SECURITY_SPEC", "CONFIDENTIALITY_PROFILE", "CRL_FILE",
           "CSR_FILE", "DEVICE_CERTIFICATE_FILE", "DTLS_TIMEOUT", "EIP_SECURITY_CLASS", "EIP_SECURITY_SPEC",
           "FILE_CLASS", "NO_CERTIFICATES_CONFIGURED", "NO_CIPHER_SUITES_CONFIGURED", "PSK_SUITE_NAMES",
           "SECURITY_CLASSES", "TRUSTED_IDENTITIES_FILE",
           "VERIFICATION_FAILED", "CertificateService", "CertificateState", "CertificateStatus",
           "CipSecurityState", "ConfigService", "SecurityState"]
