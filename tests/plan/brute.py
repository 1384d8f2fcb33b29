"""An independent plain-sets version of docs/semantics.md §8, for the planner's tests.

Combined markings are tuples of net markings (bit masks), found by a plain
breadth-first search that fires each component's net with
:func:`skinet.net.semantics.steps` (the firing rule is the ground truth, shared
with the product); everything else is written here again from the semantics' (docs/semantics.md)
formulas with Python sets and dicts: the game's moves, the forced markings by
their least fixpoint ``X = not phi | EX_unc X`` on the combined graph (not
the planner's compositional boxes), ``W``, ``W_c`` and ``E`` with their ranks,
and a checker that plays a returned policy against every outcome.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping

from skinet.net.semantics import steps
from skinet.plan.goal import Goal
from skinet.plan.policy import Command, Plan, Reached, Wait
from skinet.props.evaluate import holds
from skinet.system.model import System

Combined = tuple[int, ...]
DONE = "done"


class Brute:
    """The game of docs/semantics.md §8 on ``system`` from ``marking``, by plain sets."""

    def __init__(self, system: System, marking: Mapping[str, int], events: bool = False):
        self.system = system
        self.names = [c.name for c in system.components]
        self.nets = [c.net if events else c.eventless for c in system.components]
        outcome_kinds = {"success", "failure"} | ({"event"} if events else set())
        start = tuple(marking[n] for n in self.names)
        self.start = start
        # commands[m]: (component, name) -> results; outcomes[m]: [(component, name, result)]
        self.commands: dict[Combined, dict[tuple[int, str], set[Combined]]] = {}
        self.outcomes: dict[Combined, list[tuple[int, str, Combined]]] = {}
        todo = deque([start])
        seen = {start}
        while todo:
            m = todo.popleft()
            cmds: dict[tuple[int, str], set[Combined]] = {}
            outs: list[tuple[int, str, Combined]] = []
            for i, net in enumerate(self.nets):
                for t, results in steps(net, m[i]):
                    for r in results:
                        after = m[:i] + (r,) + m[i + 1:]
                        if t.kind in ("start", "interrupt"):
                            cmds.setdefault((i, t.name), set()).add(after)
                        elif t.kind in outcome_kinds:
                            outs.append((i, t.name, after))
                        else:
                            continue
                        if after not in seen:
                            seen.add(after)
                            todo.append(after)
            self.commands[m] = cmds
            self.outcomes[m] = outs
        self.markings = set(self.commands)
        nets = system.nets
        bad = {m for m in self.markings if not all(holds(p.expr, self.as_dict(m), nets) for p in system.properties)}
        forced = set(bad)
        while True:
            more = {m for m in self.markings - forced if any(r in forced for _, _, r in self.outcomes[m])}
            if not more:
                break
            forced |= more
        self.safe = self.markings - forced

    def as_dict(self, m: Combined) -> dict[str, int]:
        return dict(zip(self.names, m))

    # ------------------------------------------------------------ the game

    def actions(self, m: Combined, goal: Goal, relaxed: bool = False) -> list[tuple[str, set]]:
        """A(m): admissible commands whose inputs the goal gives, then waiting; each with Post (DONE for a target)."""
        out = []
        for (i, name), results in self.commands[m].items():
            if results <= self.safe and (relaxed or self.given(goal, i, name)):
                out.append((f"{self.names[i]}:{name}", results))
        if self.outcomes[m]:
            out.append(("wait", {DONE if goal.target(self.names[i], name) else r for i, name, r in self.outcomes[m]}))
        return out

    def given(self, goal: Goal, i: int, name: str) -> bool:
        if not name.endswith(".start"):
            return True
        skill = self.system.components[i].skillset.skill(name[:-len(".start")])
        return all(v.name in (goal.given(self.names[i], skill.name) or {}) for v in skill.inputs)

    def target(self, goal: Goal) -> set:
        if goal.kind == "run":
            return {DONE}
        return {m for m in self.safe if goal.holds(self.system, self.as_dict(m))}

    def strong(self, goal: Goal) -> dict:
        """rank over W = mu X. T | CPre(X)."""
        rank = {m: 0 for m in self.target(goal)}
        k = 0
        while True:
            k += 1
            new = {m for m in self.safe - rank.keys()
                   if any(post <= rank.keys() for _, post in self.actions(m, goal))}
            if not new:
                return rank
            rank.update({m: k for m in new})

    def cyclic(self, goal: Goal, relaxed: bool = False) -> dict:
        """rank over W_c = nu Z. mu X. T | CPre_c(Z, X), Z from Safe | T."""
        z = self.safe | self.target(goal)
        while True:
            rank = {m: 0 for m in self.target(goal)}
            k = 0
            while True:
                k += 1
                new = {m for m in (z & self.safe) - rank.keys()
                       if any(post <= z and post & rank.keys() for _, post in self.actions(m, goal, relaxed))}
                if not new:
                    break
                rank.update({m: k for m in new})
            if set(rank) == z:
                return rank
            z = set(rank)

    def weak(self, goal: Goal) -> set:
        """E = mu X. T | { m in Safe : some a in A(m) with Post & X }."""
        x = set(self.target(goal))
        while True:
            new = {m for m in self.safe - x if any(post & x for _, post in self.actions(m, goal, True))}
            if not new:
                return x
            x |= new

    # ------------------------------------------------------------ the checker

    def results(self, m: Combined, action: Command | Wait, goal: Goal) -> set:
        """What the robot may do after the plan's ``action`` at ``m`` (fired from the nets)."""
        if isinstance(action, Wait):
            assert self.outcomes[m], f"the plan waits at {self.as_dict(m)}, where no outcome is enabled"
            return {DONE if goal.target(self.names[i], name) else r for i, name, r in self.outcomes[m]}
        i = self.names.index(action.skillset)
        assert (i, action.transition) in self.commands[m], f"{action} is not enabled at {self.as_dict(m)}"
        if action.transition.endswith(".start"):
            skill = self.system.components[i].skillset.skill(action.transition[:-len(".start")])
            assert set(action.inputs) == {v.name for v in skill.inputs}, f"{action} lacks inputs"
        return self.commands[m][(i, action.transition)]

    def check(self, plan: Plan) -> int:
        """Play ``plan`` against every outcome; returns the markings its policy reaches.

        strong: every play reaches the goal within ``plan.moves`` moves and stays in Safe;
        cyclic: every marking the policy reaches is Safe, and the goal stays reachable from each.
        """
        goal = plan.goal
        assert plan.answer in ("strong", "cyclic")
        edges: dict[Combined, set] = {}
        depth = {self.start: 0}
        todo = deque([self.start])
        while todo:
            m = todo.popleft()
            assert m in self.safe, f"the plan reaches {self.as_dict(m)}, which is not safe"
            action = plan.action(self.as_dict(m))
            if isinstance(action, Reached):
                assert goal.holds(self.system, self.as_dict(m))
                edges[m] = set()
                continue
            assert not (goal.kind == "reach" and goal.holds(self.system, self.as_dict(m))), "no stop at the goal"
            assert action is not None, f"no action at {self.as_dict(m)}, which the plan reaches"
            edges[m] = self.results(m, action, goal)
            for r in edges[m] - {DONE}:
                if plan.answer == "strong":
                    assert depth[m] + 1 <= (plan.moves or 0), f"a play needs more than {plan.moves} moves"
                    # a strong plan's plays are finite: no marking is met twice on one play (depth grows)
                    depth[r] = max(depth.get(r, 0), depth[m] + 1)
                    todo.append(r)
                elif r not in depth:
                    depth[r] = depth[m] + 1
                    todo.append(r)
            if plan.answer == "strong" and DONE in edges[m]:
                assert depth[m] + 1 <= (plan.moves or 0)
        # the goal stays reachable from every marking the policy reaches (backwards from the goal)
        good = {m for m, out in edges.items() if not out or DONE in out}
        while True:
            more = {m for m, out in edges.items() if m not in good and out & good}
            if not more:
                break
            good |= more
        assert good == set(edges), f"the goal is not reachable from {[self.as_dict(m) for m in set(edges) - good][:3]}"
        return len(edges)
