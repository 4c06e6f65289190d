"""CIP Security faults (expire or revoke the device certificate, refuse a cipher suite, drop DTLS
records) on every surface, each applied then cleared, seen by real originators: our scanner over TLS
and DTLS, and the `openssl` binary. Plain 44818 and the sessions opened before serve on meanwhile.

A device configured over the network (Apply_Config) serves DTLS beside TLS, as `--security DIR` does.

The command-line adapter runs in a process of its own (the control socket, `cipstack drive`, HTTP);
the pytest plugin's device (`cip_adapter_factory`) runs in this one, on a loop of its own thread."""

from __future__ import annotations

import asyncio
import json
import logging
import os
import shutil
import socket
import ssl
import subprocess
import sys
import textwrap
import threading
import urllib.error
import urllib.request
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, NamedTuple

import pytest

pytest.importorskip("cryptography", reason="the security extra (cryptography) is not installed")
pytest.importorskip("OpenSSL", reason="the security extra (pyOpenSSL) is not installed")

from cipstack.control import control_request
from cipstack.control.scenario import load
from cipstack.control.scenario import run as run_scenario
from cipstack.eip.originator.class1 import IoTimeoutError
from cipstack.errors import CipstackError, SecurityError, StateRefused
from cipstack.faults import FaultStateError
from cipstack.scanner import SyncScanner
from cipstack.security import Credentials
from cipstack.security.dtls_link import DtlsLink
from cipstack.testing.device import EmulatedDevice
from tests.ports import free_port
from tests.security_peers import OPENSSL, TSHARK, needs_openssl, needs_tshark
from tests.waiting import stop_process, wait_for

EXPIRED = "certificate verify failed: certificate has expired"
REVOKED = "certificate verify failed: certificate revoked"


# -- the originators --------------------------------------------------------------------------------------
def tls_read(port: int, folder: Path) -> str:
    """The Identity's product name read over TLS, or the one line of the refusal."""
    try:
        with SyncScanner(f"127.0.0.1:{port}", security=Credentials.load(folder), identify=False) as drive:
            return str(drive.read(1, 1, 7))
    except CipstackError as exc:
        return str(exc)


def dtls_handshake(port: int, folder: Path, timeout: float = 5.0) -> str:
    """'ok' once a DTLS handshake with the device completes, or the one line of the refusal."""
    try:
        DtlsLink(Credentials.load(folder), "127.0.0.1", port, timeout).close()
    except CipstackError as exc:
        return str(exc)
    return "ok"


async def async_refusal(port: int, folder: Path) -> str:
    """What the asyncio scanner's connect over TLS says."""
    from cipstack.scanner import Scanner

    try:
        scanner = await Scanner.connect(f"127.0.0.1:{port}", security=Credentials.load(folder), identify=False)
    except CipstackError as exc:
        return str(exc)
    await scanner.close()
    return "connected"


def plain_read(port: int) -> str:
    with SyncScanner(f"127.0.0.1:{port}", identify=False) as drive:
        return str(drive.read(1, 1, 7))


def s_client(port: int, folder: Path, *extra: str) -> str:
    """What `openssl s_client -verify_return_error` says of a handshake with the device: its
    verification error, or the cipher it agreed on."""
    assert OPENSSL is not None
    result = subprocess.run([OPENSSL, "s_client", "-connect", f"127.0.0.1:{port}", "-CAfile",
                             str(folder / "ca.pem"), "-cert", str(folder / "client.pem"), "-key",
                             str(folder / "client.key"), "-verify_return_error", *extra],
                            input=b"", capture_output=True, timeout=30)
    text = result.stdout.decode(errors="replace") + result.stderr.decode(errors="replace")
    for line in text.splitlines():
        if line.startswith("verify error:") or "alert handshake failure" in line:
            return line
    for line in text.splitlines():
        if ", Cipher is " in line:
            return line.strip()
    return text


# -- the command-line adapter: control socket, cipstack drive, HTTP --------------------------------------
class Process(NamedTuple):
    port: int
    secure_port: int
    http: str
    control: Path
    log: Path
    process: subprocess.Popen[bytes]


