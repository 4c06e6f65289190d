"""The EtherNet/IP Security object's attributes acted on (issue 48): Certificate Revocation List (8),
Verify Client Certificate (9), Send Certificate Chain (10), Check Expiration (11) and DTLS Timeout (15),
each written over the wire in a configuration session (Begin_Config, Set, Apply_Config) and then met by
the next TLS and DTLS handshakes, with its opposite value.

The adapter runs in the test's event loop on ports the system picks; the peers are OpenSSL's own client
(``openssl s_client``), Python's ``ssl`` and the library's originator, over real sockets on loopback."""

from __future__ import annotations

import asyncio
import datetime
import socket
import ssl
import subprocess
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("OpenSSL", reason="the security extra (pyOpenSSL) is not installed")

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.cip.types import BOOL, UINT
from cipstack.errors import SecurityError
from cipstack.scanner import SyncScanner
from cipstack.security import Credentials
from cipstack.security.push import configure
from tests.ports import free_port
from tests.security_peers import OPENSSL, REGISTER_SESSION, needs_openssl

VERIFY_CLIENT, SEND_CHAIN, CHECK_EXPIRATION, DTLS_TIMEOUT = 9, 10, 11, 15


async def configured(lab: Path, revocation_list: bytes = b"", trusted_identities: bytes = b"",
                     state_path: Path | None = None, **attributes: bytes) -> Adapter:
    """A device started in Factory Default, configured over the wire with the lab CA and the EtherNet/IP
    Security attributes given (``a<id>=data``), and the CRL downloaded, its TLS and DTLS listeners in
    place; ``state_path``: where it keeps its state (and its configuration beside it)."""
    settings = AdapterSettings(port=0, io_port=0, security_port=free_port(), security_objects=True,
                               state_path=state_path)
    adapter = Adapter(settings)
    await adapter.start()
    written = {int(name[1:]): data for name, data in attributes.items()}
    verify = bool(written.pop(VERIFY_CLIENT, b"\x01")[0])

    def push() -> None:
        with SyncScanner(f"127.0.0.1:{adapter.port}", identify=False) as plain:
            def request(service: int, class_id: int, instance: int, attribute: int | None,
                        data: bytes) -> tuple[int, Any, bytes]:
                reply = plain.request(service, class_id, instance, attribute, data, check=False)
                return reply.general_status, reply.extended_status, reply.data
            configure(request, lab, verify_client=verify, attributes=written, revocation_list=revocation_list,
                      trusted_identities=trusted_identities)

    try:
        await asyncio.to_thread(push)
    except BaseException:
        await adapter.close()
        raise
    assert adapter.secure is not None
    for _ in range(1000):
        if adapter.secure.reloads and adapter.secure.dtls is not None and adapter.secure.dtls.is_open:
            return adapter
        await asyncio.sleep(0.01)
    raise AssertionError("the configuration's listeners were not put in place")


def s_client(port: int, *options: str, dtls: bool = False) -> tuple[int, str]:
    """``openssl s_client`` against the device's TLS (or DTLS) port: its exit status and its words; it
    ends when the handshake does (stdin is empty)."""
    assert OPENSSL is not None
    version = "-dtls1_2" if dtls else "-tls1_2"
    done = subprocess.run([OPENSSL, "s_client", "-connect", f"127.0.0.1:{port}", version, *options],
                          input=b"", capture_output=True, timeout=30, check=False)
    return done.returncode, (done.stdout + done.stderr).decode(errors="replace")


