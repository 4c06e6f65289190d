"""cpppo (independent) as a client of our adapter, and as a target for our scanner."""

from __future__ import annotations

import ast
import asyncio
import re
import struct
import subprocess
from collections.abc import Iterator
from typing import Any

import pytest

from cipstack.cip.status import CipError
from cipstack.cip.types import INT
from cipstack.eip.originator.asyncio_client import EncapsulationClient, EncapsulationStatusError, discover, parse_host
from cipstack.scanner import SyncScanner, backplane_route

from .conftest import CPPPO_RESULT_LINE as RESULT_LINE
from .conftest import IDENTITY, PeerProcess, cpppo_get_attribute, python_module

pytestmark = pytest.mark.interop

CLI_TIMEOUT = 30.0

#: One result line of cpppo's get_attribute, e.g. ``...:   0: Single G_A_S      @0x0001/1/1 == [3, 1]``.
#: One decoded field of cpppo's list_services output, e.g. ``'enip.status':    0,``.
FIELD_LINE = re.compile(r"^\s*'([\w.\[\]]+)':\s+(.*?),?\s*$")

NAME = IDENTITY["product_name"].encode()
IDENTITY_BYTES = {
    "@0x0001/1/1": list(struct.pack("<H", IDENTITY["vendor_id"])),
    "@0x0001/1/2": list(struct.pack("<H", IDENTITY["device_type"])),
    "@0x0001/1/3": list(struct.pack("<H", IDENTITY["product_code"])),
    "@0x0001/1/4": list(IDENTITY["revision"]),
    "@0x0001/1/6": list(struct.pack("<I", IDENTITY["serial_number"])),
    "@0x0001/1/7": [len(NAME), *NAME],
}