def _listening(port: int) -> bool:
    try:
        socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
    except OSError:
        return False
    return True


@pytest.fixture(scope="module")
def emulator(lab: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Process]:
    folder = tmp_path_factory.mktemp("security-faults")
    port, secure_port, http_port = free_port(), free_port(), free_port()
    log, control = folder / "adapter.log", folder / "control.sock"
    with log.open("wb") as stderr:
        process = subprocess.Popen([sys.executable, "-m", "cipstack", "adapter", "--host", "127.0.0.1", "--port",
                                    str(port), "--io-port", "0", "--factory", "--security", str(lab),
                                    "--security-port", str(secure_port), "--control", str(control),
                                    "--http", f"127.0.0.1:{http_port}"],
                                   stdout=subprocess.DEVNULL, stderr=stderr)
    started = Process(port, secure_port, f"http://127.0.0.1:{http_port}", control, log, process)
    try:
        wait_for(lambda: process.poll() is not None or (_listening(port) and _listening(http_port)), 30,
                 "the adapter to listen")
        if process.poll() is not None:
            pytest.fail(f"the adapter stopped: {log.read_text()}")
        yield started
    finally:
        stop_process(process)


def drive(emulator: Process, *words: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "cipstack", "drive", *words, "--control", str(emulator.control)],
                          capture_output=True, text=True, timeout=30, stdin=subprocess.DEVNULL)


def http(emulator: Process, method: str, path: str, body: object = None) -> tuple[int, Any]:
    data = None if body is None else json.dumps(body).encode()
    request = urllib.request.Request(emulator.http + path, data, method=method,
                                     headers={"Content-Type": "application/json"} if data else {})
    try:
        with urllib.request.urlopen(request, timeout=30) as reply:
            return int(reply.status), json.loads(reply.read())
    except urllib.error.HTTPError as error:
        with error:
            return int(error.code), json.loads(error.read())


@needs_openssl
def test_expire_certificate_over_the_control_socket(emulator: Process, lab: Path) -> None:
    with SyncScanner(f"127.0.0.1:{emulator.secure_port}", security=Credentials.load(lab), identify=False) as before:
        reply = control_request(emulator.control, {"command": "fault", "name": "expire-certificate"})
        assert reply["name"] == "expire-certificate"
        try:
            assert tls_read(emulator.secure_port, lab) == (f"TLS with 127.0.0.1:{emulator.secure_port} failed: "
                                                           f"{EXPIRED}")
            assert dtls_handshake(emulator.secure_port, lab) == (f"DTLS with 127.0.0.1:{emulator.secure_port} "
                                                                 f"failed: {EXPIRED}")
            assert s_client(emulator.secure_port, lab) == "verify error:num=10:certificate has expired"
            # The command line's originator and the asyncio scanner say the same.
            io = subprocess.run([sys.executable, "-m", "cipstack", "io", f"127.0.0.1:{emulator.secure_port}",
                                 "--security", str(lab), "--output", "21", "--input", "71", "--duration", "0.5s"],
                                capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)
            assert io.returncode == 1
            assert io.stderr == f"cipstack io: TLS with 127.0.0.1:{emulator.secure_port} failed: {EXPIRED}\n"
            assert asyncio.run(async_refusal(emulator.secure_port, lab)) == (
                f"TLS with 127.0.0.1:{emulator.secure_port} failed: {EXPIRED}")
            # The session made before the fault keeps its certificate; 44818 serves on.
            assert before.read(1, 1, 7) == plain_read(emulator.port) == "CENT"
        finally:
            control_request(emulator.control, {"command": "clear", "fault": "expire-certificate"})
    assert tls_read(emulator.secure_port, lab) == "CENT"
    assert dtls_handshake(emulator.secure_port, lab) == "ok"


