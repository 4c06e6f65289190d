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
def test_each_operation_is_bound_to_its_handler(operation: Operation) -> None:
    """The declaration holds the handler itself (no method name looked up at run time): a function of
    the service, the operation's own argument record and who asks; the record is a frozen dataclass
    whose fields are the arguments."""
    assert inspect.isfunction(operation.handler)
    parameters = list(inspect.signature(operation.handler).parameters.values())
    assert [p.annotation for p in parameters] == ["DeviceService", operation.record.__name__, "Caller"]
    fields = [f.name for f in dataclasses.fields(operation.record)]
    assert dataclasses.is_dataclass(operation.record)
    assert operation.record.__dataclass_params__.frozen   # type: ignore[attr-defined]  # dataclasses' own, untyped
    assert [a.key for a in operation.arguments] == fields


async def test_an_operation_a_device_does_not_declare_is_refused_before_its_handler() -> None:
    """A device without a drive declares no trips and no keypad (``Device.drive_trips``, ``keypad``):
    ``trip``, ``reset`` and the parameter operations are refused from that with the declaration's own
    error, and what is offered says so; ``trips`` answers the empty list a front panel shows."""
    from cipstack.adapter import Adapter, AdapterSettings
    from cipstack.devices.base import NoDrive
    from cipstack.devices.keypad import NoKeypad
    from cipstack.devices.profiles import build_device, identity_only_device
    from cipstack.errors import BadRequest, NotFound

    bare = Adapter(AdapterSettings(host="127.0.0.1", port=0), device=identity_only_device())
    service = bare.service
    for name in ("trip", "reset"):
        assert not service.offers(OPERATION_BY_NAME[name])
        with pytest.raises(NoDrive, match="this profile simulates no drive") as refused:
            service.call(name, {"code": 5} if name == "trip" else {})
        assert isinstance(refused.value, BadRequest)
    for name, arguments in (("parameter", {"code": "ACC"}), ("parameters", {})):
        assert not service.offers(OPERATION_BY_NAME[name])
        with pytest.raises(NoKeypad, match="this device has no keypad") as missing:
            service.call(name, arguments)
        assert isinstance(missing.value, NotFound)
    assert service.call("trips", {}) == []

    drive = Adapter(AdapterSettings(host="127.0.0.1", port=0), device=build_device("acg"))
    assert all(drive.service.offers(operation) for operation in OPERATIONS)
    trip = drive.service.call("trip", {"code": "0x4200"})
    assert (trip["result"], trip["trip"]) == ("tripped: OverHeat (fault code 0x4200)", "OverHeat")
    assert drive.service.call("reset", {})["cleared"] == "OverHeat"


def test_an_argument_record_is_frozen() -> None:
    record = OPERATION_BY_NAME["set-parameter"].record(code="ACC", value="2.5")
    with pytest.raises(dataclasses.FrozenInstanceError):
        record.code = "DEC"   # type: ignore[misc]  # the subject: a frozen record refuses the write
    assert OPERATION_BY_NAME["set-parameter"].given(record) == {"code": "ACC", "value": "2.5"}
