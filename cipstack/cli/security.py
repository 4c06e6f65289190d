"""``cipstack security``: CIP Security's credentials (``cipstack.security.provisioning``)."""

from __future__ import annotations

import argparse
import json

from .common import EXIT_OK, UsageError


def cmd_security_init(args: argparse.Namespace) -> int:
    from ..security.provisioning import init

    if args.days < 1:
        raise UsageError(f"--days {args.days}: must be 1 or more")
    written = init(args.folder, certificates=not args.psk_only, psk=args.psk or args.psk_only, force=args.force,
                   days=args.days)
    for path in written:
        if args.json:
            print(json.dumps({"written": str(path)}))
        else:
            print(path)
    return EXIT_OK
