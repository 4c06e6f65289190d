"""What the CIP Security tests share: the peers they drive (openssl, tshark), skipped with the reason
where a machine lacks them, and the first request a secured session carries."""

from __future__ import annotations

import shutil

import pytest

OPENSSL = shutil.which("openssl")
TSHARK = shutil.which("tshark")
needs_openssl = pytest.mark.skipif(OPENSSL is None, reason="the openssl command is not installed")
needs_tshark = pytest.mark.skipif(TSHARK is None, reason="the tshark command is not installed")

#: RegisterSession (0x0065), length 4, session 0, status 0, sender context "cipstack", options 0;
#: protocol version 1, option flags 0: 28 bytes.
REGISTER_SESSION = bytes.fromhex("6500" "0400" "00000000" "00000000") + b"cipstack" + bytes.fromhex("00000000"
                                                                                                  "0100" "0000")
