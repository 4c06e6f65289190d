"""The test corpus of EDS files written in the styles the field ships (tests/eds/files/): for every
file with a [Connection Manager], `cipstack adapter --eds FILE` serves it and `cipstack io --eds FILE
--connection N` runs each connection it declares, as a user runs them."""

from __future__ import annotations

import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cipstack.eds.interpret import read_view
from cipstack.eds.reader import read_eds
from tests.ports import free_port

FILES = sorted((Path(__file__).parent / "files").glob("*.eds"))
CONNECTIONS = [(path, connection.number) for path in FILES if read_eds(path).get("Connection Manager")
               for connection in read_view(read_eds(path)).connections]


def test_the_corpus_offers_connections() -> None:
    assert CONNECTIONS, "no file of the corpus declares a class 1 connection"


def test_an_assembly_without_a_path_takes_the_instance_its_connection_path_names() -> None:
    view = read_view(read_eds(Path(__file__).parent / "files" / "ez_style_io_block.eds"))
    assert {k: (a.instance, a.size) for k, a in view.assemblies.items()} == {"Assem100": (100, 4),
                                                                             "Assem150": (150, 2)}
    assert view.issues == []


@pytest.fixture(scope="module")
def adapters() -> dict[Path, tuple[int, int, subprocess.Popen[str]]]:
    started: dict[Path, tuple[int, int, subprocess.Popen[str]]] = {}
    for path in {path for path, _ in CONNECTIONS}:
        port, io_port = free_port(), free_port()
        process = subprocess.Popen([sys.executable, "-m", "cipstack", "adapter", "--eds", str(path), "--port",
                                    str(port), "--io-port", str(io_port), "--quiet"],
                                   stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        for _ in range(300):
            try:
                socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
                break
            except OSError:
                assert process.poll() is None, process.stderr.read() if process.stderr else ""
                time.sleep(0.05)
        started[path] = (port, io_port, process)
    yield started
    for _, _, process in started.values():
        process.terminate()
        process.wait(10)


@pytest.mark.parametrize(("path", "number"), CONNECTIONS, ids=[f"{p.stem}-{n}" for p, n in CONNECTIONS])
def test_each_declared_connection_runs(adapters: dict[Path, tuple[int, int, subprocess.Popen[str]]], path: Path,
                                       number: int) -> None:
    port, io_port, _ = adapters[path]
    result = subprocess.run([sys.executable, "-m", "cipstack", "io", f"127.0.0.1:{port}", "--eds", str(path),
                             "--connection", str(number), "--rpi", "10ms", "--duration", "0.5s",
                             "--target-io-port", str(io_port), "--print", "summary"],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    stats = next(line for line in result.stdout.splitlines() if line.startswith("sent "))
    received = int(stats.split()[3])
    assert received > 10, stats


def test_list_fields_names_what_set_and_the_input_take(tmp_path: Path) -> None:
    """`cipstack io --eds F --connection N --list-fields` reads the file alone (no device needed)."""
    from cipstack.eds.generator import eds_text
    from cipstack.eds.profiles import acg_et2_description

    path = tmp_path / "acg.eds"
    path.write_text(eds_text(acg_et2_description()), encoding="latin-1")
    result = subprocess.run([sys.executable, "-m", "cipstack", "io", "127.0.0.1:1", "--eds", str(path),
                             "--connection", "1", "--list-fields"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert lines[0] == "output (O->T): assembly 21 'Extended Speed Control Output', 4 bytes"
    assert any(line.split()[:4] == ["speed_reference", "byte", "2", "INT"] for line in lines)
    assert "input (T->O): assembly 71 'Extended Speed Control Input', 4 bytes" in lines
