"""The TLS port's sans-I/O layer (``cipstack.security.tls_session.TlsSession``): records as a stream
brings them, without sockets. The originator is the standard library's ``SSLObject`` with the lab
folder's client certificate; the target's connection is a real adapter's (not listening).

Both shells of the TLS port (asyncio's transports, the precise loop's lane) feed the session what
the socket read: these cases are what a socket can bring in one read, or split over several."""

from __future__ import annotations

import contextlib
import ssl
import struct
from pathlib import Path

import pytest

pytest.importorskip("cryptography", reason="the security extra (cryptography) is not installed")

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.eip.wire.cpf import SockAddr
from cipstack.security import Credentials
from cipstack.security.tls_session import TlsSession

HEADER = struct.Struct("<HHII8sI")
#: RegisterSession, protocol version 1, no options.
REGISTER = HEADER.pack(0x0065, 4, 0, 0, b"cipstack", 0) + b"\x01\x00\x00\x00"
#: Get_Attribute_Single of Identity 1/1/7 (product name).
GET_NAME = bytes((0x0E, 0x03, 0x20, 0x01, 0x24, 0x01, 0x30, 0x07))


def send_rr_data(session: int, context: bytes) -> bytes:
    body = struct.pack("<IHHHHHH", 0, 0, 2, 0, 0, 0xB2, len(GET_NAME)) + GET_NAME
    return HEADER.pack(0x006F, len(body), session, 0, context, 0) + body


def replies(plain: bytes) -> list[tuple[int, int, bytes, bytes]]:
    """(command, status, sender context, the reply's last bytes) of each frame in ``plain``."""
    found = []
    while plain:
        command, length, _session, status, context, _options = HEADER.unpack_from(plain)
        found.append((command, status, context, plain[24:24 + length][-5:]))
        plain = plain[24 + length:]
    return found


class Originator:
    """The client's side of TLS in memory."""

    def __init__(self, credentials: Credentials, maximum: ssl.TLSVersion | None = None) -> None:
        context = credentials.client_context()
        if maximum is not None:
            context.maximum_version = maximum
        self.incoming, self.outgoing = ssl.MemoryBIO(), ssl.MemoryBIO()
        self.tls = context.wrap_bio(self.incoming, self.outgoing, server_side=False)

    def records(self, plain: bytes) -> bytes:
        self.tls.write(plain)
        return self.outgoing.read()

    def read(self, ciphertext: bytes) -> bytes:
        self.incoming.write(ciphertext)
        chunks = []
        try:
            while True:
                chunks.append(self.tls.read(65536))
        except ssl.SSLWantReadError:
            pass
        return b"".join(chunks)


@pytest.fixture
def adapter(lab: Path) -> Adapter:
    return Adapter(AdapterSettings(port=0, io_port=0, security=lab, security_port=0))


@pytest.fixture
def psk_lab(tmp_path: Path) -> Path:
    """A folder of a pre-shared key alone: the session's TLS layer is pyOpenSSL's (``tls_psk``)."""
    from cipstack.security.provisioning import init

    folder = tmp_path / "psk"
    init(folder, certificates=False, psk=True)
    return folder


def connected(adapter: Adapter, lab: Path, maximum: ssl.TLSVersion | None = None) -> tuple[TlsSession, Originator]:
    """A session after its handshake, pumped in memory; the originator's first flight after it is
    in the session already (TLS 1.3: the client's Finished)."""
    assert adapter.tls is not None
    local = SockAddr("127.0.0.1", 2221)
    session = adapter.tls.session("127.0.0.1:50000", local)
    originator = Originator(Credentials.load(lab), maximum)
    for _ in range(10):
        try:
            originator.tls.do_handshake()
            done = True
        except ssl.SSLWantReadError:
            done = False
        flight = originator.outgoing.read()
        if flight:
            assert session.receive(flight, 0.0) == b""
            originator.incoming.write(session.data_to_send())
        if done and session.connection is not None:
            break
    assert session.connection is not None and session.refusal is None
    return session, originator


def register(session: TlsSession, originator: Originator) -> int:
    session.send(session.receive(originator.records(REGISTER), 0.0))
    reply = originator.read(session.data_to_send())
    return int(HEADER.unpack_from(reply)[2])


