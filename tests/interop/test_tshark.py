"""Wireshark's dissectors judge what our adapter and scanner put on the wire.

The whole exchange runs in a private network namespace, so the adapter can use the default
port 44818 (where tshark pairs requests with replies and decodes class 3 traffic) without
colliding with anything. In it: tshark captures loopback; our adapter listens on 127.0.0.1
and cpppo's server on 127.0.0.2; pycomm3, cpppo's tools and our scanner talk to the adapter,
and our scanner to cpppo (the steps that wait out a window, and write nothing, beside the others:
``BESIDE``). Then tshark reads the capture back.
"""

from __future__ import annotations

import json
import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from .conftest import IDENTITY
from .netns import JUDGED

# One capture for the whole module (its fixture), and one capturing module at a time (docs/contributing.md).
pytestmark = [pytest.mark.tshark, pytest.mark.interop, pytest.mark.xdist_group("tshark")]

ADAPTER_HOST = "127.0.0.1"
CPPPO_HOST = "127.0.0.2"
EXCHANGE_TIMEOUT = 90.0

HELPER = r'''
import asyncio
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
import traceback
from pathlib import Path

from waiting import wait_for  # tests/waiting.py, copied next to this script

OUT = Path(sys.argv[1])
PY = sys.executable
PORT = 44818
ADAPTER = "127.0.0.1"
CPPPO = "127.0.0.2"
seen = {"errors": []}


def log_text(name):
    path = OUT / f"{name}.log"
    return path.read_text(errors="replace") if path.exists() else ""


def bound(table, host, state):
    """Whether /proc/net/<table> lists host:PORT in the given state (no probe packet on the wire)."""
    local = f"{socket.inet_aton(host)[::-1].hex().upper()}:{PORT:04X}"
    with open(f"/proc/net/{table}") as lines:
        return any(fields[1] == local and fields[3] == state for fields in (line.split() for line in lines))


def listening(host):
    return bound("tcp", host, "0A") and bound("udp", host, "07")


def start(name, command):
    with (OUT / f"{name}.log").open("wb") as out:
        return subprocess.Popen(command, stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                env=dict(os.environ, PYTHONUNBUFFERED="1"))


def stop(process, sig):
    if process.poll() is None:
        os.kill(process.pid, sig)
        try:
            process.wait(10)
        except subprocess.TimeoutExpired:
            os.kill(process.pid, signal.SIGKILL)
            process.wait(5)
    return process.returncode


def tool(*args):
    result = subprocess.run([PY, "-m", *args], capture_output=True, text=True, timeout=30, check=False)
    return {"rc": result.returncode, "out": result.stdout, "err": result.stderr}


def step(name, function):
    try:
        seen[name] = function()
    except Exception:
        seen["errors"].append(f"{name}: {traceback.format_exc()}")


def pycomm3_exchange():
    from pycomm3 import CIPDriver, Services
    from pycomm3.cip import PADDED_EPATH, PortSegment
    from pycomm3.cip.data_types import SHORT_STRING, UDINT, UINT

    def get(drv, cls, inst, attr, data_type=None, connected=False):
        options = {"connected": True} if connected else {"connected": False, "route_path": False}
        tag = drv.generic_message(service=Services.get_attribute_single, class_code=cls, instance=inst,
                                  attribute=attr, data_type=data_type, **options)
        return [tag.value if not isinstance(tag.value, bytes) else tag.value.hex(), tag.error]

    def put(drv, cls, inst, attr, data, connected=False):
        options = {"connected": True} if connected else {"connected": False, "route_path": False}
        tag = drv.generic_message(service=Services.set_attribute_single, class_code=cls, instance=inst,
                                  attribute=attr, request_data=data, **options)
        return tag.error

    result = {}
    identity = CIPDriver.list_identity(ADAPTER)
    result["list_identity"] = {k: (v.hex() if isinstance(v, bytes) else v) for k, v in (identity or {}).items()}
    types = {1: UINT, 2: UINT, 3: UINT, 6: UDINT, 7: SHORT_STRING}
    with CIPDriver(ADAPTER) as drv:
        result["unconnected"] = {a: get(drv, 1, 1, a, t) for a, t in types.items()}
        result["missing_attribute"] = get(drv, 1, 1, 99)
        result["missing_class"] = get(drv, 0x77, 1, 1)
        result["set"] = put(drv, 0xF5, 1, 13, UINT.encode(60))
        result["read_back"] = get(drv, 0xF5, 1, 13, UINT)
        result["routed"] = drv.generic_message(
            service=Services.get_attribute_single, class_code=1, instance=1, attribute=7, data_type=SHORT_STRING,
            connected=False, unconnected_send=True, route_path=True).value
        bad_route = PADDED_EPATH.encode((PortSegment("bp", 1),), length=True, pad_length=True)
        result["bad_route"] = drv.generic_message(
            service=Services.get_attributes_all, class_code=1, instance=1, connected=False, unconnected_send=True,
            route_path=bad_route).error
    for large in (True, False):
        drv = CIPDriver(ADAPTER)
        drv._cfg["extended forward open"] = large  # internals: pycomm3 has no public switch for it
        drv.open()
        try:
            result[f"connected_large_{large}"] = {
                "name": get(drv, 1, 1, 7, SHORT_STRING, connected=True),
                "missing_attribute": get(drv, 1, 1, 99, connected=True),
                "set": put(drv, 0xF5, 1, 13, UINT.encode(120), connected=True),
                "read_back": get(drv, 0xF5, 1, 13, UINT, connected=True),
            }
        finally:
            drv.close()
    return result


GET_ATTRIBUTE = "cpppo.server.enip.get_attribute"


def cpppo_exchange():
    return {
        "routed": tool(GET_ATTRIBUTE, "-a", ADAPTER, "@1/1/1", "@1/1/7", "@0xF5/1/13=(UINT)90", "@0xF5/1/13"),
        "simple": tool(GET_ATTRIBUTE, "-S", "-a", ADAPTER, "@1/1/7", "@0xF5/1/13=(UINT)120", "@0xF5/1/13"),
    }


LIST_SERVICES = "cpppo.server.enip.list_services"


async def connection_manager_errors():
    """Forward_Open / Forward_Close refusals from our client, so tshark sees the CM error replies."""
    from cipstack.cip.epath import request_path
    from cipstack.eip.wire.cm_messages import (ConnectionTriad, ForwardCloseRequest, ForwardOpenRequest,
                                          NetworkParameters, TransportTrigger, TriggerType)
    from cipstack.eip.wire.cm_messages import CONNECTION_MANAGER_PATH
    from cipstack.eip.originator.asyncio_client import MESSAGE_ROUTER_PATH, EncapsulationClient

    def forward_open(triad, transport_class=3, path=MESSAGE_ROUTER_PATH, large=False):
        params = NetworkParameters(500, variable=True)
        return ForwardOpenRequest(
            priority_tick=0x0A, timeout_ticks=0x0E, ot_connection_id=0, to_connection_id=0x1111, triad=triad,
            timeout_multiplier=1, ot_rpi_us=2_000_000, ot_parameters=params, to_rpi_us=2_000_000,
            to_parameters=params, transport=TransportTrigger(transport_class, TriggerType.APPLICATION, server=True),
            connection_path=path, large=large).encode()

    client = await EncapsulationClient.connect(ADAPTER, PORT)
    triad = ConnectionTriad(0x4242, 0xFFFE, 0x12345678)
    close = ForwardCloseRequest(0x0A, 0x0E, triad, MESSAGE_ROUTER_PATH).encode()
    requests = [
        ("close_unknown", 0x4E, close),
        ("transport_class_2", 0x54, forward_open(triad, 2)),
        ("open", 0x54, forward_open(triad)),
        ("open_again", 0x54, forward_open(triad)),
        ("bad_application_path", 0x5B, forward_open(ConnectionTriad(0x4243, 0xFFFE, 1), 3, request_path(0x77, 1),
                                                    large=True)),
        ("close", 0x4E, close),
    ]
    result = {}
    try:
        for name, service, data in requests:
            reply = await client.request(service, CONNECTION_MANAGER_PATH, data, connected=False)
            result[name] = [reply.general_status, list(reply.extended_status)]
    finally:
        await client.close()
    return result


def ours_exchange():
    from cipstack.cip.status import CipError
    from cipstack.cip.types import INT, UINT
    from cipstack.scanner import SyncScanner, backplane_route

    def error_of(function, *args):
        try:
            function(*args)
        except CipError as exc:
            return exc.general
        return None

    result = {}
    with SyncScanner(f"{ADAPTER}:{PORT}") as scanner:
        result["unconnected"] = {a: scanner.get_attribute_single(1, 1, a).data.hex() for a in range(1, 8)}
        result["missing_attribute"] = error_of(scanner.get_attribute_single, 1, 1, 99)
        result["missing_class"] = error_of(scanner.get_attribute_single, 0x77, 1, 1)
        result["all"] = scanner.get_attributes_all(1, 1)[0].hex()
        scanner.set_attribute_single(0xF5, 1, 13, 120, UINT)
        result["read_back"] = scanner.read(0xF5, 1, 13).raw
        for large in (True, False):
            scanner.open_connection(large=large)
            result[f"connected_large_{large}"] = [scanner.read(1, 1, 7).raw,
                                                  error_of(scanner.get_attribute_single, 1, 1, 99)]
            scanner.close_connection()
        result["list_services"] = [s.name for s in scanner.list_services()]
        result["list_identity"] = [r.product_name for r in scanner.list_identity()]
    with SyncScanner(f"{ADAPTER}:{PORT}", route=backplane_route()) as scanner:
        result["routed"] = scanner.read(1, 1, 7).raw
    result["cm_errors"] = asyncio.run(connection_manager_errors())
    with SyncScanner(f"{CPPPO}:{PORT}") as scanner:
        result["cpppo_list_services"] = [s.name for s in scanner.list_services()]
        scanner.set_attribute_single(0x2A, 1, 7, 1500, INT)
        result["cpppo_tag"] = scanner.read(0x2A, 1, 7, INT).raw
        scanner.open_connection()
        result["cpppo_connected"] = scanner.read(1, 1, 7).raw
    return result


def our_discover():
    from cipstack.eip.originator.asyncio_client import discover

    return [(r.product_name, r.address.port) for r in asyncio.run(discover(ADAPTER, PORT, 1.0))]


def our_list_services_udp():
    from cipstack.eip.originator.asyncio_client import list_services_udp

    return [s.name for s in asyncio.run(list_services_udp(ADAPTER, PORT, 1.0))]


#: Steps that wait out a window or a timeout (ours collect the replies of 1 s; cpppo's tool over UDP, which
#: has no end of replies, listens out its 3 s timeout after the last) and touch nothing the others write
#: (attribute 0xF5/1/13): each in a thread of its own while the exchanges run, its finding kept under
#: the exchange it belongs to, as (exchange, name, step).
BESIDE = [
    ("cpppo", "error", lambda: tool(GET_ATTRIBUTE, "-S", "-a", ADAPTER, "@1/1/99")),
    ("cpppo", "list_tcp", lambda: tool(LIST_SERVICES, "-a", ADAPTER, "-i")),
    ("cpppo", "list_udp", lambda: tool(LIST_SERVICES, "-a", ADAPTER, "-i", "-u", "-t", "3")),
    ("ours", "discover", our_discover),
    ("ours", "list_services_udp", our_list_services_udp),
]


tshark = subprocess.Popen(["tshark", "-i", "lo", "-f", f"tcp port {PORT} or udp port {PORT}",
                           "-w", str(OUT / "capture.pcapng"), "-q"],
                          stdout=subprocess.DEVNULL, stderr=(OUT / "tshark.log").open("wb"))
servers = []
try:
    wait_for(lambda: "Capturing on" in log_text("tshark") or tshark.poll() is not None, 30, "tshark")
    if tshark.poll() is not None:
        raise RuntimeError(f"tshark exited: {log_text('tshark')}")
    adapter = start("adapter", [PY, "-m", "cipstack", "adapter", "--host", ADAPTER, "--port", str(PORT)])
    cpppo = start("cpppo", [PY, "-m", "cpppo.server.enip", "--address", f"{CPPPO}:{PORT}", "Speed@0x2A/1/7=INT"])
    servers = [("adapter", adapter), ("cpppo", cpppo)]
    wait_for(lambda: listening(ADAPTER), 20, "the adapter")
    wait_for(lambda: listening(CPPPO), 20, "the cpppo server")
    beside = [threading.Thread(target=step, args=(f"{owner}/{name}", function)) for owner, name, function in BESIDE]
    for thread in beside:
        thread.start()
    step("pycomm3", pycomm3_exchange)
    step("cpppo", cpppo_exchange)
    step("ours", ours_exchange)
    for thread in beside:
        thread.join(60)
    for owner, name, _ in BESIDE:
        if f"{owner}/{name}" in seen:
            seen.setdefault(owner, {})[name] = seen.pop(f"{owner}/{name}")
except Exception:
    seen["errors"].append(traceback.format_exc())
finally:
    for name, process in servers:
        seen[f"{name}_alive"] = process.poll() is None
        seen[f"{name}_exit"] = stop(process, signal.SIGTERM)
    time.sleep(0.5)  # the capturer reads its ring on its own time: no event says it has the last frames
    seen["tshark_exit"] = stop(tshark, signal.SIGINT)
    seen["adapter_log"] = log_text("adapter")
    (OUT / "seen.json").write_text(json.dumps(seen, indent=1, default=repr))
'''


