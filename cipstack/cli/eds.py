"""cipstack eds: check, generate, show."""

from __future__ import annotations

import argparse

from ..cip.status import CipError


# -- EDS ----------------------------------------------------------------------------------------------------
def cmd_eds_check(args: argparse.Namespace) -> int:
    from ..eds.commands import run_check

    identity = None
    if args.against:
        from ..scanner import SyncScanner

        with SyncScanner(args.against, timeout=args.timeout) as scanner:
            _, values = scanner.get_attributes_all(0x01, 1)
        if values is None:
            raise CipError(0x1F, message=f"{args.against}: Identity reply could not be decoded")
        identity = {"vendor_id": values["Vendor ID"], "device_type": values["Device Type"],
                    "product_code": values["Product Code"],
                    "revision": (values["Revision"]["major"], values["Revision"]["minor"]),
                    "product_name": values["Product Name"]}
    return run_check(args, identity)


def cmd_eds_generate(args: argparse.Namespace) -> int:
    from ..eds.commands_generate import run_generate

    return run_generate(args)


def cmd_eds_show(args: argparse.Namespace) -> int:
    from ..eds.commands import run_show

    return run_show(args)
