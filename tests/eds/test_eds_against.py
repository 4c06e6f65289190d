"""`cipstack eds check FILE --against HOST`, as a user runs it, against the four emulators: the ACG
(Get_Attributes_All), the MX2 and the RX (which refuse it with 0x08: attribute by attribute), and a
device emulated from an EDS file (every connection opened); and a deliberately wrong file."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from tests.library_support import adapter_process

DIRECTORY = Path(__file__).parent / "files"


def run(*args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "cipstack", *args], capture_output=True, text=True,
                          timeout=timeout, stdin=subprocess.DEVNULL)


def check(path: Path, address: str, io_port: int, *more: str) -> tuple[int, dict, list[dict]]:
    """Exit status, the file's JSON object, its findings."""
    result = run("eds", "check", str(path), "--against", address, "--target-io-port", str(io_port), "--json", *more)
    assert "Traceback" not in result.stderr, result.stderr
    records = [json.loads(line) for line in result.stdout.splitlines()]
    assert records[-1]["summary"]["files"] == 1
    return result.returncode, records[0], records[0]["findings"]


def generated(tmp_path: Path, *args: str) -> Path:
    result = run("eds", "generate", *args, "-o", str(tmp_path))
    assert result.returncode == 0, result.stderr
    return Path(result.stdout.split()[0])


def test_against_the_acg_its_own_file_has_no_error(tmp_path: Path) -> None:
    """Identity by Get_Attributes_All, every parameter and assembly as the file says; the connections
    of the pairs the card does not serve now (it serves the pair its parameters select, and opened the
    file's connections of that pair) are its configuration: notes, no warning (issue 52, item 5)."""
    path = generated(tmp_path, "--profile", "acg")
    with adapter_process("--profile", "acg") as (address, io_port):
        status, record, findings = check(path, address, io_port)
    assert status == 0
    assert record["against"].startswith(f"against {address}: identity by Get_Attributes_All, ")
    assert record["errors"] == 0
    assert {f["rule"] for f in findings} == {"live-connection"}
    assert all("does not offer this path now" in f["message"] for f in findings if f["severity"] == "warning")
    assert record["warnings"] == 0
    # A listener of a pair not served has no owner to listen to, and the other pairs' owners and
    # input-only connections are refused while the pair served opened: noted, not an error.
    assert all("listen only, and nothing produces input" in f["message"]
               or "not accepted in the device's present configuration, which accepts Connection1" in f["message"]
               or "not accepted in the device's present configuration, which accepts Connection13" in f["message"]
               for f in findings if f["severity"] == "info")
    assert "3 of 36 class 1 connections opened and closed" in record["against"]


def test_against_the_mx2_identity_attribute_by_attribute(tmp_path: Path) -> None:
    """The MX2 refuses Get_Attributes_All (0x08): noted, and Identity read with Get_Attribute_Single.
    What differs is real: the generated file declares the RX's input terminal 8 and FW terminal
    (Discrete Input Point instances 8 and 9) that the MX2, with 7 inputs, does not have."""
    path = generated(tmp_path, "--profile", "mx2", "--model", "MX2-A2004-E")
    with adapter_process("--profile", "mx2", "--model", "MX2-A2004-E") as (address, io_port):
        status, record, findings = check(path, address, io_port)
    assert "identity by Get_Attribute_Single" in record["against"]
    assert [f["message"] for f in findings if f["rule"] == "live-refused"] == [
        "Identity Get_Attributes_All refused (0x08 (service not supported)): read attribute by attribute"]
    errors = [f for f in findings if f["severity"] == "error"]
    assert all(f["rule"] == "live-parameter" and (" at 0x08/8/" in f["message"] or " at 0x08/9/" in f["message"])
               for f in errors), errors
    assert status == (1 if errors else 0)
    assert not any(f["rule"] == "device-identity" for f in findings)


