"""The dependency direction DESIGN.md gives, checked on the source: ``cip`` depends on nothing of
ours but ``errors`` and ``logs`` (the error root and the debug records made on demand, which every part may
import and which import nothing of ours);
``objects`` and ``assemblies`` on ``cip``; ``eip`` and ``componet`` on ``cip`` alone (a
transport knows no device); ``devices`` on those; ``eds`` reads the devices' declarations, never
the other way round."""

from __future__ import annotations

import ast
import functools
import itertools
from collections.abc import Iterator
from pathlib import Path

import pytest

#: One worker runs this module's tests (``--dist loadgroup``): the package is parsed once for all.
pytestmark = pytest.mark.xdist_group("layering")

PACKAGE = Path(__file__).resolve().parent.parent / "cipstack"

#: What every part may import: the error root and the debug records on demand (both import nothing of ours).
BELOW_ALL = {"errors", "logs"}
#: What each part may import of the package (its own modules always, and ``BELOW_ALL``).
#: The part of the families' EDS descriptions (``devices/*/eds_file.py``).
FAMILY_EDS = "family_eds"

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
                    "security", "errors"},
    # Modbus ports: transport shells over a drive's sans-I/O Modbus core (the register map is the device's).
    "modbus": {"cip", "eip", "devices", "errors"},
    # A running device: its ports, power and link, seams and observers; it knows no shell above it.
    "runtime": {"cip", "eip", "devices", "modbus", "errors"},
    # On top (DESIGN): faults and control act through the runtime's interface, never on the adapter.
    "faults": {"cip", "eip", "runtime", "errors"},
    "control": {"eip", "faults", "runtime", "devices", "errors"},
    # The pytest plugin: fixtures over the in-process adapter, its faults and events, and the scanner.
    "testing": {"adapter", "control", "scanner", "devices", "eds", "errors"},
    # The single-file modules. The adapter is the composition root: it builds the device, its ports
    # and runtime, the fault controller, the event stream and the command service, and passes each
    # its collaborators; so it sits above faults and control, which know only the runtime.
    "adapter": {"control", "devices", "eip", "errors", "faults", "listening", "modbus", "objects", "runtime",
                "security"},
    "scanner": {"catalog", "cip", "devices", "eds", "eip", "errors", "objects", "parameter_codes", "profile_catalog",
                "sync_io", "async_scanner"},
    # The async scanner: the scanner's plans on the asyncio client (``cipstack.scanner`` names it too).
    "async_scanner": {"catalog", "cip", "eip", "errors", "scanner"},
    # Parameters by code: the catalog's declarations, read and written through the scanner it is given.
    "parameter_codes": {"catalog", "cip", "errors"},
    # A profile's catalog from its generated compact declarations (devices/declared), assemblies included.
    "profile_catalog": {"assemblies", "catalog", "cip", "devices", "errors"},
    "sync_io": {"eip", "errors"},
    "params": {"catalog", "cip", "errors"},
    "catalog": {"assemblies", "cip", "eip", "objects", "errors"},
    "listening": {"errors"},
    # CIP Security: TLS shells around the encapsulation cores, credentials and provisioning.
    "security": {"cip", "eip", "errors", "objects"},
    # The EDS tool reads the devices' declarations and writes their files; compared with a live device,
    # it asks the scanner it is given through a protocol of its own (``eds.against.LiveDevice``).
    "eds": {"assemblies", "catalog", "cip", "devices", "eip", "objects", "errors"},
    # Capture analysis decodes what the devices and EDS files declare.
    "capture": {"assemblies", "catalog", "cip", "componet", "devices", "eds", "eip", "errors"},
    # A fleet: adapters in worker processes, their control planes relayed.
    "fleet": {"adapter", "control", "devices", "eds", "eip", "errors", "listening", "modbus", "runtime"},
    # A family's EDS description (``devices/NAME/eds_file.py``): the family's package, but a part above
    # the EDS tool whose types it uses, as a family from another distribution is; nothing imports it
    # (its declaration names it, ``Profile.eds``, and the EDS generator loads it by that name).
    FAMILY_EDS: {"assemblies", "cip", "devices", "eds", "eip", "objects", "errors"},
}

#: Parts that are one part in two modules (the blocking and the asyncio scanner name each other).
SAME_PART = {"async_scanner": "scanner"}

#: The parts that sit on top: nothing else in the package imports them (DESIGN.md).
ON_TOP = {"conformance": {"cli"},
          # Only what sits above the composition root imports it: the command line, a fleet, the plugin.
          "adapter": {"cli", "fleet", "testing", "__init__", "__main__"}}

#: What knows a running device only through the runtime's narrow interface, not even for type checking.
RUNTIME_CLIENTS = ("runtime", "faults", "control", "modbus", "eip", "devices")


def _type_checking_only(tree: ast.Module) -> set[int]:
    """Line numbers of imports under ``if TYPE_CHECKING:``: annotations, not a dependency at run time."""
    lines: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING":
            for inner in node.body:
                lines.update(range(inner.lineno, (inner.end_lineno or inner.lineno) + 1))
    return lines


