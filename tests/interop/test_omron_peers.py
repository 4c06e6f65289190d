"""pycomm3 and cpppo (independent clients) read and write the Modbus Register (0x64), Function Code
(0x65), Control Supervisor (0x29) and AC/DC Drive (0x2A) objects of an emulated MX2, directly and
routed through the CompoNet gateway (port 2, link = node address)."""

from __future__ import annotations

import json
import signal
import struct
import sys
import textwrap
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("pycomm3", reason="pycomm3, the peer these tests talk to, is not installed: pip install '.[test]'")

from pycomm3 import CIPDriver, Services
from pycomm3.cip.data_types import UDINT, UINT, USINT

from .conftest import HOST, PeerProcess, cpppo_get_attribute, free_port, start_peer

pytestmark = pytest.mark.interop

GATEWAY_PORT = 2
MX2_NODE = 3
RX_NODE = 5

EMULATOR = textwrap.dedent("""
    import sys

    from cipstack.adapter import Adapter, AdapterSettings
    from cipstack.devices.omron.device import build_componet_gateway, build_omron_device
    from cipstack.eip.io_server import run_precise

    kind, port = sys.argv[1], int(sys.argv[2])
    if kind == "mx2":
        device = build_omron_device("MX2-A2015-E")
    else:
        device = build_componet_gateway([("mx2", "MX2-A2015-E", 3), ("rx", "RX-A4055-E", 5)])
    adapter = Adapter(AdapterSettings(host="127.0.0.1", port=port, io_port=0), device=device)
    run_precise(adapter.serve_forever())
""")


def emulator(tmp_path: Path, kind: str) -> Iterator[PeerProcess]:
    script = tmp_path / "emulator.py"
    script.write_text(EMULATOR)
    port = free_port()
    peer = start_peer(f"emulated {kind}", [sys.executable, str(script), kind, str(port)], HOST, port,
                      tmp_path / "emulator.log")
    try:
        yield peer
    finally:
        alive = peer.alive()
        code = peer.stop(signal.SIGTERM)
    text = peer.log_text()
    assert alive and code == 0, f"the emulator exited with {code}:\n{text}"
    assert "Traceback" not in text, text


@pytest.fixture(scope="module")
def mx2(tmp_path_factory: pytest.TempPathFactory) -> Iterator[PeerProcess]:
    yield from emulator(tmp_path_factory.mktemp("mx2"), "mx2")


@pytest.fixture(scope="module")
def gateway(tmp_path_factory: pytest.TempPathFactory) -> Iterator[PeerProcess]:
    yield from emulator(tmp_path_factory.mktemp("gateway"), "gateway")


# -- pycomm3 -------------------------------------------------------------------------------------------

class Pycomm3Target:
    """pycomm3's generic_message, direct (``route_path=False``) or routed by its connection path."""

    def __init__(self, drv: CIPDriver, routed: bool) -> None:
        self.drv = drv
        self.routed = routed

    def message(self, service: int, cls: int, instance: int, attribute: int, data: bytes = b"",
                data_type: Any = None) -> Any:
        options: dict[str, Any] = {"unconnected_send": True, "route_path": True} if self.routed \
            else {"route_path": False}
        tag = self.drv.generic_message(service=service, class_code=cls, instance=instance, attribute=attribute,
                                       request_data=data, data_type=data_type, connected=False, **options)
        assert tag.error is None, tag.error
        return tag.value

    def get(self, cls: int, instance: int, attribute: int, data_type: Any) -> Any:
        return self.message(Services.get_attribute_single, cls, instance, attribute, data_type=data_type)

    def set(self, cls: int, instance: int, attribute: int, data: bytes) -> None:
        self.message(Services.set_attribute_single, cls, instance, attribute, data)

    def error(self, service: int, cls: int, instance: int, attribute: int, data: bytes = b"") -> str:
        options: dict[str, Any] = {"unconnected_send": True, "route_path": True} if self.routed \
            else {"route_path": False}
        tag = self.drv.generic_message(service=service, class_code=cls, instance=instance, attribute=attribute,
                                       request_data=data, connected=False, **options)
        return str(tag.error)


