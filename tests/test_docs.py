"""Every code block of README.md and of the documentation (docs/) runs as written, against the
emulator the reader would have running.

The convention, for whoever writes a block:

* ```` ```python ````: a complete script, run as written (``python3 FILE``); it must exit 0.
* ```` ```console ````: each line starting with ``$ `` is a command, run in order by ``sh`` in one
  scratch directory; the lines after it, up to the next command, are its expected output (its
  stdout, then its stderr). A line ``...`` matches any number of lines; ``...`` inside a line
  matches any text within that line. A command must exit 0 unless its expected output shows an
  error line of the command (one starting ``cipstack``), as a failing command prints.
* ```` ```sh ```` (set-up commands), ```` ```text ```` (synopses, sample output),
  ```` ```toml ```` and ```` ```yaml ```` (files) are not run.

A block that cannot run as written is marked by an HTML comment on the line before its fence,
which the rendered page does not show, and checked another way:

* ``<!-- test: pytest -->`` before a python block: it is a test module; ``python3 -m pytest`` runs
  it and must pass.
* ``<!-- test: interrupt after N s -->`` before a python block that runs until it is stopped: it
  must still be running after N seconds, and Ctrl-C (SIGINT) must end it within 15 s with exit
  status 0 or 130 and no traceback.

Each ``##`` section of a document is one test: its blocks run in order against one fresh
emulator, the default ``cipstack adapter`` (ACG profile) at 127.0.0.1:44818, or the one the
section's own ```` ```sh ```` blocks start before its first runnable block (the last line
``cipstack adapter ...``, ``cipstack componet ...`` or ``cipstack fleet ...``: the tour restarts
the adapter with ``--param``; the fleet's page starts a fleet instead).

The documents name the default ports (44818, 2222), so each section runs in a private network
namespace of its own (``unshare -n``, root needed), where they are free whatever else runs on this
machine; ``cipstack`` is this checkout's, run by this interpreter. Without root these tests are
skipped (``-m "not docs"`` leaves them out); the checks of the documents' shape below run anyway.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import os
import re
import resource
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
DOCS = ROOT / "docs"
DEFAULT_ADAPTER = "cipstack adapter"
COMMAND_TIMEOUT = 60.0
#: The README stays a front page; what does not fit goes to a page of docs/.
README_MAX_LINES = 250
LANGUAGES = {"python", "console", "sh", "text", "toml", "yaml"}
RUN, PYTEST, INTERRUPT = "run", "pytest", "interrupt"


def documents() -> list[Path]:
    """README.md and every page of the documentation."""
    return [README, *sorted(DOCS.rglob("*.md"))]


def _name(path: Path) -> str:
    return str(path.relative_to(ROOT))


@dataclass(frozen=True)
class Block:
    language: str
    text: str
    line: int  # of the opening fence, 1-based
    how: str = RUN  # RUN, PYTEST or INTERRUPT (by the marker before the fence)
    seconds: float = 0.0  # INTERRUPT: how long it must run before Ctrl-C


@dataclass(frozen=True)
class Section:
    document: str
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
                    if command.strip().startswith(("cipstack adapter", "cipstack componet", "cipstack fleet")):
                        found = command.strip()
        return found

    @property
    def runnable(self) -> bool:
        return any(b.language in ("python", "console") for b in self.blocks)

    @property
    def id(self) -> str:
        return f"{self.document}::{self.title}"


_FENCE = re.compile(r"^```(\w*)\s*$")
_MARKER = re.compile(r"^<!-- test: (.*?) -->\s*$")
_INTERRUPT = re.compile(r"interrupt after (\d+(?:\.\d+)?) s")


def _marker(text: str, where: str) -> tuple[str, float]:
    if text == "pytest":
        return PYTEST, 0.0
    found = _INTERRUPT.fullmatch(text)
    if found:
        return INTERRUPT, float(found.group(1))
    raise ValueError(f"{where}: unknown test marker {text!r} (known: 'pytest', 'interrupt after N s')")


def sections(text: str, document: str = "README.md") -> list[Section]:
    """The ``##`` sections of a document with their fenced blocks, in order."""
    found: list[tuple[str, list[Block]]] = [("(top)", [])]
    lines = text.splitlines()
    index = 0
    while index < len(lines):
        line = lines[index]
        if line.startswith("## "):
            found.append((line[3:].strip(), []))
        marker = _MARKER.match(line)
        if marker and not (index + 1 < len(lines) and _FENCE.match(lines[index + 1])):
            raise ValueError(f"{document}:{index + 1}: a test marker must stand right before a fence")
        fence = _FENCE.match(line)
        if fence:
            start = index
            index += 1
            body = []
            while index < len(lines) and not lines[index].startswith("```"):
                body.append(lines[index])
                index += 1
            if index == len(lines):
                raise ValueError(f"{document}:{start + 1}: code block never closed")
            how, seconds = RUN, 0.0
            before = _MARKER.match(lines[start - 1]) if start else None
            if before:
                how, seconds = _marker(before.group(1), f"{document}:{start}")
                if fence.group(1) != "python":
                    raise ValueError(f"{document}:{start}: a test marker goes before a python block")
            found[-1][1].append(Block(fence.group(1), "\n".join(body) + "\n", start + 1, how, seconds))
        index += 1
    return [Section(document, title, tuple(blocks)) for title, blocks in found if blocks]


