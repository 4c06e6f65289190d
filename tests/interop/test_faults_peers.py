"""Faults seen by a peer nobody here wrote: pycomm3 against `cipstack adapter` in its own process,
the faults injected with `cipstack drive fault` over the control socket.

A refused Forward_Open carries the chosen Connection Manager status to pycomm3, twice, and the
next is accepted; a power cycle loses exactly the parameter that was written and not saved: on
the ACG (ACG RS-485 manual, "Saving Parameters Defined by Communication") and on an RX with its CompoNet
option board (CompoNet manual, section E-2-2 note: stored in EEPROM by the ENTER command only); replies
come after the chosen delay; a chosen general and extended status reaches it; after `close-tcp` or
`drop-sessions` its next request fails and a new connection works; while unplugged it cannot
connect, after `plug` it can."""

from __future__ import annotations

import contextlib
import logging
import signal
import struct
import time
from collections.abc import Iterator

import pytest

pytest.importorskip("pycomm3", reason="pycomm3, the peer these tests talk to, is not installed: pip install '.[test]'")

from pycomm3 import CIPDriver, CommError, Services
from pycomm3.cip.data_types import SHORT_STRING, UDINT, UINT

from cipstack.devices.acg.registers import CLASS_64_INSTANCES
from cipstack.devices.omron.registers import function_code_path
from tests.ports import free_port
from tests.test_cli import run
from tests.waiting import wait_for

from .conftest import HOST, IDENTITY, PeerProcess, adapter_command, start_peer
from .test_pycomm3 import get_single, ok, set_single

pytestmark = pytest.mark.interop

CM = CLASS_64_INSTANCES["CM"]
SAVE_PARAMETERS = 0x03E0


@pytest.fixture(scope="module")
def adapter(tmp_path_factory: pytest.TempPathFactory) -> Iterator[PeerProcess]:
    """``cipstack adapter`` of this module alone, with a state file of its own: what it saves (and its
    faults) reach no other test's adapter."""
    yield from adapter_with_state(tmp_path_factory, "acg.json")


def adapter_with_state(tmp_path_factory: pytest.TempPathFactory, state: str, *options: str) -> Iterator[PeerProcess]:
    """``cipstack adapter OPTIONS`` with a state file of its own, stopped cleanly at the end."""
    port = free_port()
    directory = tmp_path_factory.mktemp("faults-peers")
    peer = start_peer(" ".join(("cipstack adapter", *options)),
                      [*adapter_command(HOST, port), *options, "--state", str(directory / state)],
                      HOST, port, directory / "adapter.log")
    try:
        yield peer
    finally:
        code = peer.stop(signal.SIGTERM)
    assert code == 0, peer.log_text()
    assert "Traceback" not in peer.log_text(), peer.log_text()


def fault(adapter: PeerProcess, *args: str) -> None:
    result = run("drive", "fault", *args, "--host", adapter.host, "--port", str(adapter.port))
    assert result.returncode == 0, result.stderr


@pytest.fixture
def cleared(adapter: PeerProcess) -> Iterator[PeerProcess]:
    """The adapter, its faults cleared after the test whatever happened (a fault left active would
    reach the next test)."""
    try:
        yield adapter
    finally:
        fault(adapter, "clear")


def vendor_id(drv: CIPDriver) -> int:
    return ok(get_single(drv, 1, 1, 1, UINT))  # type: ignore[no-any-return]


def test_refused_forward_open_carries_the_chosen_status(adapter: PeerProcess,
                                                        caplog: pytest.LogCaptureFixture) -> None:
    """pycomm3 tries a connection twice (a Large_Forward_Open, then a Forward_Open): both refused."""
    fault(adapter, "refuse-forward-open", "0x0100", "--count", "2")
    drv = CIPDriver(adapter.address)
    drv.open()
    try:
        with caplog.at_level(logging.ERROR), pytest.raises(Exception, match="did not connect"):
            get_single(drv, 1, 1, 7, SHORT_STRING, connected=True)
        failures = [r.getMessage() for r in caplog.records if "forward_open failed" in r.getMessage()]
        assert len(failures) == 2 and all(f.endswith("Connection in use  (01, 100)") for f in failures), failures
    finally:
        drv.close()
    drv = CIPDriver(adapter.address)                                           # the third is accepted
    drv.open()
    try:
        assert ok(get_single(drv, 1, 1, 1, UINT, connected=True)) == IDENTITY["vendor_id"]
    finally:
        drv.close()


