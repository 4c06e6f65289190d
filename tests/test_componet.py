"""The simulated CompoNet network: node addresses (section 2-1-4), word allocation (section 3-3),
the cyclic refresh, duplicate and lost slaves (Table 26), the explicit-message frames of appendix E
and the route from EtherNet/IP into the network."""

import pytest

from cipstack.cip.epath import PortSegment, encode_path, request_path
from cipstack.cip.messages import MessageRouterRequest, MessageRouterResponse
from cipstack.cip.router import RequestContext
from cipstack.componet.explicit import ExplicitRequest, ExplicitResponse, FrameError, serve_explicit
from cipstack.componet.gateway import COMPONET_PORT
from cipstack.componet.network import CompoNetNetwork, NodeState
from cipstack.devices.omron.device import (
    GATEWAY_IN_AREA,
    GATEWAY_OUT_AREA,
    CompoNetGatewayDevice,
    OmronDevice,
    build_componet_gateway,
    build_omron_device,
)
from cipstack.devices.omron.registers import function_code_path
from cipstack.devices.profiles import componet_gateway, parse_nodes
from cipstack.eip.wire.cm_messages import UnconnectedSendRequest

MX2 = "MX2-A2015-E"
RX = "RX-A4055-E"


def slave(name: str, switches: int, **codes: int) -> OmronDevice:
    d = build_omron_device(name, ethernet=False, rotary_switches=switches)
    d.advance(0.0)
    for code, value in codes.items():
        d.inverter.write_code(code, value, 0.0)
    if codes:
        d.reset(0)
    return d


# -- appendix E frames ----------------------------------------------------------------------------------

FRAMES = [
    # Example 1: Reset the Unit (Identity, service 05h, no attribute).
    (ExplicitRequest(5, 0x05, 0x01, 0x01), "28 02 10 05 05 00 01 00 01"),
    # Example 2: trip cause, class 29h instance 01h attribute 65h.
    (ExplicitRequest(5, 0x0E, 0x29, 0x01, 0x65), "28 02 10 05 0e 00 29 00 01 65"),
    # Example 3: Force Fault = 1.
    (ExplicitRequest(5, 0x10, 0x29, 0x01, 0x11, b"\x01"), "28 02 10 05 10 00 29 00 01 11 01"),
    # Section E-2-2 Example 2: P060 = 128000 at 3AD4h, data in CIP order.
    (ExplicitRequest(63, 0x10, 0x65, 0x3A, 0xD4, bytes.fromhex("00f40100")),
     "28 02 10 3f 10 00 65 00 3a d4 00 f4 01 00"),
]


@pytest.mark.parametrize(("request_", "raw"), FRAMES)
def test_request_frames(request_, raw):
    assert request_.encode().hex(" ") == raw
    assert ExplicitRequest.decode(bytes.fromhex(raw)) == request_


def test_response_frames_and_errors():
    assert ExplicitResponse(5, 0x8E, b"\x3e").encode().hex(" ") == "28 02 00 00 00 04 10 05 8e 3e"
    assert ExplicitResponse(5, 0x90).encode().hex(" ") == "28 02 00 00 00 03 10 05 90"
    assert ExplicitResponse(5, 0x85).encode().hex(" ") == "28 02 00 00 00 03 10 05 85"
    error = ExplicitResponse.error(5, 0x14)
    assert error.encode().hex(" ") == "28 02 00 00 00 05 10 05 94 14 ff"
    assert ExplicitResponse.decode(error.encode()).error_code == (0x14, 0xFF)
    for bad in ("28 01 10 05 0e 00 29 00 01 65",      # another command
                "28 02 00 05 0e 00 29 00 01 65",      # not a word mixed slave (10@@h)
                "28 02 10 40 0e 00 29 00 01 65",      # node 64
                "28 02 10 05 0e 00 29 00 01"):        # attribute missing
        with pytest.raises(FrameError):
            ExplicitRequest.decode(bytes.fromhex(bad))
    with pytest.raises(FrameError):
        ExplicitResponse.decode(bytes.fromhex("28 02 00 00 00 09 10 05 8e 3e"))   # wrong byte count


