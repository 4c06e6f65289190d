"""CIP Security, phase 1: `cipstack security init`, the credentials folder, EtherNet/IP over TLS in
both roles, checked against the `openssl` binary as the independent peer (issue 48).

The adapter runs in a process of its own (`cipstack adapter --security DIR`), its log in a file the
tests read; ports come from `free_port()`."""

from __future__ import annotations

import asyncio
import contextlib
import datetime
import os
import shutil
import socket
import ssl
import stat
import struct
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import NamedTuple

import pytest

pytest.importorskip("cryptography", reason="the security extra (cryptography) is not installed")

from cipstack.cli import main
from cipstack.eip.originator.blocking import BlockingEncapsulationClient
from cipstack.errors import CipstackError, PeerUnreachable, SecurityError
from cipstack.scanner import Scanner, SyncScanner
from cipstack.security import Credentials
from cipstack.security.provisioning import init
from tests.ports import free_port
from tests.security_peers import OPENSSL, REGISTER_SESSION, needs_openssl
from tests.waiting import stop_process, wait_for, wait_until


class Device(NamedTuple):
    host: str
    port: int
    tls_port: int
    process: subprocess.Popen[bytes]
    log: Path


def _connectable(host: str, port: int) -> bool:
    try:
        socket.create_connection((host, port), timeout=0.2).close()
    except OSError:
        return False
    return True


def _start_adapter(folder: Path, log: Path, env: dict[str, str] | None = None) -> Device:
    port, tls_port = free_port(), free_port()
    with log.open("wb") as stderr:
        process = subprocess.Popen([sys.executable, "-m", "cipstack", "adapter", "--host", "127.0.0.1", "--port",
                                    str(port), "--io-port", "0", "--factory", "--quiet", "--security", str(folder),
                                    "--security-port", str(tls_port)],
                                   stdout=subprocess.DEVNULL, stderr=stderr, env=env)
    try:
        # Plain TCP accepts last (``Adapter.start``): once it does, the TLS port listens too.
        wait_for(lambda: process.poll() is not None or _connectable("127.0.0.1", port), 30, "the adapter to listen")
    except BaseException:
        process.kill()
        process.wait()
        raise
    if process.poll() is not None:
        pytest.fail(f"the adapter stopped: {log.read_text()}")
    return Device("127.0.0.1", port, tls_port, process, log)


def secured_adapter(folder: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Device]:
    """A module's secured adapter, from the ``folder`` of ``security init``, stopped after its tests."""
    started = _start_adapter(folder, tmp_path_factory.mktemp("adapter") / "adapter.log")
    try:
        yield started
    finally:
        stop_process(started.process)


@pytest.fixture(scope="module")
def device(lab: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Device]:
    yield from secured_adapter(lab, tmp_path_factory)


def _refusals(log: Path) -> list[str]:
    return [line for line in log.read_text().splitlines() if "refused" in line and "TLS" in line]