@needs_openssl
def test_revoke_certificate_over_http_publishes_the_crl_the_originator_reads(emulator: Process, lab: Path) -> None:
    status, openapi = http(emulator, "GET", "/openapi.json")
    assert status == 200
    names = openapi["paths"]["/faults"]["post"]["requestBody"]["content"]["application/json"]["schema"][
        "properties"]["name"]["enum"]
    assert {"expire-certificate", "revoke-certificate", "refuse-cipher-suite", "drop-dtls-records"} <= set(names)
    before = SyncScanner(f"127.0.0.1:{emulator.secure_port}", security=Credentials.load(lab), identify=False)
    status, fault = http(emulator, "POST", "/faults", {"name": "revoke-certificate"})
    assert status == 201, fault
    try:
        assert (lab / "crl.pem").is_file()
        assert tls_read(emulator.secure_port, lab) == f"TLS with 127.0.0.1:{emulator.secure_port} failed: {REVOKED}"
        assert dtls_handshake(emulator.secure_port, lab) == (f"DTLS with 127.0.0.1:{emulator.secure_port} failed: "
                                                             f"{REVOKED}")
        assert s_client(emulator.secure_port, lab, "-CRL", str(lab / "crl.pem"), "-crl_check") == (
            "verify error:num=23:certificate revoked")
        # A second revocation while one is in force is refused, and says why.
        status, refused = http(emulator, "POST", "/faults", {"name": "revoke-certificate"})
        assert status == 409 and "revoked already" in refused["error"]
        assert plain_read(emulator.port) == "CENT" == before.read(1, 1, 7)   # 44818, and the session from before
    finally:
        status, cleared = http(emulator, "DELETE", f"/faults/{fault['id']}")
        before.close()
    assert status == 200 and [c["name"] for c in cleared] == ["revoke-certificate"]
    assert not (lab / "crl.pem").exists()   # the folder as it was
    assert tls_read(emulator.secure_port, lab) == "CENT"


@needs_openssl
def test_refuse_cipher_suite_from_cipstack_drive(emulator: Process, lab: Path) -> None:
    only = ("-tls1_2", "-cipher", "ECDHE-ECDSA-AES128-GCM-SHA256")
    assert s_client(emulator.secure_port, lab, *only).endswith("Cipher is ECDHE-ECDSA-AES128-GCM-SHA256")
    unknown = drive(emulator, "fault", "refuse-cipher-suite", "TLS_RSA_WITH_NULL_MD5")
    assert unknown.returncode == 2
    assert unknown.stderr.strip() == (
        "cipstack drive: the device does not accept TLS_RSA_WITH_NULL_MD5 now; it accepts 0xC023 "
        "ECDHE-ECDSA-AES128-SHA256, 0xC02B ECDHE-ECDSA-AES128-GCM-SHA256, 0xC02C ECDHE-ECDSA-AES256-GCM-SHA384")
    applied = drive(emulator, "fault", "refuse-cipher-suite", "TLS_ECDHE_ECDSA_WITH_AES_128_GCM_SHA256")
    assert applied.returncode == 0, applied.stderr
    assert applied.stdout.endswith("refuse-cipher-suite --suite TLS_ECDHE_ECDSA_WITH_AES_128_GCM_SHA256\n")
    try:
        # An originator that offers that suite alone: the handshake fails, over TLS and over DTLS.
        assert "alert handshake failure" in s_client(emulator.secure_port, lab, *only)
        assert "alert handshake failure" in s_client(emulator.secure_port, lab, "-dtls1_2", "-cipher",
                                                     "ECDHE-ECDSA-AES128-GCM-SHA256")
        # Another suite, our scanner (it offers every one), and 44818 are served.
        assert s_client(emulator.secure_port, lab, "-tls1_2", "-cipher", "ECDHE-ECDSA-AES256-GCM-SHA384").endswith(
            "Cipher is ECDHE-ECDSA-AES256-GCM-SHA384")
        assert tls_read(emulator.secure_port, lab) == "CENT" == plain_read(emulator.port)
        assert dtls_handshake(emulator.secure_port, lab) == "ok"
    finally:
        cleared = drive(emulator, "fault", "clear", "refuse-cipher-suite")
    assert cleared.returncode == 0 and cleared.stdout == "cleared 1 fault(s)\n"
    assert s_client(emulator.secure_port, lab, *only).endswith("Cipher is ECDHE-ECDSA-AES128-GCM-SHA256")


