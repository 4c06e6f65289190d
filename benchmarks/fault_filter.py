"""A class 1 fault's filter per T->O datagram, in process CPU time, one tree or two side by side.

The filter a datagram fault puts in the class 1 seam (``drop --every 1000000``: it acts on almost
no datagram, so what is measured is its reading of the datagram and of its options, not what it
drops; ``delay`` and ``wrong-size`` read more options per datagram and are measured too) is made
as the fault controller makes it, from a checked request, and given batches of one T->O datagram
of one connection, as the seam gives them at each production. Each figure is CPU nanoseconds per
datagram (``time.process_time_ns``), the median of ``--rounds`` rounds, each tree run in a process
of its own by turns (``--against TREE``: another checkout, ``git archive SHA | tar -x -C TREE``),
so the machine's load weighs on both alike; the ratio of the two is the figure to quote.

    python benchmarks/fault_filter.py [--datagrams 200000] [--rounds 5] [--against /tmp/before] [--json]
    valgrind --tool=callgrind --callgrind-out-file=/dev/null python benchmarks/fault_filter.py --one \
        --only drop --datagrams 20001      # minus the same with --datagrams 1: instructions per datagram
"""

from __future__ import annotations

import argparse
import json
import os
import random
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent.parent
#: The faults measured, as the command line gives them: one that acts on almost nothing, two that act on
#: every datagram and read more options.
FAULTS = (("drop", "--every", "1000000"), ("wrong-size", "--size", "12"), ("freeze-sequence",))


class _Connection:
    """What a class 1 filter reads of an open connection."""

    ot_connection_id = 0x10
    to_connection_id = 0x20
    peer = "127.0.0.1"


class _Runtime:
    """What a class 1 filter reads of the device's runtime: its class 1 seam and open connections."""

    class1 = object()

    def __init__(self) -> None:
        self.connections = [_Connection()]

    def class1_connections(self) -> list[_Connection]:
        return self.connections


def _datagram() -> tuple[bytes, tuple[str, int]]:
    # CPF count, Sequenced Address item (its connection id at 6), Connected Data item, sequence count, data.
    head = bytes.fromhex("0200028008002000000001000000b1001600") + (1).to_bytes(2, "little")
    return head + bytes(20), ("127.0.0.1", 2222)


def one_tree(datagrams: int, only: str | None = None) -> dict[str, float]:
    """In this process: CPU ns per datagram of each fault's filter, or of the fault ``only`` (the tree is
    whatever is imported)."""
    from cipstack.faults.effect import FaultContext
    from cipstack.faults.model import FAULTS as TABLE
    from cipstack.faults.model import parse_arguments

    figures = {}
    for name, *words in FAULTS:
        if only is not None and name != only:
            continue
        request = parse_arguments(name, words)
        # The record the controller hands its effect: typed where the tree has it, the mapping before.
        options = getattr(request, "settings", request.options)
        context = FaultContext(_Runtime(), 1, options, random.Random(1), lambda: None,  # type: ignore[arg-type]  # a stand-in runtime: the filters read none of it
                               lambda work: None)
        effect: Any = TABLE[name].effect(context)
        batch = [_datagram()]
        outbound = effect.outbound
        for _ in range(1000):      # warm up
            outbound(batch, 0.0, None)
        start = time.process_time_ns()
        for _ in range(datagrams):
            outbound(batch, 0.0, None)
        figures[" ".join((name, *words))] = (time.process_time_ns() - start) / datagrams
    return figures


def measure(trees: list[Path], datagrams: int, rounds: int) -> dict[str, Any]:
    runs: dict[str, list[dict[str, float]]] = {str(tree): [] for tree in trees}
    for index in range(rounds):
        for tree in trees[index % len(trees):] + trees[:index % len(trees)]:
            env = {**os.environ, "PYTHONPATH": str(tree)}
            out = subprocess.run([sys.executable, __file__, "--one", "--datagrams", str(datagrams)], env=env,
                                 check=True, capture_output=True, text=True).stdout
            runs[str(tree)].append(json.loads(out))
    medians = {tree: {fault: statistics.median(r[fault] for r in found) for fault in found[0]}
               for tree, found in runs.items()}
    return {"trees": [str(t) for t in trees], "rounds": rounds, "datagrams": datagrams, "medians": medians,
            "runs": runs}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--datagrams", type=int, default=200_000, help="datagrams per fault per round")
    parser.add_argument("--rounds", type=int, default=5, help="rounds; the median is printed (default 5)")
    parser.add_argument("--against", type=Path, action="append", default=[], help="another checkout (repeatable)")
    parser.add_argument("--json", action="store_true", help="one JSON object instead of the text report")
    parser.add_argument("--one", action="store_true",
                        help="this tree only, in this process (for callgrind: the run of N datagrams minus the run "
                             "of 1, divided by N - 1, is one filter's instructions per datagram)")
    parser.add_argument("--only", help="with --one: this fault only (drop, wrong-size, freeze-sequence)")
    args = parser.parse_args()
    if args.one:
        print(json.dumps(one_tree(args.datagrams, args.only)))
        return 0
    trees = [HERE, *(tree.resolve() for tree in args.against)]
    result = measure(trees, args.datagrams, args.rounds)
    if args.json:
        print(json.dumps(result))
        return 0
    current = result["medians"][str(HERE)]
    for fault, ns in current.items():
        line = f"{fault:<28} {Path(str(HERE)).name}: {ns:7.1f} ns/datagram"
        for tree in trees[1:]:
            theirs = result["medians"][str(tree)][fault]
            line += f"; {tree.name}: {theirs:7.1f} ns ({ns / theirs:.3f}x)"
        print(line)
    print(f"medians of {args.rounds} rounds of {args.datagrams} datagrams; load average {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
