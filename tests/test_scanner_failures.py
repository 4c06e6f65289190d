"""Each way a scanner's call can fail, on both scanners (``Scanner``, asyncio; ``SyncScanner``,
blocking): the error is a ``CipstackError`` of the kind that says what went wrong, keeps the builtin
base callers caught before, and its text is one line naming the problem.

| failure | kind | builtin kept |
|---|---|---|
| refused port, unknown host | ``PeerUnreachable`` | ``ConnectionError`` |
| silent peer (accepts, never answers) | ``NoReply`` | ``ConnectionError``, ``TimeoutError`` |
| the peer closes the connection, or the caller did | ``PeerUnreachable`` | ``ConnectionError`` |
| a path the device lacks, a value out of its range | ``CipError`` (the device's refusal) | |
| a path no request can carry (a negative id), a port or a class 1 RPI out of range | ``BadRequest`` | ``ValueError`` |
| class 1: the target stops producing | ``IoTimeoutError`` | ``ConnectionError`` |
"""

from __future__ import annotations

import asyncio
import contextlib
import inspect
import socket
import threading
from collections.abc import Callable, Iterator
from typing import Any

import pytest

from cipstack.cip.status import CipError, GeneralStatus
from cipstack.eip.originator.io_originator import IoTimeoutError
from cipstack.errors import BadRequest, CipstackError, NoReply, PeerUnreachable, TimedOut
from cipstack.scanner import Scanner, SyncScanner
from cipstack.testing import DeviceOptions, EmulatedDevice
from tests.ports import free_port, refused

KINDS = ["Scanner", "SyncScanner"]

#: What a call that fails must end within: the scanner's timeout below, with room for a loaded machine.
TIMEOUT = 0.5


def failure(kind: str, address: str, then: Callable[[Any], Any] | None = None, **options: Any) -> BaseException:
    """The error ``kind`` raises connecting to ``address`` (and, once connected, calling ``then(scanner)``,
    awaited for ``Scanner``); the scanner is closed either way."""
    if kind == "SyncScanner":
        try:
            scanner = SyncScanner(address, **options)
            try:
                if then is not None:
                    then(scanner)
            finally:
                scanner.close()
        except Exception as exc:
            return exc
    else:
        async def run() -> None:
            scanner = await Scanner.connect(address, **options)
            try:
                if then is not None:
                    result = then(scanner)
                    if inspect.isawaitable(result):
                        await result
            finally:
                await scanner.close()

        try:
            asyncio.run(run())
        except Exception as exc:
            return exc
    pytest.fail(f"{kind}: no error")


def one_line(error: BaseException, *naming: str) -> str:
    """``str(error)``, checked to be one line that says each of ``naming``."""
    text = str(error)
    assert text and "\n" not in text and text == text.strip(), repr(text)
    for word in naming:
        assert word in text, text
    return text


@pytest.fixture
def refusing_port() -> int:
    port = free_port()
    assert refused(port)
    return port


@pytest.fixture
def silent_peer() -> Iterator[int]:
    """A TCP port that accepts (the kernel completes the handshake for the backlog) and never answers."""
    port = free_port()
    with socket.socket() as listener:
        listener.bind(("127.0.0.1", port))
        listener.listen(8)
        yield port


@pytest.fixture
def closing_peer() -> Iterator[int]:
    """A TCP port that accepts, reads the first request and closes the connection without a reply."""
    port = free_port()
    listener = socket.socket()
    listener.bind(("127.0.0.1", port))
    listener.listen(8)
    listener.settimeout(0.2)
    stop = threading.Event()

    def serve() -> None:
        while not stop.is_set():
            try:
                peer, _ = listener.accept()
            except OSError:
                continue
            with peer:
                peer.settimeout(5)
                with contextlib.suppress(OSError):
                    peer.recv(4096)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        yield port
    finally:
        stop.set()
        thread.join(5)
        listener.close()


@pytest.fixture(scope="module")
def device(tmp_path_factory: pytest.TempPathFactory) -> Iterator[EmulatedDevice]:
    """One emulated ACG drive for the module's refusals (each test connects its own scanner)."""
    state = tmp_path_factory.mktemp("failures") / "state.json"
    with EmulatedDevice(DeviceOptions(state_path=state)) as emulated:
        yield emulated