def scenario(target: Pycomm3Target) -> None:
    # 0x65: d005 (3005 = 0BBDh, Table E-3) and P060 (15060 = 3AD4h) as in section E-2-2.
    assert target.get(0x65, 0x0B, 0xBD, UINT) == 0
    target.set(0x65, 0x3A, 0xD4, struct.pack("<I", 128000))
    assert target.get(0x65, 0x3A, 0xD4, UDINT) == 128000
    # 0x64: A004 at 1204h, coil data 1 at 1E01h.
    target.set(0x64, 0x12, 0x04, struct.pack("<H", 600))
    assert target.get(0x64, 0x12, 0x04, UINT) == 600
    assert target.get(0x64, 0x1E, 0x01, UINT) & 0x0002                    # Rdy
    # 0x2A / 0x29: a reference, a forced trip (E62), its reset.
    target.set(0x2A, 1, 8, struct.pack("<h", 1000))
    assert target.get(0x2A, 1, 8, UINT) == 1000
    target.set(0x29, 1, 0x11, b"\x01")
    assert target.get(0x29, 1, 0x65, USINT) == 62
    assert target.get(0x29, 1, 0x0D, UINT) == 0x7510
    target.set(0x29, 1, 0x11, b"\x00")
    target.set(0x29, 1, 0x0C, b"\x00")
    target.set(0x29, 1, 0x0C, b"\x01")
    assert target.get(0x29, 1, 0x0A, USINT) == 0
    # Table E-5 as pycomm3 names the statuses: F001 is not writable through the Function Code object (0x0E),
    # and no Modbus register has the high byte 77h (0x16).
    assert target.error(Services.set_attribute_single, 0x65, 0x13, 0x89, struct.pack("<I", 1)) \
        == "Attribute not settable"
    assert target.error(Services.get_attribute_single, 0x64, 0x77, 0x01) == "Object does not exist"


def test_pycomm3_direct(mx2: PeerProcess) -> None:
    with CIPDriver(mx2.address) as drv:
        scenario(Pycomm3Target(drv, routed=False))


@pytest.mark.parametrize("node", [MX2_NODE, RX_NODE])
def test_pycomm3_through_the_gateway(gateway: PeerProcess, node: int) -> None:
    # pycomm3 puts the route in the connection path: IP:port/port/link.
    with CIPDriver(f"{gateway.address}/{GATEWAY_PORT}/{node}") as drv:
        target = Pycomm3Target(drv, routed=True)
        if node == MX2_NODE:
            scenario(target)
        else:
            assert target.get(1, 1, 3, UINT) == 2073                        # the RX's product code
            target.set(0x29, 1, 0x11, b"\x01")
            assert target.get(0x29, 1, 0x65, USINT) == 72                   # E72 on the RX


# -- cpppo ---------------------------------------------------------------------------------------------

def get_attribute(address: str, *tags: str, route: tuple[int, int] | None = None) -> list[tuple[str, str, Any]]:
    """cpppo's get_attribute: ``-S`` for direct requests, else Unconnected_Send with ``--route-path``."""
    options = ["-S"] if route is None else ["--route-path", json.dumps([{"port": route[0], "link": route[1]}])]
    returncode, rows, output = cpppo_get_attribute(address, *options, *tags)
    assert returncode == 0, output
    assert len(rows) == len(tags), output
    return rows


CPPPO_TAGS = (
    "@0x65/0x3A/0xD4=(UDINT)128000",     # P060 (Table E-3: 3AD4h)
    "@0x65/0x3A/0xD4",
    "@0x64/0x12/0x04=(UINT)550",         # A004 at 1204h
    "@0x64/0x12/0x04",
    "@0x2A/1/8=(INT)1500",               # Speed Ref
    "@0x2A/1/8",
    # Force Fault (appendix E Example 3). cpppo encodes a BOOL's TRUE as FFh (Logix's convention), which
    # Table D-4's BOOL (0 or 1) refuses with 09h like any value out of range: the 1 is sent as a USINT.
    "@0x29/1/0x11=(USINT)1",
    "@0x29/1/0x65",                      # Trip Cause (Example 2): E62 = 3Eh
)


def check_cpppo_rows(rows: list[tuple[str, str, Any]]) -> None:
    values = [value for _, _, value in rows]
    assert values[0] is True and values[2] is True and values[4] is True and values[6] is True
    assert values[1] == list(struct.pack("<I", 128000))
    assert values[3] == list(struct.pack("<H", 550))
    assert values[5] == list(struct.pack("<h", 1500))
    assert values[7] == [62]


def test_cpppo_direct(mx2: PeerProcess) -> None:
    check_cpppo_rows(get_attribute(mx2.address, *CPPPO_TAGS))
    # cpppo's (BOOL)1 is the byte FFh: refused (09h), nothing written, Net Ref still 0.
    returncode, rows, output = cpppo_get_attribute(mx2.address, "-S", "@0x2A/1/4=(BOOL)1", "@0x2A/1/4")
    assert returncode != 0 and rows[0][2] is None and rows[1][2] == [0], output


def test_cpppo_through_the_gateway(gateway: PeerProcess) -> None:
    check_cpppo_rows(get_attribute(gateway.address, *CPPPO_TAGS, route=(GATEWAY_PORT, MX2_NODE)))
    rows = get_attribute(gateway.address, "@1/1/3", route=(GATEWAY_PORT, RX_NODE))
    assert rows[0][2] == list(struct.pack("<H", 2073))
