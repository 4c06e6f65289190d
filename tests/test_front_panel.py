"""The front panel in a real headless Chromium, against a real adapter and a real fleet: the network
made the command source from the page's parameter fields, a class 1 connection seen with its data by
field names, a fault applied from the page and seen by an independent client (pycomm3), a value out
of range refused next to its field, the power cut and restored, the plant's grid with an ended worker
and a link to a device's panel, the token asked once. Every test fails when the page logs a script error."""

from __future__ import annotations

import ipaddress
import json
import os
import signal
import subprocess
import sys
import time
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

from tests.browser import chromium, require_browser
from tests.ports import free_port
from tests.test_fleet import Fleet
from tests.test_fleet_http import worker_pid
from tests.waiting import wait_for

pytestmark = [pytest.mark.browser,
              pytest.mark.skipif(not sys.platform.startswith("linux"), reason="any 127.x on loopback")]


@contextmanager
def adapter(tmp_path: Path, *args: str) -> Iterator[tuple[subprocess.Popen[str], int, int]]:
    """``cipstack adapter --http`` (the ACG by default) in a process of its own: it, its EtherNet/IP
    port and its HTTP port, once the API listens."""
    require_browser()
    port, http = free_port(), free_port()
    log = tmp_path / "adapter.err"
    with log.open("w") as err:
        process = subprocess.Popen([sys.executable, "-m", "cipstack", "adapter", "--port", str(port), "--io-port", "0",
                                    "--state", str(tmp_path / "state.json"), "--control", str(tmp_path / "c.sock"),
                                    "--http", f"127.0.0.1:{http}", *args],
                                   stdout=subprocess.DEVNULL, stderr=err, text=True)
    try:
        wait_for(lambda: "HTTP control API on" in log.read_text() or process.poll() is not None, 20, "the API")
        assert process.poll() is None, log.read_text()
        yield process, port, http
    finally:
        if process.poll() is None:
            process.kill()
        process.wait(10)
    assert "Traceback" not in log.read_text(), log.read_text()


def no_script_error(browser: Any) -> None:
    errors = [entry for entry in browser.get_log("browser") if entry.get("source") == "javascript"]
    assert errors == [], errors


def text(browser: Any, element_id: str) -> str:
    return str(browser.find_element("id", element_id).text)


def write_parameter(browser: Any, code: str, value: str) -> str:
    """Type ``value`` into the field of ``code`` and press Enter; what the page then says beside it."""
    field = browser.find_element("id", f"parameter-{code}")
    note = field.find_element("xpath", "following-sibling::span")
    # The note is marked as waiting; the page's answer (a meaning, "written" or the device's refusal)
    # replaces the mark, whatever the note said before (a refusal, then the same refusal, included).
    pending = "(waiting for the answer)"
    browser.execute_script("arguments[0].closest('details').open = true; arguments[0].scrollIntoView();"
                           "arguments[1].textContent = arguments[2]", field, note, pending)
    from selenium.webdriver.common.keys import Keys

    field.click()                     # focused: the page's refresh of the values leaves it alone
    field.send_keys(Keys.CONTROL, "a")
    field.send_keys(value + "\n")
    wait_for(lambda: note.get_attribute("textContent") != pending, 10, f"the answer to {code}={value}")
    return str(note.text)


def read_identity(port: int) -> str | None:
    """pycomm3 reads Identity's product name: the error it reports, or None when the read succeeds."""
    from pycomm3 import CIPDriver, Services

    with CIPDriver(f"127.0.0.1:{port}") as driver:
        tag = driver.generic_message(service=Services.get_attribute_single, class_code=1, instance=1, attribute=7,
                                     connected=False, route_path=False)
        return None if tag.error is None else str(tag.error)


