"""What an operator view knows of one running system, from the monitor's messages (docs/semantics.md §7).

:class:`Board` is fed the messages an observer receives on ``skinet/<system>/**``
(no I/O here) and keeps: the last :class:`LiveState`, :class:`Verdicts`,
:class:`UnsafeReport` and :class:`StateSpaceReport`; the model bundle; the live
service instances (liveliness tokens); one :class:`StepRecord`-like point per
monitor step for the timeline (paper Fig. 3/4); the violations, each with
the step and event where its property went from holding to failing (``joined``: a property already
violated at the first step this view saw, past step 0: its onset is not known here); and the
model divergences and manager restarts of every monitor run it saw
(:class:`Divergences`, kept by monitor instance and entry number, the last
:data:`KEPT_DIVERGENCES`; issue 27 item 4); and the pilot's last status
(:class:`PilotStatus`, docs/semantics.md §8: its goal, state, plan and next command).

A monitor restart shows as a step counter going back: a new *epoch* starts, the
timeline keeps the previous points.  The same step published again with a later
stamp (its skillsets' sync states changed, docs/semantics.md §7) replaces the shown state.  Messages older than what is
shown (a late reply to the start-up query) are ignored; a reply with an earlier step but a later stamp than the
shown one comes from a restarted monitor whose publications the view missed, and starts a new epoch too.  Every
:meth:`Board.feed` returns the updates to send to views, as JSON-able dicts ``{"kind": ..., ...}``; applying
them twice is harmless (points, violations and divergences carry their index).  Cost: O(1)
per message (O(E) for a divergence list of E entries), O(H) memory for H timeline points (bounded).
"""

from __future__ import annotations

from collections import OrderedDict, deque
from typing import Any

from pydantic import BaseModel

from services.monitor.violations import onset_property
from skinet.errors import SkinetError
from skinet.system.model import System
from skinet.wire.convert import system_from_bundle
from skinet.wire.messages import (
    CanonicalEvent, Divergences, LiveState, ModelBundle, PilotStatus, StateSpaceReport, UnsafeReport, Verdicts,
)

Update = dict[str, Any]
MAX_PENDING = 8  # verdicts and reports kept while their step's state is on its way
KEPT_DIVERGENCES = 1024  # divergences and restarts kept, over every monitor run seen
MAX_RUNS = 64  # monitor runs whose divergence counts are kept


