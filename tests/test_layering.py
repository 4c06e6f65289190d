"""The dependency direction DESIGN.md gives, checked on the source: ``cip`` depends on nothing of
ours but ``errors`` (the error root, which every part may import and which imports nothing of ours);
``objects`` and ``assemblies`` on ``cip``; ``eip`` and ``componet`` on ``cip`` alone (a
transport knows no device); ``devices`` on those; ``eds`` reads the devices' declarations, never
the other way round."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "cipstack"

#: What each part may import of the package (its own modules always).
ALLOWED = {
    "cip": {"errors"},
    "objects": {"cip", "errors"},
    "assemblies": {"cip", "errors"},
    "eip": {"cip", "errors"},
    "componet": {"cip", "eip", "errors"},
    # catalog: the index of declared classes a device hands its scanner (it imports only what lies below).
    "devices": {"cip", "objects", "assemblies", "eip", "componet", "catalog", "errors"},
    # The battery sits on top: it may use what lies below (the codecs, the EDS reader, the
    # scanner's reading of an EDS) and nothing imports it but the command line.
    "conformance": {"cip", "objects", "assemblies", "eip", "componet", "devices", "catalog", "eds", "scanner",
                    "errors"},
    # Modbus ports: transport shells over a drive's sans-I/O Modbus core (the register map is the device's).
    "modbus": {"cip", "eip", "devices", "errors"},
    # A running device: its ports, power and link, seams and observers; it knows no shell above it.
    "runtime": {"cip", "eip", "devices", "modbus", "errors"},
    # On top (DESIGN): faults and control act through the runtime's interface, never on the adapter.
    "faults": {"cip", "eip", "runtime", "errors"},
    "control": {"eip", "faults", "runtime", "devices", "errors"},
    # The pytest plugin: fixtures over the in-process adapter, its faults and events, and the scanner.
    "testing": {"adapter", "control", "scanner", "devices", "eds", "errors"},
}

#: The parts that sit on top: nothing else in the package imports them (DESIGN.md).
ON_TOP = {"conformance": {"cli"}}


def _type_checking_only(tree: ast.Module) -> set[int]:
    """Line numbers of imports under ``if TYPE_CHECKING:``: annotations, not a dependency at run time."""
    lines: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING":
            for inner in node.body:
                lines.update(range(inner.lineno, (inner.end_lineno or inner.lineno) + 1))
    return lines


def _imports(path: Path) -> set[str]:
    """The top-level parts of ``cipstack`` a module imports (relative or absolute)."""
    part_depth = len(path.relative_to(PACKAGE).parts) - 1     # package levels below cipstack/
    found: set[str] = set()
    tree = ast.parse(path.read_text(encoding="utf-8"))
    typing_only = _type_checking_only(tree)
    for node in ast.walk(tree):
        if getattr(node, "lineno", None) in typing_only:
            continue
        if isinstance(node, ast.ImportFrom):
            if node.level:
                up = node.level - 1
                if up < part_depth:
                    continue                                     # inside its own part
                target = (node.module or "").split(".")
                names = [alias.name for alias in node.names] if not target[0] else [target[0]]
                found.update(names)
            elif node.module and node.module.startswith("cipstack."):
                found.add(node.module.split(".")[1])
        elif isinstance(node, ast.Import):
            found.update(alias.name.split(".")[1] for alias in node.names if alias.name.startswith("cipstack."))
    return found


@pytest.mark.parametrize("part", sorted(ALLOWED))
def test_each_part_imports_only_what_lies_below_it(part: str) -> None:
    wrong = {}
    for path in sorted((PACKAGE / part).rglob("*.py")):
        extra = _imports(path) - ALLOWED[part] - {part}
        if extra:
            wrong[str(path.relative_to(PACKAGE))] = sorted(extra)
    assert wrong == {}


@pytest.mark.parametrize("part", sorted(ON_TOP))
def test_nothing_below_imports_the_parts_on_top(part: str) -> None:
    wrong = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        owner = path.relative_to(PACKAGE).parts[0].removesuffix(".py")
        if owner == part or owner in ON_TOP[part]:
            continue
        if part in _imports(path):
            wrong[str(path.relative_to(PACKAGE))] = part
    assert wrong == {}


def test_errors_imports_nothing_of_the_package() -> None:
    """``errors`` lies below every part: it imports nothing of ours, so any part may import it."""
    assert _imports(PACKAGE / "errors.py") == set()
