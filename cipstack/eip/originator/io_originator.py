"""Class 1 connections, originator side: the asyncio shell's handle.

The protocol is ``class1.IoOriginator``'s (sans-I/O, shared with the blocking shell); ``io_context``
opens a connection on an asyncio ``IoEndpoint`` and hands back an ``IoConnectionHandle``: set output
fields, read input fields, iterate input updates (an ``asyncio.Queue`` the connection's listener
fills), switch run/idle, read statistics. The core's names are exported from here too, as they
always were.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from typing import TYPE_CHECKING, Any

from ...errors import TimedOut
from ..io_core import RUN_IDLE_HEADER_SIZE, SEQUENCE_COUNT_SIZE, IoStatistics
from .class1 import (
    MAX_CONFIG_DATA,
    MAX_FORWARD_OPEN_SIZE,
    ArrivalStatistics,
    Class1Request,
    IoOriginator,
    IoTimeoutError,
    OriginatorConnection,
    OtFormat,
    class1_path,
    new_connection,
)
from .process_image import ProcessImage

if TYPE_CHECKING:
    from ...assemblies.schema import AssemblySchema
    from ..io_server import IoEndpoint

#: Input changes a reader of ``updates()`` may fall behind by; past it, the oldest is dropped.
UPDATES_QUEUE = 64


class QueueListener:
    """A connection's listener for asyncio readers: each input change into a bounded queue (the newest
    kept: a slow reader sees the latest state), and an empty item when the connection timed out."""

    __slots__ = ("queue",)

    def __init__(self, size: int = UPDATES_QUEUE) -> None:
        self.queue: asyncio.Queue[bytes] = asyncio.Queue(maxsize=size)

    def input_changed(self, data: bytes) -> None:
        queue = self.queue
        if queue.full():
            queue.get_nowait()
        queue.put_nowait(data)

    def timed_out(self) -> None:
        if self.queue.full():
            self.queue.get_nowait()
        self.queue.put_nowait(b"")  # wakes an iterator, which then raises


class IoConnectionHandle:
    """An open class 1 connection: ``output``/``input`` process images, updates, run/idle, statistics."""

    def __init__(self, core: IoOriginator, endpoint: IoEndpoint, connection: OriginatorConnection,
                 output_schema: AssemblySchema | None, input_schema: AssemblySchema | None,
                 updates: asyncio.Queue[bytes] | None = None) -> None:
        self._core = core
        self._updates = updates
        self._endpoint = endpoint
        self.connection = connection
        self.output = ProcessImage(connection.output, output_schema, writable=True)
        self._input_schema = input_schema
        self._input_where = ""
        #: What opening had to adapt to, one line each (e.g. a retry with the size the target asked for).
        self.notes: list[str] = []
        #: The multicast group T->O data comes from (the target's Sockaddr Info), None for point-to-point.
        self.multicast_group: str | None = None

    def describe_schemas(self, output: str, input: str) -> None:
        """Say where the output and input schemas come from (or why there is none), for the
        message of a field name they do not have."""
        object.__setattr__(self.output, "_where", output)
        self._input_where = input

    @property
    def kernel_arrival_times(self) -> bool:
        """Whether T->O packets are timed when the kernel received them (``io_connection``)."""
        return self._endpoint.kernel_arrival_times

    @property
    def input(self) -> ProcessImage:
        self._check()
        return ProcessImage(bytearray(self.connection.input or bytes(self.connection.input_size)),
                            self._input_schema, writable=False, where=self._input_where)

    @property
    def stats(self) -> IoStatistics:
        return self.connection.stats

    @property
    def arrivals(self) -> ArrivalStatistics:
        """T->O inter-arrival times, received rate against the API, missed production slots."""
        return self.connection.arrivals

    def statistics(self) -> dict[str, Any]:
        """Counters and arrival figures in one dictionary."""
        return {**self.connection.stats.as_dict(), **self.connection.arrivals.as_dict()}

    @property
    def timed_out(self) -> bool:
        return self.connection.timed_out

    def _check(self) -> None:
        if self.connection.timed_out:
            raise IoTimeoutError(f"class 1 connection to {self.connection.target_host} timed out")

    def set_run(self, run: bool) -> None:
        """Run (True) or idle (False) in the O->T run/idle header."""
        self.connection.run = run

    def stop_producing(self) -> None:
        """Stop sending O->T data, with no Forward_Close: what the target sees of a scanner that lost
        power or its cable. The target's connection times out and its timeout action runs; T->O data
        is no longer taken. Leaving the ``io_connection`` block still sends the Forward_Close."""
        self._core.remove(self.connection)

    async def updates(self) -> AsyncIterator[ProcessImage]:
        """Input data each time it changes; raises ``IoTimeoutError`` when the target goes silent."""
        queue = self._updates
        assert queue is not None, "a connection opened without a listener has no updates"
        while True:
            self._check()
            data = await queue.get()
            self._check()
            if data:
                yield ProcessImage(bytearray(data), self._input_schema, writable=False, where=self._input_where)

    async def wait_input(self, predicate: Any, timeout: float) -> ProcessImage:
        """Wait until ``predicate(input_image)`` is true, or raise ``InputTimedOut`` after ``timeout``
        seconds (a ``TimedOut``, and still an ``asyncio.TimeoutError``)."""
        async def wait() -> ProcessImage:
            if self.connection.input and predicate(self.input):
                return self.input
            async for image in self.updates():
                if predicate(image):
                    return image
            raise IoTimeoutError("input updates ended")

        try:
            return await asyncio.wait_for(wait(), timeout)
        except asyncio.TimeoutError:
            raise InputTimedOut(f"input did not satisfy the condition within {timeout} s") from None


class InputTimedOut(TimedOut, asyncio.TimeoutError):
    """``wait_input``'s condition did not come true in time: a ``TimedOut`` of cipstack's, and still the
    ``asyncio.TimeoutError`` callers caught before (on Python 3.10 not the builtin ``TimeoutError``)."""


__all__ = ["MAX_CONFIG_DATA", "MAX_FORWARD_OPEN_SIZE", "RUN_IDLE_HEADER_SIZE", "SEQUENCE_COUNT_SIZE",
           "ArrivalStatistics", "Class1Request", "IoConnectionHandle", "IoOriginator", "IoStatistics",
           "IoTimeoutError", "OriginatorConnection", "OtFormat", "ProcessImage", "QueueListener", "class1_path",
           "new_connection"]
