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
from tests.test_docs import Namespace, _namespaces_available, emulator, sections
from tests.test_docs import shell_env as shell_env

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


@pytest.mark.docs
def test_the_pymodbus_example_prints_what_the_page_shows(shell_env: dict[str, str], tmp_path: Path) -> None:
    """The page's pymodbus section, as ``tests/test_docs.py`` runs it (its emulator, in a network
    namespace of its own), with the output the page shows."""
    reason = _namespaces_available()
    if reason:
        pytest.skip(reason)
    (section,) = [s for s in sections(PAGE.read_text(), "docs/serial.md") if s.title == "pymodbus"]
    script = next(b for b in section.blocks if b.language == "python")
    expected = next(b for b in section.blocks if b.language == "text")
    (tmp_path / "example.py").write_text(script.text)
    namespace = Namespace()
    try:
        with emulator(namespace, section.adapter, shell_env, tmp_path):
            result = subprocess.run(namespace.command([sys.executable, str(tmp_path / "example.py")]),
                                    capture_output=True, text=True, env=shell_env, cwd=tmp_path, timeout=60)
    finally:
        namespace.close()
    assert result.returncode == 0, result.stderr
    assert result.stdout == expected.text


def test_the_pages_spec_file_gives_the_station_ids_it_says(tmp_path: Path) -> None:
    (spec,) = blocks("toml")
    (tmp_path / "fleet.toml").write_text(spec)
    settings, groups = read_spec_file(tmp_path / "fleet.toml")
    assert settings["rtu"] == "pty"
    devices = assign_stations(assign(groups, parse_addresses(settings["addresses"]), None), workers=1)
    assert [(d.address, d.station) for d in devices] == [("127.0.0.61", 10), ("127.0.0.62", 11), ("127.0.0.63", 1)]
    assert all(d.params[-1] == f"CM.1={d.station}" for d in devices)
