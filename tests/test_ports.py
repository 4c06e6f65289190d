"""The tests' free ports: what the emulators and peers a test starts listen on."""

from __future__ import annotations

import socket

import pytest

from tests import ports


def test_a_number_just_given_is_not_given_again(monkeypatch: pytest.MonkeyPatch) -> None:
    """The OS may pick for a probe the number it picked for the last one (an adapter's --port and
    --io-port were once the same, and the adapter could not listen): a number among the last ones
    given is passed over."""
    first = ports.free_port()
    picks = iter([first, first])  # the OS offers the same number twice, then whatever it likes
    real_socket = socket.socket

    class Probe(real_socket):  # type: ignore[misc, valid-type]
        def getsockname(self):  # type: ignore[no-untyped-def]
            name = super().getsockname()
            return (name[0], next(picks, name[1]))

    monkeypatch.setattr(ports.socket, "socket", Probe)
    second = ports.free_port()
    assert second != first
    with real_socket(socket.AF_INET, socket.SOCK_DGRAM) as check:
        check.bind(("127.0.0.1", second))
