"""CIP Security's three objects served by the adapter (0x5D, 0x5E, 0x5F), the configuration session and
its timer, the push-model configuration over the wire (`cipstack security configure`), `--secure-only`,
and what a device does with bad or hostile requests to them (issue 48).

The adapter runs in the test's event loop on ports the system picks; the clients are the library's
blocking scanner in a thread, real sockets on loopback."""

from __future__ import annotations

import asyncio
import logging
import struct
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("cryptography", reason="the security extra (cryptography) is not installed")

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.cip.types import SHORT_STRING
from cipstack.cli import main
from cipstack.errors import SecurityError
from cipstack.objects.file import FileTransferError, read_file, write_file
from cipstack.scanner import SyncScanner
from cipstack.security import Credentials
from cipstack.security.attributes import PATH_LIST, PRE_SHARED_KEYS
from cipstack.security.certificates import pem
from cipstack.security.configuration import Configurator
from cipstack.security.declarations import CIPHER_SUITES, SecurityState
from cipstack.security.provisioning import sign_csr
from cipstack.security.push import configure
from tests.ports import free_port

GET, SET, GET_ALL, RESET = 0x0E, 0x10, 0x01, 0x05
BEGIN, KICK, APPLY, ABORT = 0x4B, 0x4C, 0x4D, 0x4E
CREATE_CSR, VERIFY = 0x4B, 0x4C
EIP_SECURITY, CERTIFICATES, CIP_SECURITY = 0x5E, 0x5F, 0x5D
#: The File object instances of the CSR, the device certificate and the CA certificate, and their paths
#: as the objects give them (size in words, then 20 37 24 NN).
CSR_FILE, DEVICE_FILE, CA_FILE = 0xC9, 0xCA, 0xCB
#: Available (and by default Allowed) Cipher Suites as the wire carries them: the certificate suites,
#: then the pre-shared key suites.
AVAILABLE = bytes.fromhex("07" "C023" "C02B" "C02C" "C037" "CCAC" "00A8" "00A9")
CSR_PATH, DEVICE_PATH, CA_PATH = (bytes((2, 0x20, 0x37, 0x24, n)) for n in (CSR_FILE, DEVICE_FILE, CA_FILE))




class Client:
    """One plain EtherNet/IP connection (one session), raw requests in, (status, extended, data) out."""

    def __init__(self, address: str, **options: Any) -> None:
        self.scanner = SyncScanner(address, identify=False, **options)

    def __call__(self, service: int, class_id: int, instance: int, attribute: int | None = None,
                 data: bytes = b"") -> tuple[int, tuple[int, ...], bytes]:
        reply = self.scanner.request(service, class_id, instance, attribute, data, check=False)
        return reply.general_status, reply.extended_status, reply.data

    def status(self, *request: Any) -> int:
        return self(*request)[0]

    def _file(self, instance: int) -> Callable[[int, bytes], tuple[int, bytes]]:
        def request(service: int, data: bytes) -> tuple[int, bytes]:
            status, _, reply = self(service, 0x37, instance, None, data)
            return status, reply
        return request

    def upload(self, instance: int) -> bytes:
        """A File object instance's content, read as a configuration tool reads it."""
        return read_file(self._file(instance))

    def download(self, instance: int, data: bytes) -> None:
        """Download ``data`` into a File object instance (``FileTransferError`` when refused)."""
        write_file(self._file(instance), data)

    def close(self) -> None:
        self.scanner.close()


async def run(function: Callable[..., Any], *args: Any) -> Any:
    return await asyncio.to_thread(function, *args)


def _settings(**changes: Any) -> AdapterSettings:
    return AdapterSettings(**{"port": 0, "io_port": 0, "security_port": free_port(), "security_objects": True,
                              **changes})


def _csr_request(*fields: str) -> bytes:
    values = list(fields) + [""] * (9 - len(fields))
    return b"".join(SHORT_STRING.encode(value) for value in values)


