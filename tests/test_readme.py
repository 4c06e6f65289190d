"""Every code block of README.md runs as written, against the emulator the reader would have running.

The convention, for whoever writes a block:

* ```` ```python ````: a complete script, run as written (``python3 FILE``); it must exit 0.
* ```` ```console ````: each line starting with ``$ `` is a command, run in order by ``sh`` in one
  scratch directory; the lines after it, up to the next command, are its expected output (its
  stdout, then its stderr). A line ``...`` matches any number of lines; ``...`` inside a line
  matches any text within that line. A command must exit 0 unless its expected output shows an
  error line of the command (one starting ``cipstack``), as a failing command prints.
* ```` ```sh ```` (set-up commands) and ```` ```text ```` (synopses, sample output) are not run.

Each ``##`` section is one test: its blocks run in order against one fresh emulator, the default
``cipstack adapter`` (ACG profile) at 127.0.0.1:44818, or the one the section's own ```` ```sh ````
blocks start before its first runnable block (the last line ``cipstack adapter ...`` or
``cipstack fleet ...``: the tour restarts the adapter with ``--param``; the fleet's section starts
a fleet instead).

The README names the default ports (44818, 2222), so each section runs in a private network
namespace of its own (``unshare -n``, root needed), where they are free whatever else runs on this
machine; ``cipstack`` is this checkout's, run by this interpreter.
"""

from __future__ import annotations

import contextlib
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DEFAULT_ADAPTER = "cipstack adapter"
COMMAND_TIMEOUT = 60.0


@dataclass(frozen=True)
class Block:
    language: str
    text: str
    line: int  # of the opening fence, 1-based


@dataclass(frozen=True)
class Section:
    title: str
    blocks: tuple[Block, ...]

    @property
    def adapter(self) -> str:
        """The emulator the reader has running when the section's first runnable block comes: the last
        ``cipstack adapter ...`` or ``cipstack fleet ...`` its set-up blocks start before it, else the default."""
        found = DEFAULT_ADAPTER
        for block in self.blocks:
            if block.language in ("python", "console"):
                break
            if block.language != "sh":
                continue
            for line in block.text.splitlines():
                for command in line.split("&&"):
                    if command.strip().startswith(("cipstack adapter", "cipstack fleet")):
                        found = command.strip()
        return found

    @property
    def runnable(self) -> bool:
        return any(b.language in ("python", "console") for b in self.blocks)


_FENCE = re.compile(r"^```(\w*)\s*$")


def readme_sections(text: str) -> list[Section]:
    """The README's ``##`` sections with their fenced blocks, in order."""
    sections: list[tuple[str, list[Block]]] = [("(top)", [])]
    lines = text.splitlines()
    index = 0
    while index < len(lines):
        line = lines[index]
        if line.startswith("## "):
            sections.append((line[3:].strip(), []))
        fence = _FENCE.match(line)
        if fence:
            start = index
            index += 1
            body = []
            while index < len(lines) and not lines[index].startswith("```"):
                body.append(lines[index])
                index += 1
            if index == len(lines):
                raise ValueError(f"README.md:{start + 1}: code block never closed")
            sections[-1][1].append(Block(fence.group(1), "\n".join(body) + "\n", start + 1))
        index += 1
    return [Section(title, tuple(blocks)) for title, blocks in sections if blocks]


# -- expected output ---------------------------------------------------------------------------------
def _line_pattern(expected: str) -> re.Pattern[str]:
    return re.compile(".*".join(re.escape(part) for part in expected.rstrip().split("...")) + r"\Z")


def output_matches(expected: list[str], actual: list[str]) -> bool:
    """``expected`` lines against ``actual`` lines: ``...`` alone matches any lines, within a line any text."""
    patterns = [None if e.strip() == "..." else _line_pattern(e) for e in expected]
    actual = [a.rstrip() for a in actual]
    # reach[j]: the first j actual lines are matched by the patterns seen so far.
    reach = [True] + [False] * len(actual)
    for pattern in patterns:
        if pattern is None:
            for j in range(1, len(actual) + 1):
                reach[j] = reach[j] or reach[j - 1]
        else:
            reach = [False] + [reach[j - 1] and bool(pattern.match(actual[j - 1])) for j in range(1, len(actual) + 1)]
    return reach[-1]


def console_commands(block: Block) -> list[tuple[str, list[str], int]]:
    """(command, expected output lines, README line) of each ``$ `` line of a console block."""
    commands: list[tuple[str, list[str], int]] = []
    for offset, line in enumerate(block.text.splitlines(), start=1):
        if line.startswith("$ "):
            commands.append((line[2:], [], block.line + offset))
        elif commands:
            commands[-1][1].append(line)
        elif line.strip():
            raise ValueError(f"README.md:{block.line + offset}: console output before any $ command")
    return commands


def test_output_matching() -> None:
    assert output_matches(["a", "...", "d"], ["a", "b", "c", "d"])
    assert output_matches(["a", "...", "b"], ["a", "b"])
    assert output_matches(["x ... z"], ["x 1 2 z   "])
    assert not output_matches(["a", "b"], ["a", "b", "c"])
    assert not output_matches(["x ... z"], ["x 1 2 y"])
    assert not output_matches(["a", "...", "d"], ["a", "b"])
    assert output_matches(["..."], [])


def test_two_set_up_commands() -> None:
    """The README's set-up stays two commands: install and run the emulator, install and run the tests."""
    installs = [line for s in readme_sections(README.read_text()) for b in s.blocks if b.language == "sh"
                for line in b.text.splitlines() if "pip install" in line]
    assert installs == ['python3 -m pip install . && cipstack adapter',
                        'python3 -m pip install ".[test]" && python3 -m pytest']


