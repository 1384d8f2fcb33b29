"""Systems, random goals, random reachable markings and random model mutations for the planner's tests."""

from __future__ import annotations

import random
import re
from dataclasses import replace
from pathlib import Path

import pytest

from skinet.errors import SourceError
from skinet.system.load import load_system
from skinet.lang.model import Effect, Skillset
from skinet.lang.parser import parse_skillset
from skinet.net.semantics import steps
from skinet.plan.goal import Goal, parse_goal
from skinet.system.model import System, build_system
from skinet.verify.forced import forced
from tests.corpus import require_corpus

ROOT = Path(__file__).resolve().parents[2]
CORPUS = ROOT.parent / "shared" / "corpus"


def paper() -> System:
    return load_system(ROOT / "skillsets" / "spot_arm.toml")[0]


def mobile() -> System:
    return load_system(ROOT / "skillsets" / "mobile_manip.toml")[0]


def corpus(n_spot: int = 1, n_arm: int = 1) -> System:
    """``n_spot`` copies of the corpus Spot and ``n_arm`` of its arm, renamed (spot, spot2, ...)."""
    if not CORPUS.exists():
        require_corpus()
    out = []
    for file, name, n in (("spot.rl", "spot", n_spot), ("manipulator.rl", "manipulator", n_arm)):
        text = (CORPUS / file).read_text()
        for k in range(1, n + 1):
            renamed = name if k == 1 else f"{name}{k}"
            out.append(parse_skillset(re.sub(rf"skillset\s+{name}\b", f"skillset {renamed}", text, count=1), renamed))
    return build_system(f"{n_spot}+{n_arm}", [(s, "") for s in out], (CORPUS / "spot_manipulator.props").read_text())


def cranes() -> System:
    """Two cranes (tests/plan/crane.rl): commands whose invariant cascade has two results."""
    text = (Path(__file__).with_name("crane.rl")).read_text()
    skillsets = [parse_skillset(text.replace("skillset crane", f"skillset {n}"), f"{n}.rl") for n in ("crane", "crane2")]
    props = "not_dropped = not crane:Dropped\none_lowering = not (crane:i_lower and crane2:i_lower)\n"
    return build_system("cranes", [(s, "") for s in skillsets], props)


def inputs_for(system: System, rng: random.Random, keep: float = 1.0) -> dict:
    """Values for the inputs of every skill that has some (each kept with probability ``keep``)."""
    out = {}
    for c in system.components:
        for k in c.skillset.skills:
            if k.inputs and rng.random() < keep:
                out[f"{c.name}:{k.name}"] = {v.name: {"x": 1.0} for v in k.inputs}
    return out


def random_formula(system: System, rng: random.Random, depth: int = 2) -> str:
    if depth == 0 or rng.random() < 0.35:
        c = rng.choice(system.components)
        ss = c.skillset
        if ss.resources and rng.random() < 0.7:
            r = rng.choice(ss.resources)
            return f"{c.name}:{r.name}.{rng.choice(r.states)}"
        k = rng.choice(ss.skills)
        return f"{c.name}:{rng.choice(['i_', 'e_'])}{k.name}"
    op = rng.choice(["and", "and", "or", "not"])
    if op == "not":
        return f"not ({random_formula(system, rng, depth - 1)})"
    return f"({random_formula(system, rng, depth - 1)}) {op} ({random_formula(system, rng, depth - 1)})"


def random_goal(system: System, rng: random.Random) -> Goal:
    """A ``reach`` goal over random atoms, or a ``run`` goal of a random skill that can succeed."""
    inputs = inputs_for(system, rng, keep=0.7)
    if rng.random() < 0.3:
        candidates = [(c.name, k) for c in system.components for k in c.skillset.skills if k.successes]
        ss, k = rng.choice(candidates)
        inputs[f"{ss}:{k.name}"] = {v.name: {"x": 1.0} for v in k.inputs}
        named = [m.name for m in k.successes if m.name]
        text = f"run {ss}:{k.name}" + (f".success.{rng.choice(named)}" if named and rng.random() < 0.5 else "")
    else:
        text = f"reach {random_formula(system, rng)}"
    return parse_goal(system, text, {key: v for key, v in inputs.items() if v} or None)


def random_marking(system: System, rng: random.Random, walk: int = 12, safe: bool = True) -> dict[str, int]:
    """A marking the robot can be in: a random walk on the full nets (events included) from the
    initial one; with ``safe``, one forced for no property where 50 walks find one."""
    for _ in range(50):
        marking = system.initial_marking()
        for _ in range(walk):
            c = rng.choice(system.components)
            options = [r for _, results in steps(c.net, marking[c.name]) for r in results]
            if options:
                marking[c.name] = rng.choice(sorted(options))
        if not safe or not any(forced(system, marking, p) for p in system.properties):
            break
    return marking


def mutants(system: System, count: int, seed: int) -> list[System]:
    """``count`` random mutations of ``system``'s models (an effect's target, a dropped precondition,
    a dropped postcondition, a mode's effects swapped with another mode's), each still a valid model."""
    rng = random.Random(seed)
    out: list[System] = []
    props = "\n".join(f"{p.name} = {p.text}" for p in system.properties)
    while len(out) < count:
        skillsets = [c.skillset for c in system.components]
        i = rng.randrange(len(skillsets))
        mutated = _mutate(skillsets[i], rng)
        if mutated is None:
            continue
        skillsets[i] = mutated
        try:
            out.append(build_system(f"{system.name}-m{len(out)}", [(s, "") for s in skillsets], props))
        except SourceError:
            continue
    return out


def _mutate(ss: Skillset, rng: random.Random) -> Skillset | None:
    skills = [k for k in ss.skills if k.modes]
    if not skills:
        return None
    k = rng.choice(skills)
    kind = rng.choice(["effect", "precondition", "postcondition", "swap"])
    if kind == "effect":
        mode = rng.choice(k.modes)
        if not mode.effects:
            return None
        e = rng.choice(mode.effects)
        states = ss.resource(e.resource).states
        new = Effect(e.resource, rng.choice(states))
        mode2 = replace(mode, effects=tuple(new if x is e else x for x in mode.effects))
        k2 = replace(k, successes=tuple(mode2 if m is mode else m for m in k.successes),
                     failures=tuple(mode2 if m is mode else m for m in k.failures))
    elif kind == "precondition":
        if not k.preconditions:
            return None
        drop = rng.choice(k.preconditions)
        k2 = replace(k, preconditions=tuple(p for p in k.preconditions if p is not drop))
    elif kind == "postcondition":
        modes = [m for m in k.modes if m.postcondition is not None]
        if not modes:
            return None
        mode = rng.choice(modes)
        mode2 = replace(mode, postcondition=None)
        k2 = replace(k, successes=tuple(mode2 if m is mode else m for m in k.successes),
                     failures=tuple(mode2 if m is mode else m for m in k.failures))
    else:
        if not k.successes or not k.failures:
            return None
        s, f = rng.choice(k.successes), rng.choice(k.failures)
        k2 = replace(k, successes=tuple(replace(m, effects=f.effects) if m is s else m for m in k.successes),
                     failures=tuple(replace(m, effects=s.effects) if m is f else m for m in k.failures))
    return replace(ss, skills=tuple(k2 if x is k else x for x in ss.skills))

