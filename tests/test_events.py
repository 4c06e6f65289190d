"""The event stream of a running ACG emulator (``Adapter.events``): each event with its time, seen as
a scanner's connection, run/idle, parameter writes, a trip and faults happen over loopback."""

from __future__ import annotations

import asyncio

import pytest

from cipstack.adapter import Adapter
from cipstack.devices.profiles import catalog_for
from cipstack.scanner import Scanner
from tests.test_faults import adapter as adapter  # the fixture: an ACG adapter with a state file of its own
from tests.test_faults import connect

CATALOG = catalog_for(259, 100)


async def test_connections_run_idle_writes_trips_and_faults(adapter: Adapter) -> None:
    events = adapter.events
    assert adapter.io_endpoint is not None
    async with await Scanner.connect(f"127.0.0.1:{adapter.port}", catalog=CATALOG) as scanner:
        await scanner.set_attribute_single(0x2A, 1, 102, 25)                    # ACC 2.5 s
        async with scanner.io_connection(output=21, input=71, rpi=0.01, timeout_multiplier=1,
                                         target_io_port=adapter.io_endpoint.port) as io:
            opened = await events.wait_for("connection opened", 5)
            assert opened.fields["connection"] == f"0x{io.connection.ot_connection_id:08X}"
            await events.wait_for("run", 5)
            adapter.fault("idle")
            await events.wait_for("idle", 5)
            adapter.clear_faults()
            await events.wait_for("run", 5, after=opened.number + 1)
            adapter.control({"command": "trip", "code": 0x4200})
            trip = await events.wait_for("trip", 5)
            assert trip.fields == {"trip": "OverHeat", "fault_code": 0x4200}
            mark = events.events[-1].number
            adapter.fault("unplug")                                            # no O->T: the device times out
            timed_out = await events.wait_for("connection timed out", 5, after=mark)
            assert timed_out.fields["originator"] == "127.0.0.1"
            await adapter.faults.settle()
            adapter.fault("plug")
            await adapter.faults.settle()
    kinds = events.kinds()
    write = next(e for e in events.events if e.kind == "parameter write")
    assert (write.fields["service"], write.fields["path"], write.fields["data"]) == ("0x10", "202a24013066", "1900")
    assert kinds.index("parameter write") < kinds.index("connection opened") < kinds.index("trip")
    assert [k for k in kinds if k.startswith("fault")] == ["fault applied", "fault cleared", "fault applied",
                                                            "fault cleared", "fault applied"]
    numbers = [e.number for e in events.events]
    walls = [e.wall for e in events.events]
    assert numbers == sorted(numbers) and walls == sorted(walls)
    assert all(e.time.endswith("Z") and e.as_json()["kind"] == e.kind for e in events.events)


async def test_an_adapter_nobody_watches_has_no_tap(adapter: Adapter) -> None:
    """Watching is an observer of the runtime and one in the request seam, there only while watched:
    unwatched, the seam is the router's own call and a write is no event."""
    router = adapter.device.router
    assert adapter.observers == [] and adapter.requests.handle == router.handle
    stream = adapter.events
    assert adapter.observers == [stream] and adapter.requests.handle != router.handle
    stream.stop()
    assert adapter.observers == [] and adapter.requests.handle == router.handle
    before = len(stream.events)
    async with await connect(adapter) as scanner:
        await scanner.set_attribute_single(0x2A, 1, 102, 55)                 # ACC 5.5 s
    assert len(stream.events) == before


async def test_wait_for_times_out(adapter: Adapter) -> None:
    with pytest.raises(asyncio.TimeoutError):
        await adapter.events.wait_for("trip", 0.05)
