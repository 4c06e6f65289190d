"""The tests of one ``xdist_group`` run on one worker, one after another (``--dist loadgroup``,
pyproject.toml): the capturing modules each need the loopback to themselves, and their module
fixtures are made once. pytest-xdist tells its scheduler a test's group in the test's node id; a
pytest and a pytest-xdist that disagree on node ids lose every group without a word (pytest-xdist
#1386, pytest 9.2 with pytest-xdist 3.8), so this test fails where that happens."""

from __future__ import annotations

import pytest

pytestmark = pytest.mark.xdist_group("tshark")


def test_a_grouped_test_carries_its_group_to_the_scheduler(request: pytest.FixtureRequest) -> None:
    config = request.config
    if not hasattr(config, "workerinput") or not config.getvalue("loadgroup"):
        pytest.skip("not a worker of --dist loadgroup: nothing is scheduled by group")
    import xdist

    assert request.node.nodeid.endswith("@tshark"), (
        f"pytest {pytest.__version__} with pytest-xdist {xdist.__version__} does not group tests: install the "
        "versions the test-runner extra gives (pyproject.toml)")