def test_against_the_rx_its_own_file_has_no_error(tmp_path: Path) -> None:
    path = generated(tmp_path, "--profile", "rx", "--model", "RX-A2004-E")
    with adapter_process("--profile", "rx", "--model", "RX-A2004-E") as (address, io_port):
        status, record, findings = check(path, address, io_port)
    assert status == 0 and record["errors"] == record["warnings"] == 0
    assert "identity by Get_Attribute_Single" in record["against"]
    assert [f["rule"] for f in findings] == ["live-refused"]


def test_against_an_eds_emulator_every_connection_opens() -> None:
    path = DIRECTORY / "vendor_drive_own_data.eds"
    with adapter_process("--eds", str(path)) as (address, io_port):
        status, record, findings = check(path, address, io_port)
    assert (status, findings) == (0, [])
    assert record["against"] == (f"against {address}: identity by Get_Attributes_All, 5 parameters read, "
                                 "6 assemblies sized, 7 of 7 class 1 connections opened and closed")


def test_a_deliberately_wrong_file_shows_each_difference(tmp_path: Path) -> None:
    """The file the EDS emulator serves, edited: another product code, a parameter of another type
    and size, an assembly of another size, a connection to a point the device does not have, and a
    parameter linked to an attribute it lacks. Each is one line; the text output ends with the summary."""
    original = (DIRECTORY / "vendor_drive_own_data.eds").read_bytes().decode("latin-1")
    edits = [("ProdCode = 400;", "ProdCode = 401;"),
             ('0x0000, 0xC7, 2, "Accel Time"', '0x0000, 0xC8, 4, "Accel Time"'),
             ('"Vendor Input", "20 04 24 96 30 03", 12,', '"Vendor Input", "20 04 24 96 30 03", 10,'),
             ('"20 04 24 01 2C 15 2C 47"', '"20 04 24 01 2C 16 2C 47"'),
             ('"20 64 24 01 30 05"', '"20 64 24 01 30 09"')]
    wrong = original
    for old, new in edits:
        assert old in wrong, old
        wrong = wrong.replace(old, new)
    wrong = wrong.replace("Param1, 12, Assem150", "Param1, 10, Assem150")
    path = tmp_path / "wrong.eds"
    path.write_bytes(wrong.encode("latin-1"))

    def line(snippet: str) -> int:
        return wrong[: wrong.index(snippet)].count("\n") + 1

    with adapter_process("--eds", str(DIRECTORY / "vendor_drive_own_data.eds")) as (address, io_port):
        status, _, findings = check(path, address, io_port)
        text = run("eds", "check", str(path), "--against", address, "--target-io-port", str(io_port))
    assert status == 1
    live = sorted((f["rule"], f["line"], f["message"]) for f in findings if f["rule"].startswith("live-"))
    assert live == sorted([
        ("live-parameter", line('"Accel Time"'),
         "Param4 (Accel Time) at 0x2A/1/18: the device answers 2 bytes; the file says a UDINT of 4"),
        ("live-parameter", line('"20 64 24 01 30 09"'),
         "Param6 (Heatsink Temp) at 0x64/1/9: the device has no such attribute (0x14 (attribute not supported))"),
        ("live-assembly", line('"Vendor Input"'), "Assem150 (Assembly instance 150) is 10 bytes in the file, "
                                                  "12 on the device"),
        ("live-connection", line("Connection2 ="), "Connection2 (Extended Speed Control): Forward_Open refused by "
                                                   "the device (0x01 (connection failure), extended 0x012A (invalid "
                                                   "consuming path))"),
        # The originator retries with the size the device names: the file's size is still wrong.
        ("live-connection", line("Connection3 ="), "Connection3 (Vendor Control): T->O size 12 refused (0x0128), "
                                                   "the target wants 14: retrying with 14"),
    ])
    identity = [(f["line"], f["message"]) for f in findings if f["rule"] == "device-identity"]
    assert identity == [(line("ProdCode = 401"), "ProdCode is 401 but the device reports 400")]
    lines = text.stdout.splitlines()
    assert lines[0].startswith(f"{path}: against {address}: identity by Get_Attributes_All")
    static = sorted((f["rule"], f["line"]) for f in findings if not f["rule"].startswith("live-")
                    and f["rule"] != "device-identity")
    # What the file says against itself, found without the device: the path that names another point.
    assert static == [("connection-path", line("Connection2 =") + 1)]
    assert lines[-1] == "1 file: 6 errors, 1 warning" and text.returncode == 1
    assert len(lines) == 1 + len(findings) + 1