def tshark_read(capture: Path, display_filter: str, *fields: str) -> str:
    command = ["tshark", "-r", str(capture), "-Y", display_filter]
    if fields:
        command += ["-T", "fields", "-E", "separator=|", "-E", "occurrence=a", "-E", "aggregator=,"]
        for field in fields:
            command += ["-e", field]
    result = subprocess.run(command, capture_output=True, text=True, timeout=60, check=False)
    assert result.returncode == 0, f"tshark -Y {display_filter!r} failed: {result.stderr}"
    return result.stdout


def numbers(text: str) -> list[int]:
    return [int(part, 0) for part in text.split(",") if part]


FIELDS = ("frame.number", "ip.src", "ip.dst", "udp.srcport", "tcp.srcport", "enip.command", "enip.status",
          "cip.service", "cip.genstat", "enip.lir.name", "enip.lir.vendor", "enip.sinport", "enip.lsr.servicename")


def dissect(capture: Path, display_filter: str) -> list[dict[str, str]]:
    rows = []
    for line in tshark_read(capture, display_filter, *FIELDS).splitlines():
        rows.append(dict(zip(FIELDS, line.split("|"), strict=True)))
    return rows


@pytest.fixture(scope="module")
def exchange(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    missing = [tool for tool in ("tshark", "unshare") if shutil.which(tool) is None]
    if missing:
        pytest.skip(f"{' and '.join(missing)} not installed")
    if os.geteuid() != 0:
        pytest.skip("a private network namespace (unshare -n) and a loopback capture need root")
    assert shutil.which("ip") is not None, "iproute2's ip is needed to bring up lo in the namespace"
    out = tmp_path_factory.mktemp("tshark")
    script = out / "exchange.py"
    script.write_text(HELPER)
    shutil.copy(Path(__file__).parents[1] / "waiting.py", out / "waiting.py")
    command = " ".join(shlex.quote(str(part)) for part in (sys.executable, script, out))
    inner = f"ip link set lo up && exec {command}"
    result = subprocess.run(["unshare", "-n", "sh", "-c", inner], capture_output=True, text=True,
                            timeout=EXCHANGE_TIMEOUT, check=False, cwd=out)
    assert result.returncode == 0, f"exchange failed ({result.returncode}):\n{result.stdout}\n{result.stderr}"
    seen = json.loads((out / "seen.json").read_text())
    capture = out / "capture.pcapng"
    assert capture.exists() and capture.stat().st_size > 0, (out / "tshark.log").read_text()
    return capture, seen


def test_every_client_got_the_right_answers(exchange: tuple[Path, dict[str, Any]]) -> None:
    _, seen = exchange
    assert seen["errors"] == [], "\n".join(seen["errors"])
    assert seen["adapter_alive"] and seen["adapter_exit"] == 0, seen["adapter_log"]
    assert "Traceback" not in seen["adapter_log"], seen["adapter_log"]
    assert seen["tshark_exit"] == 0

    pycomm3 = seen["pycomm3"]
    assert pycomm3["list_identity"]["product_name"] == IDENTITY["product_name"]
    assert pycomm3["list_identity"]["product_code"] == IDENTITY["product_code"]
    assert pycomm3["unconnected"] == {
        "1": [259, None], "2": [2, None], "3": [100, None], "6": [IDENTITY["serial_number"], None],
        "7": ["CENT", None]}
    assert pycomm3["missing_attribute"] == ["", "Attribute not supported"]
    assert pycomm3["missing_class"][1].endswith("(05, 00)")
    assert pycomm3["set"] is None and pycomm3["read_back"] == [60, None]
    assert pycomm3["routed"] == "CENT"
    assert pycomm3["bad_route"].endswith("(01, 312)"), pycomm3["bad_route"]
    for large in (True, False):
        assert pycomm3[f"connected_large_{large}"] == {
            "name": ["CENT", None], "missing_attribute": ["", "Attribute not supported"], "set": None,
            "read_back": [120, None]}

    cpppo = seen["cpppo"]
    for name in ("routed", "simple", "list_tcp", "list_udp"):
        assert cpppo[name]["rc"] == 0, cpppo[name]
    assert "@0x0001/1/7 == [4, 67, 69, 78, 84]" in cpppo["routed"]["out"]
    assert "@0x00F5/1/13 == [90, 0]" in cpppo["routed"]["out"]
    assert "@0x00F5/1/13 == [120, 0]" in cpppo["simple"]["out"]
    assert cpppo["error"]["rc"] != 0 and "@0x0001/1/99 == None" in cpppo["error"]["out"]
    for name in ("list_tcp", "list_udp"):
        assert "'enip.CIP.list_identity.CPF.item[0].identity_object.product_name': 'CENT'," in cpppo[name]["out"]
        assert "communications_service.service_name': 'Communications'," in cpppo[name]["out"]
        assert "identity_object.sin_port': 44818," in cpppo[name]["out"]

    ours = seen["ours"]
    assert ours["unconnected"]["1"] == "0301" and ours["unconnected"]["7"] == "0443454e54"
    assert ours["missing_attribute"] == 0x14 and ours["missing_class"] == 0x05
    assert ours["all"].startswith("0301020064000101")
    assert ours["read_back"] == 120
    assert ours["connected_large_True"] == ours["connected_large_False"] == ["CENT", 0x14]
    assert ours["list_services"] == ours["list_services_udp"] == ["Communications"]
    assert ours["list_identity"] == ["CENT"]
    assert ours["routed"] == "CENT"
    assert ours["discover"] == [["CENT", 44818]]
    assert ours["cm_errors"] == {
        "close_unknown": [0x01, [0x0107]], "transport_class_2": [0x01, [0x0103]], "open": [0, []],
        "open_again": [0x01, [0x0100]], "bad_application_path": [0x01, [0x0117]], "close": [0, []]}
    assert ours["cpppo_list_services"] == ["Communications"]
    assert ours["cpppo_tag"] == 1500
    assert ours["cpppo_connected"] == "1756-L61/B LOGIX5561"


ADAPTER_TRAFFIC = f"!(ip.addr == {CPPPO_HOST})"


def test_no_malformed_packet_and_no_expert_warning(exchange: tuple[Path, dict[str, Any]]) -> None:
    """Everything but cpppo's own replies must dissect cleanly: all of the adapter and all of our requests."""
    capture, _ = exchange
    assert tshark_read(capture, "enip").strip(), "tshark decoded no EtherNet/IP at all"
    judged = f"({JUDGED}) && !(ip.src == {CPPPO_HOST})"
    assert tshark_read(capture, judged) == ""
    # the judge bites: cpppo's 19-byte ListServices item (a known deviation) is flagged
    control = tshark_read(capture, f"_ws.malformed && ip.src == {CPPPO_HOST} && enip.command == 0x0004")
    assert control.strip(), "tshark did not flag cpppo's short ListServices item: is the judge filter working?"


def test_encapsulation_commands_over_tcp_and_udp(exchange: tuple[Path, dict[str, Any]]) -> None:
    capture, _ = exchange
    replies = dissect(capture, f"enip && ip.src == {ADAPTER_HOST} && ({ADAPTER_TRAFFIC}) "
                               "&& (tcp.srcport == 44818 || udp.srcport == 44818)")
    assert replies
    # one TCP segment may carry several encapsulation messages: fields then hold one value per message
    bad = [r for r in replies if any(numbers(r["enip.status"]))]
    assert not bad, f"encapsulation replies with a non-zero status: {bad}"
    for transport in ("udp", "tcp"):
        port_field = f"{transport}.srcport"
        identity = [r for r in replies if r[port_field] == "44818" and 0x63 in numbers(r["enip.command"])]
        assert identity, f"no ListIdentity reply over {transport.upper()}"
        for reply in identity:
            assert set(reply["enip.lir.name"].split(",")) == {IDENTITY["product_name"]}, reply
            assert set(numbers(reply["enip.lir.vendor"])) == {IDENTITY["vendor_id"]}, reply
            assert set(numbers(reply["enip.sinport"])) == {44818}, reply
        services = [r for r in replies if r[port_field] == "44818" and 0x04 in numbers(r["enip.command"])]
        assert services, f"no ListServices reply over {transport.upper()}"
        assert all(set(r["enip.lsr.servicename"].split(",")) == {"Communications"} for r in services), services
    commands = {command for r in replies for command in numbers(r["enip.command"])}
    assert {0x04, 0x63, 0x65, 0x6F, 0x70} <= commands, commands


def messages(row: dict[str, str]) -> list[tuple[int, list[int], list[int]]]:
    """(command, CIP services, general statuses) of each encapsulation message in one frame.

    A frame normally holds one message; when a segment holds several of one command, the
    services and statuses are split evenly between them.
    """
    commands = numbers(row["enip.command"])
    services, statuses = numbers(row["cip.service"]), numbers(row["cip.genstat"])
    if len(commands) == 1:
        return [(commands[0], services, statuses)]
    assert len(services) % len(commands) == 0 and len(statuses) % len(commands) == 0, row
    ns, nt = len(services) // len(commands), len(statuses) // len(commands)
    return [(c, services[i * ns:(i + 1) * ns], statuses[i * nt:(i + 1) * nt]) for i, c in enumerate(commands)]


def test_cip_exchanges_decode(exchange: tuple[Path, dict[str, Any]]) -> None:
    """Forward_Open (small and large), Forward_Close, class 3 and unconnected Get/Set, errors."""
    capture, _ = exchange
    rows = dissect(capture, f"cip && ({ADAPTER_TRAFFIC})")
    requests = [m for r in rows if r["ip.dst"] == ADAPTER_HOST and r["tcp.srcport"] != "44818" for m in messages(r)]
    replies = [m for r in rows if r["tcp.srcport"] == "44818" for m in messages(r)]
    request_services = {(command, service) for command, services, _ in requests for service in services}
    for expected in [(0x6F, 0x54), (0x6F, 0x5B), (0x6F, 0x4E), (0x6F, 0x0E), (0x6F, 0x10), (0x6F, 0x01),
                     (0x6F, 0x52), (0x70, 0x0E), (0x70, 0x10)]:
        assert expected in request_services, f"no request (command, service) {expected} decoded as CIP"
    assert all(statuses for _, _, statuses in replies), "a CIP reply without a general status"
    reply_status = {(command, services[-1], statuses[-1]) for command, services, statuses in replies}
    for expected in [(0x6F, 0xD4, 0), (0x6F, 0xDB, 0), (0x6F, 0xCE, 0), (0x6F, 0x8E, 0), (0x6F, 0x90, 0),
                     (0x6F, 0x81, 0), (0x70, 0x8E, 0), (0x70, 0x90, 0), (0x6F, 0x8E, 0x14), (0x6F, 0x8E, 0x05),
                     (0x70, 0x8E, 0x14), (0x6F, 0xD2, 0x01), (0x6F, 0xD4, 0x01), (0x6F, 0xDB, 0x01),
                     (0x6F, 0xCE, 0x01)]:
        assert expected in reply_status, f"no reply (command, service, status) {expected} decoded as CIP"
    for command in (0x6F, 0x70):
        sent = sum(1 for c, _, _ in requests if c == command)
        answered = sum(1 for c, _, _ in replies if c == command)
        assert sent == answered, f"command 0x{command:04X}: {sent} CIP requests, {answered} CIP replies"
