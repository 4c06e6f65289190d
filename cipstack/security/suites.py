"""TLS 1.2 suites by the names users give them: IANA's (RFC 5289), OpenSSL's, or the 16-bit id."""

from __future__ import annotations

import ssl
from functools import cache

from .declarations import CIPHER_SUITE_IANA_NAMES, CIPHER_SUITE_NAMES


@cache
def suite_names() -> dict[int, str]:
    """OpenSSL's name of every TLS 1.2 suite it knows, by IANA id."""
    context = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
    context.set_ciphers("ALL:@SECLEVEL=0")
    return {c["id"] & 0xFFFF: c["name"] for c in context.get_ciphers() if c["protocol"] != "TLSv1.3"}


def suite_id(name: str) -> int | None:
    """The IANA id of a suite named by IANA's name, OpenSSL's or ``0xC02B``; None for a name no table has."""
    text = name.strip()
    if text.lower().startswith("0x"):
        try:
            return int(text, 16)
        except ValueError:
            return None
    for table in (CIPHER_SUITE_IANA_NAMES, CIPHER_SUITE_NAMES, suite_names()):
        for number, known in table.items():
            if known.upper() == text.upper():
                return number
    return None


def openssl_name(name: str) -> str | None:
    """OpenSSL's name of a suite named any of those ways; None when OpenSSL knows no such TLS 1.2 suite."""
    number = suite_id(name)
    return None if number is None else suite_names().get(number)


def describe_suites(ids: list[int] | tuple[int, ...]) -> str:
    """``0xC02B ECDHE-ECDSA-AES128-GCM-SHA256, ...``."""
    return ", ".join(f"0x{i:04X} {suite_names().get(i, '?')}" for i in ids) or "none"


__all__ = ["describe_suites", "openssl_name", "suite_id", "suite_names"]