def lab_client(lab: Path, folder: Path, name: str = "expired.pem", expired: bool = True,
               common_name: str = "") -> tuple[Path, int]:
    """The lab client's key in another certificate of the lab CA (by default one whose validity ended
    yesterday; ``common_name``: another subject than the lab client's): its file and serial number."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization

    ca = x509.load_pem_x509_certificate((lab / "ca.pem").read_bytes())
    ca_key = serialization.load_pem_private_key((lab / "ca.key").read_bytes(), password=None)
    key = serialization.load_pem_private_key((lab / "client.key").read_bytes(), password=None)
    now = datetime.datetime.now(datetime.timezone.utc)
    certificate = (x509.CertificateBuilder()
                   .subject_name(x509.Name([x509.NameAttribute(x509.NameOID.COMMON_NAME, common_name)]) if common_name
                                 else x509.load_pem_x509_certificate((lab / "client.pem").read_bytes()).subject)
                   .issuer_name(ca.subject).public_key(key.public_key())  # type: ignore[arg-type]  # the lab's keys are EC, which the builder takes
                   .serial_number(x509.random_serial_number())
                   .not_valid_before(now - datetime.timedelta(days=10))
                   .not_valid_after(now + datetime.timedelta(days=-1 if expired else 10))
                   .sign(ca_key, hashes.SHA256()))  # type: ignore[arg-type]  # the lab CA's key is EC
    path = folder / name
    path.write_bytes(certificate.public_bytes(serialization.Encoding.PEM))
    return path, certificate.serial_number


def revocation_list(lab: Path, *serials: int) -> bytes:
    """A CRL of the lab CA revoking ``serials`` (PEM)."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization

    ca = x509.load_pem_x509_certificate((lab / "ca.pem").read_bytes())
    ca_key = serialization.load_pem_private_key((lab / "ca.key").read_bytes(), password=None)
    now = datetime.datetime.now(datetime.timezone.utc)
    builder = (x509.CertificateRevocationListBuilder().issuer_name(ca.subject).last_update(now)
               .next_update(now + datetime.timedelta(days=7)))
    for serial in serials:
        builder = builder.add_revoked_certificate(
            x509.RevokedCertificateBuilder().serial_number(serial).revocation_date(now).build())
    crl = builder.sign(ca_key, hashes.SHA256())  # type: ignore[arg-type]  # the lab CA's key is EC
    return crl.public_bytes(serialization.Encoding.PEM)


def register_over_tls(lab: Path, port: int, certificate: Path) -> bytes:
    """RegisterSession over TLS 1.2 from Python's ``ssl`` presenting ``certificate``: the reply's 28
    octets (an ``ssl.SSLError`` when the device refuses the handshake)."""
    context = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
    context.check_hostname = False
    context.maximum_version = ssl.TLSVersion.TLSv1_2
    context.load_verify_locations(lab / "ca.pem")
    context.load_cert_chain(certificate, lab / "client.key")
    with socket.create_connection(("127.0.0.1", port), timeout=10) as sock, context.wrap_socket(sock) as tls:
        tls.sendall(REGISTER_SESSION)
        reply = b""
        while len(reply) < 28:
            chunk = tls.recv(28 - len(reply))
            if not chunk:
                break
            reply += chunk
        return reply


# -- Verify Client Certificate (9) -------------------------------------------------------------------
@needs_openssl
@pytest.mark.parametrize("verify", [1, 0])
async def test_verify_client_certificate_decides_whether_a_client_without_one_is_served(lab: Path,
                                                                                       verify: int) -> None:
    adapter = await configured(lab, a9=BOOL.encode(verify))
    try:
        assert adapter.secure is not None and adapter.secure.server is not None
        port = adapter.secure.server.port
        # Our originator, with its certificate, is served either way.
        with_certificate = await asyncio.to_thread(
            lambda: SyncScanner(f"127.0.0.1:{port}", security=Credentials.load(lab), identify=False).read(1, 1, 7))
        assert with_certificate == "CENT"
        for dtls in (False, True):
            status, words = await asyncio.to_thread(lambda d=dtls: s_client(port, "-CAfile", str(lab / "ca.pem"),
                                                                           dtls=d))
            if verify:   # no certificate: refused at the handshake
                assert status != 0, words
                assert "Cipher is (NONE)" in words or "alert" in words, words
            else:
                assert status == 0, words
                assert "Verify return code: 0 (ok)" in words, words
    finally:
        await adapter.close()


# -- Check Expiration (11) ---------------------------------------------------------------------------
@needs_openssl
@pytest.mark.parametrize("check", [1, 0])
async def test_check_expiration_decides_whether_an_expired_client_certificate_is_served(
        lab: Path, tmp_path: Path, check: int, caplog: pytest.LogCaptureFixture) -> None:
    expired, _ = lab_client(lab, tmp_path)
    adapter = await configured(lab, a11=BOOL.encode(check))
    try:
        assert adapter.secure is not None and adapter.secure.server is not None
        port = adapter.secure.server.port
        client = ("-cert", str(expired), "-key", str(lab / "client.key"), "-CAfile", str(lab / "ca.pem"))
        if check:
            with pytest.raises(ssl.SSLError):
                await asyncio.to_thread(register_over_tls, lab, port, expired)
            assert any("certificate has expired" in r.getMessage() or "certificate expired" in r.getMessage()
                       for r in caplog.records), [r.getMessage() for r in caplog.records]
            status, words = await asyncio.to_thread(lambda: s_client(port, *client, dtls=True))
            assert status != 0, words
        else:
            reply = await asyncio.to_thread(register_over_tls, lab, port, expired)
            assert reply[:2] == b"\x65\x00" and reply[8:12] == bytes(4)      # RegisterSession, status 0
            status, words = await asyncio.to_thread(lambda: s_client(port, *client, dtls=True))
            assert status == 0 and "Cipher is ECDHE" in words, words
        # A client certificate in its validity is served either way.
        reply = await asyncio.to_thread(register_over_tls, lab, port, lab / "client.pem")
        assert reply[8:12] == bytes(4)
    finally:
        await adapter.close()


