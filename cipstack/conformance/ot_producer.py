"""The O->T side of a class 1 connection the battery holds open while it also talks explicitly to the
target: the data commanded last, sent at the granted API from a thread of its own.

Why a thread: a motion check writes attributes (ForceFault, the speed reference) and reads others
(input 70's missing flags) by explicit messaging in the middle of a connection. Each request is a
TCP round trip; if O->T waited for them, a slow target or a loaded machine would let the connection
reach its timeout (RPI x 4 << multiplier), and a real drive trips on that (its communication-loss
action), failing checks for a fault the battery caused. A new command is sent at once, not at the
next API tick: the checks time their bounds from it.
"""

from __future__ import annotations

import contextlib
import socket
import threading
import time

from ..eip.io_core import encode_io_datagram


class OutputProducer:
    """Sends ``command``'s data to ``address`` on ``sock`` every ``api_s`` seconds until ``stop``."""

    def __init__(self, sock: socket.socket, address: tuple[str, int], connection_id: int, api_s: float,
                 run_idle_header: bool) -> None:
        self._sock, self._address, self._connection_id = sock, address, connection_id
        self._api_s, self._run_idle_header = api_s, run_idle_header
        self._lock = threading.Lock()
        self._changed = threading.Event()
        self._stopped = threading.Event()
        self._data: bytes | None = None
        self._run = True
        self.sequence = 0
        #: The first datagram sent, for the report's exchanges.
        self.first: bytes | None = None
        self._thread = threading.Thread(target=self._produce, name="battery O->T", daemon=True)

    def command(self, data: bytes, run: bool = True) -> None:
        """From now on send ``data`` (``run`` False: in idle packets); a change goes out at once."""
        with self._lock:
            if (data, run) == (self._data, self._run):
                return
            self._data, self._run = data, run
        self._changed.set()
        if not self._thread.is_alive() and not self._stopped.is_set():
            self._thread.start()

    def stop(self) -> None:
        """Send nothing more (before the connection is closed)."""
        self._stopped.set()
        self._changed.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)

    def _produce(self) -> None:
        due = time.monotonic()
        while not self._stopped.is_set():
            self._changed.wait(max(0.0, due - time.monotonic()))
            if self._stopped.is_set():
                return
            changed = self._changed.is_set()
            self._changed.clear()
            now = time.monotonic()
            if not changed and now < due:
                continue
            with self._lock:
                data, run = self._data, self._run
            if data is None:
                continue
            self.sequence += 1
            run_idle = (1 if run else 0) if self._run_idle_header else None
            datagram = encode_io_datagram(self._connection_id, self.sequence, self.sequence, data, run_idle)
            self.first = self.first or datagram
            with contextlib.suppress(OSError):  # a closed or unreachable peer: the reader sees no T->O
                self._sock.sendto(datagram, self._address)
            due = now + self._api_s
