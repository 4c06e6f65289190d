"""CIP Security's objects: what serving them costs, measured in one run without sockets.

Three adapters' objects are built without listening (the default ACG profile): one without the
security objects, one with them, one with them and ``--secure-only`` configured. Each is fed the
same Get_Attribute_Single of Identity 1/1/7 through its message router as the encapsulation target
calls it, and the one with the objects also reads EtherNet/IP Security 0x5E/1/1 and Certificate
Management 0x5F/1/2. Then a whole push-model configuration (Begin_Config to Apply_Config: a P-256
key, the CSR, the CA's signature, the checks) runs against a fourth, and its CPU time is taken.

Printed: the best per-request time of ``--rounds`` rounds of ``--requests`` requests for each, the
ratios to the adapter without the objects (same run: the machine's load cancels out), and the
configuration's CPU time.

    python benchmarks/security_objects.py [--requests N] [--rounds R]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.cip.router import RequestContext
from cipstack.eip.wire.cpf import SockAddr

IDENTITY_NAME = bytes((0x0E, 3, 0x20, 0x01, 0x24, 0x01, 0x30, 0x07))
SECURITY_STATE = bytes((0x0E, 3, 0x20, 0x5E, 0x24, 0x01, 0x30, 0x01))
CERTIFICATE_STATE = bytes((0x0E, 3, 0x20, 0x5F, 0x24, 0x01, 0x30, 0x02))


def per_request(handle: Callable[[bytes, RequestContext], bytes], context: RequestContext, request: bytes,
                requests: int, rounds: int) -> float:
    reply = handle(request, context)
    assert reply[2] == 0, reply.hex()
    best = float("inf")
    for _ in range(rounds):
        started = time.perf_counter()
        for _ in range(requests):
            handle(request, context)
        best = min(best, (time.perf_counter() - started) / requests)
    return best


def _context(adapter: Adapter) -> RequestContext:
    connection = adapter.target.connection("127.0.0.1:50000", SockAddr("127.0.0.1", 44818), 0.0)
    return RequestContext(adapter.device.router, 0.0, "127.0.0.1:50000", connection)


def configuration_cpu(folder: Path) -> float:
    """CPU seconds of one whole configuration, the device's side and the tool's, in this process."""
    from cipstack.security.push import configure

    adapter = Adapter(AdapterSettings(port=0, io_port=0, security_objects=True))
    context = _context(adapter)
    handle = adapter.requests.handle

    def request(service: int, class_id: int, instance: int, attribute: int | None,
                data: bytes) -> tuple[int, tuple[int, ...], bytes]:
        path = bytes((0x20, class_id, 0x24, instance)) + (bytes((0x30, attribute)) if attribute is not None else b"")
        reply = handle(bytes((service, len(path) // 2)) + path + data, context)
        words = reply[3]
        return reply[2], tuple(int.from_bytes(reply[4 + 2 * i:6 + 2 * i], "little") for i in range(words)), \
            reply[4 + 2 * words:]

    started = time.process_time()
    configure(request, folder)
    return time.process_time() - started


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] if __doc__ else None)
    parser.add_argument("--requests", type=int, default=20000, help="requests per round (default 20000)")
    parser.add_argument("--rounds", type=int, default=9, help="rounds; the best is kept (default 9)")
    args = parser.parse_args(argv)
    from cipstack.security.provisioning import init

    plain = Adapter(AdapterSettings(port=0, io_port=0))
    served = Adapter(AdapterSettings(port=0, io_port=0, security_objects=True))
    secure_only = Adapter(AdapterSettings(port=0, io_port=0, security_objects=True, secure_only=True))
    times = {
        "identity, no security objects": per_request(plain.requests.handle, _context(plain), IDENTITY_NAME,
                                                     args.requests, args.rounds),
        "identity, security objects": per_request(served.requests.handle, _context(served), IDENTITY_NAME,
                                                  args.requests, args.rounds),
        "identity, security objects, --secure-only": per_request(secure_only.requests.handle,
                                                                 _context(secure_only), IDENTITY_NAME,
                                                                 args.requests, args.rounds),
        "0x5E/1/1 State": per_request(served.requests.handle, _context(served), SECURITY_STATE, args.requests,
                                      args.rounds),
        "0x5F/1/2 State": per_request(served.requests.handle, _context(served), CERTIFICATE_STATE, args.requests,
                                      args.rounds),
    }
    base = times["identity, no security objects"]
    with tempfile.TemporaryDirectory() as folder:
        init(Path(folder) / "lab")
        cpu = configuration_cpu(Path(folder) / "lab")
    result = {"per_request_us": {k: round(v * 1e6, 3) for k, v in times.items()},
              "ratio_to_plain": {k: round(v / base, 2) for k, v in times.items()},
              "configuration_cpu_ms": round(cpu * 1e3, 1)}
    print(json.dumps(result, indent=1))
    for adapter in (plain, served, secure_only):
        asyncio.run(adapter.close())
    return 0


if __name__ == "__main__":
    sys.exit(main())
