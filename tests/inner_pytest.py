"""The environment of a pytest a test runs in another process."""

from __future__ import annotations

import os
from pathlib import Path


def environment(root: Path | None = None) -> dict[str, str]:
    """This process's environment less ``PYTEST_ADDOPTS`` (the options of the run around the test, CI's
    budget or a marker selection, are not the inner run's), with ``root`` on ``PYTHONPATH`` if given."""
    env = {key: value for key, value in os.environ.items() if key != "PYTEST_ADDOPTS"}
    if root is not None:
        env["PYTHONPATH"] = str(root)
    return env