def test_slave_side_handler_over_the_message_router():
    d = slave(MX2, 5)
    context = RequestContext(d.router, 1.0)
    assert serve_explicit(d.router, ExplicitRequest(5, 0x10, 0x29, 1, 0x11, b"\x01"), context).encode().hex(" ") \
        == "28 02 00 00 00 03 10 05 90"
    assert serve_explicit(d.router, ExplicitRequest(5, 0x0E, 0x29, 1, 0x65), context).encode().hex(" ") \
        == "28 02 00 00 00 04 10 05 8e 3e"                    # E62: force fault from the option board
    d.inverter.set_terminals(1.0, 1)
    d.advance(1.0)
    assert serve_explicit(d.router, ExplicitRequest(5, 0x0E, 0x65, 0x0B, 0xBD), context).data == b"\x01\x00"
    assert serve_explicit(d.router, ExplicitRequest(5, 0x10, 0x65, 0x3A, 0xD4, bytes.fromhex("00f40100")),
                          context).service == 0x90
    assert d.inverter.read_code("P060") == 128000
    assert serve_explicit(d.router, ExplicitRequest(5, 0x0E, 0x64, 0x77, 0x01), context).data == b"\x16\xff"
    assert serve_explicit(d.router, ExplicitRequest(5, 0x05, 0x01, 0x01), context).service == 0x85


# -- addressing and allocation ---------------------------------------------------------------------------

def test_node_address_from_switches_or_p190():
    assert slave(MX2, 12).node_address == 12
    d = slave(MX2, 99, P190=33)                               # switches 64-99: P190 (section 2-1-4)
    assert d.node_address == 33
    d.inverter.write_code("P190", 34, 1.0)
    assert d.node_address == 33                               # read at power-on or reset only
    d.reset(0)
    assert d.node_address == 34


def test_words_allocated_from_the_node_address():
    network = CompoNetNetwork()
    a = network.attach(slave(MX2, 3), 0.0)                    # 21/71: 2 words each way
    b = network.attach(slave(RX, 10, P046=5), 0.0)            # 101/153: 4 words out, 5 in
    assert (list(a.out_range), list(a.in_range)) == ([3, 4], [3, 4])
    assert (list(b.out_range), list(b.in_range)) == ([10, 11, 12, 13], [10, 11, 12, 13, 14])
    network.advance(0.0)
    assert network.in_area[6:10].hex(" ") == "10 03 00 00"   # node 3, 71: ready, Ready
    assert network.in_area[20:30].hex(" ") == "22 00 00 00 00 00 00 00 00 00"   # node 10, 153
    assert [p.node for p in network.online()] == [3, 10]


def test_cyclic_refresh_runs_the_inverter():
    network = CompoNetNetwork(cycle=0.01)
    mx2 = slave(MX2, 3, A001=4, A002=4)
    network.attach(mx2, 0.0)
    network.set_out_words(3, bytes.fromhex("00 00 e8 03"))
    network.advance(0.0)
    network.set_out_words(3, bytes.fromhex("01 00 e8 03"))   # FWD, 10.00 Hz
    network.advance(0.01)
    assert network.in_words(3)[1] == 4                        # Enabled
    network.advance(2.5)
    assert network.in_words(3).hex(" ") == "f4 04 e8 03"
    assert network.cycles >= 250
    assert network.next_deadline() == pytest.approx(2.51)


def test_duplicate_node_address():
    network = CompoNetNetwork()
    first = slave(MX2, 3)
    second = slave(RX, 4)                                     # its words overlap node 3's word 4
    network.attach(first, 0.0)
    p = network.attach(second, 0.0)
    assert p.state is NodeState.DUPLICATE
    assert second.inverter.trip == 71                          # E71: duplicated MAC ID (Table D-5)
    assert first.inverter.trip == 0
    assert [e.kind.split(" (")[0] for e in network.events] == ["joined", "duplicate node address"]
    network.advance(0.1)
    assert network.in_area[8:12] == bytes(4)                 # the duplicate is never refreshed


def test_lost_slave_and_return():
    network = CompoNetNetwork(cycle=0.01, lost_after=3, slave_timeout=0.1)
    mx2 = slave(MX2, 3, A001=4, A002=4)
    network.attach(mx2, 0.0)
    network.advance(0.0)
    network.set_out_words(3, bytes.fromhex("01 00 e8 03"))
    network.advance(0.02)
    network.disconnect(3)
    network.advance(0.04)
    assert network.participant(3).state is NodeState.ONLINE     # two cycles missed
    network.advance(0.05)
    assert network.participant(3).state is NodeState.LOST       # the third
    assert network.in_area[6:10] == bytes(4)
    assert mx2.inverter.trip == 0
    network.advance(0.2)                                         # the slave's connection times out: P045 = 0, trip
    assert mx2.inverter.trip == 63                               # E63: communication lost (Table D-5)
    network.reconnect(3)
    network.advance(0.25)
    assert network.participant(3).state is NodeState.ONLINE
    assert [e.kind for e in network.events][-2:] == ["lost", "rejoined"]
    assert network.in_words(3)[0] & 0x01                          # FLT reported again


def test_explicit_exchange_through_the_network():
    network = CompoNetNetwork()
    network.attach(slave(MX2, 3), 0.0)
    reply = network.exchange(bytes.fromhex("28 02 10 03 0e 00 01 00 01 01"), 1.0)
    assert reply.hex(" ") == "28 02 00 00 00 05 10 03 8e 2f 00"   # vendor 47


