"""``--sample K`` (tests/sampling.py): one test in K of each module, the version-sensitive ones whole."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from tests.inner_pytest import environment
from tests.sampling import VERSION_SENSITIVE

ROOT = Path(__file__).resolve().parents[1]


def test_every_version_sensitive_module_exists() -> None:
    modules = {path.stem for path in (ROOT / "tests").rglob("test_*.py")}
    assert modules >= VERSION_SENSITIVE, sorted(VERSION_SENSITIVE - modules)


def _collected(tmp_path: Path, *options: str) -> list[str]:
    for name in ("test_alpha.py", "test_precise_loop.py"):
        (tmp_path / name).write_text("".join(f"def test_{n}():\n    pass\n" for n in range(7)), encoding="utf-8")
    result = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "tests.sampling",
                             "-n", "0", "--rootdir", str(tmp_path), "--collect-only", *options],
                            cwd=tmp_path, capture_output=True, text=True, timeout=120,
                            env=environment(ROOT))
    assert result.returncode == 0, result.stdout + result.stderr
    return [line for line in result.stdout.splitlines() if "::" in line]


def test_a_sample_keeps_one_test_in_k_of_each_module_and_version_sensitive_ones_whole(tmp_path: Path) -> None:
    everything = _collected(tmp_path)
    assert len(everything) == 14
    sampled = _collected(tmp_path, "--sample", "3")
    assert sampled == [f"test_alpha.py::test_{n}" for n in (0, 3, 6)] + [
        f"test_precise_loop.py::test_{n}" for n in range(7)]
    assert _collected(tmp_path, "--sample", "3") == sampled   # the same sample every time
