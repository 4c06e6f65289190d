"""``cipstack eds check`` and ``cipstack eds show``, run through argparse as the command runs them."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest

from cipstack.eds.commands import add_check_arguments, add_show_arguments, run_check, run_show

from .samples import ACG_IDENTITY, ADAPTER_EDS, MESSY_EDS


def parser() -> argparse.ArgumentParser:
    """The shape the cipstack command gives them: ``eds check`` and ``eds show``."""
    top = argparse.ArgumentParser(prog="cipstack")
    commands = top.add_subparsers(dest="command", required=True)
    eds = commands.add_parser("eds").add_subparsers(dest="eds_command", required=True)
    check = eds.add_parser("check")
    add_check_arguments(check)
    check.set_defaults(run=run_check)
    show = eds.add_parser("show")
    add_show_arguments(show)
    show.set_defaults(run=run_show)
    return top


def run(*argv: str) -> int:
    args = parser().parse_args(["eds", *argv])
    return args.run(args)


@pytest.fixture
def good(tmp_path: Path) -> Path:
    path = tmp_path / "acg.eds"
    path.write_text(ADAPTER_EDS, encoding="ascii")
    return path


@pytest.fixture
def bad(tmp_path: Path) -> Path:
    path = tmp_path / "bad.eds"
    path.write_text(ADAPTER_EDS.replace("0xCA, 4,", "0xCA, 2,").replace("0, 7, 1,", "0, 300, 1,"), encoding="ascii")
    return path


def line_of(snippet: str, text: str) -> int:
    return text[: text.index(snippet)].count("\n") + 1


def test_clean_file(good: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert run("check", str(good)) == 0
    assert capsys.readouterr() == ("1 file: 0 errors, 0 warnings\n", "")


def test_findings_printed_and_exit_1(bad: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert run("check", str(bad)) == 1
    out, err = capsys.readouterr()
    text = bad.read_text()
    assert out.splitlines() == [
        f"{bad}:{line_of('0, 300, 1,', text)}: warning value-range: "
        "Param7 field 11 (300) is outside USINT range 0..255",
        f"{bad}:{line_of('0xCA, 2,', text)}: error data-size: Param8 is a REAL of 4 bytes, not 2",
        "1 file: 1 error, 1 warning",
    ]
    assert err == ""


def test_warnings_alone_exit_0(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "warn.eds"
    path.write_text(ADAPTER_EDS.replace("Class1 = EtherNetIP;", "Class1 = Profibus;"))
    assert run("check", str(path)) == 0
    out = capsys.readouterr().out
    assert "warning device-classification" in out and out.endswith("1 file: 0 errors, 1 warning\n")
    # --strict: a warning fails the check.
    assert run("check", "--strict", str(path)) == 1
    assert capsys.readouterr().out.endswith("1 file: 0 errors, 1 warning\n")


def test_json_lines(bad: Path, good: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """One object per file, clean files too, then one summary object."""
    assert run("check", "--json", str(good), str(bad)) == 1
    records = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert len(records) == 3
    clean, found, summary = records
    assert clean == {"file": str(good), "readable": True, "errors": 0, "warnings": 0, "notes": 0, "findings": []}
    assert (found["file"], found["errors"], found["warnings"]) == (str(bad), 1, 1)
    assert [(record["rule"], record["severity"]) for record in found["findings"]] == [
        ("value-range", "warning"), ("data-size", "error"),
    ]
    assert set(found["findings"][0]) == {"line", "rule", "severity", "message"}
    assert found["findings"][1]["line"] == line_of("0xCA, 2,", bad.read_text())
    assert summary == {"summary": {"files": 2, "errors": 1, "warnings": 1, "notes": 0, "unreadable": 0,
                                   "strict": False}}


def test_identity_from_a_live_device(good: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = parser().parse_args(["eds", "check", str(good)])
    assert run_check(args, identity=ACG_IDENTITY) == 0
    assert run_check(args, identity={**ACG_IDENTITY, "product_code": 101}) == 1
    out = capsys.readouterr().out
    line = line_of("ProdCode", ADAPTER_EDS)
    assert out == ("1 file: 0 errors, 0 warnings\n"
                   f"{good}:{line}: error device-identity: ProdCode is 100 but the device reports 101\n"
                   "1 file: 1 error, 0 warnings\n")


def test_unreadable_file_is_one_line_and_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    missing = tmp_path / "missing.eds"
    assert run("check", str(missing)) == 2
    out, err = capsys.readouterr()
    assert out == "1 file: 0 errors, 0 warnings, 1 unreadable\n"
    assert err == f"cipstack eds check: {missing}: cannot read: No such file or directory\n"


def test_directory_is_unreadable(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert run("check", str(tmp_path)) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and "Traceback" not in err


def test_syntax_error_is_one_line_and_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "broken.eds"
    path.write_bytes(b'[File]\r\nDescText = "no end\r\n')
    assert run("check", str(path)) == 2
    assert capsys.readouterr().err == f"{path}:2: syntax error: string not closed on the line it starts\n"


def test_binary_garbage(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "garbage.eds"
    path.write_bytes(bytes(range(256)) * 4)
    assert run("check", str(path)) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"{path}:1: syntax error: ") and err.count("\n") == 1


def test_several_files_worst_status_wins(
    good: Path, bad: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert run("check", str(good), str(bad)) == 1
    assert run("check", str(tmp_path / "none.eds"), str(bad)) == 2
    out, err = capsys.readouterr()
    # The readable file is still checked after the unreadable one.
    assert out.count(f"{bad}:") == 4
    assert err.count("\n") == 1


def test_latin1_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "messy.eds"
    path.write_bytes(MESSY_EDS)
    assert run("check", str(path)) == 0
    assert run("show", str(path)) == 0
    assert "Soci\xe9t\xe9 Exemple" in capsys.readouterr().out


def test_show(good: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert run("show", str(good)) == 0
    out = capsys.readouterr().out
    assert "Device: CENT (ACG-ET2), revision 1.1\n" in out
    assert "  vendor 259 Example Drives\n  device type 2 AC Drive\n  product code 100\n" in out
    assert "Network: EtherNetIP\n" in out
    assert (
        "  Assem21 'Extended Speed Control Output': 4 bytes, path 20 04 24 15 30 03\n"
        "      16 bits  Param1 'Control Word'\n"
        "      16 bits  Param2 'Speed Reference'\n"
    ) in out
    assert (
        "  Connection1 'Exclusive Owner' (exclusive owner), path 20 04 24 01 2C 15 2C 47\n"
        "    O->T: 4 bytes, Assem21, point-to-point, run/idle header, RPI Param9\n"
        "    T->O: 4 bytes, Assem71, multicast/point-to-point, modeless, RPI Param9\n"
    ) in out
    assert "  Connection3 'Listen Only' (listen only), path 20 04 24 01 2C C7 2C 47\n" in out
    assert "    O->T: 0 bytes, Assem199, point-to-point, heartbeat, RPI Param9\n" in out


def test_show_json(good: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert run("show", "--json", str(good)) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["identity"] == {
        "vendor_id": 259, "vendor_name": "Example Drives", "device_type": 2, "device_type_name": "AC Drive",
        "product_code": 100, "product_name": "CENT", "catalog": "ACG-ET2", "revision": "1.1",
    }
    assert summary["networks"] == ["EtherNetIP"]
    assembly = {item["keyword"]: item for item in summary["assemblies"]}["Assem71"]
    assert assembly["size"] == 4 and assembly["path"] == "20 04 24 47 30 03"
    assert assembly["members"] == [
        {"bits": 16, "reference": "Param3", "name": "Status Word"},
        {"bits": 16, "reference": "Param4", "name": "Speed Actual"},
    ]
    connection = summary["connections"][1]
    assert connection["name"] == "Input Only"
    assert connection["types"] == ["input only"]
    assert connection["triggers"] == ["cyclic"]
    assert connection["transport_classes"] == [1]
    assert connection["o_to_t"] == {
        "rpi": "Param9", "size": 0, "assembly": "Assem198", "connection_types": ["point-to-point"],
        "format": "heartbeat",
    }
    assert connection["t_to_o"]["size"] == 4
    assert connection["path"] == "20 04 24 01 2C C6 2C 47"


def test_show_member_size_from_the_parameter(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "sizes.eds"
    path.write_text(ADAPTER_EDS.replace("16, Param3,", ", Param3,"))
    assert run("show", "--json", str(path)) == 0
    summary = json.loads(capsys.readouterr().out)
    members = {item["keyword"]: item for item in summary["assemblies"]}["Assem71"]["members"]
    assert members[0] == {"bits": 16, "reference": "Param3", "name": "Status Word"}


def test_show_unreadable(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert run("show", str(tmp_path / "none.eds")) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.startswith("cipstack eds show: ") and err.count("\n") == 1


def test_show_lists_assemblies_only_and_the_sizes_the_file_determines() -> None:
    """[Assembly] also holds the Assembly class's keywords (EZ-EDS writes them): they are not
    assemblies. A connection whose size field is empty or a ParamN has the size the file gives
    (the parameter's default, else the assembly's size), not '?'."""
    from cipstack.eds.commands import summarize
    from cipstack.eds.reader import parse_eds

    text = """\
