"""Scenarios: a timeline of faults and device actions, at times or on events, from a TOML file
(``cipstack adapter --scenario FILE.toml``).

Each ``[[step]]`` waits for its trigger, then does one thing:

* trigger: ``at = "2s"`` (after the scenario starts), or ``on = "KIND"`` (the next event of that
  kind after the previous step fired: ``connection opened`` is a Forward_Open accepted, ``run``, ``idle``,
  ``connection timed out``, ``trip``, ``parameter write``...; see ``cipstack.control.events``), or
  ``on = "frequency"`` with ``hz = 30`` (the drive's output frequency reaches it); ``after = "0.5s"``
  waits that much more; ``within = "10s"`` is how long the trigger may take (default 30 s).
* action, at most one, each an operation of the command service declared as a step
  (``cipstack.control.operations``, ``StepKind``): ``fault = "NAME"`` with ``options = {...}`` (as
  ``cipstack drive fault`` takes them), ``clear = true`` (every fault; or ``clear = "NAME"``),
  ``trip = "0x4200"``, ``reset = true``, ``power = "cycle"`` with ``off = "2s"``, ``link = "unplug"``
  or ``"plug"``. A step with ``on = "KIND"`` and no action waits for that event (a wait-for step).
* ``repeat = N``: the step N times in a row (each waits for its own trigger).

Steps run in order; a step whose trigger does not come in time ends the scenario. A top-level
``linger = "1s"`` keeps the device serving that long after the last step (the clients finish). Each step fired or
missed is one line, with its time since the start, handed to ``report``; ``run`` returns whether every
step fired. At the end every fault still active is cleared: nothing of a scenario outlives it.
"""

from __future__ import annotations

import asyncio
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import BadRequest
from ..faults import FaultError
from ..faults.model import parse_duration, shown
from .events import EVENT_KINDS
from .operations import OPERATIONS, Operation, StepKind

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

if TYPE_CHECKING:
    from .service import DeviceService

DEFAULT_WITHIN = 30.0
#: The highest output frequency a step may wait for: well above any emulated drive's maximum frequency.
MAX_HZ = 1000.0
#: The keys of a step that say when it fires, how often, and its name.
_TRIGGER_KEYS = ("at", "on", "hz", "after", "within", "repeat", "name")
#: The step kinds by their key, and the keys of their other arguments: from the operations' declarations.
STEP_KINDS: dict[str, Operation] = {op.step.key: op for op in OPERATIONS if op.step is not None}
_ARGUMENT_KEYS: dict[str, str] = {a.key: key for key, op in STEP_KINDS.items() for a in op.arguments[1:]}
_STEP_KEYS = {*_TRIGGER_KEYS, *STEP_KINDS, *_ARGUMENT_KEYS}


class ScenarioError(BadRequest):
    """A scenario file that cannot be run (one line naming the file and the step)."""


@dataclass(frozen=True)
class Action:
    """What a step does: an operation of the command service with its JSON arguments, checked when the
    file is read, and how the step's line says it."""

    operation: Operation
    arguments: dict[str, Any]
    record: Any
    words: str

    @property
    def kind(self) -> StepKind:
        assert self.operation.step is not None
        return self.operation.step


@dataclass(frozen=True)
class Step:
    number: int
    name: str
    at: float | None = None
    on: str | None = None
    hz: float | None = None
    after: float = 0.0
    within: float = DEFAULT_WITHIN
    #: None: a wait-for step (it fires when its event comes, and does nothing more).
    action: Action | None = None
    repeat: int = 1

    def describe(self) -> str:
        what = self.action.words if self.action is not None else "wait"
        when = (f"at {self.at:g}s" if self.at is not None else
                f"on frequency {self.hz:g} Hz" if self.on == "frequency" else f"on {self.on}")
        return f"{what} ({when}{f' + {self.after:g}s' if self.after else ''})"


@dataclass
class Scenario:
    path: Path
    steps: list[Step] = field(default_factory=list)
    #: How long the device goes on serving after the last step fired.
    linger: float = 0.0

    def check(self, service: DeviceService) -> None:
        """What only the device can tell, checked before it serves (each ``trip`` step's code is one of
        its trip codes; a step the device's declaration lacks is refused): ``ScenarioError`` naming the
        step."""
        for step in self.steps:
            action = step.action
            if action is None:
                continue
            first = next(iter(action.arguments.values()), None)
            said = f"{action.kind.key}" + (f" {shown(first)}" if first is not None else "")
            try:
                service.refuse_absent(action.operation)
                if action.kind.on_device is not None:
                    action.kind.on_device(service, action.record)
            except BadRequest as exc:
                raise ScenarioError(f"{self.path}: step {step.number}: {said}: {exc}") from None


