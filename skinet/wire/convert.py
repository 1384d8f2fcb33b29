"""Conversions between core objects and wire messages (docs/semantics.md §1, §5, §6).

The predictor answers with the *risks* of the markings one step away from the
live marking (what Algorithm 1 needs); :class:`RiskTable` turns them back into
the :class:`~skinet.verify.algorithm1.Prediction` the monitor feeds Algorithm 1.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import PurePath
from collections.abc import Iterable, Mapping
from functools import lru_cache
from typing import Any

from skinet.errors import SkinetError, SourceError
from skinet.net.semantics import steps
from skinet.system.prediction import PredictionOptions, PropertyOptions
from skinet.plan.policy import Step
from skinet.props.evaluate import holds
from skinet.system.model import Marking, System, build_system, marking_from_json, marking_to_json
from skinet.lang.parser import parse_model, parse_skillset
from skinet.verify.algorithm1 import Analysis, PredictionVerdict
from skinet.verify.predict import Forecast
from skinet.wire.messages import (
    MissedOutcome, ModelBundle, PlanBranch, PlanStep, PredictRequest, PropertyVerdict, RecoveryEntry, Risk, SkillsetStatus,
    StateSpaceReport, UnsafeEntry,
)


def statuses(system: System, marking: Mapping[str, int]) -> dict[str, SkillsetStatus]:
    return {k: SkillsetStatus(**v) for k, v in marking_to_json(system, marking).items()}


def marking_of(system: System, skillsets: Mapping[str, SkillsetStatus], source: str = "<message>") -> Marking:
    """Raises :class:`~skinet.errors.SourceError` on unknown names."""
    return marking_from_json(system, {k: v.model_dump() for k, v in skillsets.items()}, source)


def bundle(system: System) -> ModelBundle:
    """Every source of ``system`` with its content digest (sha256 of canonical JSON).

    An entry is named by its file, plus ``#skillset`` when the file declares
    several skillsets (so the predictor takes the right one).
    """
    entries = []
    files = set()
    for c in system.components:
        file = PurePath(c.skillset.source).name
        text = system.sources.get(file, "")
        files.add(file)
        name = f"{file}#{c.name}" if _declares_several(text) else file
        entries.append((name, text, c.manager))
    props_name = next((n for n in system.sources if n not in files), "properties")
    props = system.sources.get(props_name, "")
    commanded = {c.name: sorted(c.commanded) for c in system.components if c.commanded}
    digest = _digest(system.name, entries, props_name, props, commanded)
    return ModelBundle(system=system.name, digest=digest, skillsets=entries, properties=props,
                       properties_name=props_name, commanded=commanded)


def bundle_digest(b: ModelBundle) -> str:
    """The digest ``b``'s sources hash to, computed without parsing them (cost: one sha256)."""
    return _digest(b.system, [tuple(e) for e in b.skillsets], b.properties_name, b.properties, b.commanded)


def _digest(name: str, entries: list[tuple[str, str, str]], props_name: str, props: str,
            commanded: Mapping[str, list[str]]) -> str:
    # Commanded events only when there are some: the digests of systems without bindings stay as they were.
    parts: list[Any] = [name, entries, props_name, props] + ([dict(sorted(commanded.items()))] if commanded else [])
    canonical = json.dumps(parts, separators=(",", ":"))
    return hashlib.sha256(canonical.encode()).hexdigest()[:32]


@lru_cache(maxsize=64)
def _declares_several(text: str) -> bool:
    try:
        return len(parse_model(text).skillsets) > 1
    except SourceError:
        return False


def system_from_bundle(b: ModelBundle) -> System:
    """Rebuild a system from a bundle (raises SourceError on bad sources)."""
    skillsets = []
    for name, text, manager in b.skillsets:
        file, _, wanted = name.partition("#")
        if not wanted:
            skillsets.append((parse_skillset(text, file), manager))
            continue
        declared = [s for s in parse_model(text, file).skillsets if s.name == wanted]
        if not declared:
            raise SourceError.at(file, None, f"model bundle names skillset '{wanted}', which this file does not declare")
        skillsets.append((declared[0], manager))
    sources = {name.partition("#")[0]: text for name, text, _ in b.skillsets} | {b.properties_name: b.properties}
    commanded = {name: frozenset(events) for name, events in b.commanded.items()}
    for name, events in commanded.items():
        declared = {e.name for ss, _ in skillsets if ss.name == name for e in ss.events}
        unknown = sorted(events - declared) if any(ss.name == name for ss, _ in skillsets) else [f"skillset {name}"]
        if unknown:
            raise SourceError.at("<model bundle>", None, f"commanded events name what skillset '{name}' does not "
                                                         f"declare: {', '.join(unknown)}")
    return build_system(b.system, skillsets, b.properties, b.properties_name, sources, commanded=commanded)