def all_sections() -> list[Section]:
    return [s for path in documents() for s in sections(path.read_text(), _name(path))]


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


def console_commands(block: Block, document: str = "README.md") -> list[tuple[str, list[str], int]]:
    """(command, expected output lines, line in the document) of each ``$ `` line of a console block."""
    commands: list[tuple[str, list[str], int]] = []
    for offset, line in enumerate(block.text.splitlines(), start=1):
        if line.startswith("$ "):
            commands.append((line[2:], [], block.line + offset))
        elif commands:
            commands[-1][1].append(line)
        elif line.strip():
            raise ValueError(f"{document}:{block.line + offset}: console output before any $ command")
    return commands


def test_output_matching() -> None:
    assert output_matches(["a", "...", "d"], ["a", "b", "c", "d"])
    assert output_matches(["a", "...", "b"], ["a", "b"])
    assert output_matches(["x ... z"], ["x 1 2 z   "])
    assert not output_matches(["a", "b"], ["a", "b", "c"])
    assert not output_matches(["x ... z"], ["x 1 2 y"])
    assert not output_matches(["a", "...", "d"], ["a", "b"])
    assert output_matches(["..."], [])


def test_markers_are_read() -> None:
    text = ("## A\n\n<!-- test: pytest -->\n```python\ndef test_x(): pass\n```\n\n"
            "<!-- test: interrupt after 2 s -->\n```python\nwhile True: pass\n```\n")
    blocks = sections(text)[0].blocks
    assert [(b.how, b.seconds, b.line) for b in blocks] == [(PYTEST, 0.0, 4), (INTERRUPT, 2.0, 9)]
    for wrong in ("<!-- test: later -->\n```python\n```\n", "<!-- test: pytest -->\n\n```python\n```\n",
                  "<!-- test: pytest -->\n```console\n```\n"):
        with pytest.raises(ValueError):
            sections(wrong)


# -- the documents' shape ------------------------------------------------------------------------------
def test_readme_is_a_front_page() -> None:
    lines = README.read_text().splitlines()
    assert len(lines) <= README_MAX_LINES, f"README.md has {len(lines)} lines; move the detail into docs/"


