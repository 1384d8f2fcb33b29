"""Pilot runs: a mission handed to the pilot, and the skill outcomes a simulated robot gives it.

A *pilot run* file (issue 24, the demo's third run) names a system, a goals file
(:mod:`skinet.plan.goalfile`) and the mode the pilot follows it in (docs/semantics.md §8,
*The pilot*), and declares the failures the simulated skills inject on the way::

    [pilot]
    name = "pilot"
    system = "../spot_arm.toml"           # relative to this file
    goals = "../goals/paper_mission.toml"
    mode = "drive"                        # or "guide"
    seed = 0                              # for failure_rate
    failure_rate = 0.0                    # other runs: a failure with this probability

    [[failures]]                          # the 1st run of arm_ready ends in failure mode blocked
    skill = "manipulator:arm_ready"
    run = 1
    mode = "blocked"

:class:`Outcomes` decides how each run of each skill ends: a run declared in
``[[failures]]`` in its failure mode; any other in the skill's first success mode,
or, with ``failure_rate`` p > 0, in one of its failure modes with probability p,
drawn from a generator seeded with ``seed``: the same file gives the same outcomes
in the same order of starts, run after run.  Pure; parsing is linear in the text,
an outcome O(1).
"""

from __future__ import annotations

import random
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Literal

from skinet.errors import SourceError
from skinet.lang.model import Skill
from skinet.system.model import System
from skinet.files.toml import check_keys, check_tables, locate, parse_toml

HEAD_KEYS = ("name", "system", "goals", "mode", "seed", "failure_rate")
FAILURE_KEYS = ("skill", "run", "mode")
MODES = ("guide", "drive")


@dataclass(frozen=True)
class Failure:
    """The ``run``-th start (from 1) of ``skillset:skill`` ends in its failure mode ``mode``."""

    skillset: str
    skill: str
    run: int
    mode: str


@dataclass(frozen=True)
class PilotRun:
    name: str
    system: str  # path of the system file, relative to the run file
    goals: str  # path of the goals file, relative to the run file
    mode: Literal["guide", "drive"] = "drive"
    failures: tuple[Failure, ...] = ()
    seed: int = 0
    failure_rate: float = 0.0
    text: str = field(default="", compare=False, repr=False)


def is_pilot_run(text: str) -> bool:
    """Whether a TOML text (a scenario or a pilot run) is a pilot run: it has a ``[pilot]`` table."""
    return any(line.strip().startswith("[pilot]") for line in text.splitlines())


def parse_pilot_run(text: str, source: str = "<pilot run>") -> PilotRun:
    """Parse a pilot run file; errors carry the file, line and column.  Skill names are checked by
    :func:`check_pilot_run` once the system is loaded."""
    data = parse_toml(text, source)
    check_tables(data, ["[pilot]", "[[failures]]"], source, text)
    head = data.get("pilot")
    if not isinstance(head, dict) or not all(isinstance(head.get(k), str) for k in ("name", "system", "goals")):
        raise SourceError.at(source, locate(text, ("pilot",)),
                             "missing [pilot] table with 'name', 'system' and 'goals' strings")
    check_keys(head, HEAD_KEYS, source, text, ("pilot",), "[pilot]")
    mode = head.get("mode", "drive")
    if mode not in MODES:
        raise SourceError.at(source, locate(text, ("pilot",), "mode"), f"mode must be 'guide' or 'drive', got {mode!r}")
    seed = head.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise SourceError.at(source, locate(text, ("pilot",), "seed"), f"seed must be an integer, got {seed!r}")
    rate = head.get("failure_rate", 0.0)
    if isinstance(rate, bool) or not isinstance(rate, (int, float)) or not 0.0 <= rate <= 1.0:
        raise SourceError.at(source, locate(text, ("pilot",), "failure_rate"),
                             f"failure_rate must be a probability between 0 and 1, got {rate!r}")
    entries = data.get("failures", [])
    if not isinstance(entries, list):
        raise SourceError.at(source, locate(text, ("failures",)) or locate(text, (), "failures"),
                             "'failures' must be [[failures]] tables")
    failures = []
    for n, entry in enumerate(entries):
        table = ("failures", n)
        if not isinstance(entry, dict):
            raise SourceError.at(source, locate(text, (), "failures"), "'failures' must be [[failures]] tables")
        check_keys(entry, FAILURE_KEYS, source, text, table, "[[failures]]")
        skill, run, fmode = entry.get("skill"), entry.get("run", 1), entry.get("mode")
        if not isinstance(skill, str) or skill.count(":") != 1:
            raise SourceError.at(source, locate(text, table, "skill") or locate(text, table),
                                 f"failure {n + 1}: skill must be \"SKILLSET:SKILL\", got {skill!r}")
        if isinstance(run, bool) or not isinstance(run, int) or run < 1:
            raise SourceError.at(source, locate(text, table, "run"),
                                 f"failure {n + 1}: run must be a start number from 1, got {run!r}")
        if not isinstance(fmode, str):
            raise SourceError.at(source, locate(text, table, "mode") or locate(text, table),
                                 f"failure {n + 1}: needs mode = \"FAILURE_MODE\" (a failure mode of the skill)")
        skillset, name = skill.split(":")
        if any((f.skillset, f.skill, f.run) == (skillset, name, run) for f in failures):
            raise SourceError.at(source, locate(text, table, "run") or locate(text, table),
                                 f"failure {n + 1}: run {run} of {skill} is already declared")
        failures.append(Failure(skillset, name, run, fmode))
    return PilotRun(head["name"], head["system"], head["goals"], mode, tuple(failures), seed, float(rate), text)