[File] DescText = "x"; CreateDate = 01-01-2025; CreateTime = 00:00:00; Revision = 1.0;
[Device] VendCode = 1; VendName = "v"; ProdType = 12; ProdTypeStr = "t"; ProdCode = 1; MajRev = 1; MinRev = 1;
  ProdName = "p";
[Device Classification] Class1 = EtherNetIP;
[Params]
  Param1 = 0, , , 0x0000, 0xC7, 2, "Output size", "", "", 0, 64, 8, , , , , , , , , , , ;
[Assembly]
  Revision = 2;
  Object_Name = "Assembly Object";
  Object_Class_Code = 0x04;
  Number_Of_Static_Instances = 2;
  Assem100 = "Input", "", 32, 0x0000, , ;
  Assem150 = "Output", "", 8, 0x0000, , ;
[Connection Manager]
  Object_Name = "Connection Manager Object";
  Connection1 = 0x04010002, 0x44640405, , Param1, Assem150, , , Assem100, , , , ,
    "Exclusive Owner", "", "20 04 24 97 2C 96 2C 64";
"""
    summary = summarize(parse_eds(text))
    assert [assembly["keyword"] for assembly in summary["assemblies"]] == ["Assem100", "Assem150"]
    (connection,) = summary["connections"]
    assert connection["o_to_t"]["size"] == 8 and connection["t_to_o"]["size"] == 32


def test_show_reads_an_unquoted_path_and_says_so(tmp_path: Path) -> None:
    import subprocess
    import sys

    path = tmp_path / "unquoted.eds"
    path.write_text('[File] DescText = "x"; CreateDate = 01-01-2025; CreateTime = 00:00:00; Revision = 1.0;\n'
                    '[Device] VendCode = 1; VendName = "v"; ProdType = 12; ProdTypeStr = "t"; ProdCode = 1;\n'
                    '  MajRev = 1; MinRev = 1; ProdName = "p";\n'
                    "[Device Classification] Class1 = EtherNetIP;\n"
                    '[Port] Port1 = TCP, "A", 20 66 24 01, 2;\n', encoding="latin-1")
    result = subprocess.run([sys.executable, "-m", "cipstack", "eds", "show", str(path)], capture_output=True,
                            text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert result.stderr.splitlines() == [f'{path}:5: warning: Port1: unquoted value 20 66 24 01 read as the path '
                                          '"20 66 24 01"']
    assert "Device: p" in result.stdout
