"""The battery against real targets over loopback: cipstack's own emulators (every applicable check
passes) and cpppo's server (the battery runs to the end; its deviations are listed here), and the
``cipstack conform`` command: reports, exit statuses, one-line errors."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path
from xml.etree import ElementTree

import pytest

from cipstack.conformance import Report, TargetUnreachable, Verdict, check_ids, run
from tests.cli_errors import one_line_error
from tests.interop.conftest import HOST, PeerProcess, cpppo_server_command, python_module, start_peer
from tests.ports import free_port

from .conftest import AdapterStarter
from .fake_target import FakeTarget

EMULATORS = {
    "acg": ([], ["--profile", "acg"]),
    "mx2": (["--profile", "mx2", "--model", "MX2-A2015-E"], ["--profile", "mx2", "--model", "MX2-A2015-E"]),
    "rx": (["--profile", "rx", "--model", "RX-A4055-E"], ["--profile", "rx", "--model", "RX-A4055-E"]),
}


def generate_eds(profile_args: list[str], directory: Path) -> Path:
    subprocess.run(python_module("cipstack", "eds", "generate", *profile_args, "-o", str(directory)), check=True,
                   capture_output=True, timeout=60)
    (found,) = directory.glob("*.eds")
    return found


def _not_passed(report: object) -> dict[str, str]:
    return {o.name: f"{o.verdict.value}: {o.observed}" for o in report  # type: ignore[attr-defined]
            if o.verdict is Verdict.FAIL}


@pytest.mark.parametrize("name", sorted(EMULATORS))
def test_every_applicable_check_passes_on_our_emulators(name: str, adapter_with: AdapterStarter,
                                                        tmp_path: Path) -> None:
    adapter_args, eds_args = EMULATORS[name]
    eds = generate_eds(eds_args, tmp_path / "eds")
    peer = adapter_with(*adapter_args)
    report = run(peer.host, peer.port, eds=eds)
    assert _not_passed(report) == {}
    assert report.duration_s < 60
    verdicts = {o.id: o.verdict for o in report}
    assert set(verdicts) == set(check_ids())
    if name == "acg":
        # The ACG-ET2 has class 1 connections: the connection groups ran, they did not just not apply.
        assert all(verdicts[i] is Verdict.PASS for i in check_ids() if i.startswith(("cm.", "class1.")))


def not_applicable(report: Report) -> list[str]:
    """The checks that did not apply (those that need an option not given are "not run", apart)."""
    return [o.name for o in report if o.verdict is Verdict.NOT_APPLICABLE]


#: Where the battery finds each emulator's connection points without --eds (the MX2's and RX's own
#: EDS files describe CompoNet, with no class 1 connection: the AC drive profile gives them).
SOURCES = {"acg": "the device's own EDS file", "mx2": "the AC drive profile", "rx": "the AC drive profile"}


@pytest.mark.parametrize("name", sorted(EMULATORS))
def test_without_an_eds_the_battery_finds_the_points_itself(name: str, adapter_with: AdapterStarter) -> None:
    peer = adapter_with(*EMULATORS[name][0])
    report = run(peer.host, peer.port)
    assert _not_passed(report) == {}
    assert str(report.options["connection_points"]).startswith(SOURCES[name])
    assert report.options["eds"].startswith("the device's own EDS file")  # group eds runs with it
    # The ACG-ET2's own file declares the connections of every pair CM.24/CM.23 may select: those of
    # the pairs not selected are its configuration (n/a, issue 52 item 5), each saying so.
    configured = [o for o in report if o.verdict is Verdict.NOT_APPLICABLE and o.id == "eds.connection.open"
                  and o.subject]
    assert all(o.observed.startswith(("not accepted in the device's present configuration, which accepts ",
                                      "listen only, and nothing produces input ")) for o in configured)
    assert len(configured) == (33 if name == "acg" else 0)
    assert len(not_applicable(report)) - len(configured) <= 6, not_applicable(report)
    assert all(o.verdict is Verdict.PASS for o in report if o.group in ("cm", "class1"))
    # The MX2 and RX trip when a class 1 connection times out (P045 = 0, CompoNet manual Table 12): the
    # battery's class1.timeout faults them, and without --allow-writes it says so rather than write.
    (final,) = [o for o in report if o.group == "final"]
    assert final.verdict is (Verdict.PASS if name == "acg" else Verdict.WARNING), final.observed


#: The ACG takes its run command and reference from the network only when its keypad says so (drv = 4
#: Field Bus, Frq = 8; ACG-ET2 manual, output instance 21 note 2): the motion checks need them.
FROM_THE_NETWORK = {"acg": ["--param", "drv=4", "--param", "Frq=8"], "mx2": [], "rx": []}


@pytest.mark.parametrize("name", sorted(EMULATORS))
def test_both_drive_families_pass_the_profile_group(name: str, adapter_with: AdapterStarter) -> None:
    peer = adapter_with(*EMULATORS[name][0], *FROM_THE_NETWORK[name], "--factory")
    report = run(peer.host, peer.port, groups="profile", allow_writes=True, allow_motion=True)
    assert {o.id: o.verdict for o in report if o.group == "profile"} == {
        i: Verdict.PASS for i in check_ids() if i.startswith("profile.")}, _not_passed(report)
    assert "refused a Set (0x0E)" in next(o.observed for o in report if o.id == "profile.ac_dc_drive")
    # Left as found: the connection point opens again, the drive is stopped, not faulted, its sources back.
    assert next(o for o in report if o.id == "final.as_found").verdict is Verdict.PASS
    after = {attribute: _get(peer, attribute) for attribute in ("0x29/1/7", "0x29/1/10", "0x29/1/15", "0x2A/1/29")}
    assert after == {"0x29/1/7": 0, "0x29/1/10": 0, "0x29/1/15": int(name == "acg"), "0x2A/1/29": int(name == "acg")}


def _get(peer: PeerProcess, attribute: str) -> int:
    done = subprocess.run(python_module("cipstack", "get", f"{peer.host}:{peer.port}", attribute, "--json"),
                          capture_output=True, text=True, timeout=30, check=True)
    return int(json.loads(done.stdout)["value"])


@pytest.mark.parametrize("allow_writes", [False, True])
def test_a_fault_the_run_caused_is_cleared_only_when_writes_are_allowed(allow_writes: bool,
                                                                        adapter_with: AdapterStarter) -> None:
    peer = adapter_with("--profile", "mx2", "--model", "MX2-A2015-E", "--factory")
    report = run(peer.host, peer.port, groups="class1", allow_writes=allow_writes)
    (final,) = [o for o in report if o.id == "final.as_found"]
    assert "faulted during the run (FaultCode 10 75), not at its start" in final.observed
    if allow_writes:
        assert final.verdict is Verdict.PASS and "FaultRst 0->1 cleared it" in final.observed
    else:
        assert final.verdict is Verdict.WARNING and "nothing is written without --allow-writes" in final.observed
    assert _get(peer, "0x29/1/10") == int(not allow_writes)


def test_without_allow_motion_the_motor_is_not_run(adapter_with: AdapterStarter) -> None:
    peer = adapter_with("--profile", "mx2", "--model", "MX2-A2015-E", "--factory")
    report = run(peer.host, peer.port, groups="profile")
    motion = {o.id: (o.verdict, o.observed) for o in report if o.id.startswith("profile.motion.")}
    assert motion and all(v == (Verdict.NOT_RUN, "needs --allow-motion (this check runs the motor)")
                          for v in motion.values())
    assert "final.as_found" not in {o.id for o in report}  # no connection opened, nothing written


def test_an_eds_emulated_device_without_an_eds_serves_its_own(adapter_with: AdapterStarter) -> None:
    peer = adapter_with("--eds", str(Path(__file__).with_name("fake_device.eds")))
    report = run(peer.host, peer.port, allow_writes=True)
    assert _not_passed(report) == {}
    assert str(report.options["connection_points"]).startswith("the device's own EDS file")
    # Device type 12 is no drive: the AC drive profile's checks, motion ones included, do not apply.
    assert all(o.verdict is Verdict.NOT_APPLICABLE for o in report if o.group == "profile")
    assert len([i for i in not_applicable(report) if not i.startswith("profile.")]) <= 6, not_applicable(report)
    assert all(o.verdict is Verdict.PASS for o in report if o.group in ("cm", "class1", "eds", "final"))


def test_a_device_without_class_1_fails_no_connection_check(adapter_with: AdapterStarter, tmp_path: Path) -> None:
    # The first 23 lines of the fake device's file: its identity, no parameter, assembly or connection.
    header = Path(__file__).with_name("fake_device.eds").read_text(encoding="ascii").splitlines()[:23]
    (tmp_path / "explicit_only.eds").write_text("\n".join(header) + "\n", encoding="ascii")
    peer = adapter_with("--eds", str(tmp_path / "explicit_only.eds"))
    report = run(peer.host, peer.port, groups="cm")
    verdicts = {o.id: (o.verdict, o.observed) for o in report}
    assert _not_passed(report) == {}
    # Refused 0x0103 as a class 1 Forward_Open (before its path is read), the malformed path is asked again
    # on a class 3 one, whose path the message router's is.
    assert verdicts["cm.forward_open.bad_segment"] == (
        Verdict.PASS, "class 1 refused 0x0103 (no class 1 I/O); class 3, segment E0 00 before 20 02 24 01: general "
                      "status 0x01 extended 0x0315")
    assert verdicts["cm.forward_open.transport_class"][0] is Verdict.PASS


def test_the_other_sources_of_connection_points(tmp_path: Path) -> None:
    """The scripted target serves no EDS and is no drive: --eds-dir finds its file by its identity,
    --connection-points names them, and else probing the Assembly object finds them."""
    directory = tmp_path / "eds"
    directory.mkdir()
    (directory / "other.eds").write_text("[Device]\nVendCode = 1;\nProdCode = 7;\nMajRev = 1;\nMinRev = 2;\n")
    (directory / "fake.eds").write_bytes(Path(__file__).with_name("fake_device.eds").read_bytes())
    with FakeTarget() as target:
        from_dir = run(target.host, target.port, groups="cm,eds", eds_dir=directory, timeout=2.0)
        named = run(target.host, target.port, groups="cm", connection_points=(102, 103, 1), timeout=2.0)
        probed = run(target.host, target.port, groups="cm", timeout=2.0)
    assert str(from_dir.options["connection_points"]).endswith("fake.eds (--eds-dir)")
    assert {o.group for o in from_dir if o.verdict is Verdict.PASS} >= {"cm", "eds", "final"}
    assert named.options["connection_points"] == "--connection-points 102,103,1"
    assert str(probed.options["connection_points"]).startswith("probing the Assembly object")
    for report in (from_dir, named, probed):
        assert _not_passed(report) == {} and not [o for o in report if o.group == "cm"
                                                   and o.verdict is Verdict.NOT_APPLICABLE]


@pytest.mark.parametrize("deviation", [None, "cm.forward_open.bad_segment"])
def test_the_checks_that_need_no_connection_point_run_without_one(deviation: str | None) -> None:
    """Points that do not exist: no connection point, and the Forward_Opens that need none still run (the
    reserved segment before the message router's path is refused at its first segment)."""
    with FakeTarget(deviation=deviation) as target:
        report = run(target.host, target.port, groups="cm", connection_points=(0x50, 0x51, 1), timeout=2.0)
    assert "has no size" in str(report.options["connection_points"])
    ran = {o.id: o.verdict for o in report if o.verdict is not Verdict.NOT_APPLICABLE and o.group == "cm"}
    expected = Verdict.FAIL if deviation else Verdict.PASS
    assert ran == {"cm.forward_open.bad_segment": expected, "cm.forward_open.transport_class": Verdict.PASS,
                   "cm.forward_open.null": Verdict.PASS, "cm.forward_close.unknown": Verdict.PASS,
                   "cm.class3.read": Verdict.PASS, "cm.class3.duplicate": Verdict.PASS}
    assert "segment E0 00 before 20 02 24 01" in next(o.observed for o in report
                                                     if o.id == "cm.forward_open.bad_segment")


def test_every_applicable_check_passes_on_an_eds_emulated_device(adapter_with: AdapterStarter, tmp_path: Path) -> None:
    eds = Path(__file__).with_name("fake_device.eds")
    peer = adapter_with("--eds", str(eds))
    report = run(peer.host, peer.port, eds=eds, allow_writes=True)
    assert _not_passed(report) == {}
    assert all(o.verdict is Verdict.PASS for o in report if o.group in ("cm", "class1", "eds"))


#: cpppo 5.2.5's server against the battery (no EDS, and no connection point found: it has no class 1;
#: the checks that need none run all the same): each check that fails there
#: and why. These are its deviations, seen on the wire; tests/interop/test_cpppo.py pins several.
CPPPO_DEVIATIONS = {
    "encap.register_session.options": "grants a session when the option flags are not 0 (0x0069 expected)",
    "encap.register_session.protocol_version": "grants a session for protocol version 2 (0x0069 expected)",
    "encap.register_session.second": "grants a second session on the same TCP connection (0x0001 expected)",
    "encap.nop": "closes the connection after a NOP that carries data",
    "encap.list_identity.tcp": "its ListIdentity sockaddr always names port 44818, not the port it listens on",
    "encap.list_identity.udp": "the same sockaddr over UDP",
    "encap.list_services": "its ListServices item is 19 bytes (a 15-byte name field; 20 expected)",
    "encap.unsupported_command": "answers command 0x0001 with status 0 and data",
    "encap.wrong_length": "accepts a RegisterSession whose length counts 2 bytes too many",
    "encap.send_rr_data.no_session": "serves SendRRData on a connection with no session",
    "encap.send_rr_data.wrong_session": "serves SendRRData whatever the session handle",
    "router.unknown_service": "a service its objects lack: encapsulation status 0x0008, connection dropped",
    "router.unknown_class": "a missing class: encapsulation status 0x0008 (0x05 expected)",
    "router.unknown_instance": "a missing instance: encapsulation status 0x0008 (0x05 expected)",
    "router.unknown_attribute": "a missing attribute answers 0x08 (0x14 expected)",
    "router.too_much_data": "ignores bytes after a complete Get_Attribute_Single",
    "router.not_enough_data": "a short Forward_Open: encapsulation status 0x0008 (0x13 expected)",
    "router.bad_path": "a reserved segment type: encapsulation status 0x0008 (0x04 expected)",
    "router.multiple_service.bad_member": "general status 0 although a member failed (0x1E expected)",
    "objects.connection_manager": "Get_Attribute_Single of 6/1/1: encapsulation status 0x0008",
    "objects.tcp_ip.attributes": "no TCP/IP attribute 13 (encapsulation inactivity timeout)",
    "objects.ethernet_link.attributes": "no Ethernet Link object (encapsulation status 0x0008)",
    "cm.forward_close.unknown": "answers success to a Forward_Close of a connection that does not exist",
    "router.unconnected_send.missing_port": "serves the embedded request whatever port the route names",
    "router.get_attribute_list": "status 0 with a failed member, no count, 0x16 for a missing attribute",
    "cm.class3.read": "answers SendUnitData on the O->T connection ID, not the originator's T->O ID",
    "cm.class3.duplicate": "executes a request repeated with the same sequence count",
    # It has no Forward_Open: these three run without a connection point and find that.
    "cm.forward_open.transport_class": "Forward_Open: encapsulation status 0x0008 (0x01 with 0x0103 expected)",
    "cm.forward_open.null": "Forward_Open: encapsulation status 0x0008 (0 or 0x01 with 0x0132 expected)",
    "cm.forward_open.bad_segment": "Forward_Open: encapsulation status 0x0008 (0x01 with 0x0315 expected)",
}


@pytest.fixture
def cpppo_server(tmp_path: Path) -> Iterator[PeerProcess]:
    port = free_port()
    peer = start_peer("cpppo server", cpppo_server_command(HOST, port), HOST, port, tmp_path / "cpppo.log")
    try:
        yield peer
    finally:
        peer.stop(signal.SIGTERM)


@pytest.mark.interop
def test_cpppo_server_runs_to_the_end_with_its_deviations(cpppo_server: PeerProcess) -> None:
    report = run(cpppo_server.host, cpppo_server.port, timeout=3.0)
    assert {o.id for o in report} == set(check_ids())
    assert {o.id: o.observed for o in report.failures if o.id not in CPPPO_DEVIATIONS} == {}
    assert sorted(o.id for o in report.failures) == sorted(CPPPO_DEVIATIONS)


# -- the command --------------------------------------------------------------------------------------
def conform(*args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "cipstack", "conform", *args], capture_output=True, text=True,
                          timeout=timeout, check=False)


