"""Every code block of docs/library.md runs as written, as the README's do (tests/test_readme.py: the same
conventions): each ``##`` section against one fresh emulator in a private network namespace, the one
its ``sh`` blocks start before its first runnable block (``cipstack adapter ...``, ``cipstack componet
...``), else the default ``cipstack adapter``."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.test_readme import (
    DEFAULT_ADAPTER,
    Namespace,
    Section,
    _namespaces_available,
    _run_console,
    _run_python,
    emulator,
    readme_sections,
)
from tests.test_readme import shell_env as shell_env  # the fixture, for these tests

GUIDE = Path(__file__).resolve().parents[1] / "docs" / "library.md"
EMULATORS = ("cipstack adapter", "cipstack fleet", "cipstack componet")


def emulator_of(section: Section) -> str:
    found = DEFAULT_ADAPTER
    for block in section.blocks:
        if block.language in ("python", "console"):
            break
        if block.language == "sh":
            for line in block.text.splitlines():
                if line.strip().startswith(EMULATORS):
                    found = line.strip()
    return found


SECTIONS = [s for s in readme_sections(GUIDE.read_text()) if s.runnable]


def test_the_guide_has_its_sections() -> None:
    titles = [s.title for s in SECTIONS]
    assert {"A first script", "Values with their unit", "Class 1 I/O from synchronous code", "EDS files",
            "Parameter recipes"} <= set(titles)
    assert {b.language for s in readme_sections(GUIDE.read_text()) for b in s.blocks} <= {"python", "console", "sh"}


@pytest.mark.parametrize("section", SECTIONS, ids=[s.title for s in SECTIONS])
def test_guide_section(section: Section, shell_env: dict[str, str], tmp_path: Path) -> None:
    reason = _namespaces_available()
    if reason:
        pytest.skip(reason)
    env = {**shell_env, "XDG_DATA_HOME": str(tmp_path / "data")}   # saved parameters stay in this test
    work = tmp_path / "work"
    work.mkdir()
    namespace = Namespace()
    try:
        with emulator(namespace, emulator_of(section), env, tmp_path) as log:
            for block in section.blocks:
                if block.language == "python":
                    _run_python(namespace, block, env, work, log)
                elif block.language == "console":
                    _run_console(namespace, block, env, work, log)
    finally:
        namespace.close()