def test_two_set_up_commands() -> None:
    """The README's set-up stays two commands, each in a virtual environment (Debian 12 and Ubuntu 24
    refuse pip outside one): install and run the emulator, install and run the tests."""
    installs = [line for s in sections(README.read_text()) for b in s.blocks if b.language == "sh"
                for line in b.text.splitlines() if "pip install" in line]
    assert installs == ["python3 -m venv .venv && . .venv/bin/activate && pip install . && cipstack adapter",
                        '. .venv/bin/activate && pip install ".[test]" && python3 -m pytest']


def built_only(page: Path) -> bool:
    """Whether ``page`` has its content only in the built site: the command-line reference's marker, or
    the API reference (``reference/``: its pages are ``:::`` directives, its index a table of them)."""
    text = page.read_text()
    return ("<!-- cli-reference -->" in text or bool(re.search(r"^::: ", text, re.MULTILINE))
            or page.resolve().is_relative_to((DOCS / "reference").resolve()))


def test_the_readme_links_pages_that_read_where_it_is_read() -> None:
    """The README is read on a code host, where the generated references are a marker and ``:::`` lines:
    it links pages with their content in Markdown, and names where the generated ones are."""
    assert built_only(DOCS / "command-line" / "reference.md") and built_only(DOCS / "reference" / "api" / "index.md")
    assert not built_only(DOCS / "library.md") and not built_only(DOCS / "command-line" / "index.md")
    targets = re.findall(r"\]\((docs/[\w./-]+\.md)(?:#[\w-]*)?\)", README.read_text())
    assert len(targets) > 20
    assert [t for t in targets if built_only(ROOT / t)] == []


@pytest.mark.parametrize("path", [README, DOCS / "getting-started.md"], ids=_name)
def test_every_extra_is_named_where_the_install_is(path: Path) -> None:
    """A new user reads the extras where the install is: each extra of pyproject.toml is named there
    (``.[http]`` was not, and ``--http`` then said to install an extra nobody had listed)."""
    if sys.version_info >= (3, 11):
        import tomllib
    else:
        import tomli as tomllib

    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    text = path.read_text()
    missing = [name for name in extras if f".[{name}]" not in text]
    assert not missing, f"{_name(path)} does not name the extras {missing}"


def _clauses(text: str) -> list[str]:
    """The prose of a page in clauses: its lines joined, cut at a sentence's end, a semicolon and a table's
    cell border."""
    return [c for c in re.split(r"(?<=\.)\s+(?=[A-Z`(])|;\s|\s\|\s", " ".join(text.split())) if c.strip()]


def _cm94_saves_everything(text: str) -> list[str]:
    """The clauses of ``text`` that have CM.94 among what saves every parameter, without the CM group."""
    return [c for c in _clauses(text) if "CM.94" in c and re.search(r"\bsav(e|es|ed)\b", c)
            and re.search(r"every parameter|all parameters|them all|everything", c) and "CM group" not in c]


def test_the_pages_agree_on_what_each_acg_save_keeps() -> None:
    """CM.94 Comm Update saves the CM group (ACG-ET2 manual, "Comm Update (CM.94)": CM.7 and CM.10-CM.25);
    what saves every parameter is 0x03E0 from 0 to 1 (ACG RS-485 manual, "Saving Parameters Defined by
    Communication"). No clause has CM.94 save every parameter (two pages said so, a third said the CM
    group), and each page that says what CM.94 saves names 0x03E0, the save of everything, too."""
    # As the ACG page and the emulator's page put it before.
    assert _cm94_saves_everything("A write is lost unless saved: writing 0x03E0 from 0 to 1 (ACG RS-485 manual), "
                                  "CM.94 Comm Update or a parameter initialization saves every parameter in the "
                                  "state file (see\n[state files](index.md)). A save")
    assert _cm94_saves_everything("as on the real drive: the ACG saves every parameter when 0x03E0 is written "
                                  "from 0 to 1, on CM.94\nComm Update and on a parameter initialization; the Omron")
    wrong, unnamed = [], []
    for path in documents():
        text = path.read_text()
        wrong += [f"{_name(path)}: {c}" for c in _cm94_saves_everything(text)]
        if any("CM.94" in c and "CM group" in c for c in _clauses(text)) and "0x03E0" not in text:
            unnamed.append(_name(path))
    assert not wrong, "CM.94 saves the CM group, not every parameter:\n" + "\n".join(wrong)
    assert not unnamed, f"{unnamed} say what CM.94 saves, not that 0x03E0 saves every parameter"