def test_command_reports_in_every_form(tmp_path: Path) -> None:
    junit, page = tmp_path / "conform.xml", tmp_path / "conform.html"
    with FakeTarget(name=b"<b>Fake & Co</b>") as target:
        result = conform(target.address, "--only", "encap,router", "--json", "--junit", str(junit),
                         "--html", str(page))
    assert result.returncode == 0, result.stdout + result.stderr
    report = json.loads(result.stdout)
    assert report["passed"] is True and report["counts"]["fail"] == 0
    assert {c["id"] for c in report["checks"]} == {i for i in check_ids() if i.startswith(("encap.", "router."))}
    first = report["checks"][0]
    assert set(first) >= {"id", "group", "verdict", "expected", "reference", "observed", "exchanges"}
    assert bytes.fromhex(first["exchanges"][0]["sent"])[:2] == b"\x65\x00"  # RegisterSession, as sent
    suites = ElementTree.parse(junit).getroot()
    assert int(suites.get("tests", "0")) == len(report["checks"]) and suites.get("failures") == "0"
    text = page.read_text()
    assert "<b>Fake" not in text and "&lt;b&gt;Fake &amp; Co&lt;/b&gt;" in text
    assert "<script" not in text and "http" not in text.replace("http-equiv", "")  # one self-contained page