def test_the_acg_panel_runs_faults_refuses_and_loses_power(tmp_path: Path) -> None:
    pytest.importorskip("pycomm3", reason="pycomm3 is the independent client that sees the fault (the test extra)")
    with adapter(tmp_path) as (process, port, http), chromium(tmp_path / "profile") as browser:
        browser.set_window_size(1280, 1600)
        browser.get(f"http://127.0.0.1:{http}/")
        wait_for(lambda: text(browser, "link-state") == "live", 20, "the panel's stream")
        assert text(browser, "state") == "READY" and text(browser, "display") == "0.00"
        # Every control has a name a screen reader says (a label, aria-label, or its own text).
        unnamed = browser.execute_script(
            "return [...document.querySelectorAll('input, select, button, canvas, output')].filter(e =>"
            " !(e.labels && e.labels.length) && !e.getAttribute('aria-label') && !e.textContent.trim())"
            ".map(e => e.outerHTML.slice(0, 80))")
        assert unnamed == []

        # The network as the command and frequency source, from the keypad's parameter fields.
        assert write_parameter(browser, "drv", "4") == "Field Bus"
        assert write_parameter(browser, "Frq", "8") == "Field Bus"
        # A value out of range: the device's own refusal, next to the field.
        assert "takes 0.0..6000.0 s" in write_parameter(browser, "ACC", "99999")
        assert write_parameter(browser, "ACC", "1.0") == "written"

        io = subprocess.Popen([sys.executable, "-m", "cipstack", "io", f"127.0.0.1:{port}", "--output", "21",
                               "--input", "71", "--rpi", "20ms", "--io-port", "0", "--set", "run_forward=1",
                               "--set", "net_ctrl=1", "--set", "net_ref=1", "--set", "speed_reference=900",
                               "--duration", "60s"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        try:
            table = browser.find_element("id", "class1-table")
            wait_for(lambda: "21 → 71" in table.text and "run_forward = 1" in table.text, 20,
                     "the connection with its decoded output")
            wait_for(lambda: "lit" in (browser.find_element("id", "ind-run").get_attribute("class") or "").split(), 20,
                     "RUN lit")
            wait_for(lambda: text(browser, "output") not in ("0.00 Hz", "-"), 20, "the output frequency")
            assert "lit" in (browser.find_element("id", "ind-fwd").get_attribute("class") or "").split()

            # A fault from the page's form, seen by pycomm3; cleared from the page's list.
            from selenium.webdriver.support.select import Select

            Select(browser.find_element("id", "fault-name")).select_by_value("error-status")
            browser.find_element("id", "fault-option-status").send_keys("0x08")
            browser.find_element("id", "fault-option-class").send_keys("1")
            browser.find_element("css selector", "#fault-form button[type=submit]").click()
            faults = browser.find_element("id", "faults-table")
            wait_for(lambda: "error-status" in faults.text, 10, "the active fault")
            assert read_identity(port) is not None
            faults.find_element("css selector", "button").click()
            wait_for(lambda: "error-status" not in faults.text, 10, "the fault cleared")
            assert read_identity(port) is None

            # The power cut and restored.
            browser.find_element("id", "power-off").click()
            wait_for(lambda: text(browser, "power") == "off", 10, "power off")
            wait_for(lambda: "no class 1 connection" in table.text, 10, "the connection gone with the power")
            browser.find_element("id", "power-on").click()
            wait_for(lambda: text(browser, "power") == "on", 10, "power on")
            wait_for(lambda: text(browser, "link-state") == "live", 10, "the panel live again")
        finally:
            io.kill()
            io.communicate()
        events = browser.find_element("id", "event-list")
        wait_for(lambda: "fault applied" in events.text and "parameter write" in events.text, 10, "the events")
        numbers = [line.split()[1] for line in events.text.splitlines()]
        assert len(numbers) == len(set(numbers))                       # each event once, across reconnections
        browser.find_element("id", "event-filter").send_keys("parameter write")
        assert events.text and all("parameter write" in line for line in events.text.splitlines())
        no_script_error(browser)
        # An open panel does not hold up a stop.
        process.send_signal(signal.SIGINT)
        started = time.monotonic()
        assert process.wait(30) == 0
        assert time.monotonic() - started < 2.0


def test_the_panel_shows_the_voltages_while_running_and_says_what_is_not_simulated(tmp_path: Path) -> None:
    """Issue 52, item 7: at 50 Hz the operation group's vOL is the V/f output voltage (230 V x 50 / 60 Hz)
    and dCL the DC link (sqrt(2) x 230 V); the output current, which the emulator has no model for,
    says "not simulated" in the status and beside its parameter, rather than a plausible-looking 0.0 A."""
    with adapter(tmp_path, "--param", "drv=4", "--param", "Frq=8", "--param", "ACC=0.5") as (_, port, http), \
            chromium(tmp_path / "profile") as browser:
        for path, value in (("0x2A/1/101", "5000"), ("0x29/1/3", "1")):
            done = subprocess.run([sys.executable, "-m", "cipstack", "set", f"127.0.0.1:{port}", path, value],
                                  capture_output=True, text=True, timeout=30)
            assert done.returncode == 0, done.stderr
        browser.set_window_size(1280, 1600)
        browser.get(f"http://127.0.0.1:{http}/")
        wait_for(lambda: text(browser, "link-state") == "live", 20, "the panel's stream")
        wait_for(lambda: text(browser, "output") == "50.00 Hz", 20, "50 Hz")
        assert text(browser, "current") == "not simulated"

        def field(code: str) -> Any:
            return browser.find_element("id", f"parameter-{code}")

        wait_for(lambda: field("vOL").get_attribute("value") == "192", 20, "the output voltage at 50 Hz")
        assert field("dCL").get_attribute("value") == "325"
        assert field("Cur").find_element("xpath", "following-sibling::span").get_attribute("textContent") == \
            "not simulated"
        no_script_error(browser)


def test_the_plant_lists_every_device_and_links_to_its_panel(tmp_path: Path) -> None:
    require_browser()
    hosts = [f"127.79.11.{10 + n}" for n in range(3)]
    port, http = free_port(*hosts), free_port()
    fleet = Fleet(tmp_path, "--addresses", f"{hosts[0]}-{hosts[-1]}", "--device", "acg*2", "--device", "mx2*1",
                  "--port", str(port), "--io-port", "0", "--workers", "2", "--state-dir", str(tmp_path / "state"),
                  "--http", f"127.0.0.1:{http}")
    try:
        fleet.wait_ready()
        with chromium(tmp_path / "profile") as browser:
            browser.get(f"http://127.0.0.1:{http}/")
            grid = browser.find_element("id", "plant-table")
            wait_for(lambda: grid.text.count("on / plugged") == 3, 20, "every device's state")
            assert all(host in grid.text for host in hosts) and "MX2" in grid.text
            # One case for one state, whichever family says it (the ACG READY, the MX2 ready).
            states = [row.find_elements("css selector", "td")[3].text
                      for row in grid.find_elements("css selector", "tbody tr")]
            assert states == ["READY"] * 3, states
            # A worker that ended: its devices say so, the others go on.
            os.kill(worker_pid(hosts[0], port), signal.SIGKILL)
            wait_for(lambda: grid.text.count("worker ended") == 2, 20, "the ended worker's devices")
            assert grid.text.count("on / plugged") >= 1
            browser.find_element("id", "plant-filter").send_keys("MX2")
            rows = grid.find_elements("css selector", "tbody tr")
            assert [row.is_displayed() for row in rows] == [False, False, True]
            browser.find_element("link text", hosts[2]).click()
            wait_for(lambda: text(browser, "title") == hosts[2] and text(browser, "link-state") == "live", 20,
                     "the MX2's panel through the relay")
            wait_for(lambda: text(browser, "state") == "READY", 10, "its state, in the ACG's case")
            groups = browser.find_element("id", "parameter-groups")
            wait_for(lambda: "d (" in groups.text, 10, "the Digital Operator's monitor codes")
            assert browser.find_element("id", "parameter-d001").get_attribute("readonly") is not None
            no_script_error(browser)
        fleet.stop(signal.SIGINT)
    finally:
        fleet.kill()


@pytest.mark.overload  # 1,024 drives start on both CPUs at once
def test_the_grid_of_a_thousand_drives_is_summed_up_sorted_filtered_and_live(tmp_path: Path) -> None:
    """1,024 drives on two workers: the grid has a row for each from one request a refresh, a summary
    by state whose counts filter, headings that sort, and a trip through the API seen in it."""
    require_browser()
    first = ipaddress.IPv4Address("127.79.16.1")
    hosts = [str(first + n) for n in range(1024)]
    port, http = free_port(hosts[0], hosts[-1]), free_port()
    fleet = Fleet(tmp_path, "--addresses", f"{hosts[0]}-{hosts[-1]}", "--device", "acg*1024", "--port", str(port),
                  "--io-port", "0", "--workers", "2", "--factory", "--http", f"127.0.0.1:{http}")
    try:
        fleet.wait_ready(120)
        with chromium(tmp_path / "profile") as browser:
            browser.get(f"http://127.0.0.1:{http}/")
            wait_for(lambda: text(browser, "plant-summary") == "1024 devices: 1024 READY", 30, "every drive READY")
            tripped = hosts[700]
            request = urllib.request.Request(f"http://127.0.0.1:{http}/devices/{tripped}/trip", method="POST",
                                             data=json.dumps({"code": "OverHeat"}).encode(),
                                             headers={"Content-Type": "application/json"})
            with urllib.request.urlopen(request, timeout=30) as reply:
                assert reply.status == 200
            try:
                wait_for(lambda: text(browser, "plant-summary") == "1024 devices: 1023 READY 1 FAULT_STOP", 20,
                         "the trip in the summary")
            except TimeoutError:
                raise AssertionError(text(browser, "plant-summary")) from None
            grid = browser.find_element("id", "plant-table")

            def first_rows(count: int) -> list[list[str]]:
                return browser.execute_script(
                    "return [...arguments[0].tBodies[0].rows].slice(0, arguments[1])"
                    ".map((tr) => [...tr.cells].map((td) => td.textContent))", grid, count)

            headings = grid.find_elements("css selector", "thead th button")
            headings[3].click()                                    # by state: FAULT_STOP before READY
            assert first_rows(2)[0][:4] == [tripped, "CENT", "2", "FAULT_STOP (OverHeat)"], first_rows(2)
            headings[0].click()
            headings[0].click()                                    # by address, from the last
            assert [r[0] for r in first_rows(2)] == [hosts[-1], hosts[-2]]
            # The summary's button is the same element from one refresh to the next, its count changed in
            # place: one taken before a second trip is clicked after it (it would be stale if rebuilt).
            faulted = browser.find_element("css selector", "#plant-summary button[data-filter='FAULT_STOP']")
            second = hosts[701]
            request = urllib.request.Request(f"http://127.0.0.1:{http}/devices/{second}/trip", method="POST",
                                             data=json.dumps({"code": "OverHeat"}).encode(),
                                             headers={"Content-Type": "application/json"})
            with urllib.request.urlopen(request, timeout=30) as reply:
                assert reply.status == 200
            wait_for(lambda: faulted.text == "2 FAULT_STOP", 20, "the second trip counted on the same button")
            faulted.click()
            assert text(browser, "plant-shown") == "2 of 1024 shown"
            assert [row.text.split()[0] for row in grid.find_elements("css selector", "tbody tr")
                    if row.is_displayed()] == [second, tripped]
            no_script_error(browser)
        fleet.stop(signal.SIGINT)
    finally:
        fleet.kill()


def test_the_mx2_panel_shows_its_reference_in_hz_on_a_round_axis(tmp_path: Path) -> None:
    """The MX2's speed reference is a word in 0.01 Hz (CompoNet manual, P049 and d060): shown as the
    frequency it stands for ("0.00 Hz", not "0 (0.01 Hz)"); its state in the ACG's case; and the trend's
    axis at round steps (0/20/40/60 Hz for a 50 Hz reference, where it read 13.8/27.5/41.3/55.0)."""
    with adapter(tmp_path, "--profile", "mx2") as (_, port, http), chromium(tmp_path / "profile") as browser:
        browser.get(f"http://127.0.0.1:{http}/")
        wait_for(lambda: text(browser, "link-state") == "live", 20, "the panel's stream")
        wait_for(lambda: text(browser, "state") != "-", 10, "the drive's state")
        assert text(browser, "state") == "READY"
        assert text(browser, "reference") == "0.00 Hz"
        trend = browser.find_element("id", "trend")
        wait_for(lambda: str(trend.get_attribute("aria-label")).endswith(", axis 0, 2, 4, 6, 8, 10, 12 Hz"), 10,
                 "the idle drive's axis")
        written = subprocess.run([sys.executable, "-m", "cipstack", "set", f"127.0.0.1:{port}", "0x2A/1/8", "5000"],
                                 capture_output=True, text=True, timeout=60)       # Speed Ref: 50.00 Hz
        assert written.returncode == 0, written.stderr
        wait_for(lambda: text(browser, "reference") == "50.00 Hz", 10, "the new reference")
        wait_for(lambda: str(trend.get_attribute("aria-label")).endswith(", axis 0, 20, 40, 60 Hz"), 10,
                 "the axis up to 60 Hz in steps of 20")
        assert browser.execute_script("return [trendTicks(60), trendTicks(400)]") == [
            [0, 25, 50, 75], [0, 100, 200, 300, 400, 500]]
        no_script_error(browser)


def test_an_unknown_device_in_the_address_says_so_and_lists_the_devices(tmp_path: Path) -> None:
    """`/?device=ADDRESS` for a device the API does not serve: a message that says so, and the devices it
    does serve, each a link to its panel (it was an uncaught promise error and a blank page)."""
    with adapter(tmp_path) as (_, _, http), chromium(tmp_path / "profile") as browser:
        browser.get(f"http://127.0.0.1:{http}/?device=127.0.0.99")
        message = browser.find_element("id", "page-message")
        wait_for(lambda: message.is_displayed(), 10, "the message")
        assert message.text == ('There is no device "127.0.0.99" here (?device=127.0.0.99): the devices this API '
                                'serves are below.')
        grid = browser.find_element("id", "plant-table")
        wait_for(lambda: "on / plugged" in grid.text, 20, "the device that is there")
        no_script_error(browser)
        browser.find_element("link text", "127.0.0.1").click()
        wait_for(lambda: text(browser, "link-state") == "live" and text(browser, "state") == "READY", 20,
                 "its panel")
        assert not browser.find_element("id", "page-message").is_displayed()
        no_script_error(browser)


def test_the_panel_asks_for_the_token_once_and_keeps_it_for_the_tab(tmp_path: Path) -> None:
    token = tmp_path / "token"
    token.write_text("panel-s3cret\n")
    with adapter(tmp_path, "--http-token-file", str(token)) as (_, _, http), \
            chromium(tmp_path / "profile") as browser:
        browser.get(f"http://127.0.0.1:{http}/")
        dialog = browser.find_element("id", "token-dialog")
        wait_for(lambda: dialog.get_attribute("open") is not None, 10, "the token dialog")
        browser.find_element("id", "token-input").send_keys("panel-s3cret\n")
        wait_for(lambda: text(browser, "link-state") == "live", 20, "the panel, with the token")
        browser.refresh()                                                  # the same tab: not asked again
        wait_for(lambda: text(browser, "link-state") == "live", 20, "the panel after a reload")
        assert browser.find_element("id", "token-dialog").get_attribute("open") is None
        no_script_error(browser)


def test_the_pictures_of_the_docs_are_made_from_live_pages(tmp_path: Path) -> None:
    """tools/panel_screenshots.py, as the docs say it made docs/images: two PNG pictures of live pages,
    and it fails on a script error of the page."""
    require_browser()
    root = Path(__file__).resolve().parents[1]
    result = subprocess.run([sys.executable, str(root / "tools" / "panel_screenshots.py"), str(tmp_path), "--at-once"],
                            capture_output=True, text=True, timeout=180, cwd=root)
    assert result.returncode == 0, result.stderr
    for name in ("front-panel.png", "plant.png"):
        picture = (tmp_path / name).read_bytes()
        assert picture[:8] == b"\x89PNG\r\n\x1a\n" and len(picture) > 20_000, name
