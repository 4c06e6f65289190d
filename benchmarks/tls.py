"""EtherNet/IP over TLS (TCP 2221) against plain TCP (44818), in one run (issue 48).

```
python benchmarks/tls.py                       # 9 rounds of 1 s, 200 handshakes of each kind: about 70 s
python benchmarks/tls.py --idle-rounds 25         # the idle sessions' pair alone on to 25 rounds
python benchmarks/tls.py --json
python benchmarks/tls.py --profile adapter.prof   # the adapter under cProfile, top functions printed
```

One adapter started with ``--security`` (a lab folder made by ``security init`` in a temporary
directory: ECDSA P-256 certificates) serves both ports. From this process:

* **explicit**: the raw client of ``explicit.py`` (a registered session, a pre-built SendRRData
  frame of Get_Attribute_Single 1/1/7, one request in flight) on plain TCP, and the same client
  over TLS (a blocking ``ssl.SSLSocket`` with the folder's client certificate), back to back in
  each round, the one or the other first by turns; the adapter's CPU per request (utime + stime of
  ``/proc/PID/stat``) of each, and their ratio, round by round. Target: TLS within 1.5x of plain.
* **idle**: the TLS client again, with and without 100 other TLS connections open beside it (each
  with its handshake done and a session registered, then silent), paired the same way. Target: the
  ratio ~1.0; judged as ``explicit.py`` judges what 100 idle sessions add, on the sign test's bounds
  of the median of the paired ratios: PASS when the upper bound is within 1.10, FAIL when the lower
  bound is above it, INCONCLUSIVE (a FAIL) otherwise or with fewer than 5 rounds; ``--idle-rounds``
  goes on with that pair alone for tighter bounds.
* **handshake**: ``--handshakes`` connections one after the other, each a TCP connect, a full TLS
  handshake (no resumption) with client certificate, a RegisterSession and its reply (which, in TLS
  1.3, is what shows the adapter has verified the client's certificate), and a close; the adapter's
  CPU over them divided by their number, for TLS 1.3 and for TLS 1.2. The same sequence on plain TCP
  is printed beside it (what the TLS handshake adds is the difference). Target: under 20 ms a
  handshake. The adapter's certificate is checked to be ECDSA on P-256.

With two CPUs or more the adapter runs pinned to one and this process to another (as
``explicit.py``). Medians of the rounds are printed; every target line says PASS or FAIL, and the
exit status is 1 when one is missed.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import socket
import ssl
import statistics
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from explicit import (
    EXPECTED_NAME,
    HEADER,
    REGISTER_FRAME,
    Bench,
    Run,
    get_product_name_frame,
    measure,
    median_bounds,
    print_profile,
)
from io_common import Verdict, core_pair, cpu_seconds, free_port, pin_to_cpu, stop_adapter

#: Issue 48's targets.
TLS_RATIO_TARGET = 1.5
HANDSHAKE_TARGET_MS = 20.0
IDLE_RATIO_TARGET = 1.10
IDLE_SESSIONS = 100
#: The least confidence the bounds of the idle ratio's median must hold for a verdict (5 rounds).
IDLE_CONFIDENCE = 0.9


# -- the adapter --------------------------------------------------------------------------------------------
@contextlib.contextmanager
def secured_adapter(folder: Path, cpu: int | None, profile: str | None) -> Iterator[tuple[int, int, int]]:
    """The adapter with ``--security folder`` on free loopback ports: (pid, plain port, TLS port)."""
    import subprocess

    port, secure_port = free_port(), free_port()
    prefix = [sys.executable] + (["-m", "cProfile", "-o", profile] if profile else [])
    # Room for the idle connections (the defaults hold 32 sessions, 16 per address).
    limits = ["--max-sessions", "256", "--max-sessions-per-host", "256", "--max-tcp-connections", "512",
              "--max-tcp-connections-per-host", "512"]
    process = subprocess.Popen([*prefix, "-m", "cipstack", "adapter", "--host", "127.0.0.1", "--port", str(port),
                                "--io-port", "0", "--log-level", "WARNING", "--quiet", "--security", str(folder),
                                "--security-port", str(secure_port), *limits], stdin=subprocess.DEVNULL)
    pin_to_cpu(process.pid, cpu)
    try:
        deadline = time.monotonic() + 30
        for wanted in (port, secure_port):
            while True:
                if process.poll() is not None or time.monotonic() > deadline:
                    raise RuntimeError(f"the adapter does not listen on {wanted}")
                try:
                    socket.create_connection(("127.0.0.1", wanted), timeout=0.2).close()
                    break
                except OSError:
                    time.sleep(0.05)
        yield process.pid, port, secure_port
    finally:
        stop_adapter(process)


# -- clients --------------------------------------------------------------------------------------------------
class Client:
    """The raw client of ``explicit.py`` on plain TCP, or over TLS with ``context``."""

    def __init__(self, port: int, context: ssl.SSLContext | None = None) -> None:
        sock = socket.create_connection(("127.0.0.1", port))
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.sock: socket.socket = context.wrap_socket(sock) if context is not None else sock
        self.sock.sendall(REGISTER_FRAME)
        self.frame = get_product_name_frame(HEADER.unpack_from(self._read())[2])

    def _read(self) -> bytes:
        sock = self.sock
        data = sock.recv(4096)
        while len(data) < 24 or len(data) < 24 + (data[2] | data[3] << 8):
            more = sock.recv(4096)
            if not more:
                raise ConnectionError("connection closed by the adapter")
            data += more
        return data

    def call(self) -> bytes:
        self.sock.sendall(self.frame)
        return self._read()

    def close(self) -> None:
        self.sock.close()


def client_bench(name: str, port: int, pid: int, context: ssl.SSLContext | None) -> Bench:
    client = Client(port, context)
    reply = client.call()
    assert reply.endswith(b"\x8e\x00\x00\x00" + EXPECTED_NAME), reply.hex()

    def batch(n: int) -> None:
        call = client.call
        for _ in range(n):
            call()

    return Bench(name, "adapter", pid, batch, client.close)


def with_idle(bench: Bench, port: int, context: ssl.SSLContext, count: int) -> Bench:
    """``bench`` while ``count`` other TLS connections hold a session and send nothing."""
    idle: list[Client] = []

    def enter() -> None:
        idle.extend(Client(port, context) for _ in range(count))

    def leave() -> None:
        for client in idle:
            client.close()
        idle.clear()

    return Bench(f"{bench.client} +{count} idle", bench.server, bench.pid, bench.batch, bench.close,
                 bench.per_round, enter, leave)


# -- handshakes -------------------------------------------------------------------------------------------------
@dataclass
class Handshakes:
    kind: str
    count: int
    adapter_cpu_ms: float
    version: str
    cipher: str


def handshakes(port: int, pid: int, count: int, context: ssl.SSLContext | None, kind: str) -> Handshakes:
    """``count`` connections, each connect, (handshake,) RegisterSession, close: the adapter's CPU each."""
    Client(port, context).close()   # the first connection's one-time costs are not a handshake's
    version = cipher = "-"
    before = sum(cpu_seconds(pid))
    for _ in range(count):
        client = Client(port, context)
        if isinstance(client.sock, ssl.SSLSocket):
            version, cipher = client.sock.version() or "?", (client.sock.cipher() or ("?",))[0]
        client.close()
    # The adapter handles the last close after our close() returns: let it, before reading its CPU.
    time.sleep(0.05)
    cpu = sum(cpu_seconds(pid)) - before
    return Handshakes(kind, count, cpu / count * 1e3, version, cipher)


