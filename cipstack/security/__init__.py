"""CIP Security: EtherNet/IP over TLS and DTLS as shells around the same sans-I/O cores, and the
credentials folder both roles read (``cipstack security init DIR`` writes it).

``Credentials.load(DIR)`` gives the ``security=`` argument of ``SyncScanner`` and ``Scanner``;
``cipstack adapter --security DIR`` serves TLS on TCP 2221 and DTLS (with secured class 1) on UDP
2221 beside plain 44818, with certificates or a pre-shared key (``psk``, ``tls_psk``). The CIP
Security, EtherNet/IP Security and Certificate Management objects (``objects``, over
``configuration``) let a configuration tool configure a factory-default device over the network
(``push`` is that tool's side). Nothing here is imported by the plain paths of the package: ``ssl``,
``cryptography`` and pyOpenSSL load only when security is asked for."""

from __future__ import annotations

from .credentials import SECURE_PORT, Credentials

__all__ = ["SECURE_PORT", "Credentials"]
