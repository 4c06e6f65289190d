"""``capture analyze`` on scripted wire bytes: each case is a capture written frame by frame from
the project's codecs (and hand-made bytes for the malformed ones), then analysed by the command."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

from cipstack.capture.layers import CIP, CPF, ENIP, ENIP_IO, CPFItem
from cipstack.capture.synth import PcapWriter, TcpFlow, ethernet, udp
from cipstack.cip.epath import PortSegment, encode_path, request_path
from cipstack.cip.messages import MessageRouterRequest, MessageRouterResponse, Service
from cipstack.eip.io_core import encode_io_datagram
from cipstack.eip.wire.cm_messages import (
    ConnectionTriad,
    ForwardOpenReply,
    ForwardOpenRequest,
    NetworkParameters,
    TransportTrigger,
    UnconnectedSendRequest,
)
from cipstack.eip.wire.cpf import Item, ItemType, encode_items
from cipstack.eip.wire.encapsulation import RR_PREFIX, Command, encode_frame
from tests.cli_errors import one_line_error

CLIENT, TARGET = ("10.0.0.1", 50000), ("10.0.0.2", 44818)
CM_PATH = request_path(0x06, 1)


def rr(message: bytes, session: int = 7, context: bytes = b"ctx00001", extra: tuple[Item, ...] = ()) -> bytes:
    items = encode_items([Item(ItemType.NULL_ADDRESS), Item(ItemType.UNCONNECTED_DATA, message), *extra])
    return encode_frame(Command.SEND_RR_DATA, RR_PREFIX.pack(0, 0) + items, session=session, context=context)


def analyze(path: Path, *args: str) -> tuple[int, list[dict[str, Any]], str]:
    result = subprocess.run([sys.executable, "-m", "cipstack", "capture", "analyze", str(path), "--json", *args],
                            capture_output=True, text=True, timeout=60, check=False)
    return result.returncode, [json.loads(line) for line in result.stdout.splitlines()], result.stderr


def forward_open(rpi_us: int = 10_000, multiplier: int = 0) -> ForwardOpenRequest:
    return ForwardOpenRequest(
        0x0A, 0x0E, 0, 0x2000_0001, ConnectionTriad(0x1234, 0x0103, 0xCAFE), multiplier, rpi_us,
        NetworkParameters(2 + 4 + 4), rpi_us, NetworkParameters(2 + 4), TransportTrigger(1),
        bytes.fromhex("20042401") + bytes.fromhex("2c15") + bytes.fromhex("2c46"))


def test_split_and_coalesced_segments_io_timing_gaps_and_timeout(tmp_path: Path) -> None:
    path = tmp_path / "c.pcap"
    flow = TcpFlow(CLIENT, TARGET)
    request = forward_open()
    fo = rr(MessageRouterRequest(Service.FORWARD_OPEN, CM_PATH, request.encode()).encode())
    reply_data = ForwardOpenReply(0x1111, 0x2000_0001, request.triad, 10_000, 10_000).encode()
    fo_reply = rr(MessageRouterResponse(Service.FORWARD_OPEN, data=reply_data).encode())
    get = rr(MessageRouterRequest(Service.GET_ATTRIBUTE_SINGLE, request_path(1, 1, 7)).encode(), context=b"ctx00002")
    bad = rr(MessageRouterRequest(Service.GET_ATTRIBUTE_SINGLE, request_path(1, 1, 99)).encode(), context=b"ctx00003")
    with path.open("wb") as stream:
        pcap = PcapWriter(stream)
        t = 100.0
        for frame in flow.handshake():
            pcap.write(t, ethernet(frame))
        # The Forward_Open request split over two segments; its reply in one.
        pcap.write(t + 0.001, ethernet(flow.send(True, fo[:10])))
        pcap.write(t + 0.002, ethernet(flow.send(True, fo[10:])))
        pcap.write(t + 0.003, ethernet(flow.send(False, fo_reply)))
        # Two requests in one segment, then their replies (the second an error).
        pcap.write(t + 0.004, ethernet(flow.send(True, get + bad)))
        name = b"\x04CENT"
        pcap.write(t + 0.005, ethernet(flow.send(False, rr(MessageRouterResponse(0x0E, data=name).encode(),
                                                           context=b"ctx00002"))))
        pcap.write(t + 0.006, ethernet(flow.send(False, rr(MessageRouterResponse(0x0E, 0x14).encode(),
                                                           context=b"ctx00003"))))
        # 20 O->T frames at 10 ms with sequence 6 missing and 9 twice, then silence: timeout.
        for n in range(1, 21):
            if n == 6:
                continue
            run = 1 if n > 3 else 0
            data = encode_io_datagram(0x1111, n, n, b"\x00" * 4, run_idle=run)
            pcap.write(t + 0.01 + n * 0.010, ethernet(udp("10.0.0.1", 2222, "10.0.0.2", 2222, data)))
            if n == 9:
                pcap.write(t + 0.01 + n * 0.010 + 0.0001, ethernet(udp("10.0.0.1", 2222, "10.0.0.2", 2222, data)))
        # A frame for a connection nobody opened, and a malformed class 1 datagram.
        unknown = encode_io_datagram(0x9999, 1, 1, b"")
        pcap.write(t + 0.3, ethernet(udp("10.0.0.9", 2222, "10.0.0.2", 2222, unknown)))
        pcap.write(t + 0.31, ethernet(udp("10.0.0.9", 2222, "10.0.0.2", 2222, b"\x02\x00\x02\x80")))
        pcap.write(t + 1.0, ethernet(udp("10.0.0.9", 40000, "10.0.0.3", 40001, b"x")))
    code, records, stderr = analyze(path, "--profile", "acg")
    assert code == 0, stderr
    explicit = [r for r in records if r["type"] == "explicit"]
    assert [r["request"]["service_name"] for r in explicit] == ["Forward_Open", "Get_Attribute_Single",
                                                               "Get_Attribute_Single"]
    assert explicit[1]["reply"]["data"]["value"] == "CENT"
    assert explicit[1]["request"]["attribute_name"] == "Product Name"
    assert explicit[2]["error"] and explicit[2]["reply"]["status_name"] == "0x14 (attribute not supported)"
    connection = next(r for r in records if r["type"] == "connection")
    assert connection["o_t_id"] == 0x1111 and (connection["o_t_point"], connection["t_o_point"]) == (0x15, 0x46)
    o_t = connection["o_t"]
    assert (o_t["frames"], o_t["lost"], o_t["duplicates"]) == (20, 1, 1)
    assert abs(o_t["p50_ms"] - 10) < 0.2 and abs(o_t["max_ms"] - 20) < 0.2
    assert [c["mode"] for c in connection["run_idle_changes"]] == ["idle", "run"]
    # 10 ms x 4 x 2^0 = 40 ms of silence after the last frame.
    assert connection["end_reason"].startswith("timeout: O->T silent for more than 40 ms")
    anomalies = [r for r in records if r["type"] == "anomaly"]
    assert any("unknown connection 0x00009999" in a["reason"] for a in anomalies)
    assert any(a["layer"] == "class1" and a["offset"] == 4 for a in anomalies)


def test_refused_forward_open_is_a_connection_that_never_ran(tmp_path: Path) -> None:
    path = tmp_path / "refused.pcap"
    flow = TcpFlow(CLIENT, TARGET)
    request = forward_open()
    fo = rr(MessageRouterRequest(Service.FORWARD_OPEN, CM_PATH, request.encode()).encode())
    # Connection failure, extended 0x0127 (invalid O->T size) with the correct size 10.
    failure = bytes.fromhex("34120301feca00000000")  # the triad and the remaining path size
    refusal = MessageRouterResponse(Service.FORWARD_OPEN, 0x01, (0x0127, 10), failure)
    with path.open("wb") as stream:
        pcap = PcapWriter(stream)
        pcap.write(1.0, ethernet(flow.send(True, fo)))
        pcap.write(1.1, ethernet(flow.send(False, rr(refusal.encode()))))
    code, records, stderr = analyze(path)
    assert code == 0, stderr
    connection = next(r for r in records if r["type"] == "connection")
    from cipstack.cip.status import describe_status

    assert connection["end_reason"] == "refused: " + describe_status(0x01, (0x0127, 10))
    assert "extended 0x0127" in connection["end_reason"] and "additional 0x000A" in connection["end_reason"]
    assert connection["o_t"]["frames"] == 0 and connection["t_o_api_ms"] is None


def test_routed_request_to_the_componet_gateway_and_unanswered(tmp_path: Path) -> None:
    path = tmp_path / "r.pcap"
    flow = TcpFlow(CLIENT, TARGET)
    embedded = MessageRouterRequest(Service.GET_ATTRIBUTE_SINGLE, request_path(1, 1, 1)).encode()
    send = UnconnectedSendRequest(0x0A, 0x0E, embedded, encode_path([PortSegment(2, b"\x05")])).encode()
    routed = rr(MessageRouterRequest(Service.UNCONNECTED_SEND, CM_PATH, send).encode())
    lonely = rr(MessageRouterRequest(Service.GET_ATTRIBUTE_SINGLE, request_path(1, 1, 3)).encode(), context=b"zz")
    # Items after the declared count: the count says 2, a third item follows.
    extra = bytearray(rr(MessageRouterRequest(Service.GET_ATTRIBUTE_SINGLE, request_path(1, 1, 2)).encode(),
                         context=b"xx", extra=(Item(ItemType.SOCKADDR_T_O, b"\x00" * 16),)))
    extra[30] = 2
    with path.open("wb") as stream:
        pcap = PcapWriter(stream)
        for frame in flow.handshake():
            pcap.write(1.0, ethernet(frame))
        pcap.write(1.1, ethernet(flow.send(True, routed)))
        pcap.write(1.2, ethernet(flow.send(False, rr(MessageRouterResponse(0x0E, data=b"\x2f\x00").encode()))))
        pcap.write(1.3, ethernet(flow.send(True, lonely)))
        pcap.write(1.4, ethernet(flow.send(True, bytes(extra))))
    code, records, stderr = analyze(path)
    assert code == 0, stderr
    routed_record = next(r for r in records if r["type"] == "explicit" and "reply" in r
                         and r["request"]["service_name"] == "Unconnected_Send")
    assert routed_record["request"]["route"] == [{"port": 2, "link": 5, "network": "CompoNet"}]
    assert routed_record["request"]["embedded"]["attribute_name"] == "Vendor ID"
    assert routed_record["reply"]["data"]["value"] == 47
    unanswered = [r for r in records if r["type"] == "explicit" and "unanswered" in r]
    assert {r["request"]["attribute"] for r in unanswered} == {2, 3}
    after = next(r for r in records if r["type"] == "anomaly")
    assert after["layer"] == "cpf" and "after the declared count" in after["reason"]
    # Header 24, prefix 6, count 2, null address item 4, data item 4 + 8: the third item starts there.
    assert after["offset"] == 24 + 6 + 2 + 4 + 4 + 8


def test_scapy_layers_build_the_project_bytes_and_dissect_them() -> None:
    from scapy.layers.inet import IP, UDP

    path = request_path(1, 1, 7)
    built = ENIP(command_code="SEND_RR_DATA", session=0x11) / CPF(items=[
        CPFItem(type="NULL_ADDRESS"), CPFItem(type="UNCONNECTED_DATA") / CIP(service="GET_ATTRIBUTE_SINGLE",
                                                                            path=path)])
    expected = rr(MessageRouterRequest(Service.GET_ATTRIBUTE_SINGLE, path).encode(), session=0x11,
                  context=b"\x00" * 8)
    assert bytes(built) == expected
    dissected = IP(bytes(IP(src="1.1.1.1", dst="2.2.2.2") / UDP(sport=1, dport=44818) / built))
    assert dissected[ENIP].command_code == Command.SEND_RR_DATA and dissected[CPF].count == 2
    assert dissected[CIP].describe()["attribute_name"] == "Product Name"
    io = IP(bytes(IP() / UDP(sport=2222, dport=2222) / (ENIP_IO(connection_id=5, encap_sequence=9, cip_sequence=3)
                                                          / b"\x01\x00\x00\x00ab")))
    assert bytes(io[ENIP_IO]) == encode_io_datagram(5, 9, 3, b"ab", run_idle=1)
    assert io[ENIP_IO].datagram().payload == b"\x01\x00\x00\x00ab"


def test_bad_files_and_missing_matplotlib_are_one_line_errors(tmp_path: Path) -> None:
    junk = tmp_path / "junk.pcap"
    junk.write_bytes(b"not a capture at all")
    result = subprocess.run([sys.executable, "-m", "cipstack", "capture", "analyze", str(junk)], capture_output=True,
                            text=True, timeout=60, check=False)
    assert result.returncode == 1 and "not a pcap or pcapng file" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    result = subprocess.run([sys.executable, "-m", "cipstack", "capture", "analyze", str(tmp_path / "nope.pcap")],
                            capture_output=True, text=True, timeout=60, check=False)
    assert result.returncode == 1 and "No such file" in result.stderr
    script = ("import sys; sys.modules['matplotlib'] = None; from cipstack.cli import main; "
              f"sys.exit(main(['capture', 'analyze', {str(junk)!r}, '--plot', 'x.png']))")
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60, check=False)
    assert result.returncode == 2 and 'pip install "cipstack[plot]"' in result.stderr
    for args, message in ((["--connection", "xyz"], "'xyz' is not a connection number or id"),
                          (["--profile", "mx2", "--model", "BAD"], "unknown inverter model 'BAD'"),
                          (["--model", "MX2-A2015-E"], "--model needs --profile"),
                          # The acg profile has one model: --model named a crash (AttributeError) once.
                          (["--profile", "acg", "--model", "MX2-A2015-E"], "the acg profile has one model")):
        result = subprocess.run([sys.executable, "-m", "cipstack", "capture", "analyze", str(junk), *args],
                                capture_output=True, text=True, timeout=60, check=False)
        assert result.returncode == 2 and message in one_line_error(result)


def _sll(ip_packet: bytes) -> bytes:
    return b"\x00\x00\x03\x04\x00\x06" + b"\x02\x00\x00\x00\x00\x01\x00\x00" + b"\x08\x00" + ip_packet


def _null(ip_packet: bytes) -> bytes:
    return b"\x02\x00\x00\x00" + ip_packet


def test_linux_cooked_and_loopback_link_types_and_connection_filter(tmp_path: Path) -> None:
    from cipstack.capture.synth import tcp as tcp_frame

    request = forward_open()
    fo = rr(MessageRouterRequest(Service.FORWARD_OPEN, CM_PATH, request.encode()).encode())
    reply_data = ForwardOpenReply(0x2222, 0x2000_0001, request.triad, 10_000, 10_000).encode()
    fo_reply = rr(MessageRouterResponse(Service.FORWARD_OPEN, data=reply_data).encode())
    for linktype, wrap in ((113, _sll), (0, _null)):
        path = tmp_path / f"link{linktype}.pcap"
        with path.open("wb") as stream:
            pcap = PcapWriter(stream, linktype)
            pcap.write(1.0, wrap(tcp_frame(*CLIENT, *TARGET, fo, 1)))
            pcap.write(1.001, wrap(tcp_frame(*TARGET, *CLIENT, fo_reply, 1)))
            for n in range(1, 6):
                data = encode_io_datagram(0x2000_0001, n, n, b"\x00" * 4)
                pcap.write(1.01 + n * 0.01, wrap(udp("10.0.0.2", 2222, "10.0.0.1", 2222, data)))
        code, records, stderr = analyze(path, "--connection", "0x20000001")
        assert code == 0, stderr
        # --connection: only that connection's record (and the summary).
        assert [r["type"] for r in records] == ["connection", "summary"]
        assert records[0]["t_o"]["frames"] == 5 and records[0]["o_t_id"] == 0x2222


def test_eds_parameters_name_attributes_by_link_path(tmp_path: Path) -> None:
    from cipstack.eds.interpret import read_view
    from cipstack.eds.reader import read_eds

    result = subprocess.run([sys.executable, "-m", "cipstack", "eds", "generate", "--profile", "acg", "-o",
                             str(tmp_path)], capture_output=True, text=True, timeout=60, check=False)
    assert result.returncode == 0, result.stderr
    eds = next(tmp_path.glob("*.eds"))
    param = next(p for p in read_view(read_eds(eds)).params.values() if p.link is not None and p.link[0] != 1)
    flow = TcpFlow(CLIENT, TARGET)
    path = tmp_path / "eds.pcap"
    with path.open("wb") as stream:
        pcap = PcapWriter(stream)
        get = rr(MessageRouterRequest(Service.GET_ATTRIBUTE_SINGLE, request_path(*param.link)).encode())
        pcap.write(1.0, ethernet(flow.send(True, get)))
        value = param.type.encode(param.default if param.default is not None else 0)
        pcap.write(1.1, ethernet(flow.send(False, rr(MessageRouterResponse(0x0E, data=value).encode()))))
    code, records, stderr = analyze(path, "--eds", str(eds))
    assert code == 0, stderr
    exchange = next(r for r in records if r["type"] == "explicit")
    assert exchange["request"]["attribute_name"] == param.name
    assert exchange["reply"]["data"]["value"] == (param.default if param.default is not None else 0)
    bad = subprocess.run([sys.executable, "-m", "cipstack", "capture", "analyze", str(path), "--eds", "x.eds",
                          "--profile", "acg"], capture_output=True, text=True, timeout=60, check=False)
    assert bad.returncode == 2 and "not both" in bad.stderr


def test_memory_stays_bounded_on_long_streams() -> None:
    from cipstack.capture.analyzer import MAX_FRAME, MAX_TCP_BUFFER, Analyzer
    from cipstack.capture.stats import LogHistogram, Reservoir

    found: list[dict[str, Any]] = []
    analyzer = Analyzer(found.append)
    flow = TcpFlow(CLIENT, TARGET)
    # A header announcing 65,535 bytes, then more and more stream bytes: the buffer never holds
    # more than one frame's worth (the length field is 16 bits), whatever the stream carries.
    analyzer.feed(0.0, 1, 1, ethernet(flow.send(True, encode_frame(Command.SEND_RR_DATA, b"")[:2] + b"\xff\xff")))
    largest = 0
    for n in range(2, 2 + MAX_TCP_BUFFER // 1400 + 2):
        analyzer.feed(n * 0.001, n, 1, ethernet(flow.send(True, b"\x01" * 1400)))
        largest = max(largest, analyzer.buffered_bytes)
    assert 60_000 < largest < MAX_FRAME
    histogram, reservoir = LogHistogram(), Reservoir(1000)
    for n in range(200_000):
        interval = 0.001 + (n % 997) * 1e-7
        histogram.add(interval)
        reservoir.add((n, interval))
    assert len(reservoir.items) == 1000 and reservoir.seen == 200_000
    assert len(histogram.counts) < 200 and histogram.count == 200_000
    median = histogram.quantile(0.5)
    assert median is not None and abs(median - 0.00105) / 0.00105 < 0.002


def test_progress_bar_draws_on_a_stream() -> None:
    import io

    from cipstack.capture.command import Progress

    out = io.StringIO()
    bar = Progress(1000, out)
    bar.update(500, 42)
    bar.close()
    assert "50.0 % 42 frames" in out.getvalue() and out.getvalue().endswith("\r")


def test_mutated_frames_never_raise() -> None:
    """Every byte of a Forward_Open exchange, explicit messages and class 1 frames flipped at random
    (seeded, bounded): the analysis reports or ignores, it never raises."""
    import random

    from cipstack.capture.analyzer import Analyzer

    flow = TcpFlow(CLIENT, TARGET)
    request = forward_open()
    frames = [ethernet(f) for f in flow.handshake()]
    fo = rr(MessageRouterRequest(Service.FORWARD_OPEN, CM_PATH, request.encode()).encode())
    reply = ForwardOpenReply(0x1111, 0x2000_0001, request.triad, 10_000, 10_000).encode()
    embedded = MessageRouterRequest(Service.GET_ATTRIBUTE_SINGLE, request_path(1, 1, 1)).encode()
    routed = UnconnectedSendRequest(0x0A, 0x0E, embedded, encode_path([PortSegment(2, b"\x05")])).encode()
    for payload, from_client in (
            (fo, True), (rr(MessageRouterResponse(Service.FORWARD_OPEN, data=reply).encode()), False),
            (rr(MessageRouterRequest(Service.UNCONNECTED_SEND, CM_PATH, routed).encode()), True),
            (rr(MessageRouterResponse(0x0E, data=b"\x2f\x00").encode()), False)):
        frames.append(ethernet(flow.send(from_client, payload)))
    for n in range(1, 4):
        frames.append(ethernet(udp("10.0.0.1", 2222, "10.0.0.2", 2222,
                                   encode_io_datagram(0x1111, n, n, b"\x00" * 4, run_idle=1))))
    rng = random.Random(13)
    found: list[dict[str, Any]] = []
    for round_ in range(300):
        analyzer = Analyzer(found.append)
        for number, frame in enumerate(frames):
            mutated = bytearray(frame)
            for _ in range(rng.randint(0, 3)):
                mutated[rng.randrange(14, len(mutated))] = rng.randrange(256)
            if rng.random() < 0.1:
                del mutated[rng.randrange(14, len(mutated)):]
            analyzer.feed(round_ + number * 0.001, number, 1, bytes(mutated))
        analyzer.finish()
    assert any(r["type"] == "anomaly" for r in found)


def test_out_of_order_segments_are_put_back_in_order_and_a_lasting_hole_is_reported() -> None:
    from cipstack.capture.analyzer import MAX_AHEAD, Analyzer

    found: list[dict[str, Any]] = []
    analyzer = Analyzer(found.append)
    flow = TcpFlow(CLIENT, TARGET)
    for number, frame in enumerate(flow.handshake()):
        analyzer.feed(0.0, number, 1, ethernet(frame))
    requests = [rr(MessageRouterRequest(Service.GET_ATTRIBUTE_SINGLE, request_path(1, 1, a)).encode(),
                   context=bytes([a]) * 8) for a in (1, 3, 7)]
    stream = b"".join(requests)
    start = flow.seq[CLIENT]
    pieces = [(start + i, stream[i:i + 17]) for i in range(0, len(stream), 17)]
    order = [2, 0, 1, *range(3, len(pieces))]  # the third piece first, then the rest in order
    for number, index in enumerate(order):
        seq, piece = pieces[index]
        analyzer.feed(number * 0.001, number, 1, ethernet(flow.send(True, piece, seq_offset=seq)))
    flow.seq[CLIENT] = start + len(stream)
    for a in (1, 3, 7):
        analyzer.feed(1.0, 100 + a, 1, ethernet(flow.send(False, rr(MessageRouterResponse(0x0E).encode(),
                                                                    context=bytes([a]) * 8))))
    paired = [r for r in found if r["type"] == "explicit" and "reply" in r]
    assert [r["request"]["attribute"] for r in paired] == [1, 3, 7]
    assert not [r for r in found if r["type"] == "anomaly"]
    # A gap that never fills: after MAX_AHEAD held segments the stream resynchronises and says so.
    base = flow.seq[CLIENT] + 1000
    for n in range(MAX_AHEAD + 1):
        analyzer.feed(2.0, 200 + n, 1, ethernet(flow.send(True, b"\x00" * 24, seq_offset=base + 24 * n)))
    holes = [r for r in found if r["type"] == "anomaly" and r["layer"] == "tcp"]
    assert len(holes) == 1 and "1000 stream bytes missing" in holes[0]["reason"]