@functools.cache
def _tree(path: Path) -> ast.Module:
    """A module's syntax tree, parsed once for every check of the run."""
    return ast.parse(path.read_text(encoding="utf-8"))


@functools.cache
def _imports(path: Path, type_checking: bool = False) -> frozenset[str]:
    """The top-level parts of ``cipstack`` a module imports (relative or absolute); with
    ``type_checking``, its imports for annotations too. Kept for the process: the tests of this module
    ask about the same files again and again, and the source does not change during a run."""
    part_depth = len(path.relative_to(PACKAGE).parts) - 1     # package levels below cipstack/
    found: set[str] = set()
    tree = _tree(path)
    typing_only = set() if type_checking else _type_checking_only(tree)
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
    return frozenset(found)


def _is_family_eds(path: Path) -> bool:
    relative = path.relative_to(PACKAGE).parts
    return len(relative) == 3 and relative[0] == "devices" and relative[2] == "eds_file.py"


def _part(path: Path) -> str:
    """The part a module belongs to: its top-level package or single-file module, or ``FAMILY_EDS``."""
    return FAMILY_EDS if _is_family_eds(path) else path.relative_to(PACKAGE).parts[0].removesuffix(".py")


def _generic_modules() -> Iterator[tuple[Path, list[ast.AST]]]:
    """Every module outside ``cipstack/devices/`` (its path in the package) with the nodes of its tree."""
    for path in sorted(PACKAGE.rglob("*.py")):
        relative = path.relative_to(PACKAGE)
        if relative.parts[0] != "devices":
            yield relative, list(ast.walk(_tree(path)))


def _modules_of(part: str) -> list[Path]:
    """A package's modules, or the single-file module ``part.py`` (``FAMILY_EDS``: the families' EDS
    descriptions, which ``devices`` does not count as its own)."""
    if part == FAMILY_EDS:
        return sorted(path for path in (PACKAGE / "devices").rglob("eds_file.py") if _is_family_eds(path))
    single = PACKAGE / f"{part}.py"
    return [single] if single.is_file() else sorted(p for p in (PACKAGE / part).rglob("*.py") if not _is_family_eds(p))


@pytest.mark.parametrize("part", sorted(ALLOWED))
def test_each_part_imports_only_what_lies_below_it(part: str) -> None:
    modules = _modules_of(part)
    assert modules, part
    wrong = {}
    for path in modules:
        extra = _imports(path) - ALLOWED[part] - BELOW_ALL - {part}
        if extra:
            wrong[str(path.relative_to(PACKAGE))] = sorted(extra)
    assert wrong == {}


@pytest.mark.parametrize("part", sorted(ON_TOP))
def test_nothing_below_imports_the_parts_on_top(part: str) -> None:
    wrong = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        owner = _part(path)
        if owner == part or owner in ON_TOP[part]:
            continue
        if part in _imports(path, type_checking=True):
            wrong[str(path.relative_to(PACKAGE))] = part
    assert wrong == {}


@pytest.mark.parametrize("module", sorted(BELOW_ALL))
def test_what_lies_below_every_part_imports_nothing_of_the_package(module: str) -> None:
    """``errors`` and ``logs`` lie below every part: they import nothing of ours, so any part may import them."""
    assert _imports(PACKAGE / f"{module}.py") == set()


@pytest.mark.parametrize("part", RUNTIME_CLIENTS)
def test_what_lies_below_the_adapter_never_names_it_not_even_for_types(part: str) -> None:
    """Faults, the event stream and the command service work through ``cipstack.runtime``'s interface:
    no module of theirs (or of the runtime and what lies below it) imports ``adapter``, type-only
    imports included, so there is no arrow up to the adapter and no circle through it."""
    wrong = [str(path.relative_to(PACKAGE)) for path in _modules_of(part)
             if "adapter" in _imports(path, type_checking=True)]
    assert wrong == []


def test_the_import_graph_has_no_circle_through_the_adapter() -> None:
    """Follow every import (type-only ones too) from what the adapter imports: none leads back to it."""
    parts = {path.relative_to(PACKAGE).parts[0].removesuffix(".py") for path in PACKAGE.glob("*")
             if path.suffix == ".py" or (path.is_dir() and (path / "__init__.py").exists())} | {FAMILY_EDS}
    graph = {part: set().union(*(_imports(p, type_checking=True) for p in _modules_of(part))) - {part}
             for part in parts if _modules_of(part)}
    seen: set[str] = set()
    todo = list(graph["adapter"])
    while todo:
        part = todo.pop()
        if part in seen or part not in graph:
            continue
        seen.add(part)
        todo.extend(graph[part])
    assert "adapter" not in seen and seen >= {"runtime", "faults", "control"}


