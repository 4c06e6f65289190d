"""Device families as plug-ins: the registry reads the ``cipstack.devices`` entry points, cipstack's
own families first; a broken plug-in or a name given twice is one clear error for that name, and every
other family keeps working. Plug-ins here are real modules on disk, and the metadata test a real
``.dist-info`` that ``importlib.metadata`` finds on the path."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from cipstack.devices.profiles import PROFILES, Profile
from cipstack.devices.registry import (
    BUILT_IN,
    GROUP,
    FamilyRegistry,
    FamilyUnavailable,
    Registration,
    installed_families,
)

if sys.version_info >= (3, 11):
    import tomllib
else:
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]

#: A family of one model from outside cipstack: the standard objects and an identity of its own.
PLUGIN = '''
from cipstack.devices.profiles import ModelInfo, Profile


def _build(interface, limits, options):
    from cipstack.devices.profiles import identity_only_device

    return identity_only_device(interface, limits)


def describe():
    # A plug-in may use the EDS tool: it sits above cipstack, not inside its devices.
    from cipstack.devices.acg.eds_file import acg_et2_description
    from cipstack.objects.identity import IdentityInfo

    return acg_et2_description(identity=IdentityInfo(1234, 2, 7, (1, 2), 1, "Block One"))


BLOCK = Profile("block", "a block from elsewhere", _build, vendor_id=1234, product_codes=frozenset({7}),
                model_info=lambda: (ModelInfo("BLK-1", 7, "Block One"),), eds="block_family:describe")
PLAIN = Profile("plain", "a family without an EDS file", _build)


def make_block():
    return BLOCK


WRONG_NAME = Profile("other", "named otherwise", _build)
NOT_A_PROFILE = 42
'''


@pytest.fixture
def plugin_path(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A directory on ``sys.path`` holding the module ``block_family`` and a module that fails to import."""
    (tmp_path / "block_family.py").write_text(PLUGIN, encoding="utf-8")
    (tmp_path / "broken_family.py").write_text("import a_module_nobody_installed\n", encoding="utf-8")
    monkeypatch.syspath_prepend(str(tmp_path))
    return tmp_path


def registry(*extra: Registration) -> FamilyRegistry:
    return FamilyRegistry(lambda: [*(Registration(n, v, "cipstack") for n, v in BUILT_IN), *extra])


def test_pyproject_registers_the_built_in_families_as_the_registry_knows_them() -> None:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    assert list(project["project"]["entry-points"][GROUP].items()) == list(BUILT_IN)


def test_the_built_in_families_come_first_from_cipstack() -> None:
    found = installed_families()
    assert [(r.name, r.distribution) for r in found[:3]] == [("acg", "cipstack"), ("mx2", "cipstack"),
                                                               ("rx", "cipstack")]
    assert list(PROFILES)[:3] == ["acg", "mx2", "rx"]
    assert all(PROFILES.distribution(name) == "cipstack" for name in ("acg", "mx2", "rx"))
    assert PROFILES["mx2"].find_model is not None and PROFILES["acg"].find_model is None


def test_a_plugin_family_by_profile_or_by_callable(plugin_path: Path) -> None:
    for value in ("block_family:BLOCK", "block_family:make_block"):
        families = registry(Registration("block", value, "block-dist"))
        assert list(families) == ["acg", "mx2", "rx", "block"]
        assert isinstance(families["block"], Profile) and families["block"].vendor_id == 1234
        assert families.distribution("block") == "block-dist" and families.problems == {}


@pytest.mark.parametrize(("value", "reason"), [
    ("broken_family:BLOCK", "cannot be loaded: ModuleNotFoundError: No module named 'a_module_nobody_installed'"),
    ("block_family:MISSING", "cannot be loaded: AttributeError"),
    ("block_family:NOT_A_PROFILE", "is a int, not a cipstack.devices.profiles.Profile"),
    ("block_family:WRONG_NAME", "declares a profile named 'other'"),
])
def test_a_broken_plugin_is_one_error_naming_its_distribution(plugin_path: Path, value: str, reason: str) -> None:
    families = registry(Registration("block", value, "block-dist"))
    assert list(families) == ["acg", "mx2", "rx"] and "block" in families
    with pytest.raises(FamilyUnavailable) as raised:
        families["block"]
    message = str(raised.value)
    assert message.startswith(f"device family 'block' of distribution block-dist ({value}) ") and reason in message
    assert families.problems == {"block": message}
    # The other families are untouched.
    assert families["acg"].name == "acg"