def check_pilot_run(run: PilotRun, system: System, source: str = "<pilot run>") -> None:
    """Every failure names a skill of ``system`` and one of its failure modes; else one error at it."""
    for n, f in enumerate(run.failures):
        where = locate(run.text, ("failures", n), "skill")
        comps = {c.name: c for c in system.components}
        if f.skillset not in comps:
            raise SourceError.at(source, where, f"failure {n + 1}: unknown skillset '{f.skillset}' "
                                                f"(skillsets of {system.name}: {', '.join(comps)})")
        skills = {k.name: k for k in comps[f.skillset].skillset.skills}
        if f.skill not in skills:
            raise SourceError.at(source, where, f"failure {n + 1}: unknown skill '{f.skill}' of skillset "
                                                f"'{f.skillset}' (skills: {', '.join(skills)})")
        modes = _modes(skills[f.skill], "failure")
        if f.mode not in modes:
            raise SourceError.at(source, locate(run.text, ("failures", n), "mode"),
                                 f"failure {n + 1}: '{f.mode}' is not a failure mode of {f.skillset}:{f.skill} "
                                 f"(failure modes: {', '.join(modes) or 'none'})")


class Outcomes:
    """How each run of each skill ends (the module docstring); one instance per robot run."""

    def __init__(self, system: System, failures: Iterable[Failure] = (), *, failure_rate: float = 0.0,
                 seed: int = 0):
        self._skills: Mapping[tuple[str, str], Skill] = {
            (c.name, k.name): k for c in system.components for k in c.skillset.skills}
        self._failures = {(f.skillset, f.skill, f.run): f.mode for f in failures}
        self.failure_rate = failure_rate
        self._random = random.Random(seed)
        self.runs: dict[tuple[str, str], int] = {}  # (skillset, skill) -> starts so far
        self.failed: list[tuple[str, str, int, str]] = []  # (skillset, skill, run, mode) in the order decided

    @classmethod
    def of(cls, run: PilotRun, system: System) -> Outcomes:
        return cls(system, run.failures, failure_rate=run.failure_rate, seed=run.seed)

    def outcome(self, skillset: str, skill: str) -> tuple[str, str]:
        """The next run of ``skillset:skill`` starts: ``("success" | "failure", mode)`` it ends in."""
        k = self._skills[(skillset, skill)]
        n = self.runs[(skillset, skill)] = self.runs.get((skillset, skill), 0) + 1
        mode = self._failures.get((skillset, skill, n))
        failures = _modes(k, "failure")
        if mode is None and failures and self.failure_rate > 0 and self._random.random() < self.failure_rate:
            mode = failures[self._random.randrange(len(failures))]
        if mode is not None:
            self.failed.append((skillset, skill, n, mode))
            return "failure", mode
        successes = _modes(k, "success")
        return ("success", successes[0]) if successes else ("failure", failures[0])


def _modes(skill: Skill, kind: str) -> list[str]:
    return [m.name for m in skill.modes if m.kind == kind]


__all__ = ["Failure", "Outcomes", "PilotRun", "check_pilot_run", "is_pilot_run", "parse_pilot_run"]
