"""The planning game on the explored graph, as boolean arrays (docs/semantics.md §8; the explicit solver).

The product is explored breadth-first from the live marking within the
budget and the memory limit (:func:`skinet.verify.explore.explore_graphs`).
Every expanded marking gets its moves as flat arrays: one *row* per command
(marking, command) with one *edge* per result, and one edge per result of
each enabled outcome for waiting.  Sets are boolean arrays over the explored
index space plus one last element, DONE, where a ``run`` goal's target
outcome leads.  A frontier marking (stored, not expanded) has no moves, so it
is never in ``CPre``: a plan found on a partial exploration never counts on
what lies beyond it, and ``none`` is only said when the exploration is
complete (:mod:`skinet.plan.planner`).

Cost: the exploration, then O(E) to build the E edges (vectorised per
component, as ``expand_edges`` in :mod:`skinet.verify.explore`), then O(E)
per fixpoint step (a ``bincount`` over the edges).  Memory: about 40 bytes
per edge on top of the exploration's storage.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from skinet.plan.arena import DONE, Arena, Local
from skinet.plan.goal import Goal
from skinet.props.evaluate import evaluate
from skinet.verify.explore import CHUNK, Deadline, StateSpace, explore_graphs

# Planning estimates for explore_graphs: the game's arrays and fixpoints cost
# about as much per marking as a few mu1 results.
PROPERTIES_EQUIVALENT = 4


@dataclass
class _Rows:
    """Moves of one kind at the expanded markings: ``src[r]``, ``move[r]``; edges ``row[e] -> dst[e]``."""

    src: np.ndarray
    move: np.ndarray
    row: np.ndarray
    dst: np.ndarray


class ExplicitSpace:
    """The explored product with its moves; what every goal from one marking shares."""

    def __init__(self, arena: Arena, deadline: Deadline, memory_limit: int | None):
        self.arena = arena
        self.space: StateSpace = explore_graphs(arena.graphs, deadline=deadline, memory_limit=memory_limit,
                                                edges=True, properties=PROPERTIES_EQUIVALENT)
        n = self.space.size
        self.n = n
        self.done = n
        self.stored = np.zeros(n + 1, dtype=bool)
        self.stored[:n] = self.space.stored()
        expanded = np.flatnonzero(self.space.expanded() & self.space.stored()) if n else np.empty(0, np.int64)
        # Global ids: commands by (component, position in command_names), outcomes by (component, name).
        self.command_ids: list[dict[str, int]] = []
        self.outcome_ids: list[dict[str, int]] = []
        self.outcome_names: list[tuple[int, str]] = []
        base = 0
        for i, g in enumerate(arena.games):
            self.command_ids.append({name: base + j for j, name in enumerate(g.command_names)})
            base += len(g.command_names)
            names: dict[str, int] = {}
            for moves in g.outcomes:
                for mv in moves:
                    if mv.name not in names:
                        names[mv.name] = len(self.outcome_names)
                        self.outcome_names.append((i, mv.name))
            self.outcome_ids.append(names)
        self.n_commands = base
        self.commands = self._rows(expanded, "commands")
        self.outcomes = self._rows(expanded, "outcomes")
        self.waiting = np.zeros(n + 1, dtype=bool)
        self.waiting[self.outcomes.src] = True
        forced = {p: self._boxes(boxes) for p, boxes in arena.forced.items()}
        self.forced = forced
        self.safe = self.stored.copy()
        for f in forced.values():
            self.safe &= ~f
        # A command is admissible when every result is safe (docs/semantics.md §8, *Safe region*).
        unsafe_edge = ~self.safe[self.commands.dst]
        self.admissible = np.bincount(self.commands.row[unsafe_edge], minlength=self.commands.src.size) == 0

    def _boxes(self, boxes: list[list[tuple[int, np.ndarray]]]) -> np.ndarray:
        out = np.zeros(self.n + 1, dtype=bool)
        for box in boxes:
            inside = self.stored[:self.n].copy()
            for i, mask in box:
                inside &= self.space.local(mask, i)
            out[:self.n] |= inside
        return out

    def _rows(self, expanded: np.ndarray, kind: str) -> _Rows:
        """Every command (or outcome) of every expanded marking, chunk by chunk."""
        src, move, row, dst = [], [], [], []
        rows = 0
        for lo in range(0, expanded.size, CHUNK):
            idx = expanded[lo:lo + CHUNK]
            codes = self.space.code_of(idx)
            for i, g in enumerate(self.arena.games):
                table = _table(g.commands if kind == "commands" else g.outcomes,
                               self.command_ids[i] if kind == "commands" else self.outcome_ids[i])
                stride = self.space.strides[i]
                digit = (codes // stride) % self.space.shape[i]
                count = table.count[digit]
                total = int(count.sum())
                if not total:
                    continue
                local_row = _ranges(table.first[digit], count)
                src.append(np.repeat(idx, count))
                move.append(table.move[local_row])
                rcount = table.rcount[local_row]
                results = table.results[_ranges(table.rfirst[local_row], rcount)]
                from_digit = np.repeat(np.repeat(digit, count), rcount)
                target_codes = np.repeat(np.repeat(codes, count), rcount) + (results - from_digit) * stride
                row.append(rows + np.repeat(np.arange(total, dtype=np.int64), rcount))
                dst.append(self.space.index(target_codes))
                rows += total
        empty = np.empty(0, dtype=np.int64)
        cat = lambda parts: np.concatenate(parts) if parts else empty  # noqa: E731
        return _Rows(cat(src), cat(move), cat(row), cat(dst))

    # ------------------------------------------------------------ markings

    def index(self, local: Local | None) -> int:
        """Index of a product marking (DONE for :data:`DONE`), -1 when not stored."""
        if local is DONE:
            return self.done
        code = sum(int(s) * int(st) for s, st in zip(local, self.space.strides))
        return int(self.space.index(np.array([code], dtype=np.int64))[0])

    def local(self, index: int) -> Local:
        code = int(self.space.code_of(np.array([index]))[0])
        return tuple(int(code // st % n) for st, n in zip(self.space.strides, self.space.shape))


@dataclass
class _Table:
    """A component's moves of one kind, flattened: per local state ``first``/``count`` rows,
    per row its move id and ``rfirst``/``rcount`` results."""

    first: np.ndarray
    count: np.ndarray
    move: np.ndarray
    rfirst: np.ndarray
    rcount: np.ndarray
    results: np.ndarray


def _table(per_state: Sequence[Sequence[object]], ids: dict[str, int]) -> _Table:
    count = np.array([len(m) for m in per_state], dtype=np.int64)
    first = np.concatenate(([0], np.cumsum(count)[:-1])).astype(np.int64)
    flat = [mv for moves in per_state for mv in moves]
    rcount = np.array([len(mv.results) for mv in flat], dtype=np.int64)  # type: ignore[attr-defined]
    rfirst = np.concatenate(([0], np.cumsum(rcount)[:-1])).astype(np.int64) if flat else np.empty(0, np.int64)
    return _Table(first, count, np.array([ids[mv.name] for mv in flat], dtype=np.int64),  # type: ignore[attr-defined]
                  rfirst, rcount, np.array([r for mv in flat for r in mv.results], dtype=np.int64))  # type: ignore


def _ranges(first: np.ndarray, count: np.ndarray) -> np.ndarray:
    """``concatenate([arange(f, f + c) for f, c in zip(first, count)])``, vectorised."""
    total = int(count.sum())
    if not total:
        return np.empty(0, dtype=np.int64)
    starts = np.repeat(first - np.cumsum(count) + count, count)
    return starts + np.arange(total, dtype=np.int64)


class ExplicitGame:
    """One goal's game on an :class:`ExplicitSpace` (the :class:`skinet.plan.solve.Game` of arrays)."""

    def __init__(self, space: ExplicitSpace, goal: Goal, relaxed: bool = False):
        self.space = space
        self.goal = goal
        arena = space.arena
        n = space.n
        enabled = np.concatenate(arena.enabled(goal, relaxed) or [np.empty(0, bool)])
        c = space.commands
        self.allowed = enabled[c.move] & space.admissible
        self.safe = space.safe
        target_moves = np.array([goal.target(arena.names[i], name) for i, name in space.outcome_names], dtype=bool)
        o = space.outcomes
        self.wait_src = o.src[o.row]
        hits = target_moves[o.move[o.row]] if o.row.size else np.zeros(0, dtype=bool)
        self.wait_dst = np.where(hits, space.done, o.dst)
        self.goal_markings = np.zeros(n + 1, dtype=bool)  # where the goal holds or its outcome is enabled
        if goal.kind == "reach":
            def atom(a):  # noqa: ANN001, ANN202
                i, mask = arena.atom(a)
                return space.space.local(mask, i)

            value = evaluate(goal.formula, atom, lambda v: np.full(n, v))
            self.goal_markings[:n] = np.broadcast_to(value, (n,)) & space.stored[:n]
            self.target = self.goal_markings & space.safe
        else:
            self.goal_markings[self.wait_src[hits]] = True
            self.target = np.zeros(n + 1, dtype=bool)
            self.target[space.done] = True

    # ------------------------------------------------------------ fixpoints (solve.Game)

    def _commands_all(self, x: np.ndarray) -> np.ndarray:
        """Per command row: every result in ``x``."""
        c = self.space.commands
        return np.bincount(c.row[~x[c.dst]], minlength=c.src.size) == 0

    def _commands_any(self, x: np.ndarray) -> np.ndarray:
        c = self.space.commands
        return np.bincount(c.row[x[c.dst]], minlength=c.src.size) > 0

    def _waits_all(self, x: np.ndarray) -> np.ndarray:
        """Per marking: waiting is a move there and every outcome's result is in ``x``."""
        return self.space.waiting & (np.bincount(self.wait_src[~x[self.wait_dst]], minlength=x.size) == 0)

    def _waits_any(self, x: np.ndarray) -> np.ndarray:
        return np.bincount(self.wait_src[x[self.wait_dst]], minlength=x.size) > 0

    def _rows_to_markings(self, ok: np.ndarray) -> np.ndarray:
        out = np.zeros(self.space.n + 1, dtype=bool)
        out[self.space.commands.src[ok]] = True
        return out

    def strong_pre(self, x: np.ndarray) -> np.ndarray:
        pre = self._rows_to_markings(self.allowed & self._commands_all(x)) | self._waits_all(x)
        return pre & self.safe

    def cyclic_pre(self, z: np.ndarray, x: np.ndarray) -> np.ndarray:
        commands = self.allowed & self._commands_all(z) & self._commands_any(x)
        pre = self._rows_to_markings(commands) | (self._waits_all(z) & self._waits_any(x))
        return pre & self.safe & z

    def weak_pre(self, x: np.ndarray) -> np.ndarray:
        pre = self._rows_to_markings(self.allowed & self._commands_any(x)) | (self.space.waiting & self._waits_any(x))
        return pre & self.safe

    def same(self, a: np.ndarray, b: np.ndarray) -> bool:
        return bool(np.array_equal(a, b))

    # ------------------------------------------------------------ queries

    def member(self, s: np.ndarray, local: Local | None) -> bool:
        i = self.space.index(local)
        return i >= 0 and bool(s[i])

    def empty(self, s: np.ndarray) -> bool:
        return not s.any()

    def pick(self, s: np.ndarray) -> Local:
        """The first marking of ``s`` (in code order)."""
        return self.space.local(int(np.flatnonzero(s[:self.space.n])[0]))

    def preimage(self, s: np.ndarray, allowed: bool) -> np.ndarray:
        """Markings with a move into ``s``: any command (``allowed``: only those of A(m)) or outcome."""
        c = self.space.commands
        hit = s[c.dst] & (self.allowed[c.row] if allowed else True)
        out = np.zeros(self.space.n + 1, dtype=bool)
        out[c.src[c.row[hit]]] = True
        o = self.space.outcomes
        out[o.src[o.row[s[o.dst]]]] = True
        return out & (self.safe if allowed else True)

    def forced(self, prop: str) -> np.ndarray:
        return self.space.forced[prop]