# -- files from the field (issue 43, item 9) ------------------------------------------------------------------

def test_the_field_constructs_are_served_and_every_connection_opens() -> None:
    """An exclusive owner whose T->O point is a heartbeat, assemblies of empty size sized by their
    connections, points sized by a parameter that defaults to 0: `adapter --eds` serves each file,
    and `eds check --against` opens every connection it declares, with no error."""
    for name, connections in (("field_owner_heartbeat_input.eds", 2), ("field_modular_empty_size.eds", 2),
                              ("field_size_param_default_zero.eds", 1)):
        with adapter_process("--eds", str(DIRECTORY / name)) as (address, io_port):
            status, record, findings = check(DIRECTORY / name, address, io_port)
        assert status == 0 and record["errors"] == 0, findings
        assert f"{connections} of {connections} class 1 connections opened and closed" in record["against"]


def test_a_parameter_of_a_class_attribute_is_read(tmp_path: Path) -> None:
    """A ParamN linking a class attribute (instance 0) was skipped silently: it is read now. The
    emulator of the file serves it (at its default); a device without it is an error."""
    original = (DIRECTORY / "vendor_drive_own_data.eds").read_bytes().decode("latin-1")
    anchor = '    Param6 = 0, 6, "20 64 24 01 30 05"'
    assert anchor in original
    added = ('    Param7 = 0, 6, "20 64 24 00 30 08", 0x0010, 0xC7, 2, "Drive Count", "", "", 0, 16, 3, , , , , , , '
             ', , 0;\r\n')
    with_class = original.replace(anchor, added + anchor)
    path = tmp_path / "with_class_attribute.eds"
    path.write_bytes(with_class.encode("latin-1"))
    with adapter_process("--eds", str(path)) as (address, io_port):
        status, record, _ = check(path, address, io_port, "--no-connections")
    assert status == 0 and "6 parameters read" in record["against"]          # 5 of instances, 1 of the class
    with adapter_process("--eds", str(DIRECTORY / "vendor_drive_own_data.eds")) as (address, io_port):
        status, _, findings = check(path, address, io_port, "--no-connections")
    assert status == 1 and [f["message"] for f in findings if f["rule"] == "live-parameter"] == [
        "Param7 (Drive Count) at 0x64/0/8: the device has no such attribute (0x14 (attribute not supported))"]


def test_an_assembly_at_no_instance_is_noted_and_a_connection_not_openable_is_told_from_a_refusal() -> None:
    """Assemblies the file places at no instance were neither sized nor mentioned: a note says why.
    A connection the file declares so that it cannot be opened is said so (never sent), apart from
    the device's refusals."""
    path = DIRECTORY / "hand_valve_manifold.eds"
    with adapter_process("--eds", str(path)) as (address, io_port):
        _, _, findings = check(path, address, io_port)
    notes = [f["message"] for f in findings if f["rule"] == "live-assembly" and f["severity"] == "info"]
    assert notes == [
        "Assem110: not sized: it has no path and no connection names it, so nothing says which instance of the "
        "device it is",
        "Assem120: not sized: it has no path and no connection names it, so nothing says which instance of the "
        "device it is"]
    declared = sorted(f["message"] for f in findings if "cannot be opened as the file declares it" in f["message"])
    assert declared == [
        "Connection3: redundant owner connections are not supported: cannot be opened as the file declares it: "
        "not sent",
        "Connection5: path 20 04 24 01 2C 64 2C 65 80 01 0F 00 is not an assembly connection path: cannot be opened "
        "as the file declares it: not sent",
        "Connection6: path: path item [Param5] has no byte value as its default: cannot be opened as the file "
        "declares it: not sent"]
    refused = [f["message"].split(" (")[0] for f in findings if "Forward_Open refused by the device" in f["message"]]
    assert refused == ["Connection7", "Connection8", "Connection9"]
