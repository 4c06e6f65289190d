"""A real headless Chromium (Debian's ``chromium`` and ``chromedriver``) driven through Selenium, for
the tests of what a web page can and cannot do to the HTTP API. Missing pieces skip with the reason;
``.ci/run`` installs them."""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

CHROMIUM = "/usr/bin/chromium"
CHROMEDRIVER = "/usr/bin/chromedriver"


def require_browser() -> None:
    """Skip the calling test unless a headless Chromium can be driven here."""
    pytest.importorskip("selenium", reason="the browser tests drive Chromium through selenium (the test extra)")
    for binary in (CHROMIUM, CHROMEDRIVER):
        if shutil.which(binary) is None:
            pytest.skip(f"{binary} is missing (Debian packages chromium and chromium-driver)")


@contextmanager
def chromium(profile: Path, *, resolve: dict[str, str] | None = None) -> Iterator[Any]:
    """A headless Chromium with an empty profile in ``profile``; ``resolve`` maps host names to
    addresses inside the browser alone (as a DNS-rebinding attacker's name would resolve)."""
    require_browser()
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    # A closed network: nothing of Chromium's own may try to reach the Internet (each try is a
    # refused connection and a delay), and the profile is new for each test.
    for flag in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                 "--disable-dev-shm-usage", "--hide-scrollbars", f"--user-data-dir={profile}"):
        options.add_argument(flag)
    if resolve:
        rules = ", ".join(f"MAP {name} {address}" for name, address in resolve.items())
        options.add_argument(f"--host-resolver-rules={rules}")
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
    driver.set_page_load_timeout(30)
    driver.set_script_timeout(30)
    try:
        yield driver
    finally:
        driver.quit()
