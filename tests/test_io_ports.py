"""Class 1 ports between an adapter and the originators on the same machine (issue 30, items 2 and 3).

An adapter consuming on a port other than 2222 (``--io-port``) sends its T->O data to the
originator at 2222, or at the port of the T->O Sockaddr Info item of its Forward_Open, never to its
own port, and names its own port in an O->T Sockaddr Info item of the reply. And a scanner that
binds 0.0.0.0:2222 with SO_REUSEADDR runs beside an adapter on 127.0.0.2:2222, while a second
emulator on exactly the adapter's address and port is still refused. Reproduced from the wire with
plain sockets; what needs UDP 2222 on the wildcard address runs in a private network namespace.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import shlex
import shutil
import socket
import struct
import subprocess
import sys
import textwrap
from collections.abc import Iterator
from pathlib import Path

import pytest

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.scanner import Scanner
from tests.attacks import SEND_RR, Client, class1_open, rr_body, sockaddr_item
from tests.fakes import split_cpf
from tests.ports import free_port
from tests.test_cli import start_adapter, stop

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="any 127.x on loopback")

CLASS1_PORT = 2222


@contextlib.contextmanager
def originator_on_2222() -> Iterator[socket.socket]:
    """A UDP socket on port 2222 of a loopback address of its own (the address is the originator's:
    its TCP connection comes from there too)."""
    for third in range(22, 40):
        for last in range(2, 250):
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            try:
                sock.bind((f"127.0.{third}.{last}", CLASS1_PORT))
            except OSError:
                sock.close()
                continue
            sock.settimeout(2.0)
            try:
                yield sock
            finally:
                sock.close()
            return
    pytest.skip("no loopback address has UDP 2222 free")


def items_of(body: bytes) -> list[tuple[int, bytes]]:
    """The CPF items of a SendRRData reply body."""
    return split_cpf(body[6:])  # after the interface handle and the timeout


def t_to_o_id(mr: bytes) -> int:
    """The T->O connection ID of a successful Forward_Open reply (after O->T ID, no extended status)."""
    assert mr[2] == 0, f"Forward_Open refused: 0x{mr[2]:02X}"
    return int(struct.unpack_from("<I", mr, 8)[0])


def test_t_to_o_goes_to_the_originators_2222_and_the_reply_names_the_io_port(tmp_path: Path) -> None:
    """The field's case: --io-port not 2222, a Forward_Open with no Sockaddr Info item. T->O data
    went from the adapter's port to the adapter's port on the originator, and nothing in the reply
    said where O->T data should go."""
    io_port = free_port()
    address, process = start_adapter("--io-port", str(io_port), "--control", str(tmp_path / "io.sock"))
    port = int(address.rsplit(":", 1)[1])
    try:
        with originator_on_2222() as udp, Client(port, source=udp.getsockname()[0]) as client:
            status, _, body = client.exchange(SEND_RR, rr_body(class1_open(0x301)))
            assert status == 0
            items = items_of(body)
            assert [t for t, _ in items] == [0x0000, 0x00B2, 0x8000]
            # The O->T Sockaddr Info item: AF_INET, the adapter's class 1 port, address 0 (big-endian).
            assert items[2][1] == struct.pack(">hH4s8x", 2, io_port, bytes(4))
            to_id = t_to_o_id(items[1][1])
            data, (source_host, source_port) = udp.recvfrom(2048)
            assert (source_host, source_port) == ("127.0.0.1", io_port)
            assert struct.unpack_from("<HHHI", data) == (2, 0x8002, 8, to_id)
    finally:
        stop(process)


def test_the_t_to_o_item_of_the_forward_open_decides_the_port(tmp_path: Path) -> None:
    io_port = free_port()
    address, process = start_adapter("--io-port", str(io_port), "--control", str(tmp_path / "io.sock"))
    port = int(address.rsplit(":", 1)[1])
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as udp, Client(port) as client:
            udp.bind(("127.0.0.1", 0))
            udp.settimeout(2.0)
            # The item's address is not followed (only its port): T->O still goes to the TCP peer.
            status, _, body = client.exchange(SEND_RR, rr_body(class1_open(0x302),
                                                               sockaddr_item("127.0.0.9", udp.getsockname()[1])))
            assert status == 0
            to_id = t_to_o_id(items_of(body)[1][1])
            data, _ = udp.recvfrom(2048)
            assert struct.unpack_from("<HHHI", data) == (2, 0x8002, 8, to_id)
    finally:
        stop(process)


def test_on_2222_the_reply_carries_no_o_to_t_item(tmp_path: Path) -> None:
    """A target consuming on 2222 says nothing more (the reply's bytes are unchanged)."""
    hosts = ("127.0.0.2",)
    try:
        probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        probe.bind((hosts[0], CLASS1_PORT))
        probe.close()
    except OSError:
        pytest.skip("UDP 127.0.0.2:2222 is taken")
    port = free_port(*hosts)

    async def exchange() -> list[int]:
        async with Adapter(AdapterSettings(host=hosts[0], port=port, io_port=CLASS1_PORT)):
            loop = asyncio.get_running_loop()
            return await loop.run_in_executor(None, opened_items, port, hosts[0])

    assert asyncio.run(exchange()) == [0x0000, 0x00B2]


def opened_items(port: int, host: str) -> list[int]:
    with socket.create_connection((host, port), timeout=5) as sock:
        sock.sendall(struct.pack("<HHII8sI", 0x65, 4, 0, 0, bytes(8), 0) + b"\x01\x00\x00\x00")
        session = struct.unpack_from("<I", sock.recv(28), 4)[0]
        body = rr_body(class1_open(0x303), sockaddr_item("0.0.0.0", 40000))
        sock.sendall(struct.pack("<HHII8sI", SEND_RR, len(body), session, 0, bytes(8), 0) + body)
        reply = b""
        while len(reply) < 24 or len(reply) < 24 + struct.unpack_from("<H", reply, 2)[0]:
            reply += sock.recv(4096)
        return [t for t, _ in items_of(reply[24:])]


async def test_the_scanner_sends_o_to_t_where_the_reply_says() -> None:
    """Without ``target_io_port`` the scanner sends O->T to the port the reply names."""
    adapter = Adapter(AdapterSettings(host="127.0.0.1", port=0, io_port=0))
    await adapter.start()
    try:
        assert adapter.io is not None and adapter.io.io_port != CLASS1_PORT
        async with await Scanner.connect(f"127.0.0.1:{adapter.port}") as scanner, \
                scanner.io_connection(output=21, input=71, rpi=0.010) as io:
            assert io.connection.target_io_port == adapter.io.io_port
            for _ in range(100):
                await asyncio.sleep(0.02)
                if any(c.stats.received for c in adapter.io.connections.values()):
                    break
            assert any(c.stats.received for c in adapter.io.connections.values())
    finally:
        await adapter.close()


# -- item 3: beside a scanner on 0.0.0.0:2222, in a network namespace of its own ---------------------
NAMESPACE_HELPER = textwrap.dedent('''
    import asyncio, socket, sys
    from cipstack.adapter import Adapter, AdapterSettings
    from cipstack.listening import ListenError

    def scanner_socket():
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(("0.0.0.0", 2222))      # what the C++ scanner does
        return sock

    async def adapter(port):
        a = Adapter(AdapterSettings(host="127.0.0.2", port=port, io_port=2222))
        await a.start()
        return a

    async def main():
        results = []
        # The scanner first, then the adapter.
        scanner = scanner_socket()
        first = await adapter(44818)
        results.append("adapter beside scanner")
        # The adapter first, then the scanner (another scanner: two such may share by their choice).
        later = scanner_socket()
        results.append("scanner beside adapter")
        # A class 1 datagram to the adapter's address reaches the adapter (which drops and counts
        # one for no connection of its), not a scanner.
        sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sender.sendto(bytes.fromhex("0200 0280 0800 78563412 01000000 b100 0200 0100"), ("127.0.0.2", 2222))
        for _ in range(100):
            await asyncio.sleep(0.01)
            if first.io.dropped:
                break
        scanner.setblocking(False)
        later.setblocking(False)
        heard = []
        for sock in (scanner, later):
            try:
                heard.append(sock.recv(100))
            except BlockingIOError:
                pass
        results.append(f"adapter dropped {first.io.dropped}, scanners heard {len(heard)}")
        # A second emulator on exactly 127.0.0.2:2222 is refused, as before.
        try:
            second = await adapter(44819)
        except ListenError as exc:
            results.append("second refused: " + str(exc))
        else:
            await second.close()
            results.append("second started")
        await first.close()
        scanner.close()
        later.close()
        print("\\n".join(results))

    asyncio.run(main())
''')


def in_namespace(tmp_path: Path, script: str, setup: str = "") -> subprocess.CompletedProcess[str]:
    """Run ``script`` with this tree's cipstack in a private network namespace whose loopback is up
    (after the shell command ``setup``): UDP 2222 or 0.0.0.0 there take nothing from anyone."""
    missing = [tool for tool in ("unshare", "ip") if shutil.which(tool) is None]
    if missing:
        pytest.skip(f"{' and '.join(missing)} not installed")
    if os.geteuid() != 0:
        pytest.skip("a private network namespace (unshare -n) needs root")
    path = tmp_path / "in_namespace.py"
    path.write_text(script)
    inner = f"ip link set lo up && {setup or 'true'} && {shlex.quote(sys.executable)} {shlex.quote(str(path))}"
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).parents[1])}
    return subprocess.run(["unshare", "-n", "sh", "-c", inner], capture_output=True, text=True, timeout=60,
                          env=env, check=False)


