"""CIP Security over DTLS (UDP 2221), both roles: encapsulation and secured class 1 in a DTLS session,
checked against the `openssl` binary and `tshark` as independent peers, and bad input on the port
(issue 48).

The adapter runs in this process on a loop of its own thread, so that the tests read its counters
(refusals, sessions, class 1 connections) while blocking clients talk to it from the test's thread."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import re
import socket
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

pytest.importorskip("cryptography", reason="the security extra (cryptography) is not installed")
pytest.importorskip("OpenSSL", reason="the security extra (pyOpenSSL) is not installed")

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.eip.originator.blocking import BlockingEncapsulationClient
from cipstack.eip.originator.blocking_io import io_connection
from cipstack.errors import CipstackError, PeerUnreachable, SecurityError
from cipstack.scanner import Scanner, SyncScanner
from cipstack.security import Credentials
from cipstack.security.dtls import DtlsChannel, dtls_context
from cipstack.security.dtls_link import DtlsLink
from tests.ports import free_port
from tests.security_peers import OPENSSL, REGISTER_SESSION, TSHARK, needs_openssl, needs_tshark
from tests.waiting import stop_process, wait_for, wait_listening


class Served:
    """An adapter with ``--security`` on a loop of its own thread."""

    def __init__(self, folder: Path) -> None:
        self.loop = asyncio.new_event_loop()

        async def start() -> Adapter:
            adapter = Adapter(AdapterSettings(host="127.0.0.1", port=0, io_port=0, security=folder, security_port=0))
            await adapter.start()
            return adapter

        self.adapter = self.loop.run_until_complete(start())
        assert self.adapter.dtls is not None and self.adapter.io is not None
        self.dtls = self.adapter.dtls
        self.io = self.adapter.io
        self.port = self.dtls.port
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()

    def call(self, function: object, *args: object) -> None:
        """Run ``function(*args)`` on the adapter's loop and wait for it."""
        done = threading.Event()

        def run() -> None:
            try:
                function(*args)   # type: ignore[operator]
            finally:
                done.set()

        self.loop.call_soon_threadsafe(run)
        assert done.wait(10)

    def close(self) -> None:
        asyncio.run_coroutine_threadsafe(self.adapter.close(), self.loop).result(10)
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(10)
        self.loop.close()


@pytest.fixture
def served(lab: Path) -> Iterator[Served]:
    server = Served(lab)
    try:
        yield server
    finally:
        server.close()


def _client_hello(credentials: Credentials) -> bytes:
    """The first datagram of a DTLS client: a ClientHello without a cookie."""
    return DtlsChannel.client(dtls_context(credentials, server=False)).datagrams()[0]


# -- encapsulation and secured class 1 ------------------------------------------------------------------
def test_a_session_registers_in_a_dtls_session(served: Served, lab: Path) -> None:
    client = BlockingEncapsulationClient.connect_dtls("127.0.0.1", served.port, 5.0, Credentials.load(lab))
    with client:
        assert client.core.session != 0
        assert len(served.dtls.sessions) == 1
    assert served.dtls.refused == 0 and served.dtls.cookies_sent == 1


def test_class1_over_dtls_flows_in_the_session(served: Served, lab: Path) -> None:
    with SyncScanner("127.0.0.1", served.port, security=Credentials.load(lab)) as scanner, \
            scanner.io_connection(output=21, input=71, rpi=0.010) as io:
        io.update(run_forward=True, speed_reference=300)
        io.wait_input(lambda image: image.ready, timeout=10)
        io.sleep(0.2)
        (connection,) = served.io.connections.values()
        (session,) = served.dtls.sessions
        # The target sends T->O to the DTLS session's address, not to plain UDP 2222.
        assert connection.secured and connection.destination == session
        assert io.statistics()["received"] > 0
        assert connection.stats.received > 0
    assert served.io.connections == {}


