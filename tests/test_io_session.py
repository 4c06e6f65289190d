"""A class 1 connection outlives a quiet TCP session, and is still closed when it ends.

A target closes a TCP session that is silent for its encapsulation inactivity timeout (TCP/IP
attribute 13, 120 s by default); a class 1 connection carries on over UDP. Seen on the wire: a
`cipstack io` of more than 120 s, whose Forward_Close at the end found its session gone
("connection ... is closed") and left the target's connection to its watchdog. The originator now
keeps the session alive with an encapsulation NOP while the connection is open, and if the target
closed the session anyway, it opens a new one for the Forward_Close.
"""

from __future__ import annotations

import asyncio
import logging
import time

import pytest

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.cip.types import UINT
from cipstack.eip.originator import io_context
from cipstack.scanner import Scanner
from tests.waiting import wait_until

INACTIVITY_S = 1  # TCP/IP attribute 13, in seconds


async def _quiet_target() -> Adapter:
    adapter = Adapter(AdapterSettings(host="127.0.0.1", port=0, io_port=0))
    await adapter.start()
    async with await Scanner.connect(f"127.0.0.1:{adapter.port}", timeout=3) as setup:
        await setup.set_attribute_single(0xF5, 1, 13, INACTIVITY_S, UINT)
    return adapter


async def test_the_session_is_kept_alive_while_the_connection_runs(monkeypatch: pytest.MonkeyPatch,
                                                                  caplog: pytest.LogCaptureFixture) -> None:
    monkeypatch.setattr(io_context, "SESSION_KEEPALIVE_S", 0.3)
    adapter = await _quiet_target()
    try:
        async with await Scanner.connect(f"127.0.0.1:{adapter.port}", timeout=3) as scanner:
            with caplog.at_level(logging.INFO):
                async with scanner.io_connection(output=21, input=71, rpi=0.010, timeout_multiplier=5,
                                                 target_io_port=adapter.io.io_port) as io:
                    await asyncio.sleep(3 * INACTIVITY_S)   # the subject: three inactivity timeouts pass
                    assert scanner.client.is_open  # three inactivity timeouts later, NOPs kept it
                    assert io.statistics()["received"] > 100
                    assert len(adapter.io.connections) == 1
            assert "Forward_Close of class 1 connection failed" not in caplog.text
            assert "session was closed" not in caplog.text
            assert adapter.io.connections == {}
    finally:
        await adapter.close()


async def test_a_session_the_target_closed_is_reopened_for_the_forward_close(
        monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    monkeypatch.setattr(io_context, "SESSION_KEEPALIVE_S", 60.0)  # no NOP in time: the target closes it
    adapter = await _quiet_target()
    try:
        async with await Scanner.connect(f"127.0.0.1:{adapter.port}", timeout=3) as scanner:
            with caplog.at_level(logging.INFO):
                async with scanner.io_connection(output=21, input=71, rpi=0.010, timeout_multiplier=5,
                                                 target_io_port=adapter.io.io_port) as io:
                    # Within the 2.5 inactivity timeouts the test gives: the session closed by the
                    # target's inactivity timeout, and the class 1 connection running on.
                    began = time.monotonic()
                    await wait_until(lambda: not scanner.client.is_open, 2.5 * INACTIVITY_S,
                                     "the target to close the session")
                    await wait_until(lambda: io.statistics()["received"] > 100,
                                     2.5 * INACTIVITY_S - (time.monotonic() - began), "100 datagrams of class 1")
            assert "a new one sends the Forward_Close" in caplog.text
            assert "Forward_Close of class 1 connection failed" not in caplog.text
            # Closed at once by the Forward_Close, not by its watchdog a timeout later.
            assert adapter.io.connections == {}
    finally:
        await adapter.close()
