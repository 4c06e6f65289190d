"""Every check can fail: for each check id, the scripted target of ``fake_target`` deviates in that
one place, and the battery, run over the check's whole group, fails that check and no other."""

from __future__ import annotations

from pathlib import Path

import pytest

from cipstack.conformance import CHECKS, Verdict, check_ids, run
from tests.optional import needs

from .fake_target import VARIANTS, FakeTarget

EDS = Path(__file__).with_name("fake_device.eds")


def run_group(target: FakeTarget, group: str):  # type: ignore[no-untyped-def]
    secured = target.security
    return run(target.host, target.port, eds=EDS, groups=group, allow_writes=True, allow_reset=True, timeout=2.0,
               allow_motion=True, allow_stress=True, security=secured.folder if secured else None,
               security_port=secured.port if secured else 2221)


#: The group whose run shows a check's deviation, where it is not the check's own.
SHOWN_BY = {"final.as_found": "class1"}
#: The groups that open connections (profile: its motion checks): after them the final self-check has
#: something to check.
CONNECTING = ("cm", "class1", "eds", "profile")


@pytest.mark.parametrize("group", ["encap", "router", "objects", "cm", "class1", "eds", "profile", "security"])
def test_the_conformant_fake_passes_every_check(group: str) -> None:
    if group == "security":
        needs("cryptography")        # the fake's credentials, and the battery's TLS
    with FakeTarget(drive=group == "profile", security=group == "security") as target:
        report = run_group(target, group)
    assert target.errors == []
    assert {o.name: o.observed for o in report if o.verdict is not Verdict.PASS} == {}
    # The final self-check runs after every run that opened a connection or wrote.
    final = ("final",) if group in CONNECTING else ()
    assert {o.id for o in report} == {i for i in check_ids() if CHECKS[i].group in (group, *final)}


@pytest.mark.parametrize("check_id", check_ids())
def test_each_check_fails_on_its_deviation(check_id: str) -> None:
    group = CHECKS[check_id].group
    if group == "security":
        needs("cryptography")
    with FakeTarget(deviation=check_id, drive=group == "profile", security=group == "security") as target:
        report = run_group(target, SHOWN_BY.get(check_id, CHECKS[check_id].group))
    assert target.errors == []
    failed = {o.id for o in report.failures}
    assert failed == {check_id}, {o.name: o.observed for o in report.failures}


def test_every_check_has_a_deviation_in_the_fake() -> None:
    """The fake (and the motor of its drive) names each check id it can deviate for: a check added to the
    battery without a way to fail it is caught here (the parametrized test above would run it, and this
    says why)."""
    source = "".join(Path(__file__).with_name(name).read_text(encoding="utf-8")
                     for name in ("fake_target.py", "fake_drive.py", "fake_security.py", "fake_secured.py"))
    assert [i for i in check_ids() if f'"{i}"' not in source] == []


def test_a_target_that_closes_the_session_on_a_timeout_is_left_as_found() -> None:
    """OpENer, on a class 1 timeout, closes the TCP session that opened the connection and keeps the
    timed-out exclusive owner until a Forward_Close of its triad: the battery closes it on a new
    session, and the final self-check opens the point again. A second run finds the same."""
    with FakeTarget(opener_timeout=True) as target:
        first = run_group(target, "class1")
        closed_sessions = target.sessions_closed_on_timeout
        second = run_group(target, "class1")
        left = dict(target.connections)
    assert closed_sessions == 1
    for report in (first, second):
        assert {o.name: o.observed for o in report if o.verdict is not Verdict.PASS} == {}
        assert "opened again and closed" in next(o.observed for o in report if o.id == "final.as_found")
    assert left == {}


def test_a_connection_left_behind_is_named_with_how_to_clear_it() -> None:
    with FakeTarget(deviation="final.as_found") as target:
        report = run_group(target, "class1")
    (final,) = [o for o in report if o.id == "final.as_found"]
    assert final.verdict is Verdict.FAIL
    assert "0x0106 (ownership conflict" in final.observed and "power-cycle the device" in final.observed


@pytest.mark.parametrize("check_id", sorted(VARIANTS))
def test_every_answer_the_specification_permits_passes(check_id: str) -> None:
    """Where the specification allows more than one answer, the other one passes too."""
    assert CHECKS[check_id].codes or CHECKS[check_id].behaviours or check_id == "cm.forward_open.rpi"
    group = CHECKS[check_id].group
    if group == "security":
        needs("cryptography")
    with FakeTarget(variant=check_id, security=group == "security") as target:
        report = run_group(target, CHECKS[check_id].group)
    assert {o.name: o.observed for o in report if o.verdict is not Verdict.PASS} == {}, VARIANTS[check_id]


@pytest.mark.parametrize("variant", ["no-dtls:unreachable", "no-dtls:silent"])
def test_a_device_without_a_dtls_port_is_not_applicable_to_the_dtls_checks(variant: str) -> None:
    """A device that serves TLS and no DTLS (its UDP port closed, or silent): the DTLS checks say so
    and do not apply; the other checks of the group are not disturbed."""
    needs("cryptography")
    with FakeTarget(variant=variant, security=True) as target:
        report = run_group(target, "security")
    dtls = {o.id: o for o in report if o.id.startswith("security.dtls.")}
    assert {i: o.verdict for i, o in dtls.items()} == dict.fromkeys(dtls, Verdict.NOT_APPLICABLE)
    reason = "nothing listens there (ICMP port unreachable)" if variant.endswith("unreachable") else \
        "no answer to the handshake"
    assert all(o.observed.startswith("no DTLS port: ") and reason in o.observed for o in dtls.values()), \
        [o.observed for o in dtls.values()]
    assert {o.name: o.observed for o in report if o.verdict not in (Verdict.PASS, Verdict.NOT_APPLICABLE)} == {}
    assert len(dtls) == 2


def test_every_check_that_judges_a_status_declares_the_codes_with_their_reference() -> None:
    judged = [i for i, spec in CHECKS.items() if i.startswith(("router.", "cm.forward_open.", "cm.forward_close."))
              and i not in ("router.multiple_service.good", "cm.forward_open.accepted")]
    assert [i for i in judged if not CHECKS[i].codes] == []
    assert all(code.reference for spec in CHECKS.values() for code in spec.codes)


def test_the_profile_does_not_apply_to_another_device_type() -> None:
    with FakeTarget() as target:
        report = run_group(target, "profile")
    assert {o.id: o.verdict for o in report} == {i: Verdict.NOT_APPLICABLE for i in check_ids()
                                                 if i.startswith("profile.")}
