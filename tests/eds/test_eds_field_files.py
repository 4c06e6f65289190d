"""The test corpus of EDS files written in the styles the field ships (tests/eds/files/).

Every file: `eds check` finds no error (and exactly the warnings its constructs deserve), `eds
show` prints no unknown where the file determines the value, and the canonical writer's round
trip keeps its meaning. Every file with a [Connection Manager]: `cipstack adapter --eds FILE`
serves it, says on stderr exactly what it skips, and `cipstack io --eds FILE --connection N` runs
each connection it offers, as a user runs them; python-ethernetip runs those it can open.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from cipstack.eds.commands import run_check, run_show
from cipstack.eds.emulated_device import build_eds_device
from cipstack.eds.interpret import ConnectionInfo, read_view
from cipstack.eds.model import EdsDocument, semantic_differences
from cipstack.eds.reader import parse_eds, read_eds
from cipstack.eds.writer import format_eds
from tests.optional import needs
from tests.ports import free_port
from tests.waiting import wait_for, wait_until

DIRECTORY = Path(__file__).parent / "files"
FILES = sorted(DIRECTORY.glob("*.eds"))


@dataclass(frozen=True)
class Expected:
    """What a corpus file is expected to give: the warnings of `eds check` (line, rule, message), what
    `adapter --eds` skips (line, message), the connections it offers, and those python-ethernetip
    opens (it sends a run/idle header, takes point-to-point T->O only, Forward_Open sizes, instances
    up to 255)."""

    check_warnings: list[tuple[int, str, str]] = field(default_factory=list)
    #: What `eds check` notes (severity info): a UTF-8 file.
    check_notes: list[tuple[int, str, str]] = field(default_factory=list)
    skipped: list[tuple[int, str]] = field(default_factory=list)
    offered: list[int] = field(default_factory=list)
    ethernetip: list[int] = field(default_factory=list)


#: Connections of the 8-port IO-Link master python-ethernetip can open: the station owners and each
#: port's owners (run/idle header, point-to-point allowed).
ETHERNETIP_8PORT = [1, 4, 7, 10, *(13 + 6 * port + kind for port in range(8) for kind in (0, 3))]
EXPECTED: dict[str, Expected] = {
    "devicenet_valve.eds": Expected(),
    "ez_style_comm_module.eds": Expected(offered=[1, 2, 3, 4], ethernetip=[2]),
    "ez_style_io_block.eds": Expected(offered=[1, 2], ethernetip=[1]),
    "ez_style_safety_io.eds": Expected(
        skipped=[(117, "Connection3: transport 0x0001 is not class 1: skipped"),
                 (129, "Connection4: transport 0x0001 is not class 1: skipped")],
        offered=[1, 2], ethernetip=[1]),
    "ez_style_servo_large.eds": Expected(offered=[1, 2]),
    "hand_drive_oelpumpe.eds": Expected(
        check_warnings=[(194, "unquoted-value", 'Port1: unquoted value 20 F5 24 01 read as the path "20 F5 24 01"')],
        offered=[1, 2, 3, 4, 5, 6], ethernetip=[1]),
    "hand_smart_sensor.eds": Expected(offered=[1, 2, 3], ethernetip=[1]),
    "hand_written_oil_pump.eds": Expected(
        check_warnings=[(105, "unquoted-value", 'Port1: unquoted value 20 F5 24 01 read as the path "20 F5 24 01"')]),
    "hand_valve_manifold.eds": Expected(
        check_warnings=[(81, "connection-path",
                         "Connection9 T->O connection point is 103 but Assem101 is instance 101")],
        skipped=[(51, "Assem110 has no path and its connections name it as instances 110, 111: not served"),
                 (52, "Assem120 has no path and no connection names it: not served"),
                 (61, "Connection3: redundant owner connections are not supported: skipped"),
                 (64, "Connection4: transport 0x0008 is not class 1: skipped"),
                 (69, "Connection5: path 20 04 24 01 2C 64 2C 65 80 01 0F 00 is not an assembly connection path: "
                      "skipped"),
                 (72, "Connection6: path: path item [Param5] has no byte value as its default: skipped"),
                 (73, "Connection7 (Diagnostics A): T->O point 110 is no input assembly: not offered"),
                 (76, "Connection8 (Diagnostics B): T->O point 111 is no input assembly: not offered"),
                 (79, "Connection9 (Owner Of 103): T->O point 103 is no input assembly: not offered")],
        offered=[1, 2], ethernetip=[1]),
    "ez_style_iolink_master.eds": Expected(
        offered=[1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12], ethernetip=[1, 4, 7, 10]),
    "vendor_modular_coupler.eds": Expected(
        check_warnings=[(47, "keyword-case",
                         "[Assembly] Object_Class_code is written Object_Class_Code (read as such)"),
                        (56, "keyword-case",
                         "[Connection Manager] Object_Class_code is written Object_Class_Code (read as such)")],
        offered=[1, 2, 3, 4], ethernetip=[1, 4]),
    "vendor_drive_own_data.eds": Expected(offered=[1, 2, 3, 4, 5, 6, 7], ethernetip=[1, 2, 3]),
    "hand_utf8_distance_sensor.eds": Expected(
        check_notes=[(1, "encoding", "the file is UTF-8 ('µs' on this line reads as 'Âµs' in a Latin-1 tool)")],
        offered=[1, 2, 3, 4]),
    "ez_style_safety_format5.eds": Expected(
        skipped=[(83, "Assem200 has no path and no connection names it: not served"),
                 (90, "Assem201 has no path and no connection names it: not served"),
                 (150, "Connection5: transport 0x0001 is not class 1: skipped"),
                 (162, "Connection6: transport 0x0001 is not class 1: skipped")],
        offered=[1, 2, 3, 4], ethernetip=[1, 2]),
    "vendor_plc_generic_adapter.eds": Expected(offered=[1, 2, 3, 4, 5, 6], ethernetip=[1, 4, 5]),
    "vendor_iolink_master_8port.eds": Expected(offered=list(range(1, 61)), ethernetip=ETHERNETIP_8PORT),
    # An exclusive owner whose T->O point is a heartbeat (198, 254): the target produces no data.
    "field_owner_heartbeat_input.eds": Expected(offered=[1, 2]),
    # Assemblies of empty size, sized by the size their connections give (Param2, Param3).
    "field_modular_empty_size.eds": Expected(offered=[1, 2], ethernetip=[1]),
    # Points sized by parameters whose default is 0: offered at the smallest non-zero size.
    "field_size_param_default_zero.eds": Expected(
        skipped=[(37, "Param2, the O->T size of Connection1, defaults to 0: offered at 1 byte, the smallest "
                      "non-zero size it allows"),
                 (37, "Param3, the T->O size of Connection1, defaults to 0: offered at 1 byte, the smallest "
                      "non-zero size it allows")],
        offered=[1], ethernetip=[1]),
    # Controllers' "write data" owners whose T->O is the heartbeat 198 or 254 the input-only ones send to.
    "field_write_data_heartbeat.eds": Expected(offered=[1, 2, 3, 4, 5, 6], ethernetip=[1, 2, 5]),
}
WITH_CONNECTIONS = [path for path in FILES if read_eds(path).get("Connection Manager")]


def _ids(paths: list[Path]) -> list[str]:
    return [path.stem for path in paths]


def test_every_corpus_file_says_what_it_gives() -> None:
    assert sorted(EXPECTED) == [path.name for path in FILES]


# -- the constructs the corpus exists for ---------------------------------------------------------------

def test_the_corpus_holds_every_construct_of_the_field() -> None:
    """Each construct issue 11 found in published files is in at least one file of the corpus; a
    file edited so that one disappears fails here, not silently."""
    docs = {path.name: read_eds(path) for path in FILES}
    raw = {path.name: path.read_bytes() for path in FILES}
    # An AssemN with an empty path whose instance only the connection path names.
    assert b'"20 04 24 97 2C 96 2C 64"' in raw["ez_style_io_block.eds"]
    assert docs["ez_style_io_block.eds"].entry("Assembly", "Assem150").value(2) == ()
    # Files without Catalog, and files with it.
    without = [n for n, d in docs.items() if "Catalog" not in d.get("Device")]
    assert len(without) >= 4 and len(without) < len(docs)
    # CIP Safety: Class2 = Safety and connections of 17 fields.
    safety = docs["ez_style_safety_io.eds"]
    assert safety.entry("Device Classification", "Class2").value() == "Safety"
    assert {len(e.fields) for e in safety.get("Connection Manager") if e.keyword.startswith("Connection")} == {17}
    # Connection field 12 referencing a ParamN.
    assert docs["ez_style_comm_module.eds"].entry("Connection Manager", "Connection2").value(12) == "Param3"
    # An unquoted path.
    assert b"Port1 = TCP, \"Ethernet\", 20 F5 24 01, 1;" in raw["hand_drive_oelpumpe.eds"]
    # The [Assembly] class keywords next to AssemN.
    for name in ("ez_style_comm_module.eds", "ez_style_servo_large.eds", "ez_style_safety_io.eds"):
        keywords = {e.keyword for e in docs[name].get("Assembly")}
        assert {"Revision", "Object_Name", "Number_Of_Static_Instances"} <= keywords, name
    # Connection sizes that only ParamN defaults give.
    drive = docs["hand_drive_oelpumpe.eds"].entry("Connection Manager", "Connection1")
    assert (drive.value(4), drive.value(5), drive.value(7), drive.value(8)) == ("Param10", None, "Param11", None)
    # Sizes past what a Forward_Open carries.
    assert max(a.size for a in read_view(docs["ez_style_servo_large.eds"]).assemblies.values()) > 511
    # For the writer: an icon in many adjacent quoted pieces, a long help text in pieces.
    assert raw["ez_style_comm_module.eds"].count(b'"\r\n                "') >= 20
    assert b'pump; "\n\t\t"a negative' in raw["hand_drive_oelpumpe.eds"]
    # Latin-1, not UTF-8: non-ASCII in comments, ProdName and VendName.
    drive_raw = raw["hand_drive_oelpumpe.eds"]
    assert "Geräte".encode("latin-1") in drive_raw and "Überwachung".encode("latin-1") in drive_raw
    assert docs["hand_drive_oelpumpe.eds"].entry("Device", "ProdName").value() == "Ölpumpe ÖP-7.5 Antrieb"
    assert docs["hand_drive_oelpumpe.eds"].entry("Device", "VendName").value() == "Müller & Söhne Antriebstechnik"
    utf8 = {name for name, data in raw.items() if not data.isascii() and _is_utf8_text(data)}
    assert utf8 == {"hand_utf8_distance_sensor.eds"}
    # Variable-size assemblies (AssemExaN) sized by their members and by a parameter; a modular
    # station ([Modular]) whose assemblies sum its default modules; the self-member idiom; real-time
    # format 5 on CIP Safety connections; connections whose points have no assembly.
    iolink = docs["ez_style_iolink_master.eds"]
    assert iolink.entry("Assembly", "AssemExa101").value(3) is None
    assert iolink.entry("Assembly", "AssemExa103").value(3) == "Param11"
    assert "Modular" in docs["vendor_modular_coupler.eds"]
    assert docs["vendor_drive_own_data.eds"].entry("Assembly", "Assem20").value(8) == "Assem20"
    safety5 = docs["ez_style_safety_format5.eds"].entry("Connection Manager", "Connection5").value(2)
    assert (safety5 >> 8) & 7 == 5 and (safety5 >> 12) & 7 == 5
    assert "Assembly" not in docs["vendor_plc_generic_adapter.eds"]
    # CRLF in some files, LF in others; tab indentation and comments between fields in a hand-written one.
    crlf = {name for name, data in raw.items() if b"\r\n" in data}
    assert crlf and crlf != set(raw) and all(raw[name].count(b"\n") == raw[name].count(b"\r\n") for name in crlf)
    assert b"\n\tParam2 = " in drive_raw and b"\t\t$ read only\n" in drive_raw
    # A DeviceNet file without [Connection Manager].
    devicenet = docs["devicenet_valve.eds"]
    assert devicenet.entry("Device Classification", "Class1").value() == "DeviceNet"
    assert "Connection Manager" not in devicenet and "IO_Info" in devicenet


def _is_utf8_text(data: bytes) -> bool:
    try:
        data.decode("utf-8")
    except UnicodeDecodeError:
        return False
    return True


# -- eds check, eds show, the writer's round trip -------------------------------------------------------

@pytest.mark.parametrize("path", FILES, ids=_ids(FILES))
def test_eds_check_finds_no_error_and_the_expected_warnings(path: Path) -> None:
    out = io.StringIO()
    status = run_check(argparse.Namespace(files=[str(path)], json=False), stdout=out, stderr=out)
    assert status == 0, out.getvalue()
    warnings, notes = EXPECTED[path.name].check_warnings, EXPECTED[path.name].check_notes
    expected = sorted([(line, f"{path}:{line}: warning {rule}: {message}") for line, rule, message in warnings]
                      + [(line, f"{path}:{line}: info {rule}: {message}") for line, rule, message in notes])
    summary = f"1 file: 0 errors, {len(warnings)} warning" + ("" if len(warnings) == 1 else "s") + (
        f", {len(notes)} note" + ("" if len(notes) == 1 else "s") if notes else "")
    assert out.getvalue().splitlines() == [text for _, text in expected] + [summary]


@pytest.mark.parametrize("path", FILES, ids=_ids(FILES))
def test_eds_show_knows_what_the_file_determines(path: Path) -> None:
    out, err = io.StringIO(), io.StringIO()
    assert run_show(argparse.Namespace(file=str(path), json=False), stdout=out, stderr=err) == 0
    text = out.getvalue()
    assert "None" not in text and "?" not in text, text
    doc = read_eds(path)
    assert f"Device: {doc.entry('Device', 'ProdName').value()}" in text
    view = read_view(doc)
    for connection in view.connections:
        sizes = (0 if connection.heartbeat else connection.o_t_size, connection.t_o_size)
        block = text.split(f"  Connection{connection.number} ", 1)[1]
        assert [int(n) for n in re.findall(r"(?:O->T|T->O): (\d+) bytes", block)[:2]] == list(sizes), block


@pytest.mark.parametrize("path", FILES, ids=_ids(FILES))
def test_the_canonical_writer_keeps_what_the_file_means(path: Path) -> None:
    doc = read_eds(path)
    assert semantic_differences(doc, parse_eds(format_eds(doc))) == []


# -- adapter --eds and io --eds --------------------------------------------------------------------------

@pytest.mark.parametrize("path", FILES, ids=_ids(FILES))
def test_the_emulation_skips_exactly_what_it_cannot_serve(path: Path) -> None:
    device = build_eds_device(read_eds(path))
    assert [(issue.line, issue.message) for issue in device.issues] == EXPECTED[path.name].skipped
    assert [c.number for c in read_view(read_eds(path)).connections
            if f"Connection{c.number} " not in " ".join(i.message for i in device.issues)] == \
        EXPECTED[path.name].offered


def test_an_assembly_without_a_path_takes_the_instance_its_connection_path_names() -> None:
    view = read_view(read_eds(DIRECTORY / "ez_style_io_block.eds"))
    assert {k: (a.instance, a.size) for k, a in view.assemblies.items()} == {"Assem100": (100, 4),
                                                                             "Assem150": (150, 2)}
    assert view.issues == []


def test_an_assembly_path_wins_over_its_number_and_over_a_connection_path_that_disagrees() -> None:
    """Assem2's path names instance 100 (its number is no instance); Connection9 names Assem101 (instance
    101 by its path) for T->O but its path says 0x67: the assembly stays at 101, eds check warns, and
    the connection is not offered, as the point its path names is no assembly."""
    view = read_view(read_eds(DIRECTORY / "hand_valve_manifold.eds"))
    assert (view.assemblies["Assem2"].instance, view.assemblies["Assem101"].instance) == (100, 101)
    assert (view.connection(9).t_o_assembly, view.connection(9).t_o_point) == ("Assem101", 0x67)
    assert view.connection(1).config == 0x66   # "20 04 24 [Param4] ...": Param4's default


class Adapter:
    """`cipstack adapter --eds FILE` as a subprocess; its stderr read as it comes (the pipe never fills)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.port, self.io_port = free_port(), free_port()
        self.process = subprocess.Popen(
            [sys.executable, "-m", "cipstack", "adapter", "--eds", str(path), "--port", str(self.port),
             "--io-port", str(self.io_port), "--quiet"],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, encoding="utf-8")
        self.lines: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        for _ in range(300):
            try:
                socket.create_connection(("127.0.0.1", self.port), timeout=0.2).close()
                return
            except OSError:
                assert self.process.poll() is None, "\n".join(self.lines)
                time.sleep(0.05)
        raise AssertionError("the adapter does not listen")

    def _read(self) -> None:
        assert self.process.stderr is not None
        for line in self.process.stderr:
            self.lines.append(line.rstrip("\n"))

    def wait_for(self, pattern: str, timeout: float = 30.0) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if any(re.search(pattern, line) for line in self.lines):
                return
            time.sleep(0.05)
        raise AssertionError(f"the adapter never logged {pattern!r}:\n" + "\n".join(self.lines))

    def close(self) -> None:
        self.process.terminate()
        self.process.wait(10)
        self._reader.join(5)