# -- the pytest plugin's device ---------------------------------------------------------------------------
@pytest.fixture
def secured(cip_adapter_factory: Callable[..., EmulatedDevice], lab: Path) -> EmulatedDevice:
    return cip_adapter_factory(settings={"security": lab, "security_port": 0})


def test_drop_dtls_records_times_a_secured_class1_connection_out(secured: EmulatedDevice, lab: Path) -> None:
    adapter = secured.adapter
    assert adapter.dtls is not None
    port = adapter.dtls.port
    secured.events()   # the event stream watches from now on
    with SyncScanner(f"127.0.0.1:{port}", security=Credentials.load(lab), identify=False) as scanner, \
            scanner.io_connection(output=21, input=71, rpi=0.010, timeout_multiplier=0) as io:
        io.wait_input(lambda image: True, 5)
        # Every record from the originator lost: the device's watchdog (RPI x 4) ends the connection,
        # and the originator's, which no longer gets T->O data, ends it too.
        fault = secured.fault("drop-dtls-records", share=1, direction="in")
        try:
            timed_out = secured.wait_for("connection timed out", 10)
            assert timed_out.fields["originator"] == "127.0.0.1"
            with pytest.raises(IoTimeoutError):
                for _ in range(200):
                    io.sleep(0.05)
            assert secured.adapter.tls is not None   # 44818 and TLS on the same port number serve on
            assert plain_read(secured.port) == "CENT" == tls_read(secured.adapter.tls.port, lab)
        finally:
            secured.clear_faults(fault["id"])
    # What the device sends lost: a new handshake gets no answer, and the originator sends its ClientHello
    # again at its record layer's deadlines; each one reaches the device (a cookie for each).
    cookies = adapter.dtls.cookies_sent
    fault = secured.fault("drop-dtls-records", every=1, direction="out", originator="127.0.0.1")
    try:
        assert dtls_handshake(port, lab, timeout=2.5) == (f"DTLS with 127.0.0.1:{port}: no answer to the "
                                                          "handshake (is the device serving CIP Security over UDP "
                                                          "there?)")
        assert adapter.dtls.cookies_sent >= cookies + 2
    finally:
        secured.clear_faults(fault["id"])
    with SyncScanner(f"127.0.0.1:{port}", security=Credentials.load(lab), identify=False) as scanner, \
            scanner.io_connection(output=21, input=71, rpi=0.010) as io:
        io.sleep(0.3)
        assert io.statistics()["received"] > 0 and not io.timed_out


