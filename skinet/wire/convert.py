"""Conversions between core objects and wire messages (SPEC §1, §5, §6).

The predictor answers with the *risks* of the markings one step away from the
live marking (what Algorithm 1 needs); :class:`RiskTable` turns them back into
the :class:`~skinet.verify.algorithm1.Prediction` the monitor feeds Algorithm 1.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import PurePath
from collections.abc import Iterable, Mapping

from skinet.net.semantics import steps
from skinet.props.evaluate import holds
from skinet.system import Marking, System, build_system, marking_from_json, marking_to_json
from skinet.lang.parser import parse_skillset
from skinet.verify.algorithm1 import Analysis, PredictionVerdict
from skinet.verify.predict import Forecast
from skinet.wire.messages import (
    ModelBundle, PropertyVerdict, RecoveryEntry, Risk, SkillsetStatus, StateSpaceReport, UnsafeEntry,
)


def statuses(system: System, marking: Mapping[str, int]) -> dict[str, SkillsetStatus]:
    return {k: SkillsetStatus(**v) for k, v in marking_to_json(system, marking).items()}


def marking_of(system: System, skillsets: Mapping[str, SkillsetStatus], source: str = "<message>") -> Marking:
    """Raises :class:`~skinet.errors.SourceError` on unknown names."""
    return marking_from_json(system, {k: v.model_dump() for k, v in skillsets.items()}, source)


def bundle(system: System) -> ModelBundle:
    """Every source of ``system`` with its content digest (sha256 of canonical JSON)."""
    entries = []
    for c in system.components:
        name = PurePath(c.skillset.source).name
        entries.append((name, system.sources.get(name, ""), c.manager))
    models = {e[0] for e in entries}
    props_name = next((n for n in system.sources if n not in models), "properties")
    props = system.sources.get(props_name, "")
    digest = _digest(system.name, entries, props_name, props)
    return ModelBundle(system=system.name, digest=digest, skillsets=entries, properties=props, properties_name=props_name)


def bundle_digest(b: ModelBundle) -> str:
    """The digest ``b``'s sources hash to, computed without parsing them (cost: one sha256)."""
    return _digest(b.system, [tuple(e) for e in b.skillsets], b.properties_name, b.properties)


def _digest(name: str, entries: list[tuple[str, str, str]], props_name: str, props: str) -> str:
    canonical = json.dumps([name, entries, props_name, props], separators=(",", ":"))
    return hashlib.sha256(canonical.encode()).hexdigest()[:32]


def system_from_bundle(b: ModelBundle) -> System:
    """Rebuild a system from a bundle (raises SourceError on bad sources)."""
    skillsets = [(parse_skillset(text, name), manager) for name, text, manager in b.skillsets]
    sources = {name: text for name, text, _ in b.skillsets} | {b.properties_name: b.properties}
    return build_system(b.system, skillsets, b.properties, b.properties_name, sources)


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
                                        steps=v.steps, witness=list(v.witness)))
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
    """Algorithm 1's result as message parts: verdicts, operator-view entries, recovery (SPEC §5)."""
    props = [PropertyVerdict(name=p.name, holds=p.name not in analysis.violated) for p in system.properties]
    unsafe = [
        UnsafeEntry(skillset=u.skillset, transition=u.transition, kind=u.kind, controllable=u.controllable,
                    property=u.property, constraint=u.constraint, steps=u.steps, witness=list(u.witness))
        for u in analysis.operator_unsafe()
    ]
    recovery = [
        RecoveryEntry(property=p, skillset=r.skillset, transition=r.transition, controllable=r.controllable)
        for p, rs in analysis.recovery.items() for r in rs
    ]
    return props, unsafe, recovery