@pytest.fixture(scope="module", params=WITH_CONNECTIONS, ids=_ids(WITH_CONNECTIONS))
def adapter(request: pytest.FixtureRequest) -> Iterator[Adapter]:
    started = Adapter(request.param)
    yield started
    started.close()


#: At most this many connections at once, and never more than the file's MaxIOConnections (a file of
#: 60 connections runs in rounds).
ROUND_SIZE = 16


def _capacity(path: Path) -> int:
    entry = read_eds(path).entry("Capacity", "MaxIOConnections")
    declared = entry.value() if entry is not None else None
    return min(ROUND_SIZE, declared) if isinstance(declared, int) and declared > 0 else ROUND_SIZE


def _rounds(connections: list[ConnectionInfo], size: int, weight: dict[int, int] | None = None,
            ) -> list[list[ConnectionInfo]]:
    """Connections that may run at once: one exclusive owner per output assembly in a round, at most
    ``size`` connections in all, a connection counting with the listeners it takes along (``weight``,
    by number: 1 where not given)."""
    weight = weight or {}
    rounds: list[list[ConnectionInfo]] = []

    def load(batch: list[ConnectionInfo]) -> int:
        return sum(weight.get(c.number, 1) for c in batch)

    for connection in connections:
        for batch in rounds:
            if load(batch) + weight.get(connection.number, 1) <= size and (connection.heartbeat or all(
                    other.heartbeat or other.o_t_point != connection.o_t_point for other in batch)):
                batch.append(connection)
                break
        else:
            rounds.append([connection])
    return rounds