@needs_openssl
def test_the_refusal_of_a_refused_suite_says_what_the_device_allows(secured: EmulatedDevice, lab: Path,
                                                                    caplog: pytest.LogCaptureFixture) -> None:
    assert secured.adapter.tls is not None
    port = secured.adapter.tls.port
    fault = secured.fault("refuse-cipher-suite", suite="ECDHE-ECDSA-AES128-SHA256")
    try:
        with caplog.at_level("WARNING", logger="cipstack.security.tls_target"):
            assert "alert handshake failure" in s_client(port, lab, "-tls1_2", "-cipher", "ECDHE-ECDSA-AES128-SHA256")
            wait_for(lambda: any("allows" in r.getMessage() for r in caplog.records), 10, "the refusal's line")
        (line,) = [r.getMessage() for r in caplog.records if "allows" in r.getMessage()]
        assert line.endswith("refused: no cipher suite in common with the peer (NO_SHARED_CIPHER): the device allows "
                             "ECDHE-ECDSA-AES128-GCM-SHA256, ECDHE-ECDSA-AES256-GCM-SHA384")
        # Our originator offering that suite alone, by its IANA name: refused over TLS and DTLS, in one line.
        offering = Credentials.load(lab).offering("TLS_ECDHE_ECDSA_WITH_AES_128_CBC_SHA256")
        with pytest.raises(SecurityError) as refused:
            SyncScanner(f"127.0.0.1:{port}", security=offering, identify=False)
        assert str(refused.value) == (f"TLS with 127.0.0.1:{port} failed: no cipher suite in common with the peer "
                                      "(SSLV3_ALERT_HANDSHAKE_FAILURE): we offered ECDHE-ECDSA-AES128-SHA256")
        with caplog.at_level("WARNING", logger="cipstack.security.dtls_target"), \
                pytest.raises(SecurityError) as refused:
            DtlsLink(offering, "127.0.0.1", port, 5.0)
        assert str(refused.value) == (f"DTLS with 127.0.0.1:{port} failed: no cipher suite in common with the peer "
                                      "(tls alert handshake failure): we offered ECDHE-ECDSA-AES128-SHA256")
        wait_for(lambda: any("DTLS handshake" in r.getMessage() for r in caplog.records), 10, "the DTLS refusal")
        (line,) = [r.getMessage() for r in caplog.records if "DTLS handshake" in r.getMessage()]
        assert line.endswith("refused: no cipher suite in common with the peer (no shared cipher): the device allows "
                             "ECDHE-ECDSA-AES128-GCM-SHA256, ECDHE-ECDSA-AES256-GCM-SHA384")
        assert tls_read(port, lab) == "CENT"   # one that offers every suite agrees on another
    finally:
        secured.clear_faults(fault["id"])
    assert s_client(port, lab, "-tls1_2", "-cipher", "ECDHE-ECDSA-AES128-SHA256").endswith(
        "Cipher is ECDHE-ECDSA-AES128-SHA256")
    with SyncScanner(f"127.0.0.1:{port}", security=offering, identify=False) as drive:
        assert drive.read(1, 1, 7) == "CENT"
    with pytest.raises(SecurityError, match=r"^TLS_NO_SUCH: no TLS 1\.2 cipher suite of that name or id$"):
        Credentials.load(lab).offering("TLS_NO_SUCH")


@needs_tshark
def test_tshark_sees_the_client_hello_sent_again_and_nothing_back(secured: EmulatedDevice, lab: Path,
                                                                  tmp_path: Path) -> None:
    """On the wire, while every record the device sends is dropped: the originator's ClientHello again
    and again, and not one datagram from the device to it; once cleared, the device's flights."""
    assert TSHARK is not None and secured.adapter.dtls is not None
    port = secured.adapter.dtls.port
    capture = tmp_path / "dtls.pcapng"
    # -P -l: a line per packet as it is captured, so the test knows what the capture holds.
    dumpcap = subprocess.Popen([TSHARK, "-i", "lo", "-f", f"udp port {port}", "-w", str(capture), "-a",
                                "duration:60", "-P", "-l", "-q"], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                               text=True)
    lines: list[str] = []
    assert dumpcap.stdout is not None
    reader = threading.Thread(target=lambda: lines.extend(iter(dumpcap.stdout.readline, "")), daemon=True)   # type: ignore[union-attr]  # stdout=PIPE: never None
    reader.start()
    try:
        # Until the capture is live: handshakes, each of which it shows (ICMP-free: the device answers).
        wait_for(lambda: dumpcap.poll() is not None or (dtls_handshake(port, lab) == "ok" and bool(lines)), 30,
                 "the capture to run")
        if dumpcap.poll() is not None:
            pytest.skip("tshark cannot capture on lo here")
        fault = secured.fault("drop-dtls-records", share=1, direction="out")
        try:
            assert "no answer to the handshake" in dtls_handshake(port, lab, timeout=2.5)
        finally:
            secured.clear_faults(fault["id"])
        seen = len(lines)
        assert dtls_handshake(port, lab) == "ok"
        wait_for(lambda: len(lines) >= seen + 4, 10, "the last handshake in the capture")
    finally:
        dumpcap.terminate()
        dumpcap.wait(10)
        reader.join(10)
    fields = subprocess.run([TSHARK, "-r", str(capture), "-d", f"udp.port=={port},dtls", "-T", "fields",
                             "-e", "udp.srcport", "-e", "udp.dstport", "-e", "dtls.handshake.type"],
                            capture_output=True, text=True, timeout=60, check=True)
    rows = [line.split("\t") for line in fields.stdout.splitlines() if line.strip()]
    clients = list(dict.fromkeys(int(source) for source, destination, _ in rows if int(destination) == port))
    # The last two originators: the one of the fault, and the one after it.
    during, after = clients[-2], clients[-1]
    hellos = [kinds for source, _, kinds in rows if int(source) == during and kinds.split(",")[0] == "1"]
    assert len(hellos) >= 2, fields.stdout   # sent again at the record layer's deadline
    assert not [row for row in rows if int(row[0]) == port and int(row[1]) == during], fields.stdout
    assert [row for row in rows if int(row[0]) == port and int(row[1]) == after], fields.stdout