def write_register(drv: CIPDriver, address: int, value: int) -> None:
    """A drive register over CIP: named in CM.51, set through smart-scaling assembly 121 (ACG-ET2 manual)."""
    set_single(drv, 0x64, CM, 51, UINT.encode(address))
    set_single(drv, 0x04, 121, 3, UINT.encode(value))


def answers(peer: PeerProcess) -> bool:
    """Whether ``peer`` answers an explicit request (its power is back: the fault's command answers once
    the ports are closed, and when it waited for the power to come back depends on the machine's load)."""
    try:
        with CIPDriver(peer.address) as drv:
            return get_single(drv, 1, 1, 1, UINT).error is None
    except (CommError, OSError):
        return False


def test_power_cycle_loses_exactly_the_unsaved_parameter(adapter: PeerProcess) -> None:
    with CIPDriver(adapter.address) as drv:
        set_single(drv, 0x2A, 1, 102, UINT.encode(44))                        # ACC 4.4 s
        write_register(drv, SAVE_PARAMETERS, 0)
        write_register(drv, SAVE_PARAMETERS, 1)                               # 0 -> 1 saves every parameter
        set_single(drv, 0x2A, 1, 103, UINT.encode(66))                        # dEC 6.6 s, not saved
        before = (ok(get_single(drv, 0x2A, 1, 102, UINT)), ok(get_single(drv, 0x2A, 1, 103, UINT)))
        assert before == (44, 66)
        fault(adapter, "power-cycle", "--off", "200ms")
    wait_for(lambda: answers(adapter), 10, "the adapter to answer again")
    with CIPDriver(adapter.address) as drv:
        after = (ok(get_single(drv, 0x2A, 1, 102, UINT)), ok(get_single(drv, 0x2A, 1, 103, UINT)))
    assert after[0] == 44 and after[1] != 66


@pytest.fixture(scope="module")
def rx(tmp_path_factory: pytest.TempPathFactory) -> Iterator[PeerProcess]:
    """``cipstack adapter --model RX-A4055-E`` with a state file (its EEPROM) of its own."""
    yield from adapter_with_state(tmp_path_factory, "rx.json", "--model", "RX-A4055-E")


def test_power_cycle_of_an_rx_loses_exactly_what_was_not_entered(rx: PeerProcess) -> None:
    """Function codes through class 0x65 (Table E-3), the ENTER command through class 0x64 (0900h = 1):
    F002 entered survives, F003 written after it does not; pycomm3's session goes with the power. Before,
    the fault restarted the option board alone and F003 stayed."""
    f002, f003 = function_code_path("F002"), function_code_path("F003")
    drv = CIPDriver(rx.address)
    drv.open()
    try:
        ok(set_single(drv, 0x65, *f002, UDINT.encode(250)))                   # 2.50 s
        # ENTER: into EEPROM. Attribute 00h as a segment of its own: pycomm3 leaves an attribute id 0 out.
        ok(drv.generic_message(service=Services.set_attribute_single, class_code=0x64, instance=0x09,
                               attribute=b"\x00", request_data=UINT.encode(1), connected=False, route_path=False))
        ok(set_single(drv, 0x65, *f003, UDINT.encode(4321)))                  # 43.21 s, not entered
        assert ok(get_single(drv, 0x65, *f003, UDINT)) == 4321
        fault(rx, "power-cycle", "--off", "200ms")
        with pytest.raises((CommError, struct.error, AssertionError)):       # its session went with the power
            ok(get_single(drv, 0x65, *f003, UDINT))
    finally:
        with contextlib.suppress(CommError):                                  # nothing to close it on
            drv.close()
    wait_for(lambda: answers(rx), 10, "the RX to answer again")
    with CIPDriver(rx.address) as drv:
        after = ok(get_single(drv, 0x65, *f002, UDINT)), ok(get_single(drv, 0x65, *f003, UDINT))
        assert ok(get_single(drv, 0x01, 1, 9, UINT)) == 1                     # Identity 9 counted one save
    assert after == (250, 1000)                                               # F003 back at its default, 10 s