def test_command_text_report_puts_failures_first_with_their_bytes() -> None:
    with FakeTarget(deviation="router.unknown_attribute") as target:
        result = conform(target.address, "--only", "router")
    assert result.returncode == 1, result.stdout + result.stderr
    lines = result.stdout.splitlines()
    assert lines[1].startswith("11 checks: 10 pass, 1 fail")
    assert "Message router and errors (router)" in lines[2]
    failures = lines.index("Failures")
    assert lines[failures + 1] == "  FAIL router.unknown_attribute: Get_Attribute_Single of Identity attribute 0xFE"
    assert any(line.strip().startswith("sent (tcp):") and "0e 03 20 01 24 01 30 fe" in line
               for line in lines[failures:])
    table = lines.index("Message router and errors")
    assert lines[table + 1].split()[:2] == ["fail", "router.unknown_attribute"]


def test_html_report_has_a_linked_summary_per_group_failures_and_warnings_first(tmp_path: Path) -> None:
    page, junit = tmp_path / "conform.html", tmp_path / "conform.xml"
    eds = Path(__file__).with_name("fake_device.eds")
    with FakeTarget(deviation="cm.forward_open.duplicate", variant="warn:cm.forward_open.consuming_point") as target:
        result = conform(target.address, "--eds", str(eds), "--only", "router,cm", "--html", str(page),
                         "--junit", str(junit), "--timeout", "2")
    assert result.returncode == 1, result.stdout + result.stderr
    text = page.read_text()
    # The summary: a row per group with its counts, linked to the group's table.
    assert '<a href="#group-cm">Connection Manager</a>' in text and 'id="group-cm"' in text
    assert '<a href="#group-router">' in text and '<a href="#group-final">' in text
    # Failures, then warnings, listed before the tables, each linked to its row.
    failures, warnings, tables = text.index('id="fails"'), text.index('id="warnings"'), text.index('id="group-router"')
    assert failures < warnings < tables
    assert '<a href="#check-cm.forward_open.duplicate">' in text and 'id="check-cm.forward_open.duplicate"' in text
    # In a group's table, the failure comes first, the warning next.
    cm = text[text.index('id="group-cm"'):]
    assert cm.index('id="check-cm.forward_open.duplicate"') < cm.index('id="check-cm.forward_open.consuming_point"') \
        < cm.index('id="check-cm.forward_open.accepted"')
    # Rows are short: the bytes are folded away, ids never break, the reference is a citation.
    assert text.count("<details>") >= text.count('<tr class="pass"') and "break-all" not in text
    assert '<code class="id">' in text and "code.id { white-space: nowrap; }" in text and "<cite>" in text
    # JUnit: the warning is a skipped test case with its message; the failure a failure.
    cases = {c.get("name"): c for c in ElementTree.parse(junit).getroot().iter("testcase")}
    skipped = cases["cm.forward_open.consuming_point"].find("skipped")
    assert skipped is not None and skipped.get("message", "").startswith("warning: ")
    assert cases["cm.forward_open.duplicate"].find("failure") is not None


