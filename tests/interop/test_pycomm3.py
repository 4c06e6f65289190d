"""pycomm3 (an independent client) against our adapter."""

from __future__ import annotations

import struct
from collections.abc import Iterator
from typing import Any

import pytest

pytest.importorskip("pycomm3", reason="pycomm3, the peer these tests talk to, is not installed: pip install '.[test]'")

from pycomm3 import CIPDriver, Services
from pycomm3.cip import PADDED_EPATH, PortSegment
from pycomm3.cip.data_types import SHORT_STRING, UDINT, UINT, USINT, WORD, Struct
from pycomm3.cip.status_info import SERVICE_STATUS

from .conftest import IDENTITY, PeerProcess

pytestmark = pytest.mark.interop

REVISION = Struct(USINT("major"), USINT("minor"))

#: Identity attribute -> (pycomm3 type, value pycomm3 decodes). Attribute 5 is checked apart.
IDENTITY_ATTRIBUTES: dict[int, tuple[Any, Any]] = {
    1: (UINT, IDENTITY["vendor_id"]),
    2: (UINT, IDENTITY["device_type"]),
    3: (UINT, IDENTITY["product_code"]),
    4: (REVISION, {"major": IDENTITY["revision"][0], "minor": IDENTITY["revision"][1]}),
    6: (UDINT, IDENTITY["serial_number"]),
    7: (SHORT_STRING, IDENTITY["product_name"]),
}

TCPIP_CLASS = 0xF5
INACTIVITY_TIMEOUT = 13
CONNECTION_MANAGER_CLASS = 0x06


def get_single(drv: CIPDriver, class_code: int, instance: int, attribute: int, data_type: Any = None,
               connected: bool = False) -> Any:
    kwargs: dict[str, Any] = {"connected": True} if connected else {"connected": False, "route_path": False}
    return drv.generic_message(service=Services.get_attribute_single, class_code=class_code, instance=instance,
                               attribute=attribute, data_type=data_type, **kwargs)


def set_single(drv: CIPDriver, class_code: int, instance: int, attribute: int, data: bytes,
               connected: bool = False) -> Any:
    kwargs: dict[str, Any] = {"connected": True} if connected else {"connected": False, "route_path": False}
    return drv.generic_message(service=Services.set_attribute_single, class_code=class_code, instance=instance,
                               attribute=attribute, request_data=data, **kwargs)


def ok(tag: Any) -> Any:
    assert tag.error is None, f"pycomm3 reported {tag.error!r}"
    return tag.value


def forward_opens(drv: CIPDriver) -> tuple[int, int]:
    """The adapter's Connection Manager counters, read unconnected: its Open Requests (attribute 1)
    and its rejects of every kind (Open Format, Resource and Other Rejects, attributes 2 to 4)."""
    requests = ok(get_single(drv, CONNECTION_MANAGER_CLASS, 1, 1, UINT))
    rejects = sum(ok(get_single(drv, CONNECTION_MANAGER_CLASS, 1, attribute, UINT)) for attribute in (2, 3, 4))
    return requests, rejects


@pytest.fixture
def driver(adapter: PeerProcess) -> Iterator[CIPDriver]:
    drv = CIPDriver(adapter.address)
    drv.open()
    try:
        yield drv
    finally:
        drv.close()


@pytest.fixture(params=[True, False], ids=["large-forward-open", "forward-open"])
def connected_driver(request: pytest.FixtureRequest, adapter: PeerProcess) -> Iterator[CIPDriver]:
    drv = CIPDriver(adapter.address)
    drv._cfg["extended forward open"] = request.param  # internals: pycomm3 has no public switch for it
    drv.open()
    try:
        yield drv
    finally:
        drv.close()


def test_list_identity_over_tcp(adapter: PeerProcess) -> None:
    identity = CIPDriver.list_identity(adapter.address)
    assert identity is not None, "no ListIdentity reply"
    assert identity["encap_protocol_version"] == 1
    assert identity["ip_address"] == "127.0.0.1"
    assert identity["vendor"] == "LS ELECTRIC"  # pycomm3's name for vendor 259
    assert identity["product_type"] == "AC Drive"  # device type 2
    assert identity["product_code"] == IDENTITY["product_code"]
    assert identity["revision"] == {"major": 1, "minor": 1}
    assert identity["serial"] == f"{IDENTITY['serial_number']:08x}"
    assert identity["product_name"] == IDENTITY["product_name"]
    assert identity["state"] == 3  # operational

    with CIPDriver(adapter.address) as drv:
        status = ok(get_single(drv, 1, 1, 5, WORD))
    word = sum(1 << i for i, bit in enumerate(status) if bit)
    assert identity["status"] == struct.pack("<H", word), "ListIdentity status differs from Identity attribute 5"


