"""``cipstack security``: CIP Security's credentials (``cipstack.security.provisioning``)."""

from __future__ import annotations

import argparse
import json

from ..errors import CipstackError
from .common import EXIT_OK, UsageError, _emit


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


def cmd_security_configure(args: argparse.Namespace) -> int:
    """Configure a factory-default device over the network (``cipstack.security.push``), then check
    that it answers over TLS with the certificate just written."""
    import time

    from ..cip.types import BOOL, UINT
    from ..scanner import SyncScanner
    from ..security import Credentials
    from ..security.push import configure

    credentials = Credentials.load(args.security)
    if credentials.client is None:
        raise UsageError(f"{args.security}: no client.pem and client.key to check the device over TLS with")
    with SyncScanner(args.host, timeout=args.timeout, identify=False) as scanner:
        def request(service: int, class_id: int, instance: int, attribute: int | None,
                    data: bytes) -> tuple[int, tuple[int, ...], bytes]:
            reply = scanner.request(service, class_id, instance, attribute, data, check=False)
            return reply.general_status, reply.extended_status, reply.data

        steps: list[str] = []
        keys = ((credentials.psk.identity, credentials.psk.key),) if credentials.psk is not None else ()
        attributes = {number: BOOL.encode(1) for number, wanted in ((11, args.check_expiration),
                                                                   (10, args.send_chain)) if wanted}
        if args.dtls_timeout is not None:
            if not 1 <= args.dtls_timeout <= 0xFFFF:
                raise UsageError(f"--dtls-timeout {args.dtls_timeout}: 1 to 65535 seconds")
            attributes[15] = UINT.encode(args.dtls_timeout)
        crl = credentials.crl()   # the folder's CRL, when it has one: the device checks clients against it
        pushed = configure(request, args.security, common_name=args.common_name or "", step=steps.append,
                           pre_shared_keys=keys, attributes=attributes,
                           revocation_list=crl.read_bytes() if crl is not None else b"")
    host = args.host.rsplit(":", 1)[0] if args.host.count(":") == 1 else args.host
    secured = f"{host}:{args.security_port}"
    deadline = time.monotonic() + args.timeout
    while True:   # the device starts its TLS listener once Apply_Config is answered
        try:
            with SyncScanner(secured, security=credentials, timeout=args.timeout, identify=False) as check:
                identity = check.list_identity()
            break
        except CipstackError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.1)
    name = identity[0].product_name if identity else "device"
    _emit(args, {"configured": args.host, "steps": steps, "certificate_subject": pushed.subject, "tls": secured},
          f"{args.host} configured ({', '.join(steps)}); certificate {pushed.subject}; "
          f"{name} answers over TLS on {secured}")
    return EXIT_OK
