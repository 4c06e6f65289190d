"""CIP Security with pre-shared keys: the PSK suites of TLS 1.2 and DTLS 1.2 in both roles, our
originator against our adapter and both against the `openssl` binary, the bad identities and keys,
and the Pre-Shared Keys attribute (0x5E attribute 5) written over the wire as the key the next
handshake uses.

The adapter runs in this process on a loop of its own thread, so that the tests read its counters
while blocking clients talk to it from the test's thread."""

from __future__ import annotations

import asyncio
import logging
import os
import re
import shutil
import socket
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("cryptography", reason="the security extra (cryptography) is not installed")
pytest.importorskip("OpenSSL", reason="the security extra (pyOpenSSL) is not installed")

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.cip.epath import request_path
from cipstack.cli import main
from cipstack.eip.originator.blocking import BlockingEncapsulationClient
from cipstack.errors import CipstackError, SecurityError
from cipstack.scanner import Scanner, SyncScanner
from cipstack.security import Credentials
from cipstack.security.dtls_link import DtlsLink
from cipstack.security.provisioning import init
from cipstack.security.push import configure
from tests.ports import free_port
from tests.security_peers import OPENSSL, REGISTER_SESSION, TSHARK, needs_openssl, needs_tshark
from tests.waiting import stop_process, wait_for, wait_listening

GET_ATTRIBUTE_SINGLE = 0x0E


class Served:
    """An adapter on a loop of its own thread."""

    def __init__(self, settings: AdapterSettings) -> None:
        self.loop = asyncio.new_event_loop()

        async def start() -> Adapter:
            adapter = Adapter(settings)
            await adapter.start()
            return adapter

        self.adapter = self.loop.run_until_complete(start())
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()

    @property
    def secure_port(self) -> int:
        server = self.adapter.tls or (self.adapter.secure.server if self.adapter.secure is not None else None)
        assert server is not None
        return server.port

    def close(self) -> None:
        asyncio.run_coroutine_threadsafe(self.adapter.close(), self.loop).result(10)
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(10)
        self.loop.close()


def _serve(folder: Path) -> Served:
    return Served(AdapterSettings(host="127.0.0.1", port=0, io_port=0, security=folder, security_port=0))


