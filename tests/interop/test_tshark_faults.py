"""Faults on the wire, as tshark dissects them: in a private network namespace, `cipstack adapter`
on 127.0.0.2 and our scanner in another process on 127.0.0.1, both on UDP 2222. A `stop-producing`
fault stops the T->O frames, and the originator's Forward_Close follows the last of them after its
connection timeout (RPI 10 ms x 4 x 2^1 = 80 ms); a `refuse-forward-open 0x0113` reply carries
general status 0x01 with extended status 0x0113; no frame is malformed."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from .netns import PRELUDE, require_namespace, run_in_namespace
from .test_tshark_io import tshark

# One capture for the whole module (its fixture), and one capturing module at a time (docs/contributing.md).
pytestmark = [pytest.mark.interop, pytest.mark.tshark, pytest.mark.xdist_group("tshark")]

HELPER = PRELUDE + r'''


async def exchange():
    from cipstack.cip.status import CipError
    from cipstack.control import control_request
    from cipstack.devices.profiles import catalog_for
    from cipstack.eip.originator.io_originator import IoTimeoutError
    from cipstack.scanner import Scanner

    control = OUT / "control.sock"
    scanner = await Scanner.connect(f"{ADAPTER}:44818", catalog=catalog_for(259, 100))
    async with scanner:
        async with scanner.io_connection(output=21, input=71, rpi=0.010, timeout_multiplier=1,
                                         local_io_port=2222) as io:
            await io.wait_input(lambda i: True, 5)
            await asyncio.sleep(0.3)   # the subject: T->O on the wire before the fault stops it
            seen["fault"] = control_request(control, {"command": "fault", "name": "stop-producing", "options": {}})
            try:
                async for _ in io.updates():
                    pass
            except IoTimeoutError:
                seen["timed_out"] = True
        control_request(control, {"command": "clear"})
        control_request(control, {"command": "fault", "name": "refuse-forward-open", "options": {"status": 0x0113}})
        try:
            async with scanner.io_connection(output=21, input=71, rpi=0.010, local_io_port=2222):
                pass
        except CipError as exc:
            seen["refused"] = [exc.general, list(exc.extended)]


tshark = subprocess.Popen(["tshark", "-i", "lo", "-f", "tcp port 44818 or udp port 2222",
                           "-w", str(OUT / "capture.pcapng"), "-q"],
                          stdout=subprocess.DEVNULL, stderr=(OUT / "tshark.log").open("wb"))
adapter = None
try:
    wait_for(lambda: "Capturing on" in (OUT / "tshark.log").read_text(errors="replace"), 30, "tshark")
    adapter = subprocess.Popen([PY, "-m", "cipstack", "adapter", "--host", ADAPTER, "--quiet",
                                "--state", str(OUT / "state.json"), "--control", str(OUT / "control.sock")],
                               stdout=(OUT / "adapter.log").open("wb"), stderr=subprocess.STDOUT)
    wait_for(listening, 20, "the adapter")
    try:
        asyncio.run(exchange())
    except Exception:
        seen["errors"].append(traceback.format_exc())
finally:
    if adapter is not None:
        adapter.send_signal(signal.SIGTERM)
        seen["adapter_exit"] = adapter.wait(10)
    time.sleep(0.5)  # the capturer reads its ring on its own time: no event says it has the last frames
    tshark.send_signal(signal.SIGINT)
    tshark.wait(20)
    (OUT / "seen.json").write_text(json.dumps(seen, indent=1))
'''


@pytest.fixture(scope="module")
def capture(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    require_namespace()
    out = tmp_path_factory.mktemp("tshark-faults")
    seen = run_in_namespace(out, "exchange.py", HELPER)
    assert not seen["errors"], "\n".join(seen["errors"])
    assert seen["adapter_exit"] == 0
    return out / "capture.pcapng", seen


def test_stop_producing_ends_t_to_o_and_the_originator_times_out(capture: tuple[Path, dict[str, Any]]) -> None:
    path, seen = capture
    assert seen["timed_out"] is True
    t_to_o = [float(t) for t in tshark(path, "udp.srcport == 2222 && ip.src == 127.0.0.2 && enip",
                                       fields=("frame.time_relative",))]
    closes = [float(t) for t in tshark(path, "cip.service == 0x4e && ip.src == 127.0.0.1",
                                       fields=("frame.time_relative",))]
    assert len(t_to_o) > 20 and closes
    last = max(t for t in t_to_o if t < closes[0])
    # The originator's watchdog: 80 ms after the last T->O frame, then its Forward_Close.
    assert 0.075 <= closes[0] - last < 0.2, (closes[0], last)
    # No T->O frame between the fault and the end of that connection (productions gapped by RPIs before).
    before = [t for t in t_to_o if t <= last]
    assert max(b - a for a, b in zip(before[-20:], before[-19:], strict=False)) < 0.05


def test_refused_forward_open_carries_0x0113_on_the_wire(capture: tuple[Path, dict[str, Any]]) -> None:
    path, seen = capture
    assert seen["refused"] == [0x01, [0x0113]]
    replies = tshark(path, "cip.service == 0xd4 || cip.service == 0xdb",
                     fields=("cip.service", "cip.genstat", "cip.cm.ext_status"))
    assert replies[-1] == "0xd4\t0x01\t0x0113", replies


def test_no_malformed_frame(capture: tuple[Path, dict[str, Any]]) -> None:
    path, _ = capture
    assert tshark(path, "_ws.malformed || _ws.expert.severity >= error") == []
