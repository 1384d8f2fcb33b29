"""Which outcome ended a skill whose response was missed (docs/how-it-works.md, *Missed outcomes*).

After a gap (the link to a manager down, a manager or monitor restarted) a skill
known to run may be found ended with its response never seen.  The model can still
name the outcome when it is unique: of the skill's success and failure modes, only
one leads from the marking before the gap to the one observed after it (each mode's
effects and postcondition, then the invariant cascade).  Several missed skills of one
skillset are taken together: every order and every choice of one mode per skill is
tried, and a skill's outcome is inferred only when every combination that explains the
observed marking gives it the same mode.  Interrupts are not candidates: an outcome is
what the skill did by itself.

Cost: for ``s`` missed skills with at most ``k`` modes each, ``s! * k**s`` firing
sequences of ``s`` steps (each one ``stable_successors``); ``s`` is capped at
:data:`MAX_SKILLS`, beyond which every outcome is unknown.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from itertools import permutations, product

from skinet.net.petrinet import PetriNet
from skinet.net.semantics import is_enabled, stable_successors

MAX_SKILLS = 4  # missed skills of one skillset taken together: 4! * k**4 sequences at most
OUTCOME_KINDS = ("success", "failure")


@dataclass(frozen=True)
class Inference:
    """What the model says of one missed outcome: ``outcome`` (a transition name such as
    ``teleop.success.done``) when it is unique, else ``None`` with the ``candidates`` that
    explain the observation (several: the model cannot tell them apart; none: no mode does)."""

    skill: str
    outcome: str | None
    candidates: tuple[str, ...]


def modes(net: PetriNet, skill: str) -> tuple[str, ...]:
    """The success and failure transition names of ``skill``, in the net's order."""
    return tuple(dict.fromkeys(t.name for t in net.transitions if t.skill == skill and t.kind in OUTCOME_KINDS))


def infer_outcomes(net: PetriNet, before: int, after: int, skills: Sequence[str]) -> list[Inference]:
    """The outcome of each of ``skills`` (running at ``before``, ended at ``after``), one per skill.

    >>> from skinet.lang.parser import parse_skillset
    >>> from skinet.net.build import build_net, resource_place, running_place, idle_place
    >>> ss = parse_skillset('''skillset s {
    ...   resource { p { state { Off On } initial Off transition all } }
    ...   skill power { success on { postcondition p == On } failure off { } }
    ...   skill wait { success done { } failure lost { } }
    ... }''', "s.rl")
    >>> net = build_net(ss)
    >>> m = lambda p, *run: net.marking_of([resource_place("p", p)] + [
    ...     running_place(k) if k in run else idle_place(k) for k in ("power", "wait")])
    >>> infer_outcomes(net, m("Off", "power"), m("On"), ["power"])[0].outcome
    'power.success.on'
    >>> infer_outcomes(net, m("Off", "power"), m("Off"), ["power"])[0].outcome
    'power.failure.off'
    >>> infer_outcomes(net, m("Off", "wait"), m("Off"), ["wait"])[0].candidates
    ('wait.success.done', 'wait.failure.lost')
    """
    skills = list(dict.fromkeys(skills))
    if not skills or len(skills) > MAX_SKILLS:
        return [Inference(k, None, ()) for k in skills]
    options = [modes(net, k) for k in skills]
    seen: list[set[str]] = [set() for _ in skills]
    for choice in product(*options):
        for order in permutations(range(len(skills))):
            if _reaches(net, before, after, [choice[i] for i in order]):
                for i, name in enumerate(choice):
                    seen[i].add(name)
                break
    return [Inference(k, next(iter(s)) if len(s) == 1 else None, tuple(n for n in opts if n in s))
            for k, opts, s in zip(skills, options, seen)]


def _reaches(net: PetriNet, marking: int, goal: int, names: list[str]) -> bool:
    """Whether firing ``names`` in order (each with its cascade, any variant) leads from ``marking`` to ``goal``."""
    if not names:
        return marking == goal
    return any(_reaches(net, m, goal, names[1:])
               for t in net.transitions if t.name == names[0] and is_enabled(t, marking)
               for m in stable_successors(net, marking, t))


__all__ = ["MAX_SKILLS", "Inference", "infer_outcomes", "modes"]