def test_the_command_line_adapter_serves_class1_over_dtls(lab: Path, tmp_path: Path) -> None:
    # The command line's adapter runs on the precise loop, whose lane drains the DTLS socket.
    port, secure_port = free_port(), free_port()
    log = tmp_path / "adapter.log"
    with log.open("wb") as stderr:
        process = subprocess.Popen([sys.executable, "-m", "cipstack", "adapter", "--host", "127.0.0.1", "--port",
                                    str(port), "--io-port", "0", "--factory", "--quiet", "--security", str(lab),
                                    "--security-port", str(secure_port)], stdout=subprocess.DEVNULL, stderr=stderr)
    try:
        wait_listening(process, port, "the adapter to listen")   # plain TCP accepts last: DTLS is up by then
        assert process.poll() is None, log.read_text()
        with SyncScanner("127.0.0.1", secure_port, security=Credentials.load(lab)) as scanner, \
                scanner.io_connection(output=21, input=71, rpi=0.010) as io:
            io.sleep(0.5)
            counts = io.statistics()
        assert counts["received"] > 20 and counts["lost"] == 0
    finally:
        stop_process(process)
    assert "DTLS session accepted" in log.read_text()


def test_the_asyncio_scanner_opens_class1_over_dtls(served: Served, lab: Path) -> None:
    async def scan() -> tuple[int, bool, tuple[str, int], list[tuple[str, int]]]:
        scanner = await Scanner.connect(f"127.0.0.1:{served.port}", security=Credentials.load(lab))
        async with scanner, scanner.io_connection(output=21, input=71, rpi=0.010) as io:
            await io.wait_input(lambda image: image.ready, timeout=10)
            (connection,) = served.io.connections.values()
            return io.statistics()["received"], connection.secured, connection.destination, list(served.dtls.sessions)

    received, secured, destination, sessions = asyncio.run(scan())
    assert received > 0 and secured and sessions == [destination]
    wait_for(lambda: served.io.connections == {}, 5, "the Forward_Close")


