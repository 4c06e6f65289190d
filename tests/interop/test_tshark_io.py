"""tshark dissects class 1 traffic on the default ports: the Forward_Open/Forward_Close exchanges and
the cyclic I/O frames of our scanner and of python-ethernetip with the ACG emulator, in a private
network namespace (44818 and 2222 are free there), with no malformed packet and no expert warning."""

from __future__ import annotations

import subprocess
from pathlib import Path
from typing import Any

import pytest

from .netns import JUDGED, PRELUDE, require_namespace, run_in_namespace

# One capture for the whole module (its fixture), and one capturing module at a time (docs/contributing.md).
pytestmark = [pytest.mark.interop, pytest.mark.tshark, pytest.mark.xdist_group("tshark")]

ADAPTER_HOST = "127.0.0.2"

HELPER = PRELUDE + r'''


async def ours():
    from cipstack.cip.types import UINT
    from cipstack.devices.acg.registers import ACG_REGISTERS, CLASS_64_INSTANCES
    from cipstack.devices.profiles import catalog_for
    from cipstack.scanner import Scanner

    cm = CLASS_64_INSTANCES["CM"]
    scanner = await Scanner.connect(f"{ADAPTER}:44818", catalog=catalog_for(259, 100))
    async with scanner:
        # drv = 4, Frq = 8 (Field Bus) through smart scaling; ACC and dEC 0.5 s.
        await scanner.set_attribute_single(0x64, cm, 51, ACG_REGISTERS.by_code("drv").address, UINT)
        await scanner.set_attribute_single(0x64, cm, 52, ACG_REGISTERS.by_code("Frq").address, UINT)
        await scanner.set_attribute_single(0x04, 122, 3, UINT.encode(4) + UINT.encode(8))
        await scanner.set_attribute_single(0x2A, 1, 102, 5, UINT)
        await scanner.set_attribute_single(0x2A, 1, 103, 5, UINT)
        # Both sides on UDP 2222: the target on 127.0.0.2, this originator on 127.0.0.1.
        async with scanner.io_connection(output=21, input=71, rpi=0.010, local_io_port=2222) as owner, \
                scanner.io_connection(input=71, heartbeat=198, rpi=0.020, local_io_port=2222) as watcher:
            owner.output.speed_reference = 900
            owner.output.run_forward = True
            await owner.wait_input(lambda i: i.at_reference, 10)
            await watcher.wait_input(lambda i: i.running_forward, 5)
            # Half a second at speed: the ramps alone (0.25 s each way) made about as many frames
            # as the count below asks for, and a quick run fell one short.
            await asyncio.sleep(0.5)
            owner.output.run_forward = False
            await owner.wait_input(lambda i: i.speed_actual == 0, 10)
            return {"owner": owner.stats.as_dict(), "watcher": watcher.stats.as_dict()}


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
    outputs = enip.registerAssembly(ethernetip.EtherNetIP.ENIP_IO_TYPE_OUTPUT, 4, 20, conn)
    enip.startIO(0)  # its own T->O port: 2222 belongs to the adapter's socket family here
    port = enip.originator_udp_port
    status = conn.sendFwdOpenReq(70, 20, 1, torpi=10, otrpi=10, multiplier=1, inputsz=4, outputsz=4,
                                 originator_udp_port=port)
    outputs[0] = True                     # Run Fwd
    for bit in range(16):                  # Speed Reference 600 rpm, bytes 2-3
        outputs[16 + bit] = bool((600 >> bit) & 1)
    conn.produce()
    deadline = time.monotonic() + 5
    while not inputs[2] and time.monotonic() < deadline:
        time.sleep(0.01)
    running = bool(inputs[2])
    outputs[0] = False
    time.sleep(0.2)                       # the subject: the stop command on the wire, 20 of its RPIs
    conn.stopProduce()
    closed = conn.sendFwdCloseReq(70, 20, 1)
    enip.stopIO()
    return {"forward_open": status, "forward_close": closed, "running_seen": running, "port": port,
            "outputs": len(outputs)}


tshark = subprocess.Popen(["tshark", "-i", "lo", "-f", "tcp port 44818 or udp", "-w", str(OUT / "capture.pcapng"),
                           "-q"], stdout=subprocess.DEVNULL, stderr=(OUT / "tshark.log").open("wb"))
adapter = None
try:
    wait_for(lambda: "Capturing on" in (OUT / "tshark.log").read_text(errors="replace"), 30, "tshark")
    adapter = subprocess.Popen([PY, "-m", "cipstack", "adapter", "--host", ADAPTER, "--quiet",
                                "--state", str(OUT / "state.json"), "--control", str(OUT / "control.sock")],
                               stdout=(OUT / "adapter.log").open("wb"), stderr=subprocess.STDOUT)
    wait_for(listening, 20, "the adapter")
    try:
        seen["ours"] = asyncio.run(ours())
    except Exception:
        seen["errors"].append("ours: " + traceback.format_exc())
    try:
        seen["ethernetip"] = ethernetip_exchange()
    except Exception:
        seen["errors"].append("ethernetip: " + traceback.format_exc())
finally:
    if adapter is not None:
        adapter.send_signal(signal.SIGTERM)
        seen["adapter_exit"] = adapter.wait(10)
    time.sleep(0.5)  # the capturer reads its ring on its own time: no event says it has the last frames
    tshark.send_signal(signal.SIGINT)
    tshark.wait(20)
    (OUT / "seen.json").write_text(json.dumps(seen, indent=1))
'''