@pytest.mark.parametrize("path", documents(), ids=_name)
def test_document_is_parsed_whole(path: Path) -> None:
    """Every fence is closed and has a language this test knows, and every marker is known, so no
    block is left out silently."""
    found = sections(path.read_text(), _name(path))
    languages = {b.language for s in found for b in s.blocks}
    assert languages <= LANGUAGES, f"{_name(path)}: {languages - LANGUAGES}"


def nav_pages(config: str) -> list[str]:
    """The pages the ``nav`` of mkdocs.yml lists (the last key of the file; one page per line)."""
    nav = config[config.index("\nnav:"):]
    return re.findall(r"([\w./-]+\.md)\s*$", nav, re.MULTILINE)


def test_every_page_is_in_the_nav() -> None:
    """A page nobody can reach from the site's navigation is a page nobody reads (the strict build
    says so too, but this runs without MkDocs)."""
    nav = nav_pages((ROOT / "mkdocs.yml").read_text())
    pages = sorted(str(p.relative_to(DOCS)) for p in DOCS.rglob("*.md"))
    assert sorted(nav) == pages
    assert len(set(nav)) == len(nav), "a page is in the nav twice"


def _cli_reference() -> object:
    spec = importlib.util.spec_from_file_location("cli_reference", ROOT / "mkdocs_hooks" / "cli_reference.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _command_lines(parser: argparse.ArgumentParser, words: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    """Every command line the parser takes: ``("adapter",)``, ..., ``("drive", "trip")``, ..."""
    from cipstack.cli.parser import subcommands

    found = []
    for name, sub in subcommands(parser).items():
        found += [(*words, name), *_command_lines(sub, (*words, name))]
    return found


def test_cli_reference_has_every_command() -> None:
    """The reference the docs build renders from the parser has a section for every command and
    subcommand of ``cipstack``, each with that command's usage and help."""
    from cipstack.cli.parser import build_parser

    reference = _cli_reference().render()  # type: ignore[attr-defined]
    lines = _command_lines(build_parser())
    assert {("adapter",), ("fleet",), ("io",), ("get",), ("drive", "trip"), ("eds", "check"),
            ("capture", "analyze")} <= set(lines)
    for words in lines:
        name = " ".join(("cipstack", *words))
        assert f"`{name}`" in reference, name
        assert f"usage: {name}" in reference, name
    assert reference.count("usage: cipstack") == len(lines) + 1  # and cipstack itself


_IMPORT = re.compile(r"^\s*from (cipstack(?:\.\w+)*) import ([\w, ]+)", re.MULTILINE)


def test_examples_use_documented_names() -> None:
    """What an example imports of cipstack is in the API reference: its module has a ``:::``
    directive there, or a documented module below the package it is imported from defines it."""
    reference = "\n".join(p.read_text() for p in (DOCS / "reference").rglob("*.md"))
    documented = set(re.findall(r"^::: ([\w.]+)\s*$", reference, re.MULTILINE))
    assert "cipstack.scanner" in documented
    missing = []
    for section in all_sections():
        for block in section.blocks:
            if block.language != "python":
                continue
            for module, names in _IMPORT.findall(block.text):
                for name in (n.strip() for n in names.split(",")):
                    homes = [d for d in documented if d == module or d.startswith(module + ".")]
                    if module in documented or any(hasattr(importlib.import_module(d), name) for d in homes):
                        continue
                    missing.append(f"{section.document}:{block.line}: {module}.{name}")
    assert not missing, missing


def test_site_builds_strictly(tmp_path: Path) -> None:
    """``mkdocs build --strict``: a broken link, a missing anchor, a page left out of the nav or an
    API reference that does not resolve fails the build; it stays under a minute of CPU (the build's
    own work: the wall time also counts whatever the other workers and the machine run beside it).
    Not ``-q``: with it MkDocs counts no warning, and ``--strict`` lets every one pass. Any ``WARNING``
    line fails the test too, whether or not MkDocs counted it."""
    pytest.importorskip("mkdocs", reason="the docs extra is not installed: pip install '.[docs]' (or '.[test]')")
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH", "")) if p)
    site = tmp_path / "site"
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    result = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-d", str(site)],
                            cwd=ROOT, capture_output=True, text=True, env=env, timeout=120)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    took = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    output = result.stdout + result.stderr
    assert result.returncode == 0, output
    warnings = [line for line in output.splitlines() if "WARNING" in line]
    assert not warnings, "\n".join(warnings)
    assert (site / "command-line" / "reference" / "index.html").exists()
    # The hook is code the build runs, not a file of the site.
    assert not list(site.rglob("*.py")), sorted(str(p.relative_to(site)) for p in site.rglob("*.py"))
    assert took < 60, f"the docs took {took:.0f} s of CPU to build"


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


