"""Class 1 over real loopback sockets: our scanner and our adapter, several connections at once."""

from __future__ import annotations

import asyncio
import signal
import subprocess
import sys
import textwrap
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.assemblies.drive_profile import (
    basic_speed_control_input,
    basic_speed_control_output,
    extended_speed_control_input,
    extended_speed_control_output,
)
from cipstack.catalog import Catalog
from cipstack.devices.base import Device
from cipstack.devices.profiles import acg_et2_identity
from cipstack.eip.originator.io_originator import IoTimeoutError
from cipstack.eip.target.io_target import IoConnection, IoProfile
from cipstack.objects.assembly import AssemblyPoint
from cipstack.objects.tcpip import NetworkInterface
from cipstack.scanner import Scanner
from tests.ports import free_port
from tests.waiting import wait_until

OUTPUTS = [basic_speed_control_output(), extended_speed_control_output()]
INPUTS = [basic_speed_control_input(), extended_speed_control_input()]
CATALOG = Catalog(assemblies=[*OUTPUTS, *INPUTS])


@dataclass
class SpeedDevice(Device):
    """A device whose input assemblies echo the speed reference and run bits of its outputs."""

    consumed: list[tuple[int, bytes, float]] = field(default_factory=list)
    closed: list[bool] = field(default_factory=list)
    run_modes: list[bool] = field(default_factory=list)

    def __post_init__(self) -> None:
        super().__post_init__()
        self.state = {"run_forward": False, "speed": 0}
        for schema in OUTPUTS:
            self.assembly.add_assembly(AssemblyPoint(schema.instance, schema.size, True, consume=self._consume(schema)))
        self.assembly.add_assembly(AssemblyPoint(70, 4, False, produce=lambda: INPUTS[0].encode(
            running_forward=self.state["run_forward"], speed_actual=self.state["speed"])))
        self.assembly.add_assembly(AssemblyPoint(71, 4, False, produce=lambda: INPUTS[1].encode(
            running_forward=self.state["run_forward"], speed_actual=self.state["speed"], ready=True)))

    def _consume(self, schema):  # type: ignore[no-untyped-def]
        def consume(data: bytes, now: float) -> None:
            values = schema.decode(data)
            self.state.update(run_forward=values["run_forward"], speed=values["speed_reference"])
            self.consumed.append((schema.instance, data, now))
        return consume

    def io_profile(self) -> IoProfile:
        return IoProfile(lambda: {p: self.assembly.points[p] for p in (20, 21)},
                         lambda: {p: self.assembly.points[p] for p in (70, 71)}, rpi_min_us=1000)

    def io_closed(self, connection: IoConnection, timed_out: bool) -> None:
        super().io_closed(connection, timed_out)
        self.closed.append(timed_out)

    def io_run_idle(self, connection: IoConnection, run: bool) -> None:
        super().io_run_idle(connection, run)
        self.run_modes.append(run)




async def start_adapter(host: str, io_port: int = 0) -> Adapter:
    device = SpeedDevice(acg_et2_identity(), NetworkInterface(ip_address=host))
    adapter = Adapter(AdapterSettings(host=host, port=0, io_port=io_port), device=device)
    await adapter.start()
    return adapter


@pytest.fixture
async def adapter() -> AsyncIterator[Adapter]:
    running = await start_adapter("127.0.0.1")
    yield running
    await running.close()


