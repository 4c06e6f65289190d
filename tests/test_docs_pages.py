"""Every code block of docs/faults.md, docs/testing.md and docs/http.md (its curl examples) runs as
written, as the README's do (``tests/test_readme.py``: its conventions, one fresh emulator per ``##``
section in a private network namespace). A python block that defines tests (``def test_``) is run by
pytest with the plugin; the commands run where the checkout's ``examples/`` are."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.test_readme import (
    COMMAND_TIMEOUT,
    ROOT,
    Block,
    Namespace,
    _namespaces_available,
    _run_console,
    _run_python,
    emulator,
    readme_sections,
    shell_env,
)

PAGES = [ROOT / "docs" / "faults.md", ROOT / "docs" / "testing.md", ROOT / "docs" / "http.md"]
SECTIONS = [(page, s) for page in PAGES for s in readme_sections(page.read_text()) if s.runnable]

__all__ = ["shell_env"]


@pytest.mark.parametrize("page", PAGES, ids=[p.name for p in PAGES])
def test_the_page_has_runnable_blocks(page: Path) -> None:
    assert {b.language for s in readme_sections(page.read_text()) for b in s.blocks} <= {"python", "console",
                                                                                         "sh", "text"}
    assert any(s.runnable for s in readme_sections(page.read_text()))


@pytest.mark.parametrize(("page", "section"), SECTIONS, ids=[f"{p.stem}: {s.title}" for p, s in SECTIONS])
def test_page_section(page: Path, section, shell_env: dict[str, str], tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    reason = _namespaces_available()
    if reason:
        pytest.skip(reason)
    work = tmp_path / "work"
    shutil.copytree(ROOT / "examples", work / "examples")
    namespace = Namespace()
    try:
        with emulator(namespace, section.adapter, shell_env, tmp_path) as log:
            for block in section.blocks:
                if block.language == "python" and "\ndef test_" in "\n" + block.text:
                    _run_tests(namespace, block, shell_env, work, log)
                elif block.language == "python":
                    _run_python(namespace, block, shell_env, work, log)
                elif block.language == "console":
                    _run_console(namespace, block, shell_env, work, log)
    finally:
        namespace.close()


def _run_tests(namespace: Namespace, block: Block, env: dict[str, str], work: Path, log: Path) -> None:
    script = work / f"test_page_{block.line}.py"
    script.write_text(block.text)
    result = subprocess.run(namespace.command([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                                               "-p", "cipstack.testing", str(script)]),
                            capture_output=True, text=True, env=env, cwd=work, timeout=COMMAND_TIMEOUT,
                            stdin=subprocess.DEVNULL)
    assert result.returncode == 0 and " passed" in result.stdout, (
        f"{block.line}: the tests of the block failed\n{result.stdout}{result.stderr}")