# -- Send Certificate Chain (10) ---------------------------------------------------------------------
@needs_openssl
@pytest.mark.parametrize("chain", [1, 0])
async def test_send_certificate_chain_decides_what_the_handshake_carries(lab: Path, chain: int) -> None:
    adapter = await configured(lab, a10=BOOL.encode(chain))
    try:
        assert adapter.secure is not None and adapter.secure.server is not None
        port = adapter.secure.server.port
        client = ("-cert", str(lab / "client.pem"), "-key", str(lab / "client.key"), "-CAfile", str(lab / "ca.pem"),
                  "-showcerts")
        for dtls in (False, True):
            status, words = await asyncio.to_thread(lambda d=dtls: s_client(port, *client, dtls=d))
            assert status == 0, words
            assert words.count("-----BEGIN CERTIFICATE-----") == (2 if chain else 1), words
            assert ("1 s:O = cipstack lab" in words) == bool(chain), words     # the CA, second in the chain
            assert "Verify return code: 0 (ok)" in words, words               # the CA file completes it
    finally:
        await adapter.close()


def test_a_device_started_with_a_folder_shows_what_its_listeners_do(lab: Path) -> None:
    from cipstack.security.endpoint import configuration_of

    shown = configuration_of(Credentials.load(lab))
    assert (shown.verify_client, shown.send_chain, shown.check_expiration) == (1, 1, 1)


# -- DTLS Timeout (15) -------------------------------------------------------------------------------
@pytest.mark.parametrize("seconds", [1, None])
async def test_dtls_timeout_is_the_idle_timeout_of_the_dtls_port(lab: Path, seconds: int | None) -> None:
    attributes = {"a15": UINT.encode(seconds)} if seconds is not None else {}
    adapter = await configured(lab, **attributes)
    try:
        assert adapter.secure is not None and adapter.secure.dtls is not None
        dtls = adapter.secure.dtls
        assert dtls.idle_timeout == (seconds or 12)
        if seconds is None:
            return
        port = dtls.port
        link = await asyncio.to_thread(Credentials.load(lab).datagram_link, "127.0.0.1", port, 10.0)
        try:
            for _ in range(200):
                if dtls.sessions:
                    break
                await asyncio.sleep(0.01)
            assert len(dtls.sessions) == 1
            for _ in range(1000):            # closed once it has been idle for the attribute's second
                if not dtls.sessions:
                    break
                await asyncio.sleep(0.01)
            assert not dtls.sessions
        finally:
            await asyncio.to_thread(link.close)
    finally:
        await adapter.close()


# -- Certificate Revocation List (8) -----------------------------------------------------------------
@needs_openssl
@pytest.mark.parametrize("revoke", [True, False])
async def test_a_client_certificate_the_crl_lists_is_refused(lab: Path, tmp_path: Path, revoke: bool,
                                                            caplog: pytest.LogCaptureFixture) -> None:
    revoked, serial = lab_client(lab, tmp_path, "revoked.pem", expired=False)
    kept, _ = lab_client(lab, tmp_path, "kept.pem", expired=False)
    adapter = await configured(lab, revocation_list=revocation_list(lab, serial) if revoke else b"")
    try:
        assert adapter.secure is not None and adapter.secure.server is not None
        port = adapter.secure.server.port
        client = ("-cert", str(revoked), "-key", str(lab / "client.key"), "-CAfile", str(lab / "ca.pem"))
        if revoke:
            for _ in range(2):
                with pytest.raises(ssl.SSLError):
                    await asyncio.to_thread(register_over_tls, lab, port, revoked)
            lines = [r.getMessage() for r in caplog.records if "refused" in r.getMessage()]
            assert len(lines) == 1 and "certificate revoked" in lines[0], lines   # once per source per 10 s
            status, words = await asyncio.to_thread(lambda: s_client(port, *client, dtls=True))
            assert status != 0, words
            assert any(r.getMessage().startswith("DTLS handshake") and "certificate revoked" in r.getMessage()
                       for r in caplog.records)
        else:
            assert (await asyncio.to_thread(register_over_tls, lab, port, revoked))[8:12] == bytes(4)
            status, words = await asyncio.to_thread(lambda: s_client(port, *client, dtls=True))
            assert status == 0, words
        # A certificate the CRL does not list is served either way.
        assert (await asyncio.to_thread(register_over_tls, lab, port, kept))[8:12] == bytes(4)
    finally:
        await adapter.close()