# -- the objects in factory default ---------------------------------------------------------------------
@pytest.mark.parametrize("profile", ["acg", "mx2", "rx"])
async def test_factory_default_objects_read_as_declared(profile: str) -> None:
    async with Adapter(_settings(profile=profile)) as adapter:
        def read() -> None:
            client = Client(f"127.0.0.1:{adapter.port}")
            try:
                assert client(GET, EIP_SECURITY, 1, 1) == (0, (), b"\x00")              # Factory Default
                assert client(GET, EIP_SECURITY, 1, 3) == (0, (), AVAILABLE)
                assert client(GET, EIP_SECURITY, 1, 15) == (0, (), struct.pack("<H", 12))   # DTLS Timeout
                assert client(GET, EIP_SECURITY, 1, 13) == (0, (), b"\x01")             # Pull Model Enable
                assert client(GET, EIP_SECURITY, 1, 6) == (0, (), b"\x00")              # no active certificate
                assert client.status(GET, EIP_SECURITY, 1, 5) == 0x14                   # PSKs: never read back
                assert client.status(GET, EIP_SECURITY, 1, 17) == 0x14
                assert client.status(0x33, EIP_SECURITY, 1) == 0x08
                assert client.status(GET, EIP_SECURITY, 2, 1) == 0x05
                assert client(GET, CIP_SECURITY, 1, 1) == (0, (), b"\x00")
                assert client(GET, CIP_SECURITY, 1, 2) == (0, (), b"\x02\x00")           # Confidentiality Profile
                assert client(GET, CIP_SECURITY, 1, 3) == (0, (), b"\x00\x00")
                assert client(GET, CERTIFICATES, 1, 1) == (0, (), SHORT_STRING.encode("Default Device Certificate"))
                assert client(GET, CERTIFICATES, 1, 3) == (0, (), b"\x00" + DEVICE_PATH)   # not verified, its file
                assert client(GET, CERTIFICATES, 1, 4) == (0, (), b"\x00" + CA_PATH)
                assert client.upload(DEVICE_FILE) == b""                              # an empty file yet
                assert client(GET, CERTIFICATES, 0, 8) == (0, (), b"\x01\x00\x00\x00")  # push model
                # A Set outside a configuration session: object state conflict; nothing changes.
                assert client.status(SET, EIP_SECURITY, 1, 9, b"\x01") == 0x0C
                assert client(GET, EIP_SECURITY, 1, 9) == (0, (), b"\x00")
                for service in (KICK, APPLY, ABORT):
                    assert client.status(service, EIP_SECURITY, 1) == 0x0C
                status, _, data = client(GET_ALL, EIP_SECURITY, 1)
                assert status == 0 and data[0] == 0
            finally:
                client.close()

        await run(read)


async def test_an_eds_emulated_device_serves_the_objects_too() -> None:
    from cipstack.eds.emulated_device import build_eds_device
    from cipstack.eds.reader import read_eds

    device = build_eds_device(read_eds(Path(__file__).parent / "eds" / "files" / "ez_style_iolink_master.eds"))
    async with Adapter(_settings(), device) as adapter:
        def read() -> tuple[int, tuple[int, ...], bytes]:
            client = Client(f"127.0.0.1:{adapter.port}")
            try:
                return client(GET, EIP_SECURITY, 1, 1)
            finally:
                client.close()

        assert await run(read) == (0, (), b"\x00")


async def test_a_device_without_the_objects_answers_path_destination_unknown() -> None:
    async with Adapter(_settings(security_objects=False)) as adapter:
        def read() -> int:
            client = Client(f"127.0.0.1:{adapter.port}")
            try:
                return client.status(GET, EIP_SECURITY, 1, 1)
            finally:
                client.close()

        assert await run(read) == 0x05