@pytest.mark.parametrize("kind", KINDS)
def test_a_refused_port(kind: str, refusing_port: int) -> None:
    error = failure(kind, f"127.0.0.1:{refusing_port}", timeout=5)
    assert isinstance(error, PeerUnreachable) and isinstance(error, CipstackError)
    assert isinstance(error, ConnectionError)
    assert one_line(error) == f"cannot connect to 127.0.0.1:{refusing_port}: Connection refused"


@pytest.mark.parametrize("kind", KINDS)
def test_an_unknown_host(kind: str) -> None:
    error = failure(kind, "no-such-host.invalid", timeout=30)
    assert isinstance(error, PeerUnreachable) and isinstance(error, CipstackError)
    assert isinstance(error, ConnectionError)
    # The resolver's words: "Name or service not known", or without a DNS server "Temporary failure...".
    assert one_line(error).startswith("cannot connect to no-such-host.invalid:44818: ")


@pytest.mark.parametrize("kind", KINDS)
def test_a_silent_peer(kind: str, silent_peer: int) -> None:
    error = failure(kind, f"127.0.0.1:{silent_peer}", timeout=TIMEOUT)
    assert isinstance(error, NoReply) and isinstance(error, PeerUnreachable) and isinstance(error, CipstackError)
    assert isinstance(error, TimeoutError) and isinstance(error, ConnectionError)   # what callers caught before
    assert one_line(error) == f"no reply from 127.0.0.1:{silent_peer} to RegisterSession"


@pytest.mark.parametrize("kind", KINDS)
def test_a_peer_that_closes_the_connection(kind: str, closing_peer: int) -> None:
    error = failure(kind, f"127.0.0.1:{closing_peer}", timeout=5)
    assert isinstance(error, PeerUnreachable) and isinstance(error, CipstackError)
    assert isinstance(error, ConnectionError)
    assert not isinstance(error, TimeoutError)
    one_line(error, f"connection to 127.0.0.1:{closing_peer}")


def _read_after_close(scanner: Any) -> Any:
    if isinstance(scanner, SyncScanner):
        scanner.close()
        return scanner.read(0x01, 1, 1)

    async def read() -> Any:
        await scanner.close()
        return await scanner.read(0x01, 1, 1)

    return read()


@pytest.mark.parametrize("kind", KINDS)
def test_a_call_on_a_closed_connection(kind: str, device: EmulatedDevice) -> None:
    error = failure(kind, device.address, _read_after_close, timeout=5)
    assert isinstance(error, PeerUnreachable) and isinstance(error, CipstackError)
    assert isinstance(error, ConnectionError)
    assert one_line(error) == f"connection to {device.address} is closed"


@pytest.mark.parametrize("kind", KINDS)
def test_a_path_the_device_lacks(kind: str, device: EmulatedDevice) -> None:
    error = failure(kind, device.address, lambda scanner: scanner.read(0x99, 1, 1), timeout=5)
    assert isinstance(error, CipError) and isinstance(error, CipstackError)
    assert error.general == GeneralStatus.PATH_DESTINATION_UNKNOWN
    one_line(error, "path destination unknown")


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("path", [(-1, 1, 1), (0x01, -1, 1), (0x01, 1, -1)], ids=["class", "instance", "attribute"])
def test_a_path_no_request_can_carry(kind: str, path: tuple[int, int, int], device: EmulatedDevice) -> None:
    error = failure(kind, device.address, lambda scanner: scanner.read(*path), timeout=5)
    assert isinstance(error, BadRequest) and isinstance(error, CipstackError)
    assert isinstance(error, ValueError)
    one_line(error, "-1")


@pytest.mark.parametrize("kind", KINDS)
def test_a_value_out_of_the_device_s_range(kind: str, device: EmulatedDevice) -> None:
    # 0x2A/1/102 is the ACG's acceleration time, 0.0..6000.0 s in 0.1 s: 65000 is past it.
    error = failure(kind, device.address, lambda scanner: scanner.write(0x2A, 1, 102, 65000), timeout=5)
    assert isinstance(error, CipError) and isinstance(error, CipstackError)
    assert error.general == GeneralStatus.INVALID_ATTRIBUTE_VALUE
    one_line(error, "invalid attribute value")


@pytest.mark.parametrize("kind", KINDS)
def test_a_value_out_of_the_type_s_range(kind: str, device: EmulatedDevice) -> None:
    error = failure(kind, device.address, lambda scanner: scanner.write(0x2A, 1, 102, 1 << 20), timeout=5)
    assert isinstance(error, CipstackError)
    one_line(error, str(1 << 20))