async def test_a_restarted_device_keeps_its_crl_and_identities(lab: Path, tmp_path: Path) -> None:
    revoked, serial = lab_client(lab, tmp_path, "revoked.pem", expired=False)
    stranger, _ = lab_client(lab, tmp_path, "stranger.pem", expired=False, common_name="plc-9")
    adapter = await configured(lab, revocation_list=revocation_list(lab, serial),
                               trusted_identities=(lab / "client.pem").read_bytes() + revoked.read_bytes(),
                               state_path=tmp_path / "acg.json", a15=UINT.encode(5))
    settings = adapter.settings
    await adapter.close()
    async with Adapter(settings) as again:
        assert again.secure is not None
        for _ in range(1000):
            if again.secure.server is not None and again.secure.server.is_open and again.secure.dtls is not None:
                break
            await asyncio.sleep(0.01)
        assert again.secure.server is not None and again.secure.dtls is not None
        assert again.secure.dtls.idle_timeout == 5
        port = again.secure.server.port
        with pytest.raises(ssl.SSLError):                    # listed in the identities, but revoked
            await asyncio.to_thread(register_over_tls, lab, port, revoked)
        with pytest.raises(ssl.SSLError):                    # not revoked, but not listed
            await asyncio.to_thread(register_over_tls, lab, port, stranger)
        assert (await asyncio.to_thread(register_over_tls, lab, port, lab / "client.pem"))[8:12] == bytes(4)


async def test_apply_config_refuses_a_crl_path_without_a_crl_of_the_ca(lab: Path, other_lab: Path) -> None:
    with pytest.raises(SecurityError, match="Apply_Config refused"):
        await configured(lab, revocation_list=revocation_list(other_lab))


# -- Trusted Identities (12) -------------------------------------------------------------------------
@pytest.mark.parametrize("listed", [True, False])
async def test_trusted_identities_serve_only_the_clients_they_name(lab: Path, tmp_path: Path, listed: bool,
                                                                  caplog: pytest.LogCaptureFixture) -> None:
    stranger, _ = lab_client(lab, tmp_path, "stranger.pem", expired=False, common_name="plc-9")
    identities = (lab / "client.pem").read_bytes() if listed else b""
    adapter = await configured(lab, trusted_identities=identities)
    try:
        assert adapter.secure is not None and adapter.secure.server is not None
        port = adapter.secure.server.port
        # The lab client is served: it is listed, or no identity is.
        assert await asyncio.to_thread(
            lambda: SyncScanner(f"127.0.0.1:{port}", security=Credentials.load(lab), identify=False).read(1, 1, 7)) \
            == "CENT"
        if listed:   # a certificate of the same CA, another subject: refused
            with pytest.raises(ssl.SSLError):
                await asyncio.to_thread(register_over_tls, lab, port, stranger)
            lines = [r.getMessage() for r in caplog.records if "refused" in r.getMessage()]
            assert len(lines) == 1 and "CN=plc-9 is not one of the Trusted Identities" in lines[0], lines
            with pytest.raises(SecurityError):     # and over DTLS
                await asyncio.to_thread(_dtls_with, lab, tmp_path, stranger, port)
        else:
            assert (await asyncio.to_thread(register_over_tls, lab, port, stranger))[8:12] == bytes(4)
        await asyncio.to_thread(_dtls_with, lab, tmp_path, lab / "client.pem", port)
    finally:
        await adapter.close()