def test_strict_makes_a_warning_a_failure(tmp_path: Path) -> None:
    junit = tmp_path / "conform.xml"
    eds = Path(__file__).with_name("fake_device.eds")
    with FakeTarget(variant="warn:cm.forward_open.consuming_point") as target:
        lenient = conform(target.address, "--eds", str(eds), "--only", "cm", "--timeout", "2")
        strict = conform(target.address, "--eds", str(eds), "--only", "cm", "--strict", "--junit", str(junit),
                         "--timeout", "2")
    assert (lenient.returncode, strict.returncode) == (0, 1), lenient.stdout + strict.stdout
    case = next(c for c in ElementTree.parse(junit).getroot().iter("testcase")
                if c.get("name") == "cm.forward_open.consuming_point")
    failure = case.find("failure")
    assert failure is not None and failure.get("message", "").startswith("warning (--strict): ")


def test_text_report_has_one_summary_line_per_group() -> None:
    with FakeTarget(deviation="router.unknown_attribute") as target:
        result = conform(target.address, "--only", "encap,router")
    lines = result.stdout.splitlines()
    assert lines[2].split() == ["Encapsulation", "(encap)", "16", "checks:", "15", "pass,", "0", "fail,", "0",
                                "warning,", "0", "n/a,", "1", "not", "run"]
    assert lines[3].split()[:4] == ["Message", "router", "and", "errors"] and "1 fail" in lines[3]


