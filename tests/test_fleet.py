"""``cipstack fleet``: many emulated devices in one command, each on its own loopback address, run as
a real subprocess and talked to over real sockets: discovery finds each once, class 1 runs to several
at once, a trip or a saved parameter stays with its device, a taken address is one line, and the
devices spread over worker processes are all served and all stopped."""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from cipstack.cip.router import RequestContext
from cipstack.cli import main
from cipstack.devices.profiles import PROFILES, mac_for_address, serial_from_mac
from cipstack.eip.io_server import run_precise
from cipstack.eip.wire.cm_messages import ForwardOpenRequest
from cipstack.fleet.serve import DeviceSet, build_adapter
from cipstack.fleet.spec import (
    FleetDevice,
    Shard,
    SpecError,
    assign,
    describe_addresses,
    parse_addresses,
    parse_group,
    parse_shard,
    select_shard,
    shares,
)
from cipstack.scanner import Scanner, SyncScanner, discover
from tests.attacks import ACG_INPUT_ONLY_PATH, class1_open
from tests.ports import free_port, list_identity_replies
from tests.test_acg_live import SAVE_PARAMETERS, write_registers
from tests.waiting import wait_for, wait_until

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="any 127.x on loopback")

#: ListIdentity (0x0063), no data, sender context asking for replies within 500 ms.
BROADCAST = "127.255.255.255"


def addresses(block: int, count: int, first: int = 10) -> list[str]:
    """``count`` loopback addresses of a block of this file's own (127.77.BLOCK.x)."""
    return [f"127.77.{block}.{first + n}" for n in range(count)]


class Fleet:
    """A ``cipstack fleet`` subprocess, its output in files; ready once it says what it emulates."""

    def __init__(self, tmp_path: Path, *args: str, name: str = "fleet") -> None:
        self.out = tmp_path / f"{name}.out"
        self.err = tmp_path / f"{name}.err"
        with self.out.open("w") as out, self.err.open("w") as err:
            self.process = subprocess.Popen([sys.executable, "-m", "cipstack", "fleet", *args], stdout=out,
                                            stderr=err, stdin=subprocess.DEVNULL, cwd=tmp_path)

    def wait_ready(self, timeout: float = 30.0) -> list[str]:
        deadline = time.monotonic() + timeout
        while "emulating" not in self.err.read_text():
            if self.process.poll() is not None or time.monotonic() > deadline:
                self.kill()
                pytest.fail(f"the fleet did not start:\n{self.err.read_text()}")
            time.sleep(0.05)
        return self.out.read_text().splitlines()

    def stop(self, sig: int = signal.SIGINT) -> int:
        if self.process.poll() is None:
            self.process.send_signal(sig)
        try:
            return self.process.wait(30)
        except subprocess.TimeoutExpired:
            self.kill()
            raise

    def kill(self) -> None:
        for pid in children(self.process.pid):
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait(10)


@contextlib.contextmanager
def running(tmp_path: Path, *args: str, name: str = "fleet") -> Iterator[tuple[Fleet, list[str]]]:
    fleet = Fleet(tmp_path, *args, name=name)
    try:
        lines = fleet.wait_ready()
        yield fleet, lines
        assert fleet.stop() == 0, fleet.err.read_text()
    finally:
        fleet.kill()


def refused_fleet(tmp_path: Path, taken: tuple[str, int], *args: str) -> Fleet:
    """``cipstack fleet ARGS`` while another socket listens on TCP ``taken``: it must exit 2 and print
    nothing on stdout; its stderr is the caller's to judge."""
    holder = socket.socket()
    holder.bind(taken)
    holder.listen()
    try:
        fleet = Fleet(tmp_path, *args)
        try:
            assert fleet.process.wait(30) == 2
        finally:
            fleet.kill()
    finally:
        holder.close()
    assert fleet.out.read_text() == ""
    return fleet


def children(pid: int) -> list[int]:
    """The processes whose parent is ``pid`` (from /proc)."""
    found = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as stat:
                    if int(stat.read().rsplit(")", 1)[1].split()[1]) == pid:
                        found.append(int(entry))
            except (OSError, IndexError, ValueError):
                continue
    return found


def alive(pid: int) -> bool:
    """Whether ``pid`` has not ended. A process whose first thread has ended shows as a zombie while
    its other threads (a fleet worker's heartbeat thread) are still ending, and its parent cannot
    collect its exit status until they have: it has ended only once it is a zombie alone."""
    try:
        with open(f"/proc/{pid}/stat") as stat:
            if stat.read().rsplit(")", 1)[1].split()[0] != "Z":
                return True
        return len(os.listdir(f"/proc/{pid}/task")) > 1
    except OSError:
        return False


