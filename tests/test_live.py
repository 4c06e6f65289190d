"""Our scanner against our adapter over real loopback sockets."""

from __future__ import annotations

import asyncio
import struct
import time
from collections.abc import AsyncIterator

import pytest

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.cip.epath import PortSegment, request_path
from cipstack.cip.messages import MessageRouterRequest
from cipstack.cip.status import CipError
from cipstack.cip.types import UDINT, UINT
from cipstack.devices.profiles import identity_only_device
from cipstack.eip.originator.asyncio_client import EncapsulationClient, discover, list_services_udp
from cipstack.scanner import Scanner, SyncScanner, backplane_route
from tests.waiting import wait_until


@pytest.fixture
async def adapter() -> AsyncIterator[Adapter]:
    async with Adapter(AdapterSettings(host="127.0.0.1", port=0), device=identity_only_device()) as running:
        yield running


@pytest.fixture
async def scanner(adapter: Adapter) -> AsyncIterator[Scanner]:
    scanner = await Scanner.connect(f"127.0.0.1:{adapter.port}", timeout=3)
    yield scanner
    await scanner.close()


async def test_identity_attributes(scanner: Scanner) -> None:
    assert await scanner.read(1, 1, 1) == 259
    assert await scanner.read(1, 1, 2) == 2
    assert await scanner.read(1, 1, 3) == 100
    assert await scanner.read(1, 1, 4) == {"major": 1, "minor": 1}
    assert await scanner.read(1, 1, 6) == 0x10000064
    value = await scanner.get_attribute_single(1, 1, 7)
    assert (value.value, value.data, value.spec and value.spec.name) == ("CENT", b"\x04CENT", "Product Name")
    assert await scanner.read(1, 0, 1) == 1  # class revision


async def test_get_attributes_all_decodes_by_declaration(scanner: Scanner) -> None:
    raw, values = await scanner.get_attributes_all(1, 1)
    assert values == {"Vendor ID": 259, "Device Type": 2, "Product Code": 100, "Revision": {"major": 1, "minor": 1},
                      "Status": 0, "Serial Number": 0x10000064, "Product Name": "CENT"}
    assert raw.endswith(b"\x04CENT")


async def test_errors_name_the_status(scanner: Scanner) -> None:
    with pytest.raises(CipError) as exc:
        await scanner.read(1, 1, 99)
    assert exc.value.general == 0x14 and "attribute not supported" in str(exc.value)
    with pytest.raises(CipError) as exc:
        await scanner.read(0x77, 1, 1)
    assert exc.value.general == 0x05
    with pytest.raises(CipError) as exc:
        await scanner.set_attribute_single(0xF5, 1, 13, 5000)
    assert exc.value.general == 0x09


async def test_set_and_lists(scanner: Scanner, adapter: Adapter) -> None:
    await scanner.set_attribute_single(0xF5, 1, 13, 90)
    assert await scanner.read(0xF5, 1, 13) == 90
    assert adapter.device.inactivity_timeout == 90
    results = await scanner.get_attribute_list(1, 1, [1, 3, 42, 7])
    assert results[1].value == 259 and results[3].value == 100 and results[7].value == "CENT"  # type: ignore[union-attr]
    assert isinstance(results[42], CipError) and results[42].general == 0x14
    assert await scanner.set_attribute_list(0xF5, 1, {13: 30}) == {13: 0}
    assert await scanner.set_attribute_list(0xF5, 1, {13: 4000}) == {13: 0x09}
    assert await scanner.read(0xF5, 1, 13) == 30


async def test_multiple_service_packet_and_any_service(scanner: Scanner) -> None:
    replies = await scanner.multiple_service_packet([
        MessageRouterRequest(0x0E, request_path(1, 1, 1)), MessageRouterRequest(0x0E, request_path(1, 1, 7)),
        MessageRouterRequest(0x0E, request_path(1, 1, 77))])
    assert [r.general_status for r in replies] == [0, 0, 0x14]
    assert replies[1].data == b"\x04CENT"
    reply = await scanner.request(0x4B, 1, 1, check=False)
    assert reply.general_status == 0x08


async def test_reset(scanner: Scanner, adapter: Adapter) -> None:
    await scanner.reset(1, 1, 1)
    assert adapter.device.pending_reset == 1
    with pytest.raises(CipError) as exc:
        await scanner.reset(1, 1, 9)
    assert exc.value.general == 0x03


async def test_routed_requests(adapter: Adapter) -> None:
    routed = await Scanner.connect(f"127.0.0.1:{adapter.port}", route=backplane_route(0))
    try:
        assert await routed.read(1, 1, 7) == "CENT"
    finally:
        await routed.close()
    wrong = await Scanner.connect(f"127.0.0.1:{adapter.port}", route=[PortSegment(1, b"\x05")])
    try:
        with pytest.raises(CipError) as exc:
            await wrong.read(1, 1, 7)
        assert exc.value.general == 0x01 and exc.value.extended == (0x0312,)
    finally:
        await wrong.close()


