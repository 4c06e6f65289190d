"""CIP Security from the command line's clients: ``get``, ``set``, ``identity``, ``params``, ``eds
fetch``, ``eds check --against`` over TLS and ``discover`` over DTLS, each run as the real ``python -m
cipstack`` process against ``cipstack adapter --security`` (a process of its own, ports from
``free_port()``), and each mistake a user makes with them: another CA's folder, a folder that is not
there, a client certificate the device does not trust, an expired one, the plain port, a port where
nothing listens. Then ``cipstack fleet --security``: every device serves TLS and DTLS at its address."""

from __future__ import annotations

import datetime
import json
import re
import shutil
import socket
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

pytest.importorskip("cryptography", reason="the security extra (cryptography) is not installed")
pytest.importorskip("OpenSSL", reason="the security extra (pyOpenSSL) is not installed")

from cipstack.security.provisioning import init
from tests.ports import free_port
from tests.test_fleet import children, running
from tests.test_security_tls import Device, _mixed_folder, secured_adapter

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="any 127.x on loopback")


def cipstack(*argv: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "cipstack", *argv], capture_output=True, text=True,
                          timeout=timeout, stdin=subprocess.DEVNULL)


def one_line(result: subprocess.CompletedProcess[str]) -> str:
    """The one line a failed command prints on stderr (and nothing else there: no traceback)."""
    assert result.returncode != 0, result.stdout
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    return lines[0]


@pytest.fixture(scope="module")
def device(lab: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Device]:
    yield from secured_adapter(lab, tmp_path_factory)


