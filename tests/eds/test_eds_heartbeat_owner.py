"""A device emulated from an EDS file (`cipstack adapter --eds FILE`) whose exclusive owners write
O->T data while their T->O point is a heartbeat (198 or 254, size 0), as controllers declare their
"write data" connections (tests/eds/files/field_write_data_heartbeat.eds): the adapter offers them
without a word against them, an originator opens them and writes data the device receives, the
target produces packets of the sequence count alone, and the owner's watchdog holds while the
originator sends and times the connection out when it stops."""

from __future__ import annotations

import asyncio
import re
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import datetime
from pathlib import Path

import pytest

from cipstack import Scanner
from cipstack.cip.status import CipError, ExtendedStatus
from cipstack.eds.interpret import read_view
from cipstack.eds.reader import read_eds
from tests.ports import free_port
from tests.waiting import wait_for, wait_until

FILE = Path(__file__).parent / "files" / "field_write_data_heartbeat.eds"
#: The "write data" owners of the file: ConnectionN, its output assembly, its T->O heartbeat point.
WRITE_DATA = [(2, 151, 198), (5, 152, 254)]
#: RPI the tests run at (the file proposes 20 ms) and the timeout multiplier the originators are
#: given: a timeout of 20 ms x 4 x 2^4 = 1.28 s, which a stall of a loaded machine does not reach.
RPI_S = 0.020
MULTIPLIER = 4


@contextmanager
def adapter(tmp_path: Path) -> Iterator[tuple[str, int, Path]]:
    """`cipstack adapter --eds FILE` on loopback, its stderr (the log) in a file: (address, class 1
    UDP port, the log's path); terminated on exit."""
    port, io_port = free_port(), free_port()
    log = tmp_path / f"adapter-{port}.log"
    with log.open("w") as stderr:
        process = subprocess.Popen([sys.executable, "-m", "cipstack", "adapter", "--port", str(port), "--io-port",
                                    str(io_port), "--quiet", "--eds", str(FILE)],
                                   stdout=subprocess.DEVNULL, stderr=stderr, stdin=subprocess.DEVNULL)
    try:
        wait_for(lambda: "EtherNet/IP target listening" in log.read_text() or process.poll() is not None, 60,
                 "the adapter to listen")
        assert process.poll() is None, log.read_text()
        yield f"127.0.0.1:{port}", io_port, log
    finally:
        process.terminate()
        process.wait(10)


def _said(log: Path) -> list[str]:
    """What the adapter says about the file (its warnings), not its log lines."""
    return [line for line in log.read_text().splitlines() if line.startswith("cipstack adapter: ")]


def _timed_out(log: Path) -> list[float]:
    """When the log says a class 1 connection timed out (its time stamps, seconds since the epoch)."""
    out = []
    for line in log.read_text().splitlines():
        found = re.match(r"(\d{4}-\d\d-\d\d \d\d:\d\d:\d\d,\d{3}) INFO \S+: class 1 .* timed out$", line)
        if found:
            out.append(datetime.strptime(found[1], "%Y-%m-%d %H:%M:%S,%f").timestamp())
    return out


def test_the_file_declares_the_owners_as_controllers_do() -> None:
    """Read as a configuration tool reads it: two exclusive owners with O->T data whose T->O is a
    heartbeat point of size 0, the same points the input-only connections send their heartbeat to;
    the size field of Connection5 is a ParamN whose default is 0 (not "offered at 1 byte")."""
    view = read_view(read_eds(FILE))
    owners = [(c.number, c.o_t_point, c.t_o_point, c.t_o_size, c.t_o_heartbeat) for c in view.connections
              if c.kind == "exclusive owner"]
    assert owners == [(1, 150, 100, 32, False), (2, 151, 198, 0, True), (5, 152, 254, 0, True)]
    assert {c.o_t_point for c in view.connections if c.kind == "input only"} == {198, 254}
    assert view.issues == []
    assert read_eds(FILE).entry("Connection Manager", "Connection5").value(7) == "Param3"


def test_the_adapter_offers_them_and_says_nothing_against_them(tmp_path: Path) -> None:
    with adapter(tmp_path) as (_, _, log):
        pass
    assert _said(log) == []


