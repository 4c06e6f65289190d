"""The checker's minimum <= default <= maximum rule, pinned on each side with the other side held:
a default above the maximum while within the minimum, and below the minimum while within the
maximum, each reported by its rule on the default's line; the edges themselves are fine."""

from __future__ import annotations

import pytest

from cipstack.eds.checker import check_eds
from cipstack.eds.reader import parse_eds

from .samples import ADAPTER_EDS

#: Param9 (RPI Range, UDINT): minimum 2000, maximum 3200000, default 10000.
LIMITS = "2000, 3200000, 10000,"


def findings(limits: str) -> set[tuple[str, int]]:
    assert ADAPTER_EDS.count(LIMITS) == 1
    text = ADAPTER_EDS.replace(LIMITS, limits)
    line = text.count("\n", 0, text.index(limits)) + 1
    return {(f.rule, f.line - line) for f in check_eds(parse_eds(text))}


@pytest.mark.parametrize("limits", ["2000, 3200000, 3200001,", "2000, 3200000, 4000000,"])
def test_default_above_maximum_within_minimum(limits: str) -> None:
    assert findings(limits) == {("min-default-max", 0)}


@pytest.mark.parametrize("limits", ["2000, 3200000, 1999,", "2000, 3200000, 1000,"])
def test_default_below_minimum_within_maximum(limits: str) -> None:
    assert findings(limits) == {("min-default-max", 0)}


@pytest.mark.parametrize("limits", ["2000, 3200000, 2000,", "2000, 3200000, 3200000,"])
def test_default_on_an_edge_is_fine(limits: str) -> None:
    assert findings(limits) == set()