def certificate_curve(port: int, context: ssl.SSLContext) -> str:
    """The key of the certificate the adapter shows: 'ECDSA secp256r1', or what it is."""
    from cryptography import x509
    from cryptography.hazmat.primitives.asymmetric import ec

    with socket.create_connection(("127.0.0.1", port)) as sock, context.wrap_socket(sock) as tls:
        der = tls.getpeercert(binary_form=True)
    assert der is not None
    key = x509.load_der_x509_certificate(der).public_key()
    if isinstance(key, ec.EllipticCurvePublicKey):
        return f"ECDSA {key.curve.name}"
    return type(key).__name__


# -- the run --------------------------------------------------------------------------------------------------
def schedule(pairs: list[list[tuple[str, Bench]]], rounds: int, idle_rounds: int = 0) -> Iterator[tuple[str, Bench]]:
    """Each round, each pair back to back, the one or the other first by turns; then the last pair
    (the idle sessions') alone, up to ``idle_rounds`` rounds in all."""
    for index in range(max(rounds, idle_rounds)):
        for pair in (pairs if index < rounds else pairs[-1:]):
            yield from (pair if index % 2 == 0 else pair[::-1])


def run(seconds: float, rounds: int, warmup: float, handshake_count: int, idle_count: int,
        profile: str | None = None, pin: bool = True, idle_rounds: int = 0) -> dict[str, Any]:
    from cipstack.security import Credentials
    from cipstack.security.provisioning import init

    folder = Path(tempfile.mkdtemp()) / "lab"
    init(folder)
    credentials = Credentials.load(folder)
    context = credentials.client_context()
    tls12 = credentials.client_context()
    tls12.maximum_version = ssl.TLSVersion.TLSv1_2
    with contextlib.ExitStack() as stack:
        cores = core_pair() if pin else None
        if cores is not None:
            stack.callback(os.sched_setaffinity, 0, os.sched_getaffinity(0))
            os.sched_setaffinity(0, {cores[1]})
        pid, port, secure_port = stack.enter_context(secured_adapter(folder, cores[0] if cores else None, profile))
        curve = certificate_curve(secure_port, context)
        plain = client_bench("plain", port, pid, None)
        tls = client_bench("tls", secure_port, pid, context)
        stack.callback(plain.close)
        stack.callback(tls.close)
        # The TLS client is measured in both pairs: its second run is the idle pair's baseline.
        pairs = [[("plain", plain), ("tls", tls)],
                 [("tls idle", tls), ("tls +idle", with_idle(tls, secure_port, context, idle_count))]]
        measured: dict[str, list[Run]] = {"plain": [], "tls": [], "tls idle": [], "tls +idle": []}
        for key, bench in schedule(pairs, rounds, idle_rounds):
            measured[key].append(measure(bench, seconds, warmup))
        shakes = [handshakes(port, pid, handshake_count, None, "plain TCP"),
                  handshakes(secure_port, pid, handshake_count, context, "TLS"),
                  handshakes(secure_port, pid, handshake_count, tls12, "TLS 1.2")]
    return summarise(measured, shakes, curve, rounds, seconds)


