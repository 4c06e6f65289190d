"""A parameter recipe: dump every parameter of the drive, change one, see the difference, load the
recipe back (written, then saved). The same as ``cipstack params dump/diff/load``.

Against the emulator from factory settings (``cipstack adapter --factory``: the recipe's save then
lasts until it stops, and the saved drive, its state file, is left as it was).
Usage: ``python3 params_round_trip.py [HOST]``.
"""

import sys
import tempfile
from pathlib import Path

from cipstack import Scanner, diff_params, dump_params, load_params, read_recipe, run_precise, write_recipe


async def main(host: str) -> None:
    recipe_file = Path(tempfile.mkdtemp()) / "drive.toml"
    async with await Scanner.connect(host) as drive:
        recipe = await dump_params(drive)
        write_recipe(recipe_file, recipe)
        print(len(recipe), "parameters in", recipe_file.name)
        acc = next(item for item in recipe if item.code == "ACC")
        print("ACC in the recipe:", acc.value, acc.unit, f"(raw {acc.raw})")

        await drive.write(0x2A, 1, 102, 7.5, scaled=True)          # someone changes ACC on the drive
        for difference in await diff_params(drive, read_recipe(recipe_file)):
            print("differs:", difference.text())

        report = await load_params(drive, read_recipe(recipe_file))
        print("written:", [item.code for item in report.written], "saved:", report.saved)
        assert await diff_params(drive, read_recipe(recipe_file)) == []
        print("ACC now:", await drive.read(0x2A, 1, 102))


run_precise(main(sys.argv[1] if len(sys.argv) > 1 else "127.0.0.1"))