def test_two_families_of_one_name_are_an_error_for_that_name(plugin_path: Path) -> None:
    families = registry(Registration("block", "block_family:BLOCK", "block-dist"),
                        Registration("block", "block_family:make_block", "other-dist"),
                        Registration("mx2", "block_family:BLOCK", "rogue-dist"))
    assert list(families) == ["acg", "rx"]
    with pytest.raises(FamilyUnavailable, match=r"two distributions give a device family named 'block': "
                                                r"block-dist and other-dist"):
        families["block"]
    with pytest.raises(FamilyUnavailable, match="named 'mx2': cipstack and rogue-dist"):
        families["mx2"]


def test_the_registry_is_read_once() -> None:
    calls: list[int] = []

    def find() -> list[Registration]:
        calls.append(1)
        return [Registration(n, v, "cipstack") for n, v in BUILT_IN]

    families = FamilyRegistry(find)
    assert calls == []
    assert "acg" in families and len(families) == 3 and families["rx"].name == "rx"
    assert calls == [1]


def _installed(tmp_path: Path, entry_points: str) -> dict[str, str]:
    """An environment where a distribution ``block-dist`` is installed as a ``.dist-info`` directory on the
    path, declaring ``entry_points``: what pip writes for a wheel."""
    site = tmp_path / "site"
    info = site / "block_dist-1.0.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: block-dist\nVersion: 1.0\n", encoding="utf-8")
    (info / "entry_points.txt").write_text(textwrap.dedent(entry_points), encoding="utf-8")
    (site / "block_family.py").write_text(PLUGIN, encoding="utf-8")
    (site / "broken_family.py").write_text("import a_module_nobody_installed\n", encoding="utf-8")
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(site)])}


def test_an_installed_distribution_brings_its_family_by_entry_point(tmp_path: Path) -> None:
    env = _installed(tmp_path, f"""
        [{GROUP}]
        block = block_family:BLOCK
        """)
    shown = subprocess.run([sys.executable, "-m", "cipstack", "models"], capture_output=True, text=True,
                           env=env, timeout=60)
    assert shown.returncode == 0, shown.stderr
    lines = shown.stdout.splitlines()
    assert lines[0].split()[:2] == ["acg", "ACG-ET2"] and lines[0].split()[-1] == "cipstack"
    assert lines[-1].split() == ["block", "BLK-1", "product", "code", "7", "Block", "One", "-", "block-dist"]
    # --profile's choices come from the registry.
    only = subprocess.run([sys.executable, "-m", "cipstack", "models", "--profile", "block"], capture_output=True,
                          text=True, env=env, timeout=60)
    assert only.returncode == 0 and only.stdout.splitlines() == lines[-1:]


def test_a_broken_installed_plugin_leaves_the_other_commands_working(tmp_path: Path) -> None:
    env = _installed(tmp_path, f"""
        [{GROUP}]
        block = broken_family:BLOCK
        """)
    shown = subprocess.run([sys.executable, "-m", "cipstack", "models"], capture_output=True, text=True,
                           env=env, timeout=60)
    assert shown.returncode == 1
    assert "ACG-ET2" in shown.stdout and "block" not in shown.stdout
    assert shown.stderr.strip().splitlines() == [
        "cipstack models: device family 'block' of distribution block-dist (broken_family:BLOCK) cannot be "
        "loaded: ModuleNotFoundError: No module named 'a_module_nobody_installed'"]
    asked = subprocess.run([sys.executable, "-m", "cipstack", "adapter", "--profile", "block", "--port", "0"],
                           capture_output=True, text=True, env=env, timeout=60)
    assert asked.returncode != 0 and "Traceback" not in asked.stderr
    assert "device family 'block' of distribution block-dist" in asked.stderr
    assert len(asked.stderr.strip().splitlines()) == 1


def test_the_eds_tool_describes_a_family_by_its_declaration(tmp_path: Path) -> None:
    """``cipstack eds generate`` holds no table of families: a plug-in's family has its file made by the
    function its declaration names, and a family that declares none is one line."""
    env = _installed(tmp_path, f"""
        [{GROUP}]
        block = block_family:BLOCK
        plain = block_family:PLAIN
        """)
    out = tmp_path / "eds"
    made = subprocess.run([sys.executable, "-m", "cipstack", "eds", "generate", "--profile", "block", "-o", str(out)],
                          capture_output=True, text=True, env=env, timeout=120)
    assert made.returncode == 0, made.stderr
    (path,) = out.iterdir()
    text = path.read_text(encoding="ascii")
    assert made.stdout == f"{path}\n" and "VendCode = 1234;" in text and "ProdCode = 7;" in text
    assert 'ProdName = "Block One";' in text
    refused = subprocess.run([sys.executable, "-m", "cipstack", "eds", "generate", "--profile", "plain", "-o",
                              str(out)], capture_output=True, text=True, env=env, timeout=120)
    assert (refused.returncode, refused.stderr) == (2, "cipstack eds generate: profile plain declares no EDS file\n")
