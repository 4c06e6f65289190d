"""The ramp script of ``ramp_sync.py`` with the async ``Scanner``, on the precise event loop.

Against ``cipstack adapter --factory --param drv=4 --param Frq=8`` (from factory settings: what it
writes leaves the saved drive alone). Usage: ``python3 ramp_async.py [HOST]``.
"""

import sys
import time

from cipstack import Scanner, discover, run_precise


async def main(host: str) -> None:
    for device in await discover(host, timeout=1.0):
        print("found", device.product_name, "vendor", device.vendor_id, "product code", device.product_code)

    async with await Scanner.connect(host) as drive:
        print("output frequency", await drive.read(0x2A, 1, 100))
        await drive.write(0x2A, 1, 102, 2.0, scaled=True)
        await drive.write(0x2A, 1, 103, 2.0, scaled=True)

        async with drive.io_connection(output=21, input=71, rpi=0.010) as io:
            started = time.monotonic()
            io.output.update(run_forward=True, speed_reference=1350)
            await io.wait_input(lambda i: i.at_reference, timeout=10)
            print(f"up to 45 Hz in {time.monotonic() - started:.2f} s")

            started = time.monotonic()
            io.output.run_forward = False
            await io.wait_input(lambda i: i.speed_actual == 0, timeout=10)
            print(f"down to 0 Hz in {time.monotonic() - started:.2f} s")
            print("lost", io.statistics()["lost"], "packets")
        print("output frequency", await drive.read(0x2A, 1, 100))


run_precise(main(sys.argv[1] if len(sys.argv) > 1 else "127.0.0.1"))