async def test_fields_by_name_and_updates(adapter: Adapter) -> None:
    assert adapter.io_endpoint is not None
    async with await Scanner.connect(f"127.0.0.1:{adapter.port}", catalog=CATALOG) as scanner:
        async with scanner.io_connection(output=21, input=71, rpi=0.005, timeout_multiplier=5,
                                         target_io_port=adapter.io_endpoint.port) as io:
            io.output.run_forward = True
            io.output.speed_reference = 1500
            image = await io.wait_input(lambda i: i.speed_actual == 1500, timeout=5)
            assert image.running_forward and image.ready
            assert io.input.fields()["speed_actual"] == 1500
            device = adapter.device
            assert isinstance(device, SpeedDevice)
            assert device.consumed[-1][:2] == (21, bytes.fromhex("0100dc05"))
            assert device.identity.status & 0x00F1 == 0x0061  # owned, I/O running
            io.set_run(False)
            await wait_until(lambda: device.run_modes and device.run_modes[-1] is False, 5, "idle at the device")
            assert device.identity.status & 0x00F0 == 0x0070  # idle
            await wait_until(lambda: io.stats.sent > 5 and io.stats.received > 5, 5, "data both ways")
            assert io.stats.lost == 0
        assert device.closed == [False]
        assert not adapter.io or not adapter.io.connections  # Forward_Close on exit


