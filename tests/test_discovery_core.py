"""Discovery's one query without sockets (``discovery_core.UdpQuery``), and its blocking form, which
runs with no event loop (issue 54): the asyncio ``discover`` and ``discover_blocking`` are shells over it."""

from __future__ import annotations

import subprocess
import sys

from cipstack.eip.originator.discovery_core import MAX_DISCOVERY_REPLIES, UdpQuery, identities
from cipstack.eip.wire.cpf import SockAddr
from cipstack.eip.wire.encapsulation import HEADER, HEADER_SIZE, Command
from cipstack.eip.wire.identity_items import IdentityRecord, encode_list_identity

DRIVE = IdentityRecord(259, 2, 100, (1, 2), 0, 0x1234, "CENT")


def reply(record: IdentityRecord, command: int = Command.LIST_IDENTITY, status: int = 0) -> bytes:
    body = encode_list_identity(record, SockAddr("192.0.2.7", 44818))
    return HEADER.pack(command, len(body), 0, status, bytes(8), 0) + body


def test_the_query_its_datagrams_and_its_deadline() -> None:
    query = UdpQuery(Command.LIST_IDENTITY, ["192.0.2.255", "198.51.100.255"], 44818, 2.0, now=10.0)
    assert query.deadline == 12.0
    sent = query.datagrams()
    assert [destination for _, destination in sent] == [("192.0.2.255", 44818), ("198.51.100.255", 44818)]
    frame = sent[0][0]
    assert len(frame) == HEADER_SIZE and frame[:2] == b"\x63\x00"
    assert frame[12:14] == (1900).to_bytes(2, "little")        # the longest reply delay asked: timeout - 100 ms
    assert UdpQuery(Command.LIST_IDENTITY, "192.0.2.7", 44818, 0.2, now=0.0).datagrams()[0][0][12:14] == \
        (500).to_bytes(2, "little")                            # at least 500 ms


def test_replies_are_checked_bounded_and_told_apart() -> None:
    query = UdpQuery(Command.LIST_IDENTITY, "192.0.2.255", 44818, 1.0, now=0.0)
    query.receive(reply(DRIVE), ("192.0.2.7", 44818))
    query.receive(reply(DRIVE), ("192.0.2.7", 44818))                             # the same device twice
    query.receive(reply(DRIVE._replace(serial_number=7)), ("192.0.2.8", 44818))
    query.receive(reply(DRIVE, status=1), ("192.0.2.9", 44818))                   # an error status: dropped
    query.receive(reply(DRIVE, command=Command.LIST_SERVICES), ("192.0.2.9", 44818))   # another command
    query.receive(b"\x63\x00", ("192.0.2.9", 44818))                               # cut short
    found = identities(query.bodies())
    assert [(r.serial_number, r.product_name) for r in found] == [(0x1234, "CENT"), (7, "CENT")]
    for _ in range(MAX_DISCOVERY_REPLIES + 10):
        query.receive(b"", ("192.0.2.9", 1))
    assert len(query.replies) == MAX_DISCOVERY_REPLIES


def test_blocking_discovery_imports_no_asyncio() -> None:
    script = ("import sys; from cipstack.scanner import discover_blocking; "
              "discover_blocking('127.0.0.1', 9, timeout=0.05); print('asyncio' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60, check=True)
    assert done.stdout.strip() == "False"
