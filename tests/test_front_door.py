"""Tests read through the front door: what a test observes of another object is what that object
shows (a property, a counter, an event, the wire, a log line), not an attribute whose name begins
with an underscore. Where a test is about that very layer's internals (a unit test of a private
cache, a third-party peer with no public switch), its line says so with ``# internals: <why>``.

The check reads the source of every test module: a read of ``obj._name`` (``obj`` not ``self`` or
``cls``), ``getattr(obj, "_name")`` and the like, and ``from module import _name``, each on a line
without that comment, is a failure. A test module's own helpers (``tests.ports._offer``) are the
tests' own, and a named tuple's ``_replace``/``_asdict``/``_fields`` are its public interface."""

from __future__ import annotations

import ast
import io
import tokenize
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent
#: The comment that says a line is about a layer's internals, and why.
MARKER = "# internals:"
#: Names with a leading underscore that are public: a named tuple's interface, and ``sys._getframe``,
#: ``os._exit``, which the standard library documents.
PUBLIC = frozenset({"_replace", "_asdict", "_fields", "_field_defaults", "_make", "_getframe", "_exit"})
#: Calls that name an attribute by a string: ``getattr(obj, "_name")``, ``monkeypatch.setattr(obj, "_name", ...)``.
BY_NAME = frozenset({"getattr", "setattr", "hasattr", "delattr"})
def _private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__") and name not in PUBLIC


def _marked_lines(source: str) -> set[int]:
    """The lines that carry the ``# internals:`` comment (a comment token: not text in a string)."""
    marked = set()
    for token in tokenize.generate_tokens(io.StringIO(source).readline):
        if token.type == tokenize.COMMENT and MARKER in token.string:
            marked.add(token.start[0])
    return marked


def _tests_modules(tree: ast.Module, path: Path | None) -> set[str]:
    """Names the module binds to a module of the tests (``from tests import ports``, ``from . import
    fakes``, ``import tests.ports as ports``): their private helpers are the tests' own."""
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == "tests":
                    found.add(alias.asname or alias.name.split(".")[0])
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = (path or TESTS / "x.py").parent
                for _ in range(node.level - 1):
                    base = base.parent
            elif node.module is not None and node.module.split(".")[0] == "tests":
                base = ROOT
            else:
                continue
            for part in (node.module or "").split("."):
                if part:
                    base = base / part
            for alias in node.names:
                if (base / f"{alias.name}.py").is_file() or (base / alias.name / "__init__.py").is_file():
                    found.add(alias.asname or alias.name)
    return found


def _owner_is_own(value: ast.expr, own: set[str]) -> bool:
    """``self``, ``cls``, ``super()`` or a module of the tests: not another object's private."""
    if isinstance(value, ast.Name):
        return value.id in own
    return isinstance(value, ast.Call) and isinstance(value.func, ast.Name) and value.func.id == "super"


def _from_tests(node: ast.ImportFrom) -> bool:
    return bool(node.level) or (node.module or "").split(".")[0] == "tests"


def private_reads(source: str, path: Path | None = None) -> list[tuple[int, str]]:
    """Each read of another object's private attribute in ``source`` on a line without the
    ``# internals:`` comment, as (line, what is read), in line order."""
    tree = ast.parse(source)
    own = {"self", "cls"} | _tests_modules(tree, path)
    found: list[tuple[int, int, int, str]] = []
    for node in ast.walk(tree):
        first = getattr(node, "lineno", 0)
        last = getattr(node, "end_lineno", None) or first
        if isinstance(node, ast.Attribute) and _private(node.attr) and not _owner_is_own(node.value, own):
            what = ast.unparse(node)
        elif (isinstance(node, ast.Call) and len(node.args) >= 2 and isinstance(node.args[1], ast.Constant)
              and isinstance(node.args[1].value, str) and _private(node.args[1].value)
              and ((isinstance(node.func, ast.Name) and node.func.id in BY_NAME)
                   or (isinstance(node.func, ast.Attribute) and node.func.attr in BY_NAME))
              and not _owner_is_own(node.args[0], own)):
            what = f"{ast.unparse(node.args[0])}.{node.args[1].value}"
        elif isinstance(node, ast.ImportFrom) and not _from_tests(node):
            names = [alias.name for alias in node.names if _private(alias.name)]
            if not names:
                continue
            what = f"{node.module}.{', '.join(names)}"
        else:
            continue
        found.append((first, last, node.col_offset, what))
    marked = _marked_lines(source) if found else set()   # most modules have nothing to read the comments for
    return [(first, what) for first, last, _, what in sorted(found) if not marked.intersection(range(first, last + 1))]


