"""Drive parameter recipes (issue 26, item 6): dump every declared parameter to TOML, load it into
another drive (settable ones that differ, Max Freq first, refused while running unless forced, saved
with the ACG's 0x03E0 save: ACG RS-485 manual memory control, reached through CM.51 and output assembly 121,
ACG-ET2 manual), diff; the same functions in the library."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.devices.acg.device import build_acg_device
from cipstack.devices.omron.device import build_omron_device
from cipstack.eds.emulated_device import build_eds_device
from cipstack.eds.reader import parse_eds
from cipstack.objects.tcpip import NetworkInterface
from cipstack.params import (
    DriveRunningError,
    ParamValue,
    diff_params,
    dump_params,
    load_params,
    parse_recipe,
    read_recipe,
    recipe_text,
)
from cipstack.scanner import Scanner
from tests.library_support import run_cli, threaded_adapter
from tests.test_library_eds_catalog import SCALED_EDS

SETTINGS = AdapterSettings(host="127.0.0.1", port=0, io_port=0)


async def test_acg_recipe_round_trip_with_save(tmp_path: Path) -> None:
    source_state, target_state = tmp_path / "source.json", tmp_path / "target.json"
    async with Adapter(SETTINGS, device=build_acg_device(state_path=source_state)) as source, \
            await Scanner.connect(f"127.0.0.1:{source.port}") as scanner:
        await scanner.write(0x2A, 1, 102, 12.5, scaled=True)                    # ACC 12.5 s
        await scanner.write(0x64, 11, 13, 35)                                   # Pr.13 Lost Cmd Time 3.5 s
        recipe = await dump_params(scanner)
    by_code = {item.code: item for item in recipe}
    assert recipe[0].code == "dr.20"                                            # Max Freq first
    assert (by_code["ACC"].raw, by_code["ACC"].value, by_code["ACC"].unit) == (125, 12.5, "s")
    assert (by_code["Pr.13"].raw, by_code["Pr.13"].value) == (35, 3.5)
    text = recipe_text(recipe, {"product_name": "CENT"})
    def essentials(items: list[ParamValue]) -> list[tuple[object, ...]]:
        return [(i.code, i.name, i.path, i.raw, i.unit) for i in items]

    assert essentials(parse_recipe(text)) == essentials(recipe)
    async with Adapter(SETTINGS, device=build_acg_device(state_path=target_state)) as target, \
            await Scanner.connect(f"127.0.0.1:{target.port}") as scanner:
        differences = await diff_params(scanner, parse_recipe(text))
        assert {d.recipe.code for d in differences} == {"ACC", "Pr.13"}
        assert "ACC Acceleration Time: device 5.0 s (50), file 12.5 s (125)" in [d.text() for d in differences]
        report = await load_params(scanner, parse_recipe(text))
        assert {item.code for item in report.written} == {"ACC", "Pr.13"} and report.saved
        assert report.refused == [] and report.unchanged == len(recipe) - 2
        assert await diff_params(scanner, parse_recipe(text)) == []
        assert (await scanner.read(0x64, 7, 51)).raw == 5                       # CM.51 back to its value
    # The save made them survive a power cycle: a drive built anew from the state file has them.
    async with Adapter(SETTINGS, device=build_acg_device(state_path=target_state)) as restarted, \
            await Scanner.connect(f"127.0.0.1:{restarted.port}") as scanner:
        assert str(await scanner.read(0x2A, 1, 102)) == "12.5 s"
        assert (await scanner.read(0x64, 11, 13)).raw == 35


async def test_load_refuses_while_the_drive_runs_unless_forced() -> None:
    adapter = Adapter(SETTINGS, device=build_acg_device())
    adapter.apply_keypad_parameters(["drv=4", "Frq=8"])
    async with adapter, await Scanner.connect(f"127.0.0.1:{adapter.port}") as scanner:
        recipe = await dump_params(scanner)
        await scanner.write(0x2A, 1, 102, 20)
        await scanner.write(0x2A, 1, 101, 1000)                                 # Reference Hz 10.00 Hz
        await scanner.write(0x29, 1, 3, 1)                                      # Forward Run Cmd 0 -> 1
        assert (await scanner.read(0x29, 1, 7)).raw == 1                        # Running Forward
        with pytest.raises(DriveRunningError):
            await load_params(scanner, recipe)
        assert (await scanner.read(0x2A, 1, 102)).raw == 20                     # nothing written
        report = await load_params(scanner, recipe, force=True, save=False)
        assert [item.code for item in report.written] == ["ACC"] and not report.saved
        assert (await scanner.read(0x2A, 1, 102)).raw == 50


async def test_omron_recipe_by_function_codes() -> None:
    """MX2: the function codes of class 0x65 (CompoNet manual, section E-2-2), A004 first; no save command."""
    async with Adapter(SETTINGS, device=build_omron_device("MX2-A2015-E")) as adapter, \
            await Scanner.connect(f"127.0.0.1:{adapter.port}") as scanner:
        recipe = await dump_params(scanner)
        assert recipe[0].code == "A004"
        f002 = next(item for item in recipe if item.code == "F002")
        assert f002.unit == "s" and f002.value == round(f002.raw * 0.01, 9)
        changed = [replace(i, raw=i.raw + 100) if i.code == "F002" else i for i in recipe]
        report = await load_params(scanner, changed)
        assert [item.code for item in report.written] == ["F002"] and not report.saved
        assert (await scanner.read(*f002.path)).raw == f002.raw + 100


async def test_eds_recipe(tmp_path: Path) -> None:
    eds = tmp_path / "fc10.eds"
    eds.write_text(SCALED_EDS)
    device = build_eds_device(parse_eds(SCALED_EDS), NetworkInterface(ip_address="127.0.0.1"))
    async with Adapter(SETTINGS, device=device) as adapter:
        async with await Scanner.connect(f"127.0.0.1:{adapter.port}", eds=eds) as scanner:
            recipe = await dump_params(scanner)
            assert [(i.code, i.raw, i.value) for i in recipe if i.code in ("Param1", "Param8")] == [
                ("Param1", 120, 12.0), ("Param8", 100, 30.0)]
        async with await Scanner.connect(f"127.0.0.1:{adapter.port}") as plain:
            with pytest.raises(LookupError, match="no parameters are declared in the standard objects only: no "
                                                  "profile for vendor 1234"):
                await dump_params(plain)


def test_cli_params(tmp_path: Path) -> None:
    recipe = tmp_path / "drive.toml"
    with threaded_adapter(build_acg_device(), params=("drv=4", "Frq=8")) as adapter:
        address = f"127.0.0.1:{adapter.port}"
        dumped = run_cli("params", "dump", address, "-o", str(recipe))
        assert dumped.returncode == 0 and dumped.stderr.strip() == "409 parameters written to " + str(recipe)
        assert run_cli("params", "diff", address, str(recipe)).stdout.strip() == "no differences (409 parameters)"
        assert run_cli("set", address, "0x2A/1/102", "9.9", "--scaled").returncode == 0
        diff = run_cli("params", "diff", address, str(recipe))
        assert diff.returncode == 1
        assert diff.stdout.strip() == "ACC Acceleration Time: device 9.9 s (99), file 5.0 s (50)"
        assert run_cli("set", address, "0x29/1/3", "on").returncode == 0                  # run
        refused = run_cli("params", "load", address, str(recipe))
        assert refused.returncode == 1 and "the drive is running" in refused.stderr and "--force" in refused.stderr
        loaded = run_cli("params", "load", address, str(recipe), "--force")
        assert loaded.returncode == 0, loaded.stderr
        assert loaded.stdout.splitlines() == ["set ACC Acceleration Time = 5.0 s (50)",
                                              "1 written, 408 unchanged, 0 refused, saved"]
    assert read_recipe(recipe)[1].code == "ACC"
    broken = tmp_path / "broken.toml"
    broken.write_text("[[parameter]]\nname = 'x'\n")
    result = run_cli("params", "diff", "127.0.0.1:1", str(broken))
    assert result.returncode == 2 and "parameter 1: needs path" in result.stderr