def test_no_arrow_runs_up_annotations_included() -> None:
    """Between the parts, imports for annotations included, the graph has no circle: no part depends,
    even for a type, on a part that depends on it."""
    def part_of(name: str) -> str:
        return SAME_PART.get(name, name)

    graph: dict[str, set[str]] = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        part = part_of(_part(path))
        if part in ("__init__", "__main__"):
            continue
        graph.setdefault(part, set()).update(part_of(p) for p in _imports(path, type_checking=True))
    for part in graph:
        graph[part] &= set(graph) - {part}

    def reaches(start: str, goal: str) -> list[str] | None:
        paths, seen = [[start]], {start}
        while paths:
            path = paths.pop()
            for nxt in sorted(graph[path[-1]]):
                if nxt == goal:
                    return [*path, nxt]
                if nxt not in seen:
                    seen.add(nxt)
                    paths.append([*path, nxt])
        return None

    circles = [circle for part in sorted(graph) if (circle := reaches(part, part)) is not None]
    assert circles == []


#: Modules outside ``cipstack/devices/`` allowed to hold a family's name as a string, each with why. None
#: is left: the command line's choices, the EDS tool and every other surface read the families'
#: declarations (``cipstack.devices.profiles.PROFILES``).
NAMES_A_FAMILY: dict[str, str] = {}


def test_no_generic_module_names_a_family() -> None:
    """DESIGN: a family is a plug-in, and nothing outside ``devices/`` names one. No module there holds a
    string constant equal to a built-in family's name (docstrings and messages that mention one in a
    sentence are not equal to it); ``devices/`` itself, with its generated ``declared/``, is where
    families are declared."""
    from cipstack.devices.registry import BUILT_IN

    families = {name for name, _ in BUILT_IN}
    assert families == {"acg", "mx2", "rx"}
    found: dict[str, list[str]] = {}
    for relative, nodes in _generic_modules():
        for node in nodes:
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value in families:
                found.setdefault(str(relative), []).append(f"{node.lineno}: {node.value!r}")
    assert {module: lines for module, lines in found.items() if module not in NAMES_A_FAMILY} == {}
    # An exemption that is no longer needed goes.
    assert sorted(set(NAMES_A_FAMILY) - set(found)) == []


def test_no_generic_module_is_a_family_s() -> None:
    """A family's modules are in its package under ``devices/``: no module or package elsewhere is named
    after a family or a family's package (the ACG and Omron assemblies were ``assemblies/acg.py`` and
    ``assemblies/omron.py``)."""
    from cipstack.devices.registry import BUILT_IN

    names = {name for name, _ in BUILT_IN} | {path.parent.name for path in (PACKAGE / "devices").glob("*/family.py")}
    assert names == {"acg", "mx2", "rx", "omron"}
    found = sorted(str(path.relative_to(PACKAGE)) for path in PACKAGE.rglob("*")
                   if path.relative_to(PACKAGE).parts[0] != "devices" and "__pycache__" not in path.parts
                   and (path.suffix == ".py" or path.is_dir()) and path.stem in names)
    assert found == []


#: Modules outside ``cipstack/devices/`` that import a family's own package, each with why.
IMPORTS_A_FAMILY: dict[str, str] = {}


def test_nothing_imports_a_family_s_eds_description() -> None:
    """A family's EDS description is loaded by the name its declaration gives (``Profile.eds``), never
    imported: the device's runtime does not pull the EDS tool in, and the EDS tool names no family."""
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        for node in ast.walk(_tree(path)):
            if isinstance(node, ast.ImportFrom):
                # ``from .. import eds_file`` inside devices/, or a module path ending in it (not the File
                # object's function of that name).
                module = node.module or ""
                inside = path.relative_to(PACKAGE).parts[0] == "devices" or "devices" in module.split(".")
                named = [module, *(alias.name for alias in node.names if inside)]
            elif isinstance(node, ast.Import):
                named = [alias.name for alias in node.names]
            else:
                continue
            if any(name.split(".")[-1] == "eds_file" for name in named):
                found.append(str(path.relative_to(PACKAGE)))
    assert found == []
    assert [p.relative_to(PACKAGE).parts[1] for p in _modules_of(FAMILY_EDS)] == ["acg", "omron"]


def test_no_generic_module_imports_a_family_package() -> None:
    """A family's package (``devices/NAME/`` with its ``family.py``) is imported by the devices alone; the
    generic parts read the declaration (``Profile``, ``Device``, ``ModbusDrive``), type-only imports too."""
    families = {path.parent.name for path in (PACKAGE / "devices").glob("*/family.py")}
    assert families == {"acg", "omron"}
    found: dict[str, list[str]] = {}
    for relative, nodes in _generic_modules():
        for node in nodes:
            names: list[str] = []
            if isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module, *(f"{node.module}.{alias.name}" for alias in node.names)]
            elif isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            for name in names:
                parts = name.lstrip(".").split(".")
                if any(a == "devices" and b in families for a, b in itertools.pairwise(parts)):
                    found.setdefault(str(relative), []).append(f"{node.lineno}: {name}")
                    break
    assert sorted(module for module in found if module not in IMPORTS_A_FAMILY) == []
    assert sorted(set(IMPORTS_A_FAMILY) - set(found)) == []