def _test_modules() -> list[Path]:
    return sorted(path for path in TESTS.rglob("*.py") if "__pycache__" not in path.parts)


def test_every_test_reads_other_objects_through_their_public_side() -> None:
    unmarked = []
    for path in _test_modules():
        name = path.relative_to(ROOT).as_posix()
        unmarked += [f"{name}:{line}: {what}" for line, what in private_reads(path.read_text(encoding="utf-8"), path)]
    assert not unmarked, ("a test reads another object's private attribute: read what it shows instead (a "
                          "property, a counter, the wire), add one to the product if a user would want it too, "
                          f"or say why on the line with '{MARKER} <why>':\n  " + "\n  ".join(unmarked))


PLANTED = '''\
from tests import ports
from tests.interop import conftest
from cipstack.params import _load_toml
from cipstack.cli.fleet import (
    _fleet_spec,
)
from .fakes import _helper

class Harness:
    def method(self) -> None:
        self._inbox.clear()
        super()._reset()
        cls = type(self)
        cls._registry.clear()

def test_it(h, loop, monkeypatch) -> None:
    assert len(h.conn._inbox) == 0
    assert len(h.conn._outbox) == 0  # internals: the outbox is the class's own business
    assert (h.conn
            ._ready) == 0  # internals: a marker on any line of the expression counts
    assert getattr(loop, "_ready") is not None
    monkeypatch.setattr(loop, "_selector", None)
    ports._offer(1)
    assert conftest.IDENTITY
    assert SPEED._replace(maximum=1)._asdict()["maximum"] == 1
    text = "obj._hidden # internals: text in a string is no comment"
    sys._getframe(0)
'''


def test_the_check_finds_a_planted_read_and_passes_a_marked_or_own_one() -> None:
    """The check can fail: on planted lines it finds each kind of read, and only those."""
    found = private_reads(PLANTED, TESTS / "test_planted.py")
    assert found == [
        (3, "cipstack.params._load_toml"),
        (4, "cipstack.cli.fleet._fleet_spec"),
        (17, "h.conn._inbox"),
        (21, "loop._ready"),
        (22, "loop._selector"),
    ]


@pytest.mark.parametrize("line", [
    "    assert len(h.conn._inbox) == 0",
    "    value = getattr(adapter, '_state')",
    "    from cipstack.scanner import _Unsplittable",
])
def test_a_planted_line_in_a_test_module_fails_the_check(tmp_path: Path, line: str) -> None:
    """A read planted in (a copy of) a real test module is found there, and its marker clears it."""
    source = (TESTS / "test_router.py").read_text(encoding="utf-8")
    planted = source.replace("def test_attribute_readers_are_bounded() -> None:\n",
                             f"def test_attribute_readers_are_bounded() -> None:\n{line}\n", 1)
    assert planted != source
    before = private_reads(source, TESTS / "test_router.py")
    after = private_reads(planted, TESTS / "test_router.py")
    assert len(after) == len(before) + 1
    cleared = planted.replace(f"{line}\n", f"{line}  {MARKER} planted\n", 1)
    assert private_reads(cleared, TESTS / "test_router.py") == before