def test_the_adapter_says_what_it_skips(adapter: Adapter) -> None:
    warnings = [line for line in adapter.lines if ": warning: " in line and "cipstack adapter:" in line]
    assert warnings == [f"cipstack adapter: {adapter.path}:{line}: warning: {message}"
                        for line, message in EXPECTED[adapter.path.name].skipped]


async def test_each_offered_connection_runs(adapter: Adapter) -> None:
    """Every connection the adapter offers exchanges data with the library's originator, as `cipstack
    io --eds` opens it (``io_connection_from_eds``, RPI 10 ms, timeout multiplier 4); those of a round
    run at once, in this process. A listen-only connection runs while a connection of the file that
    produces the same input by multicast (its owner) runs. The command line itself runs one
    connection of each kind (the next test)."""
    from cipstack.scanner import Scanner

    doc = read_eds(adapter.path)
    view = read_view(doc)
    offered = [c for c in view.connections if c.number in EXPECTED[adapter.path.name].offered]
    listeners = [c for c in offered if c.kind == "listen only"]
    owners = {c.number: next(o for o in offered if o.kind != "listen only" and o.t_o_point == c.t_o_point
                             and o.t_o_multicast) for c in listeners}
    received: dict[int, int] = {}

    def opened(number: int, **options: Any) -> Any:
        return scanner.io_connection_from_eds(doc, number, 0.010, target_io_port=adapter.io_port,
                                              timeout_multiplier=4, **options)

    async with await Scanner.connect(f"127.0.0.1:{adapter.port}", eds=doc) as scanner:
        # The listeners run beside their owners' round: an owner counts with its listeners, or the last
        # to open finds the device's connections taken (0x0113).
        weight = {o.number: 1 + sum(owner is o for owner in owners.values()) for o in owners.values()}
        for batch in _rounds([c for c in offered if c.kind != "listen only"], _capacity(adapter.path), weight):
            serving = [o for o in batch if o in owners.values()]
            async with contextlib.AsyncExitStack() as stack:
                # An owner the file lets produce both ways is asked for multicast, for its listeners.
                running = {c.number: await stack.enter_async_context(
                    opened(c.number, **({"multicast": True} if c in serving else {}))) for c in batch}
                for owner in serving:
                    assert running[owner.number].multicast_group is not None, f"Connection{owner.number}"
                for number, owner in owners.items():
                    if owner in serving:
                        running[number] = await stack.enter_async_context(opened(number))
                for handle in running.values():
                    handle.set_run(True)
                # Data both ways until each has received more than 10 packets.
                await wait_until(lambda now=running: all(h.statistics()["received"] > 10 for h in now.values()), 10.0,
                                 f"more than 10 packets on each of {sorted(running)}")
                received.update({n: h.statistics()["received"] for n, h in running.items()})
    assert sorted(received) == EXPECTED[adapter.path.name].offered
    for number, count in sorted(received.items()):
        assert count > 10, f"Connection{number}: received {count}"


