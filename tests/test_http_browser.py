"""A web page of another origin, in a real headless Chromium, against the HTTP API of one adapter and
of a fleet's relay: every way a page can send a state-changing request without the API's consent
(a ``no-cors`` fetch, a plain HTML form, a sandboxed ``Origin: null`` frame, a CORS request that needs
a preflight) reaches the API and is refused, and the drive neither trips nor takes a fault. A page
reached under a foreign host name (DNS rebinding) is refused for every request, and a page of the
API's own origin is served: the refusals are the origin's, not the browser's."""

from __future__ import annotations

import json
import subprocess
import sys
import threading
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

import pytest

from tests.browser import chromium, require_browser
from tests.ports import free_port
from tests.test_cli import stop
from tests.test_fleet import Fleet
from tests.waiting import wait_for

pytestmark = [pytest.mark.browser,
              pytest.mark.skipif(not sys.platform.startswith("linux"), reason="any 127.x on loopback")]

FAULT = '{"name": "error-status", "options": {"status": "0x08", "class": 1}}'
TRIP = '{"code": "OverHeat"}'
#: What the page tries, by name; each entry's outcome is what the page could see of it.
ATTEMPTS = ("no-cors trip", "no-cors fault", "no-cors fault typed json", "cors fault", "form trip",
            "form fault", "null-origin trip")


def in_script(text: str) -> str:
    """``text`` as a JavaScript string literal that can stand inside a <script> element."""
    return json.dumps(text).replace("</", "<\\/")


def hostile_page(api: str) -> bytes:
    """The page of another origin: it sends each of ``ATTEMPTS`` to ``api`` and records in
    ``window.results`` whether an answer came back (opaque to it) or the browser blocked the request."""
    sandboxed = ("<script>fetch(" + json.dumps(api + "/trip") + ", {method: 'POST', mode: 'no-cors', body: "
                 + json.dumps(TRIP) + "}).then(() => parent.postMessage('answered', '*'), "
                 "e => parent.postMessage('blocked:' + e.name, '*'))</script>")
    return f"""<!doctype html><html><head><title>another origin</title></head><body>
<form id="form-trip" method="POST" action="{api}/trip" enctype="text/plain" target="sink-trip">
  <input name='{{"code": "OverHeat", "x": "' value='"}}'></form>
<iframe name="sink-trip"></iframe>
<form id="form-fault" method="POST" action="{api}/faults" target="sink-fault">
  <input name="name" value="error-status"></form>
<iframe name="sink-fault"></iframe>
<script>
window.results = {{}};
const api = {json.dumps(api)};
async function attempt(name, request) {{
  try {{ const reply = await request; results[name] = "answered:" + reply.type; }}
  catch (error) {{ results[name] = "blocked:" + error.name; }}
}}
function submitted(form, sink, name) {{
  return new Promise(done => {{
    document.querySelector(`iframe[name=${{sink}}]`).onload = () => {{ results[name] = "answered"; done(); }};
    document.getElementById(form).submit();
  }});
}}
window.addEventListener("message", event => {{ results["null-origin trip"] = event.data; }});
window.addEventListener("load", async () => {{
  await attempt("no-cors trip", fetch(api + "/trip", {{method: "POST", mode: "no-cors", body: {json.dumps(TRIP)}}}));
  await attempt("no-cors fault", fetch(api + "/faults", {{method: "POST", mode: "no-cors",
      body: {json.dumps(FAULT)}}}));
  await attempt("no-cors fault typed json", fetch(api + "/faults", {{method: "POST", mode: "no-cors",
      headers: {{"Content-Type": "application/json"}}, body: {json.dumps(FAULT)}}}));
  await attempt("cors fault", fetch(api + "/faults", {{method: "POST",
      headers: {{"Content-Type": "application/json"}}, body: {json.dumps(FAULT)}}}));
  await submitted("form-trip", "sink-trip", "form trip");
  await submitted("form-fault", "sink-fault", "form fault");
  const frame = document.createElement("iframe");
  frame.setAttribute("sandbox", "allow-scripts");
  frame.srcdoc = {in_script(sandboxed)};
  document.body.appendChild(frame);
}});
</script></body></html>""".encode()