def command_shims(bin_dir: Path, python: str) -> None:
    """``cipstack`` and ``python3`` in ``bin_dir``, each a script that execs ``python`` by the path it
    has. Not a symlink: a virtual environment's interpreter finds its environment by the
    ``pyvenv.cfg`` beside (or above) the path it was started by, so a link to it in another directory
    starts the base Python, without the packages the environment installed (cpppo, pycomm3)."""
    bin_dir.mkdir(parents=True, exist_ok=True)
    for name, argv in (("cipstack", f"{shlex.quote(python)} -m cipstack"), ("python3", shlex.quote(python))):
        shim = bin_dir / name
        shim.write_text(f'#!/bin/sh\nexec {argv} "$@"\n')
        shim.chmod(0o755)


def test_the_shims_run_a_virtual_environment_s_python(tmp_path: Path) -> None:
    """From a virtual environment (as the README's install makes one), the sections' ``python3`` is
    that environment's: its ``sys.prefix`` is the environment, not the base Python's."""
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=120,
                   capture_output=True)
    command_shims(tmp_path / "bin", str(venv / "bin" / "python3"))
    env = dict(os.environ, PATH=f"{tmp_path / 'bin'}{os.pathsep}{os.environ.get('PATH', '')}")
    env.pop("PYTHONHOME", None)
    prefix = subprocess.run(["sh", "-c", 'python3 -c "import sys; print(sys.prefix)"'], capture_output=True,
                            text=True, env=env, cwd=tmp_path, timeout=60, check=True).stdout.strip()
    assert Path(prefix).resolve() == venv.resolve()


@pytest.fixture
def shell_env(tmp_path: Path) -> dict[str, str]:
    """The environment of the README's commands: this checkout's ``cipstack`` and this interpreter
    first on the PATH."""
    bin_dir = tmp_path / "bin"
    command_shims(bin_dir, sys.executable)
    env = dict(os.environ)
    env["PATH"] = f"{bin_dir}{os.pathsep}{env.get('PATH', '')}"
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH", "")) if p)
    env["XDG_DATA_HOME"] = str(tmp_path / "data")   # parameters a block saves stay in its test
    env.pop("COLUMNS", None)
    env.pop("PYTEST_ADDOPTS", None)   # the suite's options are not those of a page's own pytest
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


SECTIONS = [s for s in all_sections() if s.runnable]