def _io(adapter: Adapter, number: int, duration: float, *more: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "cipstack", "io", f"127.0.0.1:{adapter.port}", "--eds", str(adapter.path),
         "--connection", str(number), "--rpi", "10ms", "--duration", f"{duration}s", "--timeout-multiplier", "4",
         "--target-io-port", str(adapter.io_port), "--print", "summary", *more],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _first_of_each_kind() -> dict[str, tuple[Path, int]]:
    """The first corpus file and connection the adapter offers of each kind (listen only: one whose
    owner may produce by multicast)."""
    found: dict[str, tuple[Path, int]] = {}
    for path in WITH_CONNECTIONS:
        view = read_view(read_eds(path))
        for connection in view.connections:
            if connection.number in EXPECTED[path.name].offered and connection.kind not in found:
                found[connection.kind] = (path, connection.number)
    return found


def test_a_connection_of_each_kind_runs_with_cipstack_io() -> None:
    """`cipstack io --eds FILE --connection N`, as a user runs it, for one connection of each kind the
    corpus offers; a listen-only one beside its owner, which is asked for multicast (--multicast)
    and runs until its listener is done, then stops as Ctrl-C stops it (exit 130, after closing
    and printing its statistics)."""
    kinds = _first_of_each_kind()
    assert set(kinds) == {"exclusive owner", "input only", "listen only"}
    for kind, (path, number) in sorted(kinds.items()):
        started = Adapter(path)
        try:
            view = read_view(read_eds(path))
            if kind == "listen only":
                listener = view.connection(number)
                owner = next(o for o in view.connections if o.number in EXPECTED[path.name].offered
                             and o.kind != "listen only" and o.t_o_point == listener.t_o_point and o.t_o_multicast)
                serving = _io(started, owner.number, 30.0, "--multicast")
                started.wait_for(rf"->{owner.t_o_point} \(0x[0-9A-F]+\) opened .*multicast")
                listening = _io(started, number, 0.5)
                outputs = {number: listening.communicate(timeout=60)}
                serving.send_signal(signal.SIGINT)
                results = [(number, 0, listening), (owner.number, 130, serving)]
            else:
                results = [(number, 0, _io(started, number, 0.5))]
                outputs = {}
            for connection, expected, process in results:
                stdout, stderr = outputs.get(connection) or process.communicate(timeout=60)
                assert process.returncode == expected, (
                    f"{path.name} Connection{connection} ({kind}): {stderr}\n" + "\n".join(started.lines))
                stats = next(line for line in stdout.splitlines() if line.startswith("sent "))
                assert int(stats.split()[3]) > 10, f"{path.name} Connection{connection}: {stats}"
        finally:
            started.close()


