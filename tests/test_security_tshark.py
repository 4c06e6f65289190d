"""What tshark shows of the EtherNet/IP Security (0x5E) and Certificate Management (0x5F) attributes the
emulator serves: Wireshark's packet-enip.c dissects them (Volume 8 edition 1.11), an independent reading
of the bytes on the wire (issue 48).

The requests go over a plain socket to an emulator in the test's event loop; the bytes both ways are
written into a pcap as one TCP flow (``cipstack.capture.synth``) and tshark reads it."""

from __future__ import annotations

import asyncio
import shutil
import socket
import struct
import subprocess
from pathlib import Path

import pytest

pytest.importorskip("cryptography", reason="the security extra (cryptography) is not installed")

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.capture.synth import PcapWriter, TcpFlow, ethernet
from cipstack.eip.wire.cpf import Item, ItemType, encode_items
from cipstack.eip.wire.encapsulation import Command, EncapsulationHeader, encode_frame
from cipstack.scanner import SyncScanner
from cipstack.security.provisioning import init
from cipstack.security.push import configure
from tests.ports import free_port

pytestmark = [pytest.mark.tshark,
              pytest.mark.skipif(shutil.which("tshark") is None, reason="tshark is not installed")]

HOST = "127.0.0.1"


def _exchange(port: int, requests: list[bytes]) -> list[tuple[bool, bytes]]:
    """RegisterSession, then each CIP request as SendRRData: the frames both ways, in order."""
    frames: list[tuple[bool, bytes]] = []
    with socket.create_connection((HOST, port), timeout=10) as sock:
        def round_trip(frame: bytes) -> bytes:
            sock.sendall(frame)
            head = b""
            while len(head) < 24:
                head += sock.recv(24 - len(head))
            length = EncapsulationHeader.decode(head).length
            body = b""
            while len(body) < length:
                body += sock.recv(length - len(body))
            frames.extend([(True, frame), (False, head + body)])
            return head + body

        reply = round_trip(encode_frame(Command.REGISTER_SESSION, struct.pack("<HH", 1, 0)))
        session = EncapsulationHeader.decode(reply).session
        for number, request in enumerate(requests):
            data = struct.pack("<IH", 0, 10) + encode_items([Item(ItemType.NULL_ADDRESS),
                                                             Item(ItemType.UNCONNECTED_DATA, request)])
            round_trip(encode_frame(Command.SEND_RR_DATA, data, session, context=struct.pack("<Q", number + 1)))
    return frames


def _get(class_id: int, instance: int, attribute: int) -> bytes:
    return bytes((0x0E, 3, 0x20, class_id, 0x24, instance, 0x30, attribute))


def _tshark(pcap: Path, *fields: str) -> list[list[str]]:
    command = ["tshark", "-r", str(pcap), "-Y", "cip", "-T", "fields", "-E", "separator=|", "-E", "occurrence=a",
               "-E", "aggregator=,"]
    for name in fields:
        command += ["-e", name]
    result = subprocess.run(command, capture_output=True, text=True, timeout=60, check=False)
    assert result.returncode == 0, result.stderr
    return [line.split("|") for line in result.stdout.splitlines()]


async def test_tshark_dissects_the_security_attributes_as_served(tmp_path: Path) -> None:
    lab = tmp_path / "lab"
    init(lab)
    settings = AdapterSettings(port=0, io_port=0, security_port=free_port(), security_objects=True)
    async with Adapter(settings) as adapter:
        def run() -> list[tuple[bool, bytes]]:
            with SyncScanner(f"{HOST}:{adapter.port}", identify=False) as plain:
                def request(service: int, class_id: int, instance: int, attribute: int | None,
                            data: bytes) -> tuple[int, tuple[int, ...], bytes]:
                    reply = plain.request(service, class_id, instance, attribute, data, check=False)
                    return reply.general_status, reply.extended_status, reply.data
                configure(request, lab, allowed_suites=(0xC02B,))
            return _exchange(adapter.port, [_get(0x5E, 1, 1), _get(0x5E, 1, 2), _get(0x5E, 1, 3), _get(0x5E, 1, 4),
                                            _get(0x5E, 1, 6), _get(0x5E, 1, 7), _get(0x5E, 1, 9), _get(0x5F, 1, 1),
                                            _get(0x5F, 1, 2), _get(0x5F, 1, 5), _get(0x5F, 0, 8), _get(0x5F, 1, 3),
                                            _get(0x5F, 1, 4)])

        frames = await asyncio.to_thread(run)
    pcap = tmp_path / "security.pcap"
    flow = TcpFlow((HOST, 50000), (HOST, 44818))
    with pcap.open("wb") as stream:
        writer = PcapWriter(stream)
        for number, frame in enumerate(flow.handshake() + [flow.send(client, data) for client, data in frames]):
            writer.write(1_700_000_000 + number / 1000, ethernet(frame))

    rows = _tshark(pcap, "cip.eip_security.state", "cip.eip_security.capability_flags.secure_renegotiation",
                   "cip.eip_security.num_avail_cipher_suites", "cip.eip_security.avail_cipher_suite",
                   "cip.eip_security.num_allow_cipher_suites", "cip.eip_security.allow_cipher_suite",
                   "cip.eip_security.num_active_certs", "cip.eip_security.num_trusted_auths",
                   "cip.eip_security.verify_client_cert", "cip.eip_cert.name", "cip.eip_cert.state",
                   "cip.eip_cert.encoding", "cip.eip_cert.capflags.push", "_ws.expert",
                   "cip.eip_cert.device_cert.status", "cip.eip_cert.ca_cert.status", "cip.instance")
    shown: dict[int, str] = {}
    for row in rows:
        for index, value in enumerate(row):
            if value:
                shown[index] = shown.get(index, "") + value
    assert shown[0] == "2"                                   # State: Configured
    assert shown[1] == "1"                         # secure renegotiation
    assert shown[2] == "7"
    # IANA ids, first byte first, as Wireshark reads them: the certificate suites, then the PSK suites.
    assert shown[3] == "0xc023,0xc02b,0xc02c,0xc037,0xccac,0x00a8,0x00a9"
    assert shown[4] == "1" and shown[5] == "0xc02b"
    assert shown[6] == "1" and shown[7] == "1"               # one path each (to 0x5F/1)
    assert shown[8] == "1"
    assert shown[9] == "Default Device Certificate"
    assert shown[10] == "3" and shown[11] == "0"             # Verified, PEM
    assert shown[12] == "1"                        # push model
    assert 13 not in shown                                   # no expert info: nothing malformed
    assert shown[14] == "1" and shown[15] == "1"             # both certificates verified, each then its path
    # The paths to the certificates' File object instances, as Wireshark reads them (0xCA, 0xCB).
    assert "0xca" in shown[16] and "0xcb" in shown[16]       # the instances of the two replies' paths