def test_a_fault_on_a_device_without_cip_security_is_refused(cip_adapter_factory: Callable[..., EmulatedDevice],
                                                             ) -> None:
    plain = cip_adapter_factory()
    with pytest.raises(FaultStateError, match="this device serves no CIP Security"):
        plain.fault("expire-certificate")
    factory_default = cip_adapter_factory(settings={"security_objects": True, "security_port": 0})
    with pytest.raises(StateRefused, match=r"serves no CIP Security now \(in Factory Default"):
        factory_default.fault("drop-dtls-records", share=0.5)
    assert plain.faults() == [] == factory_default.faults()


# -- scenarios --------------------------------------------------------------------------------------------
SCENARIO = """
[[step]]
at = "0s"
fault = "expire-certificate"

[[step]]
on = "parameter write"
clear = true

[[step]]
on = "parameter write"
fault = "revoke-certificate"

[[step]]
on = "parameter write"
clear = "revoke-certificate"

[[step]]
on = "parameter write"
fault = "refuse-cipher-suite"
options = { suite = "0xC02C" }

[[step]]
on = "parameter write"
clear = true

[[step]]
on = "parameter write"
fault = "drop-dtls-records"
options = { share = 1.0, direction = "out", for = "60s" }

[[step]]
on = "parameter write"
clear = true
"""


@needs_openssl
def test_each_fault_from_a_scenario_file(secured: EmulatedDevice, lab: Path, tmp_path: Path) -> None:
    path = tmp_path / "security.toml"
    path.write_text(textwrap.dedent(SCENARIO))
    scenario = load(path)
    lines: list[str] = []
    assert secured.adapter.tls is not None
    port = secured.adapter.tls.port
    ended = asyncio.run_coroutine_threadsafe(run_scenario(secured.adapter.service, scenario, lines.append),
                                             secured.loop)
    written = iter(range(1, 100))

    def step(active: list[str]) -> None:
        """Wait for the scenario's step to put these faults in force, then have a parameter written,
        which fires its next step."""
        wait_for(lambda: [f["name"] for f in secured.faults()] == active, 10, f"faults {active}")

    def advance() -> None:
        secured.set_parameter("ACC", f"{next(written)}.0")

    step(["expire-certificate"])
    assert tls_read(port, lab) == f"TLS with 127.0.0.1:{port} failed: {EXPIRED}"
    advance()
    step([])
    assert tls_read(port, lab) == "CENT"
    advance()
    step(["revoke-certificate"])
    assert tls_read(port, lab) == f"TLS with 127.0.0.1:{port} failed: {REVOKED}"
    advance()
    step([])
    assert tls_read(port, lab) == "CENT" and not (lab / "crl.pem").exists()
    advance()
    step(["refuse-cipher-suite"])
    assert "alert handshake failure" in s_client(port, lab, "-tls1_2", "-cipher", "ECDHE-ECDSA-AES256-GCM-SHA384")
    advance()
    step([])
    assert s_client(port, lab, "-tls1_2", "-cipher", "ECDHE-ECDSA-AES256-GCM-SHA384").endswith(
        "Cipher is ECDHE-ECDSA-AES256-GCM-SHA384")
    advance()
    step(["drop-dtls-records"])
    assert "no answer to the handshake" in dtls_handshake(port, lab, timeout=1.5)
    assert plain_read(secured.port) == "CENT"
    advance()
    assert ended.result(20) is True
    assert secured.faults() == [] and dtls_handshake(port, lab) == "ok"
    assert [int(line.split()[2]) for line in lines if " fired: " in line] == list(range(1, 9)), lines