def load(path: str | Path) -> Scenario:
    path = Path(path)
    try:
        document = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ScenarioError(f"{path}: {exc.strerror or exc}") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ScenarioError(f"{path}: not TOML: {exc}") from None
    except RecursionError:
        raise ScenarioError(f"{path}: not TOML a scenario can be: it nests too deeply") from None
    unknown = set(document) - {"step", "linger"}
    if unknown:
        raise ScenarioError(f"{path}: unknown table or key {sorted(unknown)[0]!r} (a scenario is [[step]] tables "
                            "and linger)")
    try:
        linger = parse_duration(document.get("linger", 0))
    except FaultError as exc:
        raise ScenarioError(f"{path}: linger: {exc}") from None
    raw_steps = document.get("step")
    if not isinstance(raw_steps, list) or not raw_steps:
        raise ScenarioError(f"{path}: no [[step]]")
    return Scenario(path, [_step(path, index, raw) for index, raw in enumerate(raw_steps, start=1)], linger)


def _step(path: Path, number: int, raw: Any) -> Step:
    where = f"{path}: step {number}"
    if not isinstance(raw, dict):
        raise ScenarioError(f"{where}: not a table")
    unknown = set(raw) - _STEP_KEYS
    if unknown:
        raise ScenarioError(f"{where}: unknown key {sorted(unknown)[0]!r}; valid: {', '.join(sorted(_STEP_KEYS))}")
    try:
        at = parse_duration(raw["at"]) if "at" in raw else None
        after = parse_duration(raw.get("after", 0))
        within = parse_duration(raw.get("within", DEFAULT_WITHIN))
        on = raw.get("on")
        if (at is None) == (on is None):
            raise ScenarioError(f"{where}: one trigger, at = TIME or on = EVENT")
        if on is not None and (not isinstance(on, str) or on not in (*EVENT_KINDS, "frequency")):
            raise ScenarioError(f"{where}: on = {shown(on)} is no event kind; valid: {', '.join(EVENT_KINDS)}, "
                                "frequency")
        hz = raw.get("hz")
        if (on == "frequency") != (hz is not None) or (hz is not None and (
                isinstance(hz, bool) or not isinstance(hz, (int, float)) or not 0 <= hz <= MAX_HZ)):
            raise ScenarioError(f"{where}: on = \"frequency\" goes with hz = a number 0..{MAX_HZ:g}")
        action = _action(where, raw)
        if action is None and on is None:
            raise ScenarioError(f"{where}: one action ({_ACTIONS}), or none with on = EVENT to wait for it")
        repeat = raw.get("repeat", 1)
        if not isinstance(repeat, int) or isinstance(repeat, bool) or not 1 <= repeat <= 1000:
            raise ScenarioError(f"{where}: repeat is a whole number 1..1000")
    except ScenarioError:
        raise
    except (FaultError, BadRequest) as exc:   # a step's own check (``StepKind.check``) refused its arguments
        raise ScenarioError(f"{where}: {exc}") from None
    return Step(number, str(raw.get("name", f"step {number}")), at, on, float(hz) if hz is not None else None,
                after, within, action, repeat)


def _spelled(op: Operation) -> str:
    """How a step kind is written: ``fault = NAME``, ``clear = true or ID|NAME``, ``reset = true``."""
    if not op.arguments:
        return f"{op.step.key if op.step else op.name} = true"
    first = op.arguments[0]
    value = first.metavar or first.key.upper()
    return f"{op.step.key if op.step else op.name} = {value if first.required else 'true or ' + value}"


#: Every action a step may take, as an error message lists them.
_ACTIONS = ", ".join(_spelled(op) for op in STEP_KINDS.values())


def _action(where: str, raw: dict[str, Any]) -> Action | None:
    """The step's action, from the declaration of the operation its key names; None for none."""
    keys = [key for key in STEP_KINDS if key in raw]
    if len(keys) > 1:
        raise ScenarioError(f"{where}: one action, not {' and '.join(keys)}")
    stray = sorted(k for k in raw if k in _ARGUMENT_KEYS and (not keys or _ARGUMENT_KEYS[k] != keys[0]))
    if stray:
        raise ScenarioError(f"{where}: {stray[0]} goes with {_ARGUMENT_KEYS[stray[0]]} = ...")
    if not keys:
        return None
    key = keys[0]
    operation = STEP_KINDS[key]
    value = raw[key]
    arguments: dict[str, Any] = {a.key: raw[a.key] for a in operation.arguments[1:] if a.key in raw}
    first = operation.arguments[0] if operation.arguments else None
    if value is True and (first is None or not first.required):
        pass
    elif first is None or isinstance(value, bool):
        raise ScenarioError(f"{where}: {key} is written {_spelled(operation)}")
    else:
        arguments = {first.key: value, **arguments}
    from .service import check_arguments

    try:
        check_arguments(operation, arguments)
    except BadRequest as exc:      # its message names the operation: "trip: \"code\" is a string or integer"
        raise ScenarioError(f"{where}: {exc}") from None
    record = operation.record(**arguments)
    kind = operation.step
    assert kind is not None
    words = kind.check(record) if kind.check is not None else ""
    for argument in operation.arguments:
        given = arguments.get(argument.key)
        if given is not None and argument.choices is not None and given not in argument.choices():
            raise ScenarioError(f"{where}: {key}: {shown(given)} is not one of {', '.join(argument.choices())}")
    if not words:
        words = " ".join([key, *(str(arguments[a.key]) for a in operation.arguments[:1] if a.key in arguments),
                          *(f"--{a.key} {arguments[a.key]}" for a in operation.arguments[1:] if a.key in arguments)])
    return Action(operation, arguments, record, words)