class Board:
    """The operator's picture of system ``system`` (not thread-safe)."""

    def __init__(self, system: str, history: int = 5000, model: System | None = None):
        self.system = system
        self.lanes: dict[str, Any] = {} if model is None else lanes(model)
        self.state: LiveState | None = None
        self.verdicts: Verdicts | None = None
        self.unsafe: UnsafeReport | None = None
        self.state_space: StateSpaceReport | None = None
        self.state_space_t: float | None = None  # receive time of the last report
        self.model: ModelBundle | None = None
        self.alive: dict[str, set[str]] = {}  # service -> instance ids
        self.epoch = 0
        self.points: deque[dict[str, Any]] = deque(maxlen=history)
        self.violations: list[dict[str, Any]] = []
        self.events = 0  # canonical events seen
        self._index = 0  # points ever added (their "i")
        self._last_seq = -1
        self._holds: dict[str, bool] = {}
        self._held_at: dict[str, int] = {}  # property -> the last step this view saw it hold (this epoch)
        self._pending: list[tuple[Verdicts | UnsafeReport, bool]] = []
        self.pilot: PilotStatus | None = None  # the pilot's last status (docs/semantics.md §8)
        self.divergences: OrderedDict[tuple[str, int], dict[str, Any]] = OrderedDict()  # (monitor, n) -> entry
        self._noted: OrderedDict[str, int] = OrderedDict()  # monitor run -> entries it noted (listed or older)
        self._forgotten = 0  # entries noted by runs no longer in _noted

    # -- feeding ------------------------------------------------------------------------

    def feed(self, message: BaseModel, t: float, initial: bool = False) -> list[Update]:
        """Take one message received at ``t``; ``initial``: a reply to the start-up query."""
        if isinstance(message, LiveState):
            return self._state(message, t, initial)
        if isinstance(message, Verdicts):
            return self._verdicts(message, initial)
        if isinstance(message, UnsafeReport):
            return self._unsafe(message, initial)
        if isinstance(message, StateSpaceReport):
            self.state_space, self.state_space_t = message, t
            return [{"kind": "state_space", "message": _json(message), "t": t}]
        if isinstance(message, ModelBundle):
            if self.model is not None and self.model.digest == message.digest:
                return []
            self.model = message
            try:
                self.lanes = lanes(system_from_bundle(message))
            except SkinetError:
                pass  # keep the lanes we had: the page still shows what the messages say
            return [{"kind": "model", "model": self._model_json()}]
        if isinstance(message, CanonicalEvent):
            self.events += 1
            return []
        if isinstance(message, Divergences):
            return self._divergences(message)
        if isinstance(message, PilotStatus):
            return self._pilot(message)
        return []

    def _pilot(self, msg: PilotStatus) -> list[Update]:
        """The pilot's status, unless an older copy of the one shown (same instance, lower or equal seq)."""
        if self.pilot is not None and msg.pilot == self.pilot.pilot and msg.seq <= self.pilot.seq:
            return []
        self.pilot = msg
        return [{"kind": "pilot", "message": _json(msg)}]

    def token(self, key: str, alive: bool) -> list[Update]:
        """A liveliness token ``skinet/<system>/alive/<service>/<id>`` appeared or vanished."""
        parts = key.split("/")
        if len(parts) != 5:
            return []
        service, instance = parts[3], parts[4]
        ids = self.alive.setdefault(service, set())
        if alive == (instance in ids):
            return []
        (ids.add if alive else ids.discard)(instance)
        return [{"kind": "alive", "alive": self._alive_json()}]

    def _state(self, msg: LiveState, t: float, initial: bool) -> list[Update]:
        out: list[Update] = []
        if self.state is not None and (msg.seq, msg.stamp) == (self.state.seq, self.state.stamp):
            return []  # the same step again (the start-up query)
        if self.state is not None and (msg.seq, msg.event) == (self.state.seq, self.state.event) and \
                msg.stamp > self.state.stamp:
            self.state = msg  # the step published again: its sync state changed (docs/semantics.md §7)
            return [{"kind": "state", "message": _json(msg)}]
        if msg.seq <= self._last_seq:
            if initial and self.state is not None and msg.stamp <= self.state.stamp:
                return []  # an older copy than what is shown
            # Else a restarted monitor; a get's answer says so when its publications were missed (link down).
            self.epoch += 1
            self.verdicts = self.unsafe = None
            self._holds, self._held_at = {}, {}
            out.append({"kind": "restart", "epoch": self.epoch, "t": t})
        self._last_seq = msg.seq
        self.state = msg
        point = {"i": self._index, "epoch": self.epoch, "seq": msg.seq, "t": msg.stamp, "event": msg.event,
                 "divergence": msg.divergence,
                 "skillsets": {k: v.model_dump() for k, v in msg.skillsets.items()},
                 "holds": dict(self._holds), "unsafe": None, "literal": None}
        self._index += 1
        self.points.append(point)
        out += [{"kind": "state", "message": _json(msg)}, {"kind": "point", "point": point}]
        waiting, self._pending = self._pending, []
        for message, was_initial in waiting:  # what arrived before its step's state
            out += self.feed(message, t, was_initial)
        return out

    def _mine(self, msg: Verdicts | UnsafeReport, initial: bool) -> bool:
        """Whether ``msg`` belongs to the shown step; one of a step not shown yet waits for it.

        Verdicts carry their step's stamp; an UnsafeReport may be a later refresh of it."""
        st = self.state
        if st is not None and msg.seq == st.seq and (msg.stamp == st.stamp if isinstance(msg, Verdicts)
                                                      else msg.stamp >= st.stamp):
            return True
        if st is None or msg.stamp > st.stamp:
            self._pending = [*self._pending[-(MAX_PENDING - 1):], (msg, initial)]
        return False

    def _verdicts(self, msg: Verdicts, initial: bool) -> list[Update]:
        if not self._mine(msg, initial) or (initial and self.verdicts is not None and self.verdicts.seq >= msg.seq):
            return []
        self.verdicts = msg
        out: list[Update] = [{"kind": "verdicts", "message": _json(msg)}]
        now = {v.name: v.holds for v in msg.properties}
        point = self._point(msg.seq)
        for name, holds in now.items():
            if holds:
                self._held_at[name] = msg.seq
            if holds or self._holds.get(name) is False:
                continue
            # Violated where this view knows nothing before (it joined late): not an onset at this step.
            joined = name not in self._holds and msg.seq > 0
            after = self._held_at.get(name, -1)  # a view that missed steps (a gap) sees the onset in the list
            if any(v["property"] == name and v["seq"] > after and v["epoch"] == self.epoch and v.get("listed")
                   for v in self.violations):
                continue  # the monitor's list named its onset already (its step, its event)
            v = {"n": len(self.violations), "property": name, "seq": msg.seq, "epoch": self.epoch,
                 "event": "" if joined or point is None else point["event"], "t": point["t"] if point else msg.stamp,
                 "joined": joined}
            self.violations.append(v)
            out.append({"kind": "violation", "violation": v})
        self._holds = now
        if point is not None:
            point["holds"] = dict(now)
            out.append({"kind": "point", "point": point})
        return out

    def _unsafe(self, msg: UnsafeReport, initial: bool) -> list[Update]:
        if not self._mine(msg, initial) or (initial and self.unsafe is not None and self.unsafe.stamp >= msg.stamp):
            return []
        self.unsafe = msg
        out: list[Update] = [{"kind": "unsafe", "message": _json(msg)}]
        point = self._point(msg.seq)
        if point is not None:
            point["unsafe"], point["literal"] = len(msg.unsafe), msg.literal_count
            point["stale"] = msg.prediction_stale
            out.append({"kind": "point", "point": point})
        return out

    def _point(self, seq: int) -> dict[str, Any] | None:
        for point in reversed(self.points):
            if point["epoch"] == self.epoch and point["seq"] == seq:
                return point
            if point["epoch"] != self.epoch or point["seq"] < seq:
                return None
        return None

    # -- divergences and manager restarts (issue 27 item 4) ---------------------------------

    def _divergences(self, msg: Divergences) -> list[Update]:
        """A monitor's list: its entries not seen yet are added (an older copy adds nothing)."""
        noted = msg.older + len(msg.entries)
        if noted <= self._noted.get(msg.monitor, 0):
            return []
        self._noted[msg.monitor] = noted
        self._noted.move_to_end(msg.monitor)
        if len(self._noted) > MAX_RUNS:  # its entries go with it, counted as older
            run, count = self._noted.popitem(last=False)
            self._forgotten += count
            for key in [k for k in self.divergences if k[0] == run]:
                del self.divergences[key]
        added = []
        for entry in msg.entries:
            key = (msg.monitor, entry.n)
            if key not in self.divergences:
                self.divergences[key] = {"monitor": msg.monitor, **entry.model_dump(mode="json")}
                added.append(self.divergences[key])
        while len(self.divergences) > KEPT_DIVERGENCES:
            self.divergences.popitem(last=False)
        out: list[Update] = [{"kind": "divergences", "added": added, "older": self.divergences_older}]
        return out + self._listed_violations(added)

    def _listed_violations(self, added: list[dict[str, Any]]) -> list[Update]:
        """Violation onsets of the monitor's list this view did not see happen (it joined later): added to
        :attr:`violations` with their step and event, once (a view that saw the step has it already)."""
        out: list[Update] = []
        seen = {(v["property"], v["seq"]) for v in self.violations}
        for d in added:
            prop = onset_property(d["reason"]) if d["kind"] == "violation" else None
            if prop is None or (prop, d["seq"]) in seen:
                continue
            v = {"n": len(self.violations), "property": prop, "seq": d["seq"], "epoch": self.epoch,
                 "event": d["event"], "t": d["stamp"], "joined": False, "listed": True}
            self.violations.append(v)
            seen.add((prop, d["seq"]))
            out.append({"kind": "violation", "violation": v})
        return out

    @property
    def divergences_older(self) -> int:
        """Divergences and restarts known to have happened and not kept."""
        return self._forgotten + sum(self._noted.values()) - len(self.divergences)

    # -- reading ------------------------------------------------------------------------

    def _alive_json(self) -> dict[str, list[str]]:
        return {s: sorted(ids) for s, ids in sorted(self.alive.items()) if ids}

    def _model_json(self) -> dict[str, Any]:
        return {"digest": None if self.model is None else self.model.digest, "lanes": self.lanes}

    def snapshot(self) -> Update:
        """Everything a new view needs, as one update."""
        return {
            "kind": "snapshot", "system": self.system, "epoch": self.epoch,
            "state": _json(self.state), "verdicts": _json(self.verdicts), "unsafe": _json(self.unsafe),
            "state_space": _json(self.state_space), "state_space_t": self.state_space_t,
            "model": self._model_json(),
            "alive": self._alive_json(), "points": list(self.points), "violations": list(self.violations),
            "divergences": list(self.divergences.values()), "divergences_older": self.divergences_older,
            "pilot": _json(self.pilot),
        }


def lanes(system: System) -> dict[str, Any]:
    """Per skillset, its resources with their states, its skills and their inputs: the timeline's lanes and
    the page's examples of goals and commands."""
    return {c.name: {"resources": {r.name: list(r.states) for r in c.skillset.resources},
                     "skills": [k.name for k in c.skillset.skills],
                     "inputs": {k.name: [v.name for v in k.inputs] for k in c.skillset.skills if k.inputs}}
            for c in system.components}


def _json(message: BaseModel | None) -> dict[str, Any] | None:
    return None if message is None else message.model_dump(mode="json")