def run_tool(module: str, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(python_module(module, *args), capture_output=True, text=True, timeout=CLI_TIMEOUT,
                          check=False)


def get_attribute(address: str, *arguments: str, simple: bool = False) -> tuple[int, list[tuple[str, str, Any]], str]:
    """Run cpppo's get_attribute with tags (and options); returns (exit status, [(operation, path, value)], output)."""
    return cpppo_get_attribute(address, *(["-S"] if simple else []), *arguments)


def list_services(address: str, udp: bool) -> tuple[list[dict[str, Any]], str]:
    """Run cpppo's list_services with -i; returns one dict of decoded fields per reply."""
    args = ["-a", address, "-i"] + (["-u", "-t", "3"] if udp else [])
    result = run_tool("cpppo.server.enip.list_services", *args)
    output = result.stdout + result.stderr
    assert result.returncode == 0, output
    replies: list[dict[str, Any]] = []
    for line in result.stdout.splitlines():
        if line.startswith("{"):
            replies.append({})
            continue
        match = FIELD_LINE.match(line)
        if match and replies and not match.group(2).startswith("array("):
            try:
                replies[-1][match.group(1)] = ast.literal_eval(match.group(2))
            except (ValueError, SyntaxError):
                replies[-1][match.group(1)] = match.group(2)
    return replies, output


# -- cpppo's client tools against our adapter ---------------------------------------------------------
@pytest.mark.parametrize("simple", [False, True], ids=["unconnected-send", "simple"])
def test_get_attribute_identity(adapter: PeerProcess, simple: bool) -> None:
    tags = [f"@1/1/{attribute}" for attribute in range(1, 8)]
    code, rows, output = get_attribute(adapter.address, *tags, simple=simple)
    assert code == 0, output
    assert [(op, path) for op, path, _ in rows] == [("G_A_S", f"@0x0001/1/{a}") for a in range(1, 8)], output
    values = {path: value for _, path, value in rows}
    for path, expected in IDENTITY_BYTES.items():
        assert values[path] == expected, (path, output)
    status = values["@0x0001/1/5"]
    assert isinstance(status, list) and len(status) == 2, output


@pytest.mark.parametrize("simple", [False, True], ids=["unconnected-send", "simple"])
def test_get_attribute_missing_attribute_fails(adapter: PeerProcess, simple: bool) -> None:
    code, rows, output = get_attribute(adapter.address, "@1/1/99", "@1/1/1", simple=simple)
    assert code != 0, f"cpppo should exit non-zero on an error status:\n{output}"
    assert rows[0] == ("G_A_S", "@0x0001/1/99", None), output
    assert rows[1] == ("G_A_S", "@0x0001/1/1", IDENTITY_BYTES["@0x0001/1/1"]), output


@pytest.mark.parametrize("simple", [False, True], ids=["unconnected-send", "simple"])
def test_set_attribute_then_read_back(adapter: PeerProcess, simple: bool) -> None:
    code, rows, output = get_attribute(adapter.address, "@0xF5/1/13", "@0xF5/1/13=(UINT)60", "@0xF5/1/13",
                                       simple=simple)
    assert code == 0, output
    original = rows[0][2]
    assert original == [120, 0], output
    assert rows[1] == ("S_A_S", "@0x00F5/1/13", True), output
    assert rows[2] == ("G_A_S", "@0x00F5/1/13", [60, 0]), output
    code, rows, output = get_attribute(adapter.address, "@0xF5/1/13=(UINT)120", "@0xF5/1/13", simple=simple)
    assert code == 0, output
    assert rows == [("S_A_S", "@0x00F5/1/13", True), ("G_A_S", "@0x00F5/1/13", [120, 0])], output


def test_get_attributes_all(adapter: PeerProcess) -> None:
    code, rows, output = get_attribute(adapter.address, "@1/1", simple=True)
    assert code == 0, output
    status = get_attribute(adapter.address, "@1/1/5", simple=True)[1][0][2]
    expected = [value for path in ("@0x0001/1/1", "@0x0001/1/2", "@0x0001/1/3", "@0x0001/1/4") for value in
                IDENTITY_BYTES[path]] + status + IDENTITY_BYTES["@0x0001/1/6"] + IDENTITY_BYTES["@0x0001/1/7"]
    assert rows == [("G_A_A", "@0x0001/1", expected)], output


@pytest.mark.parametrize("simple", [False, True], ids=["unconnected-send", "simple"])
def test_multiple_service_packet(adapter: PeerProcess, simple: bool) -> None:
    options = ["-m"] + (["-S"] if simple else [])
    result = run_tool("cpppo.server.enip.get_attribute", *options, "-a", adapter.address, "@1/1/1", "@1/1/7",
                      "@0xF6/1/3")
    assert result.returncode == 0, result.stdout + result.stderr
    rows = [(m.group(3), ast.literal_eval(m.group(4))) for m in map(RESULT_LINE.search, result.stdout.splitlines())
            if m]
    assert rows[:2] == [("@0x0001/1/1", IDENTITY_BYTES["@0x0001/1/1"]), ("@0x0001/1/7", IDENTITY_BYTES["@0x0001/1/7"])]
    assert rows[2][0] == "@0x00F6/1/3" and len(rows[2][1]) == 6, result.stdout  # a MAC address
    assert "Multi." in result.stdout


def test_multiple_service_packet_with_a_failing_request(adapter: PeerProcess) -> None:
    """One failing embedded request makes the whole reply 0x1E (embedded service error), which cpppo raises."""
    result = run_tool("cpppo.server.enip.get_attribute", "-m", "-S", "-a", adapter.address, "@1/1/1", "@1/1/99")
    assert result.returncode != 0
    assert "Multiple Service status: 0x1e" in result.stderr, result.stderr


def test_pipelined_requests(adapter: PeerProcess) -> None:
    """cpppo keeps up to 8 requests in flight on one session: every reply must come back, in order."""
    tags = [f"@1/1/{attribute}" for _ in range(6) for attribute in (1, 3, 7)]
    code, rows, output = get_attribute(adapter.address, "-d", "8", *tags, simple=True)
    assert code == 0, output
    assert [path for _, path, _ in rows] == [t.replace("@1/", "@0x0001/") for t in tags], output
    assert all(value == IDENTITY_BYTES[path] for _, path, value in rows), output


def check_list_services_reply(reply: dict[str, Any], output: str) -> None:
    prefix = "enip.CIP.list_services.CPF."
    assert reply["enip.command"] == 0x0004, output
    assert reply["enip.status"] == 0, output
    assert reply[prefix + "count"] == 1, output
    assert reply[prefix + "item[0].type_id"] == 0x0100, output
    assert reply[prefix + "item[0].length"] == 20, output
    assert reply[prefix + "item[0].communications_service.version"] == 1, output
    assert reply[prefix + "item[0].communications_service.capability"] & 0x0020, output
    assert reply[prefix + "item[0].communications_service.service_name"] == "Communications", output


def check_list_identity_reply(reply: dict[str, Any], port: int, output: str) -> None:
    prefix = "enip.CIP.list_identity.CPF.item[0].identity_object."
    assert reply["enip.command"] == 0x0063, output
    assert reply["enip.status"] == 0, output
    assert reply["enip.CIP.list_identity.CPF.count"] == 1, output
    assert reply["enip.CIP.list_identity.CPF.item[0].type_id"] == 0x000C, output
    major, minor = IDENTITY["revision"]
    expected = {
        "version": 1, "sin_family": 2, "sin_port": port, "sin_addr": "127.0.0.1",
        "vendor_id": IDENTITY["vendor_id"], "device_type": IDENTITY["device_type"],
        "product_code": IDENTITY["product_code"], "product_revision": major | minor << 8,
        "serial_number": IDENTITY["serial_number"], "product_name": IDENTITY["product_name"], "state": 3,
    }
    assert {name: reply.get(prefix + name) for name in expected} == expected, output
    assert reply["enip.CIP.list_identity.CPF.item[0].length"] == 34 + len(NAME), output


@pytest.mark.parametrize("udp", [False, True], ids=["tcp", "udp"])
def test_list_services_and_identity(adapter: PeerProcess, udp: bool) -> None:
    replies, output = list_services(adapter.address, udp)
    assert len(replies) == 2, output
    services, identity = replies
    for reply in replies:
        assert reply["peer"] == ("127.0.0.1", adapter.port), output
    check_list_services_reply(services, output)
    check_list_identity_reply(identity, adapter.port, output)


# -- our scanner against cpppo's server -------------------------------------------------------------
CPPPO_IDENTITY = {
    1: 1,  # Rockwell
    2: 14,  # PLC
    3: 54,
    4: {"major": 20, "minor": 11},
    5: 0x3160,
    6: 7079450,
    7: "1756-L61/B LOGIX5561",
}


@pytest.fixture
def scanner(cpppo_server: PeerProcess) -> Iterator[SyncScanner]:
    with SyncScanner(cpppo_server.address, timeout=5.0) as sync:
        yield sync


def normalise(value: Any) -> Any:
    if isinstance(value, tuple):
        return {"major": value[0], "minor": value[1]}
    if hasattr(value, "_asdict"):
        return {k: normalise(v) for k, v in value._asdict().items()}
    return value


def test_scanner_reads_cpppo_identity(scanner: SyncScanner) -> None:
    for attribute, expected in CPPPO_IDENTITY.items():
        result = scanner.get_attribute_single(1, 1, attribute)
        assert result.known, attribute
        assert normalise(result.value) == expected, attribute


def test_scanner_get_attributes_all_from_cpppo(scanner: SyncScanner) -> None:
    """cpppo's reply continues after the product name (State 0xFF, then attributes 9 and 10).

    The known attributes must still decode: a CIP reader takes the declared prefix.
    """
    raw, values = scanner.get_attributes_all(1, 1)
    name = CPPPO_IDENTITY[7].encode()
    prefix = struct.pack("<HHHBBHI", 1, 14, 54, 20, 11, 0x3160, 7079450) + bytes((len(name),)) + name
    assert raw.startswith(prefix)
    assert raw[len(prefix):] == b"\xff\x00\x00\x00"
    assert values is not None, f"Identity Get_Attributes_All reply not decoded: {raw.hex(' ')}"
    assert {k: normalise(v) for k, v in values.items()} == {
        "Vendor ID": 1, "Device Type": 14, "Product Code": 54, "Revision": {"major": 20, "minor": 11},
        "Status": 0x3160, "Serial Number": 7079450, "Product Name": "1756-L61/B LOGIX5561",
        # What follows the declared attributes is kept, raw (issue 9.8), not dropped.
        "(undecoded)": b"\xff\x00\x00\x00",
    }


@pytest.mark.parametrize("connection", [None, "large", "small"],
                         ids=["unconnected", "large-forward-open", "forward-open"])
def test_scanner_reads_and_writes_cpppo_tag(cpppo_server: PeerProcess, connection: str | None) -> None:
    with SyncScanner(cpppo_server.address) as sync:
        if connection is not None:
            sync.open_connection(large=connection == "large")
            assert sync.client.connection is not None
        sync.set_attribute_single(0x2A, 1, 7, 1500, INT)
        result = sync.get_attribute_single(0x2A, 1, 7, INT)
        assert (result.value, result.data) == (1500, b"\xdc\x05")
        sync.set_attribute_single(0x2A, 1, 7, -2, INT)
        assert sync.read(0x2A, 1, 7, INT) == -2
        sync.set_attribute_single(0x2A, 1, 7, 0, INT)
        assert sync.get_attribute_single(0x2A, 1, 7, INT).data == b"\x00\x00"
        assert sync.read(1, 1, 7) == CPPPO_IDENTITY[7]


@pytest.mark.parametrize("large", [True, False], ids=["large-forward-open", "forward-open"])
def test_scanner_with_route_over_class3_to_cpppo(cpppo_server: PeerProcess, large: bool) -> None:
    """With a route (port 1, link 0) the route belongs in the Forward_Open connection path.

    Unconnected requests travel in Unconnected_Send with the route; requests on the class 3
    connection must then be the plain request: the connection already leads to the target.
    """
    with SyncScanner(cpppo_server.address, route=backplane_route()) as sync:
        assert sync.read(1, 1, 7) == CPPPO_IDENTITY[7]
        sync.open_connection(large=large)
        assert sync.read(1, 1, 7) == CPPPO_IDENTITY[7]
        sync.set_attribute_single(0x2A, 1, 7, 7, INT)
        assert sync.read(0x2A, 1, 7, INT) == 7


@pytest.mark.parametrize("path", [(1, 1, 99), (0x2A, 1, 8)], ids=["identity-99", "tag-attribute-8"])
def test_cpppo_missing_attribute_answers_service_not_supported(scanner: SyncScanner, path: tuple[int, int, int]
                                                                ) -> None:
    """cpppo deviation: a missing attribute answers 0x08 (a conformant target answers 0x14)."""
    with pytest.raises(CipError) as caught:
        scanner.get_attribute_single(*path)
    assert caught.value.general == 0x08
    assert scanner.get_attribute_single(1, 1, 1).value == 1  # the session survives


def test_cpppo_missing_class_drops_the_session(scanner: SyncScanner) -> None:
    """cpppo deviation: a missing class answers encapsulation status 8 and closes the connection."""
    with pytest.raises(EncapsulationStatusError) as caught:
        scanner.get_attribute_single(0x77, 1, 1)
    assert caught.value.status == 0x0008
    assert caught.value.command == 0x006F
    with pytest.raises(ConnectionError):
        scanner.get_attribute_single(1, 1, 1)


def test_encapsulation_client_against_cpppo(cpppo_server: PeerProcess) -> None:
    host, port = parse_host(cpppo_server.address)

    async def run() -> tuple[Any, Any, Any]:
        client = await EncapsulationClient.connect(host, port, 5.0, register=False)
        try:
            return await client.list_services(), await client.list_identity(), await discover(host, port, 1.0)
        finally:
            await client.close()

    services, identities, discovered = asyncio.run(run())
    assert [(s.version, s.name, s.cip_over_tcp) for s in services] == [(1, "Communications", True)]
    for records in (identities, discovered):
        assert len(records) == 1
        record = records[0]
        assert (record.vendor_id, record.device_type, record.product_code, record.revision) == (1, 14, 54, (20, 11))
        assert (record.serial_number, record.product_name) == (7079450, "1756-L61/B LOGIX5561")
        # cpppo deviation: its ListIdentity always says 0.0.0.0:44818, wherever it listens
        assert record.address is not None
        assert (record.address.host, record.address.port) == ("0.0.0.0", 44818)
