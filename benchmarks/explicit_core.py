"""Explicit messaging cost without sockets: the adapter's work for one Get_Attribute_Single.

Builds the adapter's objects (default profile, the ACG drive) without listening, registers a
session on an ``EncapsulationConnection`` and feeds it the same SendRRData frame (Identity 1/1/7,
as ``explicit.py``'s raw client sends) over and over, as the TCP shell does: ``receive`` with the
time, then ``data_to_send``. The target serves a frame that repeats the last one byte for byte
from what it kept of it; ``--new-context`` alternates two sender contexts, so that every frame is
parsed whole (a client that numbers its requests in the context). It checks the replies and
prints the time per request: the best of ``--rounds`` rounds of ``--requests`` requests (the
least the machine's other load added).

    python benchmarks/explicit_core.py [--requests N] [--rounds R] [--new-context]

The time moves with the machine; instructions do not. Under callgrind, the difference between two
runs gives the instructions of one request whatever else the machine does:

    valgrind --tool=callgrind --callgrind-out-file=/dev/null python3 benchmarks/explicit_core.py \
        --requests 0 --rounds 1
    (the same with --requests 5000)

The "Collected" totals of the two, their difference divided by 5,000 (give valgrind the real
interpreter, not a wrapper script such as pyenv's shim).
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from explicit import EXPECTED_NAME, HEADER, REGISTER_FRAME, get_product_name_frame

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.eip.wire.cpf import SockAddr

#: The reply's end: Get_Attribute_Single reply (0x8E), success, the product name.
EXPECTED_REPLY_END = b"\x8e\x00\x00\x00" + EXPECTED_NAME


async def measure(requests: int, rounds: int, new_context: bool = False) -> float:
    adapter = Adapter(AdapterSettings(port=0, io_port=0))
    loop = asyncio.get_running_loop()
    connection = adapter.target.connection("127.0.0.1:50000", SockAddr("127.0.0.1", 44818), loop.time())
    connection.receive(REGISTER_FRAME, loop.time())
    session = HEADER.unpack_from(connection.data_to_send())[2]
    frame = get_product_name_frame(session)
    connection.receive(frame, loop.time())
    reply = connection.data_to_send()
    assert reply.endswith(EXPECTED_REPLY_END), reply.hex()
    other = get_product_name_frame(session, b"bench\x00\x00\x01") if new_context else frame
    connection.receive(other, loop.time())
    assert connection.data_to_send().endswith(EXPECTED_REPLY_END)
    pairs = requests // 2
    receive, send, clock = connection.receive, connection.data_to_send, time.monotonic
    best = float("inf")
    for _ in range(rounds):
        started = time.perf_counter()
        for _ in range(pairs):
            receive(frame, clock())
            send()
            receive(other, clock())
            send()
        best = min(best, (time.perf_counter() - started) / max(2 * pairs, 1))
    return best


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] if __doc__ else None)
    parser.add_argument("--requests", type=int, default=20000, help="requests per round (default 20000)")
    parser.add_argument("--rounds", type=int, default=15, help="rounds; the best is printed (default 15)")
    parser.add_argument("--new-context", action="store_true",
                        help="alternate two sender contexts: no frame repeats the one before it")
    args = parser.parse_args(argv)
    best = asyncio.run(measure(args.requests, args.rounds, args.new_context))
    if args.requests:
        print(f"adapter work per Get_Attribute_Single, no sockets: {best * 1e6:.2f} µs "
              f"(best of {args.rounds} rounds of {args.requests}; "
              f"{'two sender contexts in turn' if args.new_context else 'the same frame each time'})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