@pytest.mark.docs
@pytest.mark.parametrize("section", SECTIONS, ids=[s.id for s in SECTIONS])
def test_section(section: Section, shell_env: dict[str, str], tmp_path: Path) -> None:
    reason = _namespaces_available()
    if reason:
        pytest.skip(reason)
    work = tmp_path / "work"
    # Commands and emulators name the EDS corpus as from the repository's root (docs/eds.md).
    for where in (work, tmp_path):
        (where / "tests" / "eds").mkdir(parents=True)
        (where / "tests" / "eds" / "files").symlink_to(ROOT / "tests" / "eds" / "files")
    namespace = Namespace()
    try:
        with emulator(namespace, section.adapter, shell_env, tmp_path) as log:
            for block in section.blocks:
                if block.language == "python":
                    _run_python(namespace, section.document, block, shell_env, work, log)
                elif block.language == "console":
                    _run_console(namespace, section.document, block, shell_env, work, log)
    finally:
        namespace.close()
    if " --factory" in section.adapter:   # what the section wrote or saved left the user's saved drive alone
        assert not list((tmp_path / "data").rglob("*.json")), f"{section.id} wrote a state file"


def _run_python(namespace: Namespace, document: str, block: Block, env: dict[str, str], work: Path,
                log: Path) -> None:
    where = f"{document}:{block.line}"
    script = work / (f"test_block_{block.line}.py" if block.how == PYTEST else f"block_{block.line}.py")
    script.write_text(block.text)
    if block.how == INTERRUPT:
        _run_until_interrupted(namespace, where, script, block.seconds, env, work, log)
        return
    argv = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(script)] if block.how == PYTEST \
        else [sys.executable, str(script)]
    result = subprocess.run(namespace.command(argv), capture_output=True, text=True,
                            env=env, cwd=work, timeout=COMMAND_TIMEOUT, stdin=subprocess.DEVNULL)
    assert result.returncode == 0, (f"{where}: the python block exited {result.returncode}\n"
                                    f"{result.stdout}{result.stderr}\n--- emulator ---\n{log.read_text()}")


def _run_until_interrupted(namespace: Namespace, where: str, script: Path, seconds: float, env: dict[str, str],
                           work: Path, log: Path) -> None:
    """A block that runs until it is stopped: still running after ``seconds``, then Ctrl-C ends it."""
    # nsenter execs the interpreter in place, so the signal reaches the script itself.
    process = subprocess.Popen(namespace.command([sys.executable, str(script)]), stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True, env=env, cwd=work, stdin=subprocess.DEVNULL)
    try:
        time.sleep(seconds)               # the subject: still running after the seconds the page gives
        ended = process.poll()
        process.send_signal(signal.SIGINT)
        out, err = process.communicate(timeout=15)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait(5)
    shown = f"{out}{err}\n--- emulator ---\n{log.read_text()}"
    assert ended is None, f"{where}: the block ended by itself (exit {ended}) before {seconds} s\n{shown}"
    assert process.returncode in (0, 130), f"{where}: Ctrl-C ended it with exit {process.returncode}\n{shown}"
    assert "Traceback" not in err, f"{where}: Ctrl-C ended it with a traceback\n{shown}"


def _run_console(namespace: Namespace, document: str, block: Block, env: dict[str, str], work: Path,
                 log: Path) -> None:
    for command, expected, line in console_commands(block, document):
        result = subprocess.run(namespace.command(["sh", "-c", command]), capture_output=True, text=True, env=env,
                                cwd=work, timeout=COMMAND_TIMEOUT, stdin=subprocess.DEVNULL)
        actual = (result.stdout + result.stderr).splitlines()
        shown = "\n".join(actual)
        assert output_matches(expected, actual), (
            f"{document}:{line}: `{command}` printed\n{shown}\n--- expected ---\n" + "\n".join(expected))
        fails = any(e.startswith("cipstack") for e in expected)
        assert result.returncode == 0 or fails, (
            f"{document}:{line}: `{command}` exited {result.returncode}\n{shown}\n--- emulator ---\n{log.read_text()}")
