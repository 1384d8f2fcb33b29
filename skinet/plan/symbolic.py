"""The planning game over the whole product, as BDDs (docs/semantics.md §8; the symbolic solver).

Encoded as :mod:`skinet.verify.symbolic` encodes the stable graph: each
component's local state index in binary variables ``x_i``, primed copies
``y_i`` for results, and here also the index of a command in ``a_i`` (the
position of its name in the component's ``command_names``).  Per component:

* ``C_i(x_i, a_i, y_i)``: command ``a_i`` at ``x_i`` may lead to ``y_i``;
* ``O_i^o(x_i, y_i)``: outcome ``o`` at ``x_i`` may lead to ``y_i`` (one per name,
  so that a ``run`` goal can set its target outcomes apart).

The union is an asynchronous product (docs/semantics.md §6.4): a move changes one
component, so every pre-image is taken per component and no frame condition
is built.  With ``X'_i`` the set ``X`` with ``x_i`` renamed to ``y_i``::

    CPre(X) = Safe & ( OR_i EXISTS a_i. Ok_i & En_i & not EXISTS y_i. C_i & not X'_i
                     | Out & AND_i not EXISTS y_i. U_i & not X'_i )

where ``En_i = EXISTS y_i. C_i``, ``Ok_i`` the commands whose inputs the goal
gives, ``U_i`` the outcomes that are not the goal's target, ``Out`` "some
outcome is enabled"; a target outcome leads to DONE, which every set of a
``run`` goal holds, so it never spoils a wait.  ``CPre_c`` and the weak
pre-image are built alike (see the methods).  Sets range over the product of
the component graphs, all of it reachable from the live marking.

Cost: BDD operations whose size follows the structure of the components,
not the number of markings (the product of 3 + 3 corpus copies has 1.2e8);
a BDD operation cannot be interrupted, so the deadline is checked between
fixpoint steps (:mod:`skinet.plan.solve`).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

from skinet.plan.arena import DONE, Arena, Local
from skinet.plan.goal import Goal
from skinet.props.evaluate import evaluate
from skinet.verify.symbolic import cube, cubes

Function = Any  # dd.cudd.Function


def _bits(n: int) -> int:
    return max(1, (n - 1).bit_length())


class SymbolicSpace:
    """The product of an :class:`Arena` as BDDs; what every goal from one marking shares."""

    def __init__(self, arena: Arena):
        import dd.cudd

        self.arena = arena
        self.bdd = bdd = dd.cudd.BDD()
        self._and_exists = dd.cudd.and_exists
        k = len(arena.games)
        self.x = [[f"x{i}_{b}" for b in range(_bits(g.size))] for i, g in enumerate(arena.games)]
        self.y = [[f"y{i}_{b}" for b in range(_bits(g.size))] for i, g in enumerate(arena.games)]
        self.a = [[f"a{i}_{b}" for b in range(_bits(len(g.command_names)))] for i, g in enumerate(arena.games)]
        order: list[str] = []
        for i in range(k):
            order += self.a[i]
            for xb, yb in zip(self.x[i], self.y[i]):
                order += [xb, yb]
        bdd.declare(*order)
        self.xs = [v for vs in self.x for v in vs]
        self.x_sets = [set(v) for v in self.x]
        self.y_sets = [set(v) for v in self.y]
        self.xa_sets = [set(self.x[i]) | set(self.a[i]) for i in range(k)]
        self._to_y = [dict(zip(self.x[i], self.y[i])) for i in range(k)]
        self._to_x = [dict(zip(self.y[i], self.x[i])) for i in range(k)]
        self.universe = bdd.true
        for i, g in enumerate(arena.games):
            self.universe &= self.states(i, range(g.size))
        self.commands: list[Function] = []
        self.outcomes: list[dict[str, Function]] = []
        for i, g in enumerate(arena.games):
            rel = bdd.false
            per: dict[str, Function] = {}
            for s in range(g.size):
                here = self._code(self.x[i], s)
                for mv in g.commands[s]:
                    rel |= here & self._code(self.a[i], g.command_names.index(mv.name)) & self.states(i, mv.results, True)
                for mv in g.outcomes[s]:
                    per[mv.name] = per.get(mv.name, bdd.false) | (here & self.states(i, mv.results, True))
            self.commands.append(rel)
            self.outcomes.append(per)
        self.enabled = [bdd.exist(self.y_sets[i], c) for i, c in enumerate(self.commands)]
        self.waiting = bdd.false
        for i, per in enumerate(self.outcomes):
            for rel in per.values():
                self.waiting |= bdd.exist(self.y_sets[i], rel)
        self.forced = {p: self._boxes(boxes) for p, boxes in arena.forced.items()}
        forced_any = bdd.false
        for f in self.forced.values():
            forced_any |= f
        self.safe = self.universe & ~forced_any
        # Adm_i: command a_i at x is admissible, every result safe (docs/semantics.md §8, *Safe region*).
        self.admissible = [en & ~self._and_exists(c, ~self.prime(self.safe, i), self.y_sets[i])
                           for i, (c, en) in enumerate(zip(self.commands, self.enabled))]

    # ------------------------------------------------------------ sets

    def _code(self, names: Sequence[str], value: int) -> Function:
        return cube(self.bdd, names, value)

    def states(self, i: int, indices: Iterable[int], primed: bool = False) -> Function:
        """Component ``i`` in one of the local states ``indices``, the others anywhere."""
        return cubes(self.bdd, self.y[i] if primed else self.x[i], indices)

    def _boxes(self, boxes: list[list[tuple[int, Any]]]) -> Function:
        out = self.bdd.false
        for box in boxes:
            inside = self.universe
            for i, mask in box:
                inside &= self.states(i, [s for s, v in enumerate(mask) if v])
            out |= inside
        return out

    def prime(self, f: Function, i: int) -> Function:
        return self.bdd.let(self._to_y[i], f)

    def assignment(self, local: Local) -> dict[str, bool]:
        return {v: bool(s >> b & 1) for names, s in zip(self.x, local) for b, v in enumerate(names)}


class SymbolicGame:
    """One goal's game on a :class:`SymbolicSpace` (the :class:`skinet.plan.solve.Game` of BDDs)."""

    def __init__(self, space: SymbolicSpace, goal: Goal, relaxed: bool = False):
        self.space = space
        self.goal = goal
        bdd = space.bdd
        arena = space.arena
        self.run = goal.kind == "run"
        self.ok = []
        for i, mask in enumerate(arena.enabled(goal, relaxed)):
            f = bdd.false
            for j, allowed in enumerate(mask):
                if allowed:
                    f |= space._code(space.a[i], j)
            self.ok.append(f)
        self.others: list[Function] = []  # U_i: outcomes that are not the goal's target
        hit = bdd.false  # some target outcome is enabled
        for i, per in enumerate(space.outcomes):
            u = bdd.false
            for name, rel in per.items():
                if goal.target(arena.names[i], name):
                    hit |= bdd.exist(space.y_sets[i], rel)
                else:
                    u |= rel
            self.others.append(u)
        self.hit = hit
        self.safe = space.safe
        if goal.kind == "reach":
            def atom(a):  # noqa: ANN001, ANN202
                i, mask = arena.atom(a)
                return space.states(i, [s for s, v in enumerate(mask) if v])

            self.goal_markings = space.universe & evaluate(goal.formula, atom,
                                                           lambda v: bdd.true if v else bdd.false)
            self.target = self.goal_markings & space.safe
        else:
            self.goal_markings = hit & space.universe
            self.target = bdd.false  # DONE alone: outside the encoding, held by every set (member)

    # ------------------------------------------------------------ fixpoints (solve.Game)

    def _none_outside(self, rel: Function, x: Function, i: int) -> Function:
        """``not EXISTS y_i. rel & not x'_i``: every ``y_i`` that ``rel`` allows lies in ``x``."""
        return ~self.space._and_exists(rel, ~self.space.prime(x, i), self.space.y_sets[i])

    def _some_inside(self, rel: Function, x: Function, i: int) -> Function:
        return self.space._and_exists(rel, self.space.prime(x, i), self.space.y_sets[i])

    def _command(self, i: int, body: Function) -> Function:
        return self.space.bdd.exist(set(self.space.a[i]), self.ok[i] & self.space.enabled[i] & body)

    def _wait_all(self, x: Function) -> Function:
        out = self.space.waiting
        for i, u in enumerate(self.others):
            out &= self._none_outside(u, x, i)
        return out

    def _wait_any(self, x: Function) -> Function:
        out = self.hit
        for i, u in enumerate(self.others):
            out |= self._some_inside(u, x, i)
        return out

    def strong_pre(self, x: Function) -> Function:
        pre = self._wait_all(x)
        for i, c in enumerate(self.space.commands):
            pre |= self._command(i, self._none_outside(c, x, i))
        return pre & self.safe

    def cyclic_pre(self, z: Function, x: Function) -> Function:
        pre = self._wait_all(z) & self._wait_any(x)
        for i, c in enumerate(self.space.commands):
            pre |= self._command(i, self._none_outside(c, z, i) & self._some_inside(c, x, i))
        return pre & self.safe & z

    def weak_pre(self, x: Function) -> Function:
        pre = self._wait_any(x)
        for i, c in enumerate(self.space.commands):
            pre |= self._command(i, self.space.admissible[i] & self._some_inside(c, x, i))
        return pre & self.safe

    def same(self, a: Function, b: Function) -> bool:
        return a == b

    # ------------------------------------------------------------ queries

    def member(self, s: Function, local: Local | None) -> bool:
        if local is DONE:
            return self.run
        return self.space.bdd.let(self.space.assignment(local), s) == self.space.bdd.true

    def empty(self, s: Function) -> bool:
        return s == self.space.bdd.false

    def pick(self, s: Function) -> Local:
        """The least marking of ``s`` by local indices, component after component (the explicit
        engine's first in code order: the same example in both)."""
        sp = self.space
        rest = s & sp.universe
        out = []
        for i, g in enumerate(sp.arena.games):
            for state in range(g.size):
                here = rest & sp._code(sp.x[i], state)
                if here != sp.bdd.false:
                    out.append(state)
                    rest = here
                    break
        return tuple(out)

    def preimage(self, s: Function, allowed: bool) -> Function:
        """Markings with a move into ``s``: any command (``allowed``: only those of A(m)) or outcome."""
        sp = self.space
        out = sp.bdd.false
        for i, c in enumerate(sp.commands):
            rel = c & self.ok[i] & sp.admissible[i] if allowed else c
            out |= sp.bdd.exist(set(sp.a[i]), self._some_inside(rel, s, i))
            for o in sp.outcomes[i].values():
                out |= self._some_inside(o, s, i)
        return out & (self.safe if allowed else sp.universe)

    def forced(self, prop: str) -> Function:
        return self.space.forced[prop]