def _dtls_with(lab: Path, folder: Path, certificate: Path, port: int) -> None:
    """A DTLS session from our originator presenting ``certificate`` (the lab client's key): the handshake,
    then closed; ``SecurityError`` when the device refuses it."""
    import shutil

    own = folder / f"as-{certificate.stem}"
    own.mkdir(exist_ok=True)
    for name in ("ca.pem", "client.key"):
        shutil.copy(lab / name, own / name)
    shutil.copy(certificate, own / "client.pem")
    Credentials.load(own).datagram_link("127.0.0.1", port, 10.0).close()


# -- what a Set or a download the device cannot take gets ----------------------------------------------
async def test_paths_and_files_the_device_cannot_take_are_refused_and_change_nothing(lab: Path) -> None:
    from cipstack.objects.file import FileTransferError, write_file
    from cipstack.security.attributes import OBJECT_PATH, PATH_LIST

    settings = AdapterSettings(port=0, io_port=0, security_port=free_port(), security_objects=True)
    async with Adapter(settings) as adapter:
        def attempt() -> None:
            with SyncScanner(f"127.0.0.1:{adapter.port}", identify=False) as plain:
                def status(service: int, class_id: int, instance: int, attribute: int | None,
                           data: bytes = b"") -> int:
                    return plain.request(service, class_id, instance, attribute, data, check=False).general_status

                def file(instance: int) -> Any:
                    def request(service: int, data: bytes) -> tuple[int, bytes]:
                        reply = plain.request(service, 0x37, instance, None, data, check=False)
                        return reply.general_status, reply.data
                    return request

                assert status(0x4B, 0x5E, 1, None) == 0                                        # Begin_Config
                assert status(0x10, 0x5E, 1, 8, OBJECT_PATH.encode((0x37, 0xCA))) == 0x09      # not the CRL's file
                assert status(0x10, 0x5E, 1, 12, PATH_LIST.encode(((0x5F, 1),))) == 0x09      # not the identities'
                assert status(0x10, 0x5E, 1, 15, UINT.encode(0)) == 0x09                       # 1 s at least
                for instance in (0xCC, 0xCD):
                    with pytest.raises(FileTransferError):
                        write_file(file(instance), b"no certificate, no CRL", name="x.pem")
                reply = plain.request(0x0E, 0x5E, 1, 8, check=False)
                assert (reply.general_status, reply.data) == (0, b"\x00")                      # still none
                reply = plain.request(0x0E, 0x5E, 1, 12, check=False)
                assert (reply.general_status, reply.data) == (0, b"\x00")
                assert status(0x10, 0x5E, 1, 8, OBJECT_PATH.encode((0x37, 0xCC))) == 0        # its own file
                assert status(0x4E, 0x5E, 1, None) == 0                                        # Abort_Config

        await asyncio.to_thread(attempt)


# -- the command line --------------------------------------------------------------------------------
async def test_security_configure_sets_the_attributes_and_pushes_the_folders_crl(
        lab: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import shutil

    from cipstack.cli import main

    folder = tmp_path / "lab"
    shutil.copytree(lab, folder)
    revoked, serial = lab_client(lab, tmp_path, "revoked.pem", expired=False)
    (folder / "crl.pem").write_bytes(revocation_list(lab, serial))
    settings = AdapterSettings(port=0, io_port=0, security_port=free_port(), security_objects=True)
    async with Adapter(settings) as adapter:
        code = await asyncio.to_thread(main, [
            "security", "configure", f"127.0.0.1:{adapter.port}", "--security", str(folder), "--security-port",
            str(settings.security_port), "--check-expiration", "--send-chain", "--dtls-timeout", "7"])
        out = capsys.readouterr().out
        assert code == 0, out
        assert ("download Certificate Revocation List, Set Certificate Revocation List, Set Check Expiration, "
                "Set Send Certificate Chain, Set DTLS Timeout, Verify_Certificate, Apply_Config)") in out, out
        assert adapter.configurator is not None
        active = adapter.configurator.active
        assert (active.check_expiration, active.send_chain, active.dtls_timeout) == (1, 1, 7)
        assert active.revocation_list == (0x37, 0xCC)
        with pytest.raises(ssl.SSLError):
            await asyncio.to_thread(register_over_tls, lab, settings.security_port, revoked)
        code = await asyncio.to_thread(main, ["security", "configure", f"127.0.0.1:{adapter.port}", "--security",
                                              str(folder), "--dtls-timeout", "0"])
        assert code != 0
        assert capsys.readouterr().err.strip().splitlines() == [
            "cipstack security: --dtls-timeout 0: 1 to 65535 seconds"]