def _ethernetip_format(doc: EdsDocument, number: int) -> int:
    """The O->T real-time format of ConnectionN (field 2 bits 8-10: 4 run/idle header)."""
    return (doc.entry("Connection Manager", f"Connection{number}").value(2) >> 8) & 0x7


def test_python_ethernetip_runs_what_it_can_open(adapter: Adapter, monkeypatch: pytest.MonkeyPatch) -> None:
    ethernetip = needs("ethernetip")
    enip_module = needs("ethernetip.ethernetip")

    from cipstack.scanner import SyncScanner

    doc = read_eds(adapter.path)   # once: a file of 60 connections was read once for each
    view = read_view(doc)
    expected = EXPECTED[adapter.path.name].ethernetip
    usable = [c.number for c in view.connections if c.number in EXPECTED[adapter.path.name].offered
              and _ethernetip_format(doc, c.number) == 4 and c.t_o_point_to_point
              and max(c.o_t_size + 6, c.t_o_size + 2) <= 511 and max(c.config, c.o_t_point, c.t_o_point) <= 255]
    assert usable == expected
    if not expected:
        return  # none applies (the servo's sizes take a Large_Forward_Open, which it cannot send)
    received: dict[int, int] = {}

    class Counting(enip_module.UdpRecvDataPacket):  # type: ignore[misc,name-defined]
        def __init__(self, buf: bytes) -> None:
            super().__init__(buf)
            received[self.conn_id] = received.get(self.conn_id, 0) + 1

    monkeypatch.setattr(enip_module, "UdpRecvDataPacket", Counting)
    monkeypatch.setattr(enip_module, "ENIP_TCP_PORT", adapter.port)
    monkeypatch.setattr(enip_module, "ENIP_UDP_PORT", adapter.io_port)
    for number in expected:
        connection = view.connection(number)
        enip = ethernetip.EtherNetIP("127.0.0.1")
        explicit = enip.explicit_conn("127.0.0.1")
        explicit.registerSession()
        enip.registerAssembly(ethernetip.EtherNetIP.ENIP_IO_TYPE_INPUT, connection.t_o_size, connection.t_o_point,
                              explicit)
        # Input only: the heartbeat point as an output of no data (it sends the run/idle header alone).
        outputs = enip.registerAssembly(ethernetip.EtherNetIP.ENIP_IO_TYPE_OUTPUT, connection.o_t_size,
                                        connection.o_t_point, explicit)
        enip.startIO(free_port("0.0.0.0"))
        try:
            status = explicit.sendFwdOpenReq(connection.t_o_point, connection.o_t_point, connection.config,
                                             torpi=10, otrpi=10, multiplier=2, inputsz=connection.t_o_size,
                                             outputsz=0 if connection.heartbeat else connection.o_t_size,
                                             originator_udp_port=enip.originator_udp_port)
            assert status == 0, f"Connection{number}: Forward_Open refused, extended status 0x{status or 0:04X}"
            if outputs:
                outputs[1] = outputs[3] = True          # 0x0A in the first output byte
            explicit.produce()
            wait_for(lambda conn=explicit.toconnid: received.get(conn, 0) > 10, 10.0,
                     f"more than 10 packets of Connection{number}")
            if outputs:
                with SyncScanner(f"127.0.0.1:{adapter.port}") as scanner:
                    def holds(point: int = connection.o_t_point) -> bool:
                        return scanner.get_attribute_single(0x04, point, 3).data[0] == 0x0A

                    wait_for(holds, 10.0, f"the output of Connection{number} (0x0A) in its assembly")
            explicit.stopProduce()
            assert explicit.sendFwdCloseReq(connection.t_o_point, connection.o_t_point, connection.config) == 0
        finally:
            explicit.stopProduce()
            enip.stopIO()
            # A session each: ended, as a well-behaved client ends it, or the device's table fills.
            explicit.unregisterSession()
        assert received.get(explicit.toconnid, 0) > 10, f"Connection{number}: {received}"


