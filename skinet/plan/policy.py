"""A plan: its answer, its policy by descent in the layers, and its steps (docs/semantics.md §8, *Plans*).

At a marking of rank ``k > 0`` the policy takes the first action, in the fixed
order of :meth:`skinet.plan.arena.Arena.actions` (starts by component and net
order, then waiting, then interrupts), whose results all lie in layer ``k - 1`` (strong), or
all in ``W_c`` with one in layer ``k - 1`` (cyclic): the same question always
gets the same plan.  The *steps* follow the policy from the start marking
along favourable outcomes (the result of least rank, the first on ties);
every other result becomes a branch: a retry (back to a step already taken),
a jump ahead, or another route with its own steps, as an engineer would
draw the behaviour tree.  Cost: per marking asked, one membership test per
layer probed (binary search) and per result of each action tried; the steps
and the policy visit each marking the policy can reach once.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

from skinet.plan.arena import DONE, WAIT, Action, Arena, Local
from skinet.plan.goal import Goal

Answer = Literal["strong", "cyclic", "none", "unknown"]
MAX_POLICY = 100_000  # markings listed by Plan.policy()


@dataclass(frozen=True)
class Command:
    """Send ``transition`` (``init_power.start`` or ``teleop.interrupt``) to ``skillset``'s manager."""

    skillset: str
    transition: str
    inputs: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Wait:
    """Send nothing: a running skill's outcome is what the plan needs next."""


@dataclass(frozen=True)
class Reached:
    """The goal holds here (a ``reach`` goal)."""


@dataclass
class Step:
    """One step of the favourable path: a command, or waiting for the outcome ``expect``."""

    number: str  # "2", or "2.1" inside the route of a branch of step 2
    skillset: str  # the command's component; for waiting, the expected outcome's
    action: str  # "init_power.start", "teleop.interrupt" or "wait"
    expect: str | None  # waiting: the favourable outcome ("init_power.success.powered_on")
    inputs: Mapping[str, Any] | None
    branches: list[Branch] = field(default_factory=list)


@dataclass
class Branch:
    """Another result of a step: ``then`` is ``retry`` or ``continue`` (at ``step``), ``route``
    (its own ``steps``, then on at ``step`` if it joins the steps already shown) or ``reached``."""

    skillset: str
    transition: str  # the outcome; for a command with several results, the command itself
    then: Literal["retry", "continue", "route", "reached"]
    step: str | None = None
    steps: list[Step] = field(default_factory=list)


@dataclass
class Stats:
    engine: str
    markings: int  # explored (explicit) or in the product (symbolic)
    complete: bool
    truncated_by: str | None
    elapsed: float