async def test_kernel_arrival_times_through_the_scanner(adapter: Adapter) -> None:
    """``kernel_arrival_times``: on the precise loop the packets are timed by the kernel, and the
    intervals still say what the target does (its RPI); on asyncio's own loop it cannot be, and the
    handle says so."""
    from cipstack.eip.io_server import PreciseEventLoop

    assert adapter.io_endpoint is not None
    rpi = 0.004
    scanner = await Scanner.connect(f"127.0.0.1:{adapter.port}", catalog=CATALOG)
    async with scanner, scanner.io_connection(output=21, input=71, rpi=rpi, target_io_port=adapter.io_endpoint.port,
                                              timeout_multiplier=5, keep_intervals=True,
                                              kernel_arrival_times=True) as io:
        await wait_until(lambda: len(io.connection.interval_samples) > 20, 5, "20 intervals")
        intervals = sorted(io.connection.interval_samples)
        kernel = io.kernel_arrival_times
    assert kernel is isinstance(asyncio.get_running_loop(), PreciseEventLoop)
    assert len(intervals) > 20
    assert 0.5 * rpi < intervals[len(intervals) // 2] < 1.5 * rpi


async def test_sizes_from_attribute_4_without_schema(adapter: Adapter) -> None:
    assert adapter.io_endpoint is not None
    scanner = await Scanner.connect(f"127.0.0.1:{adapter.port}", identify=False)  # no catalog: raw bytes
    async with scanner, scanner.io_connection(output=20, input=70, rpi=0.004, timeout_multiplier=5,
                                              target_io_port=adapter.io_endpoint.port) as io:
        io.output.raw = bytes.fromhex("0100e803")
        image = await io.wait_input(lambda i: i.raw == bytes.fromhex("0400e803"), timeout=5)
        assert image.raw[2:] == (1000).to_bytes(2, "little")
        with pytest.raises(AttributeError):
            io.output.speed_reference = 5  # no schema: fields unknown


async def test_several_targets_on_two_loopback_addresses() -> None:
    port = free_port("127.0.0.1", "127.0.0.2")
    first = await start_adapter("127.0.0.2", io_port=port)
    second = await start_adapter("127.0.0.1", io_port=free_port("127.0.0.1"))
    try:
        assert first.io_endpoint and second.io_endpoint
        a = await Scanner.connect(f"127.0.0.2:{first.port}", catalog=CATALOG)
        b = await Scanner.connect(f"127.0.0.1:{second.port}", catalog=CATALOG)
        second_port = second.io_endpoint.port
        # Our originator's own I/O socket uses the same port number, on 127.0.0.1.
        async with a, b, a.io_connection(output=21, input=71, rpi=0.002, target_io_port=port,
                                         local_io_port=port, timeout_multiplier=5) as io_a, \
                b.io_connection(output=21, input=71, rpi=0.003, target_io_port=second_port,
                                timeout_multiplier=5) as io_b, \
                b.io_connection(output=20, input=70, rpi=0.010, target_io_port=second_port,
                                timeout_multiplier=5) as io_c:
            io_a.output.speed_reference = 111
            io_b.output.speed_reference = 222
            io_c.output.speed_reference = 333
            await io_a.wait_input(lambda i: i.speed_actual == 111, 5)
            await io_b.wait_input(lambda i: i.speed_actual in (222, 333), 5)
            await wait_until(lambda: io_a.stats.received > 50 and io_b.stats.received > 30 and io_c.stats.received > 10,
                             5, "data on all three connections")
            assert first.io and first.io.connections and len(second.io.connections) == 2  # type: ignore[union-attr]
    finally:
        await first.close()
        await second.close()


def _slot_offsets(first: float, second: float, period: float) -> float:
    """How far apart two times are on a grid of ``period``: 0 when they fall on the same slots."""
    apart = (second - first) % period
    return min(apart, period - apart)


async def test_connections_opened_apart_are_produced_in_the_same_slots_both_ways(adapter: Adapter) -> None:
    """Two Forward_Opens at 10 ms, 3 ms apart: the adapter's T->O and the scanner's O->T productions of
    the second fall on the first's slots (whole periods apart), and on the wire the two T->O packets of a
    slot reach the scanner together, not 3 ms and a round trip apart."""
    assert adapter.io_endpoint is not None and adapter.io is not None
    rpi = 0.010
    scanner = await Scanner.connect(f"127.0.0.1:{adapter.port}", catalog=CATALOG)
    async with scanner, scanner.io_connection(output=21, input=71, rpi=rpi, target_io_port=adapter.io_endpoint.port,
                                              timeout_multiplier=5, kernel_arrival_times=True) as io_a:
        await asyncio.sleep(0.003)
        async with scanner.io_connection(output=20, input=70, rpi=rpi, target_io_port=adapter.io_endpoint.port,
                                         timeout_multiplier=5, kernel_arrival_times=True) as io_b:
            produced = [c.producer for c in adapter.io.connections.values() if c.producer is not None]
            assert len(produced) == 2
            assert _slot_offsets(produced[0].next_due, produced[1].next_due, rpi) < 1e-9
            assert _slot_offsets(io_a.connection.producer.next_due, io_b.connection.producer.next_due, rpi) < 1e-9
            apart = []
            for _ in range(9):
                await asyncio.sleep(0.037)
                a, b = io_a.connection.arrivals.last, io_b.connection.arrivals.last
                assert a is not None and b is not None
                apart.append(_slot_offsets(a, b, rpi))
    # The median of nine looks: one adapter wake-up sends both, microseconds apart (a look may fall
    # between the two of a slot, or the adapter be preempted between them: the median is past that).
    assert sorted(apart)[4] < 0.001, apart


async def test_originator_watchdog_raises_when_target_stops(adapter: Adapter) -> None:
    assert adapter.io_endpoint is not None
    scanner = await Scanner.connect(f"127.0.0.1:{adapter.port}", catalog=CATALOG)
    async with scanner, scanner.io_connection(output=21, input=71, rpi=0.002, timeout_multiplier=0,
                                              target_io_port=adapter.io_endpoint.port) as io:
        await io.wait_input(lambda i: i.ready, 5)
        await adapter.io_endpoint.close()  # the target goes silent
        with pytest.raises(IoTimeoutError):
            async for _ in io.updates():
                pass
        assert io.timed_out


async def test_killed_originator_times_out_at_the_target(adapter: Adapter, tmp_path: Path) -> None:
    assert adapter.io_endpoint is not None
    script = tmp_path / "originator.py"
    script.write_text(textwrap.dedent(f"""
        import asyncio, sys
        from cipstack.scanner import Scanner
        async def main():
            scanner = await Scanner.connect("127.0.0.1:{adapter.port}")
            async with scanner.io_connection(output=21, input=71, rpi=0.010, timeout_multiplier=3,
                                             target_io_port={adapter.io_endpoint.port}) as io:
                await io.wait_input(lambda i: len(i.raw) == 4, 5)
                print("running", flush=True)
                await asyncio.sleep(60)
        asyncio.run(main())
    """))
    process = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True)
    try:
        line = await asyncio.wait_for(asyncio.get_running_loop().run_in_executor(None, process.stdout.readline), 20)  # type: ignore[union-attr]
        assert line.strip() == "running"
        device = adapter.device
        assert isinstance(device, SpeedDevice)
        assert adapter.io and len(adapter.io.connections) == 1
        process.send_signal(signal.SIGKILL)
        process.wait(5)
        # Timeout = 10 ms x 4 x 2^3 = 320 ms after the last packet (past the stalls of a loaded machine,
        # which at 80 ms timed the connection out before the kill now and then).
        await wait_until(lambda: device.closed, 5, "the target's watchdog")
        assert device.closed == [True]
        assert not adapter.io.connections
        assert device.identity.status & 0x00F0 == 0x0020  # I/O connection faulted
    finally:
        if process.poll() is None:
            process.kill()