async def run(service: DeviceService, scenario: Scenario, report: Callable[[str], None]) -> bool:
    """Run the steps on the device of ``service`` (its command service, as every surface); True when
    every one fired. Each step's line carries the time it fired, not the time its ports settled."""
    loop = asyncio.get_running_loop()
    events = service.events
    events.start()
    start = loop.time()
    mark = events.events[-1].number if events.events else 0
    fired_all = True
    #: Every step's label, in order; those fired are taken off the front.
    waiting = [step.name + (f" ({round_}/{step.repeat})" if step.repeat > 1 else "")
               for step in scenario.steps for round_ in range(1, step.repeat + 1)]
    interrupted = False
    total = len(waiting)

    def line(text: str, at: float | None = None) -> None:
        report(f"{(loop.time() if at is None else at) - start:8.3f}s  {text}")

    def progress(state: str) -> None:
        # What ``status`` (and the front panel) shows of the scenario: steps fired, the one awaited.
        service.scenario = {"file": scenario.path.name, "state": state, "steps": total,
                            "fired": total - len(waiting), "next": waiting[0] if waiting else None}

    line(f"scenario {scenario.path.name}: {sum(s.repeat for s in scenario.steps)} step(s)")
    progress("running")
    try:
        for step in scenario.steps:
            for round_ in range(1, step.repeat + 1):
                label = step.name + (f" ({round_}/{step.repeat})" if step.repeat > 1 else "")
                try:
                    mark = await _trigger(service, step, start, mark)
                except asyncio.TimeoutError:
                    line(f"{label} did not fire: no {step.describe()} within {step.within:g}s")
                    fired_all = False
                    return False
                if step.after:
                    await asyncio.sleep(step.after)
                fired_at = loop.time()
                try:
                    await _act(service, step)
                except Exception as exc:  # a step refused by the device's state: said, and the scenario ends
                    line(f"{label} failed: {step.describe()}: {exc}", fired_at)
                    fired_all = False
                    return False
                line(f"{label} fired: {step.describe()}", fired_at)
                waiting.pop(0)
                progress("running")
        if scenario.linger:
            await asyncio.sleep(scenario.linger)
        return fired_all
    except asyncio.CancelledError:   # SIGINT or SIGTERM: the emulator stops before the timeline is done
        interrupted = fired_all = True
        raise
    finally:
        if service.faults.active:
            await service.call_async("clear", {})
        await service.faults.settle()
        progress("interrupted" if interrupted and waiting else "complete" if fired_all else "incomplete")
        if interrupted and waiting:
            shown = ", ".join(waiting[:10]) + (f" and {len(waiting) - 10} more" if len(waiting) > 10 else "")
            line(f"scenario interrupted: {len(waiting)} step(s) did not fire ({shown}); no fault left active")
        else:
            line("scenario " + ("complete: every step fired" if fired_all else "incomplete") +
                 "; no fault left active")


async def _trigger(service: DeviceService, step: Step, start: float, mark: int) -> int:
    """Wait for ``step``'s trigger; returns the number of the last event seen (the next step's mark)."""
    loop = asyncio.get_running_loop()
    events = service.events
    if step.at is not None:
        await asyncio.sleep(max(0.0, start + step.at - loop.time()))
        return events.events[-1].number if events.events else mark
    if step.on == "frequency":
        async def reached() -> None:
            while True:
                fields = service.status().get("drive") or {}
                if float(fields.get("output_frequency_hz") or 0.0) >= (step.hz or 0.0):
                    return
                await asyncio.sleep(0.01)
        await asyncio.wait_for(reached(), step.within)
        return events.events[-1].number if events.events else mark
    event = await events.wait_for(step.on or "", step.within, after=mark)
    return event.number


async def _act(service: DeviceService, step: Step) -> None:
    """The step's action, through the command service (a fault waits for its ports, not for a long off);
    nothing for a wait-for step, whose trigger was all of it."""
    if step.action is not None:
        await service.call_async(step.action.operation.name, step.action.arguments)
