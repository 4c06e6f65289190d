"""The optional packages some tests need, imported inside those tests: ``needs`` skips the test, with the
reason, where the package is not installed, so that ``pytest -m quick`` runs green with the runtime
dependencies alone (``.ci/run`` checks it in a clean environment) and the rest of a module still runs."""

from __future__ import annotations

from types import ModuleType

import pytest

#: What brings each package: the extra a user installs for it.
_EXTRA = {"aiohttp": "http", "prometheus_client": "http", "matplotlib": "plot", "shtab": "completion",
          "serial": "rtu", "cryptography": "security", "OpenSSL": "security"}


def needs(module: str) -> ModuleType:
    """``module`` (``"aiohttp"``, ``"pymodbus.client"``), or the test is skipped saying what installs it."""
    package = module.split(".")[0]
    extra = _EXTRA.get(package, "test")
    return pytest.importorskip(module, reason=f"{package} is not installed (the {extra} extra): "
                                              f"pip install '.[{extra}]'")
