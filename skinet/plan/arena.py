"""The arena of the planning game (docs/semantics.md §8, *The game*), shared by both solvers.

The game is played on the stable-marking graph of the eventless union, which
is the asynchronous product of the components' graphs (docs/semantics.md §6.4).  So the
arena is kept per component, as a :class:`LocalGame`: the component's stable
markings reachable from its live marking (:mod:`skinet.verify.component`;
invariant cascades and priorities are inside its steps) and, at each one,
its *commands* (``k.start``, ``k.interrupt``, and the events a binding commands,
docs/planning.md) and *outcomes* (``k.success.m``, ``k.failure.m``, and the other
events when they count as uncontrollable, docs/semantics.md §6.3),
each with every stable marking it may lead to.  Variants of one logical
transition are one move: the controller sends ``k.start``, not a variant, so
``Post(m, k.start)`` is the union of its variants' results.

A product marking is a tuple of local state indices, one per component;
``Post(m, c)`` of a command of component ``i`` changes index ``i`` only, and
waiting may bring any enabled outcome of any component.  ``Safe`` (the
markings forced for no property, docs/semantics.md §6.3) is kept as boxes over the local
states (:func:`skinet.verify.forced.forced_boxes`), which each solver turns
into its own set.  Cost: one breadth-first search per component (memoised per
net and marking), then the forced boxes; nothing here grows with the product.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from skinet.net.semantics import steps
from skinet.plan.goal import Goal
from skinet.props.formula import PlaceAtom
from skinet.system.model import Component, System
from skinet.verify.component import ComponentGraph, explore_component
from skinet.verify.forced import OUTCOMES, forced_boxes

COMMANDS = frozenset({"start", "interrupt"})
CACHE_SIZE = 256  # local games remembered per net

Local = tuple[int, ...]
"""A product marking: one local state index per component."""


@dataclass(frozen=True)
class Move:
    """A command or an outcome of one component at one local state."""

    name: str  # logical transition name: "init_power.start", "init_power.success.powered_on"
    kind: str  # start, interrupt, success, failure, event
    skill: str | None
    results: tuple[int, ...]  # local state indices it may lead to


@dataclass(frozen=True)
class LocalGame:
    """One component's stable graph with its moves sorted into commands and outcomes."""

    graph: ComponentGraph
    commands: tuple[tuple[Move, ...], ...]  # per local state, in the net's transition order
    outcomes: tuple[tuple[Move, ...], ...]
    command_names: tuple[str, ...]  # every command of the net, in its order (the symbolic solver's codes)

    @property
    def name(self) -> str:
        return self.graph.name

    @property
    def size(self) -> int:
        return self.graph.size


def local_game(component: Component, marking: int, events: bool = False) -> LocalGame:
    """The local game of ``component`` from its ``marking`` (memoised on the net).

    With ``events``, the graph is the full net's and events are outcomes; otherwise it is
    the eventless net's (docs/semantics.md §8: the eventless union).  Either way the commanded events
    (docs/semantics.md §9) are in it as commands: they happen only when someone commands them, and the
    pilot does so through the binding (docs/planning.md).
    """
    net = component.net if events else component.commanding
    cache: OrderedDict[int, LocalGame] = net.__dict__.setdefault("_local_games", OrderedDict())
    if marking in cache:
        cache.move_to_end(marking)
        return cache[marking]
    graph = explore_component(component.name, net, [marking])
    uncontrollable = OUTCOMES | {"event"} if events else OUTCOMES
    commands: list[tuple[Move, ...]] = []
    outcomes: list[tuple[Move, ...]] = []
    for m in graph.states:
        grouped: dict[str, tuple[str, str | None, set[int]]] = {}
        for t, results in steps(net, m):
            entry = grouped.setdefault(t.name, (t.kind, t.skill, set()))
            entry[2].update(graph.index[r] for r in results)
        moves = [Move(name, kind, skill, tuple(sorted(res))) for name, (kind, skill, res) in grouped.items()]
        ours = {mv.name for mv in moves if _command(mv.kind, mv.name, component)}
        commands.append(tuple(mv for mv in moves if mv.name in ours))
        outcomes.append(tuple(mv for mv in moves if mv.kind in uncontrollable and mv.name not in ours))
    names = tuple(dict.fromkeys(t.name for t in net.transitions if _command(t.kind, t.name, component)))
    game = LocalGame(graph, tuple(commands), tuple(outcomes), names)
    cache[marking] = game
    while len(cache) > CACHE_SIZE:
        cache.popitem(last=False)
    return game


def _command(kind: str, name: str, component: Component) -> bool:
    """Whether a move is the controller's: a skill start or interrupt, or a commanded event."""
    return kind in COMMANDS or (kind == "event" and name in component.commanded)


