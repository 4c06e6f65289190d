"""Every console block of docs/eds.md runs as written, by the README's convention (tests/test_readme.py):
``$ `` lines are commands, the lines after them their output, ``...`` matching any lines or any
text within a line; each ``##`` section runs against the emulator its ```` ```sh ```` block starts
(else the default ``cipstack adapter``), in a private network namespace.

The commands run in a scratch directory where ``tests/eds/files`` is this checkout's corpus, so
they read as they run from the repository's root. The rules table is the checker's own
(``RULES``, ``SOURCES`` and the severities), and the adapter's lines shown are what it prints.
"""

from __future__ import annotations

import re
import subprocess
import time
from pathlib import Path

import pytest

from cipstack.eds.checker import RULES, SOURCES
from cipstack.eds.emulated_device import build_eds_device
from cipstack.eds.reader import read_eds
from tests.test_readme import (
    Namespace,
    Section,
    _namespaces_available,
    _run_console,
    readme_sections,
    shell_env,
)

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "eds.md"
SECTIONS = [s for s in readme_sections(DOC.read_text(encoding="utf-8")) if s.runnable]

__all__ = ["shell_env"]  # the fixture, shared with the README's test


def _start(namespace: Namespace, section: Section, env: dict[str, str], work: Path) -> subprocess.Popen[bytes]:
    log = work.parent / "adapter.log"
    with log.open("w") as out:
        process = subprocess.Popen(namespace.command(["sh", "-c", f"exec {section.adapter}"]), stdout=out,
                                   stderr=subprocess.STDOUT, env=env, cwd=work, stdin=subprocess.DEVNULL)
    deadline = time.monotonic() + 30
    while "emulating" not in log.read_text():
        if process.poll() is not None or time.monotonic() > deadline:
            pytest.fail(f"`{section.adapter}` did not start:\n{log.read_text()}")
        time.sleep(0.05)
    return process


@pytest.mark.parametrize("section", SECTIONS, ids=[s.title for s in SECTIONS])
def test_docs_eds_section(section: Section, shell_env: dict[str, str], tmp_path: Path) -> None:
    reason = _namespaces_available()
    if reason:
        pytest.skip(reason)
    work = tmp_path / "work"
    (work / "tests" / "eds").mkdir(parents=True)
    (work / "tests" / "eds" / "files").symlink_to(ROOT / "tests" / "eds" / "files")
    namespace = Namespace()
    try:
        process = _start(namespace, section, shell_env, work)
        try:
            for block in section.blocks:
                if block.language == "console":
                    _run_console(namespace, block, shell_env, work, work.parent / "adapter.log")
        finally:
            process.terminate()
            process.wait(15)
    finally:
        namespace.close()


def test_the_rules_table_is_the_checkers() -> None:
    """One row per rule: its name, its severity (as the checker reports it) and its source."""
    text = DOC.read_text(encoding="utf-8")
    rows = dict(re.findall(r"^\| `([a-z0-9-]+)` \| (.*) \|$", text, re.MULTILINE))
    assert set(rows) == set(RULES)
    for rule, row in rows.items():
        severity, source = (cell.strip() for cell in row.split(" | ", 1))
        assert source == SOURCES[rule], rule
        assert severity, rule


def test_the_adapter_lines_shown_are_what_it_prints() -> None:
    text = DOC.read_text(encoding="utf-8")
    shown = re.findall(r"^cipstack adapter: (tests/eds/files/\S+\.eds):(\d+): warning: (.*)$", text, re.MULTILINE)
    assert shown
    by_file: dict[str, list[tuple[int, str]]] = {}
    for path, line, message in shown:
        by_file.setdefault(path, []).append((int(line), message))
    for path, lines in by_file.items():
        issues = [(i.line, i.message) for i in build_eds_device(read_eds(ROOT / path)).issues]
        assert lines == issues, path


def test_every_section_runs_something() -> None:
    assert len(SECTIONS) >= 6
