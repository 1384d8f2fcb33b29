"""An observer's board updates as Foxglove channel messages (docs/foxglove.md).

:class:`Translator` turns the updates of a :class:`~services.dashboard.board.Board`
(the operator's picture, fed by a Zenoh observer or by a recorded log) into
messages of the channels of :mod:`skinet.wire.foxglove`: the monitor's messages
as they are, one message per violation and per divergence, the plot series per
step, and ``foxglove.Log`` lines (one per step, per unsafe command newly warned
about, per violation, per divergence and per pilot change, and one for steps a
view did not show).  Log times are the
messages' own stamps, so a bundle replays on the timeline of the run.
:class:`Round` is a view's flood policy: past a few steps in one of its rounds, it shows the last of the live
picture and every violation, divergence and pilot change, and says how many steps it did not show.  Pure: no
I/O.  Cost: O(size of the update) per update; it keeps O(unsafe commands) to say
which warnings are new.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from typing import Any

from skinet.verify.explain import warning_line
from skinet.wire import foxglove as fx
from skinet.wire.limits import FEED_FLOOD_ROUND, FEED_ROUND, FEED_STEPS
from skinet.wire.messages import UnsafeEntry

Out = tuple[str, dict[str, Any], int]  # (topic, JSON message, log time in ns)
# Seconds between a view's rounds (50 a second); past STEPS_PER_ROUND steps in a round, the last of each kind,
# and rounds every FLOOD_ROUND seconds while steps come faster: the monitor's feed keeps the same rhythm.
ROUND, STEPS_PER_ROUND, FLOOD_ROUND = FEED_ROUND, FEED_STEPS, FEED_FLOOD_ROUND
PICTURE = ("state", "verdicts", "unsafe", "state_space")  # board updates of which the last one is the picture
UNSHOWN = ("point", "model", "alive")  # board updates a Translator ignores


class Round:
    """A view's round of board updates, folded as they come: all of them up to ``most`` steps; past it (a flood: a
    robot makes a few steps a second) only the violations, divergences, pilot changes and restarts in order, and
    the last state, verdicts, report and state space.  :meth:`shown` gives them, past ``most`` with a ``skipped``
    note for the steps not shown (``length``: the round's length in seconds, for the note).  Cost: O(1) per
    update once past ``most`` steps, so that a flood costs a view little in the thread that receives it."""

    def __init__(self, most: int, length: float):
        self.most = most
        self.length = length
        self.updates: list[dict[str, Any]] = []  # in order; past ``most`` steps, none of the live picture
        self.steps = 0  # steps begun in this round
        self._seq: int | None = None
        self._last: dict[str, dict[str, Any]] = {}  # past ``most`` steps: the last of each kind of the picture

    @property
    def flood(self) -> bool:
        return self.steps > self.most

    def add(self, updates: Iterable[dict[str, Any]]) -> None:
        for u in updates:
            kind = u["kind"]
            if kind == "state" and u["message"]["seq"] != self._seq:
                self._seq = u["message"]["seq"]
                self.steps += 1
            if not self.flood:
                self.updates.append(u)
            elif kind in PICTURE:
                self._last[kind] = u
            elif kind not in UNSHOWN:
                self.updates.append(u)

    def shown(self) -> list[dict[str, Any]]:
        if not self.flood:
            return self.updates
        last: dict[str, dict[str, Any]] = {}
        kept = []
        skipped = self.steps - 1
        for u in self.updates:
            if u["kind"] in PICTURE:
                last[u["kind"]] = u
            elif u["kind"] == "skipped":  # a pipe's reader already left steps out: one note for all
                skipped += u["steps"]
            elif u["kind"] not in UNSHOWN:
                kept.append(u)
        last.update(self._last)
        return [*kept, *(last[k] for k in PICTURE if k in last),
                {"kind": "skipped", "steps": skipped, "most": self.most, "round": self.length}]


class Translator:
    """Board updates -> channel messages (not thread-safe)."""

    def __init__(self, system: str, clock: Callable[[], float] = time.time):
        self.system = system
        self.clock = clock
        self.violations = 0
        self.divergences = 0
        self._warned: set[tuple[str, str, str, str]] = set()
        self._fresh_at: float | None = None  # stamp of the last fresh prediction
        self._state: dict[str, Any] | None = None
        self._unsafe: dict[str, Any] | None = None
        self._violated = 0
        self._pilot: tuple[str, int, str] | None = None  # (goal, id, state) last logged

    def feed(self, updates: Iterable[dict[str, Any]]) -> list[Out]:
        out: list[Out] = []
        for u in updates:
            out += self._one(u)
        return out

    def snapshot(self, snap: dict[str, Any]) -> list[Out]:
        """The messages a snapshot (a view starting mid-run) gives: the last of each kind, after the violations
        and divergences so far (the series counts them)."""
        updates: list[dict[str, Any]] = [{"kind": "violation", "violation": v} for v in snap.get("violations", [])]
        if snap.get("divergences"):
            updates.append({"kind": "divergences", "added": snap["divergences"]})
        for kind in ("state", "verdicts", "unsafe", "state_space", "pilot"):
            if snap.get(kind) is not None:
                updates.append({"kind": kind, "message": snap[kind], "t": snap.get("state_space_t")})
        return self.feed(updates)

    def _log(self, t: float, level: int, text: str) -> Out:
        return fx.LOG, fx.log_line(t, level, text, self.system), fx.nanoseconds(t)

    def _one(self, u: dict[str, Any]) -> list[Out]:
        kind = u["kind"]
        if kind == "state":
            m = u["message"]
            new_step = self._state is None or (m["seq"], m["event"]) != (self._state["seq"], self._state["event"])
            self._state = m
            out: list[Out] = [(fx.STATE, m, fx.nanoseconds(m["stamp"]))]
            if new_step:
                text = f"step {m['seq']}: {m['event'] or 'start'}"
                if m.get("divergence"):
                    text += f" (model divergence: {m['divergence']})"
                out.append(self._log(m["stamp"], fx.WARNING if m.get("divergence") else fx.INFO, text))
            stale = [f"{n} {s['state']}: {s['reason']}" for n, s in m.get("sync", {}).items() if s["state"] != "live"]
            if stale:
                out.append(self._log(m["stamp"], fx.WARNING, "state not vouched for: " + "; ".join(stale)))
            return out
        if kind == "verdicts":
            m = u["message"]
            self._violated = sum(not p["holds"] for p in m["properties"])
            return [(fx.VERDICTS, m, fx.nanoseconds(m["stamp"]))]
        if kind == "unsafe":
            m = u["message"]
            self._unsafe = m
            if not m["prediction_stale"]:
                self._fresh_at = m["stamp"]
            out = [(fx.UNSAFE, m, fx.nanoseconds(m["stamp"]))]
            now = {(e["skillset"], e["transition"], e["property"], e["constraint"]) for e in m["unsafe"]}
            for e in m["unsafe"]:
                if (e["skillset"], e["transition"], e["property"], e["constraint"]) not in self._warned:
                    out.append(self._log(m["stamp"], fx.WARNING,
                                         f"step {m['seq']}: unsafe {warning_line(UnsafeEntry(**e))}"))
            self._warned = now
            out.append(self._series(m["stamp"], m["seq"]))
            return out
        if kind == "violation":
            v = u["violation"]
            self.violations = max(self.violations, v["n"] + 1)
            where = "already violated when this view joined" if v["joined"] else f"at {v['event']}"
            return [(fx.VIOLATIONS, v, fx.nanoseconds(v["t"])),
                    self._log(v["t"], fx.ERROR, f"step {v['seq']}: VIOLATED {v['property']} {where}")]
        if kind == "divergences":
            out = []
            for d in u["added"]:
                if d["kind"] == "violation":
                    continue  # an onset the monitor lists for late views: the board made it a violation update
                self.divergences += 1
                what = "manager restart" if d["kind"] == "restart" else "model divergence"
                why = "; ".join(w for w in (d.get("reason", ""), d.get("info", "")) if w)
                out += [(fx.DIVERGENCES, d, fx.nanoseconds(d["stamp"])),
                        self._log(d["stamp"], fx.ERROR, f"step {d['seq']}: {what}: {d['event']}: {why}")]
            return out
        if kind == "state_space":
            m = u["message"]
            return [(fx.STATE_SPACE, m, fx.nanoseconds(m["stamp"]))]
        if kind == "pilot":
            m = u["message"]
            out = [(fx.PILOT, m, fx.nanoseconds(m["stamp"]))]
            goal = m["goals"][m["index"]] if m["index"] < len(m["goals"]) else ""
            key = (goal, m["goal_id"], m["state"])
            if key != self._pilot:
                self._pilot = key
                nxt = m.get("next")
                text = f"pilot: {m['state']}" + (f" goal {m['goal_id']} '{goal}'" if goal else "") + (
                    f": {m['reason']}" if m["reason"] else "") + (
                    f"; next {nxt['skillset']}:{nxt['transition']}" if nxt else "")
                out.append(self._log(m["stamp"], fx.ERROR if m["state"] == "failed" else fx.INFO, text))
            return out
        if kind == "skipped":  # Round, or services/foxglove/feed.py: the view fell behind a flood of steps
            st = self._state or {}
            return [self._log(st.get("stamp") or self.clock(), fx.WARNING,
                              f"{u['steps']} steps before step {st.get('seq', '?')} not shown: more than "
                              f"{u['most']} steps in {u['round'] * 1000:g} ms, the view shows the last of each round")]
        if kind == "restart":
            t = u.get("t") or self.clock()
            return [self._log(t, fx.WARNING, f"monitor restarted (run {u['epoch']} of this view)")]
        return []

    def _series(self, t: float, seq: int) -> Out:
        u = self._unsafe or {}
        age = 0.0 if self._fresh_at is None else max(0.0, t - self._fresh_at)
        return fx.SERIES, {"seq": seq, "violated": self._violated, "violations": self.violations,
                           "unsafe": len(u.get("unsafe", [])), "literal": u.get("literal_count", 0),
                           "prediction_stale": bool(u.get("prediction_stale", False)),
                           "prediction_age": age, "divergences": self.divergences}, fx.nanoseconds(t)