def summarise(measured: dict[str, list[Run]], shakes: list[Handshakes], curve: str, rounds: int,
              seconds: float) -> dict[str, Any]:
    cpu = {key: [r.server_cpu_us for r in runs] for key, runs in measured.items()}
    tls_ratios = [t / p for t, p in zip(cpu["tls"], cpu["plain"], strict=True)]
    idle_ratios = [i / t for i, t in zip(cpu["tls +idle"], cpu["tls idle"], strict=True)]
    low, high, confidence = median_bounds(idle_ratios) if idle_ratios else (0.0, 0.0, 0.0)
    return {
        "rounds": rounds, "seconds": seconds, "certificate": curve,
        "cpu_per_request_us": {key: statistics.median(values) for key, values in cpu.items() if values},
        "cpu_per_request_rounds_us": cpu,
        "requests_per_s": {key: statistics.median(r.rate for r in runs) for key, runs in measured.items() if runs},
        "tls_ratio": statistics.median(tls_ratios), "tls_ratio_rounds": tls_ratios,
        "idle_ratio": statistics.median(idle_ratios), "idle_ratio_rounds": idle_ratios,
        "idle_ratio_low": low, "idle_ratio_high": high, "idle_ratio_confidence": confidence,
        "handshakes": [asdict(h) for h in shakes],
    }


def verdicts(summary: dict[str, Any]) -> list[Verdict]:
    cpu = summary["cpu_per_request_us"]
    found = [Verdict("adapter CPU per Get_Attribute_Single, TLS / plain TCP", summary["tls_ratio"],
                     TLS_RATIO_TARGET, "x", digits=2,
                     note=f"median of {len(summary['tls_ratio_rounds'])} paired rounds; "
                          f"{cpu['tls']:.1f} / {cpu['plain']:.1f} µs")]
    by_kind = {h["kind"]: h for h in summary["handshakes"]}
    plain = by_kind["plain TCP"]["adapter_cpu_ms"]
    for kind in ("TLS", "TLS 1.2"):
        shake = by_kind[kind]
        found.append(Verdict(f"adapter CPU per handshake ({summary['certificate']}, {shake['version']}, "
                             f"{shake['cipher']})", shake["adapter_cpu_ms"], HANDSHAKE_TARGET_MS, "ms",
                             note=f"connect, handshake, RegisterSession, close; plain TCP the same without "
                                  f"TLS: {plain:.2f} ms",
                             passed=shake["adapter_cpu_ms"] <= HANDSHAKE_TARGET_MS
                             and summary["certificate"] == "ECDSA secp256r1", digits=2))
    found.append(idle_verdict(summary))
    return found