def test_delayed_replies_reach_pycomm3_after_the_delay(cleared: PeerProcess) -> None:
    with CIPDriver(cleared.address) as drv:
        fault(cleared, "delay-replies", "--by", "300ms")
        started = time.monotonic()
        assert vendor_id(drv) == IDENTITY["vendor_id"]
        delayed = time.monotonic() - started
        fault(cleared, "clear")
        started = time.monotonic()
        assert vendor_id(drv) == IDENTITY["vendor_id"]
        prompt = time.monotonic() - started
    assert 0.3 <= delayed < 0.5 and prompt < 0.2, (delayed, prompt)


def test_error_status_reaches_pycomm3_with_the_chosen_general_and_extended_status(cleared: PeerProcess) -> None:
    """Identity attribute 7 answered with general status 0x1F (vendor specific) and extended 0x1234;
    attribute 1 of the same object is not matched and answers as ever."""
    fault(cleared, "error-status", "--status", "0x1F/0x1234", "--class", "1", "--attribute", "7")
    with CIPDriver(cleared.address) as drv:
        reply = drv.generic_message(service=Services.get_attribute_single, class_code=1, instance=1, attribute=7,
                                    connected=False, route_path=False, return_response_packet=True).value
        # SendRRData reply: the CIP general status at byte 42, the size of the additional status in
        # words at 43, then the status words (CIP Vol. 1, 2-4.2).
        general, words, extended = reply.raw[42], reply.raw[43], UINT.decode(reply.raw[44:46])
        assert (general, words, extended) == (0x1F, 1, 0x1234), reply.raw.hex()
        assert vendor_id(drv) == IDENTITY["vendor_id"]
        fault(cleared, "clear")
        assert ok(get_single(drv, 1, 1, 7, SHORT_STRING)) == IDENTITY["product_name"]


def test_close_tcp_fails_pycomm3s_next_request_and_a_new_connection_works(cleared: PeerProcess) -> None:
    drv = CIPDriver(cleared.address)
    drv.open()
    try:
        assert vendor_id(drv) == IDENTITY["vendor_id"]
        fault(cleared, "close-tcp")
        # Its send meets the closed socket, or its read the end of the stream: either is a CommError.
        with pytest.raises(CommError, match=r"failed to (send message|receive reply)"):
            get_single(drv, 1, 1, 1, UINT)
    finally:
        with contextlib.suppress(CommError):                  # its UnregisterSession may fail as well
            drv.close()
    with CIPDriver(cleared.address) as drv:
        assert vendor_id(drv) == IDENTITY["vendor_id"]


def test_drop_sessions_fails_pycomm3s_next_request_and_a_new_session_works(cleared: PeerProcess) -> None:
    """The TCP connection stays; the session handle pycomm3 holds is no longer known: the reply carries
    encapsulation status 0x0064 (invalid session handle, CIP Vol. 2, 2-3.3)."""
    with CIPDriver(cleared.address) as drv:
        assert vendor_id(drv) == IDENTITY["vendor_id"]
        fault(cleared, "drop-sessions")
        reply = drv.generic_message(service=Services.get_attribute_single, class_code=1, instance=1, attribute=1,
                                    connected=False, route_path=False, return_response_packet=True).value
        assert not reply and UDINT.decode(reply.raw[8:12]) == 0x64, reply.raw.hex()
    with CIPDriver(cleared.address) as drv:
        assert vendor_id(drv) == IDENTITY["vendor_id"]


def test_unplugged_pycomm3_cannot_connect_until_plug(cleared: PeerProcess) -> None:
    fault(cleared, "unplug")
    with pytest.raises(CommError, match="failed to open a connection"), CIPDriver(cleared.address):
        pass
    fault(cleared, "plug")
    with CIPDriver(cleared.address) as drv:
        assert vendor_id(drv) == IDENTITY["vendor_id"]