class Plan:
    """The answer to one goal from one marking, and the policy that realises it."""

    def __init__(self, goal: Goal, arena: Arena, start: Local, answer: Answer, reason: str | None,
                 stats: Stats, game: Any = None, layers: list[Any] | None = None):
        self.goal = goal
        self.arena = arena
        self.start = start
        self.answer = answer
        self.reason = reason
        self.stats = stats
        # From a start forced for a property: the admissible commands (every result in Safe) that recover
        # from it, (skillset, transition) in the planner's fixed order (docs/planning.md); else empty.
        self.recovery: list[tuple[str, str]] = []
        self._game = game
        self._layers = layers or []
        self._allowed = arena.enabled(goal) if layers else None
        self._rank: dict[Local, int | None] = {}
        self._choice: dict[Local, Action | None] = {}
        self._steps: list[Step] | None = None

    # ------------------------------------------------------------ the policy

    @property
    def moves(self) -> int | None:
        """Strong: the most moves any play takes; cyclic: the fewest, outcomes favourable."""
        return self.rank(self.arena.marking(self.start)) if self._layers else None

    def _local(self, marking: Mapping[str, int]) -> Local | None:
        return self.arena.local(marking)

    def covers(self, marking: Mapping[str, int]) -> bool:
        """Whether ``marking`` is in the winning region: the policy applies there."""
        return self.rank(marking) is not None

    def rank(self, marking: Mapping[str, int]) -> int | None:
        """Moves left from ``marking`` (worst case, or favourable for a cyclic plan); None outside."""
        local = self._local(marking)
        return None if local is None else self._rank_of(local)

    def _rank_of(self, local: Local | None) -> int | None:
        if local is DONE:
            return 0
        if local not in self._rank:
            layers = self._layers
            if not layers or not self._game.member(layers[-1], local):
                self._rank[local] = None
            else:
                lo, hi = 0, len(layers) - 1  # layers grow: the first holding ``local``
                while lo < hi:
                    mid = (lo + hi) // 2
                    if self._game.member(layers[mid], local):
                        hi = mid
                    else:
                        lo = mid + 1
                self._rank[local] = lo
        return self._rank[local]

    def _choose(self, local: Local) -> Action | None:
        """The policy's action at ``local`` (None at rank 0 or outside)."""
        if local in self._choice:
            return self._choice[local]
        k = self._rank_of(local)
        chosen = None
        if k:
            below = self._layers[k - 1]
            region = self._layers[-1]
            member = self._game.member
            for action in self.arena.actions(local, self._allowed):
                results = [r for _, r in self.arena.post(local, action, self.goal)]
                if self.answer == "strong":
                    ok = all(member(below, r) for r in results)
                else:
                    ok = all(member(region, r) for r in results) and any(member(below, r) for r in results)
                if ok:
                    chosen = action
                    break
        self._choice[local] = chosen
        return chosen

    def action(self, marking: Mapping[str, int]) -> Command | Wait | Reached | None:
        """What to do at ``marking``: a command, waiting, nothing (the goal holds), or None
        when ``marking`` is outside the winning region (plan again)."""
        local = self._local(marking)
        k = None if local is None else self._rank_of(local)
        if k is None:
            return None
        if k == 0:
            return Reached()
        chosen = self._choose(local)
        return None if chosen is None else self._command(local, chosen)  # None: never a guessed move

    def _command(self, local: Local, action: Action) -> Command | Wait:
        if action.component is None or action.move is None:
            return Wait()
        name = self.arena.names[action.component]
        inputs = self.goal.given(name, action.move.skill or "") if action.move.kind == "start" else None
        return Command(name, action.move.name, dict(inputs or {}))

    # ------------------------------------------------------------ steps and branches

    @property
    def steps(self) -> list[Step]:
        """The steps expected when outcomes are favourable, each with its branches."""
        if self._steps is None:
            self._steps = [] if not self._layers else _Tree(self).route(self.start, "")[0]
        return self._steps

    @property
    def branches(self) -> list[Branch]:
        """Every branch of every step, depth first."""
        def walk(steps: list[Step]) -> Iterator[Branch]:
            for s in steps:
                for b in s.branches:
                    yield b
                    yield from walk(b.steps)

        return list(walk(self.steps))

    @property
    def retries(self) -> list[str]:
        """The outcomes (``skillset:transition``) after which the plan goes back to a step already taken."""
        return list(dict.fromkeys(f"{b.skillset}:{b.transition}" for b in self.branches if b.then == "retry"))

    @property
    def end(self) -> dict[str, int] | None:
        """The marking where the favourable path ends (after the target outcome, for a ``run`` goal)."""
        if not self._layers:
            return None
        local = self.start
        while True:
            action = self._choose(local)
            if action is None:
                return self.arena.marking(local)
            post = self.arena.post(local, action, self.goal)
            label, nxt = min(post, key=lambda p: self._rank_of(p[1]) or 0)
            if nxt is DONE:
                i = self.arena.names.index(label.split(":", 1)[0])
                move = next(mv for mv in self.arena.games[i].outcomes[local[i]] if f"{self.arena.names[i]}:{mv.name}" == label)
                return self.arena.marking(local[:i] + (move.results[0],) + local[i + 1:])
            local = nxt

    def policy(self) -> tuple[list[tuple[dict[str, int], Command | Wait | Reached, int]], bool]:
        """Every marking the plan can reach from the start, with its action and rank, breadth first;
        and whether the list is complete (at most :data:`MAX_POLICY` markings)."""
        if not self._layers:
            return [], True
        out = []
        seen = {self.start}
        todo = deque([self.start])
        while todo:
            if len(out) == MAX_POLICY:
                return out, False
            local = todo.popleft()
            k = self._rank_of(local)
            if not k:
                out.append((self.arena.marking(local), Reached(), 0))
                continue
            action = self._choose(local)
            if action is None:  # a marking of rank k > 0 has an action into layer k - 1, by the fixpoint
                raise RuntimeError(f"no action at a marking of rank {k}: the layers are inconsistent")
            out.append((self.arena.marking(local), self._command(local, action), k))
            for _, r in self.arena.post(local, action, self.goal):
                if r is not DONE and r not in seen:
                    seen.add(r)
                    todo.append(r)
        return out, True


class _Tree:
    """Builds the steps and branches, each marking shown once (later results point at its step)."""

    def __init__(self, plan: Plan):
        self.plan = plan
        self.shown: dict[Local, tuple[int, str]] = {}  # marking -> (order shown, step number)

    def route(self, local: Local, prefix: str) -> tuple[list[Step], str | None]:
        """The steps from ``local``, and the step they join when they reach a marking already shown."""
        plan = self.plan
        path: list[tuple[Local, Action, list[tuple[str, Local | None]], int]] = []
        while local is not DONE and local not in self.shown and plan._rank_of(local):
            action = plan._choose(local)
            if action is None:  # cannot happen inside the winning region
                break
            post = plan.arena.post(local, action, plan.goal)
            best = min(range(len(post)), key=lambda j: plan._rank_of(post[j][1]) or 0)
            self.shown[local] = (len(self.shown), f"{prefix}{len(path) + 1}")
            path.append((local, action, post, best))
            local = post[best][1]
        joins = self.shown[local][1] if local is not DONE and local in self.shown else None
        steps = []
        for n, (here, action, post, best) in enumerate(path, 1):
            number = f"{prefix}{n}"
            command = plan._command(here, action)
            label = post[best][0]
            if isinstance(command, Command):
                step = Step(number, command.skillset, command.transition, None,
                            command.inputs or None if action.move and action.move.kind == "start" else None)
            else:
                skillset, outcome = label.split(":", 1)
                step = Step(number, skillset, "wait", outcome, None)
            order = self.shown[here][0]
            for j, (other, result) in enumerate(post):
                if j == best or (result == post[best][1] and action is not WAIT):
                    continue
                skillset, transition = other.split(":", 1)
                if result is DONE or plan._rank_of(result) == 0:
                    step.branches.append(Branch(skillset, transition, "reached"))
                elif result in self.shown:
                    seen_order, at = self.shown[result]
                    step.branches.append(Branch(skillset, transition, "retry" if seen_order <= order else "continue", at))
                else:
                    sub, at = self.route(result, f"{number}.")
                    step.branches.append(Branch(skillset, transition, "route", at, sub))
            steps.append(step)
        return steps, joins
