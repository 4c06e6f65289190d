"""The tests' free ports: what the emulators and peers a test starts listen on."""

from __future__ import annotations

import socket
from pathlib import Path

import pytest

from tests import ports


def test_a_number_just_given_is_not_given_again(monkeypatch: pytest.MonkeyPatch) -> None:
    """A number may come up again (the kernel's pick once gave an adapter's --port and --io-port the
    same number, and the adapter could not listen): a number among the last ones given is passed
    over."""
    first = ports.free_port()
    real_offer = ports._offer
    picks = iter([first, first])  # the same number offered twice, then whatever comes

    def offer(host: str) -> int:
        return next(picks, None) or real_offer(host)

    monkeypatch.setattr(ports, "_offer", offer)
    second = ports.free_port()
    assert second != first
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as check:
        check.bind(("127.0.0.1", second))


def test_numbers_come_from_below_the_kernels_ephemeral_ports() -> None:
    """A socket bound to port 0, or an outgoing connection, gets a number of the ephemeral range: a
    number handed out and not bound yet is never it (a test once reached another test's emulator on
    the port it had been given)."""
    low, _ = (int(n) for n in Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split())
    if low - 10_000 < 4_096:
        pytest.skip(f"the ephemeral ports start at {low}: no room below them")
    assert all(10_000 <= ports.free_port() < low for _ in range(50))


def test_each_worker_has_numbers_of_its_own() -> None:
    """pytest-xdist's workers (PYTEST_XDIST_WORKER gwN of PYTEST_XDIST_WORKER_COUNT) share the range
    out by residue: no number is in two shares, and together they cover it."""
    space = range(10_000, 32_768)
    shares = []
    for index in range(3):
        with pytest.MonkeyPatch.context() as patch:
            patch.setenv("PYTEST_XDIST_WORKER", f"gw{index}")
            patch.setenv("PYTEST_XDIST_WORKER_COUNT", "3")
            shares.append(set(ports._worker_share(space)))
    assert sum(len(share) for share in shares) == len(space)
    assert set().union(*shares) == set(space)
    with pytest.MonkeyPatch.context() as patch:
        patch.delenv("PYTEST_XDIST_WORKER", raising=False)
        patch.delenv("PYTEST_XDIST_WORKER_COUNT", raising=False)
        assert ports._worker_share(space) == space          # one process: the whole range
