"""Each operation of the command service is declared once (``cipstack.control.operations``): its
handler, its argument record, its console formatter and its help. No surface asks an operation's name
what it is: the source of ``control/``, ``cli/drive.py`` and ``testing/`` holds no comparison with an
operation's name and no table keyed by operation names."""

from __future__ import annotations

import ast
import dataclasses
import inspect
from pathlib import Path

import pytest

from cipstack.control.operations import OPERATION_BY_NAME, OPERATIONS, Operation
from cipstack.control.service import DeviceService

PACKAGE = Path(__file__).resolve().parent.parent / "cipstack"
#: Where an operation's name must not be branched on (the declarations themselves excepted).
SURFACES = [*sorted((PACKAGE / "control").glob("*.py")), PACKAGE / "cli" / "drive.py",
            *sorted((PACKAGE / "testing").glob("*.py"))]
DECLARATION = PACKAGE / "control" / "operations.py"
NAMES = set(OPERATION_BY_NAME)


def _names_an_operation(node: ast.AST) -> bool:
    """A string constant equal to an operation's name, alone or in a tuple, list or set of constants."""
    if isinstance(node, ast.Constant):
        return isinstance(node.value, str) and node.value in NAMES
    if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
        return any(_names_an_operation(element) for element in node.elts)
    return False


def branches_on_a_name(source: str) -> list[str]:
    """Where ``source`` compares with an operation's name (``==``, ``!=``, ``in``, ``match``), or holds a
    table that maps two or more operation names to functions or methods (a second declaration)."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Compare) and any(map(_names_an_operation, [node.left, *node.comparators])):
            found.append(f"line {node.lineno}: {ast.unparse(node)}")
        elif isinstance(node, ast.MatchValue) and _names_an_operation(node.value):
            found.append(f"line {node.lineno}: case {ast.unparse(node.value)}")
        elif isinstance(node, ast.Dict):
            keyed = [value for key, value in zip(node.keys, node.values, strict=True)
                     if key is not None and _names_an_operation(key)]
            if len(keyed) >= 2 and all(isinstance(v, (ast.Name, ast.Attribute, ast.Lambda)) for v in keyed):
                found.append(f"line {node.lineno}: a table by operation names")
    return found


def test_the_check_finds_each_way_of_branching_on_a_name() -> None:
    """The check itself: each kind of branch it refuses is found, and a call by name is not one."""
    assert branches_on_a_name('if operation.name == "fault": pass')
    assert branches_on_a_name('x = a if name in ("trip", "reset") else b')
    assert branches_on_a_name('match name:\n    case "status": pass')
    assert branches_on_a_name('TEXT = {"status": status_text, "faults": faults_text}')
    assert not branches_on_a_name('service.call("trip", {"code": 5})')
    assert not branches_on_a_name('record = {"status": line, "faults": count()}')


@pytest.mark.parametrize("path", [p for p in SURFACES if p != DECLARATION], ids=lambda p: p.name)
def test_no_surface_branches_on_an_operation_s_name(path: Path) -> None:
    assert branches_on_a_name(path.read_text(encoding="utf-8")) == []


@pytest.mark.parametrize("operation", OPERATIONS, ids=lambda o: o.name)
def test_each_operation_s_handler_takes_its_record(operation: Operation) -> None:
    """The handler is a method of the service whose parameters are the record's fields (plus who asks,
    for an operation that records it), each required field a required parameter."""
    handler = getattr(DeviceService, operation.handler)
    parameters = inspect.signature(handler).parameters
    taken = [name for name in parameters if name != "self"]
    fields = [f.name for f in dataclasses.fields(operation.record)]
    assert taken == fields + (["origin", "peer"] if operation.tells_origin else [])
    for f in dataclasses.fields(operation.record):
        required = f.default is dataclasses.MISSING
        assert (parameters[f.name].default is inspect.Parameter.empty) == required, f.name
    assert dataclasses.is_dataclass(operation.record)
    assert operation.record.__dataclass_params__.frozen   # type: ignore[attr-defined]  # dataclasses' own, untyped
    assert [a.key for a in operation.arguments] == fields


def test_an_argument_record_is_frozen() -> None:
    record = OPERATION_BY_NAME["set-parameter"].record(code="ACC", value="2.5")
    with pytest.raises(dataclasses.FrozenInstanceError):
        record.code = "DEC"   # type: ignore[misc]  # the subject: a frozen record refuses the write
    assert OPERATION_BY_NAME["set-parameter"].given(record) == {"code": "ACC", "value": "2.5"}
