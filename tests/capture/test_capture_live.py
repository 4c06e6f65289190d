"""Real traffic, recorded and analysed: our scanner, pycomm3 and python-ethernetip with the ACG
emulator in a private network namespace (44818 and 2222 are free there), captured by dumpcap;
``capture analyze`` is checked frame by frame against tshark's dissection of the same file and
against what the run knows (the RPI asked, the frames sent, the trip injected)."""

from __future__ import annotations

import itertools
import json
import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

# One capture for the whole module (its fixture), and one capturing module at a time (docs/contributing.md).
pytestmark = [pytest.mark.interop, pytest.mark.tshark, pytest.mark.xdist_group("tshark")]

ADAPTER_HOST = "127.0.0.2"
TRIP_CODE = 0x4200  # OverHeat (tests/test_cli.py)

HELPER = r'''
import asyncio, json, signal, socket, subprocess, sys, time, traceback
from pathlib import Path

OUT = Path(sys.argv[1])
PY = sys.executable
ADAPTER = "127.0.0.2"
GATEWAY = "127.0.0.3"
seen = {"errors": []}


def listening(host=ADAPTER):
    local = f"{socket.inet_aton(host)[::-1].hex().upper()}:{44818:04X}"
    with open("/proc/net/tcp") as lines:
        return any(f[1] == local and f[3] == "0A" for f in (line.split() for line in lines))


def wait_for(predicate, timeout, what):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return
        time.sleep(0.05)
    raise RuntimeError(f"timed out waiting for {what}")


async def ours():
    from cipstack.cip.status import CipError
    from cipstack.cip.types import UINT
    from cipstack.control import control_request
    from cipstack.devices.profiles import catalog_for
    from cipstack.scanner import Scanner

    scanner = await Scanner.connect(f"{ADAPTER}:44818", catalog=catalog_for(259, 100))
    async with scanner:
        await scanner.get_attributes_all(0x01, 1)  # the identity the analysis picks the profile by
        await scanner.get_attribute_single(0x01, 1, 7)
        try:
            await scanner.set_attribute_single(0x01, 1, 1, 5, UINT)  # Vendor ID is read-only: refused
        except CipError as exc:
            seen["refused_status"] = exc.general
        await scanner.open_connection()  # class 3: SendUnitData with CIP sequence counts
        await scanner.get_attribute_single(0x01, 1, 3)
        await scanner.close_connection()
        async with scanner.io_connection(output=21, input=71, rpi=0.010, local_io_port=2222,
                                         timeout_multiplier=4) as owner:
            await asyncio.sleep(0.5)   # the subject: a run of class 1 frames to time (the RPI's p50)
            reply = await asyncio.to_thread(control_request, OUT / "control.sock",
                                            {"command": "trip", "code": int(sys.argv[2])})
            seen["trip"] = reply.get("result")
            await owner.wait_input(lambda i: i.faulted, 5)
            await asyncio.sleep(0.3)   # the subject: the tripped drive's input on the wire
            stats = owner.stats.as_dict()
    # A request routed through the CompoNet gateway (port 2) to the MX2 at node 5.
    from cipstack.cip.epath import PortSegment

    gateway = await Scanner.connect(f"{GATEWAY}:44818", route=[PortSegment(2, bytes([5]))], identify=False)
    async with gateway:
        vendor = await gateway.get_attribute_single(0x01, 1, 1)
    return {"owner": stats, "routed_vendor": repr(vendor)}


def pycomm3_exchange():
    from pycomm3 import CIPDriver

    with CIPDriver(f"{ADAPTER}:44818") as driver:
        tag = driver.generic_message(service=0x0E, class_code=0x01, instance=1, attribute=1,
                                     name="vendor")
        bad = driver.generic_message(service=0x0E, class_code=0x01, instance=1, attribute=99,
                                     name="missing")
    return {"vendor": int.from_bytes(tag.value, "little"), "missing_error": bool(bad.error)}


def ethernetip_exchange():
    import ethernetip
    import ethernetip.ethernetip as module
    from cipstack.cip.types import UINT
    from cipstack.devices.acg.registers import CLASS_64_INSTANCES
    from cipstack.scanner import SyncScanner

    cm = CLASS_64_INSTANCES["CM"]
    with SyncScanner(f"{ADAPTER}:44818") as scanner:      # CM.24/CM.23 = 0: 20/70, applied by CM.94
        scanner.set_attribute_single(0x64, cm, 24, 0, UINT)
        scanner.set_attribute_single(0x64, cm, 23, 0, UINT)
        scanner.set_attribute_single(0x64, cm, 94, 1, UINT)
    module.ENIP_TCP_PORT, module.ENIP_UDP_PORT = 44818, 2222
    enip = ethernetip.EtherNetIP(ADAPTER)
    conn = enip.explicit_conn(ADAPTER)
    conn.registerSession()
    inputs = enip.registerAssembly(ethernetip.EtherNetIP.ENIP_IO_TYPE_INPUT, 4, 70, conn)
    enip.registerAssembly(ethernetip.EtherNetIP.ENIP_IO_TYPE_OUTPUT, 4, 20, conn)
    enip.startIO(0)
    port = enip.originator_udp_port
    status = conn.sendFwdOpenReq(70, 20, 1, torpi=20, otrpi=20, multiplier=1, inputsz=4, outputsz=4,
                                 originator_udp_port=port)
    conn.produce()
    time.sleep(0.4)                   # the subject: the peer's frames at its RPI, to capture
    conn.stopProduce()  # and no Forward_Close: the connection times out (20 ms x 4 x 2^1 = 160 ms)
    from cipstack.control import control_request

    wait_for(lambda: control_request(OUT / "control.sock", {"command": "status"})["class1_connections"] == 0, 5,
             "the adapter to time the connection out")
    enip.stopIO()
    return {"forward_open": status, "port": port}


dump = subprocess.Popen(["dumpcap", "-i", "lo", "-f", "tcp port 44818 or udp", "-w", str(OUT / "capture.pcapng"),
                         "-q"], stdout=subprocess.DEVNULL, stderr=(OUT / "dumpcap.log").open("wb"))
adapter = gateway = None
try:
    wait_for(lambda: "Capturing on" in (OUT / "dumpcap.log").read_text(errors="replace"), 30, "dumpcap")
    adapter = subprocess.Popen([PY, "-m", "cipstack", "adapter", "--host", ADAPTER, "--quiet",
                                "--state", str(OUT / "state.json"), "--control", str(OUT / "control.sock")],
                               stdout=(OUT / "adapter.log").open("wb"), stderr=subprocess.STDOUT)
    gateway = subprocess.Popen([PY, "-m", "cipstack", "componet", "--host", GATEWAY, "--quiet", "--nodes",
                                "mx2:MX2-A2015-E@5", "--io-port", "2223", "--control", str(OUT / "gateway.sock")],
                               stdout=(OUT / "gateway.log").open("wb"), stderr=subprocess.STDOUT)
    wait_for(listening, 20, "the adapter")
    wait_for(lambda: listening(GATEWAY), 20, "the CompoNet gateway")
    for name, job in (("ours", lambda: asyncio.run(ours())), ("pycomm3", pycomm3_exchange),
                      ("ethernetip", ethernetip_exchange)):
        try:
            seen[name] = job()
        except Exception:
            seen["errors"].append(name + ": " + traceback.format_exc())
finally:
    for name, process in (("adapter", adapter), ("gateway", gateway)):
        if process is not None:
            process.send_signal(signal.SIGTERM)
            seen[name + "_exit"] = process.wait(10)
    time.sleep(0.5)  # the capturer reads its ring on its own time: no event says it has the last frames
    dump.send_signal(signal.SIGINT)
    dump.wait(20)
    (OUT / "seen.json").write_text(json.dumps(seen, indent=1))
'''


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    missing = [tool for tool in ("tshark", "dumpcap", "unshare", "ip") if shutil.which(tool) is None]
    if missing:
        pytest.skip(f"{' and '.join(missing)} not installed")
    if os.geteuid() != 0:
        pytest.skip("a private network namespace (unshare -n) and a loopback capture need root")
    out = tmp_path_factory.mktemp("capture-live")
    script = out / "exchange.py"
    script.write_text(HELPER)
    command = " ".join(shlex.quote(str(part)) for part in (sys.executable, script, out, TRIP_CODE))
    result = subprocess.run(["unshare", "-n", "sh", "-c", f"ip link set lo up && exec {command}"],
                            capture_output=True, text=True, timeout=120, check=False, cwd=out,
                            env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])})
    assert result.returncode == 0, f"{result.stdout}\n{result.stderr}"
    seen = json.loads((out / "seen.json").read_text())
    assert not seen["errors"], "\n".join(seen["errors"])
    return out / "capture.pcapng", seen


