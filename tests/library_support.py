"""What the library tests share: an emulator on a loop of its own (so that blocking code, a
``SyncScanner``, can talk to it from the test's thread) and the CLI as a subprocess."""

from __future__ import annotations

import asyncio
import os
import socket
import subprocess
import sys
import threading
import time
from collections.abc import AsyncIterator, Iterator, Sequence
from contextlib import asynccontextmanager, contextmanager
from pathlib import Path

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.devices.base import Device
from cipstack.scanner import Scanner
from tests.ports import free_port

ROOT = Path(__file__).resolve().parents[1]


@contextmanager
def threaded_adapter(device: Device, host: str = "127.0.0.1", params: Sequence[str] = ()) -> Iterator[Adapter]:
    """An in-process adapter serving ``device`` on loopback (ephemeral TCP and UDP ports) from a
    background thread's event loop; closed on exit. ``params``: keypad parameters set first, as
    ``cipstack adapter --param CODE=VALUE`` sets them (``drv=4``, ``Frq=8``)."""
    loop = asyncio.new_event_loop()

    async def start() -> Adapter:
        adapter = Adapter(AdapterSettings(host=host, port=0, io_port=0), device=device)
        if params:
            adapter.apply_keypad_parameters(list(params))
        await adapter.start()
        return adapter

    adapter = loop.run_until_complete(start())
    thread = threading.Thread(target=loop.run_forever, daemon=True)
    thread.start()
    try:
        yield adapter
    finally:
        asyncio.run_coroutine_threadsafe(adapter.close(), loop).result(10)
        loop.call_soon_threadsafe(loop.stop)
        thread.join(10)
        loop.close()


def run_cli(*args: str, timeout: float = 60.0) -> subprocess.CompletedProcess[str]:
    """``python3 -m cipstack ARGS`` with this checkout first on the path."""
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    return subprocess.run([sys.executable, "-m", "cipstack", *args], capture_output=True, text=True,
                          timeout=timeout, env=env, check=False)


@contextmanager
def adapter_process(*args: str) -> Iterator[tuple[str, int]]:
    """``cipstack adapter ARGS`` as a process on loopback, once it accepts TCP: (its address, its
    class 1 UDP port); terminated on exit."""
    port, io_port = free_port(), free_port()
    process = subprocess.Popen([sys.executable, "-m", "cipstack", "adapter", "--port", str(port), "--io-port",
                                str(io_port), "--quiet", *args], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        for _ in range(400):
            try:
                socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
                break
            except OSError:
                assert process.poll() is None, "the adapter exited"
                time.sleep(0.05)
        yield f"127.0.0.1:{port}", io_port
    finally:
        process.terminate()
        process.wait(10)


@asynccontextmanager
async def serving(device: Device) -> AsyncIterator[tuple[Adapter, Scanner]]:
    """An adapter serving ``device`` on loopback in this event loop, and a scanner connected to it."""
    adapter = Adapter(AdapterSettings(host="127.0.0.1", port=0, io_port=0), device=device)
    await adapter.start()
    try:
        async with await Scanner.connect(f"127.0.0.1:{adapter.port}") as scanner:
            yield adapter, scanner
    finally:
        await adapter.close()
