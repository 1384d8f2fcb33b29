"""Mission scenarios and their replay on the core (docs/mission.md, docs/semantics.md §5).

A scenario is a TOML file of timed steps; each step is a model transition of
one skillset (``transition = "teleop.start"``: an operator command, an event
or a skill outcome) or an operator *considering* a command without issuing it
(``consider = "arm_ready.start"``), which shows whether SkiNet warns about it.
A transition step the model does not allow at that moment is a model divergence
(docs/semantics.md §7); a scenario that plays one on purpose (a conformance test, a faulty
robot) says so with ``expect_divergence = true`` on the step.
For a skillset bound to plain ROS 2 interfaces (docs/semantics.md §9), ``message = {...}``
gives the fields of the message that causes the step (a goal's inputs or result,
a topic sample), and ``[scenario] topics`` the first sample of each bound topic.
``[scenario] pilot = "dock.toml"`` names a goals file (:mod:`skinet.plan.goalfile`)
that the pilot drives after the steps (docs/semantics.md §8), when the run goes through the
whole chain (``skinet demo``).
The simulator of issue 5 plays the same files through the whole chain.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, TypeVar

from skinet.errors import SourceError
from skinet.system.live import LiveSystem
from skinet.props.evaluate import holds
from skinet.system.model import System
from skinet.files.toml import check_keys, check_tables, locate, parse_toml
from skinet.verify.algorithm1 import Analysis, UnsafeTransition, analyse
from skinet.verify.predict import forecast


T = TypeVar("T")


@dataclass(frozen=True)
class Step:
    t: float
    skillset: str
    transition: str | None = None
    consider: str | None = None
    note: str = ""
    expect_divergence: bool = False  # the model is expected not to explain this step
    message: Mapping[str, Any] | None = field(default=None, compare=False)  # on a bound interface (docs/semantics.md §9): the
    # fields of the message that causes the step


@dataclass(frozen=True)
class Scenario:
    name: str
    system: str  # path of the system file, relative to the scenario file
    steps: tuple[Step, ...]
    text: str = field(default="", compare=False, repr=False)  # the file's text, to locate errors in it
    # bound skillsets (docs/semantics.md §9): the first sample the simulated robot publishes on each bound topic
    topics: Mapping[str, Mapping[str, Any]] = field(default_factory=dict, compare=False)
    pilot: str = ""  # a goals file (relative to the scenario file) the pilot drives after the steps; '' for none


@dataclass
class StepRecord:
    """What the operator would have seen after (or before, for ``consider``) one step."""

    index: int
    step: Step
    holds: dict[str, bool]
    violations: list[str] = field(default_factory=list)  # properties that became false here
    warnings: list[UnsafeTransition] = field(default_factory=list)  # flags on the considered command
    unsafe_count: int = 0  # operator-view unsafe transitions after the step
    divergence: str | None = None
    flagged: list[UnsafeTransition] = field(default_factory=list)  # flags the issued command had when issued
    recovery: dict[str, list[str]] = field(default_factory=dict)  # violated property -> recovery transitions


SCENARIO_TABLES = ("[scenario]", "[[steps]]")
SCENARIO_KEYS = ("name", "system", "topics", "pilot")
STEP_KEYS = ("t", "skillset", "transition", "consider", "note", "expect_divergence", "message")


def parse_scenario(text: str, source: str = "<scenario>") -> Scenario:
    """Parse a scenario file; errors name the file, the position and the step number.

    Strict: an unknown table or key is an error with the close names.
    """
    data = parse_toml(text, source)
    check_tables(data, SCENARIO_TABLES, source, text)
    head = data.get("scenario", {})
    if not isinstance(head, dict) or not all(isinstance(head.get(k), str) for k in ("name", "system")):
        raise SourceError.at(source, locate(text, ("scenario",)),
                             "missing [scenario] table with 'name' and 'system' strings")
    check_keys(head, SCENARIO_KEYS, source, text, ("scenario",), "[scenario]")
    entries = data.get("steps", [])
    if not isinstance(entries, list):
        raise SourceError.at(source, locate(text, (), "steps"), "'steps' must be [[steps]] tables")
    steps = []
    last = 0.0
    for n, s in enumerate(entries, 1):
        table = ("steps", n - 1)
        if not isinstance(s, dict) or not isinstance(s.get("skillset"), str):
            raise SourceError.at(source, locate(text, table, "skillset") or locate(text, table),
                                 f"step {n}: needs a 'skillset' string")
        check_keys(s, STEP_KEYS, source, text, table, f"step {n}")
        if (s.get("transition") is None) == (s.get("consider") is None):
            raise SourceError.at(source, locate(text, table),
                                 f"step {n}: give exactly one of 'transition' or 'consider'")
        if not isinstance(s.get("transition", s.get("consider")), str):
            key = "transition" if "transition" in s else "consider"
            raise SourceError.at(source, locate(text, table, key), f"step {n}: '{key}' must be a string")
        t = s.get("t", last)
        if isinstance(t, bool) or not isinstance(t, (int, float)) or t != t:
            raise SourceError.at(source, locate(text, table, "t"),
                                 f"step {n}: 't' must be a number of seconds, got {t!r}")
        t = float(t)
        if t < last:
            raise SourceError.at(source, locate(text, table, "t"),
                                 f"step {n}: time {t} goes backwards (previous step at {last})")
        last = t
        expect = s.get("expect_divergence", False)
        if not isinstance(expect, bool):
            raise SourceError.at(source, locate(text, table, "expect_divergence"),
                                 f"step {n}: 'expect_divergence' must be true or false, got {expect!r}")
        if expect and s.get("transition") is None:
            raise SourceError.at(source, locate(text, table, "expect_divergence"),
                                 f"step {n}: 'expect_divergence' needs a 'transition' (a considered command is "
                                 "not played)")
        message = s.get("message")
        if message is not None and not isinstance(message, dict):
            raise SourceError.at(source, locate(text, table, "message"),
                                 f"step {n}: 'message' must be a table of message fields")
        steps.append(Step(t, s["skillset"], s.get("transition"), s.get("consider"), str(s.get("note", "")), expect,
                          message))
    topics = head.get("topics", {})
    if not isinstance(topics, dict) or not all(isinstance(v, dict) for v in topics.values()):
        raise SourceError.at(source, locate(text, ("scenario",), "topics"),
                             "[scenario] 'topics' must map topic names to tables of message fields")
    pilot = head.get("pilot", "")
    if not isinstance(pilot, str):
        raise SourceError.at(source, locate(text, ("scenario",), "pilot"),
                             "[scenario] 'pilot' must be the path of a goals file (relative to the scenario)")
    return Scenario(head["name"], head["system"], tuple(steps), text, topics, pilot)


def step_numbers(scenario: Scenario) -> list[int]:
    """The step number of each scenario entry, as the live monitor counts steps.

    Transitions are steps 1, 2, ...; a considered command is weighed at the
    marking before the next step, so it takes that step's number (``skinet run``
    beside the simulator and ``skinet demo`` then show the same numbers).
    """
    numbers, done = [], 0
    for step in scenario.steps:
        if step.transition is not None:
            done += 1
        numbers.append(done if step.transition is not None else done + 1)
    return numbers


def check_scenario(scenario: Scenario, system: System, source: str = "<scenario>") -> None:
    """Every step names a skillset of ``system`` and one of its transitions; else one error naming the step.

    (A transition that is not enabled when its step comes is not an error: the
    live monitor reports it as a model divergence.)
    """
    components = {c.name: c for c in system.components}
    for n, step in enumerate(scenario.steps, 1):
        comp = components.get(step.skillset)
        if comp is None:
            raise SourceError.at(source, locate(scenario.text, ("steps", n - 1), "skillset"),
                                 f"step {n}: unknown skillset '{step.skillset}' "
                                 f"(skillsets of {system.name}: {', '.join(components)})")
        name = step.transition if step.transition is not None else step.consider
        known = list(dict.fromkeys(t.name for t in comp.net.transitions))
        if name not in known:
            key = "transition" if step.transition is not None else "consider"
            hint = [k for k in known if k.split(".")[0] == name.split(".")[0]] or known
            raise SourceError.at(source, locate(scenario.text, ("steps", n - 1), key),
                                 f"step {n}: unknown {key} '{name}' of skillset '{step.skillset}' "
                                 f"(for example: {', '.join(hint[:6])})")


def replay(system: System, scenario: Scenario, predict: bool = True, budget: float = 5.0) -> list[StepRecord]:
    """Play ``scenario`` on the live nets, running Algorithm 1 after every step."""
    live = LiveSystem(system)
    nets = system.nets

    def analysis() -> Analysis:
        return analyse(system, live.marking, forecast(system, live.marking, budget=budget) if predict else None)

    before = {p.name: holds(p.expr, live.marking, nets) for p in system.properties}
    current = analysis()
    records = []
    for i, step in zip(step_numbers(scenario), scenario.steps):
        if step.consider is not None:
            flags = flags_on(current.operator_unsafe(), step.skillset, step.consider)
            records.append(StepRecord(i, step, dict(before), [], flags, len(current.operator_unsafe())))
            continue
        issued = flags_on(current.operator_unsafe(), step.skillset, step.transition or "")
        outcome = live.apply(step.skillset, step.transition)
        now = {p.name: holds(p.expr, live.marking, nets) for p in system.properties}
        newly = [p for p, ok in now.items() if before[p] and not ok]
        current = analysis()
        recovery = {p: [f"{r.skillset}:{r.transition}" for r in rs] for p, rs in current.recovery.items()}
        records.append(StepRecord(i, step, now, newly, [], len(current.operator_unsafe()), outcome.divergence,
                                  issued, recovery))
        before = now
    return records


def flags_on(unsafe: Iterable[T], skillset: str, transition: str) -> list[T]:
    """The entries of ``unsafe`` about ``skillset:transition``."""
    return [u for u in unsafe if u.skillset == skillset and u.transition == transition]  # type: ignore[attr-defined]


def flagged_before(records: Sequence[StepRecord], index: int, prop: str) -> tuple[int, UnsafeTransition] | None:
    """The first flag for ``prop`` of the unbroken run of flagged steps that ends in step ``index``.

    Preferably an operator command (controllable): the outcome that violated the
    property may itself be flagged only because the command before it was.
    """
    run: list[tuple[int, UnsafeTransition]] = []
    upto = next(n for n, r in enumerate(records) if r.index == index and r.step.transition is not None) + 1
    for r in reversed(records[:upto]):
        if r.step.transition is None:
            continue
        flags = [u for u in r.flagged if u.property == prop]
        if not flags:
            break
        run.append((r.index, flags[0]))
    commands = [f for f in run if f[1].controllable]
    return (commands or run or [None])[-1]


__all__ = ["Scenario", "Step", "StepRecord", "check_scenario", "flagged_before", "flags_on", "parse_scenario", "replay",
           "step_numbers"]
