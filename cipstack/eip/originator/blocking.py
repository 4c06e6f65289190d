"""The originator over a blocking socket, for scripts and one-shot commands: no event loop.

A thin shell over ``OriginatorCore``: it writes a transaction's frame, reads until the core says the
reply came (or the deadline passed), and returns the reply's meaning. One request at a time; a late
reply to one that timed out is dropped by the core. It imports nothing of asyncio.
"""

from __future__ import annotations

import socket
import time
from typing import Any, TypeVar

from ...errors import CipstackError, PeerUnreachable
from ..wire.encapsulation import DEFAULT_PORT
from .core import (
    DEFAULT_TIMEOUT,
    CoreClient,
    NoReplyError,
    OriginatorCore,
    Plan,
    SecureChannel,
    Transaction,
    run_plan,
)

T = TypeVar("T")

#: A reply is small: a 64 KiB receive buffer would be allocated and shrunk on every call.
_RECEIVE_SIZE = 4096


def _open(host: str, port: int, timeout: float) -> socket.socket:
    """A TCP connection to ``host``: an IPv4 address is connected to as it is, a name (or an IPv6
    address) through ``getaddrinfo``. The resolver encodes every host it is given with the idna
    codec, whose import is a sizeable share of a one-shot command's time."""
    try:
        socket.inet_pton(socket.AF_INET, host)  # a dotted quad and nothing else
    except OSError:
        return socket.create_connection((host, port), timeout)
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    try:
        sock.settimeout(timeout)
        sock.connect((host, port))
    except BaseException:
        sock.close()
        raise
    return sock


class BlockingEncapsulationClient(CoreClient):
    """One TCP connection and one session, blocking: ``perform`` a transaction, ``run`` a plan."""

    def __init__(self, host: str, port: int = DEFAULT_PORT, timeout: float = DEFAULT_TIMEOUT,
                 core: OriginatorCore | None = None) -> None:
        super().__init__(host, port, timeout, core)
        self._sock: socket.socket | Any = None
        self._security: SecureChannel | None = None
        self._sock_timeout: float | None = None
        #: Over DTLS: the session (``security.dtls_link.DtlsLink``) whose datagrams class 1 shares.
        self.datagram_link: Any = None

    @classmethod
    def connect(cls, host: str, port: int = DEFAULT_PORT, timeout: float = DEFAULT_TIMEOUT,
                register: bool = True, security: SecureChannel | None = None) -> BlockingEncapsulationClient:
        """Connect (and register a session unless ``register`` is false); with ``security``, over
        TLS (CIP Security: the device's port 2221)."""
        client = cls(host, port, timeout)
        try:
            sock = _open(host, port, timeout)
        except OSError as exc:
            raise PeerUnreachable.connecting(host, port, exc) from None
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        client._sock = sock if security is None else security.wrap_client(sock, host, port)
        client._security = security
        return client._registered() if register else client

    @classmethod
    def connect_dtls(cls, host: str, port: int, timeout: float, security: SecureChannel,
                     register: bool = True) -> BlockingEncapsulationClient:
        """Open a DTLS session with ``security`` (``Credentials``) to the device's UDP ``port`` (2221)
        and register an encapsulation session in it: class 1 connections opened on this client then
        flow in the same DTLS session."""
        client = cls(host, port, timeout)
        client._sock = client.datagram_link = security.datagram_link(host, port, timeout)
        client._security = security
        return client._registered() if register else client

    def _registered(self) -> BlockingEncapsulationClient:
        """This client with its session registered; closed if the registration fails."""
        try:
            self.perform(self.core.register_session())
        except BaseException:
            self.close()
            raise
        return self

    @property
    def is_open(self) -> bool:
        return self._sock is not None

    def local_host(self) -> str:
        """The local address of the TCP connection (where T->O data should come)."""
        assert self._sock is not None
        return str(self._sock.getsockname()[0])

    def host_address(self) -> str:
        """The target's address as connected (an IP address even if a name was given)."""
        assert self._sock is not None
        return str(self._sock.getpeername()[0])

    def nop(self) -> None:
        """An encapsulation NOP (no reply, by definition): keeps an idle session open."""
        self._send(self.core.nop())

    def _send(self, frame: bytes) -> None:
        if self._sock is None:
            raise PeerUnreachable(f"connection to {self.host}:{self.port} is closed")
        try:
            self._sock.sendall(frame)
        except OSError as exc:
            raise self._lost(exc) from None

    def perform(self, transaction: Transaction[T]) -> T:
        """Send ``transaction`` and wait for its reply; the reply's meaning, or the error it carries."""
        core = self.core
        self._send(core.start(transaction, time.monotonic()))
        sock = self._sock
        assert sock is not None
        timeout = transaction.timeout or self.timeout
        if timeout != self._sock_timeout:
            sock.settimeout(timeout)
            self._sock_timeout = timeout
        while True:
            try:
                chunk = sock.recv(_RECEIVE_SIZE)
            except TimeoutError:
                raise self._no_reply(transaction) from None
            except OSError as exc:
                core.lost()
                raise self._lost(exc) from None
            if not chunk:
                core.lost()
                raise PeerUnreachable(f"connection to {self.host}:{self.port} closed by the target")
            for done, header, body in core.receive_data(chunk):
                if done is transaction:
                    return transaction.result(header, body)
            if time.monotonic() >= transaction.deadline:  # only frames nothing waits for kept coming
                raise self._no_reply(transaction)

    def _lost(self, failure: OSError) -> CipstackError:
        refusal = self._security.refusal(failure, self.host, self.port) if self._security is not None else None
        return refusal or PeerUnreachable(f"connection to {self.host}:{self.port} lost: {failure}")

    def _no_reply(self, transaction: Transaction[Any]) -> NoReplyError:
        self.core.forget(transaction)
        return self.no_reply(transaction)

    def run(self, plan: Plan[T]) -> T:
        """Drive a plan of several requests to its result."""
        return run_plan(plan, self.perform)

    def close(self) -> None:
        """Forward_Close the class 3 connection, UnRegisterSession, close the socket."""
        if self._sock is None:
            return
        try:
            closing = self.core.forward_close()
            if closing is not None:
                self.perform(closing)
            if self.core.session:
                self._send(self.core.unregister_session())
        except (OSError, CipstackError):
            pass  # the session ends either way: the target may be gone already
        finally:
            self._sock.close()
            self._sock = None
            self.core.session = 0

    def __enter__(self) -> BlockingEncapsulationClient:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


__all__ = ["BlockingEncapsulationClient", "SecureChannel"]