@contextmanager
def served_page(address: str, page: bytes) -> Iterator[str]:
    """``page`` served at ``/`` of http://ADDRESS:PORT (another origin than the API's); its URL."""

    class Page(BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            self.send_response(200)
            self.send_header("Content-Type", "text/html; charset=utf-8")
            self.send_header("Content-Length", str(len(page)))
            self.end_headers()
            self.wfile.write(page)

        def log_message(self, *args: Any) -> None:
            pass

    server = ThreadingHTTPServer((address, free_port(address)), Page)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://{address}:{server.server_address[1]}/"
    finally:
        server.shutdown()
        server.server_close()
        thread.join(5)


@dataclass
class Target:
    """The API a page attacks: ``origin`` (http://127.0.0.1:PORT), ``prefix`` of one device's routes,
    and the file its process logs to."""

    origin: str
    prefix: str
    log: Path

    def get(self, path: str) -> Any:
        """What a script (no browser headers) reads at ``path`` of the device."""
        with urllib.request.urlopen(self.origin + self.prefix + path, timeout=10) as reply:
            return json.loads(reply.read())


@contextmanager
def adapter_api(tmp_path: Path) -> Iterator[Target]:
    http = free_port()
    log = tmp_path / "adapter.err"
    with log.open("w") as err:
        process = subprocess.Popen([sys.executable, "-m", "cipstack", "adapter", "--port", str(free_port()),
                                    "--io-port", "0", "--state", str(tmp_path / "acg.json"),
                                    "--control", str(tmp_path / "control.sock"), "--http", f"127.0.0.1:{http}"],
                                   stdout=subprocess.DEVNULL, stderr=err, text=True)
    try:
        wait_for(lambda: "HTTP control API on" in log.read_text() or process.poll() is not None, 20, "the HTTP API")
        assert process.poll() is None, log.read_text()
        yield Target(f"http://127.0.0.1:{http}", "", log)
    finally:
        stop(process)


@contextmanager
def fleet_api(tmp_path: Path) -> Iterator[Target]:
    host, http = "127.79.9.10", free_port()
    port = free_port(host)
    fleet = Fleet(tmp_path, "--addresses", f"{host}-127.79.9.11", "--device", "acg*2", "--port", str(port),
                  "--io-port", "0", "--workers", "2", "--state-dir", str(tmp_path / "state"),
                  "--http", f"127.0.0.1:{http}")
    try:
        fleet.wait_ready()
        yield Target(f"http://127.0.0.1:{http}", f"/devices/{host}", fleet.err)
        assert fleet.stop() == 0
    finally:
        fleet.kill()


@pytest.fixture(params=["adapter", "fleet relay"])
def target(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[Target]:
    require_browser()
    with (adapter_api if request.param == "adapter" else fleet_api)(tmp_path) as api:
        yield api


FETCH = """const [url, method, body, done] = arguments;
fetch(url, {method, headers: body ? {"Content-Type": "application/json"} : {}, body})
  .then(async reply => done([reply.status, await reply.text()]), error => done(["blocked", error.name]));"""


def test_a_page_of_another_origin_reaches_the_api_and_changes_nothing(target: Target, tmp_path: Path) -> None:
    api = target.origin + target.prefix
    with served_page("127.0.0.2", hostile_page(api)) as page, chromium(tmp_path / "profile") as browser:
        browser.get(page)
        wait_for(lambda: len(browser.execute_script("return window.results")) == len(ATTEMPTS), 30,
                 "the page's attempts")
        results = browser.execute_script("return window.results")
    # Every request but the one that needs a preflight was sent and answered (opaque to the page);
    # the preflight was not consented to, so the browser never sent that POST.
    assert results == {"no-cors trip": "answered:opaque", "no-cors fault": "answered:opaque",
                       "no-cors fault typed json": "answered:opaque", "cors fault": "blocked:TypeError",
                       "form trip": "answered", "form fault": "answered", "null-origin trip": "answered"}
    assert target.get("/status")["drive"]["trip"] is None
    assert target.get("/faults") == []
    refusals = [line for line in target.log.read_text().splitlines() if "refused (403)" in line]
    assert len([line for line in refusals if line.count("/trip")]) == 3, refusals       # fetch, form, null
    assert len([line for line in refusals if line.count("/faults")]) == 3, refusals     # two fetches, form
    assert any("Origin 'null'" in line for line in refusals)
    assert "Traceback" not in target.log.read_text()


def test_a_rebound_name_is_refused_and_the_apis_own_origin_is_served(target: Target, tmp_path: Path) -> None:
    """Under ``rebind.example`` (resolved to the API's address inside the browser, as a rebinding
    attacker's name is) the page's same-origin requests carry a matching ``Origin``, and the ``Host``
    check alone refuses them; the same requests from the API's own origin are served."""
    port = target.origin.rsplit(":", 1)[1]
    rebound = f"http://rebind.example:{port}"
    with chromium(tmp_path / "profile", resolve={"rebind.example": "127.0.0.1"}) as browser:
        browser.get(rebound + target.prefix + "/status")
        assert "is not this API's" in browser.find_element("tag name", "body").text
        status, text = browser.execute_async_script(FETCH, rebound + target.prefix + "/faults", "POST", FAULT)
        assert status == 403 and "Host 'rebind.example'" in json.loads(text)["error"]
        assert target.get("/faults") == []

        browser.get(target.origin + "/openapi.json")                    # a page of the API's own origin
        status, text = browser.execute_async_script(FETCH, target.origin + target.prefix + "/faults", "POST", FAULT)
        assert status == 201 and json.loads(text)["name"] == "error-status"
        assert [fault["name"] for fault in target.get("/faults")] == ["error-status"]
        status, _ = browser.execute_async_script(FETCH, target.origin + target.prefix + "/faults", "DELETE", None)
        assert status == 200
    assert target.get("/faults") == []
