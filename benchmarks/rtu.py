"""Modbus-RTU requests per second against the line's own limit, at 9,600 and 115,200 bps.

Starts the adapter emulator with its RS-485 port on a pty (``python -m cipstack adapter --rtu pty
--param CM.3=N --param CM.5=D``) once per baud rate, and reads one holding register (ACC) over the
pty, one request at a time, ``--requests`` times: an 8-byte request and a 7-byte reply. A pty has
no baud rate; the emulator paces itself at its CM.3 setting (it hears the request as the line would
bring it, waits the 3.5-character frame-end silence, CM.5, and releases the reply when its last
character would have left the UART). The line's own limit is the rate at which the request's and
the reply's characters alone fill the line (15 characters of 10 bits, D8/PN/S1); the ratio says
how much of it the emulator reaches. It cannot reach 1: every exchange also holds the frame-end
silence (3.5 characters, 1.75 ms above 19,200 bps) and CM.5, as a drive on a real line does.

    python benchmarks/rtu.py [--requests N] [--delay MS] [--json]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import re
import select
import signal
import subprocess
import sys
import tempfile
import time
import tty
from collections.abc import Iterator
from typing import Any

from io_common import free_port  # benchmarks/ is on the path when a benchmark runs

from cipstack.devices.acg.modbus_rtu import BAUD_RATES, LineSettings, with_crc
from cipstack.devices.acg.registers import ACG_REGISTERS

BAUDS = (9600, 115200)
#: Read Holding Registers, station 1, one word: ACC (PDU address = communication address - 1).
REQUEST = with_crc(bytes((1, 3)) + (ACG_REGISTERS.by_code("ACC").address - 1).to_bytes(2, "big") + b"\x00\x01")
REPLY_SIZE = 7
LINE = re.compile(r"^Modbus-RTU on (\S+) \(")


@contextlib.contextmanager
def emulator(baud: int, delay_ms: int) -> Iterator[str]:
    """A ``cipstack adapter --rtu pty`` at ``baud``; the pty path it prints."""
    setting = next(s for s, b in BAUD_RATES.items() if b == baud)
    scratch = tempfile.TemporaryDirectory(prefix="cipstack-rtu-bench-")
    process = subprocess.Popen(
        [sys.executable, "-m", "cipstack", "--log-level", "WARNING", "adapter", "--port", str(free_port()),
         "--io-port", "0", "--quiet", "--rtu", "pty", "--state", os.path.join(scratch.name, "acg.json"),
         "--control", os.path.join(scratch.name, "control.sock"),
         "--param", f"CM.3={setting}", "--param", f"CM.5={delay_ms}"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert process.stdout is not None
        line = process.stdout.readline()
        match = LINE.match(line)
        if match is None:
            error = process.stderr.read() if process.stderr else ""
            raise SystemExit(f"rtu.py: the emulator printed {line!r}: {error}")
        yield match.group(1)
    finally:
        process.send_signal(signal.SIGTERM)
        process.wait(15)
        scratch.cleanup()


def exchange(fd: int, timeout: float = 2.0) -> None:
    os.write(fd, REQUEST)
    received = b""
    end = time.monotonic() + timeout
    while len(received) < REPLY_SIZE:
        left = end - time.monotonic()
        if left <= 0 or not select.select([fd], [], [], left)[0]:
            raise SystemExit("rtu.py: no reply from the emulator")
        received += os.read(fd, 64)
    if len(received) != REPLY_SIZE or received[:2] != b"\x01\x03":
        raise SystemExit(f"rtu.py: unexpected reply {received.hex(' ')}")


def measure(baud: int, requests: int, delay_ms: int) -> dict[str, Any]:
    with emulator(baud, delay_ms) as path:
        fd = os.open(path, os.O_RDWR | os.O_NOCTTY)
        try:
            tty.setraw(fd)
            for _ in range(3):                  # warm-up
                exchange(fd)
            start = time.perf_counter()
            for _ in range(requests):
                exchange(fd)
            elapsed = time.perf_counter() - start
        finally:
            os.close(fd)
    settings = LineSettings(baud=baud)
    characters = len(REQUEST) + REPLY_SIZE
    limit = 1 / settings.transmission_time(characters)
    rate = requests / elapsed
    # What a drive on a real line can do at most: the characters, the frame-end silence and CM.5.
    ceiling = 1 / (settings.transmission_time(characters) + settings.frame_silence + delay_ms / 1000)
    return {"baud": baud, "requests": requests, "requests_per_s": rate, "line_limit_per_s": limit,
            "ratio": rate / limit, "ceiling_per_s": ceiling, "characters": characters,
            "character_time_ms": settings.character_time * 1000,
            "frame_silence_ms": settings.frame_silence * 1000, "response_delay_ms": delay_ms}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--requests", type=int, default=200, help="requests per baud rate (default 200)")
    parser.add_argument("--delay", type=int, default=0, help="CM.5 response delay, ms (default 0)")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    results = [measure(baud, args.requests, args.delay) for baud in BAUDS]
    if args.json:
        print(json.dumps(results))
        return 0
    print(f"Modbus-RTU over a pty, Read Holding Registers of one word (8-byte request, 7-byte reply), "
          f"CM.5 = {args.delay} ms, {args.requests} requests one at a time:")
    for r in results:
        print(f"  {r['baud']:>7,} bps: {r['requests_per_s']:7.1f} requests/s; the line's limit "
              f"{r['line_limit_per_s']:7.1f}/s ({r['characters']} characters of {r['character_time_ms']:.3f} ms); "
              f"ratio {r['ratio']:.2f} (at most {r['ceiling_per_s'] / r['line_limit_per_s']:.2f} with the "
              f"{r['frame_silence_ms']:.2f} ms frame-end silence and CM.5)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