def analyze(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "cipstack", "capture", "analyze", *args], capture_output=True,
                          text=True, timeout=120, check=False)


@pytest.fixture(scope="module")
def analysis(recorded: tuple[Path, dict[str, Any]]) -> list[dict[str, Any]]:
    path, _ = recorded
    result = analyze(str(path), "--json")
    assert result.returncode == 0, result.stderr
    return [json.loads(line) for line in result.stdout.splitlines()]


def tshark_fields(path: Path, display_filter: str, fields: tuple[str, ...], *options: str) -> list[list[str]]:
    command = ["tshark", "-r", str(path), *options, "-Y", display_filter, "-T", "fields", "-E", "separator=|"]
    for name in fields:
        command += ["-e", name]
    result = subprocess.run(command, capture_output=True, text=True, timeout=60, check=False)
    assert result.returncode == 0, result.stderr
    return [line.split("|") for line in result.stdout.splitlines() if line.strip()]


def test_explicit_exchanges_match_tshark_frame_by_frame(recorded: tuple[Path, dict[str, Any]],
                                                        analysis: list[dict[str, Any]]) -> None:
    path, _ = recorded
    # Every CIP reply tshark sees over TCP: frame, session, service, general status.
    from cipstack.eip.wire.encapsulation import Command

    rows = tshark_fields(path, "tcp && cip && enip.command != 0x0065",
                         ("frame.number", "enip.command", "enip.session", "cip.service", "cip.genstat",
                          "enip.cpf.itemcount"))
    theirs = {}
    for frame, command, session, service, status, items in rows:
        services = [int(s, 16) for s in service.split(",")]
        statuses = [int(s, 0) for s in status.split(",")] if status else []
        if services[0] & 0x80:
            theirs[int(frame)] = (int(command, 16), int(session, 16), int(items), services[0] & 0x7F, statuses[0])
    ours = {r["reply_frame"]: (Command[r["command"]].value, r["session"], len(r["reply_items"]), r["reply"]["service"],
                               r["reply"]["status"])
            for r in analysis if r["type"] == "explicit" and "reply_frame" in r}
    assert theirs, "tshark found no CIP reply"
    assert ours == theirs
    requests = {int(f[0]) for f in tshark_fields(path, "tcp && cip.rr == 0 && enip.command != 0x0065",
                                                 ("frame.number",))}
    assert {r["request_frame"] for r in analysis if r["type"] == "explicit" and "request_frame" in r} == requests


