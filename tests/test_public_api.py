"""The public API (issue 26, item 7): one import for each thing a user touches, each documented and
typed, and ``import cipstack`` that loads none of it until used (``cipstack --help`` stays fast)."""

from __future__ import annotations

import inspect
import subprocess
import sys

import pytest

import cipstack
from tests.library_support import ROOT


@pytest.mark.parametrize("name", [n for n in cipstack.__all__ if n != "__version__"])
def test_each_public_name_resolves_documented_and_typed(name: str) -> None:
    value = getattr(cipstack, name)
    assert name in dir(cipstack)
    if inspect.isclass(value) or inspect.isfunction(value):
        assert inspect.getdoc(value), f"{name} has no docstring"
    if inspect.isfunction(value):
        hints = inspect.signature(value)
        assert hints.return_annotation is not inspect.Signature.empty, f"{name} has no return type"
        for parameter in hints.parameters.values():
            assert parameter.annotation is not inspect.Parameter.empty, f"{name}({parameter.name}) is untyped"


def test_the_names_a_user_needs() -> None:
    from cipstack import (  # noqa: F401 - the import is the test
        Adapter,
        CipError,
        IoConnectionHandle,
        ProcessImage,
        Scanner,
        SyncScanner,
        Value,
        discover,
        discover_blocking,
        dump_params,
        read_eds,
    )
    with pytest.raises(AttributeError, match="no attribute 'Nope'"):
        cipstack.Nope  # noqa: B018


def test_import_is_light() -> None:
    script = "import sys, cipstack; print(sorted(m for m in sys.modules if m.startswith('cipstack')))"
    loaded = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True,
                            cwd=ROOT).stdout.strip()
    assert loaded == "['cipstack']"