async def broadcast_replies(port: int, seconds: float = 1.2) -> list[str]:
    """The source address of each reply to one ListIdentity sent to loopback's broadcast address."""
    return [host for _, host in await list_identity_replies(BROADCAST, port, seconds)]


def drive(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "cipstack", "drive", *args], capture_output=True, text=True,
                          timeout=30, stdin=subprocess.DEVNULL)


def sort_key(address: str) -> int:
    return int(ipaddress.IPv4Address(address))


# -- the spec, without sockets ------------------------------------------------------------------------
def test_serial_numbers_derive_from_the_address() -> None:
    assert mac_for_address("127.0.0.10") == bytes.fromhex("02CA7F00000A")
    assert serial_from_mac(mac_for_address("127.0.0.10")) == 0x7F00000A
    assert serial_from_mac(mac_for_address("10.1.2.3")) == 0x0A010203


def test_groups_take_addresses_in_order() -> None:
    pool = parse_addresses("127.0.0.10-127.0.0.13,127.0.0.20")
    assert describe_addresses(pool) == "127.0.0.10-127.0.0.13,127.0.0.20"
    groups = [parse_group("acg*2"), parse_group("MX2-A2015-E*1@127.0.0.11"), parse_group("rx:RX-A4055-E*2")]
    devices = assign(groups, pool, Path("state"))
    assert [(d.address, d.profile, d.model) for d in devices] == [
        ("127.0.0.10", "acg", None), ("127.0.0.11", "mx2", "MX2-A2015-E"), ("127.0.0.12", "acg", None),
        ("127.0.0.13", "rx", "RX-A4055-E"), ("127.0.0.20", "rx", "RX-A4055-E")]
    assert devices[1].state_path == Path("state/127.0.0.11-mx2-MX2-A2015-E.json")
    assert [len(s) for s in shares(devices, 2)] == [3, 2]
    with pytest.raises(SpecError, match="already given"):
        assign([parse_group("acg*2@127.0.0.10"), parse_group("acg@127.0.0.11")], None, None)


def test_factory_fleet_keeps_no_state_file(tmp_path: Path) -> None:
    """`cipstack fleet --factory`: every device from factory settings, no state file read or written
    (the devices' saves last until the fleet stops); with --state-dir it is one line, exit 2."""
    from cipstack.cli import build_parser
    from cipstack.cli.fleet import _fleet_spec  # internals: the spec the line makes, before any device starts

    args = build_parser().parse_args(["fleet", "--addresses", "127.77.9.1-127.77.9.2", "--device", "acg*2",
                                      "--factory"])
    spec = _fleet_spec(args)
    assert spec.state_dir is None and [d.state_path for d in spec.devices] == [None, None]
    kept = _fleet_spec(build_parser().parse_args(["fleet", "--addresses", "127.77.9.1", "--device", "acg",
                                                  "--state-dir", str(tmp_path)]))
    assert kept.devices[0].state_path == tmp_path / "127.77.9.1-acg.json"
    assert main(["fleet", "--addresses", "127.77.9.1", "--device", "acg", "--factory", "--state-dir",
                 str(tmp_path)]) == 2


@pytest.mark.parametrize("count", [1, 2, 3, 7, 10])
def test_the_shards_of_a_plant_are_the_plant_once_in_address_order(count: int) -> None:
    pool = parse_addresses("10.0.0.10-10.0.0.19")
    groups = [parse_group("acg*6"), parse_group("mx2:MX2-A2015-E*4")]
    plant = assign(groups, pool, Path("state"))
    cut = [select_shard(plant, Shard(index, count)) for index in range(count)]
    assert [device for shard in cut for device in shard] == plant
    assert max(map(len, cut)) - min(map(len, cut)) <= 1
    # Computed again, from a spec assigned again (another pod reading the same ConfigMap): the same cut.
    again = [select_shard(assign(groups, pool, Path("state")), Shard(index, count)) for index in range(count)]
    assert again == cut


def test_a_shard_is_index_over_count_from_zero() -> None:
    assert parse_shard("0/3") == Shard(0, 3) and str(parse_shard(" 2/3 ")) == "2/3"
    for text in ("3/3", "-1/3", "1/0", "1", "1/3/4", ""):
        with pytest.raises(SpecError, match="not INDEX/COUNT"):
            parse_shard(text)


