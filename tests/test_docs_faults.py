"""Every code block of docs/faults.md runs as written, as the README's do (``tests/test_readme.py``:
its conventions, one fresh emulator per ``##`` section in a private network namespace)."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.test_readme import (
    ROOT,
    Namespace,
    _namespaces_available,
    _run_console,
    _run_python,
    emulator,
    readme_sections,
    shell_env,
)

PAGE = ROOT / "docs" / "faults.md"
SECTIONS = [s for s in readme_sections(PAGE.read_text()) if s.runnable]

__all__ = ["shell_env"]


def test_the_page_has_runnable_blocks() -> None:
    assert {b.language for s in readme_sections(PAGE.read_text()) for b in s.blocks} <= {"python", "console",
                                                                                         "sh", "text"}
    assert len(SECTIONS) >= 2


@pytest.mark.parametrize("section", SECTIONS, ids=[s.title for s in SECTIONS])
def test_faults_page_section(section, shell_env: dict[str, str], tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
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