DONE = None
"""Where a ``run`` goal's target outcome leads: the goal is reached (not a marking)."""


@dataclass(frozen=True)
class Action:
    """A move of the controller: a command of component ``component``, or waiting (``component is None``)."""

    component: int | None
    move: Move | None


WAIT = Action(None, None)


class Arena:
    """The product of the components' local games from one combined marking, and Safe as boxes."""

    def __init__(self, system: System, marking: Mapping[str, int], events: bool = False):
        self.system = system
        self.events = events
        self.games = [local_game(c, marking[c.name], events) for c in system.components]
        self.names = [g.name for g in self.games]
        self.graphs = [g.graph for g in self.games]
        self.shape = tuple(g.size for g in self.games)
        self.root: Local = tuple(g.graph.index[marking[g.name]] for g in self.games)
        self.forced = {p.name: forced_boxes(system, self.graphs, p, events) for p in system.properties}

    @property
    def box(self) -> int:
        """Markings of the product (all reachable from the root: docs/semantics.md §6.4)."""
        n = 1
        for s in self.shape:
            n *= s
        return n

    # ------------------------------------------------------------ markings

    def local(self, marking: Mapping[str, int]) -> Local | None:
        """``marking`` as local indices, or None when it lies outside the arena."""
        out = []
        for g in self.games:
            i = g.graph.index.get(marking[g.name])
            if i is None:
                return None
            out.append(i)
        return tuple(out)

    def marking(self, local: Local) -> dict[str, int]:
        return {g.name: g.graph.states[i] for g, i in zip(self.games, local)}

    def atom(self, atom: PlaceAtom) -> tuple[int, np.ndarray]:
        """Where ``atom`` holds: its component's position and a mask over that component's local states."""
        i = self.names.index(atom.skillset)
        bit = self.graphs[i].net.place_index(atom.place)
        return i, np.array([m >> bit & 1 == 1 for m in self.graphs[i].states], dtype=bool)

    def safe_at(self, local: Local) -> bool:
        return not self.forced_for(local)

    def forced_for(self, local: Local) -> list[str]:
        """The properties ``local`` is forced for (violated now, or by outcomes alone)."""
        return [p for p, boxes in self.forced.items()
                if any(all(mask[local[i]] for i, mask in box) for box in boxes)]

    # ------------------------------------------------------------ moves

    def enabled(self, goal: Goal, relaxed: bool = False) -> list[np.ndarray]:
        """Per component, per command name (``command_names``): whether the goal lets the plan send it.

        A start needs the skill's inputs (docs/semantics.md §8, *Skill inputs*); ``relaxed`` lifts that.
        """
        out = []
        for g, c in zip(self.games, self.system.components):
            skills = {k.name: k for k in c.skillset.skills}
            ok = []
            for name in g.command_names:
                skill = skills.get(name.rsplit(".", 1)[0])
                given = goal.given(g.name, skill.name) if skill is not None else None
                ok.append(relaxed or not name.endswith(".start") or skill is None
                          or all(v.name in (given or {}) for v in skill.inputs))
            out.append(np.array(ok, dtype=bool))
        return out

    def actions(self, local: Local, allowed: Sequence[np.ndarray] | None) -> Iterator[Action]:
        """The controller's moves at ``local`` in the fixed order of ties: starts by component and
        net order (those ``allowed`` lets through, all when None), then waiting if an outcome is
        enabled, then interrupts (never interrupt a skill when waiting for it does as well)."""
        interrupts = []
        for i, (g, s) in enumerate(zip(self.games, local)):
            for mv in g.commands[s]:
                if allowed is None or allowed[i][g.command_names.index(mv.name)]:
                    if mv.kind == "interrupt":
                        interrupts.append(Action(i, mv))
                    else:
                        yield Action(i, mv)
        if any(g.outcomes[s] for g, s in zip(self.games, local)):
            yield WAIT
        yield from interrupts

    def post(self, local: Local, action: Action, goal: Goal | None) -> list[tuple[str, Local | None]]:
        """``Post(m, a)`` with the transition (``skillset:name``) behind each result; a ``run``
        goal's target outcome leads to :data:`DONE`."""
        out: list[tuple[str, Local | None]] = []
        if action.component is not None and action.move is not None:
            i = action.component
            for r in action.move.results:
                out.append((f"{self.names[i]}:{action.move.name}", local[:i] + (r,) + local[i + 1:]))
            return out
        for i, (g, s) in enumerate(zip(self.games, local)):
            for mv in g.outcomes[s]:
                label = f"{g.name}:{mv.name}"
                if goal is not None and goal.target(g.name, mv.name):
                    out.append((label, DONE))
                else:
                    out.extend((label, local[:i] + (r,) + local[i + 1:]) for r in mv.results)
        return out