# -- the gateway --------------------------------------------------------------------------------------------

def routed(gateway: CompoNetGatewayDevice, node: int, service: int, cls: int, instance: int,
           attribute: int | None, data: bytes = b"", port: int = COMPONET_PORT, now: float = 1.0
           ) -> MessageRouterResponse:
    gateway.advance(now)
    embedded = MessageRouterRequest(service, request_path(cls, instance, attribute), data).encode()
    send = UnconnectedSendRequest(0x0A, 0x0E, embedded, encode_path([PortSegment(port, bytes([node]))]))
    raw = MessageRouterRequest(0x52, request_path(6, 1), send.encode()).encode()
    return gateway.router.dispatch(raw, RequestContext(gateway.router, now))


def test_gateway_routes_to_each_slave():
    gateway = build_componet_gateway(parse_nodes("mx2:MX2-A2015-E@3,rx:RX-A4055-E@5"))
    assert routed(gateway, 3, 0x0E, 1, 1, 3).data == (1806).to_bytes(2, "little")
    assert routed(gateway, 5, 0x0E, 1, 1, 3).data == (2073).to_bytes(2, "little")
    assert routed(gateway, 5, 0x10, 0x65, *function_code_path("P060"), bytes.fromhex("00f40100")).ok
    assert gateway.slave(5).inverter.read_code("P060") == 128000
    error = routed(gateway, 3, 0x0E, 0x29, 1, 0x99)
    assert (error.service, error.general_status, error.extended_status) == (0x0E, 0x14, ())
    assert routed(gateway, 9, 0x0E, 1, 1, 1).extended_status == (0x0204,)   # nobody at node 9
    assert routed(gateway, 64, 0x0E, 1, 1, 1).extended_status == (0x0312,)  # outside 0-63
    assert routed(gateway, 3, 0x0E, 1, 1, 1, port=3).extended_status == (0x0311,)
    assert gateway.gateway.routed == 4                               # the three above and the error


def test_gateway_io_areas_show_each_slave():
    gateway = build_componet_gateway([("mx2", MX2, 3), ("rx", RX, 5)])
    gateway.advance(0.0)
    assert len(gateway.assembly.data(GATEWAY_IN_AREA)) == 128
    assert gateway.assembly.data(GATEWAY_IN_AREA)[6:14].hex(" ") == "10 03 00 00 10 03 00 00"
    area = bytearray(128)
    area[6:10] = bytes.fromhex("60 00 e8 03")                        # node 3: CTR, REF, 10.00 Hz
    area[10:14] = bytes.fromhex("60 00 d0 07")                       # node 5: CTR, REF, 20.00 Hz
    gateway.assembly.deliver(GATEWAY_OUT_AREA, bytes(area), 0.1)
    gateway.advance(0.2)
    area[6] = area[10] = 0x61                                       # FWD on both
    gateway.assembly.deliver(GATEWAY_OUT_AREA, bytes(area), 0.2)
    gateway.advance(0.3)                                            # the next cycle carries FWD
    gateway.advance(10.0)
    assert gateway.assembly.data(GATEWAY_IN_AREA)[6:14].hex(" ") == "f4 04 e8 03 f4 04 d0 07"
    assert "node  3: online" in gateway.status_line()


def test_gateway_rejects_mismatched_profiles():
    with pytest.raises(ValueError):
        build_componet_gateway([("rx", MX2, 3)])
    with pytest.raises(ValueError):
        parse_nodes("mx2-MX2-A2015-E")


def test_the_gateway_is_the_one_the_nodes_families_declare():
    """``cipstack componet`` builds the gateway the nodes' families declare (``Profile.componet_gateway``):
    MX2 and RX share the option board's; a family without a CompoNet port is refused by name."""
    from cipstack.errors import BadRequest
    from cipstack.objects.tcpip import NetworkInterface

    gateway = componet_gateway(parse_nodes("mx2:MX2-A2015-E@3,rx:RX-A4055-E@5"), NetworkInterface())
    assert isinstance(gateway, CompoNetGatewayDevice) and len(gateway.slaves) == 2
    with pytest.raises(BadRequest, match=r"profile 'acg' has no CompoNet port \(one has: profile mx2 or rx\)"):
        componet_gateway(parse_nodes("acg:ACG@3"), NetworkInterface())
    with pytest.raises(BadRequest, match="unknown profile 'vfd'"):
        componet_gateway(parse_nodes("vfd:X@3"), NetworkInterface())
    with pytest.raises(BadRequest, match="--nodes names no node"):
        componet_gateway(parse_nodes(" , "), NetworkInterface())
