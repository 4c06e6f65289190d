"""CIP Security for the scripted fake target: the three objects' attributes (a Configured device with
the ECDHE-ECDSA suites), the configuration services a configured device answers, and a TLS listener
on a port of its own that hands each TLS connection to the fake's encapsulation server. Each check of
group security has one deviation here, named by its id."""

from __future__ import annotations

import shutil
import socket
import ssl
import struct
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from cipstack.security.provisioning import init

SUITES = {0xC023: "ECDHE-ECDSA-AES128-SHA256", 0xC02B: "ECDHE-ECDSA-AES128-GCM-SHA256",
          0xC02C: "ECDHE-ECDSA-AES256-GCM-SHA384"}
OWN_PATH = b"\x02\x20\x5f\x24\x01"     # one path: 2 words, 0x5F/1


def _reply(service: int, status: int = 0, data: bytes = b"") -> bytes:
    return bytes((service | 0x80, 0, status, 0)) + data


class FakeSecurity:
    """What the fake serves of CIP Security; ``deviates(check_id)`` is the fake target's."""

    def __init__(self, deviates: Callable[[str], bool], host: str, start: Callable[..., None],
                 serve: Callable[[Any], None], stopped: Callable[[], bool]) -> None:
        self.deviates = deviates
        self.serve = serve
        self.start = start
        self.stopped = stopped
        self._temporary = tempfile.mkdtemp(prefix="fake-security-")
        #: The credentials folder the battery is given (``--security DIR``).
        self.folder = Path(self._temporary) / "lab"
        init(self.folder)
        suites = b"".join(s.to_bytes(2, "big") for s in SUITES)
        self.attributes: dict[tuple[int, int], bytes] = {
            (0x5D, 1): b"\x02",
            (0x5E, 1): b"\x02", (0x5E, 2): struct.pack("<I", 1),
            (0x5E, 3): (b"\x03" + suites[:4]) if deviates("security.objects.attributes") else b"\x03" + suites,
            (0x5E, 4): b"\x03" + suites, (0x5E, 6): b"\x01" + OWN_PATH, (0x5E, 7): b"\x01" + OWN_PATH,
            (0x5E, 8): b"\x00", (0x5E, 9): b"\x01", (0x5E, 10): b"\x00", (0x5E, 11): b"\x00", (0x5E, 12): b"\x00",
            (0x5E, 13): b"\x01", (0x5E, 14): b"\x00\x00", (0x5E, 15): struct.pack("<H", 12), (0x5E, 16): b"\x00",
            (0x5F, 1): b"\x1aDefault Device Certificate", (0x5F, 2): b"\x03", (0x5F, 5): b"\x00",
            (0x5F, 3): b"\x01\x02\x20\x37\x24\xca", (0x5F, 4): b"\x01\x02\x20\x37\x24\xcb",
        }
        self.context = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
        self.context.minimum_version = self.context.maximum_version = ssl.TLSVersion.TLSv1_2
        self.context.load_cert_chain(self.folder / "device.pem", self.folder / "device.key")
        self.context.load_verify_locations(cafile=self.folder / "ca.pem")
        self.context.verify_mode = ssl.CERT_NONE if deviates("security.tls.untrusted_client") else ssl.CERT_REQUIRED
        names = list(SUITES.values())
        if deviates("security.tls.allowed_suite"):
            names = ["ECDHE-ECDSA-AES256-GCM-SHA384"]     # not the first it lists as allowed
        if deviates("security.tls.disallowed_suite"):
            names.append("ECDHE-ECDSA-CHACHA20-POLY1305")
        self.context.set_ciphers(":".join(names))
        self.listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.listener.bind((host, 0))
        self.listener.listen(8)
        self.listener.settimeout(0.05)
        #: The TLS port.
        self.port = self.listener.getsockname()[1]
        start(self._accept)

    def close(self) -> None:
        self.listener.close()
        shutil.rmtree(self._temporary, ignore_errors=True)

    # -- the objects -------------------------------------------------------------------------------------
    def request(self, service: int, class_id: int, attribute: int | None) -> bytes:
        if service == 0x0E and attribute is not None:
            if (class_id, attribute) == (0x5E, 5):
                if self.deviates("security.objects.psk_unreadable"):
                    return _reply(service, 0, b"\x01\x03lab\x04\x00\x01\x02\x03")
                return _reply(service, 0x14)
            value = self.attributes.get((class_id, attribute))
            return _reply(service, 0x14) if value is None else _reply(service, 0, value)
        if (service, class_id) == (0x4C, 0x5E):          # Kick_Timer: no session here
            return _reply(service, 0 if self.deviates("security.session.outside") else 0x0C)
        if (service, class_id) == (0x4B, 0x5E):          # Begin_Config: the device is Configured
            return _reply(service, 0 if self.deviates("security.session.begin") else 0x0C)
        return _reply(service, 0x08)

    # -- the TLS port ------------------------------------------------------------------------------------
    def _accept(self) -> None:
        while not self.stopped():
            try:
                conn, _ = self.listener.accept()
            except (TimeoutError, OSError):
                continue
            conn.settimeout(2.0)
            try:
                first = conn.recv(1, socket.MSG_PEEK)
            except OSError:
                conn.close()
                continue
            if first != b"\x16":                          # not a TLS handshake record
                if self.deviates("security.tls.plaintext"):
                    conn.settimeout(0.05)
                    self.start(self.serve, conn)          # answered in plain, as on 44818
                else:
                    conn.close()
                continue
            try:
                tls = self.context.wrap_socket(conn, server_side=True)
            except (ssl.SSLError, OSError):
                conn.close()
                continue
            tls.settimeout(0.05)
            self.start(self.serve, tls)