@pytest.mark.parametrize("attribute", sorted(IDENTITY_ATTRIBUTES))
def test_get_identity_unconnected(driver: CIPDriver, attribute: int) -> None:
    data_type, expected = IDENTITY_ATTRIBUTES[attribute]
    assert ok(get_single(driver, 1, 1, attribute, data_type)) == expected


def test_get_identity_attributes_all_unconnected(driver: CIPDriver) -> None:
    raw = ok(driver.generic_message(service=Services.get_attributes_all, class_code=1, instance=1,
                                    connected=False, route_path=False))
    status = ok(get_single(driver, 1, 1, 5))
    name = IDENTITY["product_name"].encode()
    expected = (struct.pack("<HHHBB", IDENTITY["vendor_id"], IDENTITY["device_type"], IDENTITY["product_code"],
                            *IDENTITY["revision"])
                + status + struct.pack("<I", IDENTITY["serial_number"]) + bytes((len(name),)) + name)
    assert raw == expected


def test_get_identity_connected(connected_driver: CIPDriver) -> None:
    requests, rejects = forward_opens(connected_driver)
    for attribute, (data_type, expected) in sorted(IDENTITY_ATTRIBUTES.items()):
        assert ok(get_single(connected_driver, 1, 1, attribute, data_type, connected=True)) == expected, attribute
    # One Forward_Open (or Large_Forward_Open, as asked), accepted: the reads went over a connection.
    assert forward_opens(connected_driver) == (requests + 1, rejects), "pycomm3 did not open a connection"
    raw = ok(get_single(connected_driver, 1, 1, 5, connected=True))
    assert len(raw) == 2
    # an error on the connection leaves it usable
    assert get_single(connected_driver, 1, 1, 99, connected=True).error == SERVICE_STATUS[0x14]
    assert ok(get_single(connected_driver, 1, 1, 7, SHORT_STRING, connected=True)) == IDENTITY["product_name"]


def test_attribute_not_supported(driver: CIPDriver) -> None:
    tag = get_single(driver, 1, 1, 99)
    assert tag.error == SERVICE_STATUS[0x14] == "Attribute not supported"
    assert not tag.value
    # the session is still usable
    assert ok(get_single(driver, 1, 1, 1, UINT)) == IDENTITY["vendor_id"]


def test_unknown_class(driver: CIPDriver) -> None:
    tag = get_single(driver, 0x77, 1, 1)
    assert tag.error is not None
    # pycomm3 prints the general status text, then "(general, extended)": no extended status here
    assert tag.error.startswith(SERVICE_STATUS[0x05]), tag.error
    assert tag.error.endswith("(05, 00)"), tag.error
    assert ok(get_single(driver, 1, 1, 1, UINT)) == IDENTITY["vendor_id"]


def test_unknown_instance(driver: CIPDriver) -> None:
    tag = get_single(driver, 1, 9, 1)
    assert tag.error is not None and tag.error.startswith(SERVICE_STATUS[0x05]), tag.error


def test_set_read_only_attribute(driver: CIPDriver) -> None:
    tag = set_single(driver, TCPIP_CLASS, 1, 1, UDINT.encode(0))
    assert tag.error == SERVICE_STATUS[0x0E] == "Attribute not settable"


def test_set_inactivity_timeout_then_read_back(driver: CIPDriver, adapter: PeerProcess) -> None:
    original = ok(get_single(driver, TCPIP_CLASS, 1, INACTIVITY_TIMEOUT, UINT))
    assert original == 120, "the encapsulation inactivity timeout defaults to 120 s"
    try:
        ok(set_single(driver, TCPIP_CLASS, 1, INACTIVITY_TIMEOUT, UINT.encode(60)))
        assert ok(get_single(driver, TCPIP_CLASS, 1, INACTIVITY_TIMEOUT, UINT)) == 60
        # another client (a new session) sees the value
        with CIPDriver(adapter.address) as other:
            assert ok(get_single(other, TCPIP_CLASS, 1, INACTIVITY_TIMEOUT, UINT)) == 60
            ok(set_single(other, TCPIP_CLASS, 1, INACTIVITY_TIMEOUT, UINT.encode(90), connected=True))
            assert ok(get_single(other, TCPIP_CLASS, 1, INACTIVITY_TIMEOUT, UINT, connected=True)) == 90
        assert ok(get_single(driver, TCPIP_CLASS, 1, INACTIVITY_TIMEOUT, UINT)) == 90
        # too little data for a UINT
        short = set_single(driver, TCPIP_CLASS, 1, INACTIVITY_TIMEOUT, b"\x05")
        assert short.error == SERVICE_STATUS[0x13], short.error
        assert ok(get_single(driver, TCPIP_CLASS, 1, INACTIVITY_TIMEOUT, UINT)) == 90
    finally:
        ok(set_single(driver, TCPIP_CLASS, 1, INACTIVITY_TIMEOUT, UINT.encode(original)))
    assert ok(get_single(driver, TCPIP_CLASS, 1, INACTIVITY_TIMEOUT, UINT)) == original