# -- the configuration session ------------------------------------------------------------------------
async def test_the_session_belongs_to_the_connection_that_began_it() -> None:
    async with Adapter(_settings()) as adapter:
        def session() -> None:
            owner, other = Client(f"127.0.0.1:{adapter.port}"), Client(f"127.0.0.1:{adapter.port}")
            try:
                assert owner.status(BEGIN, EIP_SECURITY, 1) == 0
                assert owner(GET, EIP_SECURITY, 1, 1) == (0, (), b"\x01")      # Configuration In Progress
                assert other(GET, CIP_SECURITY, 1, 1) == (0, (), b"\x01")
                # A second connection: neither a session of its own, nor a hand in this one.
                assert other.status(BEGIN, EIP_SECURITY, 1) == 0x0C
                assert other.status(SET, EIP_SECURITY, 1, 9, b"\x01") == 0x0C
                assert other.status(KICK, EIP_SECURITY, 1) == 0x0C
                assert other.status(ABORT, EIP_SECURITY, 1) == 0x0C
                assert other.status(APPLY, EIP_SECURITY, 1) == 0x0C
                assert other.status(RESET, EIP_SECURITY, 1) == 0x0C
                assert other.status(CREATE_CSR, CERTIFICATES, 1, None, _csr_request()) == 0x0C
                # The owner goes on undisturbed.
                assert owner.status(SET, EIP_SECURITY, 1, 9, b"\x01") == 0
                assert owner(GET, EIP_SECURITY, 1, 9) == (0, (), b"\x01")
                assert owner.status(KICK, EIP_SECURITY, 1) == 0
                # Apply without a certificate: 0x0C, extended 0x0002 (no certificates configured); still open.
                assert owner(APPLY, EIP_SECURITY, 1, None, b"\x00\x00\x00\x00")[:2] == (0x0C, (0x0002,))
                assert owner.status(ABORT, EIP_SECURITY, 1) == 0
                assert other(GET, EIP_SECURITY, 1, 1) == (0, (), b"\x00")      # back to Factory Default
                assert other(GET, EIP_SECURITY, 1, 9) == (0, (), b"\x00")      # the change dropped
                assert other.status(BEGIN, EIP_SECURITY, 1) == 0               # now the other's turn
            finally:
                owner.close()
                other.close()

        await run(session)


async def test_the_session_timer_expires_and_drops_the_changes() -> None:
    async with Adapter(_settings(security_config_timeout=0.3)) as adapter:
        def session() -> None:
            from tests.waiting import wait_for

            owner, other = Client(f"127.0.0.1:{adapter.port}"), Client(f"127.0.0.1:{adapter.port}")
            try:
                assert owner.status(BEGIN, EIP_SECURITY, 1) == 0
                assert owner.status(SET, EIP_SECURITY, 1, 11, b"\x01") == 0
                wait_for(lambda: other(GET, EIP_SECURITY, 1, 1)[2] == b"\x00", 10, "the session to expire")
                assert other(GET, EIP_SECURITY, 1, 11) == (0, (), b"\x00")
                assert owner.status(KICK, EIP_SECURITY, 1) == 0x0C        # too late: no session any more
                assert other.status(BEGIN, EIP_SECURITY, 1) == 0          # a new one can begin
            finally:
                owner.close()
                other.close()

        await run(session)


async def test_kick_timer_keeps_a_live_session_past_its_timeout() -> None:
    """A 1 s session kicked every 0.1 s is still open 2.5 s later; left alone, it ends."""
    async with Adapter(_settings(security_config_timeout=1.0)) as adapter:
        def session() -> None:
            import time

            from tests.waiting import wait_for

            owner = Client(f"127.0.0.1:{adapter.port}")
            try:
                assert owner.status(BEGIN, EIP_SECURITY, 1) == 0
                started = time.monotonic()
                while time.monotonic() - started < 2.5:
                    assert owner.status(KICK, EIP_SECURITY, 1) == 0
                    time.sleep(0.1)                                   # the pace of a tool's keep-alive
                assert owner(GET, EIP_SECURITY, 1, 1) == (0, (), b"\x01")  # still In Progress
                wait_for(lambda: owner(GET, EIP_SECURITY, 1, 1)[2] == b"\x00", 10, "the session to expire")
                assert owner.status(KICK, EIP_SECURITY, 1) == 0x0C
            finally:
                owner.close()

        await run(session)


def test_the_adapters_session_timeout_is_the_configurators() -> None:
    from cipstack.adapter import SECURITY_CONFIG_TIMEOUT
    from cipstack.security.configuration import CONFIG_TIMEOUT

    assert SECURITY_CONFIG_TIMEOUT == CONFIG_TIMEOUT


def test_kick_timer_keeps_the_session_alive_on_the_configurators_clock() -> None:
    """Sans-I/O: the time is an argument. A session of 10 s kicked at 9 s lives until 19 s."""
    applied: list[object] = []
    configurator = Configurator(applied.append, timeout=10.0)
    owner = object()
    configurator.begin(owner, "127.0.0.1:1", now=0.0)
    configurator.kick(owner, "127.0.0.1:1", now=9.0)
    configurator.expire(18.9)
    assert configurator.state == SecurityState.CONFIGURATION_IN_PROGRESS
    configurator.expire(19.0)
    assert configurator.state == SecurityState.FACTORY_DEFAULT
    assert applied == []


