"""Class 1 by the field names an EDS file gives: any device with an EDS, no profile needed.

Usage: ``python3 eds_io.py EDS_FILE [HOST]``. Against the default emulator (``cipstack adapter``),
with the EDS file it generates: ``cipstack eds generate --profile acg -o eds``, then
``python3 eds_io.py eds/ACG-ET2_1.01.eds``.
"""

import sys

from cipstack import SyncScanner, read_eds

eds = read_eds(sys.argv[1])
host = sys.argv[2] if len(sys.argv) > 2 else "127.0.0.1"

with SyncScanner(host, eds=eds) as device:                  # decode by the file's parameters
    print("declarations:", device.catalog.source)
    with device.io_connection_from_eds(eds, 1) as io:       # Connection1 of the file
        print("output fields:", ", ".join(sorted(io.output.field_names)))
        print("input fields:", ", ".join(sorted(io.input.field_names)))
        io.update(fault_reset=True)                         # a field named after its ParamN
        image = io.wait_input(lambda i: i.ready, timeout=5)
        print("input:", image.fields())