@pytest.fixture(scope="module")
def psk_lab(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A PSK-only folder, as `cipstack security init DIR --psk-only` writes it."""
    folder = tmp_path_factory.mktemp("psk") / "lab"
    assert main(["security", "init", str(folder), "--psk-only"]) == 0
    assert sorted(path.name for path in folder.iterdir()) == ["psk.txt"]
    return folder


@pytest.fixture
def served(psk_lab: Path) -> Iterator[Served]:
    server = _serve(psk_lab)
    try:
        yield server
    finally:
        server.close()


def _folder(path: Path, identity: str, key: bytes) -> Path:
    path.mkdir(parents=True, exist_ok=True)
    (path / "psk.txt").write_text(f"{identity}:{key.hex()}\n")
    return path


def _key_of(folder: Path) -> tuple[str, str]:
    identity, _, key = (folder / "psk.txt").read_text().strip().partition(":")
    return identity, key


def _accepted(caplog: pytest.LogCaptureFixture, what: str) -> list[str]:
    return [record.getMessage() for record in caplog.records if f"{what} accepted" in record.getMessage()]


def _read_until(fd: int, size: int, timeout: float = 30) -> bytes:
    out = b""
    deadline = time.monotonic() + timeout
    while len(out) < size and time.monotonic() < deadline:
        chunk = os.read(fd, 4096)
        if not chunk:
            break
        out += chunk
    return out


# -- our originator, our adapter ----------------------------------------------------------------------
def test_a_psk_only_folder_reads_over_tls(served: Served, psk_lab: Path, caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, logger="cipstack.security")
    with SyncScanner("127.0.0.1", served.secure_port, security=Credentials.load(psk_lab)) as drive:
        assert drive.read(1, 1, 7) == "CENT"   # Identity, Product Name: a Get_Attribute_Single over TLS
    (line,) = _accepted(caplog, "TLS connection")
    identity, _ = _key_of(psk_lab)
    assert f"(TLSv1.2, ECDHE-PSK-AES128-CBC-SHA256, PSK identity '{identity}')" in line


async def test_the_asyncio_scanner_reads_over_tls_with_a_psk(served: Served, psk_lab: Path) -> None:
    async with await Scanner.connect("127.0.0.1", served.secure_port, security=Credentials.load(psk_lab)) as drive:
        assert await drive.read(1, 1, 7) == "CENT"
    assert served.adapter.tls is not None and served.adapter.tls.refused == 0


def test_explicit_and_class1_over_dtls_with_a_psk(served: Served, psk_lab: Path,
                                                  caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, logger="cipstack.security")
    credentials = Credentials.load(psk_lab)
    client = BlockingEncapsulationClient.connect_dtls("127.0.0.1", served.secure_port, 5.0, credentials)
    with client:
        reply = client.perform(client.core.request(GET_ATTRIBUTE_SINGLE, request_path(1, 1, 7)))
        assert (reply.general_status, reply.data) == (0, b"\x04CENT")
    with SyncScanner("127.0.0.1", served.secure_port, security=credentials) as scanner, \
            scanner.io_connection(output=21, input=71, rpi=0.010) as io:
        io.update(run_forward=True, speed_reference=300)
        io.wait_input(lambda image: image.ready, timeout=10)
        assert served.adapter.io is not None
        (connection,) = served.adapter.io.connections.values()
        assert connection.secured
        wait_for(lambda: io.statistics()["received"] > 5, 10, "T->O data in the DTLS session")
    lines = _accepted(caplog, "DTLS session")
    identity, _ = _key_of(psk_lab)
    assert len(lines) == 2
    assert all(f"(DTLSv1.2, ECDHE-PSK-AES128-CBC-SHA256, PSK identity '{identity}')" in line for line in lines)
    assert served.adapter.dtls is not None and served.adapter.dtls.refused == 0


def test_a_folder_with_both_serves_certificates_and_the_psk(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, logger="cipstack.security")
    both = tmp_path / "both"
    init(both, psk=True)
    certificates_only = tmp_path / "certificates"
    certificates_only.mkdir()
    for name in ("ca.pem", "client.pem", "client.key"):
        shutil.copy(both / name, certificates_only / name)
    server = _serve(both)
    try:
        with SyncScanner("127.0.0.1", server.secure_port, security=Credentials.load(certificates_only)) as drive:
            assert drive.read(1, 1, 7) == "CENT"
        with SyncScanner("127.0.0.1", server.secure_port, security=Credentials.load(both)) as drive:
            assert drive.read(1, 1, 7) == "CENT"
    finally:
        server.close()
    first, second = _accepted(caplog, "TLS connection")
    assert "(TLSv1.2, ECDHE-ECDSA-" in first     # no key: the certificate suites, TLS 1.2 alone
    assert "(TLSv1.2, ECDHE-PSK-AES128-CBC-SHA256, PSK identity 'cipstack-lab')" in second   # its key first


def test_cipstack_io_with_a_psk_only_folder_runs_over_dtls(served: Served, psk_lab: Path, tmp_path: Path) -> None:
    address = f"127.0.0.1:{served.secure_port}"
    result = subprocess.run([sys.executable, "-m", "cipstack", "io", address, "--security", str(psk_lab),
                             "--output", "21", "--input", "71", "--rpi", "10ms", "--duration", "0.5s"],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    sent, received = (int(word) for word in re.findall(r"sent (\d+)  received (\d+)", result.stdout)[0])
    assert sent > 0 and received > 0
    identity, _ = _key_of(psk_lab)
    wrong = _folder(tmp_path / "wrong", identity, bytes(32))
    result = subprocess.run([sys.executable, "-m", "cipstack", "io", address, "--security", str(wrong),
                             "--output", "21", "--input", "71", "--duration", "0.5s"],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode != 0
    (line,) = result.stderr.strip().splitlines()
    # The command asks the device's identity over TLS first: that handshake is the one refused.
    assert line.startswith(f"cipstack io: TLS with {address} failed: the peer could not check our Finished: "
                           f"wrong pre-shared key for identity '{identity}'"), line


async def test_the_asyncio_scanner_opens_class1_over_dtls_with_a_psk(served: Served, psk_lab: Path) -> None:
    async with await Scanner.connect("127.0.0.1", served.secure_port, security=Credentials.load(psk_lab)) as drive, \
            drive.io_connection(output=21, input=71, rpi=0.010) as io:
        await io.wait_input(lambda image: image.ready, timeout=10)
        deadline = time.monotonic() + 10
        while io.statistics()["received"] <= 5 and time.monotonic() < deadline:
            await asyncio.sleep(0.01)
        assert io.statistics()["received"] > 5
    assert served.adapter.dtls is not None and served.adapter.dtls.refused == 0


def test_an_originator_with_a_key_still_reads_a_device_of_certificates(lab: Path, other_lab: Path,
                                                                       tmp_path: Path) -> None:
    # The originator's TLS is pyOpenSSL's once it holds a key: the device's certificate is still checked.
    mine, stranger = tmp_path / "mine", tmp_path / "stranger"
    for folder, source in ((mine, lab), (stranger, other_lab)):
        folder.mkdir()
        for name in ("ca.pem", "client.pem", "client.key"):
            shutil.copy(source / name, folder / name)
        _folder(folder, "line-7", bytes(range(32)))
    server = _serve(lab)
    try:
        with SyncScanner("127.0.0.1", server.secure_port, security=Credentials.load(mine)) as drive:
            assert drive.read(1, 1, 7) == "CENT"
        with pytest.raises(SecurityError) as raised:
            SyncScanner("127.0.0.1", server.secure_port, security=Credentials.load(stranger), timeout=5)
        assert str(raised.value) == (f"TLS with 127.0.0.1:{server.secure_port} failed: certificate verify "
                                     "failed: self-signed certificate in certificate chain")
    finally:
        server.close()


# -- against openssl ------------------------------------------------------------------------------------
@needs_openssl
@pytest.mark.parametrize("version", ["-tls1_2", "-dtls1_2"])
@pytest.mark.parametrize("suite", ["ECDHE-PSK-AES128-CBC-SHA256", "PSK-AES128-GCM-SHA256"])
def test_openssl_s_client_with_a_psk_registers_a_session(served: Served, psk_lab: Path, version: str,
                                                         suite: str) -> None:
    assert OPENSSL is not None
    identity, key = _key_of(psk_lab)
    command = [OPENSSL, "s_client", version, "-connect", f"127.0.0.1:{served.secure_port}", "-psk", key,
               "-psk_identity", identity, "-cipher", suite, "-quiet"]
    process = subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        assert process.stdin is not None and process.stdout is not None
        process.stdin.write(REGISTER_SESSION)
        process.stdin.flush()
        reply = _read_until(process.stdout.fileno(), 28)
    finally:
        stop_process(process)
        assert process.stderr is not None
        stderr = process.stderr.read()
        for stream in (process.stdin, process.stdout, process.stderr):
            if stream is not None:
                stream.close()
    assert len(reply) == 28, stderr
    command_code, length, session, status = struct.unpack_from("<HHII", reply)
    assert (command_code, length, status) == (0x0065, 4, 0) and session != 0
    assert reply[12:20] == b"cipstack"


@needs_openssl
@pytest.mark.parametrize("version", ["-tls1_2", "-dtls1_2"])
def test_originator_completes_a_psk_handshake_with_openssl_s_server(psk_lab: Path, version: str) -> None:
    assert OPENSSL is not None
    identity, key = _key_of(psk_lab)
    port = free_port()
    server = subprocess.Popen([OPENSSL, "s_server", version, "-accept", f"127.0.0.1:{port}", "-quiet", "-nocert",
                               "-psk", key, "-psk_identity", identity, "-cipher", "PSK-AES128-GCM-SHA256"],
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    credentials = Credentials.load(psk_lab)
    try:
        if version == "-tls1_2":
            wait_listening(server, port, "s_server to listen")
            sock = socket.create_connection(("127.0.0.1", port), timeout=10)
            tls = credentials.wrap_client(sock, "127.0.0.1", port)
            try:
                tls.sendall(REGISTER_SESSION)
                assert server.stdout is not None
                received = _read_until(server.stdout.fileno(), 28)
            finally:
                tls.close()
        else:
            links: list[DtlsLink] = []

            def handshake() -> bool:
                try:
                    links.append(DtlsLink(credentials, "127.0.0.1", port, 2.0))
                except CipstackError:   # not listening yet
                    return server.poll() is not None
                return True

            wait_for(handshake, 30, "a DTLS handshake with s_server")
            assert links, server.stderr.read() if server.stderr else ""
            assert links[0].channel.description() == "DTLSv1.2, PSK-AES128-GCM-SHA256"
            links[0].sendall(REGISTER_SESSION)
            assert server.stdout is not None
            received = _read_until(server.stdout.fileno(), 28)
            links[0].close()
        assert received == REGISTER_SESSION
    finally:
        stop_process(server)


# -- bad identities and keys ------------------------------------------------------------------------------
def _refusals(caplog: pytest.LogCaptureFixture, what: str) -> list[str]:
    return [record.getMessage() for record in caplog.records
            if record.getMessage().startswith(f"{what} handshake from 127.0.0.1:")]


def test_an_unknown_identity_or_a_wrong_key_is_named_and_nothing_else_is_disturbed(
        served: Served, psk_lab: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, logger="cipstack.security")
    identity, key = _key_of(psk_lab)
    stranger = Credentials.load(_folder(tmp_path / "stranger", "intruder", bytes.fromhex(key)))
    wrong = Credentials.load(_folder(tmp_path / "wrong", identity, bytes(32)))
    adapter, port = served.adapter, served.secure_port
    assert adapter.tls is not None and adapter.dtls is not None and adapter.io_endpoint is not None
    good = Credentials.load(psk_lab)
    plain_io_port = adapter.io_endpoint.port
    # Opened before the bad input, used after it: a TLS session, class 1 over DTLS, plain 44818 and 2222.
    with SyncScanner("127.0.0.1", port, security=good) as kept, \
            kept.io_connection(output=21, input=71, rpi=0.010) as secured_io, \
            SyncScanner("127.0.0.1", adapter.port) as plain, \
            plain.io_connection(input=71, heartbeat=198, rpi=0.010, target_io_port=plain_io_port) as plain_io:
        with pytest.raises(SecurityError) as raised:
            SyncScanner("127.0.0.1", port, security=stranger, timeout=5)
        assert str(raised.value) == (f"TLS with 127.0.0.1:{port} failed: PSK identity 'intruder' unknown to "
                                     "the device (alert: unknown PSK identity)")
        with pytest.raises(SecurityError) as raised:
            SyncScanner("127.0.0.1", port, security=wrong, timeout=5)
        assert str(raised.value).startswith(f"TLS with 127.0.0.1:{port} failed: the peer could not check our "
                                            f"Finished: wrong pre-shared key for identity '{identity}'")
        with pytest.raises(SecurityError) as raised:
            BlockingEncapsulationClient.connect_dtls("127.0.0.1", port, 5.0, stranger)
        assert str(raised.value) == (f"DTLS with 127.0.0.1:{port} failed: PSK identity 'intruder' unknown to "
                                     "the device (alert: unknown PSK identity)")
        with pytest.raises(SecurityError, match=f"wrong pre-shared key for identity '{identity}'"):
            BlockingEncapsulationClient.connect_dtls("127.0.0.1", port, 5.0, wrong)
        wait_for(lambda: adapter.tls is not None and adapter.tls.refused == 2 and adapter.dtls is not None
                 and adapter.dtls.refused == 2, 10, "the four refusals to be counted")
        # One line per source per 10 s for each port: the first refusal names the identity it did not know.
        (tls_line,) = _refusals(caplog, "TLS")
        (dtls_line,) = _refusals(caplog, "DTLS")
        assert tls_line.endswith("refused: unknown PSK identity 'intruder'")
        assert dtls_line.endswith("refused: unknown PSK identity 'intruder'")
        # Nothing else disturbed.
        assert kept.read(1, 1, 7) == "CENT"
        assert plain.read(1, 1, 7) == "CENT"
        for io in (secured_io, plain_io):
            before = io.statistics()["received"]
            wait_for(lambda io=io, before=before: io.statistics()["received"] > before + 5, 10, "class 1 data")
    with SyncScanner("127.0.0.1", port, security=good) as fresh:
        assert fresh.read(1, 1, 7) == "CENT"


def test_the_describe_of_a_wrong_key_on_the_device_names_it(served: Served, psk_lab: Path, tmp_path: Path,
                                                            caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, logger="cipstack.security")
    identity, _ = _key_of(psk_lab)
    wrong = Credentials.load(_folder(tmp_path / "wrong", identity, bytes(32)))
    with pytest.raises(SecurityError):
        SyncScanner("127.0.0.1", served.secure_port, security=wrong, timeout=5)
    wait_for(lambda: _refusals(caplog, "TLS"), 10, "the refusal line")
    (line,) = _refusals(caplog, "TLS")
    assert line.endswith(f"refused: wrong pre-shared key for identity '{identity}' "
                         "(decryption failed or bad record mac)"), line


# -- the Pre-Shared Keys attribute, written over the wire ---------------------------------------------------
def _push(served: Served, lab: Path, keys: tuple[tuple[bytes, bytes], ...],
          allowed: tuple[int, ...] | None = None) -> None:
    with SyncScanner("127.0.0.1", served.adapter.port, identify=False) as plain:
        def request(service: int, class_id: int, instance: int, attribute: int | None,
                    data: bytes) -> tuple[int, tuple[int, ...], bytes]:
            reply = plain.request(service, class_id, instance, attribute, data, check=False)
            return reply.general_status, reply.extended_status, reply.data

        configure(request, lab, pre_shared_keys=keys, allowed_suites=allowed)
    secure = served.adapter.secure
    assert secure is not None
    wait_for(lambda: secure.server is not None and secure.server.is_open, 10, "the TLS listener after Apply_Config")


def _reset(served: Served) -> None:
    secure = served.adapter.secure
    assert secure is not None
    reloads = secure.reloads
    with SyncScanner("127.0.0.1", served.adapter.port, identify=False) as plain:
        reply = plain.request(0x05, 0x5E, 1, None, b"", check=False)   # Reset: back to Factory Default
        assert reply.general_status == 0
    wait_for(lambda: secure.reloads > reloads, 10, "the listener to close after Reset")


def test_the_psk_written_over_the_wire_is_the_one_the_next_handshake_uses(lab: Path, tmp_path: Path) -> None:
    first, second = os.urandom(32), os.urandom(32)
    old = Credentials.load(_folder(tmp_path / "first", "line-7", first))
    new = Credentials.load(_folder(tmp_path / "second", "line-7", second))
    served = Served(AdapterSettings(host="127.0.0.1", port=0, io_port=0, security_objects=True, security_port=0))
    try:
        _push(served, lab, ((b"line-7", first),))
        with SyncScanner("127.0.0.1", served.secure_port, security=old, identify=False) as drive:
            assert drive.read(1, 1, 7) == "CENT"
        # A certificate client is still served beside the key.
        with SyncScanner("127.0.0.1", served.secure_port, security=Credentials.load(lab)) as drive:
            assert drive.read(1, 1, 7) == "CENT"
        _reset(served)
        _push(served, lab, ((b"line-7", second),))
        with pytest.raises(SecurityError, match="wrong pre-shared key for identity 'line-7'"):
            SyncScanner("127.0.0.1", served.secure_port, security=old, timeout=5)
        with SyncScanner("127.0.0.1", served.secure_port, security=new, identify=False) as drive:
            assert drive.read(1, 1, 7) == "CENT"
    finally:
        served.close()


def test_allowed_cipher_suites_decide_the_psk_suites(lab: Path, tmp_path: Path,
                                                     caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, logger="cipstack.security")
    key = os.urandom(32)
    originator = Credentials.load(_folder(tmp_path / "key", "line-7", key))
    served = Served(AdapterSettings(host="127.0.0.1", port=0, io_port=0, security_objects=True, security_port=0))
    try:
        # PSK suites alone and no key: nothing a handshake could use, refused at Apply_Config.
        with pytest.raises(SecurityError, match=r"Apply_Config refused: 0x0C .*extended 0x0004"):
            _push(served, lab, (), allowed=(0xC037,))
        # A key, and one PSK suite allowed: that suite alone.
        _push(served, lab, ((b"line-7", key),), allowed=(0xC02B, 0x00A8))
        with SyncScanner("127.0.0.1", served.secure_port, security=originator, identify=False) as drive:
            assert drive.read(1, 1, 7) == "CENT"
        assert "(TLSv1.2, PSK-AES128-GCM-SHA256, PSK identity 'line-7')" in _accepted(caplog, "TLS connection")[-1]
        _reset(served)
        # A key, and no PSK suite allowed: the key is kept, no PSK handshake.
        _push(served, lab, ((b"line-7", key),), allowed=(0xC02B,))
        with pytest.raises(SecurityError, match="no cipher suite in common with the peer"):
            SyncScanner("127.0.0.1", served.secure_port, security=originator, timeout=5)
    finally:
        served.close()


def test_the_psk_suites_are_named_alike_in_the_object_and_the_handshake() -> None:
    from cipstack.security.declarations import AVAILABLE_CIPHER_SUITES, PSK_SUITE_NAMES
    from cipstack.security.psk import PSK_SUITES

    assert tuple(PSK_SUITE_NAMES.values()) == PSK_SUITES
    assert AVAILABLE_CIPHER_SUITES[-len(PSK_SUITES):] == (0xC037, 0xCCAC, 0x00A8, 0x00A9)


def test_a_key_written_over_the_wire_survives_a_restart_with_a_state_file(lab: Path, tmp_path: Path) -> None:
    key = os.urandom(32)
    originator = Credentials.load(_folder(tmp_path / "key", "line-7", key))
    settings = AdapterSettings(host="127.0.0.1", port=0, io_port=0, security_objects=True,
                               security_port=free_port(), state_path=tmp_path / "acg.json")
    served = Served(settings)
    try:
        _push(served, lab, ((b"line-7", key),))
    finally:
        served.close()
    kept = (tmp_path / "acg.json.security" / "configuration.json").read_text()
    assert key.hex() in kept   # in the 0600 file beside the state (test_security_objects checks the mode)
    again = Served(settings)
    try:
        wait_for(lambda: again.adapter.secure is not None and again.adapter.secure.server is not None
                 and again.adapter.secure.server.is_open, 10, "the kept configuration's listener")
        with SyncScanner("127.0.0.1", again.secure_port, security=originator, identify=False) as drive:
            assert drive.read(1, 1, 7) == "CENT"
    finally:
        again.close()


def test_a_device_configured_with_keys_alone_serves_the_psk_suites_alone(lab: Path, tmp_path: Path) -> None:
    from cipstack.security.attributes import PRE_SHARED_KEYS
    from cipstack.security.declarations import CIPHER_SUITES

    key = os.urandom(32)
    originator = Credentials.load(_folder(tmp_path / "key", "line-7", key))
    served = Served(AdapterSettings(host="127.0.0.1", port=0, io_port=0, security_objects=True,
                                    security_port=free_port()))
    try:
        with SyncScanner("127.0.0.1", served.adapter.port, identify=False) as plain:
            def status(service: int, attribute: int | None = None, data: bytes = b"") -> tuple[int, tuple[int, ...]]:
                reply = plain.request(service, 0x5E, 1, attribute, data, check=False)
                return reply.general_status, tuple(reply.extended_status)

            assert status(0x4B) == (0, ())                                             # Begin_Config
            assert status(0x10, 4, CIPHER_SUITES.encode((0xC02B,))) == (0, ())
            assert status(0x10, 5, PRE_SHARED_KEYS.encode(((b"line-7", key),))) == (0, ())
            assert status(0x4D) == (0x0C, (0x0002,))   # a key, no PSK suite allowed, no certificate
            assert status(0x10, 4, CIPHER_SUITES.encode((0xC037, 0x00A8))) == (0, ())
            assert status(0x4D) == (0, ())                                             # Apply_Config
        secure = served.adapter.secure
        assert secure is not None
        wait_for(lambda: secure.server is not None and secure.server.is_open, 10, "the TLS listener")
        with SyncScanner("127.0.0.1", served.secure_port, security=originator, identify=False) as drive:
            assert drive.read(1, 1, 7) == "CENT"
        with pytest.raises(SecurityError, match="no cipher suite in common with the peer"):
            SyncScanner("127.0.0.1", served.secure_port, security=Credentials.load(lab), timeout=5)
    finally:
        served.close()


def test_an_identity_of_128_octets_is_offered_whole(tmp_path: Path) -> None:
    # 128 octets: the longest the Pre-Shared Keys attribute takes (and psk.txt, MAX_PSK_IDENTITY).
    identity = "i" * 128
    folder = _folder(tmp_path / "long", identity, os.urandom(32))
    server = _serve(folder)
    try:
        with SyncScanner("127.0.0.1", server.secure_port, security=Credentials.load(folder)) as drive:
            assert drive.read(1, 1, 7) == "CENT"
        client = BlockingEncapsulationClient.connect_dtls("127.0.0.1", server.secure_port, 5.0,
                                                          Credentials.load(folder))
        client.close()
    finally:
        server.close()


def test_bindings_without_psk_are_one_security_error_line(psk_lab: Path) -> None:
    # A cryptography build whose OpenSSL bindings lack PSK (Cryptography_HAS_PSK false), in a process
    # of its own (the bindings are checked once per process).
    script = f"""
import OpenSSL._util as util
real = util.lib
class WithoutPsk:
    def __getattr__(self, name):
        return 0 if name == "Cryptography_HAS_PSK" else getattr(real, name)
util.lib = WithoutPsk()
from cipstack.errors import SecurityError
from cipstack.security import Credentials
try:
    Credentials.load({str(psk_lab)!r}).client_context()
except SecurityError as exc:
    print(exc)
"""
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert result.stdout == ("pre-shared keys: the OpenSSL bindings of this cryptography package have no PSK "
                             "functions (Cryptography_HAS_PSK)\n")


def test_the_dtls_port_follows_a_reset_and_the_keys_written_over_the_wire(psk_lab: Path, lab: Path,
                                                                          tmp_path: Path) -> None:
    from cipstack.errors import PeerUnreachable

    key = os.urandom(32)
    pushed = Credentials.load(_folder(tmp_path / "pushed", "line-7", key))
    folder = Credentials.load(psk_lab)
    served = _serve(psk_lab)
    try:
        dtls = served.adapter.dtls   # the folder's, the endpoint's until a Reset
        assert dtls is not None and served.adapter.secure is not None
        secure = served.adapter.secure
        port = dtls.port
        BlockingEncapsulationClient.connect_dtls("127.0.0.1", port, 5.0, folder).close()
        _reset(served)
        # Factory Default: the DTLS port is closed, as the TLS listener is.
        assert not dtls.is_open and secure.dtls is None
        with pytest.raises(PeerUnreachable):
            BlockingEncapsulationClient.connect_dtls("127.0.0.1", port, 1.0, folder)
        _push(served, lab, ((b"line-7", key),))
        wait_for(lambda: secure.dtls is not None and secure.dtls.is_open, 10, "the DTLS port with the configuration")
        assert secure.dtls is not None and secure.dtls.port == served.secure_port == port
        client = BlockingEncapsulationClient.connect_dtls("127.0.0.1", port, 5.0, pushed)
        with client:
            reply = client.perform(client.core.request(GET_ATTRIBUTE_SINGLE, request_path(1, 1, 7)))
            assert reply.data == b"\x04CENT"
        with pytest.raises(SecurityError, match="PSK identity 'cipstack-lab' unknown to the device"):
            BlockingEncapsulationClient.connect_dtls("127.0.0.1", port, 5.0, folder)
    finally:
        served.close()


def test_a_device_configured_from_factory_default_serves_dtls_with_the_keys(lab: Path, tmp_path: Path) -> None:
    key = os.urandom(32)
    pushed = Credentials.load(_folder(tmp_path / "pushed", "line-7", key))
    served = Served(AdapterSettings(host="127.0.0.1", port=0, io_port=0, security_objects=True,
                                    security_port=free_port()))
    try:
        secure = served.adapter.secure
        assert secure is not None and secure.dtls is None   # Factory Default: no DTLS port yet
        _push(served, lab, ((b"line-7", key),))
        wait_for(lambda: secure.dtls is not None and secure.dtls.is_open, 10, "the DTLS port with the configuration")
        dtls = secure.dtls
        assert dtls is not None
        with SyncScanner("127.0.0.1", served.secure_port, security=pushed) as scanner, \
                scanner.io_connection(output=21, input=71, rpi=0.010) as io:
            io.wait_input(lambda image: image.ready, timeout=10)
            wait_for(lambda: io.statistics()["received"] > 5, 10, "T->O data in the DTLS session")
        # The certificate pushed serves DTLS too.
        BlockingEncapsulationClient.connect_dtls("127.0.0.1", dtls.port, 5.0, Credentials.load(lab)).close()
        _reset(served)
        assert not dtls.is_open and secure.dtls is None
    finally:
        served.close()


def test_both_roles_write_psk_sessions_to_sslkeylogfile(psk_lab: Path, tmp_path: Path,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    device_log, originator_log = tmp_path / "device.keys", tmp_path / "originator.keys"
    monkeypatch.setenv("SSLKEYLOGFILE", str(device_log))
    server = _serve(psk_lab)   # the device's credentials read the variable when loaded
    try:
        monkeypatch.setenv("SSLKEYLOGFILE", str(originator_log))
        credentials = Credentials.load(psk_lab)
        with SyncScanner("127.0.0.1", server.secure_port, security=credentials) as drive:
            assert drive.read(1, 1, 7) == "CENT"
        BlockingEncapsulationClient.connect_dtls("127.0.0.1", server.secure_port, 5.0, credentials).close()
    finally:
        server.close()
    for path in (device_log, originator_log):
        lines = path.read_text().splitlines()
        # TLS 1.2 and DTLS 1.2: one CLIENT_RANDOM line (the master secret) per session.
        assert len([line for line in lines if line.startswith("CLIENT_RANDOM ")]) == 2, lines


@needs_tshark
def test_tshark_decrypts_a_psk_tls_session_with_the_key_log(psk_lab: Path, tmp_path: Path,
                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    assert TSHARK is not None
    keylog, capture = tmp_path / "keys.log", tmp_path / "tls.pcapng"
    monkeypatch.setenv("SSLKEYLOGFILE", str(keylog))
    server = _serve(psk_lab)
    port = server.secure_port
    dumpcap = None
    try:
        # -P -l: each packet is printed as it is captured: probes to a port of nothing until one shows
        # tell the test the capture is live before the handshake it must see.
        probe_port = free_port()
        dumpcap = subprocess.Popen([TSHARK, "-i", "lo", "-f", f"tcp port {port} or udp port {probe_port}",
                                    "-w", str(capture), "-a", "duration:60", "-P", "-l", "-q"],
                                   stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
        assert dumpcap.stdout is not None
        live = threading.Event()
        threading.Thread(target=lambda: (dumpcap.stdout.readline(), live.set()), daemon=True).start()   # type: ignore[union-attr]
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            for _ in range(200):
                probe.sendto(b"probe", ("127.0.0.1", probe_port))
                if live.wait(0.05) or dumpcap.poll() is not None:
                    break
        if not live.is_set():
            pytest.skip("tshark cannot capture on lo here")
        with SyncScanner("127.0.0.1", port, security=Credentials.load(psk_lab)) as drive:
            assert drive.read(1, 1, 7) == "CENT"
        time.sleep(0.5)   # what was sent reaches the capture before it stops
    finally:
        if dumpcap is not None:
            stop_process(dumpcap)
        server.close()
    fields = subprocess.run([TSHARK, "-r", str(capture), "-o", f"tls.keylog_file:{keylog}",
                             "-d", f"tcp.port=={port},tls", "-d", f"tls.port=={port},enip",
                             "-Y", "enip.command == 0x0065", "-T", "fields", "-e", "enip.command"],
                            capture_output=True, text=True, timeout=60, check=True)
    rows = [line for line in fields.stdout.splitlines() if line.strip()]
    # RegisterSession, request and reply, read out of the PSK suite's records.
    assert len(rows) >= 2, subprocess.run([TSHARK, "-r", str(capture)], capture_output=True, text=True).stdout


def _on_loop(served: Served, call: Any) -> Any:
    """``call()`` on the adapter's loop, as the control socket calls the faults."""
    async def run() -> Any:
        return call()

    return asyncio.run_coroutine_threadsafe(run(), served.loop).result(10)


def test_refuse_cipher_suite_takes_a_psk_suite_over_tls_and_dtls(psk_lab: Path,
                                                                caplog: pytest.LogCaptureFixture) -> None:
    served = _serve(psk_lab)
    port = served.secure_port
    offering = Credentials.load(psk_lab).offering("TLS_ECDHE_PSK_WITH_AES_128_CBC_SHA256")
    allowed = "the device allows ECDHE-PSK-CHACHA20-POLY1305, PSK-AES128-GCM-SHA256, PSK-AES256-GCM-SHA384"
    try:
        _on_loop(served, lambda: served.adapter.fault("refuse-cipher-suite", suite="ECDHE-PSK-AES128-CBC-SHA256"))
        with caplog.at_level("WARNING", logger="cipstack.security"):
            with pytest.raises(SecurityError) as refused:
                SyncScanner(f"127.0.0.1:{port}", security=offering, identify=False)
            assert str(refused.value) == (f"TLS with 127.0.0.1:{port} failed: no cipher suite in common with the "
                                          "peer (SSLV3_ALERT_HANDSHAKE_FAILURE): we offered "
                                          "ECDHE-PSK-AES128-CBC-SHA256")
            with pytest.raises(SecurityError) as refused:
                DtlsLink(offering, "127.0.0.1", port, 5.0)
            assert str(refused.value).endswith("no cipher suite in common with the peer (tls alert handshake "
                                               "failure): we offered ECDHE-PSK-AES128-CBC-SHA256")
            wait_for(lambda: len([r for r in caplog.records if allowed in r.getMessage()]) == 2, 10,
                     "the device's TLS and DTLS refusals")
        # One that offers every PSK suite agrees on another.
        with SyncScanner(f"127.0.0.1:{port}", security=Credentials.load(psk_lab), identify=False) as drive:
            assert drive.read(1, 1, 7) == "CENT"
        _on_loop(served, served.adapter.clear_faults)
        with SyncScanner(f"127.0.0.1:{port}", security=offering, identify=False) as drive:
            assert drive.read(1, 1, 7) == "CENT"
        DtlsLink(offering, "127.0.0.1", port, 5.0).close()
    finally:
        served.close()