@pytest.mark.parametrize(("number", "output", "heartbeat"), WRITE_DATA)
async def test_the_scanner_writes_data_the_device_receives(tmp_path: Path, number: int, output: int,
                                                           heartbeat: int) -> None:
    """`Scanner.io_connection_from_eds`: the Forward_Open asks T->O of 2 bytes (the sequence count);
    the data written O->T is in the output assembly; T->O packets come at the RPI with no data; a
    second owner of the same output is refused with 0x0106 while the first runs."""
    size = 16 if number == 2 else 8   # Assem151; Param2's default
    data = bytes(range(0xA1, 0xA1 + size))
    assert read_view(read_eds(FILE)).connection(number).t_o_point == heartbeat
    with adapter(tmp_path) as (address, io_port, log):
        scanner = await Scanner.connect(address)
        async with scanner, scanner.io_connection_from_eds(FILE, number, rpi=RPI_S, target_io_port=io_port,
                                                           timeout_multiplier=MULTIPLIER) as io:
            io.output.raw = data

            async def received() -> bytes:
                return (await scanner.get_attribute_single(0x04, output, 3)).data

            deadline = time.monotonic() + 10
            while await received() != data:
                assert time.monotonic() < deadline, f"assembly {output} holds {(await received()).hex()}"
                await asyncio.sleep(0.02)
            # Longer than a timeout (RPI x 4 x 2^multiplier = 1.28 s): the watchdog holds.
            before = io.stats.received
            await wait_until(lambda: io.stats.received >= before + 100, 30, "100 more T->O packets")
            assert not io.timed_out and io.input.raw == b""
            assert io.statistics()["wrong_size"] == 0
            with pytest.raises(CipError) as refused:
                async with scanner.io_connection_from_eds(FILE, number, rpi=RPI_S, target_io_port=io_port):
                    pass
            assert refused.value.extended[0] == ExtendedStatus.OWNERSHIP_CONFLICT
    assert _timed_out(log) == []


@pytest.mark.parametrize(("number", "output", "heartbeat"), WRITE_DATA)
def test_the_watchdog_times_out_when_the_originator_stops(tmp_path: Path, number: int, output: int,
                                                          heartbeat: int) -> None:
    """`cipstack io --eds FILE --connection N`, as a user runs it, stopped dead (SIGKILL: no
    Forward_Close): the device times the connection out (the log says so) once RPI x 4 x
    2^multiplier has passed without O->T data, and a new owner is accepted."""
    size = 16 if number == 2 else 8
    data = bytes(range(1, size + 1))
    assert read_view(read_eds(FILE)).connection(number).t_o_point == heartbeat
    with adapter(tmp_path) as (address, io_port, log):
        originator = subprocess.Popen(
            [sys.executable, "-m", "cipstack", "io", address, "--eds", str(FILE), "--connection", str(number),
             "--target-io-port", str(io_port), "--rpi", f"{RPI_S * 1e3:g}ms", "--timeout-multiplier",
             str(MULTIPLIER), "--duration", "120s", "--print", "summary", "--set", f"raw={data.hex()}"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, stdin=subprocess.DEVNULL)
        try:
            def written() -> bool:
                assert originator.poll() is None, "cipstack io exited"
                result = subprocess.run([sys.executable, "-m", "cipstack", "get", address, f"0x04/{output}/3"],
                                        capture_output=True, text=True, timeout=60)
                return result.stdout.strip() == "Data = " + data.hex(" ")

            wait_for(written, 60, f"assembly {output} to hold the data written", interval=0.2)
            assert _timed_out(log) == []
            stopped = time.time()
            originator.kill()
        finally:
            originator.kill()
            originator.wait(10)
        timeout = RPI_S * 4 * 2 ** MULTIPLIER
        wait_for(lambda: _timed_out(log), timeout + 20, "the connection to time out")
        (when,) = _timed_out(log)
        # The log's time stamps have milliseconds; the last O->T packet left before the kill, and the
        # connection ran until then.
        assert stopped - 0.01 < when < stopped + timeout + 10, (when - stopped, timeout)
        again = subprocess.run([sys.executable, "-m", "cipstack", "io", address, "--eds", str(FILE), "--connection",
                                str(number), "--target-io-port", str(io_port), "--duration", "1s", "--print",
                                "summary", "--set", f"raw={bytes(reversed(data)).hex()}"],
                               capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)
        assert again.returncode == 0, again.stderr
        # No input to change on a T->O without data: no warning that the target may not receive the outputs.
        assert "warning" not in again.stderr, again.stderr
        assert again.stdout.startswith("sent "), again.stdout