def test_cipstack_io_with_security_runs_over_dtls(served: Served, lab: Path) -> None:
    result = subprocess.run([sys.executable, "-m", "cipstack", "io", f"127.0.0.1:{served.port}", "--security", str(lab),
                             "--output", "21", "--input", "71", "--rpi", "10ms", "--duration", "0.5s"],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    sent, received = (int(word) for word in re.findall(r"sent (\d+)  received (\d+)", result.stdout)[0])
    assert sent > 0 and received > 0
    assert served.dtls.refused == 0


def test_cipstack_io_names_a_missing_security_folder(tmp_path: Path) -> None:
    result = subprocess.run([sys.executable, "-m", "cipstack", "io", "127.0.0.1", "--security", str(tmp_path / "none"),
                             "--output", "21", "--input", "71"], capture_output=True, text=True, timeout=60)
    assert result.returncode != 0
    assert result.stderr.strip().splitlines() == [f"cipstack io: {tmp_path / 'none'}: no such folder (make one with "
                                                  f"`cipstack security init {tmp_path / 'none'}`)"]


def test_class1_faults_act_on_a_secured_connection(served: Served, lab: Path) -> None:
    with SyncScanner("127.0.0.1", served.port, security=Credentials.load(lab)) as scanner, \
            scanner.io_connection(output=21, input=71, rpi=0.010, on_input=lambda image: None) as io:
        wait_for(lambda: [c.run for c in served.io.connections.values()] == [True], 5, "the connection to run")
        (connection,) = served.io.connections.values()
        # An O->T filter: the run bit cleared on its way in, from the DTLS session as from UDP 2222.
        served.call(served.adapter.fault, "idle")
        wait_for(lambda: connection.run is False, 5, "the connection to go idle")
        served.call(served.adapter.clear_faults)
        wait_for(lambda: connection.run is True, 5, "the connection to run again")
        # Withheld: consumed (its watchdog fed) without reaching the device, still secured.
        served.call(served.adapter.fault, "ignore-output")
        received = connection.stats.received
        wait_for(lambda: connection.stats.received > received + 20, 5, "O->T datagrams under ignore-output")
        served.call(served.adapter.clear_faults)
        assert not io.timed_out and served.io.connections


def test_a_forward_open_over_tls_keeps_plain_udp(served: Served, lab: Path) -> None:
    tls_port = served.adapter.tls.port   # type: ignore[union-attr]
    client = BlockingEncapsulationClient.connect("127.0.0.1", tls_port, 5.0, security=Credentials.load(lab))
    with io_connection(client, 21, 71, 0.010, output_size=4, input_size=4) as io:
        io.wait_input(lambda image: len(image.raw) == 4, timeout=10)
        (connection,) = served.io.connections.values()
        assert not connection.secured
        assert connection.destination[1] != served.port


def test_plain_udp_naming_a_secured_connection_is_dropped(served: Served, lab: Path) -> None:
    with SyncScanner("127.0.0.1", served.port, security=Credentials.load(lab)) as scanner, \
            scanner.io_connection(output=21, input=71, rpi=0.010) as io:
        io.sleep(0.1)
        (connection,) = served.io.connections.values()
        before = served.io.dropped
        # A well-formed O->T datagram for the secured connection, as plain UDP to the class 1 port.
        datagram = struct.pack("<HHHIIHHHI", 2, 0x8002, 8, connection.ot_connection_id, 10_000, 0x00B1, 10,
                               10_000, 1) + b"\0\0\0\0"
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as plain:
            plain.sendto(datagram, ("127.0.0.1", served.adapter.io_endpoint.port))   # type: ignore[union-attr]
        wait_for(lambda: served.io.dropped > before, 5, "the plain datagram to be dropped")
        io.sleep(0.1)
        assert io.statistics()["received"] > 0


# -- from outside: openssl ------------------------------------------------------------------------------
@needs_openssl
def test_openssl_s_client_dtls_registers_a_session(served: Served, lab: Path) -> None:
    assert OPENSSL is not None
    command = [OPENSSL, "s_client", "-dtls1_2", "-connect", f"127.0.0.1:{served.port}", "-CAfile",
               str(lab / "ca.pem"), "-cert", str(lab / "client.pem"), "-key", str(lab / "client.key"), "-quiet",
               "-verify_return_error"]
    process = subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        assert process.stdin is not None and process.stdout is not None
        process.stdin.write(REGISTER_SESSION)
        process.stdin.flush()
        reply = b""
        deadline = time.monotonic() + 30
        while len(reply) < 28 and time.monotonic() < deadline:
            chunk = os.read(process.stdout.fileno(), 4096)
            if not chunk:
                break
            reply += chunk
    finally:
        stop_process(process)
    command_code, length, session, status = struct.unpack_from("<HHII", reply)
    assert (command_code, length, status) == (0x0065, 4, 0) and session != 0
    assert reply[12:20] == b"cipstack"


@needs_openssl
def test_originator_completes_a_dtls_handshake_with_openssl_s_server(lab: Path) -> None:
    assert OPENSSL is not None
    port = free_port()
    server = subprocess.Popen([OPENSSL, "s_server", "-dtls1_2", "-accept", f"127.0.0.1:{port}", "-quiet",
                               "-cert", str(lab / "device.pem"), "-key", str(lab / "device.key"),
                               "-CAfile", str(lab / "ca.pem"), "-Verify", "1", "-verify_return_error"],
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    links: list[DtlsLink] = []

    def handshake() -> bool:
        try:
            links.append(DtlsLink(Credentials.load(lab), "127.0.0.1", port, 2.0))
        except PeerUnreachable:   # not listening yet
            return server.poll() is not None
        return True

    try:
        wait_for(handshake, 30, "a DTLS handshake with s_server")
        assert links, server.stderr.read() if server.stderr else ""
        link = links[0]
        assert link.channel.description().startswith("DTLSv1.2")
        link.sendall(REGISTER_SESSION)
        assert server.stdout is not None
        received = b""
        deadline = time.monotonic() + 30
        while len(received) < 28 and time.monotonic() < deadline:
            chunk = os.read(server.stdout.fileno(), 4096)
            if not chunk:
                break
            received += chunk
        link.close()
        assert received == REGISTER_SESSION
    finally:
        stop_process(server)


@needs_tshark
def test_tshark_decrypts_class1_in_dtls_with_the_key_log(lab: Path, tmp_path: Path,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    assert TSHARK is not None
    keylog = tmp_path / "keys.log"
    capture = tmp_path / "dtls.pcapng"
    monkeypatch.setenv("SSLKEYLOGFILE", str(keylog))
    served = Served(lab)
    dumpcap = None
    try:
        # -P -l: each packet is also printed as it is captured, so the test knows the capture is live
        # (probes sent to a port of nothing until one shows) before the handshake it must see.
        probe_port = free_port()
        dumpcap = subprocess.Popen([TSHARK, "-i", "lo", "-f", f"udp port {served.port} or udp port {probe_port}",
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
        with SyncScanner("127.0.0.1", served.port, security=Credentials.load(lab)) as scanner, \
                scanner.io_connection(output=21, input=71, rpi=0.010) as io:
            io.sleep(0.3)
        time.sleep(0.5)   # what was sent reaches the capture before it stops
    finally:
        if dumpcap is not None:
            stop_process(dumpcap)
        served.close()
    assert keylog.read_text().count("CLIENT_RANDOM") >= 2   # both roles wrote their secrets
    fields = subprocess.run([TSHARK, "-r", str(capture), "-o", f"tls.keylog_file:{keylog}",
                             # Wireshark gives DTLS on 2221 to its CIP I/O dissector; elsewhere, say so.
                             "-d", f"udp.port=={served.port},dtls", "-d", f"dtls.port=={served.port},cipio",
                             "-Y", "enip.cpf.sai.seq",
                             "-T", "fields", "-e", "enip.cpf.sai.connid", "-e", "enip.cpf.sai.seq"],
                            capture_output=True, text=True, timeout=60, check=True)
    rows = [line.split("\t") for line in fields.stdout.splitlines() if line.strip()]
    assert len(rows) >= 20, subprocess.run([TSHARK, "-r", str(capture)], capture_output=True, text=True).stdout
    by_connection: dict[str, list[int]] = {}
    for connection_id, sequence in rows:
        by_connection.setdefault(connection_id, []).append(int(sequence, 0))
    assert len(by_connection) == 2   # O->T and T->O, each with its own connection id
    for sequences in by_connection.values():
        assert sequences == sorted(sequences) and len(set(sequences)) == len(sequences)


# -- bad input on UDP 2221 ------------------------------------------------------------------------------
@contextlib.contextmanager
def _bystanders(served: Served, lab: Path) -> Iterator[None]:
    """A class 1 connection over DTLS and one plain (44818, UDP 2222), each served by a thread of its
    own (``on_input``), running while the bad input comes: both must go on receiving, untimed-out."""
    with SyncScanner("127.0.0.1", served.port, security=Credentials.load(lab)) as secured, \
            secured.io_connection(output=21, input=71, rpi=0.010, on_input=lambda image: None) as over_dtls, \
            SyncScanner("127.0.0.1", served.adapter.server.port) as plain, \
            plain.io_connection(input=71, heartbeat=198, rpi=0.010, on_input=lambda image: None) as over_udp:
        before = [io.statistics()["received"] for io in (over_dtls, over_udp)]
        yield
        wait_for(lambda: all(io.statistics()["received"] > count + 10
                             for io, count in zip((over_dtls, over_udp), before, strict=True)), 10,
                 "both bystanders to go on receiving")
        assert not over_dtls.timed_out and not over_udp.timed_out


def _refusal_lines(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [record.getMessage() for record in caplog.records
            if record.name == "cipstack.security.dtls_target" and "refused" in record.getMessage()]


def test_garbage_and_plain_enip_are_refused_and_logged_once(served: Served, lab: Path,
                                                            caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, logger="cipstack.security.dtls_target")
    with _bystanders(served, lab), socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        for index in range(20):
            sock.sendto(os.urandom(40 + index), ("127.0.0.1", served.port))
        for _ in range(20):
            sock.sendto(REGISTER_SESSION, ("127.0.0.1", served.port))
        wait_for(lambda: served.dtls.refused >= 40, 10, "40 refusals")
    lines = _refusal_lines(caplog)
    assert len(lines) == 1 and "not a DTLS ClientHello" in lines[0]
    wait_for(lambda: served.dtls.sessions == {}, 5, "the bystander's session to close with it")
    # Nothing else is disturbed: a new DTLS session and class 1 work, and so does 44818.
    with SyncScanner("127.0.0.1", served.port, security=Credentials.load(lab)) as scanner, \
            scanner.io_connection(output=21, input=71, rpi=0.010) as io:
        io.sleep(0.2)
        assert io.statistics()["received"] > 0
    with SyncScanner("127.0.0.1", served.adapter.server.port) as plain:
        assert plain.identify() is not None


def test_garbage_in_an_established_session_is_discarded(served: Served, lab: Path) -> None:
    client = BlockingEncapsulationClient.connect_dtls("127.0.0.1", served.port, 5.0, Credentials.load(lab))
    with client:
        link = client.datagram_link
        for index in range(10):   # from the session's own address: not records of it (RFC 6347, 4.1.2.7)
            link.sock.send(os.urandom(30 + index))
        link.sock.send(bytes([23, 0xFE, 0xFD]) + bytes(10) + b"\x00\x20" + os.urandom(32))   # a forged record
        [identity] = client.perform(client.core.list_identity())
        assert identity.product_name == "CENT"
        assert len(served.dtls.sessions) == 1


def test_a_client_hello_flood_from_many_sources_keeps_no_state(served: Served, lab: Path) -> None:
    hello = _client_hello(Credentials.load(lab))
    sources, burst = 200, 50
    sockets = []
    with contextlib.ExitStack() as running:
        running.enter_context(_bystanders(served, lab))
        flood(hello, sources, burst, sockets, served)
    wait_for(lambda: served.dtls.sessions == {}, 5, "the bystander's session to close with it")
    with SyncScanner("127.0.0.1", served.port, security=Credentials.load(lab)) as scanner:
        assert scanner.identify() is not None


def flood(hello: bytes, sources: int, burst: int, sockets: list[socket.socket], served: Served) -> None:
    """ClientHellos without a cookie from ``sources`` loopback addresses, ``burst`` at a time."""
    try:
        for index in range(sources):
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            sockets.append(sock)
            sock.bind((f"127.0.{index // 250}.{index % 250 + 2}", 0))
            sock.sendto(hello, ("127.0.0.1", served.port))
            if (index + 1) % burst == 0:   # a burst at a time: what a receive buffer holds, none lost
                sent = index + 1
                wait_for(lambda: served.dtls.cookies_sent >= sent, 20, "a HelloVerifyRequest to each source")  # noqa: B023
        # Each got its cookie and none got a session: no state per source until a cookie comes back
        # (the one session is the bystander's).
        assert len(served.dtls.sessions) == 1
        answered = 0
        for sock in sockets:
            sock.settimeout(5)
            if sock.recv(2048)[13] == 3:   # handshake type 3: HelloVerifyRequest
                answered += 1
        assert answered == sources
    finally:
        for sock in sockets:
            sock.close()


def test_an_untrusted_client_certificate_is_refused(served: Served, other_lab: Path,
                                                    caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, logger="cipstack.security.dtls_target")
    with pytest.raises(SecurityError, match=r"DTLS with 127\.0\.0\.1:\d+ failed: .*certificate"):
        BlockingEncapsulationClient.connect_dtls("127.0.0.1", served.port, 5.0, Credentials.load(other_lab))
    wait_for(lambda: _refusal_lines(caplog), 5, "the refusal's line")
    (line,) = _refusal_lines(caplog)
    assert "DTLS handshake from 127.0.0.1:" in line and "refused" in line
    assert served.dtls.sessions == {}


def test_a_peer_that_vanishes_mid_handshake_is_forgotten(served: Served, lab: Path) -> None:
    served.call(setattr, served.dtls, "handshake_timeout", 1.0)
    channel = DtlsChannel.client(dtls_context(Credentials.load(lab), server=False))
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.settimeout(5)
        sock.connect(("127.0.0.1", served.port))
        for datagram in channel.datagrams():
            sock.send(datagram)
        channel.feed(sock.recv(2048))   # the HelloVerifyRequest
        for datagram in channel.datagrams():
            sock.send(datagram)         # the ClientHello with its cookie: now a session exists
        sock.recv(65536)                # the server's first flight; then this peer says nothing more
        wait_for(lambda: len(served.dtls.sessions) == 1, 5, "the half-open session")
        wait_for(lambda: served.dtls.sessions == {}, 10, "the half-open session to be forgotten")
    assert served.dtls.refused == 1


def test_an_idle_session_is_closed_after_the_dtls_timeout(served: Served, lab: Path) -> None:
    served.call(setattr, served.dtls, "idle_timeout", 0.5)
    client = BlockingEncapsulationClient.connect_dtls("127.0.0.1", served.port, 5.0, Credentials.load(lab))
    try:
        wait_for(lambda: len(served.dtls.sessions) == 1, 5, "the session")
        wait_for(lambda: served.dtls.sessions == {}, 10, "the idle session to be closed")
    finally:
        client.close()
    assert served.dtls.refused == 0


def test_sessions_past_the_bound_are_refused_and_the_others_serve(served: Served, lab: Path) -> None:
    served.call(setattr, served.dtls.limiter, "total", 1)
    credentials = Credentials.load(lab)
    with SyncScanner("127.0.0.1", served.port, security=credentials) as scanner, \
            scanner.io_connection(output=21, input=71, rpi=0.010, on_input=lambda image: None) as io:
        # (served by a thread of its own, on_input: it runs while this thread waits for the refusal)
        with pytest.raises(PeerUnreachable, match="no answer to the handshake"):
            DtlsLink(credentials, "127.0.0.1", served.port, 1.0)
        assert served.dtls.refused >= 1 and len(served.dtls.sessions) == 1 and served.dtls.limiter.refused >= 1
        before = io.statistics()["received"]
        io.sleep(0.2)
        assert io.statistics()["received"] > before


def test_originator_names_a_device_that_does_not_listen(lab: Path) -> None:
    port = free_port()
    with pytest.raises(PeerUnreachable, match=rf"127\.0\.0\.1:{port}"):
        DtlsLink(Credentials.load(lab), "127.0.0.1", port, 2.0)


async def test_asyncio_originator_names_no_answer_and_nothing_listening(lab: Path) -> None:
    """The asyncio side says what the blocking one says: a port that drops the ClientHello (plain UDP
    EtherNet/IP would) is no answer to the handshake, not a socket error; a closed port, one line."""
    from cipstack.eip.originator.asyncio_client import EncapsulationClient

    credentials = Credentials.load(lab)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as silent:
        silent.bind(("127.0.0.1", 0))
        port = silent.getsockname()[1]
        with pytest.raises(PeerUnreachable) as raised:
            await EncapsulationClient.connect("127.0.0.1", port, 0.5, security=credentials, datagrams=True)
    assert str(raised.value) == (f"DTLS with 127.0.0.1:{port}: no answer to the handshake (is the device serving "
                                 "CIP Security over UDP there?)")
    closed = free_port()
    with pytest.raises(PeerUnreachable) as raised:
        await EncapsulationClient.connect("127.0.0.1", closed, 2.0, security=credentials, datagrams=True)
    assert str(raised.value) == f"DTLS with 127.0.0.1:{closed}: nothing listens there (ICMP port unreachable)"


def test_originator_names_an_untrusted_device(served: Served, lab: Path, other_lab: Path) -> None:
    # The device's certificate is of lab's CA; this client trusts only other_lab's.
    mixed = Credentials.load(other_lab)
    with pytest.raises(SecurityError, match="certificate verify failed") as raised:
        DtlsLink(mixed, "127.0.0.1", served.port, 5.0)
    assert isinstance(raised.value, CipstackError) and "\n" not in str(raised.value)
