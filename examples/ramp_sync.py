"""Run the drive at 45 Hz over class 1 by field names, and time its ramps (blocking code).

Against the emulator started as the README's tour starts it, with the network as command and
frequency source, from factory settings (what it writes leaves the saved drive alone):
``cipstack adapter --factory --param drv=4 --param Frq=8``. Usage: ``python3 ramp_sync.py [HOST]``.
"""

import sys
import time

from cipstack import SyncScanner, discover_blocking

host = sys.argv[1] if len(sys.argv) > 1 else "127.0.0.1"

for device in discover_blocking(host, timeout=1.0):       # UDP ListIdentity
    print("found", device.product_name, "vendor", device.vendor_id, "product code", device.product_code)

with SyncScanner(host) as drive:                           # identifies the drive: values come decoded
    print("output frequency", drive.read(0x2A, 1, 100))     # Actual Hz: 0.00 Hz
    drive.write(0x2A, 1, 102, 2.0, scaled=True)            # ACC: 0 to 60 Hz in 2.0 s
    drive.write(0x2A, 1, 103, 2.0, scaled=True)            # dEC: 60 Hz to 0 in 2.0 s

    # Output 21 / input 71 (Extended Speed Control): speeds in rpm, 1350 rpm = 45 Hz on a 4-pole motor.
    with drive.io_connection(output=21, input=71, rpi=0.010) as io:
        started = time.monotonic()
        io.update(run_forward=True, speed_reference=1350)
        io.wait_input(lambda i: i.at_reference, timeout=10)
        print(f"up to 45 Hz in {time.monotonic() - started:.2f} s")           # 45/60 of 2.0 s: 1.5 s

        started = time.monotonic()
        io.update(run_forward=False)
        io.wait_input(lambda i: i.speed_actual == 0, timeout=10)
        print(f"down to 0 Hz in {time.monotonic() - started:.2f} s")
        print("lost", io.statistics()["lost"], "packets")
    # Leaving the block sent the Forward_Close; the drive stopped before that.
    print("output frequency", drive.read(0x2A, 1, 100))
