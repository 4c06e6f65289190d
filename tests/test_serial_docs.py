"""docs/serial.md runs as written: its pymodbus example against the emulator its ``sh`` block starts
(the pty path it prints given to the script), with the output the page shows; its spec file gives
the station IDs the page says."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from cipstack.fleet.spec import assign, assign_stations, parse_addresses, read_spec_file
from tests.ports import free_port
from tests.test_rtu_live import cipstack

PAGE = Path(__file__).resolve().parents[1] / "docs" / "serial.md"
FENCE = re.compile(r"^```(\w+)\n(.*?)^```", re.S | re.M)

pytestmark = pytest.mark.interop


def blocks(language: str) -> list[str]:
    return [text for lang, text in FENCE.findall(PAGE.read_text(encoding="utf-8")) if lang == language]


def section(title: str) -> str:
    text = PAGE.read_text(encoding="utf-8")
    start = text.index(f"## {title}\n")
    end = text.find("\n## ", start + 1)
    return text[start:end if end >= 0 else None]


def test_the_pymodbus_example_runs_against_the_emulator_the_page_starts(tmp_path: Path) -> None:
    command = next(line for line in blocks("sh")[0].splitlines() if line.startswith("cipstack adapter"))
    example = FENCE.findall(section("pymodbus"))
    (_, script), (_, expected) = [b for b in example if b[0] in ("python", "text")]
    (tmp_path / "example.py").write_text(script)
    args = command.split()[2:]
    with cipstack("adapter", *args, "--port", str(free_port()), "--io-port", "0", "--quiet", "--state",
                  str(tmp_path / "acg.json"), "--control", str(tmp_path / "control.sock")) as path:
        result = subprocess.run([sys.executable, str(tmp_path / "example.py"), path], capture_output=True, text=True,
                                timeout=60)
    assert result.returncode == 0, result.stderr
    assert result.stdout == expected


def test_the_pages_spec_file_gives_the_station_ids_it_says(tmp_path: Path) -> None:
    (spec,) = blocks("toml")
    (tmp_path / "fleet.toml").write_text(spec)
    settings, groups = read_spec_file(tmp_path / "fleet.toml")
    assert settings["rtu"] == "pty"
    devices = assign_stations(assign(groups, parse_addresses(settings["addresses"]), None), workers=1)
    assert [(d.address, d.station) for d in devices] == [("127.0.0.61", 10), ("127.0.0.62", 11), ("127.0.0.63", 1)]
    assert all(d.params[-1] == f"CM.1={d.station}" for d in devices)