def tshark(capture: Path, display_filter: str, *options: str, fields: tuple[str, ...] = ()) -> list[str]:
    command = ["tshark", "-r", str(capture), *options, "-Y", display_filter]
    for field in fields:
        command += ["-T", "fields", "-e", field] if field == fields[0] else ["-e", field]
    result = subprocess.run(command, capture_output=True, text=True, timeout=60, check=False)
    assert result.returncode == 0, result.stderr
    return [line for line in result.stdout.splitlines() if line.strip()]


@pytest.fixture(scope="module")
def capture(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    require_namespace()
    out = tmp_path_factory.mktemp("tshark-io")
    seen = run_in_namespace(out, "exchange.py", HELPER)
    assert not seen["errors"], "\n".join(seen["errors"])
    return out / "capture.pcapng", seen


def test_both_originators_ran_the_drive(capture: tuple[Path, dict[str, Any]]) -> None:
    _, seen = capture
    assert seen["adapter_exit"] == 0
    for name in ("owner", "watcher"):
        stats = seen["ours"][name]
        assert stats["received"] > 10 and stats["lost"] == 0, stats
    assert seen["ethernetip"]["forward_open"] == 0 and seen["ethernetip"]["forward_close"] == 0
    assert seen["ethernetip"]["running_seen"] is True


def test_no_malformed_packet_and_no_expert_warning(capture: tuple[Path, dict[str, Any]]) -> None:
    path, seen = capture
    decode = ("-d", f"udp.port=={seen['ethernetip']['port']},cipio")
    assert tshark(path, JUDGED, *decode) == []
    assert tshark(path, "enip", *decode), "nothing dissected as EtherNet/IP: wrong ports?"


def test_forward_open_and_close_exchanges_decode(capture: tuple[Path, dict[str, Any]]) -> None:
    path, _ = capture
    opens = tshark(path, "cip.service == 0x54 && cip.cm.transport_type_trigger", fields=("frame.number",))
    replies = tshark(path, "cip.service == 0xd4 && cip.genstat == 0", fields=("frame.number",))
    closes = tshark(path, "cip.service == 0xce && cip.genstat == 0", fields=("frame.number",))
    # Ours: exclusive owner and input only; python-ethernetip: one exclusive owner.
    assert len(opens) >= 3 and len(replies) >= 3 and len(closes) >= 3, (opens, replies, closes)


def test_io_frames_decode_in_both_directions(capture: tuple[Path, dict[str, Any]]) -> None:
    path, seen = capture
    decode = ("-d", f"udp.port=={seen['ethernetip']['port']},cipio")
    to_target = tshark(path, f"cipio && ip.dst == {ADAPTER_HOST} && udp.dstport == 2222", *decode,
                       fields=("frame.number",))
    from_target = tshark(path, f"cipio && ip.src == {ADAPTER_HOST}", *decode, fields=("frame.number",))
    assert len(to_target) > 100 and len(from_target) > 100, (len(to_target), len(from_target))
    # Sequenced Address items carry the connection ids the Forward_Open replies named.
    ids = tshark(path, f"enip.cpf.sai.connid && ip.src == {ADAPTER_HOST}", *decode, fields=("enip.cpf.sai.connid",))
    assert len(set(ids)) >= 2
