"""A request answered 0x15 (too much data) names its likely cause in the adapter's log (issue 43,
item 4). pycomm3's ``CIPDriver.generic_message`` sends a request straight to the device with the
route path of an Unconnected_Send after it unless ``route_path=False``: ``00 00`` (an empty route
path) for a device addressed by its IP address, ``01 00 01 00`` (port 1, link 0) for ``HOST/1/0``.
A strict device answers 0x15, and the client shows only "Too much data". Reproduced here from those
wire bytes, by a scripted peer against an in-process adapter."""

from __future__ import annotations

import logging

import pytest

from cipstack.devices.profiles import build_device
from cipstack.eip.target.trailing_bytes import route_path_at_end, too_much_data_hint
from tests.attacks import GET_NAME, IDENTITY_NAME, Client
from tests.library_support import threaded_adapter

#: What pycomm3 puts after the request: the empty route path, and port 1 link 0.
EMPTY_ROUTE, BACKPLANE_SLOT_0 = bytes.fromhex("0000"), bytes.fromhex("01000100")
CAUSE = ("a client that appends the route path of an Unconnected_Send to a request sent to the device itself "
         "(pycomm3's generic_message does, unless route_path=False)")


def test_the_hint_names_the_bytes_and_reads_them_as_a_route_path() -> None:
    assert too_much_data_hint(GET_NAME + EMPTY_ROUTE) == (
        "Get_Attribute_Single 0x01/1/7 answered 0x15 (too much data): the request carries 2 bytes after it "
        f"(00 00), which read as a route path (empty): {CAUSE}")
    assert too_much_data_hint(GET_NAME + BACKPLANE_SLOT_0).endswith(
        f"carries 4 bytes after it (01 00 01 00), which read as a route path (port 1, link 0): {CAUSE}")
    # Bytes that are no route path are named, without a cause guessed.
    assert too_much_data_hint(GET_NAME + b"\x05") == (
        "Get_Attribute_Single 0x01/1/7 answered 0x15 (too much data): the request carries 1 byte after it (05)")
    assert route_path_at_end(GET_NAME) is None
    assert too_much_data_hint(b"\x0e\x09") == "a request of 2 bytes answered 0x15 (too much data)"


@pytest.mark.parametrize("route", [EMPTY_ROUTE, BACKPLANE_SLOT_0], ids=["empty", "port1-link0"])
def test_the_adapter_answers_0x15_logs_why_and_keeps_serving(route: bytes, caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, logger="cipstack.eip.target.core")
    with threaded_adapter(build_device("acg")) as adapter, Client(adapter.port) as client:
        status, _, data = client.request(GET_NAME + route)
        assert (status, data) == (0x15, b"")
        assert client.request(GET_NAME) == (0, (), IDENTITY_NAME)   # the same request without them
        for _ in range(5):   # a client that goes on doing it: one line per 10 s, not one per request
            assert client.request(GET_NAME + route)[0] == 0x15
    lines = [r.getMessage() for r in caplog.records if "answered 0x15" in r.getMessage()]
    assert len(lines) == 1, lines
    hops = "empty" if route == EMPTY_ROUTE else "port 1, link 0"
    assert lines[0].startswith("127.0.0.1:") and lines[0].endswith(f"which read as a route path ({hops}): {CAUSE}")
