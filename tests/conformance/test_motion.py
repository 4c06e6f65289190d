"""The motion checks leave the drive as they found it whatever happens in them: stopped, NetCtl/NetRef
and the speed reference back, the connection closed (against the scripted drive of ``fake_target``)."""

from __future__ import annotations

import threading
from pathlib import Path

import pytest

from cipstack.conformance import CHECKS, Verdict, run
from cipstack.conformance.motion import RUN_FWD, SPEED_REFERENCE, MotionLink, motion_link
from cipstack.conformance.registry import Context

from .fake_target import AC_DRIVE, FakeTarget


def test_a_check_that_raises_leaves_the_drive_stopped_and_its_sources_as_found() -> None:
    with FakeTarget(drive=True) as target:
        assert target.motor is not None
        ctx = Context(target.host, target.port, 2.0, allow_motion=True)
        ctx.identity = {"device_type": AC_DRIVE}
        with pytest.raises(RuntimeError, match="raised mid-run"), \
                motion_link(ctx, CHECKS["profile.motion.run_forward"]) as link:
            assert isinstance(link, MotionLink)
            assert not isinstance(link.take_control(), str)
            took, _ = link.send(link.control | RUN_FWD, SPEED_REFERENCE, 2.0, until=lambda s: bool(s.at_reference))
            assert took is not None and target.motor.running and target.motor.net_ctl
            assert target.motor.reference == SPEED_REFERENCE
            raise RuntimeError("raised mid-run")
        ctx.cleanup()
        motor = target.motor
        assert (motor.running, motor.net_ctl, motor.net_ref, motor.reference) == (False, False, False, 0)
        assert target.connections == {} and ctx.left_behind == []


def test_without_allow_motion_nothing_is_opened() -> None:
    with FakeTarget(drive=True) as target:
        ctx = Context(target.host, target.port, 2.0)
        ctx.identity = {"device_type": AC_DRIVE}
        with motion_link(ctx, CHECKS["profile.motion.idle"]) as link:
            assert not isinstance(link, MotionLink)
            assert "--allow-motion" in link.observed
        assert ctx.accepted == [] and target.motor is not None and not target.motor.touched


def test_every_motion_check_declares_the_behaviours_it_permits() -> None:
    motion = {i: spec for i, spec in CHECKS.items() if i.startswith("profile.motion.")}
    assert len(motion) == 5
    assert [i for i, spec in motion.items() if not spec.behaviours] == []
    assert all(b.reference and b.meaning for spec in motion.values() for b in spec.behaviours)
    with pytest.raises(KeyError, match="declares no behaviour"):
        motion["profile.motion.idle"].permits("runs")


def test_a_slow_explicit_server_does_not_starve_the_motion_connection() -> None:
    """Each Set_Attribute_Single answered 0.2 s late: the fault reset check writes ForceFault twice in a
    row while its connection (RPI 20 ms x 16: 0.32 s timeout) is open. O->T goes on meanwhile, so the
    connection never times out (a real drive would trip on it) and every motion check passes."""
    eds = Path(__file__).with_name("fake_device.eds")
    with FakeTarget(drive=True, set_delay=0.2) as target:
        report = run(target.host, target.port, eds=eds, groups="profile", allow_writes=True, allow_reset=True,
                     timeout=2.0, allow_motion=True)
    assert target.errors == [] and target.timeouts == 0
    assert {o.name: o.observed for o in report if o.verdict is not Verdict.PASS} == {}
    assert [t.name for t in threading.enumerate() if t.name == "battery O->T"] == []