# -- push-model configuration ---------------------------------------------------------------------------
def _push(address: str, folder: Path, **options: Any) -> Any:
    client = Client(address)
    try:
        return configure(client, folder, **options)
    finally:
        client.close()


async def test_configured_over_the_wire_the_device_serves_tls_with_the_new_certificate(lab: Path) -> None:
    async with Adapter(_settings()) as adapter:
        plain = f"127.0.0.1:{adapter.port}"
        pushed = await run(_push, plain, lab)
        assert adapter.secure is not None
        secured = f"127.0.0.1:{adapter.settings.security_port}"

        def check() -> None:
            import socket

            credentials = Credentials.load(lab)
            with SyncScanner(secured, security=credentials, identify=False) as drive:
                assert drive.read(1, 1, 7) == "CENT"
            # The certificate the device presents is the one just pushed, signed by the lab CA.
            sock = socket.create_connection(("127.0.0.1", adapter.settings.security_port), timeout=10)
            with credentials.wrap_client(sock, "127.0.0.1", adapter.settings.security_port) as tls:
                assert tls.getpeercert(binary_form=True) == pushed.certificate
                assert tls.version() == "TLSv1.2"
            client = Client(plain)
            try:
                assert client(GET, EIP_SECURITY, 1, 1) == (0, (), b"\x02")             # Configured
                assert client(GET, CIP_SECURITY, 1, 3) == (0, (), b"\x02\x00")
                assert client(GET, CERTIFICATES, 1, 2) == (0, (), b"\x03")             # Verified
                assert client(GET, CERTIFICATES, 1, 3) == (0, (), b"\x01" + DEVICE_PATH)   # verified
                assert client.upload(DEVICE_FILE) == pem(pushed.certificate)           # the file holds it
                assert client(GET, EIP_SECURITY, 1, 6) == (0, (), bytes.fromhex("01" "02" "205F2401"))
                # Configured: a new session needs a Reset first.
                assert client.status(BEGIN, EIP_SECURITY, 1) == 0x0C
            finally:
                client.close()

        await wait_reloaded(adapter)
        await run(check)


async def wait_reloaded(adapter: Adapter, count: int = 1) -> None:
    """Until the device's TLS listener follows the configuration (it is put in place after the reply)."""
    assert adapter.secure is not None
    for _ in range(1000):
        if adapter.secure.reloads >= count:
            return
        await asyncio.sleep(0.01)
    raise AssertionError("the TLS listener was not put in place")


async def test_reset_returns_to_factory_default_and_closes_tls(lab: Path) -> None:
    async with Adapter(_settings()) as adapter:
        plain = f"127.0.0.1:{adapter.port}"
        await run(_push, plain, lab)
        await wait_reloaded(adapter)
        assert adapter.secure is not None and adapter.secure.server is not None

        def reset() -> None:
            client = Client(plain)
            try:
                assert client.status(RESET, EIP_SECURITY, 1, None, b"\x02") == 0x20   # a BOOL is 0 or 1
                assert client.status(RESET, EIP_SECURITY, 1) == 0
                assert client(GET, EIP_SECURITY, 1, 1) == (0, (), b"\x00")
                assert client(GET, CERTIFICATES, 1, 3) == (0, (), b"\x00" + DEVICE_PATH)
                assert client.upload(DEVICE_FILE) == b""
            finally:
                client.close()

        await run(reset)
        await wait_reloaded(adapter, 2)
        assert adapter.secure.server is None
        # Configured again: the listener is back, on the same port.
        await run(_push, plain, lab)
        await wait_reloaded(adapter, 3)
        assert adapter.secure.server is not None and adapter.secure.server.port == adapter.settings.security_port

        def read() -> str:
            with SyncScanner(f"127.0.0.1:{adapter.settings.security_port}", security=Credentials.load(lab),
                             identify=False) as drive:
                return str(drive.read(1, 1, 7))
        assert await run(read) == "CENT"


