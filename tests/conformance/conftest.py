"""What the battery's tests share: emulators started as the user starts them."""

from __future__ import annotations

import signal
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from tests.interop.conftest import HOST, PeerProcess, python_module, start_peer
from tests.ports import free_port

#: ``adapter_with(*ARGS)``: a ``cipstack adapter ARGS`` started for the test.
AdapterStarter = Callable[..., PeerProcess]


@pytest.fixture
def adapter_with(tmp_path: Path) -> Iterator[AdapterStarter]:
    """Start ``cipstack adapter ARGS`` on a free port; stopped by PID when the test ends."""
    started: list[PeerProcess] = []

    def start(*args: str) -> PeerProcess:
        port = free_port()
        command = python_module("cipstack", "adapter", "--host", HOST, "--port", str(port), "--io-port", "0",
                                "--quiet", *args)
        peer = start_peer("cipstack adapter", command, HOST, port, tmp_path / f"adapter-{port}.log")
        started.append(peer)
        return peer

    yield start
    for peer in started:
        peer.stop(signal.SIGTERM)
        assert "Traceback" not in peer.log_text(), peer.log_text()
