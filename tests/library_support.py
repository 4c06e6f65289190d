"""What the library tests share: an emulator on a loop of its own (so that blocking code, a
``SyncScanner``, can talk to it from the test's thread) and the CLI as a subprocess."""

from __future__ import annotations

import asyncio
import os
import subprocess
import sys
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.devices.base import Device

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