async def test_configuration_survives_a_restart_with_a_state_file(lab: Path, tmp_path: Path) -> None:
    settings = _settings(state_path=tmp_path / "acg.json")
    async with Adapter(settings) as adapter:
        await run(_push, f"127.0.0.1:{adapter.port}", lab)
        await wait_reloaded(adapter)
    kept = tmp_path / "acg.json.security"
    assert {p.name for p in kept.iterdir()} == {"configuration.json", "ca.pem", "device.pem", "device.key"}
    for secret in ("device.key", "configuration.json"):   # the key, and the PSKs a configuration may hold
        assert oct((kept / secret).stat().st_mode & 0o777) == "0o600"
    assert oct(kept.stat().st_mode & 0o777) == "0o700"
    async with Adapter(settings) as again:
        def read() -> None:
            client = Client(f"127.0.0.1:{settings.security_port}", security=Credentials.load(lab))
            try:
                assert client(GET, EIP_SECURITY, 1, 1) == (0, (), b"\x02")
            finally:
                client.close()
        await run(read)
        assert again.configurator is not None and again.configurator.state == SecurityState.CONFIGURED


async def test_the_configure_command_configures_a_factory_default_device(lab: Path,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    async with Adapter(_settings()) as adapter:
        code = await run(main, ["security", "configure", f"127.0.0.1:{adapter.port}", "--security", str(lab),
                                "--security-port", str(adapter.settings.security_port), "--common-name", "drive 7"])
        assert code == 0
        out = capsys.readouterr().out
        assert out.startswith(f"127.0.0.1:{adapter.port} configured (Begin_Config, Create_CSR, ")
        assert "certificate 2.5.4.5=" in out and ",CN=drive 7; CENT answers over TLS on" in out
        # Once more: the device is configured, Begin_Config is refused, the command says so in one line.
        code = await run(main, ["security", "configure", f"127.0.0.1:{adapter.port}", "--security", str(lab)])
        captured = capsys.readouterr()
        assert code != 0
        assert captured.err.strip().splitlines() == [
            "cipstack security: Begin_Config refused: 0x0C (object state conflict); the device is configured "
            "already, or another configuration session is open (a Reset of 0x5E/1 returns a configured device to "
            "factory default)"]


# -- --secure-only -------------------------------------------------------------------------------------
async def test_secure_only_refuses_plain_explicit_requests_once_configured(lab: Path) -> None:
    async with Adapter(_settings(secure_only=True)) as adapter:
        plain = f"127.0.0.1:{adapter.port}"

        def before() -> None:
            with SyncScanner(plain, identify=False) as drive:
                assert drive.read(1, 1, 7) == "CENT"     # factory default: plain is served
        await run(before)
        await run(_push, plain, lab)
        await wait_reloaded(adapter)

        def after() -> None:
            client = Client(plain)
            try:
                assert client(GET, 1, 1, 7) == (0x0F, (), b"")       # privilege violation, nothing served
                assert client.scanner.list_identity()[0].product_name   # discovery still answers
            finally:
                client.close()
            with SyncScanner(f"127.0.0.1:{adapter.settings.security_port}", security=Credentials.load(lab),
                             identify=False) as drive:
                assert drive.read(1, 1, 7) == "CENT"
        await run(after)


# -- bad input -----------------------------------------------------------------------------------------
async def test_malformed_create_csr_requests_get_their_status_and_change_nothing() -> None:
    async with Adapter(_settings()) as adapter:
        def attack() -> None:
            client = Client(f"127.0.0.1:{adapter.port}")
            try:
                assert client.status(BEGIN, EIP_SECURITY, 1) == 0
                full = _csr_request()
                assert client.status(CREATE_CSR, CERTIFICATES, 1, None, full[:-1]) == 0x13    # eight strings
                assert client.status(CREATE_CSR, CERTIFICATES, 1, None, full + b"\x00") == 0x15
                assert client.status(CREATE_CSR, CERTIFICATES, 1, None, b"\x40abc") == 0x13    # a string cut short
                assert client.status(CREATE_CSR, CERTIFICATES, 1, None, _csr_request("", "", "", "", "", "USA")) \
                    == 0x20                                                                   # not a country code
                assert client(CREATE_CSR, CERTIFICATES, 1, None, _csr_request("drive")) == (0, (), CSR_PATH)
                assert client.upload(CSR_FILE).startswith(b"-----BEGIN CERTIFICATE REQUEST-----\n")
                assert client.status(GET, 1, 1, 7) == 0                                      # the rest serves on
            finally:
                client.close()

        await run(attack)


async def test_a_certificate_not_signed_by_the_trusted_ca_is_refused(lab: Path, other_lab: Path) -> None:
    async with Adapter(_settings()) as adapter:
        def attack() -> None:

            client = Client(f"127.0.0.1:{adapter.port}")
            try:
                assert client.status(BEGIN, EIP_SECURITY, 1) == 0
                assert client(CREATE_CSR, CERTIFICATES, 1, None, _csr_request()) == (0, (), CSR_PATH)
                forged = sign_csr(other_lab, client.upload(CSR_FILE))   # signed by another CA than the one pushed
                client.download(CA_FILE, (lab / "ca.pem").read_bytes())
                client.download(DEVICE_FILE, pem(forged))
                assert client.status(SET, EIP_SECURITY, 1, 6, PATH_LIST.encode(((0x5F, 1),))) == 0
                assert client.status(SET, EIP_SECURITY, 1, 7, PATH_LIST.encode(((0x5F, 1),))) == 0
                assert client.status(VERIFY, CERTIFICATES, 1) == 0xD0             # verification failed
                assert client(GET, CERTIFICATES, 1, 2) == (0, (), b"\x04")         # Invalid
                assert client(APPLY, EIP_SECURITY, 1, None, b"\x00" * 4)[:2] == (0x0C, (0x0002,))
                assert client(GET, EIP_SECURITY, 1, 1) == (0, (), b"\x01")         # not applied
                # Octets that are no certificate at all: refused at the last transfer, 0x09.
                with pytest.raises(FileTransferError, match="general status 0x09"):
                    client.download(DEVICE_FILE, b"\x30\x03abc")
                assert client.upload(DEVICE_FILE) == pem(forged)                    # the file as it was
            finally:
                client.close()

        await run(attack)
        assert adapter.secure is not None and adapter.secure.server is None      # no TLS from it


def test_the_configuration_tool_names_the_step_the_device_refused(lab: Path, other_lab: Path) -> None:
    """The originator's side: a CA folder whose CA the device cannot verify the certificate with."""
    async def scenario() -> str:
        async with Adapter(_settings()) as adapter:
            mixed = other_lab.parent / "mixed"
            mixed.mkdir(exist_ok=True)
            for name in ("ca.key", "client.pem", "client.key"):
                (mixed / name).write_bytes((other_lab / name).read_bytes())
            (mixed / "ca.pem").write_bytes((lab / "ca.pem").read_bytes())   # the CA pushed is not the signer
            with pytest.raises(SecurityError) as raised:
                await run(_push, f"127.0.0.1:{adapter.port}", mixed)

            def state() -> bytes:
                client = Client(f"127.0.0.1:{adapter.port}")
                try:
                    return client(GET, EIP_SECURITY, 1, 1)[2]
                finally:
                    client.close()
            assert await run(state) == b"\x00"     # the tool aborted its session
            return str(raised.value)

    assert asyncio.run(scenario()) == ("Verify_Certificate refused: 0xD0 (unknown status); the device certificate "
                                       "does not verify against the CA certificate pushed")


async def test_oversized_and_malformed_attribute_writes(caplog: pytest.LogCaptureFixture) -> None:
    async with Adapter(_settings()) as adapter:
        def attack() -> None:
            client = Client(f"127.0.0.1:{adapter.port}")
            try:
                assert client.status(BEGIN, EIP_SECURITY, 1) == 0
                elsewhere = bytes((2, 0x20, 0x37, 0x24, 0xC8))                                # the EDS file's
                assert client.status(SET, CERTIFICATES, 1, 3, b"\x00" + elsewhere) == 0x09     # not its file
                assert client.status(SET, CERTIFICATES, 1, 3, b"\x00\x02\x20") == 0x13          # cut short
                with pytest.raises(FileTransferError, match="Initiate_Download answered general status 0x20"):
                    client.download(DEVICE_FILE, b"\x30" * 20000)                          # over the file's limit
                with pytest.raises(FileTransferError, match="general status 0x09"):
                    client.download(DEVICE_FILE, b"\x30" * 5000)                           # over a certificate's
                identity = b"i" * 129
                psk = b"\x01" + bytes((len(identity),)) + identity + b"\x20" + b"k" * 32
                assert client.status(SET, EIP_SECURITY, 1, 5, psk) == 0x09                     # identity > 128
                two = PRE_SHARED_KEYS.encode(((b"a", b"k"),)) [1:]
                assert client.status(SET, EIP_SECURITY, 1, 5, b"\x02" + two + two) == 0x09     # one key kept
                assert client.status(SET, EIP_SECURITY, 1, 5, PRE_SHARED_KEYS.encode(((b"a", b"k" * 32),))) == 0
                assert client.status(SET, EIP_SECURITY, 1, 4, CIPHER_SUITES.encode((0xC02B, 0x0001))) == 0x09
                assert client.status(SET, EIP_SECURITY, 1, 4, b"\x09" + b"\xc0\x2b" * 9) == 0x09  # more than kept
                assert client.status(SET, EIP_SECURITY, 1, 9, b"\x01\x00") == 0x15
                assert client.status(SET, EIP_SECURITY, 1, 9, b"\x02") == 0x09
                assert client.status(SET, EIP_SECURITY, 1, 6, PATH_LIST.encode(((0x01, 1),))) == 0x09
                assert client.status(SET, EIP_SECURITY, 1, 3, CIPHER_SUITES.encode((0xC02B,))) == 0x0E
                assert client.status(SET, EIP_SECURITY, 1, 15, b"\x00\x00") == 0x09              # DTLS timeout 0
                assert client(GET, EIP_SECURITY, 1, 4) == (0, (), AVAILABLE)
                assert client.status(GET, 1, 1, 7) == 0
            finally:
                client.close()

        with caplog.at_level(logging.WARNING, logger="cipstack.security"):
            await run(attack)
        refused = [r for r in caplog.records if "refused" in r.getMessage()]
        assert len(refused) == 1     # twelve refusals from one source: one line in 10 s
        assert adapter.configurator is not None and adapter.configurator.refused == 12


async def test_allowed_cipher_suites_decide_the_tls_handshake(lab: Path) -> None:
    async with Adapter(_settings()) as adapter:
        await run(lambda: _push(f"127.0.0.1:{adapter.port}", lab, allowed_suites=(0xC02B,)))
        await wait_reloaded(adapter)
        port = adapter.settings.security_port

        def handshake(suite: str) -> str:
            import socket
            import ssl

            context = Credentials.load(lab).client_context()
            context.maximum_version = ssl.TLSVersion.TLSv1_2
            context.set_ciphers(suite)
            with socket.create_connection(("127.0.0.1", port), timeout=10) as sock, \
                    context.wrap_socket(sock) as tls:
                return str(tls.cipher()[0])

        assert await run(handshake, "ECDHE-ECDSA-AES128-GCM-SHA256") == "ECDHE-ECDSA-AES128-GCM-SHA256"
        with pytest.raises(OSError, match=r"HANDSHAKE_FAILURE|handshake failure"):
            await run(handshake, "ECDHE-ECDSA-AES128-SHA256")      # available, not allowed
        # A client that offers TLS 1.3 only: a configured device speaks 1.2 (its suites decide).
        def tls13() -> None:
            import socket
            import ssl

            context = Credentials.load(lab).client_context()
            context.minimum_version = ssl.TLSVersion.TLSv1_3
            with socket.create_connection(("127.0.0.1", port), timeout=10) as sock, context.wrap_socket(sock):
                pass
        with pytest.raises(OSError):
            await run(tls13)
        assert await run(handshake, "ECDHE-ECDSA-AES128-GCM-SHA256")   # the device serves on


async def test_cipstack_get_words_the_security_attributes(capsys: pytest.CaptureFixture[str]) -> None:
    async with Adapter(_settings()) as adapter:
        target = f"127.0.0.1:{adapter.port}"
        for path, line in (("0x5E/1/1", "State = 0 (Factory Default)"),
                           ("0x5E/1/4", "Allowed Cipher Suites = 0xC023 ECDHE-ECDSA-AES128-SHA256, "
                                        "0xC02B ECDHE-ECDSA-AES128-GCM-SHA256, 0xC02C ECDHE-ECDSA-AES256-GCM-SHA384, "
                                        "0xC037 ECDHE-PSK-AES128-CBC-SHA256, 0xCCAC ECDHE-PSK-CHACHA20-POLY1305, "
                                        "0x00A8 PSK-AES128-GCM-SHA256, 0x00A9 PSK-AES256-GCM-SHA384"),
                           ("0x5E/1/7", "Trusted Authorities = none"),
                           ("0x5E/1/15", "DTLS Timeout = 12 s"),
                           ("0x5F/1/4", "CA Certificate = not verified, in File object instance 203 (class 0x37)"),
                           ("0x5D/1/2", "Security Profiles = 2")):
            assert await run(main, ["get", target, path]) == 0
            assert capsys.readouterr().out == line + "\n"
        assert await run(main, ["get", target, "0x5E/1/3", "--json"]) == 0
        import json

        assert json.loads(capsys.readouterr().out) == {
            "status": 0, "data": AVAILABLE.hex(), "type": "CIPHER_SUITES",
            "value": ["0xC023", "0xC02B", "0xC02C", "0xC037", "0xCCAC", "0x00A8", "0x00A9"],
            "name": "Available Cipher Suites", "path": "0x5E/1/3"}


async def test_a_power_cycle_keeps_the_configuration_and_tls(lab: Path) -> None:
    """The power-cycle fault closes and opens every port: the TLS listener of a configuration applied
    over the network comes back with it, on the same port; the configuration is the device's."""
    async with Adapter(_settings()) as adapter:
        await run(_push, f"127.0.0.1:{adapter.port}", lab)
        await wait_reloaded(adapter)
        adapter.fault("power-cycle")
        await adapter.faults.settle()                      # the power is back, every port open again
        assert adapter.secure is not None and adapter.secure.server is not None
        assert adapter.secure.server.is_open and adapter.secure.server.port == adapter.settings.security_port

        def read() -> tuple[str, tuple[int, tuple[int, ...], bytes]]:
            with SyncScanner(f"127.0.0.1:{adapter.settings.security_port}", security=Credentials.load(lab),
                             identify=False) as drive:
                name = str(drive.read(1, 1, 7))
            client = Client(f"127.0.0.1:{adapter.port}")
            try:
                return name, client(GET, EIP_SECURITY, 1, 1)
            finally:
                client.close()
        assert await run(read) == ("CENT", (0, (), b"\x02"))


async def test_file_downloads_refused_where_the_file_object_says() -> None:
    """The EDS file's instance stays read-only; a download out of turn, with a wrong checksum or outside
    the session is refused and the certificate's file stays as it was."""
    from cipstack.eds.served import profile_eds_file

    async with Adapter(_settings(files=(profile_eds_file("acg", None),))) as adapter:
        def attack() -> None:
            client = Client(f"127.0.0.1:{adapter.port}")
            try:
                eds = client.upload(0xC8)
                with pytest.raises(FileTransferError, match="Initiate_Download answered general status 0x0C"):
                    client.download(0xC8, b"[File]\n")
                assert client.upload(0xC8) == eds
                # Outside a configuration session: refused at the last transfer (0x0C), nothing kept.
                with pytest.raises(FileTransferError, match="general status 0x0C"):
                    client.download(DEVICE_FILE, b"-----BEGIN CERTIFICATE-----\n")
                assert client.status(BEGIN, EIP_SECURITY, 1) == 0
                initiate = struct.pack("<IHBB", 4, 1, 1, 0) + b"\x00"
                assert client(0x4C, 0x37, DEVICE_FILE, None, initiate)[0] == 0
                assert client.status(0x50, 0x37, DEVICE_FILE, None, b"\x05\x00abcd") == 0x20      # out of turn
                assert client.status(0x50, 0x37, DEVICE_FILE, None, b"\x00\x01ab") == 0x0C        # Middle first
                assert client.status(0x50, 0x37, DEVICE_FILE, None, b"\x00\x04abcd\x00\x00") == 0xD0  # checksum
                assert client.upload(DEVICE_FILE) == b""
                assert client(GET, 0x37, DEVICE_FILE, 1) == (0, (), b"\x02")                       # loaded
                assert client.status(GET, 1, 1, 7) == 0
            finally:
                client.close()

        await run(attack)
