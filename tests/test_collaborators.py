"""A running adapter's collaborators are the ones each object was given when it was made (DESIGN: a
core takes its collaborators at construction; nothing is patched at run time).

The adapter is made and started while a profile hook records, as each ``__init__`` of a cipstack
class returns, what the new object then holds. After ``start`` the objects reachable from the adapter
are walked: every collaborator one of them holds (a function, a bound method, an object of a cipstack
class) must be the one it held when its constructor returned, and the class 1 hooks, the hot path of
every datagram, are the bound methods of the objects that serve them (no lambda of the adapter or the
runtime filled in afterwards)."""

from __future__ import annotations

import enum
import functools
import sys
import types
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

import cipstack
from cipstack.adapter import Adapter, AdapterSettings
from cipstack.eds.emulated_device import build_eds_device
from cipstack.eds.reader import read_eds

PACKAGE = Path(cipstack.__file__).parent
EDS_FILE = Path(__file__).parent / "eds" / "files" / "ez_style_iolink_master.eds"

#: What a shell takes in ``start`` from the running loop, not from whoever made it: the loop itself, the
#: class 1 lane of a ``PreciseEventLoop`` (None on any other loop), the TCP listener the encapsulation
#: server makes on that lane for its own socket, and the line the RS-485 port makes when it opens its tty.
TAKEN_AT_START = frozenset({("IoEndpoint", "loop"), ("IoEndpoint", "_lane"), ("EncapsulationServer", "loop"),
                            ("EncapsulationServer", "_tcp"), ("ModbusTcpServer", "loop"), ("RtuLine", "loop"),
                            ("Rs485Port", "line"),
                            # The line's settings, read from the first drive when the line starts: state.
                            ("RtuLine", "_settings")})

#: What a device's builder sets once the device has the objects it is computed from: the class 1 offer
#: of a device emulated from an EDS file is read from the assemblies the builder added to it (the
#: description the class 1 target is then made with, not a hook of the device).
BUILT_IN_STEPS = frozenset({("EdsDevice", "_io")})



def _ours(value: object) -> bool:
    return type(value).__module__.startswith("cipstack.") and not isinstance(value, (type, enum.Enum))


def _collaborator(value: object) -> bool:
    """A hook (a function, a bound method, a partial) or an object of a cipstack class."""
    return isinstance(value, (types.FunctionType, types.MethodType, functools.partial)) or _ours(value)


class Constructions:
    """``sys.setprofile`` hook: what each cipstack object holds when its (outermost) ``__init__`` returns."""

    def __init__(self) -> None:
        self.made: dict[int, tuple[object, dict[str, Any]]] = {}

    def __call__(self, frame: types.FrameType, event: str, arg: object) -> None:
        if event != "return" or frame.f_code.co_name != "__init__":
            return
        made = frame.f_locals.get("self")
        if made is not None and _ours(made):
            # An inner __init__ (super().__init__) returns first; the outermost one, last, overwrites it.
            self.made[id(made)] = (made, _attributes(made))

    def at_construction(self, held: object) -> dict[str, Any] | None:
        found = self.made.get(id(held))
        return found[1] if found is not None and found[0] is held else None


def _attributes(held: object) -> dict[str, Any]:
    """What an object holds: its ``__dict__`` and its slots."""
    found = dict(getattr(held, "__dict__", {}))
    for kind in type(held).__mro__:
        for name in getattr(kind, "__slots__", ()):
            if name not in ("__dict__", "__weakref__") and hasattr(held, name):
                found[name] = getattr(held, name)
    return found


def _members(value: object) -> Iterator[object]:
    if isinstance(value, dict):
        yield from value.values()
    elif isinstance(value, (list, tuple, set, frozenset)):
        yield from value
    elif isinstance(value, types.MethodType):
        yield value.__self__
    elif isinstance(value, functools.partial):
        yield value.func
        yield from value.args
        yield from value.keywords.values()
    elif _ours(value):
        yield from _attributes(value).values()


