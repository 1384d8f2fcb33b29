"""Algorithm 1 with implicit and forced constraints (docs/semantics.md §5; seed paper, Algorithm 1).

For each skillset, each transition firable at the live marking is fired (with
its invariant cascade); a property it violates at once is an *explicit*
constraint, one whose result lies in mu1 = Sat(AF not phi) (fair or literal,
from the predictor) an *implicit* constraint, one whose result is forced
(:mod:`skinet.verify.forced`: skill outcomes alone can lead to a violation) a
*forced* constraint, and one whose result the predictor could not decide
(truncated exploration) is *unknown*, never reported as safe.  Rank: explicit >
implicit > forced > unknown.  Forced constraints are computed here, at every
call, so they never wait for a predictor.

Cost: O(T x R x P) formula evaluations for T firable transitions, R results
per cascade and P properties, plus one memoised forced query per result and
property (see :mod:`skinet.verify.forced`); cascades are tiny in practice.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Literal, Protocol, get_args

from skinet.verify import explain
from skinet.net.petrinet import Transition
from skinet.net.semantics import steps
from skinet.system.prediction import PredictionOptions, PropertyOptions
from skinet.props.evaluate import holds
from skinet.props.formula import Property
from skinet.system.model import Marking, System
from skinet.verify.forced import oracle as forced_oracle

Constraint = Literal["explicit", "implicit", "forced", "unknown"]
CONSTRAINTS: tuple[str, ...] = get_args(Constraint)  # worst first
_RANK: dict[str, int] = {c: len(CONSTRAINTS) - i for i, c in enumerate(CONSTRAINTS)}


@dataclass(frozen=True)
class PredictionVerdict:
    """What the predictor knows of one marking for one property."""

    status: Literal["dangerous", "safe", "undecided"]
    steps: int | None = None  # bound on steps to the violation, when dangerous
    witness: tuple[str, ...] = ()  # transition names leading to a violation


class Prediction(Protocol):
    """mu1 as Algorithm 1 consumes it (implemented by :mod:`skinet.verify.predict`)."""

    def verdict(self, prop: str, marking: Mapping[str, int]) -> PredictionVerdict: ...


@dataclass(frozen=True)
class UnsafeTransition:
    skillset: str
    transition: str  # logical name, e.g. "go_to_waypoint.start"
    kind: str
    controllable: bool
    property: str
    constraint: Constraint
    steps: int | None = None  # 0 for explicit; steps to the violation for implicit and forced
    witness: tuple[str, ...] = ()  # "skillset:transition" per step
    reason: str = field(default="", compare=False)  # the operator's sentence (skinet.verify.explain)


@dataclass(frozen=True)
class Recovery:
    skillset: str
    transition: str
    kind: str
    controllable: bool


@dataclass
class Analysis:
    """Algorithm 1's result at one live marking."""

    marking: Marking
    violated: list[str] = field(default_factory=list)  # properties failing now
    unsafe: list[UnsafeTransition] = field(default_factory=list)  # the literal algorithm
    recovery: dict[str, list[Recovery]] = field(default_factory=dict)  # per violated property

    def operator_unsafe(self) -> list[UnsafeTransition]:
        """Unsafe transitions for properties that hold now (the operator view, docs/semantics.md §5)."""
        return [u for u in self.unsafe if u.property not in self.violated]


def analyse(
    system: System, marking: Mapping[str, int], prediction: Prediction | None = None,
    options: PredictionOptions | None = None,
) -> Analysis:
    """Run Algorithm 1 at ``marking`` (a stable combined marking).

    ``prediction`` is mu1; ``None`` means mu1 is empty (no implicit constraint).
    ``options`` (default: the system's) say per property whether forced
    constraints are computed and whether events count as uncontrollable.
    Variants of one logical transition and the several results of a cascade are
    merged, keeping the worst constraint (explicit > implicit > forced > unknown).
    """
    options = options or system.prediction
    nets = system.nets
    result = Analysis(dict(marking))
    result.violated = [p.name for p in system.properties if not holds(p.expr, marking, nets)]
    worst: dict[tuple[str, str, str], UnsafeTransition] = {}
    recovers: dict[tuple[str, str, str], bool] = {}
    firable: dict[tuple[str, str], Transition] = {}  # first variant per logical name, in firing order
    for comp in system.components:
        for t, results in steps(comp.net, marking[comp.name]):
            firable.setdefault((comp.name, t.name), t)
            for m in results:
                after = dict(marking)
                after[comp.name] = m
                for p in system.properties:
                    key = (comp.name, t.name, p.name)
                    found = _judge(system, p, comp.name, holds(p.expr, after, nets), after, prediction,
                                   options.of(p.name))
                    if p.name in result.violated:
                        # Every result must restore the property for a recovery.
                        recovers[key] = recovers.get(key, True) and found is None
                    if found is None:
                        continue
                    constraint, n, witness, reason = found
                    old = worst.get(key)
                    if old is None or _RANK[constraint] > _RANK[old.constraint] or (
                            constraint == old.constraint and n is not None and old.steps is not None and n < old.steps):
                        worst[key] = UnsafeTransition(
                            comp.name, t.name, t.kind, t.controllable, p.name, constraint, n, witness, reason
                        )
    for (ss, tname), t in firable.items():
        for p in system.properties:
            if (ss, tname, p.name) in worst:
                result.unsafe.append(worst[(ss, tname, p.name)])
            if recovers.get((ss, tname, p.name)):
                result.recovery.setdefault(p.name, []).append(Recovery(ss, tname, t.kind, t.controllable))
    for p in result.violated:
        result.recovery.setdefault(p, [])
    return result


def _judge(
    system: System, prop: Property, moved: str, safe: bool, after: Mapping[str, int],
    prediction: Prediction | None, opts: PropertyOptions,
) -> tuple[Constraint, int | None, tuple[str, ...], str] | None:
    if not safe:
        return "explicit", 0, (), explain.explicit_reason(system, prop, after, moved)
    v = prediction.verdict(prop.name, after) if prediction is not None else None
    if v is not None and v.status == "dangerous":
        return "implicit", v.steps, v.witness, explain.implicit_reason(opts.af, v.steps, v.witness)
    if opts.forced:
        f = forced_oracle(system, opts.events_uncontrollable).verdict(prop, after)
        if f is not None:
            return "forced", f.steps, f.witness, explain.forced_reason(system, prop, f.witness, f.reached)
    if v is not None and v.status == "undecided":
        return "unknown", None, (), explain.UNKNOWN_REASON
    return None