def request_options(system: System, request: PredictRequest) -> PredictionOptions:
    """The prediction options a request asks for (unknown property names are errors)."""
    unknown = sorted(set(request.af) - {p.name for p in system.properties})
    if unknown:
        names = ", ".join(p.name for p in system.properties) or "none"
        raise SkinetError(f"request names unknown property '{unknown[0]}' (properties: {names})")
    return PredictionOptions(overrides={p: PropertyOptions(af=mode) for p, mode in request.af.items()})


def risks(system: System, marking: Mapping[str, int], forecast: Forecast) -> list[Risk]:
    """Non-safe verdicts of every marking one step from ``marking`` (explicit ones excluded)."""
    nets = system.nets
    out: list[Risk] = []
    seen: set[tuple[str, str]] = set()
    for comp in system.components:
        for _t, results in steps(comp.net, marking[comp.name]):
            for m in results:
                after = dict(marking)
                after[comp.name] = m
                key = json.dumps(marking_to_json(system, after), sort_keys=True)
                for p in system.properties:
                    if (key, p.name) in seen or not holds(p.expr, after, nets):
                        continue
                    seen.add((key, p.name))
                    v = forecast.verdict(p.name, after)
                    if v.status != "safe":
                        out.append(Risk(skillsets=statuses(system, after), property=p.name, status=v.status,
                                        af=forecast.risks[p.name].af, steps=v.steps, witness=list(v.witness)))
    return out


def state_space_report(system: System, forecast: Forecast, stamp: float) -> StateSpaceReport:
    s = forecast.space
    return StateSpaceReport(system=system.name, stamp=stamp, time=s.elapsed, timeout_reached=not s.complete,
                            depth=s.expanded_depth, markings=s.markings, edges=s.edges)


class RiskTable:
    """A predictor reply as Algorithm 1's ``Prediction``: unlisted markings are safe."""

    def __init__(self, system: System, entries: Iterable[Risk]):
        self.system = system
        self.table: dict[tuple[str, str], PredictionVerdict] = {}
        for r in entries:
            key = json.dumps({k: v.model_dump() for k, v in r.skillsets.items()}, sort_keys=True)
            self.table[(key, r.property)] = PredictionVerdict(r.status, r.steps, tuple(r.witness))

    def verdict(self, prop: str, marking: Mapping[str, int]) -> PredictionVerdict:
        key = json.dumps(marking_to_json(self.system, marking), sort_keys=True)
        return self.table.get((key, prop), PredictionVerdict("safe"))


def analysis_bodies(
    system: System, analysis: Analysis
) -> tuple[list[PropertyVerdict], list[UnsafeEntry], list[RecoveryEntry]]:
    """Algorithm 1's result as message parts: verdicts, operator-view entries, recovery (docs/semantics.md §5)."""
    props = [PropertyVerdict(name=p.name, holds=p.name not in analysis.violated) for p in system.properties]
    unsafe = [
        UnsafeEntry(skillset=u.skillset, transition=u.transition, kind=u.kind, controllable=u.controllable,
                    property=u.property, constraint=u.constraint, steps=u.steps, witness=list(u.witness),
                    reason=u.reason)
        for u in analysis.operator_unsafe()
    ]
    recovery = [
        RecoveryEntry(property=p, skillset=r.skillset, transition=r.transition, controllable=r.controllable)
        for p, rs in analysis.recovery.items() for r in rs
    ]
    return props, unsafe, recovery


def missed_line(m: MissedOutcome) -> str:
    """One line for a missed outcome (the monitor's log, ``skinet watch``, the dashboard): the skill, the gap,
    and the outcome inferred or why none is (docs/how-it-works.md, *Missed outcomes*)."""
    head = f"missed outcome: {m.skillset}:{m.skill} ended without its response ({m.gap})"
    if m.outcome is not None:
        return f"{head}: {m.outcome} inferred from the resources"
    if m.candidates:
        return f"{head}: outcome unknown, the model cannot tell {' from '.join(m.candidates)}"
    return f"{head}: outcome unknown, no mode of the model explains the status"


def plan_steps(steps: Iterable[Step]) -> list[PlanStep]:
    """A plan's steps and branches (:attr:`skinet.plan.Plan.steps`) as wire messages (docs/semantics.md §8)."""
    return [PlanStep(number=s.number, skillset=s.skillset, action=s.action, expect=s.expect,
                     inputs=dict(s.inputs) if s.inputs else None,
                     branches=[PlanBranch(skillset=b.skillset, transition=b.transition, then=b.then, step=b.step,
                                          steps=plan_steps(b.steps)) for b in s.branches])
            for s in steps]
