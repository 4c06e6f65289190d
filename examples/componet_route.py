"""Talk to an Omron MX2 on CompoNet through the EtherNet/IP gateway: every request is routed
(Unconnected_Send, port 2 = CompoNet, link = the node address), and the scanner identifies the node
itself, so its values come decoded by the MX2's declarations.

Against ``cipstack componet --nodes mx2:MX2-A2015-E@3``. Usage: ``python3 componet_route.py [HOST]``.
"""

import sys

from cipstack import SyncScanner, componet_route

host = sys.argv[1] if len(sys.argv) > 1 else "127.0.0.1"

with SyncScanner(host) as gateway:
    print("gateway:", gateway.read(0x01, 1, 7))                       # its own Identity

with SyncScanner(host, route=componet_route(3)) as node:
    print("node 3:", node.read(0x01, 1, 7), "-", node.catalog.source)
    print("accel time:", node.read(0x2A, 1, 0x12))                    # Table D-7: ms
    node.write(0x2A, 1, 0x12, 2500)                                   # 2.5 s
    print("accel time now:", node.read(0x2A, 1, 0x12))
    print("output current:", node.read(0x2A, 1, 0x09))                # Table D-7: 0.1 A