# -- DTLS on a device configured over the network ----------------------------------------------------------
def _push(port: int, folder: Path) -> str:
    from cipstack.security.push import configure

    with SyncScanner(f"127.0.0.1:{port}", identify=False) as plain:
        def request(service: int, class_id: int, instance: int, attribute: int | None, data: bytes
                    ) -> tuple[int, tuple[int, ...], bytes]:
            reply = plain.request(service, class_id, instance, attribute, data, check=False)
            return reply.general_status, reply.extended_status, reply.data

        return str(configure(request, folder).subject)


def test_a_device_configured_over_the_network_serves_secured_class1(
        cip_adapter_factory: Callable[..., EmulatedDevice], lab: Path) -> None:
    device = cip_adapter_factory(settings={"security_objects": True, "security_port": 0})
    adapter = device.adapter
    assert adapter.secure is not None and adapter.secure.dtls is None
    _push(device.port, lab)
    wait_for(lambda: adapter.secure is not None and adapter.secure.dtls is not None and adapter.secure.dtls.is_open,
             10, "the DTLS listener of the configuration")
    assert adapter.secure.server is not None and adapter.secure.dtls is not None
    port = adapter.secure.dtls.port
    assert port == adapter.secure.server.port
    with SyncScanner(f"127.0.0.1:{port}", security=Credentials.load(lab), identify=False) as scanner, \
            scanner.io_connection(output=21, input=71, rpi=0.010) as io:
        io.sleep(0.3)
        assert io.statistics()["received"] > 0
        (connection,) = adapter.io.connections.values()   # type: ignore[union-attr]  # the adapter serves class 1 here
        assert connection.secured
        # The faults that need no CA key act on it; the CA's key is the configuration tool's, not the device's.
        fault = device.fault("refuse-cipher-suite", suite="ECDHE-ECDSA-AES128-GCM-SHA256")
        assert tls_read(port, lab) == "CENT" and io.statistics()["received"] > 0
        device.clear_faults(fault["id"])
        with pytest.raises(StateRefused, match=r"ca\.key: missing: the lab CA's key signs what this fault makes"):
            device.fault("expire-certificate")
    assert device.faults() == []
    # The cable pulled and plugged again: DTLS back on its number. A Reset closes it with TLS.
    device.fault("unplug")
    device.fault("plug")
    assert adapter.secure.dtls.is_open and adapter.secure.dtls.port == port
    assert dtls_handshake(port, lab) == "ok"
    with SyncScanner(f"127.0.0.1:{device.port}", identify=False) as plain:
        assert plain.request(0x05, 0x5E, 1, None, b"", check=False).general_status == 0
    wait_for(lambda: adapter.secure is not None and adapter.secure.dtls is None, 10, "the DTLS listener to close")
    assert dtls_handshake(port, lab, timeout=1.0).endswith("nothing listens there (ICMP port unreachable)")


def test_a_dtls_handshake_refusal_names_the_x509_failure(cip_adapter_factory: Callable[..., EmulatedDevice],
                                                          lab: Path, other_lab: Path) -> None:
    """The originator's DTLS refusal names what OpenSSL's check of the device's certificate met, as the
    TLS one does (here a device of another CA, which sends its chain: a CA the originator does not know)."""
    device = cip_adapter_factory(settings={"security": other_lab, "security_port": 0})
    assert device.adapter.dtls is not None
    port = device.adapter.dtls.port
    assert dtls_handshake(port, lab) == (f"DTLS with 127.0.0.1:{port} failed: certificate verify failed: "
                                         "self-signed certificate in certificate chain")


def test_a_crl_in_the_folder_that_does_not_read_is_one_line(lab: Path, tmp_path: Path) -> None:
    folder = tmp_path / "lab"
    shutil.copytree(lab, folder)
    (folder / "crl.pem").write_text("not a CRL\n")
    with pytest.raises(SecurityError, match=r"crl\.pem: not a usable CRL"):
        Credentials.load(folder).client_context()
    with pytest.raises(SecurityError, match=r"crl\.pem: not a usable CRL"):
        DtlsLink(Credentials.load(folder), "127.0.0.1", free_port(), 0.5)
    os.unlink(folder / "crl.pem")
    assert Credentials.load(folder).client_context().verify_flags & ssl.VERIFY_CRL_CHECK_LEAF == 0