@pytest.mark.parametrize("kind", KINDS)
def test_a_parameter_value_out_of_range(kind: str, device: EmulatedDevice) -> None:
    error = failure(kind, device.address, lambda scanner: scanner.set_parameter("ACC", 10**7), timeout=5)
    assert isinstance(error, BadRequest) and isinstance(error, ValueError)
    one_line(error, "ACC")


@pytest.mark.parametrize("kind", KINDS)
def test_a_class_1_timeout(kind: str, cip_adapter: EmulatedDevice) -> None:
    """The target stops producing (the ``stop-producing`` fault): the originator's watchdog times the
    connection out (RPI 10 ms x 4 x 2, 80 ms) and the next look at it raises ``IoTimeoutError``."""
    options = {"output": 21, "input": 71, "rpi": 0.010, "timeout_multiplier": 1, "target_io_port": cip_adapter.io_port}
    if kind == "SyncScanner":
        with cip_adapter.scanner() as scanner, scanner.io_connection(**options) as sync_io:
            sync_io.wait_input(lambda image: True, 10)
            cip_adapter.fault("stop-producing")
            with pytest.raises(IoTimeoutError) as raised:
                sync_io.wait_input(lambda image: False, 30)
    else:
        async def run() -> None:
            async with await Scanner.connect(cip_adapter.address) as scanner, \
                    scanner.io_connection(**options) as io:
                await io.wait_input(lambda image: True, 10)
                cip_adapter.fault("stop-producing")
                async for _ in io.updates():
                    pass

        with pytest.raises(IoTimeoutError) as raised:
            asyncio.run(run())
    error = raised.value
    assert isinstance(error, PeerUnreachable) and isinstance(error, CipstackError)
    assert isinstance(error, ConnectionError)
    assert one_line(error) == "class 1 connection to 127.0.0.1 timed out"


@pytest.mark.parametrize("kind", KINDS)
def test_a_port_out_of_range(kind: str) -> None:
    """Given apart from the address: the socket's own error for it is an OverflowError."""
    error = failure(kind, "127.0.0.1", port=70000, timeout=5)
    assert isinstance(error, BadRequest) and isinstance(error, ValueError)
    assert one_line(error) == "port 70000 out of range"


@pytest.mark.parametrize("kind", KINDS)
def test_a_class_1_rpi_out_of_range(kind: str, device: EmulatedDevice) -> None:
    """A negative RPI: struct's own error ("argument out of range") named neither the RPI nor its range."""
    def open_io(scanner: Any) -> Any:
        opening = scanner.io_connection(output=21, input=71, rpi=-1, target_io_port=device.io_port)
        return opening.__aenter__() if isinstance(scanner, Scanner) else opening.__enter__()

    error = failure(kind, device.address, open_io, timeout=5)
    assert isinstance(error, BadRequest) and isinstance(error, ValueError)
    one_line(error, "RPI", "-1000000 us")


@pytest.mark.parametrize("kind", KINDS)
def test_an_input_condition_that_never_comes_true(kind: str, cip_adapter: EmulatedDevice) -> None:
    """``wait_input`` whose condition stays false: ``TimedOut`` (a ``CipstackError``) after the timeout,
    still a ``TimeoutError``, and on the async scanner still the ``asyncio.TimeoutError`` it was."""
    options = {"output": 21, "input": 71, "rpi": 0.010, "target_io_port": cip_adapter.io_port}
    if kind == "SyncScanner":
        with cip_adapter.scanner() as scanner, scanner.io_connection(**options) as sync_io, \
                pytest.raises(TimedOut) as raised:
            sync_io.wait_input(lambda image: False, 0.2)
    else:
        async def run() -> None:
            async with await Scanner.connect(cip_adapter.address) as scanner, \
                    scanner.io_connection(**options) as io:
                await io.wait_input(lambda image: False, 0.2)

        with pytest.raises(asyncio.TimeoutError) as raised:
            asyncio.run(run())
        assert isinstance(raised.value, TimedOut)
    assert isinstance(raised.value, CipstackError) and isinstance(raised.value, TimeoutError)
    assert one_line(raised.value) == "input did not satisfy the condition within 0.2 s"