def _garbage_server(reply: bytes) -> tuple[socket.socket, threading.Thread]:
    listener = socket.socket()
    listener.bind((HOST, 0))
    listener.listen(1)

    def serve() -> None:
        conn, _ = listener.accept()
        with conn:
            conn.recv(1024)
            conn.sendall(reply)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    return listener, thread


@pytest.mark.parametrize("args", [
    ["--only", "encap,bogus"], ["--eds", "/nonexistent.eds"], ["--timeout", "0"], ["--eds-dir", "/nonexistent"],
    ["--connection-points", "150"], ["--connection-points", "150,x"],
], ids=["unknown-group", "missing-eds", "zero-timeout", "missing-eds-dir", "one-point", "not-a-number"])
def test_command_bad_arguments_exit_2_in_one_line(args: list[str]) -> None:
    result = conform("127.0.0.1:1", *args)
    assert (result.returncode, result.stdout) == (2, "")
    assert one_line_error(result).startswith("cipstack conform: ")


def test_command_unreachable_or_not_enip_exits_2_in_one_line() -> None:
    result = conform(f"127.0.0.1:{free_port()}")
    assert (result.returncode, result.stdout) == (2, "")
    assert one_line_error(result).startswith("cipstack conform: cannot connect to 127.0.0.1:")
    listener, thread = _garbage_server(b"HTTP/1.0 400 Bad Request\r\n\r\n")
    with listener:
        result = conform(f"127.0.0.1:{listener.getsockname()[1]}", "--timeout", "1")
        thread.join(5)
    assert (result.returncode, result.stdout) == (2, "")
    assert "not an EtherNet/IP target" in one_line_error(result)