def test_a_scanner_on_the_wildcard_2222_runs_beside_the_adapter(tmp_path: Path) -> None:
    result = in_namespace(tmp_path, NAMESPACE_HELPER)
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines() == [
        "adapter beside scanner", "scanner beside adapter", "adapter dropped 1, scanners heard 0",
        "second refused: cannot listen on UDP 127.0.0.2:2222 (class 1 I/O, --io-port): Address already in use"]


# -- item 4: the address and the netmask a device reports -------------------------------------------
INTERFACE_HELPER = textwrap.dedent('''
    import asyncio, ipaddress, socket, struct
    from cipstack.adapter import Adapter, AdapterSettings
    from tests.ports import list_identity_replies

    def advertised(reply):
        """The sockaddr of a ListIdentity reply's item (after count, type, length and version)."""
        family, port, address = struct.unpack_from(">hH4s", reply, 24 + 2 + 4 + 2)
        return f"{socket.inet_ntoa(address)}:{port}"

    def tcp_exchange(host, port, frames):
        with socket.create_connection((host, port), timeout=5) as sock:
            replies = []
            session = 0
            for command, body in frames:
                sock.sendall(struct.pack("<HHII8sI", command, len(body), session, 0, bytes(8), 0) + body)
                head = sock.recv(24, socket.MSG_WAITALL)
                length, session = struct.unpack_from("<HI", head, 2)
                replies.append(head + sock.recv(length, socket.MSG_WAITALL) if length else head)
            return replies

    async def main():
        lines = []
        # An adapter on an address of a /24: the TCP/IP object's attribute 5 (address, mask).
        async with Adapter(AdapterSettings(host="10.20.30.40", port=44818, io_port=2222)):
            get = bytes.fromhex("0e03 20f5 2401 3005")
            rr = struct.pack("<IHHHHHH", 0, 5, 2, 0, 0, 0xB2, len(get)) + get
            loop = asyncio.get_running_loop()
            _, reply = await loop.run_in_executor(None, tcp_exchange, "10.20.30.40", 44818,
                                                  [(0x65, b"\\x01\\x00\\x00\\x00"), (0x6F, rr)])
            data = reply[24 + 16 + 4:]
            address, mask = struct.unpack_from("<II", data)
            lines.append(f"tcp/ip {ipaddress.IPv4Address(address)} {ipaddress.IPv4Address(mask)}")
            # The broadcast of the subnet of an address added to an interface (not its first) is heard.
            replies = await list_identity_replies("10.20.30.255", 44818)
            lines.append("subnet broadcast " + " ".join(advertised(reply) for reply, _ in replies))
        # An adapter on every address: ListIdentity says the address each request arrived on.
        async with Adapter(AdapterSettings(host="0.0.0.0", port=44819, io_port=0)):
            for destination in ("127.0.0.5", "10.20.30.40"):
                [(reply, _)] = await list_identity_replies(destination, 44819)
                lines.append(f"udp {destination} {advertised(reply)}")
            [_, reply] = await asyncio.get_running_loop().run_in_executor(
                None, tcp_exchange, "127.0.0.7", 44819, [(0x65, b"\\x01\\x00\\x00\\x00"), (0x63, b"")])
            lines.append(f"tcp 127.0.0.7 {advertised(reply)}")
        print("\\n".join(lines))

    asyncio.run(main())
''')