def test_known_errors_are_named(recorded: tuple[Path, dict[str, Any]], analysis: list[dict[str, Any]]) -> None:
    _, seen = recorded
    errors = [r for r in analysis if r.get("error")]
    by_status = {r["reply"]["status"]: r for r in errors}
    from cipstack.cip.status import describe_status

    refused = by_status[seen["refused_status"]]
    assert refused["request"]["service_name"] == "Set_Attribute_Single"
    assert refused["request"]["attribute_name"] == "Vendor ID"
    assert refused["reply"]["status_name"] == describe_status(seen["refused_status"])
    assert seen["pycomm3"]["missing_error"] and 0x14 in by_status
    names = [r for r in analysis if r["type"] == "explicit" and r.get("request", {}).get("attribute") == 7
             and r["request"].get("class") == 1 and not r.get("error")]
    assert names and names[0]["reply"]["data"]["value"] == "CENT"


def test_class1_connections_match_tshark_and_the_run(recorded: tuple[Path, dict[str, Any]],
                                                     analysis: list[dict[str, Any]]) -> None:
    path, seen = recorded
    connections = [r for r in analysis if r["type"] == "connection"]
    port = seen["ethernetip"]["port"]
    decode = ("-d", f"udp.port=={port},cipio")
    frames = tshark_fields(path, "cipio", ("enip.cpf.sai.connid", "enip.cpf.sai.seq"), *decode)
    per_id: dict[int, int] = {}
    sequences: dict[int, list[int]] = {}
    for conn_id, seq in frames:
        per_id[int(conn_id, 16)] = per_id.get(int(conn_id, 16), 0) + 1
        sequences.setdefault(int(conn_id, 16), []).append(int(seq))
    opened = [c for c in connections if not c["end_reason"].startswith("refused")]
    assert len(opened) == 2, [c["end_reason"] for c in connections]
    for connection in opened:
        assert connection["o_t"]["frames"] == per_id[connection["o_t_id"]]
        assert connection["t_o"]["frames"] == per_id[connection["t_o_id"]]
        for key, conn_id in (("o_t", connection["o_t_id"]), ("t_o", connection["t_o_id"])):
            seqs = sequences[conn_id]
            gaps = sum(max(0, b - a - 1) for a, b in itertools.pairwise(seqs))
            duplicates = sum(1 for a, b in itertools.pairwise(seqs) if a == b)
            assert (connection[key]["lost"], connection[key]["duplicates"]) == (gaps, duplicates)
    owner = next(c for c in opened if c["t_o_point"] == 71)
    truth = seen["ours"]["owner"]
    assert owner["o_t"]["rpi_ms"] == 10 and owner["o_t_point"] == 21
    assert owner["o_t"]["frames"] == truth["sent"]
    assert owner["t_o"]["frames"] >= truth["received"]
    assert owner["end_reason"] == "Forward_Close"
    assert 9.0 <= owner["t_o"]["p50_ms"] <= 11.0
    trips = [c for c in owner["data_changes"] if c["changes"].get("faulted") == [False, True]]
    assert trips, owner["data_changes"]
    theirs = next(c for c in opened if c is not owner)
    assert seen["ethernetip"]["forward_open"] == 0
    assert theirs["o_t"]["rpi_ms"] == 20 and theirs["end_reason"] == "timeout: O->T silent for more than 160 ms"