def test_readme_is_parsed_whole() -> None:
    """Every fence is closed and has a language this test knows, so no block is left out silently."""
    sections = readme_sections(README.read_text())
    languages = {b.language for s in sections for b in s.blocks}
    assert languages <= {"python", "console", "sh", "text"}, languages
    assert any(s.runnable for s in sections)


# -- the private network namespace ---------------------------------------------------------------------------
class Namespace:
    """A network namespace with its loopback up, kept alive by a ``sleep`` process we started."""

    def __init__(self) -> None:
        self.holder = subprocess.Popen(["unshare", "-n", "sh", "-c", "ip link set lo up && echo up && exec sleep 3600"],
                                       stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        assert self.holder.stdout is not None
        if self.holder.stdout.readline().strip() != "up":
            self.holder.kill()
            raise RuntimeError(f"no network namespace: {self.holder.stderr.read() if self.holder.stderr else ''}")

    def command(self, argv: list[str]) -> list[str]:
        return ["nsenter", f"--net=/proc/{self.holder.pid}/ns/net", *argv]

    def listening(self, port: int) -> bool:
        local = f"0100007F:{port:04X}"
        with open(f"/proc/{self.holder.pid}/net/tcp") as lines:
            return any(f[1] == local and f[3] == "0A" for f in (line.split() for line in lines) if len(f) > 3)

    def close(self) -> None:
        self.holder.kill()
        self.holder.wait(10)


@pytest.fixture
def shell_env(tmp_path: Path) -> dict[str, str]:
    """The environment of the README's commands: this checkout's ``cipstack`` first on the PATH."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    shim = bin_dir / "cipstack"
    shim.write_text(f'#!/bin/sh\nexec {shlex.quote(sys.executable)} -m cipstack "$@"\n')
    shim.chmod(0o755)
    python = bin_dir / "python3"
    python.symlink_to(sys.executable)
    env = dict(os.environ)
    env["PATH"] = f"{bin_dir}{os.pathsep}{env.get('PATH', '')}"
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH", "")) if p)
    env.pop("COLUMNS", None)
    env["LC_ALL"] = "C.UTF-8"
    return env


def _namespaces_available() -> str | None:
    missing = [tool for tool in ("unshare", "nsenter", "ip") if shutil.which(tool) is None]
    if missing:
        return f"{' and '.join(missing)} not installed"
    if os.geteuid() != 0:
        return "the README's default ports need a private network namespace (unshare -n), which needs root"
    return None


@contextlib.contextmanager
def emulator(namespace: Namespace, command: str, env: dict[str, str], cwd: Path) -> Iterator[Path]:
    """``command`` (a ``cipstack adapter ...`` or ``cipstack fleet ...`` line) running in ``namespace``
    until the block ends; yields its log file."""
    log = cwd / "adapter.log"
    with log.open("w") as out:
        process = subprocess.Popen(namespace.command(["sh", "-c", f"exec {command}"]), stdout=out,
                                   stderr=subprocess.STDOUT, env=env, cwd=cwd, stdin=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 30
        # Ready once it says what it emulates: every port and its control socket are open then.
        while "emulating" not in log.read_text():
            if process.poll() is not None or time.monotonic() > deadline:
                pytest.fail(f"`{command}` did not start:\n{log.read_text()}")
            time.sleep(0.05)
        yield log
    finally:
        if process.poll() is None:
            process.send_signal(signal.SIGTERM)
            try:
                process.wait(15)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait(5)


SECTIONS = [s for s in readme_sections(README.read_text()) if s.runnable]


@pytest.mark.parametrize("section", SECTIONS, ids=[s.title for s in SECTIONS])
def test_readme_section(section: Section, shell_env: dict[str, str], tmp_path: Path) -> None:
    reason = _namespaces_available()
    if reason:
        pytest.skip(reason)
    work = tmp_path / "work"
    work.mkdir()
    namespace = Namespace()
    try:
        with emulator(namespace, section.adapter, shell_env, tmp_path) as log:
            for block in section.blocks:
                if block.language == "python":
                    _run_python(namespace, block, shell_env, work, log)
                elif block.language == "console":
                    _run_console(namespace, block, shell_env, work, log)
    finally:
        namespace.close()


def _run_python(namespace: Namespace, block: Block, env: dict[str, str], work: Path, log: Path) -> None:
    script = work / f"readme_{block.line}.py"
    script.write_text(block.text)
    result = subprocess.run(namespace.command([sys.executable, str(script)]), capture_output=True, text=True,
                            env=env, cwd=work, timeout=COMMAND_TIMEOUT, stdin=subprocess.DEVNULL)
    assert result.returncode == 0, (f"README.md:{block.line}: the python block exited {result.returncode}\n"
                                    f"{result.stdout}{result.stderr}\n--- emulator ---\n{log.read_text()}")


def _run_console(namespace: Namespace, block: Block, env: dict[str, str], work: Path, log: Path) -> None:
    for command, expected, line in console_commands(block):
        result = subprocess.run(namespace.command(["sh", "-c", command]), capture_output=True, text=True, env=env,
                                cwd=work, timeout=COMMAND_TIMEOUT, stdin=subprocess.DEVNULL)
        actual = (result.stdout + result.stderr).splitlines()
        shown = "\n".join(actual)
        assert output_matches(expected, actual), (
            f"README.md:{line}: `{command}` printed\n{shown}\n--- expected ---\n" + "\n".join(expected))
        fails = any(e.startswith("cipstack") for e in expected)
        assert result.returncode == 0 or fails, (
            f"README.md:{line}: `{command}` exited {result.returncode}\n{shown}\n--- emulator ---\n{log.read_text()}")
