"""No bare builtin exception is raised on purpose: every ``raise`` in ``cipstack/`` raises a
``CipstackError`` kind (``cipstack/errors.py``), so ``except cipstack.CipstackError`` catches what the
package means to raise. The kinds keep the builtin they replace as a base (``BadRequest`` is a
``ValueError``, ``UnknownKey`` a ``KeyError``, ``NoReply`` a ``TimeoutError``).

Read from the source (ast), not by importing it: a raise on a path no test reaches counts too."""

from __future__ import annotations

import ast
import builtins
from pathlib import Path

import pytest

#: One worker runs this module's tests (``--dist loadgroup``): the package is scanned once for all.
pytestmark = pytest.mark.xdist_group("raise_builtins")

PACKAGE = Path(__file__).resolve().parent.parent / "cipstack"

#: Every builtin exception class, by name (``asyncio.TimeoutError`` and the like are caught by name too).
BUILTIN_ERRORS = frozenset(name for name, value in vars(builtins).items()
                           if isinstance(value, type) and issubclass(value, BaseException))

#: The raises of builtins that stay, by (file, enclosing function, builtin), each with why.
ALLOWED: dict[tuple[str, str, str], str] = {
    # Python's own protocols: the caller is the interpreter or a library, not a user.
    ("eip/originator/process_image.py", "ProcessImage.__getattr__", "AttributeError"):
        "a dunder looked up by copy/pickle/hasattr: the protocol's plain AttributeError (names are UnknownField)",
    ("eip/target/limits.py", "GuardedListener.accept", "BlockingIOError"):
        "to asyncio's accept loop an empty queue (EAGAIN), never an error: no user sees it",
    ("control/http.py", "QuietRequestHandler.handle_error", "ConnectionError"):
        "aiohttp ends a connection whose answer began on this error; it never leaves the server",
    ("eip/io_server.py", "refuse_exact_sharer", "OSError"):
        "a bind's EADDRINUSE, as the kernel would say it: the adapter turns it into ListenError",
    ("devices/omron/flexible.py", "flexible_writes", "AssertionError"):
        "an invariant (validate_flexible let no such address through): a defect if it ever fires",
}


def _enclosing(tree: ast.Module) -> dict[ast.Raise, str]:
    """Each raise of ``tree`` and the qualified name of the function (or class) it is in ('' at top level)."""
    found: dict[ast.Raise, str] = {}

    def visit(node: ast.AST, scope: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
                visit(child, f"{scope}.{child.name}" if scope else child.name)
            else:
                if isinstance(child, ast.Raise):
                    found[child] = scope
                visit(child, scope)

    visit(tree, "")
    return found


def _builtin_raised(node: ast.Raise) -> str | None:
    exc = node.exc
    target = exc.func if isinstance(exc, ast.Call) else exc
    if isinstance(target, ast.Name) and target.id in BUILTIN_ERRORS:
        return target.id
    if isinstance(target, ast.Attribute) and target.attr in BUILTIN_ERRORS:   # asyncio.TimeoutError(...)
        return target.attr
    return None


def _allowed_by_rule(node: ast.Raise, scope: str, name: str) -> bool:
    exc = node.exc
    bare = not isinstance(exc, ast.Call) or not (exc.args or exc.keywords)
    if name == "NotImplementedError" and bare:
        return True   # an abstract method: a subclass's duty, not an error of the package
    if name == "AttributeError" and scope == "__getattr__":
        return True   # a module's __getattr__ (PEP 562): ``from cipstack import Nope`` needs AttributeError
    return name == "SystemExit" and scope in ("", "main")   # ``python -m``: the process's exit status


def builtin_raises() -> dict[tuple[str, str, str], list[int]]:
    """Every raise of a builtin exception in the package, by (file, scope, builtin) -> line numbers."""
    raises: dict[tuple[str, str, str], list[int]] = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        for node, scope in _enclosing(tree).items():
            name = _builtin_raised(node)
            if name is None or _allowed_by_rule(node, scope, name):
                continue
            raises.setdefault((path.relative_to(PACKAGE).as_posix(), scope, name), []).append(node.lineno)
    return raises


@pytest.fixture(scope="module")
def scanned() -> dict[tuple[str, str, str], list[int]]:
    """The scan, once for the tests of this module (it parses the whole package)."""
    return builtin_raises()


def test_the_scan_finds_raises_of_builtins(scanned: dict[tuple[str, str, str], list[int]]) -> None:
    # Without this, a scan that found nothing would pass the test below: the allowed ones are there.
    assert set(ALLOWED) <= set(scanned)


def test_no_builtin_is_raised_outside_the_allow_list(scanned: dict[tuple[str, str, str], list[int]]) -> None:
    unexpected = {f"cipstack/{file}:{lines[0]}: raise {name} in {scope or 'the module'}"
                  for (file, scope, name), lines in scanned.items() if (file, scope, name) not in ALLOWED}
    assert sorted(unexpected) == [], ("raise a kind of cipstack.errors (BadRequest keeps ValueError, UnknownKey "
                                      "KeyError, PeerUnreachable ConnectionError, NoReply TimeoutError), or say "
                                      "in ALLOWED why the builtin stays")


def test_the_allow_list_stays_short() -> None:
    assert len(ALLOWED) <= 8
