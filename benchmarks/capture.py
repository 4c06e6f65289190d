"""Frames per second of ``cipstack capture analyze`` against ``tshark -r FILE -T fields`` on the same
synthetic capture, in the same run.

The capture is written with the project's own codecs: a session, a Forward_Open/reply pair per
connection, class 1 traffic of ``--connections`` connections at a 1 ms RPI both ways (a few
sequence gaps and duplicates), an explicit Get_Attribute_Single exchange every 1,000 frames, and
the Forward_Closes. Goal: ``capture analyze`` no slower than tshark (ratio >= 1).

    python benchmarks/capture.py [--frames 1000000] [--connections 4] [--json] [--keep FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from cipstack.capture.synth import PcapWriter, TcpFlow, ethernet, udp
from cipstack.cip.epath import request_path
from cipstack.cip.messages import MessageRouterRequest, MessageRouterResponse, Service
from cipstack.eip.io_core import encode_io_datagram
from cipstack.eip.wire.cm_messages import (
    ConnectionTriad,
    ForwardCloseReply,
    ForwardCloseRequest,
    ForwardOpenReply,
    ForwardOpenRequest,
    NetworkParameters,
    TransportTrigger,
)
from cipstack.eip.wire.cpf import Item, ItemType, encode_items
from cipstack.eip.wire.encapsulation import RR_PREFIX, Command, encode_frame

SCANNER, ADAPTER = "192.168.1.10", "192.168.1.20"
CM_PATH = request_path(0x06, 1)


def _rr(message: bytes, context: int) -> bytes:
    items = encode_items([Item(ItemType.NULL_ADDRESS), Item(ItemType.UNCONNECTED_DATA, message)])
    return encode_frame(Command.SEND_RR_DATA, RR_PREFIX.pack(0, 0) + items, session=0x1001,
                        context=context.to_bytes(8, "little"))


def write_capture(path: Path, frames: int, connections: int) -> int:
    """Write about ``frames`` frames; returns the number written."""
    flow = TcpFlow((SCANNER, 50123), (ADAPTER, 44818))
    written = 0
    t = 1_700_000_000.0
    with path.open("wb") as stream:
        pcap = PcapWriter(stream)

        def put(frame: bytes) -> None:
            nonlocal written
            pcap.write(t, ethernet(frame))
            written += 1

        for frame in flow.handshake():
            put(frame)
        put(flow.send(True, encode_frame(Command.REGISTER_SESSION, b"\x01\x00\x00\x00")))
        put(flow.send(False, encode_frame(Command.REGISTER_SESSION, b"\x01\x00\x00\x00", session=0x1001)))
        opened = []
        for n in range(connections):
            triad = ConnectionTriad(100 + n, 0x0103, 0xBEEF)
            request = ForwardOpenRequest(0x0A, 0x0E, 0, 0x3000 + n, triad, 2, 1000, NetworkParameters(2 + 4 + 4),
                                         1000, NetworkParameters(2 + 4 + 12), TransportTrigger(1),
                                         bytes.fromhex("200424012c152c47"))
            put(flow.send(True, _rr(MessageRouterRequest(Service.FORWARD_OPEN, CM_PATH, request.encode()).encode(), n)))
            reply = ForwardOpenReply(0x2000 + n, 0x3000 + n, triad, 1000, 1000).encode()
            put(flow.send(False, _rr(MessageRouterResponse(Service.FORWARD_OPEN, data=reply).encode(), n)))
            opened.append(triad)
        get = MessageRouterRequest(Service.GET_ATTRIBUTE_SINGLE, request_path(0x2A, 1, 7)).encode()
        answer = MessageRouterResponse(Service.GET_ATTRIBUTE_SINGLE, data=b"\x64\x00").encode()
        sequence = 0
        while written < frames - 2 * connections - 8:
            t += 0.001
            sequence += 1
            for n in range(connections):
                if sequence % 5000 == 17:  # a lost packet now and then
                    continue
                o_t = encode_io_datagram(0x2000 + n, sequence, sequence, b"\x03\x00\x84\x03", run_idle=1)
                put(udp(SCANNER, 2222, ADAPTER, 2222, o_t))
                t_o = encode_io_datagram(0x3000 + n, sequence, sequence,
                                         (sequence & 0xFFFF).to_bytes(2, "little") + b"\x00" * 10)
                put(udp(ADAPTER, 2222, SCANNER, 2222, t_o))
            if sequence % 250 == 0:
                put(flow.send(True, _rr(get, sequence)))
                put(flow.send(False, _rr(answer, sequence)))
        for n, triad in enumerate(opened):
            close = ForwardCloseRequest(0x0A, 0x0E, triad, bytes.fromhex("200424012c152c47")).encode()
            put(flow.send(True, _rr(MessageRouterRequest(Service.FORWARD_CLOSE, CM_PATH, close).encode(), n)))
            reply = ForwardCloseReply(triad).encode()
            put(flow.send(False, _rr(MessageRouterResponse(Service.FORWARD_CLOSE, data=reply).encode(), n)))
    return written


def timed(command: list[str], env: dict[str, str] | None = None) -> tuple[float, int]:
    """Wall time of ``command`` with its output going to a file; the number of lines it wrote."""
    with tempfile.TemporaryFile() as out:
        start = time.perf_counter()
        result = subprocess.run(command, stdout=out, stderr=subprocess.PIPE, check=False, env=env)
        elapsed = time.perf_counter() - start
        if result.returncode != 0:
            raise SystemExit(f"{command[0]} failed: {result.stderr.decode(errors='replace')[-500:]}")
        out.seek(0)
        return elapsed, sum(chunk.count(b"\n") for chunk in iter(lambda: out.read(1 << 20), b""))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=1_000_000)
    parser.add_argument("--connections", type=int, default=4)
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--keep", type=Path, help="write the capture here and keep it")
    args = parser.parse_args()
    if shutil.which("tshark") is None:
        print("benchmarks/capture.py: tshark is not installed (apt-get install tshark)", file=sys.stderr)
        return 1
    with tempfile.TemporaryDirectory() as scratch:
        path = args.keep or Path(scratch) / "synthetic.pcap"
        start = time.perf_counter()
        frames = write_capture(path, args.frames, args.connections)
        written_s = time.perf_counter() - start
        env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
        ours_s, _ = timed([sys.executable, "-m", "cipstack", "capture", "analyze", str(path), "--json",
                           "--no-progress"], env)
        fields = ["frame.number", "frame.time_epoch", "enip.command", "enip.session", "cip.service", "cip.genstat",
                  "enip.cpf.sai.connid", "enip.cpf.sai.seq", "cip.seq"]
        command = ["tshark", "-r", str(path), "-T", "fields"]
        for name in fields:
            command += ["-e", name]
        tshark_s, rows = timed(command)
        result: dict[str, Any] = {
            "frames": frames, "file_mb": round(path.stat().st_size / 1e6, 1), "write_s": round(written_s, 2),
            "capture_analyze_s": round(ours_s, 2), "capture_analyze_fps": round(frames / ours_s),
            "tshark_fields_s": round(tshark_s, 2), "tshark_fields_fps": round(frames / tshark_s),
            "tshark_rows": rows, "ratio_vs_tshark": round(tshark_s / ours_s, 2),
        }
    if args.json:
        print(json.dumps(result))
    else:
        for key, value in result.items():
            print(f"{key:22} {value}")
        print("goal: ratio_vs_tshark >= 1 (capture analyze no slower than tshark -T fields)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
