"""examples/device-family, a device family in a distribution of its own, as a user installs it: cipstack
and the example pip-installed (editable, no dependencies, no build isolation: nothing is downloaded) into a
throwaway venv, then `cipstack models`, `cipstack adapter --profile dio` and `cipstack identity`, `get` and
`set` against the block, each a process of that venv."""

from __future__ import annotations

import importlib.util
import os
import socket
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

from tests.ports import free_port
from tests.waiting import wait_for

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "device-family"

pytestmark = pytest.mark.skipif(importlib.util.find_spec("hatchling") is None,
                                reason="hatchling (the test extra) builds the editable installs offline")


@pytest.fixture(scope="module")
def venv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A venv with cipstack from this tree and the example installed by pip. The running interpreter's
    site-packages are on its path (a ``.pth``) for cipstack's dependencies and the build backend, whose
    ``.pth`` files it does not read: the cipstack installed there does not hide this one."""
    where = tmp_path_factory.mktemp("family") / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(where)], check=True, timeout=120)
    python = where / "bin" / "python"
    purelib = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                             capture_output=True, text=True, check=True, timeout=60).stdout.strip()
    ours = sorted({sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"],
                   *(p for p in sys.path if p.endswith("site-packages"))})
    Path(purelib, "zz_parent_site.pth").write_text("".join(f"{p}\n" for p in ours), encoding="utf-8")
    installed = subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install", "--quiet",
                                "--no-deps", "--no-build-isolation", "--no-index", "--disable-pip-version-check",
                                "-e", str(ROOT), "-e", str(EXAMPLE)],
                               capture_output=True, text=True, env=_environment(), timeout=300)
    assert installed.returncode == 0, installed.stdout + installed.stderr
    return where


def _environment() -> dict[str, str]:
    # Not this tree on PYTHONPATH: the venv's installs are what is tested.
    return {key: value for key, value in os.environ.items() if key not in ("PYTHONPATH", "PIP_FIND_LINKS")}


def cipstack(venv: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(venv / "bin" / "cipstack"), *args], capture_output=True, text=True,
                          env=_environment(), timeout=60, cwd=venv)


def test_the_installed_family_is_listed_with_its_distribution(venv: Path) -> None:
    shown = cipstack(venv, "models")
    assert shown.returncode == 0, shown.stderr
    assert shown.stdout.splitlines()[-1].split() == ["dio", "DIO-4", "product", "code", "4", "DIO-4", "-",
                                                     "cipstack-dio"]
    assert shown.stdout.splitlines()[0].split()[-1] == "cipstack"


def test_the_adapter_serves_the_block_and_a_scanner_reads_and_writes_it(venv: Path) -> None:
    port = free_port()
    adapter = subprocess.Popen([str(venv / "bin" / "cipstack"), "adapter", "--profile", "dio", "--port", str(port),
                                "--io-port", "0", "--factory", "--quiet"], stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE, text=True, env=_environment(), cwd=venv)

    def listening() -> bool:
        assert adapter.poll() is None, adapter.stderr.read() if adapter.stderr else ""
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
        except OSError:
            return False
        return True

    try:
        wait_for(listening, 30, "the dio adapter to listen")
        address = f"127.0.0.1:{port}"
        identity = cipstack(venv, "identity", address, "--json")
        assert identity.returncode == 0, identity.stderr
        assert '"vendor_id": 65520' in identity.stdout and '"product_code": 4' in identity.stdout
        assert '"device_type": 7' in identity.stdout and '"product_name": "DIO-4"' in identity.stdout
        # Output point 2 on: input point 2 (wired to it) reads on, and the input assembly has bit 1 set.
        assert cipstack(venv, "get", address, "8/2/3", "--type", "BOOL").stdout == "0\n"
        written = cipstack(venv, "set", address, "9/2/3", "1", "--type", "BOOL")
        assert written.returncode == 0, written.stderr
        assert cipstack(venv, "get", address, "8/2/3", "--type", "BOOL").stdout == "1\n"
        inputs = cipstack(venv, "get", address, "4/100/3", "--json")
        assert inputs.returncode == 0 and '"data": "02"' in inputs.stdout, inputs.stdout + inputs.stderr
        # The Discrete Input Point's Value is the device's, not the network's (CIP Vol 1, section 5-9).
        refused = cipstack(venv, "set", address, "8/2/3", "0", "--type", "BOOL")
        assert refused.returncode == 1 and "0x0E (attribute not settable)" in refused.stderr, refused.stderr
    finally:
        adapter.terminate()
        adapter.wait(15)
