"""Saved parameters across a restart, and the state file that keeps them.

The rule (ACG RS-485 manual, "Saving Parameters Defined by Communication" and the memory control area):
a parameter written over the network takes effect but reverts at power-up unless 0x03E0 has
been set from 0 to 1 since; setting it from 1 to 0 saves nothing. A restart here is a new drive
object on the same state file.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import pytest

from cipstack.devices import state
from cipstack.devices.acg.drive import FAMILY, MODEL, AcgDrive
from cipstack.devices.acg.registers import ACG_REGISTERS
from cipstack.devices.registers import RegisterError, RegisterRefusal
from cipstack.devices.state import (
    STATE_FORMAT,
    STATE_VERSION,
    ParameterStore,
    StateFileError,
    default_state_path,
    load_state,
    save_state,
)

SAVE = 0x03E0


def addr(code: str) -> int:
    return ACG_REGISTERS.by_code(code).address


ACC, DEC = addr("ACC"), addr("dEC")


@pytest.fixture
def path(tmp_path: Path) -> Path:
    return tmp_path / "acg.json"


def start(path: Path, now: float = 0.0) -> AcgDrive:
    """Power the drive up on its state file."""
    return AcgDrive.with_state_file(path, now=now)


# --- the file ----------------------------------------------------------------------------------

def test_round_trip_and_format(path: Path) -> None:
    save_state(path, "acg", "ACG-ET2", {0x1F01: 200, 0x1717: 4})
    document = json.loads(path.read_text())
    assert document == {"format": STATE_FORMAT, "version": STATE_VERSION, "family": "acg", "model": "ACG-ET2",
                        "parameters": {"0x1717": 4, "0x1F01": 200}}
    assert load_state(path, "acg") == {0x1F01: 200, 0x1717: 4}


def test_missing_file_means_nothing_saved(path: Path) -> None:
    assert load_state(path, "acg") == {}


def test_write_is_atomic(path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    save_state(path, "acg", "ACG-ET2", {0x1F01: 200})
    original = path.read_bytes()

    def failing_replace(source: str, target: str) -> None:
        raise OSError("disk gone")

    monkeypatch.setattr(state.os, "replace", failing_replace)
    with pytest.raises(OSError, match="disk gone"):
        save_state(path, "acg", "ACG-ET2", {0x1F01: 300})
    assert path.read_bytes() == original                 # the old file is untouched
    assert sorted(p.name for p in path.parent.iterdir()) == [path.name]   # no temporary left


def test_write_syncs_before_renaming(path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    events: list[str] = []
    real_fsync, real_replace = os.fsync, os.replace
    monkeypatch.setattr(state.os, "fsync", lambda fd: (events.append("fsync"), real_fsync(fd))[1])
    monkeypatch.setattr(state.os, "replace", lambda a, b: (events.append("replace"), real_replace(a, b))[1])
    save_state(path, "acg", "ACG-ET2", {0x1F01: 200})
    assert events[:2] == ["fsync", "replace"]
    temporary_dir_entries = [p for p in path.parent.iterdir() if p.name != path.name]
    assert temporary_dir_entries == []


@pytest.mark.parametrize(("content", "message"), [
    (b"", "empty file"),
    (b'{"format": "cipstack.drive-state", "version": 1, "fam', "not valid JSON"),
    (b"\xff\xfe\x00garbage", "not UTF-8"),
    (b"[1, 2, 3]", "not a cipstack drive state file"),
    (b'{"format": "other", "version": 1, "family": "acg", "parameters": {}}', "not a cipstack drive state file"),
    (b'{"format": "cipstack.drive-state", "version": 2, "family": "acg", "parameters": {}}', "version 2"),
    (b'{"format": "cipstack.drive-state", "version": 1, "family": "mx2", "model": "MX2-A2015-E", '
     b'"parameters": {}}', "'mx2' drive"),
    (b'{"format": "cipstack.drive-state", "version": 1, "family": "acg"}', '"parameters"'),
    (b'{"format": "cipstack.drive-state", "version": 1, "family": "acg", "parameters": {"ACC": 5}}', "'ACC'"),
    (b'{"format": "cipstack.drive-state", "version": 1, "family": "acg", "parameters": {"0x1F01": "5"}}',
     "'0x1F01'"),
    (b'{"format": "cipstack.drive-state", "version": 1, "family": "acg", "parameters": {"0x1F01": true}}',
     "'0x1F01'"),
])
def test_unusable_files_are_refused(path: Path, content: bytes, message: str) -> None:
    path.write_bytes(content)
    with pytest.raises(StateFileError) as raised:
        load_state(path, "acg")
    text = str(raised.value)
    assert message in text and str(path) in text and "\n" not in text


def test_truncated_file_is_refused(path: Path) -> None:
    save_state(path, "acg", "ACG-ET2", {0x1F01: 200, 0x1F02: 300})
    whole = path.read_bytes()
    for length in (1, len(whole) // 2, len(whole) - 3):
        path.write_bytes(whole[:length])
        with pytest.raises(StateFileError):
            load_state(path, "acg")


# --- default location --------------------------------------------------------------------------

def test_default_path_uses_the_user_data_directory(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    expected_root = Path(__import__("platformdirs").user_data_dir("cipstack", appauthor=False))
    assert default_state_path("acg") == expected_root / "state" / "acg.json"
    if sys.platform.startswith("linux"):
        assert default_state_path("acg").is_relative_to(tmp_path / "data")


def test_default_path_without_platformdirs(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setitem(sys.modules, "platformdirs", None)   # import fails
    monkeypatch.setenv("HOME", str(tmp_path))
    assert default_state_path("bench-2") == tmp_path / ".local" / "share" / "cipstack" / "state" / "bench-2.json"


@pytest.mark.parametrize("profile", ["", "../etc", "a/b", ".hidden", "a b"])
def test_default_path_refuses_odd_profile_names(profile: str) -> None:
    with pytest.raises(ValueError):
        default_state_path(profile)


# --- the save rule across a restart -------------------------------------------------------------

def test_saved_value_survives_and_unsaved_one_does_not(path: Path) -> None:
    drive = start(path)
    drive.write(ACC, 200, 1)
    drive.write(SAVE, 1, 2)                       # 0 -> 1: save
    drive.write(DEC, 300, 3)                      # written after the save
    assert drive.read(DEC) == 300                 # in effect now
    restarted = start(path)
    assert restarted.read(ACC) == 200
    assert restarted.read(DEC) == 100             # back to its previous (default) value
    assert restarted.read(SAVE) == 0


def test_one_to_zero_does_not_save(path: Path) -> None:
    drive = start(path)
    drive.write(SAVE, 1, 0)                       # saves the defaults
    drive.write(ACC, 200, 1)
    drive.write(SAVE, 0, 2)                       # 1 -> 0: no save
    assert start(path).read(ACC) == 50


def test_one_over_one_does_not_save_again(path: Path) -> None:
    drive = start(path)
    drive.write(SAVE, 1, 0)
    drive.write(ACC, 200, 1)
    drive.write(SAVE, 1, 2)                       # 1 -> 1: nothing
    assert start(path).read(ACC) == 50
    drive.write(SAVE, 0, 3)
    drive.write(SAVE, 1, 4)                       # 0 -> 1 again: saved
    assert start(path).read(ACC) == 200


def test_nothing_saved_means_factory_values(path: Path) -> None:
    drive = start(path)
    drive.write(ACC, 200, 1)
    assert not path.exists()
    assert start(path).read(ACC) == 50


def test_save_is_refused_while_running(path: Path) -> None:
    drive = start(path)
    drive.write(addr("drv"), 4, 0)
    drive.write(addr("0.00"), 3000, 0)
    drive.set_run_command(True, False, 0)
    with pytest.raises(RegisterError) as raised:
        drive.write(SAVE, 1, 1)
    assert raised.value.refusal is RegisterRefusal.NOT_WHILE_RUNNING
    assert not path.exists()


def test_network_frequency_is_not_saved_keypad_frequency_is(path: Path) -> None:
    # ACG RS-485 manual: a frequency set at 0x0380 is not saved even with the save function; the
    # parameter-area frequency is.
    drive = start(path)
    drive.write(0x0380, 4000, 0)
    drive.write(addr("0.00"), 2500, 0)
    drive.write(SAVE, 1, 1)
    restarted = start(path)
    assert restarted.read(0x0380) == 0
    assert restarted.read(addr("0.00")) == 2500


def test_saved_alias_write(path: Path) -> None:
    drive = start(path)
    drive.write(0x0383, 70, 0)                    # control area acceleration time is ACC
    drive.write(SAVE, 1, 1)
    assert start(path).read(ACC) == 70
    assert load_state(path, "acg")[ACC] == 70


def test_comm_update_saves_and_activates(path: Path) -> None:
    drive = start(path)
    drive.write(addr("CM.23"), 5, 0)
    drive.write(addr("CM.7"), 20, 0)
    drive.write(addr("CM.94"), 1, 1)
    restarted = start(path)
    assert restarted.active_comm_settings.input_instance.instance == 142
    assert restarted.active_comm_settings.station_id == 20
    assert restarted.read(addr("CM.30")) == 2
    assert not restarted.comm_update_pending


def test_pending_comm_setting_is_lost_at_restart(path: Path) -> None:
    drive = start(path)
    drive.write(addr("CM.23"), 5, 0)              # neither CM.94 nor a save
    restarted = start(path)
    assert restarted.read(addr("CM.23")) == 1
    assert restarted.active_comm_settings.input_instance.instance == 71


def test_saved_but_not_updated_comm_setting_is_active_after_restart(path: Path) -> None:
    # The card reads the drive's CM parameters when it powers up.
    drive = start(path)
    drive.write(addr("CM.24"), 2, 0)
    drive.write(SAVE, 1, 1)
    assert drive.active_comm_settings.output_instance.instance == 21
    assert start(path).active_comm_settings.output_instance.instance == 100


def test_parameter_initialization_is_saved(path: Path) -> None:
    drive = start(path)
    drive.write(ACC, 200, 0)
    drive.write(addr("Pr.12"), 2, 0)
    drive.write(SAVE, 1, 1)
    drive.write(0x03E2, 14, 2)                    # initialize the operation group
    assert drive.read(ACC) == 50
    restarted = start(path)
    assert restarted.read(ACC) == 50              # the initialization was saved
    assert restarted.read(addr("Pr.12")) == 2     # other groups keep their saved values


def test_corrupt_state_file_stops_the_drive(path: Path) -> None:
    path.write_text('{"format": "cipstack.drive-state", "version": 1, "family": "acg", "param')
    with pytest.raises(StateFileError, match="not valid JSON"):
        start(path)


def test_foreign_state_file_stops_the_drive(path: Path) -> None:
    save_state(path, "mx2", "MX2-A2015-E", {0x1F01: 1})
    with pytest.raises(StateFileError, match="'mx2' drive"):
        start(path)


@pytest.mark.parametrize(("address", "value", "message"), [
    (0x0311, 5, "not a saved parameter"),         # a monitor
    (0x0007, 5, "not a saved parameter"),         # an alias: ACC is saved at 0x1F01
    (0x4000, 5, "not a saved parameter"),         # no such register
    (0x1F01, 60001, "out of range"),              # ACC beyond 6000.0 s
])
def test_state_file_with_values_the_drive_cannot_hold(path: Path, address: int, value: int, message: str) -> None:
    save_state(path, "acg", "ACG-ET2", {address: value})
    with pytest.raises(StateFileError, match=message):
        start(path)


def test_parameter_store_is_the_drive_memory(path: Path) -> None:
    store = ParameterStore(path, "acg", "ACG-ET2")
    drive = AcgDrive(store.load(), on_save=store.save)
    drive.write(ACC, 120, 0)
    drive.write(SAVE, 1, 0)
    assert store.load() == drive.saved_parameters
    assert store.load()[ACC] == 120
    assert json.loads(path.read_text())["model"] == "ACG-ET2"


def test_factory_leaves_the_users_saved_drive_alone(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """What a new user met: a docs script saved ACC = 2.5 s, and the tour's `cipstack get` then said
    2.5 s where the README says 5.0 s. `cipstack adapter --factory` starts from factory settings, a
    save there (here `params load`, which saves with 0x03E0) lasts until it stops, and the user's
    state file is neither read nor written; the next `cipstack adapter` comes back with the user's save."""
    from tests.library_support import run_cli
    from tests.test_cli import start_adapter, stop

    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    users = default_state_path("acg")
    assert str(users).startswith(str(tmp_path / "data"))
    users.parent.mkdir(parents=True)
    save_state(users, FAMILY, MODEL, {addr("ACC"): 25})
    before = users.read_bytes()

    address, process = start_adapter("--factory")
    try:
        assert run_cli("get", address, "0x2A/1/102").stdout == "Acceleration Time = 5.0 s (50)\n"
        recipe = tmp_path / "drive.toml"
        assert run_cli("params", "dump", address, "-o", str(recipe)).returncode == 0
        text = recipe.read_text()
        assert "raw = 50" in text
        changed = tmp_path / "changed.toml"
        changed.write_text(text.replace("raw = 50", "raw = 75", 1))
        loaded = run_cli("params", "load", address, str(changed))
        assert loaded.returncode == 0 and loaded.stdout.splitlines()[-1].endswith(", saved"), loaded.stdout
        assert run_cli("get", address, "0x2A/1/102").stdout == "Acceleration Time = 7.5 s (75)\n"
    finally:
        log = stop(process)
    assert f"factory settings: saves last until the emulator stops; {users} is not read or written" in log
    assert users.read_bytes() == before

    address, process = start_adapter()
    try:
        assert run_cli("get", address, "0x2A/1/102").stdout == "Acceleration Time = 2.5 s (25)\n"
    finally:
        log = stop(process)
    assert f"saved parameters in {users} (--factory starts without them)" in log
    refused = run_cli("adapter", "--factory", "--state", str(tmp_path / "other.json"))
    assert refused.returncode == 2 and refused.stderr.strip().endswith("--factory reads and writes no state "
                                                                        "file: drop --state FILE")