@pytest.mark.parametrize("maximum", [None, ssl.TLSVersion.TLSv1_2], ids=["tls1.3", "tls1.2"])
def test_two_records_in_one_read_are_both_served(adapter: Adapter, lab: Path, maximum: ssl.TLSVersion | None) -> None:
    session, originator = connected(adapter, lab, maximum)
    handle = register(session, originator)
    both = originator.records(send_rr_data(handle, b"first\x00\x00\x00")) + originator.records(
        send_rr_data(handle, b"second\x00\x00"))
    session.send(session.receive(both, 0.0))
    assert replies(originator.read(session.data_to_send())) == [
        (0x006F, 0, b"first\x00\x00\x00", b"\x04CENT"), (0x006F, 0, b"second\x00\x00", b"\x04CENT")]


def test_two_records_in_one_read_are_both_served_with_a_pre_shared_key(psk_lab: Path) -> None:
    """pyOpenSSL takes every octet of the read at once: the records after the first still count as
    waiting (``TlsObject.pending``), so both are served now, not at the next read."""
    adapter = Adapter(AdapterSettings(port=0, io_port=0, security=psk_lab, security_port=0))
    session, originator = connected(adapter, psk_lab)
    handle = register(session, originator)
    both = originator.records(send_rr_data(handle, b"first\x00\x00\x00")) + originator.records(
        send_rr_data(handle, b"second\x00\x00"))
    session.send(session.receive(both, 0.0))
    assert replies(originator.read(session.data_to_send())) == [
        (0x006F, 0, b"first\x00\x00\x00", b"\x04CENT"), (0x006F, 0, b"second\x00\x00", b"\x04CENT")]


def test_a_record_split_over_many_reads_is_served_once_whole(adapter: Adapter, lab: Path) -> None:
    session, originator = connected(adapter, lab)
    handle = register(session, originator)
    record = originator.records(send_rr_data(handle, b"pieces\x00\x00"))
    for index in range(len(record) - 1):   # every byte but the last: nothing to serve yet
        assert session.receive(record[index:index + 1], 0.0) == b""
        assert session.data_to_send() == b""
    session.send(session.receive(record[-1:], 0.0))
    assert replies(originator.read(session.data_to_send())) == [(0x006F, 0, b"pieces\x00\x00", b"\x04CENT")]


def test_a_request_and_close_notify_in_one_read_are_answered_then_ended(adapter: Adapter, lab: Path) -> None:
    session, originator = connected(adapter, lab)
    handle = register(session, originator)
    request = originator.records(send_rr_data(handle, b"lastword"))
    with contextlib.suppress(ssl.SSLWantReadError):   # our close_notify is written; the target's has not come
        originator.tls.unwrap()
    session.send(session.receive(request + originator.outgoing.read(), 0.0))
    assert session.ended
    session.close_notify()   # as the shells answer it, after the replies
    originator.incoming.write(session.data_to_send())
    assert replies(originator.tls.read(65536)) == [(0x006F, 0, b"lastword", b"\x04CENT")]
    originator.tls.unwrap()   # the target's close_notify has come: no SSLWantReadError now
    assert session.receive(request, 0.0) == b"" and session.data_to_send() == b""   # nothing after it


def test_plain_enip_on_the_tls_port_is_refused_and_what_follows_is_dropped(adapter: Adapter) -> None:
    assert adapter.tls is not None
    session = adapter.tls.session("127.0.0.1:50000", SockAddr("127.0.0.1", 2221))
    assert session.receive(REGISTER, 0.0) == b""
    assert session.connection is None
    assert session.refusal is not None and "wrong version number" in session.refusal
    session.data_to_send()   # whatever the TLS library says to a peer that does not speak TLS
    assert session.receive(REGISTER, 0.0) == b"" and session.data_to_send() == b""
    assert session.connection is None


def test_a_client_certificate_of_another_ca_is_refused(adapter: Adapter, other_lab: Path) -> None:
    """TLS 1.2: the target judges the client's certificate within the handshake, and says why."""
    assert adapter.tls is not None
    session = adapter.tls.session("127.0.0.1:50000", SockAddr("127.0.0.1", 2221))
    stranger = Credentials.load(other_lab).client_context()
    stranger.maximum_version = ssl.TLSVersion.TLSv1_2
    stranger.verify_mode = ssl.CERT_NONE   # the target's certificate is not the point here
    incoming, outgoing = ssl.MemoryBIO(), ssl.MemoryBIO()
    originator = stranger.wrap_bio(incoming, outgoing, server_side=False)
    for _ in range(10):
        try:
            originator.do_handshake()
        except ssl.SSLWantReadError:
            pass
        except ssl.SSLError:
            break
        session.receive(outgoing.read(), 0.0)
        incoming.write(session.data_to_send())
        if session.refusal is not None:
            break
    assert session.connection is None
    assert session.refusal is not None and "certificate verify failed" in session.refusal