def idle_verdict(summary: dict[str, Any]) -> Verdict:
    """The paired ratios' median with its sign-test bounds (``explicit.median_bounds``): PASS only when
    the upper bound is within the target, FAIL when the lower bound is above it, INCONCLUSIVE (a FAIL)
    between the two or with bounds held at less than ``IDLE_CONFIDENCE``."""
    low, high = summary["idle_ratio_low"], summary["idle_ratio_high"]
    confident = summary["idle_ratio_confidence"] >= IDLE_CONFIDENCE
    passed = confident and high <= IDLE_RATIO_TARGET
    conclusive = passed or (confident and low > IDLE_RATIO_TARGET)
    why = "the bounds straddle the target" if confident else "too few rounds to bound the median"
    cpu = summary["cpu_per_request_us"]
    note = (f"{len(summary['idle_ratio_rounds'])} paired rounds, median within {low:.2f} .. {high:.2f} "
            f"({100 * summary['idle_ratio_confidence']:.0f} % bounds); {cpu['tls +idle']:.1f} / "
            f"{cpu['tls idle']:.1f} µs" + ("" if conclusive else f"; {why}: INCONCLUSIVE on this run"))
    return Verdict(f"adapter CPU per TLS request, {IDLE_SESSIONS} idle TLS sessions / none", summary["idle_ratio"],
                   IDLE_RATIO_TARGET, "x", note=note, passed=passed, digits=2)


def print_report(summary: dict[str, Any]) -> None:
    cpu, rates = summary["cpu_per_request_us"], summary["requests_per_s"]
    print(f"{'client':<22} {'req/s':>8} {'adapter CPU':>12}")
    names = {"plain": "plain TCP", "tls": "TLS", "tls idle": "TLS (idle pair)",
             "tls +idle": f"TLS +{IDLE_SESSIONS} idle"}
    for key, name in names.items():
        print(f"{name:<22} {rates[key]:>8.0f} {cpu[key]:>9.1f} µs")
    for shake in summary["handshakes"]:
        print(f"{shake['kind'] + ' connections':<22} {shake['count']:>8} {shake['adapter_cpu_ms']:>9.2f} ms each"
              f"  ({shake['version']}, {shake['cipher']})")
    print()
    for verdict in verdicts(summary):
        print(verdict.line())


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] if __doc__ else None)
    parser.add_argument("--seconds", type=float, default=1.0, help="measured time per client and round")
    parser.add_argument("--rounds", type=int, default=9, help="rounds; medians are reported (default 9)")
    parser.add_argument("--warmup", type=float, default=0.2, help="unmeasured time before each run")
    parser.add_argument("--idle-rounds", type=int, default=0,
                        help="rounds of the idle sessions' pair, more than --rounds: the pair alone goes on")
    parser.add_argument("--handshakes", type=int, default=200, help="connections per kind (default 200)")
    parser.add_argument("--idle", type=int, default=IDLE_SESSIONS, help=argparse.SUPPRESS)
    parser.add_argument("--json", action="store_true", help="one JSON object instead of the table")
    parser.add_argument("--profile", metavar="FILE", help="run the adapter under cProfile, statistics to FILE")
    parser.add_argument("--no-pin", action="store_true", help="let the scheduler place adapter and clients")
    args = parser.parse_args(argv)
    summary = run(args.seconds, args.rounds, args.warmup, args.handshakes, args.idle, args.profile,
                  pin=not args.no_pin, idle_rounds=args.idle_rounds)
    found = verdicts(summary)
    summary["verdicts"] = [{"name": v.name, "measured": v.measured, "target": v.target, "passed": v.passed}
                           for v in found]
    summary["passed"] = all(v.passed for v in found)
    summary["load_average"] = os.getloadavg()
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print_report(summary)
        print(f"medians of {args.rounds} rounds of {args.seconds:g} s; load average {os.getloadavg()[0]:.2f} "
              f"on {os.cpu_count()} CPUs")
        if args.profile:
            print_profile(args.profile)
    return 0 if summary["passed"] else 1


if __name__ == "__main__":
    sys.exit(main())
