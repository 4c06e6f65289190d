"""docs/conformance.md runs as written: each of its ``##`` sections with runnable blocks runs against
a fresh emulator in a private network namespace, by the README's conventions (tests/test_readme.py),
and the page lists every check of the battery."""

from __future__ import annotations

from pathlib import Path

import pytest

from cipstack.conformance import check_ids
from tests.test_readme import (
    Namespace,
    _namespaces_available,
    _run_console,
    _run_python,
    emulator,
    readme_sections,
    shell_env,  # noqa: F401 - the fixture the sections run with
)

PAGE = Path(__file__).resolve().parents[2] / "docs" / "conformance.md"
SECTIONS = [s for s in readme_sections(PAGE.read_text()) if s.runnable]


def test_the_page_has_runnable_sections() -> None:
    assert [s.title for s in SECTIONS] == ["Running it", "From a program"]


def test_the_page_lists_every_check() -> None:
    text = PAGE.read_text()
    assert [i for i in check_ids() if f"| `{i}` |" not in text] == []


@pytest.mark.parametrize("section", SECTIONS, ids=[s.title for s in SECTIONS])
def test_page_section(section, shell_env: dict[str, str], tmp_path: Path) -> None:  # type: ignore[no-untyped-def]  # noqa: F811
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
        assert (work / "conform.xml").is_file() == (section.title == "Running it")
    finally:
        namespace.close()