def test_library_raises_target_unreachable() -> None:
    with pytest.raises(TargetUnreachable):
        run("127.0.0.1", free_port(), timeout=1.0)


def test_command_help_has_a_description_and_an_example() -> None:
    result = subprocess.run([sys.executable, "-m", "cipstack", "conform", "--help"], capture_output=True, text=True,
                            timeout=30, check=True)
    text = " ".join(result.stdout.split())
    assert "Exit status 0 when no check fails, 1 when one fails, 2 for bad arguments" in text
    assert "examples: cipstack conform 127.0.0.1 " in text


def test_safe_by_default_no_write_no_reset() -> None:
    with FakeTarget() as target:
        report = run(target.host, target.port, groups="objects")
        sent = [e.sent for o in report for e in o.exchanges]
    verdicts = {o.id: o.verdict for o in report}
    assert verdicts["objects.identity.reset"] is Verdict.NOT_RUN
    assert verdicts["objects.identity.set_read_only"] is Verdict.NOT_RUN
    # No Set_Attribute_Single (0x10) and no Reset (0x05) in any request sent.
    requests = [raw[40:] for raw in sent if raw[:2] == b"\x6f\x00"]
    assert not any(r[:1] in (b"\x10", b"\x05") for r in requests)


def test_every_connection_opened_is_closed(adapter_with: AdapterStarter, tmp_path: Path) -> None:
    """After the whole battery, the target holds no connection: each was closed, on every path."""
    eds = generate_eds(["--profile", "acg"], tmp_path / "eds")
    peer = adapter_with()
    run(peer.host, peer.port, eds=eds, groups="cm,class1,eds")
    status = subprocess.run(python_module("cipstack", "drive", "status", "--host", peer.host, "--port",
                                          str(peer.port), "--json"), capture_output=True, text=True, timeout=30)
    assert status.returncode == 0, status.stderr
    record = json.loads(status.stdout.splitlines()[-1])
    assert (record["class1_connections"], record["class3_connections"], record["io_connections"]) == (0, 0, 0), record


