"""A fault's options are a typed record (``cipstack.faults.options.FaultOptions``) made once when the
request is checked; the effects read its attributes. The relations between faults and between
options are declared beside them (``FaultKind.replaces``, ``EXCLUSIVE_OPTIONS``)."""

from __future__ import annotations

import dataclasses

import pytest

from cipstack.faults import FaultError, FaultRequest
from cipstack.faults.model import EXCLUSIVE_OPTIONS, FAULTS, FOR, JSON_SPELLING, parse_arguments
from cipstack.faults.options import ATTRIBUTES, FaultOptions


def test_every_option_of_the_table_has_its_attribute_and_no_attribute_is_unused() -> None:
    declared = {FOR.field}
    for kind in FAULTS.values():
        declared |= {o.field for o in kind.options}
        if kind.positional is not None:
            declared.add(kind.positional.field)
    assert declared == set(ATTRIBUTES)


def test_a_request_s_record_holds_its_options_parsed_once() -> None:
    request = parse_arguments("drop", ["--every", "0x10", "--originator", "127.0.0.1", "--for", "500ms"])
    assert request.settings == FaultOptions(every=16, originator="127.0.0.1", duration=0.5)
    assert dict(request.options) == {"every": 16, "originator": "127.0.0.1", "for": 0.5}
    with pytest.raises(dataclasses.FrozenInstanceError):
        request.settings.every = 2   # type: ignore[misc]  # the subject: a frozen record refuses the write


def test_the_two_statuses_are_two_attributes() -> None:
    general = FaultRequest.build("error-status", {"status": "0x01/0x0100", "class": "4"}, JSON_SPELLING)
    assert (general.settings.status, general.settings.class_id) == ((0x01, (0x0100,)), 4)
    assert general.settings.extended_status is None
    refused = parse_arguments("refuse-forward-open", ["0x0113"])
    assert (refused.settings.extended_status, refused.settings.status) == (0x0113, None)
    assert refused.as_json() == {"status": "0x0113"}


@pytest.mark.parametrize(("one", "other"), EXCLUSIVE_OPTIONS)
def test_options_declared_exclusive_are_refused_together(one: str, other: str) -> None:
    values = {"connection": "1", "originator": "127.0.0.1", "share": "0.5", "every": "2"}
    with pytest.raises(FaultError, match=f"--{one} or --{other}, not both"):
        FaultRequest.build("drop", {"share": "0.5", one: values[one], other: values[other]})


def test_what_applying_a_fault_ends_is_declared_on_it() -> None:
    assert FAULTS["plug"].replaces == ("unplug",)
    assert FAULTS["delay-replies"].replaces == ("delay-replies",)
    assert FAULTS["drop"].replaces == ()


def test_a_request_made_with_its_checked_options_alone_has_its_record() -> None:
    """``FaultRequest(name, options)`` (options already checked) has the record ``build`` would make."""
    built = parse_arguments("delay", ["--by", "20ms", "--for", "2s"])
    made = FaultRequest("delay", dict(built.options))
    assert made.settings == built.settings == FaultOptions(by=0.02, duration=2.0)
    assert made.duration == 2.0
    assert parse_arguments("power-cycle", []).duration == 0.0
