"""The corpus (tests/eds/files) as a whole: what share of its class 1 connections is served, every
true error planted into its files is found (and nothing else), and what a file forbids is refused
at start with its reason.

Zero false alarms on the files as written is ``test_eds_field_files``'s
``test_eds_check_finds_no_error_and_the_expected_warnings``; that every offered connection opens
and exchanges data with ``cipstack io --eds`` is its ``test_each_offered_connection_runs_with_cipstack_io``.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from cipstack.cip.router import RequestContext
from cipstack.cip.status import CipError
from cipstack.eds.checker import check_eds
from cipstack.eds.emulated_device import build_eds_device
from cipstack.eds.reader import parse_eds, read_eds
from cipstack.eip.io_core import decode_io_datagram, encode_io_datagram
from cipstack.eip.originator.io_originator import class1_path
from cipstack.eip.target.io_target import IoTarget
from cipstack.eip.wire.cm_messages import (
    ConnectionTriad,
    ConnectionType,
    ForwardOpenRequest,
    NetworkParameters,
    TransportTrigger,
    TriggerType,
)

from .test_eds_field_files import EXPECTED, FILES

DIRECTORY = Path(__file__).parent / "files"
CLASS_1 = 1 << 1


def _declared_class_1(path: Path) -> list[str]:
    """The ConnectionN of a file whose transport (field 1 bits 0-15) includes class 1."""
    section = read_eds(path).get("Connection Manager")
    return [entry.keyword for entry in section or ()
            if re.fullmatch(r"Connection[0-9]+", entry.keyword) and isinstance(entry.value(1), int)
            and entry.value(1) & CLASS_1]


def test_at_least_95_percent_of_the_declared_class_1_connections_are_offered() -> None:
    """Across the corpus, the class 1 connections `adapter --eds` offers (each then opened and run
    by `cipstack io --eds` in test_eds_field_files) over those the files declare; every one not
    offered is explained in exactly one line of what the adapter prints."""
    declared = offered = 0
    for path in FILES:
        connections = _declared_class_1(path)
        issues = [issue.message for issue in build_eds_device(read_eds(path)).issues]
        for keyword in connections:
            number = int(keyword[len("Connection"):])
            explained = [m for m in issues if re.match(rf"{keyword}\b", m)]
            if number in EXPECTED[path.name].offered:
                assert explained == [], (path.name, keyword, explained)
                offered += 1
            else:
                assert len(explained) == 1, (path.name, keyword, explained)
            declared += 1
    assert declared >= 120
    share = offered / declared
    assert share >= 0.95, f"{offered} of {declared} class 1 connections offered ({100 * share:.1f} %)"
    docs = (Path(__file__).parents[2] / "docs" / "eds.md").read_text(encoding="utf-8")
    assert f"the adapter offers {offered} of the {declared} class 1 connections" in docs


# -- true errors planted into the corpus: each found, nothing else -------------------------------------------

#: (file, text replaced, replacement, the errors expected as (rule, snippet of their line)).
PLANTED = [
    ("hand_utf8_distance_sensor.eds", '"Distance Only", "20 04 24 65 30 03", 4,',
     '"Distance Only", "20 04 24 65 30 03", 6,',
     [("assembly-size", '"Distance Only"'), ("connection-size", "Param1,4,Assem101")]),
    ("vendor_modular_coupler.eds", "0x44640405,Param1,4,AssemExa150", "0x44640405,Param1,6,AssemExa150",
     [("connection-size", "Param1,6,AssemExa150")]),
    ("vendor_plc_generic_adapter.eds", "0x01010002,0x44240305", "0x01010002,0x44440305",
     [("connection-format", "0x44440305")]),
    ("ez_style_safety_format5.eds", "0x44245505,", "0x44246505,", [("connection-format", "0x44246505")]),
    ("vendor_modular_coupler.eds", 'Assem1 = "Slot 1 DI8 Input",,1,0x0000,,,8,Param11;',
     'Assem1 = "Slot 1 DI8 Input",,1,0x0000,,,8,AssemExa100;',
     [("assembly-member", "Assem1 ="), ("assembly-member", "AssemExa100 =")]),
    ("vendor_plc_generic_adapter.eds", "Param1,Param10,,", "Param1,Param19,,", [("param-reference", "Param19")]),
    ("vendor_drive_own_data.eds", '0x0000, 0xC7, 2, "Accel Time"', '0x0000, 0xC7, 4, "Accel Time"',
     [("data-size", '"Accel Time"')]),
    ("vendor_iolink_master_8port.eds", "AssemExa111,,,,,\"Port 1 Owner\"", "AssemExa119,,,,,\"Port 1 Owner\"",
     [("assembly-reference", "AssemExa119")]),
    ("vendor_drive_own_data.eds", "0x01010002, 0x44240305, Param1, 0, , Param1, 4, Assem70",
     "0x01010002, 0x44440305, Param1, 0, , Param1, 4, Assem70", [("connection-format", "0x44440305")]),
]


def _text(name: str) -> str:
    return (DIRECTORY / name).read_bytes().decode("latin-1")


def _line(text: str, snippet: str) -> int:
    assert text.count(snippet) == 1, f"{snippet!r} is not unique"
    return text[: text.index(snippet)].count("\n") + 1


@pytest.mark.parametrize(("name", "old", "new", "errors"), PLANTED,
                         ids=[f"{p[0]}:{p[3][0][0]}" for p in PLANTED])
def test_a_planted_error_is_found_and_nothing_else(name: str, old: str, new: str,
                                                   errors: list[tuple[str, str]]) -> None:
    text = _text(name)
    assert text.count(old) == 1, old
    planted = text.replace(old, new)
    before = [(f.rule, f.line) for f in check_eds(parse_eds(text)) if f.severity == "error"]
    after = sorted((f.rule, f.line) for f in check_eds(parse_eds(planted)) if f.severity == "error")
    assert before == []
    assert after == sorted((rule, _line(planted, snippet)) for rule, snippet in errors)


def test_format_5_on_a_connection_that_is_not_safety_is_a_warning() -> None:
    text = _text("vendor_drive_own_data.eds")
    planted = text.replace("0x04010002, 0x44640405, Param1, 8, Assem100", "0x04010002, 0x44640505, Param1, 8, Assem100")
    findings = [(f.rule, f.severity, f.line) for f in check_eds(parse_eds(planted))]
    assert findings == [("connection-format", "warning", _line(planted, "0x44640505"))]


def test_keyword_case_on_the_corpus_is_a_warning_only() -> None:
    text = _text("vendor_plc_generic_adapter.eds").replace("    Param10 = ", "    param10 = ")
    findings = [(f.rule, f.severity) for f in check_eds(parse_eds(text))]
    assert findings == [("keyword-case", "warning")]


# -- what a file forbids: refused at start, with the reason ---------------------------------------------------

def test_a_listen_only_connection_limited_to_point_to_point_is_refused_at_start() -> None:
    """The file allows Connection6 T->O point-to-point only: every Forward_Open of it would be refused
    (a listener receives its owner's multicast, 0x0108), so the adapter says so at start and offers
    the rest; `eds check` reports the same construct as an error (the file is wrong)."""
    text = _text("vendor_drive_own_data.eds")
    planted = text.replace("0x01010002, 0x44240305, Param1, 0, , Param1, 4, Assem70",
                           "0x01010002, 0x44440305, Param1, 0, , Param1, 4, Assem70")
    line = _line(planted, "Connection6 =")
    issues = [(i.line, i.message) for i in build_eds_device(parse_eds(planted)).issues]
    assert issues == [(line, "Connection6 (Listen Only Basic): listen only, but the file allows its T->O "
                             "point-to-point only (field 2 bits 20-23), and a listener receives its owner's "
                             "multicast: not offered")]


def test_a_listen_only_connection_without_a_multicast_owner_is_refused_at_start() -> None:
    text = _text("hand_utf8_distance_sensor.eds").encode("latin-1").decode("utf-8")
    # Every other connection producing Assem100 made point-to-point only: nothing to listen to.
    planted = text.replace('0x04010002, 0x44640305, Param1,0,, Param1,8,Assem100',
                           '0x04010002, 0x44440305, Param1,0,, Param1,8,Assem100').replace(
        '0x02010002, 0x44640305, Param1,0,, Param1,8,Assem100', '0x02010002, 0x44440305, Param1,0,, Param1,8,Assem100')
    issues = [i.message for i in build_eds_device(parse_eds(planted)).issues]
    assert issues == ["Connection4 (Listen Only): listen only, and no other connection of the file produces input "
                      "100 by multicast for it to listen to: not offered"]


# -- variable-size assemblies: a Forward_Open may ask less -----------------------------------------------------

def _forward_open(serial: int, path: bytes, ot_size: int, to_size: int, variable: bool) -> ForwardOpenRequest:
    return ForwardOpenRequest(
        0x0A, 0x0E, 0, 0xABCD0000 + serial, ConnectionTriad(serial, 0xFFFE, 7), 2,
        10_000, NetworkParameters(ot_size, ConnectionType.POINT_TO_POINT, variable=variable),
        10_000, NetworkParameters(to_size, ConnectionType.POINT_TO_POINT, variable=variable),
        TransportTrigger(1, TriggerType.CYCLIC), path)


def test_a_variable_size_assembly_is_served_at_its_default_size_and_a_forward_open_may_ask_less() -> None:
    """AssemExa103/153 of the IO-Link master are sized by Param11/Param13 (defaults 36 and 32 bytes):
    served at that size; a Forward_Open that says its sizes are variable may ask fewer bytes (the
    first ones are produced, and consumed with the rest zero); a fixed one of another size is refused."""
    device = build_eds_device(read_eds(DIRECTORY / "ez_style_iolink_master.eds"))
    profile = device.io_profile()
    assert profile is not None
    points = {**profile.consumed(), **profile.produced()}
    assert (points[103].size, points[153].size, points[103].variable) == (36, 32, True)
    target = IoTarget(profile, deliver=device.assembly.deliver)   # as the adapter makes it
    context = RequestContext(device.router, 0.0, "127.0.0.1:50000")
    with pytest.raises(CipError) as refused:
        target.forward_open(_forward_open(1, class1_path(153, 103, 1), 6 + 16, 2 + 20, variable=False), context)
    assert refused.value.extended[:1] == (0x0127,)
    reply = target.forward_open(_forward_open(2, class1_path(153, 103, 1), 6 + 16, 2 + 20, variable=True), context)
    datagrams = target.poll(1.0)
    assert datagrams and {len(decode_io_datagram(raw).payload) for raw, _ in datagrams} == {20}
    # 16 bytes of outputs arrive: the assembly holds them and zeros after.
    target.receive(encode_io_datagram(reply.ot_connection_id, 1, 1, bytes(range(1, 17)), run_idle=1),
                   ("127.0.0.1", 2222), 1.0)
    assert bytes(device.assembly.stores[153]) == bytes(range(1, 17)) + bytes(16)