def test_a_check_an_option_was_not_given_for_is_not_run_in_every_form(tmp_path: Path) -> None:
    """Identity Reset and the set of a read-only attribute need --allow-reset and --allow-writes: without
    them they are "not run", apart from the checks the target does not offer (n/a)."""
    junit, page = tmp_path / "conform.xml", tmp_path / "conform.html"
    with FakeTarget() as target:
        result = conform(target.address, "--only", "objects", "--json", "--junit", str(junit), "--html", str(page))
        text = conform(target.address, "--only", "objects")
    assert result.returncode == 0, result.stdout + result.stderr
    report = json.loads(result.stdout)
    verdicts = {c["id"]: (c["verdict"], c["observed"]) for c in report["checks"]}
    assert verdicts["objects.identity.reset"] == ("not run", "needs --allow-reset")
    assert verdicts["objects.identity.set_read_only"] == ("not run", "needs --allow-writes")
    assert report["counts"]["not run"] == 2 and report["counts"]["n/a"] == sum(
        v == "n/a" for v, _ in verdicts.values())
    cases = {c.get("name"): c for c in ElementTree.parse(junit).getroot().iter("testcase")}
    skipped = cases["objects.identity.reset"].find("skipped")
    assert skipped is not None and skipped.get("message") == "needs --allow-reset"
    assert "<th>not run</th>" in page.read_text()
    assert "  not run objects.identity.reset" in text.stdout and ", 2 not run" in text.stdout.splitlines()[1]
