"""The screenshots of docs/front-panel.md, taken from live pages: an ACG adapter run by a class 1
connection (`cipstack io`) with a fault applied, and a fleet's plant view. Run from the repository:

    python3 tools/panel_screenshots.py docs/images

Each picture is taken once the page shows what it is of (the drive running under its connection, the
fault listed; every device of the plant polled, the tripped one marked), and then after the front
panel's trend has gathered a few seconds of history; `--at-once` leaves out that history (the tests).

It needs what the browser tests need (Debian's chromium and chromium-driver, selenium)."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.browser import chromium  # noqa: E402  (the browser the tests drive, set up once)
from tests.ports import free_port  # noqa: E402
from tests.waiting import wait_for  # noqa: E402


def wait_listening(port: int, seconds: float = 30) -> None:
    def accepting() -> bool:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
        except OSError:
            return False
        return True

    wait_for(accepting, seconds, f"127.0.0.1:{port} to accept")


def call(base: str, method: str, path: str, body: object) -> object:
    request = urllib.request.Request(base + path, method=method, data=json.dumps(body).encode(),
                                     headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(request, timeout=10) as reply:
        return json.loads(reply.read())


#: The front panel shows the drive running under a class 1 connection.
RUNNING = ("return document.getElementById('state').className === 'state-running'"
           " && document.getElementById('class1-table').tBodies[0].rows.length > 0")
#: ... and the fault applied.
FAULTED = RUNNING + " && document.getElementById('faults-table').tBodies[0].rows.length > 0"
#: The plant view has read every device, and marks the tripped one.
POLLED = ("const rows = [...document.getElementById('plant-table').tBodies[0].rows];"
          " return rows.length > 0 && rows.every((r) => r.cells[3].textContent !== '\u2026')"
          " && rows.some((r) => r.cells[3].className === 'down')")


def showing(driver: Any, script: str, what: str, seconds: float = 60) -> None:
    """Wait until the page's ``script`` returns true."""
    wait_for(lambda: driver.execute_script(script), seconds, what, interval=0.1)


def laid_out(driver: Any) -> None:
    """Wait until the page has drawn two frames (its layout after a change of the window's size)."""
    driver.execute_async_script("const done = arguments[arguments.length - 1];"
                                " requestAnimationFrame(() => requestAnimationFrame(() => done(true)));")


def shoot(driver: Any, url: str, out: Path, ready: str, history: float, height: int) -> None:
    driver.get(url)
    showing(driver, ready, f"{url} to show its subject")
    time.sleep(history)                   # the trend's history in the picture (0 with --at-once)
    driver.set_window_size(1280, height)
    laid_out(driver)
    driver.save_screenshot(str(out))
    errors = [e for e in driver.get_log("browser") if e.get("source") == "javascript"]
    if errors:
        raise RuntimeError(f"{url}: the page logged script errors: {errors}")
    print(out)


def main(out: Path, at_once: bool = False) -> None:
    out.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp())
    port, http = free_port(), free_port()
    started: list[subprocess.Popen[bytes]] = []
    try:
        started.append(subprocess.Popen([sys.executable, "-m", "cipstack", "adapter", "--port", str(port), "--io-port",
                                         "0", "--quiet", "--state", str(work / "acg.json"), "--control",
                                         str(work / "c.sock"), "--http", f"127.0.0.1:{http}"],
                                        stderr=subprocess.DEVNULL))
        wait_listening(http)
        base = f"http://127.0.0.1:{http}"
        for code, value in (("drv", "4"), ("Frq", "8"), ("ACC", "8.0")):
            call(base, "PUT", f"/parameters/{code}", {"value": value})
        started.append(subprocess.Popen([sys.executable, "-m", "cipstack", "io", f"127.0.0.1:{port}", "--output", "21",
                                         "--input", "71", "--rpi", "20ms", "--io-port", "0", "--set", "run_forward=1",
                                         "--set", "net_ctrl=1", "--set", "net_ref=1", "--set", "speed_reference=1500",
                                         "--duration", "120s"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        with chromium(work / "profile") as driver:
            driver.get(base + "/")
            showing(driver, RUNNING, "the drive running under its connection")
            time.sleep(0 if at_once else 3)   # the trend: the ramp before the fault
            call(base, "POST", "/faults", {"name": "delay", "options": {"by": "3ms", "jitter": "1ms"}})
            shoot(driver, base + "/", out / "front-panel.png", FAULTED, 0 if at_once else 6, 1900)
        hosts = [f"127.79.200.{n}" for n in range(10, 14)]
        fleet_http = free_port()
        started.append(subprocess.Popen([sys.executable, "-m", "cipstack", "fleet", "--addresses",
                                         f"{hosts[0]}-{hosts[-1]}", "--device", "acg*2", "--device", "mx2*1",
                                         "--device", "rx*1", "--port", str(free_port(*hosts)), "--io-port", "0",
                                         "--workers", "2", "--state-dir", str(work / "state"), "--http",
                                         f"127.0.0.1:{fleet_http}"], stdout=subprocess.DEVNULL,
                                        stderr=subprocess.DEVNULL))
        wait_listening(fleet_http)
        call(f"http://127.0.0.1:{fleet_http}", "POST", f"/devices/{hosts[1]}/trip", {"code": "OverHeat"})
        with chromium(work / "profile-plant") as driver:
            shoot(driver, f"http://127.0.0.1:{fleet_http}/", out / "plant.png", POLLED, 0, 620)
    finally:
        for process in reversed(started):
            process.terminate()
            process.wait(30)


if __name__ == "__main__":
    arguments = [a for a in sys.argv[1:] if a != "--at-once"]
    main(Path(arguments[0]) if arguments else ROOT / "docs" / "images", at_once="--at-once" in sys.argv[1:])