def test_list_fields_names_what_set_and_the_input_take(tmp_path: Path) -> None:
    """`cipstack io --eds F --connection N --list-fields` reads the file alone (no device needed)."""
    from cipstack.devices.acg.eds_file import acg_et2_description
    from cipstack.eds.generator import eds_text

    path = tmp_path / "acg.eds"
    path.write_text(eds_text(acg_et2_description()), encoding="latin-1")
    result = subprocess.run([sys.executable, "-m", "cipstack", "io", "127.0.0.1:1", "--eds", str(path),
                             "--connection", "1", "--list-fields"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert lines[0] == "output (O->T): assembly 21 'Extended Speed Control Output', 4 bytes"
    assert any(line.split()[:4] == ["speed_reference", "byte", "2", "INT"] for line in lines)
    assert "input (T->O): assembly 71 'Extended Speed Control Input', 4 bytes" in lines


# -- configuration assemblies ---------------------------------------------------------------------------

def test_a_configuration_assembly_without_a_path_is_the_configuration_instance_of_its_connection() -> None:
    view = read_view(read_eds(DIRECTORY / "ez_style_comm_module.eds"))
    assert view.connection(1).config_assembly == "Assem128" and view.connection(1).config == 0x80
    assert (view.assemblies["Assem128"].instance, view.assemblies["Assem128"].size) == (0x80, 8)
    # Field 12 may name a parameter (Connection2): no assembly is placed for it.
    assert view.connection(2).config_assembly is None and view.connection(2).config == 0x81


async def test_the_configuration_data_of_a_forward_open_goes_to_the_configuration_assembly() -> None:
    from cipstack.adapter import Adapter as Target
    from cipstack.adapter import AdapterSettings
    from cipstack.cip.status import CipError, ExtendedStatus
    from cipstack.objects.tcpip import NetworkInterface
    from cipstack.scanner import Scanner

    doc = read_eds(DIRECTORY / "ez_style_comm_module.eds")
    device = build_eds_device(doc, NetworkInterface(ip_address="127.0.0.1"))
    target = Target(AdapterSettings(host="127.0.0.1", port=0, io_port=0), device=device)
    await target.start()
    try:
        assert target.io_endpoint is not None
        io_port = target.io_endpoint.port
        settings = bytes(range(1, 9))
        async with await Scanner.connect(f"127.0.0.1:{target.port}") as scanner:
            # Instance 0x80 is the configuration point, not an output a connection may own.
            assert 0x80 not in device.io_profile().consumed()  # type: ignore[union-attr]
            async with scanner.io_connection_from_eds(doc, 1, target_io_port=io_port, config_data=settings) as io:
                await io.wait_input(lambda image: True, timeout=5)
            assert (await scanner.get_attribute_single(0x04, 0x80, 3)).data == settings
            # Another size is refused (0x0126), and so is data for a configuration instance that is
            # no assembly (Connection2's is a parameter); the assembly keeps what it had.
            for number, data, status in ((1, settings[:6], ExtendedStatus.INVALID_CONFIGURATION_SIZE),
                                         (2, b"\x01\x00", ExtendedStatus.INVALID_CONFIGURATION_PATH)):
                with pytest.raises(CipError) as refused:
                    async with scanner.io_connection_from_eds(doc, number, target_io_port=io_port, config_data=data):
                        pass
                assert refused.value.extended[:1] == (status,)
            assert (await scanner.get_attribute_single(0x04, 0x80, 3)).data == settings
    finally:
        await target.close()


def test_the_docs_show_what_the_adapter_prints_for_the_manifold() -> None:
    readme = (Path(__file__).parents[2] / "docs" / "emulator" / "eds-device.md").read_text(encoding="utf-8")
    shown = [line for line in readme.splitlines() if line.startswith("cipstack adapter: hand_valve_manifold.eds:")]
    assert shown == [f"cipstack adapter: hand_valve_manifold.eds:{line}: warning: {message}"
                     for line, message in EXPECTED["hand_valve_manifold.eds"].skipped]