def test_list_addresses_prints_the_shard_of_a_spec_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    spec = tmp_path / "plant.toml"
    spec.write_text('addresses = "10.20.0.10-10.20.0.19"\n[[device]]\nprofile = "acg"\ncount = 7\n'
                    '[[device]]\nmodel = "MX2-A2015-E"\nfirst = "10.20.1.1"\n')
    printed = []
    for index in range(3):
        assert main(["fleet", "--spec", str(spec), "--shard", f"{index}/3", "--list-addresses"]) == 0
        printed.append(capsys.readouterr().out.split())
    assert printed == [["10.20.0.10", "10.20.0.11", "10.20.0.12"], ["10.20.0.13", "10.20.0.14", "10.20.0.15"],
                       ["10.20.0.16", "10.20.1.1"]]
    assert main(["fleet", "--spec", str(spec), "--list-addresses"]) == 0
    assert capsys.readouterr().out.split() == [a for shard in printed for a in shard]


BAD_SPECS = [
    (["--addresses", "127.77.9.1-127.77.9.4", "--device", "pump*2"], "unknown profile 'pump'"),
    (["--addresses", "127.77.9.4-127.77.9.1", "--device", "acg"], "the range 127.77.9.4-127.77.9.1 ends before"),
    (["--addresses", "127.77.9.1-127.77.9.300", "--device", "acg"], "'127.77.9.300' is not an IPv4 address"),
    (["--addresses", "127.77.9.1-127.77.9.4", "--device", "acg*5"],
     "5 devices, but the addresses 127.77.9.1-127.77.9.4 have 4 left"),
    (["--addresses", "127.77.9.1-127.77.9.4", "--device", "acg*2", "--device", "mx2*3"], "3 devices, but"),
    (["--addresses", "127.0.0.0-127.255.255.255", "--device", "acg"],
     "more than 1024 addresses (a fleet serves at most 1024 devices; --max-devices N for more)"),
    (["--addresses", "127.77.0.1-127.77.8.1", "--device", "acg*2", "--max-devices", "2048"],
     "more than 2048 addresses"),
    (["--addresses", "127.77.9.1-127.77.9.4", "--device", "acg*1025"], "the count 1025 is not in 1..1024"),
    (["--addresses", "127.77.9.1-127.77.9.4", "--device", "acg", "--max-devices", "0"],
     "--max-devices: 0 is not a number of devices"),
    (["--addresses", "127.77.9.1-127.77.9.4", "--device", "acg*x"], "the count 'x' is not a number"),
    (["--addresses", "127.77.9.1-127.77.9.4", "--device", "mx2:RX-A4055-E"], "RX-A4055-E is an rx model"),
    (["--addresses", "127.77.9.1-127.77.9.4", "--device", "mx2", "--param", "drv=4"],
     "--param drv=4: no device of the fleet has a keypad with these codes (profiles mx2)"),
    (["--addresses", "127.77.9.1-127.77.9.4", "--device", "acg", "--param", "drv=99"], "--param 'drv=99'"),
    (["--addresses", "127.77.9.1-127.77.9.4", "--device", "acg*2", "--workers", "3"], "more worker processes"),
    (["--device", "acg*2"], "no address: give --addresses"),
    (["--addresses", "127.77.9.1"], "no device"),
    (["--addresses", "127.77.9.1-127.77.9.4", "--device", "acg*4", "--shard", "3/3"], "--shard '3/3': not INDEX/COUNT"),
    (["--addresses", "127.77.9.1-127.77.9.4", "--device", "acg*4", "--shard", "1"], "--shard '1': not INDEX/COUNT"),
    (["--addresses", "127.77.9.1-127.77.9.4", "--device", "acg*4", "--shard", "a/b"], "--shard 'a/b': not INDEX/"),
    (["--addresses", "127.77.9.1-127.77.9.4", "--device", "acg*2", "--shard", "0/3"],
     "--shard 0/3: more shards than the plant's 2 device(s)"),
    (["--addresses", "127.77.9.1-127.77.9.4", "--device", "acg*4", "--shard", "0/2", "--workers", "3"],
     "--workers 3: more worker processes than the fleet's 2 device(s)"),
]