@pytest.fixture(scope="module")
def expired(lab: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The CA of ``lab`` and a client certificate that expired in 2020 (of a CA of its own: the
    folder is refused when it is read, before any handshake)."""
    old = tmp_path_factory.mktemp("security") / "old"
    init(old, days=1, now=datetime.datetime(2020, 1, 1, tzinfo=datetime.timezone.utc))
    folder = old.parent / "expired"
    folder.mkdir()
    shutil.copy(lab / "ca.pem", folder / "ca.pem")
    shutil.copy(old / "client.pem", folder / "client.pem")
    shutil.copy(old / "client.key", folder / "client.key")
    return folder


# -- get, set, identity over TLS ----------------------------------------------------------------------
def test_get_set_and_identity_over_tls(device: Device, lab: Path) -> None:
    secured = f"{device.host}:{device.tls_port}"
    result = cipstack("get", secured, "1/1/7", "--security", str(lab))
    assert (result.returncode, result.stdout, result.stderr) == (0, "Product Name = 'CENT'\n", "")
    result = cipstack("set", secured, "ACC", "2.5", "--security", str(lab), "--json")
    assert result.returncode == 0, result.stderr
    assert (json.loads(result.stdout)["value"], json.loads(result.stdout)["engineering"]) == (25, 2.5)
    # The same device on plain 44818 sees the value written over TLS.
    result = cipstack("get", f"{device.host}:{device.port}", "ACC")
    assert result.stdout == "ACC Acceleration Time = 2.5 s (25)\n", result.stderr
    result = cipstack("identity", secured, "--security", str(lab), "--json")
    assert result.returncode == 0, result.stderr
    record = json.loads(result.stdout)
    assert (record["product_name"], record["vendor_id"]) == ("CENT", 259)
    result = cipstack("get", secured, "0x5E/1/1", "--security", str(lab), "--connected")
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("State = ")


def test_with_security_the_port_is_2221_unless_named(lab: Path) -> None:
    # Nothing listens on 127.0.0.3:2221 in a test (free_port never hands out 2221).
    for argv in (["get", "127.0.0.3", "1/1/7"], ["identity", "127.0.0.3"]):
        line = one_line(cipstack(*argv, "--security", str(lab), "--timeout", "2"))
        assert line.startswith(f"cipstack {argv[0]}: cannot connect to 127.0.0.3:2221: "), line


def _bad_inputs(device: Device, lab: Path, other_lab: Path, expired: Path, tmp_path: Path) -> list[
        tuple[str, list[str], str]]:
    """(what the user did, the target and --security, the line expected) of each careless use."""
    secured = f"{device.host}:{device.tls_port}"
    closed = f"127.0.0.1:{free_port()}"
    return [
        ("another CA's folder", [secured, "--security", str(other_lab)],
         f"TLS with {secured} failed: certificate verify failed: self-signed certificate in certificate chain"),
        ("no such folder", [secured, "--security", str(tmp_path / "nowhere")],
         f"{tmp_path / 'nowhere'}: no such folder (make one with `cipstack security init {tmp_path / 'nowhere'}`)"),
        ("a client certificate the device does not trust", [secured, "--security",
                                                           str(_mixed_folder(tmp_path, lab, other_lab))],
         f"TLS with {secured} failed: the peer does not trust our certificate..."),
        ("an expired client certificate", [secured, "--security", str(expired)],
         f"{expired / 'client.pem'}: certificate expired on 2020-01-01 23:55:00 UTC"),
        ("the plain port", [f"{device.host}:{device.port}", "--security", str(lab), "--timeout", "1"],
         f"TLS with {device.host}:{device.port} failed: no answer to the handshake within 1 s: a plain EtherNet/IP "
         "port (44818) answers no TLS; the device's TLS port is 2221 unless it was given another"),
        ("nothing listening", [closed, "--security", str(lab)], f"cannot connect to {closed}: Connection refused"),
    ]


def _matches(expected: str, line: str) -> bool:
    return re.fullmatch(".*".join(re.escape(part) for part in expected.split("...")), line) is not None


@pytest.mark.parametrize("command", [["get", "{}", "1/1/7"], ["set", "{}", "ACC", "2.5"], ["identity", "{}"],
                                     ["params", "dump", "{}"], ["eds", "fetch", "{}", "-o", "-"]],
                         ids=lambda c: " ".join(c[:2]).replace(" {}", ""))
def test_each_careless_use_is_one_line(command: list[str], device: Device, lab: Path, other_lab: Path,
                                       expired: Path, tmp_path: Path) -> None:
    name = command[0]   # a subcommand's error is its command's: `cipstack eds: ...`
    for what, (target, *options), expected in _bad_inputs(device, lab, other_lab, expired, tmp_path):
        argv = [target if word == "{}" else word for word in command]
        result = cipstack(*argv, *options)
        line = one_line(result)
        assert result.returncode == 1, (what, result.stderr)
        assert result.stdout == "", what
        assert _matches(f"cipstack {name}: {expected}", line), (what, line)
    # The device served on through all of it.
    assert device.process.poll() is None
    result = cipstack("get", f"{device.host}:{device.tls_port}", "1/1/7", "--security", str(lab))
    assert result.returncode == 0, result.stderr


# -- params and EDS over TLS --------------------------------------------------------------------------
def test_params_dump_and_diff_over_tls(device: Device, lab: Path, tmp_path: Path) -> None:
    secured = f"{device.host}:{device.tls_port}"
    recipe = tmp_path / "recipe.toml"
    result = cipstack("params", "dump", secured, "--security", str(lab), "-o", str(recipe))
    assert result.returncode == 0, result.stderr
    assert re.fullmatch(r"\d+ parameters written to .*\n", result.stderr)
    result = cipstack("params", "diff", secured, str(recipe), "--security", str(lab))
    assert (result.returncode, result.stdout) == (0, f"no differences ({result.stdout.split('(')[1]}"), result.stderr
    result = cipstack("params", "load", secured, str(recipe), "--security", str(lab), "--no-save")
    assert result.returncode == 0, result.stderr
    assert re.fullmatch(r"0 written, \d+ unchanged, 0 refused\n", result.stdout), result.stdout


def test_eds_fetch_and_check_against_over_tls(device: Device, lab: Path, tmp_path: Path) -> None:
    secured = f"{device.host}:{device.tls_port}"
    eds = tmp_path / "device.eds"
    result = cipstack("eds", "fetch", secured, "--security", str(lab), "-o", str(eds))
    assert result.returncode == 0, result.stderr
    plain = cipstack("eds", "check", str(eds), "--against", f"{device.host}:{device.port}", "--no-connections")
    secure = cipstack("eds", "check", str(eds), "--against", secured, "--security", str(lab), "--no-connections")
    assert secure.returncode == plain.returncode == 0, secure.stderr
    # The same comparison over TLS as on plain 44818, the address apart.
    assert secure.stdout.replace(secured, "HOST") == plain.stdout.replace(f"{device.host}:{device.port}", "HOST")
    assert "parameters read" in secure.stdout


def test_eds_check_against_opens_its_connections_over_dtls(device: Device, lab: Path, tmp_path: Path) -> None:
    secured = f"{device.host}:{device.tls_port}"
    eds = tmp_path / "device.eds"
    assert cipstack("eds", "fetch", f"{device.host}:{device.port}", "-o", str(eds)).returncode == 0
    result = cipstack("eds", "check", str(eds), "--against", secured, "--security", str(lab))
    assert result.returncode == 0, result.stdout + result.stderr
    opened = re.search(r"(\d+) of (\d+) class 1 connections opened and closed", result.stdout)
    assert opened is not None and int(opened.group(1)) >= 1, result.stdout
    assert " error " not in result.stdout


def test_eds_check_security_without_against_and_with_another_ca(device: Device, other_lab: Path,
                                                                 tmp_path: Path) -> None:
    eds = tmp_path / "device.eds"
    assert cipstack("eds", "fetch", f"{device.host}:{device.port}", "-o", str(eds)).returncode == 0
    result = cipstack("eds", "check", str(eds), "--security", str(other_lab))
    assert result.returncode == 2
    assert one_line(result) == "cipstack eds: --security goes with --against HOST: the check of a file alone reads " \
                               "no device"
    secured = f"{device.host}:{device.tls_port}"
    result = cipstack("eds", "check", str(eds), "--against", secured, "--security", str(other_lab))
    assert result.returncode == 1
    assert one_line(result) == (f"cipstack eds: TLS with {secured} failed: certificate verify failed: self-signed "
                                "certificate in certificate chain")


# -- discover over DTLS -------------------------------------------------------------------------------
def test_discover_asks_each_named_device_over_dtls(device: Device, lab: Path) -> None:
    result = cipstack("discover", "--broadcast", device.host, "--port", str(device.tls_port), "--security", str(lab),
                      "--json")
    assert (result.returncode, result.stderr) == (0, "")
    record = json.loads(result.stdout)
    assert (record["product_name"], record["vendor_id"]) == ("CENT", 259)
    # HOST:PORT per device; one that does not answer is its own line, the others still listed, exit 1.
    closed = free_port()
    result = cipstack("discover", "--broadcast", f"{device.host}:{device.tls_port},127.0.0.1:{closed}",
                      "--security", str(lab))
    assert result.returncode == 1
    assert "'CENT'" in result.stdout
    assert one_line(result) == (f"cipstack discover: DTLS with 127.0.0.1:{closed}: nothing listens there "
                                "(ICMP port unreachable)")


@pytest.mark.parametrize("broadcast", [None, "255.255.255.255", "127.255.255.255", "239.192.1.1", "0.0.0.0"])
def test_discover_refuses_to_broadcast_with_security(broadcast: str | None, lab: Path) -> None:
    result = cipstack("discover", *(["--broadcast", broadcast] if broadcast else []), "--security", str(lab))
    assert result.returncode == 2
    line = one_line(result)
    assert line.startswith("cipstack discover: --"), line
    assert "cannot be secured" in line or "a DTLS session has one peer" in line, line
    assert result.stdout == ""


def test_discover_names_each_bad_answer(device: Device, lab: Path, other_lab: Path) -> None:
    secured = ["--broadcast", device.host, "--port", str(device.tls_port)]
    line = one_line(cipstack("discover", *secured, "--security", str(other_lab)))
    assert line == (f"cipstack discover: DTLS with {device.host}:{device.tls_port} failed: certificate verify "
                    "failed: self-signed certificate in certificate chain")    # OpenSSL's X.509 error 19
    # The plain UDP port takes the ClientHello for garbage and answers nothing.
    line = one_line(cipstack("discover", "--broadcast", device.host, "--port", str(device.port), "--security",
                             str(lab), "--timeout", "1"))
    assert line == (f"cipstack discover: DTLS with {device.host}:{device.port}: no answer to the handshake (is the "
                    "device serving CIP Security over UDP there?)")


# -- the fleet ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("workers", [1, 2])
def test_fleet_serves_tls_and_dtls_at_every_device(workers: int, lab: Path, tmp_path: Path) -> None:
    hosts = [f"127.78.{workers}.{10 + n}" for n in range(3)]
    port, secure_port = free_port(*hosts), free_port(*hosts)
    with running(tmp_path, "--addresses", f"{hosts[0]}-{hosts[-1]}", "--device", "acg*3", "--port", str(port),
                 "--io-port", "0", "--factory", "--workers", str(workers), "--security", str(lab),
                 "--security-port", str(secure_port)) as (_, lines):
        assert [line.split()[0] for line in lines] == [f"{host}:{port}" for host in hosts]
        assert all(line.endswith(f"TLS/DTLS {secure_port}") for line in lines), lines
        serials = []
        for host in hosts:
            result = cipstack("get", f"{host}:{secure_port}", "1/1/6", "--security", str(lab), "--json")
            assert result.returncode == 0, result.stderr
            serials.append(json.loads(result.stdout)["value"])
        assert len(set(serials)) == 3   # each its own device
        result = cipstack("discover", "--broadcast", ",".join(hosts), "--port", str(secure_port), "--security",
                          str(lab), "--json")
        assert result.returncode == 0, result.stderr
        assert sorted(json.loads(line)["address"] for line in result.stdout.splitlines()) == \
               sorted(f"{host}:{secure_port}" for host in hosts)
        result = cipstack("io", f"{hosts[1]}:{secure_port}", "--security", str(lab), "--output", "21", "--input",
                          "71", "--rpi", "10ms", "--duration", "0.5s", "--print", "summary")
        assert result.returncode == 0, result.stderr
        sent, received = (int(word) for word in re.findall(r"sent (\d+)  received (\d+)", result.stdout)[0])
        assert sent > 0 and received > 0
        line = one_line(cipstack("get", f"{hosts[2]}:{secure_port}", "1/1/7", "--security", str(tmp_path / "none")))
        assert "no such folder" in line


def test_fleet_spec_file_names_the_folder(lab: Path, tmp_path: Path) -> None:
    hosts = [f"127.78.9.{10 + n}" for n in range(2)]
    port, secure_port = free_port(*hosts), free_port(*hosts)
    (tmp_path / "lab").symlink_to(lab)
    spec = tmp_path / "plant.toml"
    spec.write_text(f'addresses = "{hosts[0]}-{hosts[1]}"\nport = {port}\nio_port = 0\nsecurity = "lab"\n'
                    f'security_port = {secure_port}\n[[device]]\nprofile = "acg"\ncount = 2\n')
    with running(tmp_path, "--spec", str(spec), "--factory") as (_, lines):
        assert all(line.endswith(f"TLS/DTLS {secure_port}") for line in lines), lines
        result = cipstack("identity", f"{hosts[1]}:{secure_port}", "--security", str(lab))
        assert result.returncode == 0, result.stderr
        assert "'CENT'" in result.stdout


def test_fleet_security_mistakes_are_one_line(tmp_path: Path, lab: Path) -> None:
    host = "127.78.8.10"
    result = cipstack("fleet", "--addresses", host, "--device", "acg", "--port", str(free_port(host)), "--factory",
                      "--security", str(tmp_path / "none"))
    assert result.returncode == 1
    assert one_line(result) == (f"cipstack fleet: {tmp_path / 'none'}: no such folder (make one with `cipstack "
                                f"security init {tmp_path / 'none'}`)")
    result = cipstack("fleet", "--addresses", host, "--device", "acg", "--factory", "--security-port", "3000")
    assert result.returncode == 2
    assert one_line(result) == "cipstack fleet: --security-port goes with --security DIR (or security in the spec file)"
    # A security port another socket holds: one line, and no worker left behind.
    with socket.socket() as taken:
        taken.bind((host, 0))
        taken.listen()
        held = taken.getsockname()[1]
        process = subprocess.Popen([sys.executable, "-m", "cipstack", "fleet", "--addresses", host, "--device", "acg",
                                    "--port", str(free_port(host)), "--io-port", "0", "--factory", "--security",
                                    str(lab), "--security-port", str(held), "--workers", "1"],
                                   stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        out, err = process.communicate(timeout=60)
    assert process.returncode == 2, err
    assert out == ""
    assert err == (f"cipstack fleet: cannot listen on TCP {host}:{held} (EtherNet/IP over TLS, --security-port): "
                   "Address already in use\n")
    assert children(process.pid) == []
