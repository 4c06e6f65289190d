"""Coverage without an EDS against an OpENer-like target: its configuration assembly is 151, not 1, so
a probe that always names configuration instance 1 is refused (0x0315) and the connection checks do
not apply. The battery finds the configuration instance the device has: the Assembly class's highest
instance and instance count, the instances that exist (data-less ones included), then the
configuration candidates in turn. The scripted target is laid out as OpENer's sample application
(input 100, output 150, configuration 151, heartbeats 152 and 153, explicit 154) and, as stock
OpENer's debug build, aborts at its 21st TCP connection."""

from __future__ import annotations

from cipstack.conformance import Verdict, check_ids, run

from .fake_target import FakeTarget

#: At most this many checks may not apply against OpENer without its EDS: group eds (no file) and
#: the drive profile, its five motion checks included (not a drive), Get_Attribute_List where it lacks it.
MOST_NOT_APPLICABLE = 15


def test_without_an_eds_the_battery_finds_opener_s_configuration_instance() -> None:
    with FakeTarget(opener_layout=True, tcp_limit=20, max_sessions=40) as target:
        report = run(target.host, target.port, timeout=2.0)
        aborted, errors = target.aborted, target.errors
    assert not aborted and errors == []
    source = str(report.options["connection_points"])
    assert source.startswith("probing the Assembly object") and "150/100, configuration 151" in source, source
    not_applicable = [o.name for o in report if o.verdict is Verdict.NOT_APPLICABLE]
    assert len(not_applicable) <= MOST_NOT_APPLICABLE, not_applicable
    # As docs/conformance.md says: group eds (no EDS file) and the drive profile's eight, motion included
    # (no drive).
    assert sorted(not_applicable) == sorted(i for i in check_ids() if i.startswith(("eds.", "profile.")))
    # The Connection Manager's and class 1's checks ran on the points found.
    ran = {o.id: o.verdict for o in report if o.group in ("cm", "class1")}
    assert not [i for i, v in ran.items() if v is Verdict.NOT_APPLICABLE], ran
    for check in ("cm.forward_open.accepted", "cm.forward_open.ownership", "class1.production", "class1.timeout"):
        assert ran[check] is Verdict.PASS, next(o.observed for o in report if o.id == check)
    assert next(o for o in report if o.id == "final.as_found").verdict is Verdict.PASS


def test_configuration_instance_1_is_ruled_out_at_its_first_refusal() -> None:
    """OpENer refuses a configuration instance it lacks with 0x0315 whatever the points: instance 1
    is not asked again, and the instance after the output (151 after 150) is tried next."""
    with FakeTarget(opener_layout=True) as target:
        report = run(target.host, target.port, groups="cm", timeout=2.0)
        opens = list(target.forward_opens)
    assert str(report.options["connection_points"]).startswith("probing the Assembly object")
    assert next(o for o in report if o.id == "cm.forward_open.accepted").verdict is Verdict.PASS
    # (general status, extended status) of each Forward_Open: the probe's two, then the checks'.
    assert opens[:2] == [(0x01, 0x0315), (0x00, 0)]