@pytest.mark.parametrize("large", [False, True])
async def test_class3_connection(scanner: Scanner, adapter: Adapter, large: bool) -> None:
    await scanner.open_connection(rpi=1.0, large=large)
    assert len(adapter.device.connection_table.connections) == 1
    connection = next(iter(adapter.device.connection_table.connections.values()))
    for _ in range(3):
        assert await scanner.read(1, 1, 7) == "CENT"
    assert connection.requests == 3
    await scanner.close_connection()
    assert not adapter.device.connection_table.connections


async def test_requests_in_flight_together(scanner: Scanner) -> None:
    values = await asyncio.gather(*(scanner.read(1, 1, attribute) for attribute in [1, 2, 3, 6, 7] * 20))
    assert values[:5] == [259, 2, 100, 0x10000064, "CENT"]
    assert values[5:10] == values[:5]


async def test_list_commands(adapter: Adapter) -> None:
    client = await EncapsulationClient.connect("127.0.0.1", adapter.port, register=False)
    try:
        [identity] = await client.list_identity()
        assert identity.product_name == "CENT" and identity.address is not None
        assert identity.address.port == adapter.port
        [service] = await client.list_services()
        assert service.name == "Communications" and service.cip_over_tcp
        assert await client.list_interfaces() == []
    finally:
        await client.close()


async def test_udp_discovery(adapter: Adapter) -> None:
    # Both at once, each collecting its own window.
    records, services = await asyncio.gather(discover("127.0.0.1", adapter.port, timeout=0.8),
                                             list_services_udp("127.0.0.1", adapter.port, timeout=0.3))
    assert [(r.vendor_id, r.product_code, r.product_name) for r in records] == [(259, 100, "CENT")]
    assert records[0].address and records[0].address.port == adapter.port
    [service] = services
    assert service.cip_over_tcp


async def test_inactivity_timeout_closes_idle_connection(adapter: Adapter) -> None:
    adapter.device.tcpip.set(1, 13, 1)
    connected = time.monotonic()
    client = await EncapsulationClient.connect("127.0.0.1", adapter.port)
    # The subject: closed once idle for the timeout (1 s), not before.
    await wait_until(lambda: not adapter.server.connections, 1.6, "the idle connection closed")
    assert time.monotonic() - connected >= 1.0
    with pytest.raises(ConnectionError):
        await client.send_rr_data(MessageRouterRequest(0x0E, request_path(1, 1, 1)).encode())
    await client.close()


async def test_typed_request_bytes(scanner: Scanner) -> None:
    reply = await scanner.request(0x0E, 0xF6, 1, 1)
    assert UDINT.decode(reply.data) == 100
    reply = await scanner.request(0x0E, 0x02, 1, 2)
    assert UINT.decode(reply.data) == 32
    raw, values = await scanner.get_attributes_all(0xF6, 1)
    assert raw == struct.pack("<II", 100, 0x0F) + bytes.fromhex("02CA10000064")
    assert values and values["Physical Address"] == bytes.fromhex("02CA10000064")


def test_sync_scanner() -> None:
    async def start() -> Adapter:
        adapter = Adapter(AdapterSettings(host="127.0.0.1", port=0), device=identity_only_device())
        await adapter.start()
        return adapter

    loop = asyncio.new_event_loop()
    adapter = loop.run_until_complete(start())
    import threading

    thread = threading.Thread(target=loop.run_forever, daemon=True)
    thread.start()
    try:
        with SyncScanner(f"127.0.0.1:{adapter.port}") as scanner:
            assert scanner.read(1, 1, 7) == "CENT"
            scanner.open_connection()
            assert scanner.read(1, 1, 1) == 259
            with pytest.raises(CipError):
                scanner.read(1, 1, 99)
    finally:
        asyncio.run_coroutine_threadsafe(adapter.close(), loop).result(5)
        loop.call_soon_threadsafe(loop.stop)
        thread.join(5)
        loop.close()


def test_sync_scanner_connection_refused() -> None:
    with pytest.raises(ConnectionError):
        SyncScanner("127.0.0.1:1", timeout=1)


def test_the_adapter_freezes_its_start_up_objects_once_it_serves() -> None:
    """A full collection over one ACG drive's 28,000 objects stops the loop for about 8 ms, past a
    1 ms connection's watchdog (the stall behind `cipstack io` timing out at 1 ms): once the
    adapter serves, what start-up built is frozen out of the collector's reach."""
    import gc
    import os
    import signal

    from cipstack.eip.io_server import run_precise

    async def serve_then_stop() -> int:
        adapter = Adapter(AdapterSettings(host="127.0.0.1", port=0, io_port=0))
        serving = asyncio.ensure_future(adapter.serve_forever())
        for _ in range(500):
            if gc.get_freeze_count() or serving.done():
                break
            await asyncio.sleep(0.01)
        frozen = gc.get_freeze_count()
        os.kill(os.getpid(), signal.SIGTERM)   # serve_forever's own handler: it closes and returns
        await asyncio.wait_for(serving, 10)
        return frozen

    gc.unfreeze()
    try:
        frozen = run_precise(serve_then_stop())
    finally:
        gc.unfreeze()
    assert frozen > 0