# -- security init and the credentials folder ---------------------------------------------------------
def test_init_writes_the_six_files_keys_private(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = tmp_path / "lab"
    assert main(["security", "init", str(folder)]) == 0
    names = {"ca.pem", "ca.key", "device.pem", "device.key", "client.pem", "client.key"}
    assert {path.name for path in folder.iterdir()} == names
    assert capsys.readouterr().out.split() == [str(folder / name) for name in
                                               ("ca.pem", "ca.key", "device.pem", "device.key", "client.pem",
                                                "client.key")]
    for key in ("ca.key", "device.key", "client.key"):
        assert stat.S_IMODE((folder / key).stat().st_mode) == 0o600
    credentials = Credentials.load(folder)
    assert credentials.device is not None and credentials.client is not None and credentials.ca is not None
    assert credentials.device.certificate.subject == "CN=cipstack device,O=cipstack lab"
    assert credentials.psk is None
    from cryptography import x509
    from cryptography.hazmat.primitives.asymmetric import ec

    certificate = x509.load_pem_x509_certificate((folder / "device.pem").read_bytes())
    key = certificate.public_key()
    assert isinstance(key, ec.EllipticCurvePublicKey) and key.curve.name == "secp256r1"


def test_init_refuses_to_overwrite_without_force(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = tmp_path / "lab"
    assert main(["security", "init", str(folder)]) == 0
    before = (folder / "ca.pem").read_bytes()
    capsys.readouterr()
    assert main(["security", "init", str(folder)]) == 1
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "already there (--force replaces them)" in error
    assert (folder / "ca.pem").read_bytes() == before
    assert main(["security", "init", str(folder), "--force"]) == 0
    assert (folder / "ca.pem").read_bytes() != before


def test_init_psk_writes_identity_and_hex_key(tmp_path: Path) -> None:
    folder = tmp_path / "psk"
    assert main(["security", "init", str(folder), "--psk-only"]) == 0
    assert [path.name for path in folder.iterdir()] == ["psk.txt"]
    assert stat.S_IMODE((folder / "psk.txt").stat().st_mode) == 0o600
    identity, key = (folder / "psk.txt").read_text().strip().split(":")
    assert identity == "cipstack-lab" and len(bytes.fromhex(key)) == 32
    credentials = Credentials.load(folder)
    assert credentials.psk is not None and credentials.psk.key == bytes.fromhex(key)
    assert credentials.ca is None and credentials.client is None   # a PSK-only originator (test_security_psk)
    with pytest.raises(SecurityError, match=r"no device\.pem and device\.key"):
        credentials.server_context()   # the standard library's context is the certificates' alone


def test_load_names_a_missing_folder_or_file(tmp_path: Path) -> None:
    with pytest.raises(SecurityError, match=r"no such folder \(make one with `cipstack security init"):
        Credentials.load(tmp_path / "nowhere")
    folder = tmp_path / "lab"
    init(folder)
    (folder / "client.key").unlink()
    with pytest.raises(SecurityError, match=r"client\.key: missing$"):
        Credentials.load(folder)
    (folder / "device.pem").write_text("not a certificate\n")
    with pytest.raises(SecurityError, match=r"device\.pem: not a PEM certificate$"):
        Credentials.load(folder)


def test_load_names_an_expired_certificate(tmp_path: Path) -> None:
    folder = tmp_path / "old"
    init(folder, days=1, now=datetime.datetime(2020, 1, 1, tzinfo=datetime.timezone.utc))
    with pytest.raises(SecurityError, match=r"device\.pem: certificate expired on 2020-01-01 23:55:00 UTC$"):
        Credentials.load(folder)


def test_adapter_with_a_broken_folder_says_one_line(tmp_path: Path) -> None:
    result = subprocess.run([sys.executable, "-m", "cipstack", "adapter", "--port", str(free_port()), "--io-port",
                             "0", "--factory", "--quiet", "--security", str(tmp_path / "nowhere")],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode != 0
    assert result.stderr.strip().count("\n") == 0, result.stderr
    assert "no such folder" in result.stderr


def test_a_taken_security_port_is_one_line(lab: Path) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", free_port()))
        taken.listen()
        port = taken.getsockname()[1]
        result = subprocess.run([sys.executable, "-m", "cipstack", "adapter", "--port", str(free_port()),
                                 "--io-port", "0", "--factory", "--quiet", "--security", str(lab),
                                 "--security-port", str(port)], capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    assert result.stderr == (f"cipstack adapter: cannot listen on TCP 127.0.0.1:{port} (EtherNet/IP over TLS, "
                             "--security-port): Address already in use\n")


# -- the target, from openssl s_client ---------------------------------------------------------------
def _s_client(device: Device, lab: Path, *extra: str, cert: bool = True, data: bytes = REGISTER_SESSION,
              timeout: float = 30) -> subprocess.CompletedProcess[bytes]:
    assert OPENSSL is not None
    command = [OPENSSL, "s_client", "-connect", f"{device.host}:{device.tls_port}", "-CAfile", str(lab / "ca.pem"),
               "-quiet", "-verify_return_error", *extra]
    if cert:
        command += ["-cert", str(lab / "client.pem"), "-key", str(lab / "client.key")]
    process = subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        assert process.stdin is not None and process.stdout is not None
        process.stdin.write(data)
        process.stdin.flush()
        reply = b""
        deadline = time.monotonic() + timeout
        while len(reply) < 28 and time.monotonic() < deadline and data:
            chunk = os.read(process.stdout.fileno(), 4096)
            if not chunk:
                break
            reply += chunk
        if len(reply) >= 28:
            process.terminate()   # -quiet implies -ign_eof: s_client stays until it is ended
        process.wait(timeout)
        assert process.stderr is not None
        stderr = process.stderr.read()
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
        for stream in (process.stdin, process.stdout, process.stderr):
            if stream is not None:
                stream.close()
    return subprocess.CompletedProcess(command, process.returncode, reply, stderr)


@needs_openssl
@pytest.mark.parametrize("version", ["-tls1_2", "-tls1_3"])
def test_openssl_s_client_registers_a_session(device: Device, lab: Path, version: str) -> None:
    result = _s_client(device, lab, version)
    reply = result.stdout
    assert len(reply) == 28, result.stderr
    command, length, session, status = struct.unpack_from("<HHII", reply)
    assert (command, length, status) == (0x0065, 4, 0) and session != 0
    assert reply[12:20] == b"cipstack" and reply[24:28] == bytes.fromhex("01000000")


@needs_openssl
def test_openssl_s_client_below_tls_1_2_is_refused(device: Device, lab: Path) -> None:
    # TLS 1.1 is not even offered by a default OpenSSL 3 (security level 1): ask for it explicitly.
    result = _s_client(device, lab, "-tls1_1", "-cipher", "DEFAULT@SECLEVEL=0")
    assert result.stdout == b""
    assert result.returncode != 0


# -- the originator, against openssl s_server --------------------------------------------------------
@needs_openssl
@pytest.mark.parametrize("version", ["-tls1_2", "-tls1_3"])
def test_originator_completes_a_handshake_with_openssl_s_server(lab: Path, version: str) -> None:
    assert OPENSSL is not None
    port = free_port()
    server = subprocess.Popen([OPENSSL, "s_server", "-accept", f"127.0.0.1:{port}", "-quiet",
                               "-cert", str(lab / "device.pem"), "-key", str(lab / "device.key"),
                               "-CAfile", str(lab / "ca.pem"), "-Verify", "1", "-verify_return_error", version],
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        wait_for(lambda: server.poll() is not None or _connectable("127.0.0.1", port), 30, "s_server to listen")
        credentials = Credentials.load(lab)
        sock = socket.create_connection(("127.0.0.1", port), timeout=10)
        tls = credentials.wrap_client(sock, "127.0.0.1", port)
        with tls:
            assert tls.version() == ("TLSv1.2" if version == "-tls1_2" else "TLSv1.3")
            tls.sendall(REGISTER_SESSION)
            assert server.stdout is not None
            received = b""
            deadline = time.monotonic() + 30
            while len(received) < 28 and time.monotonic() < deadline:
                chunk = os.read(server.stdout.fileno(), 4096)
                if not chunk:
                    break
                received += chunk
        assert received == REGISTER_SESSION
    finally:
        stop_process(server)


@needs_openssl
def test_originator_names_an_expired_device_certificate(tmp_path: Path) -> None:
    assert OPENSSL is not None
    folder = tmp_path / "old"
    then = datetime.datetime(2020, 1, 1, tzinfo=datetime.timezone.utc)
    init(folder, days=1, now=then)
    port = free_port()
    server = subprocess.Popen([OPENSSL, "s_server", "-accept", f"127.0.0.1:{port}", "-quiet",
                               "-cert", str(folder / "device.pem"), "-key", str(folder / "device.key")],
                              stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        wait_for(lambda: server.poll() is not None or _connectable("127.0.0.1", port), 30, "s_server to listen")
        credentials = Credentials.load(folder, now=then + datetime.timedelta(hours=1))
        with pytest.raises(SecurityError) as raised:
            BlockingEncapsulationClient.connect("127.0.0.1", port, timeout=10, security=credentials)
        assert str(raised.value) == (f"TLS with 127.0.0.1:{port} failed: certificate verify failed: "
                                     "certificate has expired")
    finally:
        stop_process(server)


@needs_openssl
def test_originator_names_no_cipher_suite_in_common(lab: Path) -> None:
    assert OPENSSL is not None
    port = free_port()
    # TLS 1.2 with RSA key exchange only: nothing an ECDSA P-256 certificate can serve, nothing we offer.
    server = subprocess.Popen([OPENSSL, "s_server", "-accept", f"127.0.0.1:{port}", "-quiet",
                               "-tls1_2", "-cipher", "AES128-SHA256", "-cert", str(lab / "device.pem"),
                               "-key", str(lab / "device.key")],
                              stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        wait_for(lambda: server.poll() is not None or _connectable("127.0.0.1", port), 30, "s_server to listen")
        with pytest.raises(SecurityError, match=r"failed: no cipher suite in common with the peer"):
            BlockingEncapsulationClient.connect("127.0.0.1", port, timeout=10, security=Credentials.load(lab))
    finally:
        stop_process(server)


# -- the scanner over TLS, and plain 44818 beside it --------------------------------------------------
def test_sync_scanner_reads_identity_over_tls_and_plain_still_serves(device: Device, lab: Path) -> None:
    credentials = Credentials.load(lab)
    with SyncScanner(f"{device.host}:{device.tls_port}", security=credentials) as secured, \
            SyncScanner(f"{device.host}:{device.port}") as plain:
        assert secured.read(1, 1, 7) == "CENT"
        assert plain.read(1, 1, 7) == "CENT"
        assert secured.read(1, 1, 1) == plain.read(1, 1, 1)


def test_sync_scanner_with_security_goes_to_2221_by_default(lab: Path) -> None:
    # Nothing listens on 127.0.0.3:2221 in a test (free_port never hands out 2221).
    with pytest.raises(PeerUnreachable, match=r"^cannot connect to 127\.0\.0\.3:2221: "):
        SyncScanner("127.0.0.3", security=Credentials.load(lab), timeout=2)


def test_wrong_ca_is_certificate_verify_failed(device: Device, other_lab: Path) -> None:
    with pytest.raises(SecurityError) as raised:
        SyncScanner(f"{device.host}:{device.tls_port}", security=Credentials.load(other_lab), timeout=10)
    # The device sends its chain (its certificate and the CA's): another CA's self-signed root in it.
    assert str(raised.value) == (f"TLS with {device.host}:{device.tls_port} failed: certificate verify failed: "
                                 "self-signed certificate in certificate chain")


async def test_asyncio_scanner_reads_identity_over_tls(device: Device, lab: Path) -> None:
    async with await Scanner.connect(f"{device.host}:{device.tls_port}", security=Credentials.load(lab)) as drive:
        assert await drive.read(1, 1, 7) == "CENT"


async def test_asyncio_scanner_names_a_wrong_ca(device: Device, other_lab: Path) -> None:
    with pytest.raises(SecurityError, match=r"failed: certificate verify failed: self-signed certificate in "):
        await Scanner.connect(f"{device.host}:{device.tls_port}", security=Credentials.load(other_lab), timeout=10)


@pytest.mark.parametrize("blocking", [True, False], ids=["blocking", "asyncio"])
async def test_both_scanners_name_a_plain_port_that_never_answers_the_handshake(blocking: bool, device: Device,
                                                                                lab: Path) -> None:
    # Plain 44818 takes the ClientHello for the start of an encapsulation header and waits for the rest.
    address = f"{device.host}:{device.port}"
    with pytest.raises(SecurityError) as raised:
        if blocking:
            await asyncio.to_thread(SyncScanner, address, security=Credentials.load(lab), timeout=1)
        else:
            await Scanner.connect(address, security=Credentials.load(lab), timeout=1)
    assert str(raised.value) == (f"TLS with {address} failed: no answer to the handshake within 1 s: a plain "
                                 "EtherNet/IP port (44818) answers no TLS; the device's TLS port is 2221 unless it "
                                 "was given another")
    # And a port where nothing listens is not taken for one.
    closed = free_port()
    with pytest.raises(PeerUnreachable, match=rf"^cannot connect to 127\.0\.0\.1:{closed}: "):
        await Scanner.connect(f"127.0.0.1:{closed}", security=Credentials.load(lab), timeout=1)


async def test_asyncio_scanner_names_a_client_certificate_the_device_refuses(device: Device, lab: Path,
                                                                             other_lab: Path,
                                                                             tmp_path: Path) -> None:
    mixed = Credentials.load(_mixed_folder(tmp_path, lab, other_lab))
    with pytest.raises(SecurityError, match=r"failed: the peer does not trust our certificate \(alert: unknown CA\)"):
        await Scanner.connect(f"{device.host}:{device.tls_port}", security=mixed, timeout=10)


# -- bad input on the device's side ------------------------------------------------------------------
def _mixed_folder(tmp_path: Path, lab: Path, other_lab: Path) -> Path:
    """Trusts the device (``lab``'s CA) but presents a client certificate of another CA."""
    folder = tmp_path / "mixed"
    folder.mkdir()
    shutil.copy(lab / "ca.pem", folder / "ca.pem")
    shutil.copy(other_lab / "client.pem", folder / "client.pem")
    shutil.copy(other_lab / "client.key", folder / "client.key")
    return folder


def _send_from(source: str, device: Device, data: bytes) -> bytes:
    """Connect from ``source``, send ``data``, read until the device closes."""
    with socket.create_connection((device.host, device.tls_port), timeout=15, source_address=(source, 0)) as sock:
        sock.sendall(data)
        answer = b""
        while True:
            try:
                chunk = sock.recv(4096)
            except ConnectionResetError:
                break
            if not chunk:
                break
            answer += chunk
    return answer


@needs_openssl
def test_bad_input_on_2221_is_refused_logged_once_per_source(tmp_path: Path, lab: Path, other_lab: Path) -> None:
    device = _start_adapter(lab, tmp_path / "adapter.log")
    try:
        credentials = Credentials.load(lab)
        # A TLS session opened before the bad input, used after it.
        with SyncScanner(f"{device.host}:{device.tls_port}", security=credentials) as kept:
            # Plain EtherNet/IP on the TLS port: refused with a TLS alert, never an encapsulation reply.
            answer = _send_from("127.0.0.1", device, REGISTER_SESSION)
            assert answer[:1] in (b"", b"\x15")   # nothing, or an alert record
            wait_for(lambda: len(_refusals(device.log)) == 1, 15, "the refusal line")
            # Garbage, a client with no certificate, a client certificate of another CA: from the same
            # source within 10 s, refused and counted, not logged again.
            _send_from("127.0.0.1", device, os.urandom(600))
            no_certificate = _s_client(device, lab, "-tls1_2", cert=False)
            assert no_certificate.stdout == b""
            with pytest.raises(SecurityError, match=r"failed: the peer does not trust our certificate"):
                SyncScanner(f"{device.host}:{device.tls_port}", security=Credentials.load(
                    _mixed_folder(tmp_path, lab, other_lab)), timeout=10)
            # Another source is logged on its own.
            _send_from("127.0.0.2", device, b"GET / HTTP/1.0\r\n\r\n")
            wait_for(lambda: len(_refusals(device.log)) == 2, 15, "the second source's refusal line")
            lines = _refusals(device.log)
            assert "TLS handshake from 127.0.0.1:" in lines[0] and "refused: " in lines[0]
            assert "TLS handshake from 127.0.0.2:" in lines[1]
            assert "Traceback" not in device.log.read_text()
            # Nothing else disturbed: the kept TLS session, a new one, and plain 44818.
            assert kept.read(1, 1, 7) == "CENT"
            with SyncScanner(f"{device.host}:{device.tls_port}", security=credentials) as fresh:
                assert fresh.read(1, 1, 7) == "CENT"
            with SyncScanner(f"{device.host}:{device.port}") as plain:
                assert plain.read(1, 1, 7) == "CENT"
        assert device.process.poll() is None
    finally:
        stop_process(device.process)


async def test_a_handshake_that_never_comes_is_closed_and_counted(lab: Path) -> None:
    import asyncio

    from cipstack.adapter import Adapter, AdapterSettings

    settings = AdapterSettings(port=0, io_port=0, security=lab, security_port=0)
    async with Adapter(settings) as adapter:
        tls = adapter.tls
        assert tls is not None
        tls.handshake_timeout = 0.5
        reader, writer = await asyncio.open_connection("127.0.0.1", tls.port)
        try:
            # Silence: closed once the handshake's time is up (a bound from the setting, with room).
            assert await asyncio.wait_for(reader.read(), 15) == b""
        finally:
            writer.close()
        assert tls.refused == 1
        assert tls.connections == set()


async def test_a_reply_fault_acts_on_tls_as_on_44818(lab: Path) -> None:
    """The TLS shell passes its replies through the same seam: ``delay-replies`` holds them too."""
    import asyncio

    from cipstack.adapter import Adapter, AdapterSettings

    async with Adapter(AdapterSettings(port=0, io_port=0, security=lab, security_port=0)) as adapter:
        assert adapter.tls is not None
        secured = f"127.0.0.1:{adapter.tls.port}"
        credentials = Credentials.load(lab)

        def timed_read() -> float:
            with SyncScanner(secured, security=credentials, identify=False) as drive:
                start = time.monotonic()
                assert drive.read(1, 1, 7) == "CENT"
                return time.monotonic() - start

        adapter.fault("delay-replies", by="400ms")
        assert await asyncio.to_thread(timed_read) >= 0.4
        adapter.clear_faults()
        assert await asyncio.to_thread(timed_read) < 5


async def test_pipelined_requests_and_a_close_notify_are_answered_then_closed(lab: Path) -> None:
    """A RegisterSession and a ListServices sealed in two records and sent in one write with the
    client's close_notify: both are answered, the adapter answers the close_notify with its own and
    closes, and the connection leaves the server's set (on the lane and on asyncio's loop alike)."""
    import asyncio

    from cipstack.adapter import Adapter, AdapterSettings

    async with Adapter(AdapterSettings(port=0, io_port=0, security=lab, security_port=0)) as adapter:
        tls = adapter.tls
        assert tls is not None
        context = Credentials.load(lab).client_context()

        def exchange() -> tuple[bytes, bytes]:
            with socket.create_connection(("127.0.0.1", tls.port), timeout=10) as sock:
                incoming, outgoing = ssl.MemoryBIO(), ssl.MemoryBIO()
                client = context.wrap_bio(incoming, outgoing)
                while True:
                    try:
                        client.do_handshake()
                        break
                    except ssl.SSLWantReadError:
                        sock.sendall(outgoing.read())
                        incoming.write(sock.recv(65536))
                client.write(REGISTER_SESSION)
                client.write(struct.pack("<HHII8sI", 0x0004, 0, 0, 0, b"services", 0))   # ListServices
                with contextlib.suppress(ssl.SSLWantReadError):   # the adapter's close_notify: not yet
                    client.unwrap()
                sock.sendall(outgoing.read())   # two records and the close_notify, in one write
                plain, notified = b"", False
                while data := sock.recv(65536):
                    incoming.write(data)
                    try:
                        while chunk := client.read(65536):
                            plain += chunk
                    except ssl.SSLWantReadError:
                        pass
                    except ssl.SSLZeroReturnError:   # the adapter's close_notify, before its FIN
                        notified = True
                return plain, notified

        plain, notified = await asyncio.to_thread(exchange)
        assert notified
        # RegisterSession's reply (28 bytes, status 0), then ListServices' (status 0, "Communications").
        assert struct.unpack_from("<HH", plain) == (0x0065, 4) and struct.unpack_from("<I", plain, 8) == (0,)
        assert struct.unpack_from("<H", plain, 28) == (0x0004,) and struct.unpack_from("<I", plain, 36) == (0,)
        assert plain[40:48] == b"services" and b"Communications" in plain[52:]
        await wait_until(lambda: not tls.connections, timeout=5, what="the connection closed")


def test_plain_scanner_on_the_tls_port_gets_one_line(device: Device) -> None:
    with pytest.raises(CipstackError) as raised:
        SyncScanner(f"{device.host}:{device.tls_port}", timeout=5)
    assert "\n" not in str(raised.value)


# -- SSLKEYLOGFILE -------------------------------------------------------------------------------------
def test_sslkeylogfile_is_written_by_both_roles(tmp_path: Path, lab: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    device_keys, client_keys = tmp_path / "device.keys", tmp_path / "client.keys"
    device = _start_adapter(lab, tmp_path / "adapter.log", env={**os.environ, "SSLKEYLOGFILE": str(device_keys)})
    try:
        monkeypatch.setenv("SSLKEYLOGFILE", str(client_keys))
        credentials = Credentials.load(lab)
        assert credentials.keylog == str(client_keys)
        with SyncScanner(f"{device.host}:{device.tls_port}", security=credentials) as secured:
            assert secured.read(1, 1, 7) == "CENT"
        wait_for(lambda: device_keys.exists() and "TRAFFIC_SECRET" in device_keys.read_text(), 15, "the device's keys")
        for keys in (device_keys, client_keys):
            labels = {line.split()[0] for line in keys.read_text().splitlines() if line and not line.startswith("#")}
            assert {"CLIENT_HANDSHAKE_TRAFFIC_SECRET", "CLIENT_TRAFFIC_SECRET_0"} <= labels, keys
        # TLS 1.2 logs CLIENT_RANDOM.
        context = credentials.client_context()
        context.maximum_version = ssl.TLSVersion.TLSv1_2
        with context.wrap_socket(socket.create_connection((device.host, device.tls_port), timeout=10)) as tls:
            tls.sendall(REGISTER_SESSION)
            assert len(tls.recv(64)) == 28
        assert "CLIENT_RANDOM " in client_keys.read_text()
    finally:
        stop_process(device.process)


# -- a security-free emulator and scanner pay nothing ------------------------------------------------
def test_plain_adapter_and_scanner_import_nothing_of_security() -> None:
    script = ("import asyncio, sys\n"
              "from cipstack.adapter import Adapter, AdapterSettings\n"
              "from cipstack.scanner import SyncScanner\n"
              "async def main():\n"
              "    async with Adapter(AdapterSettings(port=0, io_port=0)) as adapter:\n"
              "        def read():\n"
              "            with SyncScanner(f'127.0.0.1:{adapter.port}') as drive:\n"
              "                assert drive.read(1, 1, 7) == 'CENT'\n"
              "        await asyncio.to_thread(read)\n"
              "asyncio.run(main())\n"
              "print(sorted(m for m in sys.modules\n"
              "             if m.startswith(('cipstack.security', 'cryptography', 'OpenSSL'))))\n")
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "[]"