async def test_every_port_is_ready_once_the_ethernet_ip_port_accepts() -> None:
    """The adapter takes its EtherNet/IP ports first but accepts TCP on them last: while the class 1
    and Modbus TCP ports are being opened, a connection to the EtherNet/IP port is refused, and once
    it is accepted a Forward_Open finds its class 1 socket (and Modbus TCP its listener)."""
    import socket

    port, modbus_port = free_port(), free_port()
    adapter = Adapter(AdapterSettings(host="127.0.0.1", port=port, io_port=0, modbus_port=modbus_port))
    assert adapter.io_endpoint is not None and adapter.modbus is not None
    refused_while_opening: list[bool] = []

    def refused() -> bool:
        with socket.socket() as probe:
            return probe.connect_ex(("127.0.0.1", port)) != 0

    for opening in (adapter.io_endpoint, adapter.modbus):
        original = opening.start

        async def start(original=original) -> None:  # type: ignore[no-untyped-def]
            refused_while_opening.append(refused())
            await original()
        opening.start = start  # type: ignore[method-assign]
    await adapter.start()
    try:
        assert refused_while_opening == [True, True]
        assert not refused()
        with socket.create_connection(("127.0.0.1", modbus_port), timeout=2):
            pass
        scanner = await Scanner.connect(f"127.0.0.1:{port}", catalog=CATALOG)
        async with scanner, scanner.io_connection(output=21, input=71, rpi=0.005, timeout_multiplier=5,
                                                  target_io_port=adapter.io_endpoint.port) as io:
            for _ in range(500):  # T->O data comes: the class 1 port served the connection
                if io.stats.received:
                    break
                await asyncio.sleep(0.01)
            assert io.stats.received > 0
    finally:
        await adapter.close()


async def test_a_port_another_process_began_to_listen_on_meanwhile_is_named() -> None:
    """Two emulators started together may both bind the EtherNet/IP port (SO_REUSEADDR, neither
    listening yet): the one that listens second fails there, names the port, and leaves nothing open."""
    import socket

    from cipstack.listening import ListenError

    port = free_port()
    rival = socket.socket()
    rival.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    rival.bind(("127.0.0.1", port))
    adapter = Adapter(AdapterSettings(host="127.0.0.1", port=port, io_port=0))
    assert adapter.io_endpoint is not None
    original = adapter.io_endpoint.start

    async def start() -> None:
        rival.listen()  # the other emulator got there first
        await original()
    adapter.io_endpoint.start = start  # type: ignore[method-assign]
    try:
        with pytest.raises(ListenError) as raised:
            await adapter.start()
        assert str(raised.value) == (f"cannot listen on TCP 127.0.0.1:{port} (EtherNet/IP, --port): "
                                     "Address already in use")
        assert not adapter.io_endpoint.is_open
    finally:
        rival.close()
    # Nothing of the failed start holds the ports: the same adapter's ports are free for another.
    again = Adapter(AdapterSettings(host="127.0.0.1", port=port, io_port=0))
    await again.start()
    await again.close()