def walk(root: object) -> list[object]:
    """Every cipstack object reachable from ``root`` through attributes, containers and bound methods."""
    seen: set[int] = set()
    found: list[object] = []
    stack = [root]
    while stack:
        value = stack.pop()
        if id(value) in seen or isinstance(value, (str, bytes, int, float, type, types.ModuleType)):
            continue
        seen.add(id(value))
        if _ours(value):
            found.append(value)
        stack.extend(_members(value))
    return found


def _same(before: object, now: object) -> bool:
    # A bound method is a new object at each attribute read: the same method of the same object is equal.
    return before is now or (isinstance(now, types.MethodType) and before == now)


def _defined_in(hook: object, *places: Path) -> bool:
    code = getattr(getattr(hook, "__func__", hook), "__code__", None)
    return code is not None and any(Path(code.co_filename).is_relative_to(place) for place in places)


@pytest.fixture(params=["bare", "every port", "mx2", "eds", "security"])
async def adapter(request: pytest.FixtureRequest, tmp_path: Path) -> Any:
    """An adapter on free ports: the ACG as ``cipstack adapter`` runs by default, or with every port its
    family has (Modbus TCP, Modbus-RTU on a pseudo-terminal) and a state file; an Omron MX2 with its
    CompoNet option board; a device emulated from an EDS file."""
    settings = AdapterSettings(host="127.0.0.1", port=0, io_port=0)
    device = None
    if request.param == "mx2":
        settings = AdapterSettings(host="127.0.0.1", port=0, io_port=0, profile="mx2")
    elif request.param == "security":   # CIP Security's objects, their endpoint and the --secure-only filter
        settings = AdapterSettings(host="127.0.0.1", port=0, io_port=0, security_port=0, security_objects=True,
                                   secure_only=True, state_path=tmp_path / "state.json")
    elif request.param == "every port":
        settings = AdapterSettings(host="127.0.0.1", port=0, io_port=0, modbus_port=0, rtu="pty",
                                   state_path=tmp_path / "state.json")
    constructions = Constructions()
    previous = sys.getprofile()
    sys.setprofile(constructions)
    try:
        if request.param == "eds":
            device = build_eds_device(read_eds(EDS_FILE))
        made = Adapter(settings, device)
        await made.start()
    finally:
        sys.setprofile(previous)
    try:
        yield made, constructions
    finally:
        await made.close()


async def test_every_collaborator_is_the_one_given_at_construction(adapter: Any) -> None:
    running, constructions = adapter
    objects = walk(running)
    assert len(objects) > 100   # the device, its objects, its ports, the runtime, the faults...
    later = []
    for held in objects:
        before = constructions.at_construction(held)
        if before is None:
            continue   # made before the adapter (a shared declaration), or by no __init__ of ours
        kind = type(held).__name__
        for name, now in _attributes(held).items():
            if not _collaborator(now) or (kind, name) in TAKEN_AT_START | BUILT_IN_STEPS:
                continue
            if name not in before or not _same(before[name], now):
                later.append(f"{kind}.{name}: {before.get(name)!r} at construction, {now!r} after start")
    assert not later, "\n".join(later)


async def test_the_class1_hooks_are_the_methods_of_what_serves_them(adapter: Any) -> None:
    running, constructions = adapter
    io, seam, endpoint = running.io, running.io_seam, running.io_endpoint
    assert io is not None and seam is not None and endpoint is not None
    assert endpoint.core is seam and seam.core is io and running.target.class1 is io
    assert io.changed == endpoint.wakeup
    assert io.deliver == running.device.assembly.deliver
    assert io.tick == running.clock.tick
    assert seam.send_later == endpoint.send_later
    assert running.faults.runtime.class1 is seam
    for hook in (io.changed, io.deliver, io.tick, seam.send_later):
        assert constructions.at_construction(hook.__self__) is not None   # made with the adapter
    # No hook anywhere is a lambda or a nested function of the adapter or the runtime filled in later.
    composition = (PACKAGE / "adapter.py", PACKAGE / "runtime")
    for held in walk(running):
        for name, value in _attributes(held).items():
            if isinstance(value, types.FunctionType) and _defined_in(value, *composition):
                before = constructions.at_construction(held)
                assert before is not None and before.get(name) is value, f"{type(held).__name__}.{name}"