def test_the_interface_address_and_netmask_are_the_interfaces_own(tmp_path: Path) -> None:
    """In a namespace whose loopback also holds 10.20.30.40/24 (as a fleet adds its addresses to an
    interface): an adapter there reports netmask 255.255.255.0 (it said 255.0.0.0 whatever the
    interface) and hears its subnet's broadcast (the interface table read missed such addresses);
    an adapter on 0.0.0.0 advertises in ListIdentity the address each request arrived on (over UDP
    it said 127.0.0.1)."""
    result = in_namespace(tmp_path, INTERFACE_HELPER, setup="ip addr add 10.20.30.40/24 dev lo")
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines() == [
        "tcp/ip 10.20.30.40 255.255.255.0",
        "subnet broadcast 10.20.30.40:44818",
        "udp 127.0.0.5 127.0.0.5:44819",
        "udp 10.20.30.40 10.20.30.40:44819",
        "tcp 127.0.0.7 127.0.0.7:44819",
    ]


async def test_endpoints_on_port_0_never_share_a_port() -> None:
    """``--io-port 0`` and an originator's own socket take a port of their own: with SO_REUSEADDR on a
    port-0 bind, Linux gave a port another such socket held (600 of them shared about 5), and an
    adapter then refused to start ("cannot listen on UDP 127.0.0.1:0") or two endpoints read each
    other's T->O."""
    from cipstack.eip.io_server import IoEndpoint
    from cipstack.eip.originator.io_originator import IoOriginator

    # An originator's endpoint, and a target's (``exclusive``, as the adapter opens it); no datagram
    # is sent, so one core serves both kinds.
    core = IoOriginator()
    endpoints = [IoEndpoint(core, "127.0.0.1", 0, exclusive=n % 2 == 0) for n in range(600)]
    try:
        for endpoint in endpoints:
            await endpoint.start()
        ports = [endpoint.port for endpoint in endpoints]
        assert len(set(ports)) == len(ports), sorted(p for p in ports if ports.count(p) > 1)
    finally:
        for endpoint in endpoints:
            if endpoint.is_open:
                await endpoint.close()