def test_unconnected_send_with_route(driver: CIPDriver) -> None:
    """pycomm3 wraps the request in Unconnected_Send with its route path (port 1, link 0)."""
    tag = driver.generic_message(service=Services.get_attribute_single, class_code=1, instance=1, attribute=7,
                                 data_type=SHORT_STRING, connected=False, unconnected_send=True, route_path=True)
    assert ok(tag) == IDENTITY["product_name"]


def test_get_module_info_through_backplane_route(driver: CIPDriver) -> None:
    """pycomm3 reads Identity Get_Attributes_All in Unconnected_Send via port 1 link 0, and decodes it itself."""
    info = driver.get_module_info(0)
    assert info["vendor"] == "LS ELECTRIC"
    assert info["product_type"] == "AC Drive"
    assert info["product_code"] == IDENTITY["product_code"]
    assert info["revision"] == {"major": 1, "minor": 1}
    assert info["serial"] == f"{IDENTITY['serial_number']:08x}"
    assert info["product_name"] == IDENTITY["product_name"]


@pytest.mark.parametrize(("port", "link", "extended"), [("bp", 1, 0x0312), ("bp", 5, 0x0312), ("enet", 0, 0x0311)])
def test_unconnected_send_to_missing_port_or_link(driver: CIPDriver, port: str, link: int, extended: int) -> None:
    route = PADDED_EPATH.encode((PortSegment(port, link),), length=True, pad_length=True)
    tag = driver.generic_message(service=Services.get_attributes_all, class_code=1, instance=1, connected=False,
                                 unconnected_send=True, route_path=route)
    assert tag.error is not None and tag.error.startswith(SERVICE_STATUS[0x01]), tag.error
    assert tag.error.endswith(f"(01, {extended:x})"), tag.error


def test_default_route_path_appends_two_bytes(driver: CIPDriver) -> None:
    """pycomm3's default route_path=True appends ``00 00`` after a plain request: trailing data is "too much"."""
    tag = driver.generic_message(service=Services.get_attribute_single, class_code=1, instance=1, attribute=1,
                                 data_type=UINT, connected=False)
    assert tag.error == SERVICE_STATUS[0x15] == "Too much data"
    assert ok(get_single(driver, 1, 1, 1, UINT)) == IDENTITY["vendor_id"]


@pytest.mark.parametrize("large", [True, False], ids=["large-forward-open", "forward-open"])
def test_route_in_the_path(adapter: PeerProcess, large: bool) -> None:
    """``HOST:PORT/bp/0``: pycomm3 puts port 1 link 0 in the Forward_Open path and in Unconnected_Send."""
    drv = CIPDriver(f"{adapter.address}/bp/0")
    drv._cfg["extended forward open"] = large  # internals: pycomm3 has no public switch for it
    drv.open()
    try:
        requests, rejects = forward_opens(drv)
        assert ok(get_single(drv, 1, 1, 7, SHORT_STRING, connected=True)) == IDENTITY["product_name"]
        assert forward_opens(drv) == (requests + 1, rejects)
        tag = drv.generic_message(service=Services.get_attribute_single, class_code=1, instance=1, attribute=1,
                                  data_type=UINT, connected=False, unconnected_send=True)
        assert ok(tag) == IDENTITY["vendor_id"]
    finally:
        drv.close()


def test_forward_open_to_a_missing_slot_is_refused(adapter: PeerProcess, caplog: pytest.LogCaptureFixture) -> None:
    drv = CIPDriver(f"{adapter.address}/bp/3")
    drv.open()
    try:
        requests, rejects = forward_opens(drv)
        with caplog.at_level("ERROR"), pytest.raises(Exception, match="did not connect"):
            get_single(drv, 1, 1, 7, SHORT_STRING, connected=True)
        requests_after, rejects_after = forward_opens(drv)
        assert requests_after > requests and requests_after - rejects_after == requests - rejects  # all refused
        failures = [r.getMessage() for r in caplog.records if "forward_open failed" in r.getMessage()]
        assert failures and failures[0].endswith("(01, 312)"), failures
        # the session is still usable without a connection
        assert ok(get_single(drv, 1, 1, 1, UINT)) == IDENTITY["vendor_id"]
    finally:
        drv.close()