@pytest.mark.parametrize(("argv", "message"), BAD_SPECS, ids=[" ".join(a) for a, _ in BAD_SPECS])
def test_a_bad_spec_is_one_line(argv: list[str], message: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["fleet", *argv]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("cipstack fleet: ") and message in lines[0], captured.err


@pytest.mark.parametrize(("text", "message"), [
    ('addresses = "127.77.9.1-127.77.9.2"\n[[device]]\nprofile = "pump"\n', "device 1: unknown profile 'pump'"),
    ('addresses = "127.77.9.1-127.77.9.2"\n[[device]]\nprofile = "acg"\ncount = 3\n', "3 devices, but"),
    ('adresses = "127.77.9.1"\n', "unknown key 'adresses'"),
    ('[[device]]\nprofile = "acg"\ncolour = "red"\n', "unknown key 'colour'"),
    ('[[device]\n', "not valid TOML"),
    ('max_devices = "many"\n[[device]]\nprofile = "acg"\n', "max_devices: 'many' is not a number of devices"),
    ('addresses = "127.77.9.1-127.77.9.4"\nmax_devices = 2\n[[device]]\nprofile = "acg"\ncount = 3\n',
     "the count 3 is not in 1..2"),
    ('addresses = "127.77.9.1"\n[[device]]\nprofile = "mx2"\nparams = ["drv=4"]\n',
     "'drv' is not a code of the MX2 Digital Operator"),
])
def test_a_bad_spec_file_is_one_line(text: str, message: str, tmp_path: Path,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    spec = tmp_path / "plant.toml"
    spec.write_text(text)
    assert main(["fleet", "--spec", str(spec)]) == 2
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"cipstack fleet: {spec}") and message in lines[0], lines


# -- running fleets ---------------------------------------------------------------------------------
def test_discovery_finds_every_device_once(tmp_path: Path) -> None:
    hosts = addresses(1, 16)
    port, io_port = free_port(*hosts), free_port(*hosts)
    with running(tmp_path, "--addresses", f"{hosts[0]}-{hosts[-1]}", "--device", "acg*12", "--device",
                 "mx2:MX2-A2015-E*4", "--port", str(port), "--io-port", str(io_port),
                 "--state-dir", str(tmp_path / "state")) as (_, lines):
        assert [line.split()[0] for line in lines] == [f"{h}:{port}" for h in hosts]
        # Four broadcasts at once, each collecting its own window (the command's output is read below).
        command = subprocess.Popen([sys.executable, "-m", "cipstack", "discover", "--broadcast", BROADCAST, "--port",
                                    str(port)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)

        async def at_once() -> tuple[list[str], list[tuple[bytes, str]], list[Any]]:
            return await asyncio.gather(broadcast_replies(port), list_identity_replies("255.255.255.255", port),
                                        discover(BROADCAST, port, timeout=1.2))

        looped, limited, found = asyncio.run(at_once())
        stdout, _ = command.communicate(timeout=30)
        # One broadcast: each device answers once, from its own address.
        assert sorted(looped, key=sort_key) == hosts
        # And to the limited broadcast, which many scanners send (issue 30, item 1).
        replies = [host for _, host in limited]
        assert sorted(replies, key=sort_key) == hosts
        # The scanner's discovery lists each once, with its own identity: the serial is its address's.
        by_host = {r.address.host: r for r in found if r.address}
        assert sorted(by_host, key=sort_key) == hosts and len(found) == len(hosts)
        for host in hosts:
            assert by_host[host].serial_number == int(ipaddress.IPv4Address(host))
        assert {by_host[h].vendor_id for h in hosts[:12]} == {PROFILES["acg"].vendor_id}
        assert {by_host[h].vendor_id for h in hosts[12:]} == {47}
        listed = sorted((line.split()[0] for line in stdout.splitlines()), key=lambda a: sort_key(a[:-6]))
        assert listed == [f"{h}:{port}" for h in hosts], stdout


async def _class1_then_trip(hosts: list[str], port: int, io_port: int) -> None:
    catalog = PROFILES["acg"].catalog
    assert catalog is not None
    scanners = [await Scanner.connect(f"{h}:{port}", timeout=5, catalog=catalog()) for h in hosts]
    try:
        async with contextlib.AsyncExitStack() as stack:
            handles = [await stack.enter_async_context(s.io_connection(output=21, input=71, rpi=0.010,
                                                                        timeout_multiplier=5, target_io_port=io_port))
                       for s in scanners[:3]]
            await wait_until(lambda: all(h.stats.received >= 50 for h in handles), 10, "50 packets on each")
            for handle in handles:
                assert not handle.timed_out, handle.stats.as_dict()
            # One device's trip: that device faults; the others, and their connections, do not.
            tripped = await asyncio.to_thread(drive, "trip", "OverHeat", "--host", hosts[1], "--port", str(port))
            assert tripped.returncode == 0 and "tripped: OverHeat" in tripped.stdout, tripped.stderr
            assert await scanners[1].read(0x29, 1, 10) == 1                       # Faulted
            assert await scanners[1].read(0x29, 1, 13) == 0x4200                  # Fault Code
            for index in (0, 2, 3):
                assert await scanners[index].read(0x29, 1, 10) == 0
            # Their data goes on after the trip (x128 connections: judged by packets that came, not by
            # whether a watchdog has run out yet).
            since = [handle.stats.received for handle in handles]
            await wait_until(lambda: all(h.stats.received - n >= 20 for h, n in zip(handles, since, strict=True)),
                             10, "20 more packets on each connection")
            assert not any(handle.timed_out for handle in handles)
            for host in (hosts[0], hosts[2]):
                status = await asyncio.to_thread(drive, "status", "--host", host, "--port", str(port))
                assert status.returncode == 0 and "TRIP" not in status.stdout.upper() and "class 1 1" in status.stdout
    finally:
        for scanner in scanners:
            await scanner.close()


def test_class1_to_several_devices_and_a_trip_stays_with_its_device(tmp_path: Path) -> None:
    hosts = addresses(2, 4)
    port, io_port = free_port(*hosts), free_port(*hosts)
    with running(tmp_path, "--addresses", ",".join(hosts), "--device", "acg*4", "--port", str(port),
                 "--io-port", str(io_port), "--state-dir", str(tmp_path / "state")):
        run_precise(_class1_then_trip(hosts, port, io_port))


async def _read(host: str, port: int, *path: int) -> object:
    catalog = PROFILES["acg"].catalog
    assert catalog is not None
    async with await Scanner.connect(f"{host}:{port}", timeout=5, catalog=catalog()) as scanner:
        return await scanner.read(*path)


async def _save_deceleration(host: str, port: int, tenths: int) -> None:
    catalog = PROFILES["acg"].catalog
    assert catalog is not None
    async with await Scanner.connect(f"{host}:{port}", timeout=5, catalog=catalog()) as scanner:
        await scanner.set_attribute_single(0x2A, 1, 103, tenths)              # dEC
        await write_registers(scanner, {SAVE_PARAMETERS: 0})
        await write_registers(scanner, {SAVE_PARAMETERS: 1})                   # 0x03E0: 0 -> 1 saves


def test_each_device_keeps_its_own_saved_parameters(tmp_path: Path) -> None:
    hosts = addresses(3, 2)
    port = free_port(*hosts)
    state = tmp_path / "state"
    args = ("--addresses", f"{hosts[0]}-{hosts[1]}", "--device", "acg*2", "--port", str(port), "--io-port", "0",
            "--state-dir", str(state))
    with running(tmp_path, *args):
        default = asyncio.run(_read(hosts[1], port, 0x2A, 1, 103))
        asyncio.run(_save_deceleration(hosts[0], port, 55))
        assert default != 55
    assert (state / f"{hosts[0]}-acg.json").exists()
    assert not (state / f"{hosts[1]}-acg.json").exists()                     # nothing saved there
    with running(tmp_path, *args, name="restarted"):                         # a power cycle of both
        assert asyncio.run(_read(hosts[0], port, 0x2A, 1, 103)) == 55
        assert asyncio.run(_read(hosts[1], port, 0x2A, 1, 103)) == default


def test_param_goes_to_every_device_whose_keypad_has_its_codes(tmp_path: Path) -> None:
    """``--param A004=60`` is an MX2 function code: the MX2 takes it at start, the ACG (whose keypad
    has no A004) is left as it is; ``ACC=7.5`` is the ACG's alone."""
    hosts = addresses(4, 2)
    port = free_port(*hosts)
    with running(tmp_path, "--addresses", f"{hosts[0]}-{hosts[1]}", "--device", "acg", "--device", "mx2",
                 "--param", "A004=60", "--port", str(port), "--io-port", "0", "--factory"):
        with SyncScanner(f"{hosts[1]}:{port}") as mx2:
            assert mx2.parameter("A004").value == 60.0
        with SyncScanner(f"{hosts[0]}:{port}") as acg:
            assert acg.catalog.profile == "acg"
    with (running(tmp_path, "--addresses", f"{hosts[0]}-{hosts[1]}", "--device", "acg", "--device", "mx2",
                  "--param", "ACC=7.5", "--port", str(port), "--io-port", "0", "--factory", name="acc"),
          SyncScanner(f"{hosts[0]}:{port}") as acg):
        assert acg.parameter("ACC").value == 7.5


def test_shards_of_one_spec_serve_the_plant_between_them(tmp_path: Path) -> None:
    hosts = addresses(11, 5)
    port = free_port(*hosts)
    spec = tmp_path / "plant.toml"
    spec.write_text(f'addresses = "{hosts[0]}-{hosts[-1]}"\nport = {port}\nio_port = 0\nstate_dir = "s"\n'
                    f'[[device]]\nprofile = "acg"\ncount = 5\n')
    with running(tmp_path, "--spec", str(spec), "--shard", "1/2") as (_, lines):
        # The second of two shares of five: the last two addresses, and nothing answers on the others.
        assert [line.split()[0] for line in lines] == [f"{hosts[3]}:{port}", f"{hosts[4]}:{port}"]
        found = asyncio.run(discover(BROADCAST, port, timeout=1.2))
        assert sorted(r.address.host for r in found if r.address and r.address.host in hosts) == hosts[3:]
        fleet = Fleet(tmp_path, "--spec", str(spec), "--shard", "0/2", name="first")
        try:
            first = fleet.wait_ready()
            assert [line.split()[0] for line in first] == [f"{h}:{port}" for h in hosts[:3]]
            found = asyncio.run(discover(BROADCAST, port, timeout=1.2))
            assert sorted((r.address.host for r in found if r.address and r.address.host in hosts),
                          key=sort_key) == hosts
        finally:
            assert fleet.stop() == 0


@pytest.mark.parametrize("workers", [1, 2])
def test_a_taken_address_is_one_line_and_nothing_is_left(tmp_path: Path, workers: int) -> None:
    hosts = addresses(4 + workers, 4)
    port = free_port(*hosts)
    fleet = refused_fleet(tmp_path, (hosts[2], port), "--addresses", f"{hosts[0]}-{hosts[-1]}", "--device", "acg*4",
                          "--port", str(port), "--io-port", "0", "--workers", str(workers),
                          "--state-dir", str(tmp_path / "state"))
    lines = fleet.err.read_text().splitlines()
    assert lines == [f"cipstack fleet: cannot listen on TCP {hosts[2]}:{port} (EtherNet/IP, --port): "
                     "Address already in use"], lines
    assert children(fleet.process.pid) == []
    for host in hosts:                                                      # every port of every device free
        for kind in (socket.SOCK_STREAM, socket.SOCK_DGRAM):
            with socket.socket(socket.AF_INET, kind) as probe:
                probe.bind((host, port))


def test_workers_serve_every_device_and_a_dead_worker_stops_the_fleet(tmp_path: Path) -> None:
    hosts = addresses(7, 64)
    port, io_port = free_port(hosts[0], hosts[-1]), free_port(hosts[0], hosts[-1])
    fleet = Fleet(tmp_path, "--addresses", f"{hosts[0]}-{hosts[-1]}", "--device", "acg*64", "--port", str(port),
                  "--io-port", str(io_port), "--workers", "2", "--state-dir", str(tmp_path / "state"))
    try:
        lines = fleet.wait_ready(60)
        assert [line.split()[0] for line in lines] == [f"{h}:{port}" for h in hosts]
        workers = children(fleet.process.pid)
        assert len(workers) == 2
        # Three broadcasts at once, each collecting its own window: `cipstack discover` with its default
        # broadcast addresses, and ListIdentity to loopback's broadcast address and to the limited one.
        command = subprocess.Popen([sys.executable, "-m", "cipstack", "discover", "--port", str(port), "--json"],
                                   stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)

        async def both() -> tuple[list[str], list[tuple[bytes, str]]]:
            return await asyncio.gather(broadcast_replies(port, 2.0),
                                        list_identity_replies("255.255.255.255", port, 2.0))

        looped, limited = asyncio.run(both())
        stdout, _ = command.communicate(timeout=30)
        assert sorted(looped, key=sort_key) == hosts                       # 64 devices, each answered once
        replies = [host for _, host in limited]
        assert sorted(replies, key=sort_key) == hosts                      # the limited broadcast too
        # `cipstack discover` lists every device once.
        listed = [json.loads(line)["address"] for line in stdout.splitlines()]
        assert sorted(listed, key=lambda a: sort_key(a.rsplit(":", 1)[0])) == [f"{h}:{port}" for h in hosts]
        for host in (hosts[0], hosts[-1]):                                   # one of each worker's share
            status = drive("status", "--host", host, "--port", str(port))
            assert status.returncode == 0 and "READY" in status.stdout, status.stderr
        os.kill(workers[1], signal.SIGKILL)
        assert fleet.process.wait(30) == 1
        err = [line for line in fleet.err.read_text().splitlines() if "cipstack fleet:" in line]
        assert len(err) == 1 and "ended: killed by SIGKILL; stopping the fleet" in err[0], err
        assert f"{hosts[0]}-{hosts[31]}" in err[0] or f"{hosts[32]}-{hosts[63]}" in err[0]
        assert "Traceback" not in fleet.err.read_text()
        wait_for(lambda: not any(alive(pid) for pid in workers), 10, "the other worker to stop")
    finally:
        fleet.kill()


def test_a_stopped_worker_is_reported_and_stopping_takes_seconds(tmp_path: Path) -> None:
    """A worker that stops answering (SIGSTOP) is reported as one that ended, within the heartbeat's
    deadline, and the fleet exits 1 with none left; a fleet stopped while one of its workers is
    stopped ends within seconds (SIGCONT, then SIGTERM), not after 30 s."""
    from cipstack.fleet.workers import HEARTBEAT_INTERVAL, HEARTBEAT_TIMEOUT, HUNG_STOP_TIMEOUT

    def fleet(block: int, name: str) -> Fleet:
        hosts = addresses(block, 4)
        return Fleet(tmp_path, "--addresses", f"{hosts[0]}-{hosts[-1]}", "--device", "acg*4", "--port",
                     str(free_port(*hosts)), "--io-port", "0", "--workers", "2", "--state-dir",
                     str(tmp_path / name), name=name)

    # Two fleets started together: the second is stopped while the first finds its worker hung.
    hung, stopped = fleet(20, "hung"), fleet(21, "stopped")
    try:
        hung.wait_ready()
        stopped.wait_ready()
        workers = children(hung.process.pid)
        assert len(workers) == 2
        os.kill(workers[1], signal.SIGSTOP)
        stopped_at = time.monotonic()

        others = children(stopped.process.pid)
        os.kill(others[0], signal.SIGSTOP)
        asked = time.monotonic()
        stopped.process.send_signal(signal.SIGTERM)
        assert stopped.process.wait(30) == 0, stopped.err.read_text()
        assert time.monotonic() - asked < 8.0
        wait_for(lambda: not any(alive(pid) for pid in others), 10, "the workers to end")

        assert hung.process.wait(30) == 1
        took = time.monotonic() - stopped_at
        assert took < HEARTBEAT_TIMEOUT + HEARTBEAT_INTERVAL + HUNG_STOP_TIMEOUT + 3.0, took
        err = [line for line in hung.err.read_text().splitlines() if "cipstack fleet:" in line]
        assert len(err) == 1 and "stopped answering" in err[0] and "stopping the fleet" in err[0], err
        hosts = addresses(20, 4)
        assert f"{hosts[2]}-{hosts[3]}" in err[0], err
        assert "Traceback" not in hung.err.read_text()
        wait_for(lambda: not any(alive(pid) for pid in workers), 10, "the workers to end")
    finally:
        hung.kill()
        stopped.kill()


def test_sigterm_stops_every_worker_and_a_killed_parent_leaves_none(tmp_path: Path) -> None:
    hosts = addresses(8, 2)
    port = free_port(*hosts)
    args = ("--addresses", f"{hosts[0]}-{hosts[1]}", "--device", "acg*2", "--port", str(port), "--io-port", "0",
            "--workers", "2", "--state-dir", str(tmp_path / "state"))
    with running(tmp_path, *args) as (fleet, _):
        workers = children(fleet.process.pid)
        assert len(workers) == 2
        assert fleet.stop(signal.SIGTERM) == 0
        assert not any(alive(pid) for pid in workers)
    fleet = Fleet(tmp_path, *args, name="killed")
    try:
        fleet.wait_ready()
        workers = children(fleet.process.pid)
        fleet.process.kill()                                                 # no chance to stop them
        fleet.process.wait(10)
        wait_for(lambda: not any(alive(pid) for pid in workers), 10, "the workers to end with their parent")
    finally:
        fleet.kill()


def test_a_spec_file(tmp_path: Path) -> None:
    hosts = addresses(9, 4)
    port = free_port(*hosts)
    spec = tmp_path / "plant.toml"
    spec.write_text(f"""
# Two conveyors' drives under network control, and the pump's inverter.
addresses = "{hosts[0]}-{hosts[2]}"
port = {port}
io_port = 0
state_dir = "plant-state"

[[device]]
profile = "acg"
count = 2
params = {{drv = 4, Frq = 8}}

[[device]]
model = "MX2-A2015-E"
first = "{hosts[3]}"
""")
    with running(tmp_path, "--spec", str(spec)) as (_, lines):
        assert [line.split()[:2] for line in lines] == [[f"{hosts[0]}:{port}", "acg"], [f"{hosts[1]}:{port}", "acg"],
                                                        [f"{hosts[3]}:{port}", "mx2:MX2-A2015-E"]]
        assert f"state {tmp_path / 'plant-state' / (hosts[0] + '-acg.json')}" in lines[0]
        # drv = 4, Frq = 8: the network is the command and the frequency source (0x29/1/14, 0x2A/1/29).
        assert asyncio.run(_read(hosts[1], port, 0x29, 1, 14)) == 1
        assert asyncio.run(_read(hosts[1], port, 0x2A, 1, 29)) == 1
        found = asyncio.run(discover(BROADCAST, port, timeout=1.2))
        assert sorted((r.address.host for r in found if r.address), key=sort_key) == [hosts[0], hosts[1], hosts[3]]


@pytest.mark.parametrize("workers", [1, 2])
def test_a_corrupt_state_file_is_one_line_naming_it(tmp_path: Path, workers: int) -> None:
    hosts = addresses(10 + workers, 4)
    state = tmp_path / "state"
    state.mkdir()
    corrupt = state / f"{hosts[3]}-acg.json"
    corrupt.write_text("{garbage")
    result = subprocess.run([sys.executable, "-m", "cipstack", "fleet", "--addresses", f"{hosts[0]}-{hosts[-1]}",
                             "--device", "acg*4", "--port", str(free_port(*hosts)), "--io-port", "0", "--workers",
                             str(workers), "--state-dir", str(state)], capture_output=True, text=True, timeout=60)
    assert result.returncode == 2 and result.stdout == ""
    assert result.stderr.splitlines() == [f"cipstack fleet: {hosts[3]}: {corrupt}: not valid JSON, truncated or "
                                          "corrupt (Expecting property name enclosed in double quotes at line 1, "
                                          "column 2)"]
    assert corrupt.read_text() == "{garbage"                                 # never silently reset


def test_start_up_objects_are_frozen_out_of_the_collector(tmp_path: Path) -> None:
    """A full collection walks every tracked object with the loop stopped: 42 ms over 64 ACG
    drives' tables, past the watchdog of a 10 ms RPI (connections timed out). Once every device
    serves, what start-up built is frozen out of the collector's reach."""
    import gc

    from cipstack.fleet.serve import serve_until_signalled

    hosts = addresses(9, 2)
    port, io_port = free_port(*hosts), free_port(*hosts)
    devices = assign([parse_group("acg*2")], parse_addresses(",".join(hosts)), tmp_path)
    frozen: list[int] = []

    def ready(lines: list[str]) -> None:
        frozen.append(gc.get_freeze_count())
        os.kill(os.getpid(), signal.SIGUSR1)   # the handler below stops the devices

    gc.unfreeze()
    try:
        stopped_by = run_precise(serve_until_signalled(devices, port, io_port, ready, signals=(signal.SIGUSR1,)))
    finally:
        gc.unfreeze()
    assert stopped_by == signal.SIGUSR1
    # Every object the process tracks, the two drives' tables, schemas and registers among them.
    assert frozen and frozen[0] > 40_000, frozen


def test_the_devices_of_one_process_produce_class1_in_the_same_slots() -> None:
    """Two devices of one worker, a connection opened on each 3.7 ms apart: the second's first T->O
    packet is due on the first's 10 ms slots, as if one device had both."""
    devices = [FleetDevice(f"127.0.0.{n}", "acg") for n in (1, 2)]
    fleet = DeviceSet(devices, free_port(), free_port())
    first, second = (build_adapter(device, fleet.port, fleet.io_port, fleet.production_grid) for device in devices)
    try:
        for adapter, serial, now in ((first, 0x101, 5.0), (second, 0x102, 5.0037)):
            assert adapter.io is not None
            request = ForwardOpenRequest.decode(class1_open(serial, path=ACG_INPUT_ONLY_PATH, ot_size=2)[6:],
                                                large=False)
            adapter.io.forward_open(request, RequestContext(adapter.device.router, now, "127.0.0.1:1", None))
        assert first.io is not None and second.io is not None
        assert first.io.next_deadline() == 5.0
        assert second.io.next_deadline() == pytest.approx(5.010)
    finally:
        first.device.close()
        second.device.close()
