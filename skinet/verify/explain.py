"""Operator wording of constraints: why a command is unsafe, in a sentence (docs/semantics.md §5).

``go_to_waypoint.start: forced for safety_guard — arm_ready may succeed
(1 step) and leave manipulator arm_status at RD while spot go_to_waypoint
runs``.  The violating marking is described by the literals of one clause of
``not phi`` that it satisfies, each as the actual state of its subject.

Cost: the disjunctive normal form of ``not phi`` once per property (capped at
:data:`MAX_CLAUSES`; beyond it every atom is described), then one pass over
its clauses per sentence.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence

from skinet.lang.expr import And, Const, Expr, Implies, Not, Or, atoms
from skinet.net.build import idle_place, resource_place, running_place
from skinet.props.formula import PlaceAtom, Property
from skinet.system.model import System, is_running, resource_state

MAX_CLAUSES = 256
Literal_ = tuple[PlaceAtom, bool]


def step_words(label: str) -> str:
    """``manipulator:arm_ready.success.ready`` -> ``arm_ready may succeed``."""
    name = label.split(":", 1)[-1]
    parts = name.split(".")
    head = parts[0]
    kind = parts[1] if len(parts) > 1 else ""
    if kind == "success":
        return f"{head} may succeed"
    if kind == "failure":
        return f"{head} may fail" + (f" ({parts[2]})" if len(parts) > 2 and parts[2] else "")
    if kind == "start":
        return f"{head} is started"
    if kind == "interrupt":
        return f"{head} is interrupted"
    if kind == "inv":
        return f"{head} stops ({parts[2] if len(parts) > 2 else 'invariant'} fails)"
    return f"event {name} may occur"


def path_words(witness: Sequence[str]) -> str:
    return ", then ".join(step_words(w) for w in witness)


def plural(n: int, word: str = "step") -> str:
    return f"{n} {word}{'' if n == 1 else 's'}"


def _clauses(expr: Expr, positive: bool) -> list[list[Literal_]] | None:
    """DNF of ``expr`` (or of its negation) as lists of literals; None past the cap."""
    if isinstance(expr, Const):
        return [[]] if expr.value == positive else []
    if isinstance(expr, PlaceAtom):
        return [[(expr, positive)]]
    if isinstance(expr, Not):
        return _clauses(expr.arg, not positive)
    if isinstance(expr, Implies):
        return _clauses(Or(Not(expr.left), expr.right), positive)
    if isinstance(expr, (And, Or)):
        left, right = _clauses(expr.left, positive), _clauses(expr.right, positive)
        if left is None or right is None:
            return None
        if isinstance(expr, And) != positive:
            out = left + right
        else:
            out = [a + b for a in left for b in right]
        return out if len(out) <= MAX_CLAUSES else None
    return None


def violation_clauses(prop: Property) -> list[list[Literal_]] | None:
    """Clauses of ``not phi`` (memoised on the property object)."""
    cache = prop.__dict__.get("_not_dnf", False)
    if cache is False:
        cache = _clauses(prop.expr, False)
        prop.__dict__["_not_dnf"] = cache
    return cache


def subject_words(system: System, atom: PlaceAtom, marking: Mapping[str, int]) -> str:
    """The actual state at ``marking`` of what ``atom`` speaks of: ``manipulator arm_status at RD``."""
    comp = system.component(atom.skillset)
    m = marking[atom.skillset]
    for r in comp.skillset.resources:
        if atom.place in (resource_place(r.name, s) for s in r.states):
            return f"{atom.skillset} {r.name} at {resource_state(comp, m, r)}"
    for k in comp.skillset.skills:
        if atom.place in (idle_place(k.name), running_place(k.name)):
            return f"{atom.skillset} {k.name} {'runs' if is_running(comp, m, k.name) else 'is idle'}"
    return str(atom)


def violation_words(
    system: System, prop: Property, marking: Mapping[str, int], moved: Collection[str] = ()
) -> tuple[list[str], list[str]]:
    """Why ``prop`` fails at ``marking``: subjects on components in ``moved``, then the others."""
    nets = system.nets
    value = {}

    def holds(atom: PlaceAtom) -> bool:
        if atom not in value:
            value[atom] = bool(marking[atom.skillset] >> nets[atom.skillset].place_index(atom.place) & 1)
        return value[atom]

    clauses = violation_clauses(prop)
    chosen: list[PlaceAtom] = []
    if clauses is not None:
        for clause in clauses:
            if all(holds(a) == positive for a, positive in clause):
                chosen = list(dict.fromkeys(a for a, _ in clause))
                break
    if not chosen:
        chosen = list(dict.fromkeys(a for a in atoms(prop.expr) if isinstance(a, PlaceAtom)))
    words = list(dict.fromkeys(subject_words(system, a, marking) for a in chosen))
    first = [w for a, w in zip(chosen, words) if a.skillset in moved]
    return first, [w for w in words if w not in first]


def explicit_reason(system: System, prop: Property, after: Mapping[str, int], moved: str) -> str:
    first, rest = violation_words(system, prop, after, {moved})
    return "violates it at once: " + " while ".join(first + rest)


def forced_reason(system: System, prop: Property, witness: Sequence[str], reached: Mapping[str, int]) -> str:
    moved = {w.split(":", 1)[0] for w in witness}
    first, rest = violation_words(system, prop, reached, moved)
    leave = " and ".join(first) or "the robot"
    text = f"{path_words(witness)} ({plural(len(witness))}) and leave {leave}"
    return text + (" while " + " and ".join(rest) if rest else "")


def implicit_reason(af: str, steps: int | None, witness: Sequence[str]) -> str:
    example = f", e.g. {path_words(witness)}" if witness else ""
    if af == "literal":
        bound = f" within {plural(steps)}" if steps is not None else ""
        return f"every continuation violates it{bound}{example}"
    earliest = f", at the earliest in {plural(steps)}" if steps is not None else ""
    return f"every continuation in which running skills end violates it{earliest}{example}"


def warning_line(u: object) -> str:
    """``base:navigate.start: forced for stowed_drive — unfold may succeed (1 step) and ...``.

    ``u`` is an :class:`~skinet.verify.algorithm1.UnsafeTransition` or a wire ``UnsafeEntry``.
    """
    head = f"{u.skillset}:{u.transition}: {u.constraint} for {u.property}"  # type: ignore[attr-defined]
    return f"{head} — {u.reason}" if u.reason else head  # type: ignore[attr-defined]


UNKNOWN_REASON = "the prediction could not decide (exploration truncated or budget spent)"