def test_a_device_started_with_a_folder_refuses_the_clients_its_crl_lists(
        cip_adapter_factory: Callable[..., EmulatedDevice], lab: Path, tmp_path: Path) -> None:
    """A device of ``--security DIR`` checks each client's certificate against the folder's ``crl.pem``
    as it is at the handshake: a CRL published while it runs refuses the client it lists over TLS and
    DTLS, one that lists another certificate refuses nobody, and a CRL withdrawn refuses nobody; plain
    44818 serves on throughout."""
    from cryptography import x509

    from tests.test_security_attributes import revocation_list

    folder = tmp_path / "lab"
    shutil.copytree(lab, folder)
    client_serial = x509.load_pem_x509_certificate((folder / "client.pem").read_bytes()).serial_number
    device = cip_adapter_factory(settings={"security": folder, "security_port": 0})
    assert device.adapter.tls is not None and device.adapter.dtls is not None
    tls_port, dtls_port = device.adapter.tls.port, device.adapter.dtls.port
    # The client reads the same folder, and checks the device's certificate against the same CRL: the
    # device's is never listed here.
    assert tls_read(tls_port, folder) == "CENT" and dtls_handshake(dtls_port, folder) == "ok"

    (folder / "crl.pem").write_bytes(revocation_list(folder, client_serial + 1))
    assert tls_read(tls_port, folder) == "CENT" and dtls_handshake(dtls_port, folder) == "ok"

    (folder / "crl.pem").write_bytes(revocation_list(folder, client_serial, client_serial + 1))
    refused = tls_read(tls_port, folder)
    assert refused.startswith(f"TLS with 127.0.0.1:{tls_port} failed") and "revoked" in refused, refused
    refused = dtls_handshake(dtls_port, folder, timeout=2.0)
    assert refused.startswith(f"DTLS with 127.0.0.1:{dtls_port} failed") and "revoked" in refused, refused
    assert plain_read(device.port) == "CENT"

    os.unlink(folder / "crl.pem")
    assert tls_read(tls_port, folder) == "CENT" and dtls_handshake(dtls_port, folder) == "ok"


def test_a_crl_that_does_not_read_leaves_a_running_device_as_it_was(
        cip_adapter_factory: Callable[..., EmulatedDevice], lab: Path, tmp_path: Path,
        caplog: pytest.LogCaptureFixture) -> None:
    """A careless publisher: a ``crl.pem`` that is no CRL, written while the device runs. The next
    handshakes are served with the contexts the device had (its clients are not all refused for it),
    each port says so in one line, once for that file, and a good CRL after it counts again."""
    from cryptography import x509

    from tests.test_security_attributes import revocation_list

    folder = tmp_path / "lab"
    shutil.copytree(lab, folder)
    device = cip_adapter_factory(settings={"security": folder, "security_port": 0})
    assert device.adapter.tls is not None and device.adapter.dtls is not None
    tls_port, dtls_port = device.adapter.tls.port, device.adapter.dtls.port
    caplog.set_level(logging.ERROR, logger="cipstack.security")
    (folder / "crl.pem").write_text("not a CRL\n")
    for _ in range(2):   # the client reads the unchanged lab folder, which holds no CRL
        assert tls_read(tls_port, lab) == "CENT" and dtls_handshake(dtls_port, lab) == "ok"
    lines = [r.getMessage() for r in caplog.records if "keeps the contexts it had" in r.getMessage()]
    assert sorted(line.split(":")[0] for line in lines) == ["the DTLS port keeps the contexts it had",
                                                           "the TLS port keeps the contexts it had"]
    assert all("crl.pem: not a usable CRL" in line for line in lines)
    client_serial = x509.load_pem_x509_certificate((folder / "client.pem").read_bytes()).serial_number
    (folder / "crl.pem").write_bytes(revocation_list(folder, client_serial))
    assert "revoked" in tls_read(tls_port, lab) and "revoked" in dtls_handshake(dtls_port, lab, timeout=2.0)