def test_class3_exchange_is_paired_by_its_sequence_count(analysis: list[dict[str, Any]]) -> None:
    connected = [r for r in analysis if r["type"] == "explicit" and r.get("command") == "SEND_UNIT_DATA"
                 and r["request"].get("attribute") == 3]
    assert len(connected) == 1, connected
    assert connected[0]["request"]["attribute_name"] == "Product Code"
    assert connected[0]["reply"]["data"]["value"] == 100 and "connection_id" in connected[0]


def test_routed_request_through_the_componet_gateway(analysis: list[dict[str, Any]]) -> None:
    routed = [r for r in analysis if r["type"] == "explicit" and "route" in r.get("request", {})]
    assert len(routed) == 1, routed
    assert routed[0]["target"] == "127.0.0.3:44818"
    assert routed[0]["request"]["route"] == [{"port": 2, "link": 5, "network": "CompoNet"}]
    assert routed[0]["request"]["embedded"]["attribute_name"] == "Vendor ID"
    assert routed[0]["reply"]["status"] == 0 and routed[0]["reply"]["data"]["value"] == 47


def test_human_summary_csv_and_plot(recorded: tuple[Path, dict[str, Any]], tmp_path: Path) -> None:
    path, _ = recorded
    result = analyze(str(path), "--csv", str(tmp_path / "csv"), "--plot", str(tmp_path / "plot.png"))
    assert result.returncode == 0, result.stderr
    assert "Connection 1:" in result.stdout and "ended: Forward_Close" in result.stdout
    assert "Set_Attribute_Single Identity 0x01/1/1 Vendor ID" in result.stdout
    rows = (tmp_path / "csv" / "connections.csv").read_text().splitlines()
    assert rows[0].startswith("connection,direction") and len(rows) == 1 + 2 * 2
    assert (tmp_path / "plot.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
