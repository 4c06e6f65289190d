"""The token of an HTTP API that serves other than loopback (``--http-allow-remote``) is the only lock on
it: ``cipstack fleet`` and ``cipstack plant`` (and every command with ``--http``) refuse to serve with a
token that can be guessed, wherever it comes from (``--http-token-file``, as a Kubernetes Secret gives
it; ``CIPSTACK_HTTP_TOKEN``; ``--http-token``): shorter than 32 characters, of a handful of different
characters, or one ever shipped in the repository, such as the ``replace-this-token`` every overlay of
deploy/ once carried. Each refusal is one line naming the fix, exit status 2, before anything listens,
and never repeats the token. A token made as docs/kubernetes.md says is served. Run as real commands."""

from __future__ import annotations

import os
import secrets
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("aiohttp", reason="aiohttp is not installed (the http extra): pip install '.[http]'")

from cipstack.control.http import HttpApiError, check_settings
from cipstack.control.tokens import KNOWN_WEAK_TOKENS, MIN_REMOTE_TOKEN_LENGTH, weak_token_reason
from tests.cli_errors import one_line_error
from tests.http_client import status
from tests.ports import free_port
from tests.test_fleet import running
from tests.waiting import wait_for

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="any 127.x on loopback")

#: Loopback addresses of this file's own.
DEVICE, API = "127.84.1.10", "127.84.2.1"
#: What a careless deployment gives: deploy/'s old placeholder, one character short, one character
#: forty times (each is refused for its own reason, said in the line).
WEAK = {
    "placeholder": ("replace-this-token", "published in cipstack's repository"),
    "short": (secrets.token_hex(16)[:MIN_REMOTE_TOKEN_LENGTH - 1], "has 31 characters"),
    "monotonous": ("x" * 40, "made of 1 different character"),
}


def command(name: str, tmp_path: Path) -> list[str]:
    """``cipstack fleet`` or ``cipstack plant`` with its HTTP API on a loopback address, remote allowed."""
    http = f"{API}:{free_port(API)}"
    if name == "fleet":
        return ["fleet", "--device", f"acg@{DEVICE}", "--port", str(free_port(DEVICE)), "--io-port", "0",
                "--state-dir", str(tmp_path / "state"), "--http", http, "--http-allow-remote"]
    return ["plant", "--fleet", f"{API}:{free_port(API)}", "--http", http, "--http-allow-remote"]


def given(where: str, token: str, tmp_path: Path) -> tuple[list[str], dict[str, str]]:
    """The options and environment that hand ``token`` over ``where``."""
    if where == "file":   # as the manifests do: a Secret's key, mounted as a file
        secret = tmp_path / "token"
        secret.write_text(token + "\n", encoding="utf-8")
        secret.chmod(0o600)
        return ["--http-token-file", str(secret)], {}
    if where == "environment":
        return [], {"CIPSTACK_HTTP_TOKEN": token}
    return ["--http-token", token], {}


def cipstack(args: list[str], environment: dict[str, str]) -> subprocess.CompletedProcess[str]:
    env = {key: value for key, value in os.environ.items() if key != "CIPSTACK_HTTP_TOKEN"}
    # Bounded: a command that served instead of refusing is ended here, and the test fails on it.
    return subprocess.run([sys.executable, "-m", "cipstack", *args], capture_output=True, text=True, timeout=30,
                          stdin=subprocess.DEVNULL, env={**env, **environment})


@pytest.mark.parametrize("weakness", sorted(WEAK))
@pytest.mark.parametrize("where", ["file", "environment", "option"])
@pytest.mark.parametrize("name", ["fleet", "plant"])
def test_a_remote_api_with_a_token_that_can_be_guessed_is_refused(name: str, where: str, weakness: str,
                                                                  tmp_path: Path) -> None:
    token, said = WEAK[weakness]
    options, environment = given(where, token, tmp_path)
    try:
        result = cipstack([*command(name, tmp_path), *options], environment)
    except subprocess.TimeoutExpired:
        pytest.fail(f"cipstack {name} served --http-allow-remote with the {weakness} token")
    line = one_line_error(result)
    assert result.returncode == 2 and result.stdout == "", result.stderr
    assert line.startswith(f"cipstack {name}: ") and said in line, line
    assert "openssl rand -hex 32" in line, line                      # the fix, named
    source = {"file": f"--http-token-file {tmp_path / 'token'}", "environment": "CIPSTACK_HTTP_TOKEN",
              "option": "--http-token"}[where]
    assert source in line, line                                      # and where the token came from
    if weakness != "placeholder":                                    # a real (short) token is not logged
        assert token not in result.stderr
    assert not (tmp_path / "state").exists()                         # refused before it started anything


def test_the_same_token_on_loopback_alone_is_still_served(tmp_path: Path) -> None:
    """Without --http-allow-remote the address is the lock and the token a second one: not refused."""
    http = free_port(API)
    options, _ = given("file", "replace-this-token", tmp_path)
    with running(tmp_path, "--device", f"acg@{DEVICE}", "--port", str(free_port(DEVICE)), "--io-port", "0",
                 "--state-dir", str(tmp_path / "state"), "--http", f"{API}:{http}", *options):
        assert status(f"http://{API}:{http}/devices", "replace-this-token") == 200


@pytest.mark.parametrize("length", [MIN_REMOTE_TOKEN_LENGTH, 64])
def test_a_token_made_as_the_docs_say_is_served_remotely(length: int, tmp_path: Path) -> None:
    """32 characters (the least), and 64 (``openssl rand -hex 32``): the fleet serves with them."""
    token = secrets.token_hex(length // 2)
    http = free_port(API)
    options, _ = given("file", token, tmp_path)
    with running(tmp_path, "--device", f"acg@{DEVICE}", "--port", str(free_port(DEVICE)), "--io-port", "0",
                 "--state-dir", str(tmp_path / "state"), "--http", f"{API}:{http}", "--http-allow-remote",
                 *options):
        base = f"http://{API}:{http}/devices"
        wait_for(lambda: status(base, token) == 200, 10, "the fleet's API")
        assert status(base, None) == 401 and status(base, token[:-1] + "!") == 401


def test_the_library_refuses_it_too() -> None:
    """``HttpApi`` and ``RelayApi`` check their settings with ``check_settings``: a program that builds
    one with a weak token and ``allow_remote`` gets the same refusal as the command line."""
    for token, said in WEAK.values():
        with pytest.raises(HttpApiError, match=said):
            check_settings("0.0.0.0:8080", token, True)
        check_settings("127.0.0.1:8080", token, False)   # loopback: the address is the lock
    assert check_settings("0.0.0.0:8080", secrets.token_hex(32), True) == ("0.0.0.0", 8080)
    assert "replace-this-token" in KNOWN_WEAK_TOKENS
    assert all(weak_token_reason(known) is not None for known in KNOWN_WEAK_TOKENS)


