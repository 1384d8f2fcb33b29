"""The monitor's fast path without I/O (docs/semantics.md §1 monitor, §5, §7).

:class:`Engine` checks each event's sequence number, advances the live marking
with :class:`~skinet.system.live.LiveSystem`, runs Algorithm 1 and returns the
encoded :class:`LiveState`, :class:`Verdicts` and :class:`UnsafeReport`.

The work per event is compiled once per marking, in the spirit of rosbags'
generated deserialisers: the result of ``LiveSystem.apply`` is cached per
(skillset marking, transition, observed status), and the msgpack bytes of the
three messages per (combined marking, prediction) with holes for the fields of
a step (seq, stamp, event, divergence, missed outcomes, and the sync states of
docs/semantics.md §7, left out while they hold their default).  Both caches are bounded and exact (the core
functions are pure); a step packs a few small values and joins bytes.

An event naming skills found ended without their response (``missed``) gets the
model's inference of each outcome (:func:`skinet.net.outcomes.infer_outcomes`,
docs/how-it-works.md, *Missed outcomes*) in its step's ``LiveState.missed``; cost:
that function's, only for such events.

A resync answer adopted while a skillset was not live (:meth:`Engine.adopt`) sets
its marking without judging how the robot got there, and the events of its
stream up to the answer's seq become history (:meth:`Engine.check_seq`).
"""

from __future__ import annotations

import time
from collections import OrderedDict
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import msgpack

from services.monitor.divergences import event_name
from skinet.system.live import LiveSystem
from skinet.system.model import Marking, System, marking_from_json
from skinet.verify.algorithm1 import Analysis, analyse
from skinet.wire.convert import RiskTable, analysis_bodies, statuses
from skinet.net.outcomes import infer_outcomes
from skinet.wire.messages import (
    CanonicalEvent, LiveState, MissedOutcome, SkillsetSync, UnsafeReport, Verdicts,
)

MarkingKey = tuple[int, ...]


@dataclass
class Counters:
    """What happened to the payloads received on the events key."""

    received: int = 0  # payloads on the events key
    applied: int = 0  # events applied to the live marking
    malformed: int = 0  # garbage, wrong schema or another system's events
    duplicates: int = 0  # seq equal to the last applied one
    out_of_order: int = 0  # seq older than the last applied one
    lost: int = 0  # seq numbers skipped (gaps), events never seen
    jumps: int = 0  # seq far ahead of the last (forged, or a long outage): resynced
    restarts: int = 0  # a stream begun anew: new epoch, or seq far behind (a wrap)
    resyncs: int = 0  # status resyncs applied
    unrecovered: int = 0  # events an outage took that the bridge's cache could not give back (also in lost)
    history: int = 0  # events a resync answer covered (the bridge's cache replayed them to a late monitor)
    divergences: int = 0  # events the model could not explain (docs/semantics.md §7)
    errors: int = 0  # unexpected exceptions while handling a payload (bugs)


OMIT = object()  # a hole's value that leaves its field out (a later field at its default, skinet/wire/messages.py)


class Template:
    """The msgpack encoding of a message with holes for some fields (same bytes as packing the dict)."""

    def __init__(self, body: dict[str, Any], holes: tuple[str, ...]):
        packer = msgpack.Packer(use_bin_type=True)
        self.size = len(body)
        self.pairs: list[tuple[bytes, bytes, str]] = []  # constant bytes, then the field to pack after them
        const = b""
        for name, value in body.items():
            key = packer.pack(name)
            if name in holes:
                self.pairs.append((const, key, name))
                const = b""
            else:
                const += key + packer.pack(value)
        self.tail = const

    def fill(self, packer: msgpack.Packer, values: dict[str, Any]) -> bytes:
        pack, size, parts = packer.pack, self.size, []
        for const, key, name in self.pairs:
            value = values[name]
            if value is OMIT:
                size -= 1
                parts.append(const)
            else:
                parts.append(const + key + pack(value))
        return packer.pack_map_header(size) + b"".join(parts) + self.tail


@dataclass(frozen=True)
class Frame:
    """The messages of one combined marking and prediction, to be filled per step."""

    live: Template
    verdicts: Template
    unsafe: Template
    analysis: Analysis  # what the command check reads


@dataclass(frozen=True)
class Step:
    """The encoded messages of one step of the live marking."""

    seq: int
    key: MarkingKey
    changed: bool
    divergence: str | None  # as LiveState.divergence says it: with the message that showed it
    live: bytes
    verdicts: bytes
    unsafe: bytes
    reason: str | None = None  # the divergence alone (the live nets' reason, or the bridge's drift): the list's
    missed: tuple[MissedOutcome, ...] = ()  # as LiveState.missed lists them (for the monitor's log)
    unchecked: str = ""  # a resync step: the events its answer covers, which were not checked


@dataclass
class Prediction:
    """A predictor's answer for one marking, as Algorithm 1 consumes it."""

    token: int  # identifies the table in the frame cache
    table: RiskTable


def _divergence(reason: str | None, ev: CanonicalEvent) -> str | None:
    """What a step reports as a model divergence (docs/semantics.md §7, §9), with the message that showed it: the bridge's
    own finding (a binding's drift names its message), else the live nets' reason with the event's info."""
    if ev.divergence:
        return f"{ev.divergence} ({reason})" if reason else ev.divergence
    if reason is not None and ev.info:
        return f"{reason} (message: {ev.info})"
    return reason


@dataclass
class Engine:
    """Sequence check, live marking, Algorithm 1 and message bodies (not thread-safe)."""

    system: System
    cache_size: int = 4096
    prediction_cache: int = 256
    window: int = 1024  # seq distance within which events belong to the same run of a stream
    max_streams: int = 256  # (skillset, source) pairs remembered
    counters: Counters = field(default_factory=Counters)

    def __post_init__(self) -> None:
        self.live = LiveSystem(self.system)
        self.names = tuple(c.name for c in self.system.components)
        self.seq = -1  # monitor step counter; the initial state is step 0
        self.last_seq: OrderedDict[tuple[str, str], tuple[int, int]] = OrderedDict()  # -> (epoch, seq)
        self.covered: dict[tuple[str, str], tuple[int, int]] = {}  # -> (epoch, seq) of the last adopted resync
        self.sync: dict[str, Any] = {"sync": OMIT, "state_stale": OMIT, "state_reason": OMIT, "stale_since": OMIT}
        self._last: dict[str, Any] = {"event": "", "divergence": None}  # of the last step
        self.predictions: OrderedDict[MarkingKey, Prediction] = OrderedDict()
        self._applied: dict[tuple, tuple[int | None, bool, str | None]] = {}
        self._frames: dict[tuple[MarkingKey, int], Frame] = {}
        self._tokens = 0
        self._packer = msgpack.Packer(use_bin_type=True)

    @property
    def key(self) -> MarkingKey:
        return tuple(map(self.live.marking.__getitem__, self.names))

    def marking(self) -> Marking:
        return dict(self.live.marking)

    def initial(self) -> Step:
        """Step 0: the initial marking, published at start."""
        return self._step("", False, None)

    def check_seq(self, ev: CanonicalEvent) -> tuple[bool, str | None, bool]:
        """Whether to apply ``ev`` given its (epoch, seq), what to log, and whether to resync.

        Streams are keyed by (skillset, source) and start at any seq.  Within one
        epoch (one run of the publisher): a duplicate or a seq less than ``window``
        behind the last is counted and not applied; a gap is counted in ``lost``,
        applied, and answered by a status resync.  Anything else starts the stream
        anew, applied and resynced: a new epoch (a restarted bridge), a seq
        ``window`` or more behind (a wrap, or a publisher restarted without epochs)
        or ahead (a jump: counted in ``jumps``, not in ``lost``).  So one forged
        event costs at most one resync, never the stream.  At most ``max_streams``
        streams are remembered (least recently seen dropped).  Cost: O(1).
        """
        stream = (ev.skillset, ev.source)
        streams = self.last_seq
        prev = streams.get(stream)
        if ev.skillset not in self.live.marking:  # unknown skillsets are not tracked
            return True, None, False
        covered = self.covered.get(stream)
        if covered is not None and covered[0] == ev.epoch and ev.seq <= covered[1] and prev is not None and \
                prev[0] == ev.epoch and -self.window < ev.seq - prev[1] <= 0:
            self.counters.history += 1  # before the status a resync adopted: already in the marking
            return False, None, False
        streams[stream] = (ev.epoch, ev.seq)
        streams.move_to_end(stream)
        if len(streams) > self.max_streams:
            self.covered.pop(streams.popitem(last=False)[0], None)
        if prev is None:
            return True, None, False
        epoch, last = prev
        who = f"{ev.skillset}#{ev.seq} from '{ev.source}'"
        c = self.counters
        if epoch != ev.epoch:
            c.restarts += 1
            return True, f"new run (epoch {ev.epoch}, was {epoch}) at {who}: resync", True
        gap = ev.seq - last
        if -self.window < gap <= 0:
            streams[stream] = prev
            if gap == 0:
                c.duplicates += 1
                return False, f"duplicate event {who} ignored", False
            c.out_of_order += 1
            return False, f"out-of-order event {who} (last {last}) ignored", False
        if gap <= -self.window:
            c.restarts += 1
            return True, f"sequence restarted at {who} (last {last}): resync", True
        if gap > self.window:
            c.jumps += 1
            return True, f"sequence jump at {who} (last {last}): resync", True
        if gap > 1:
            c.lost += gap - 1
            return True, f"lost events {ev.skillset}#{last + 1}..{ev.seq - 1} from '{ev.source}': resync", True
        return True, None, False

    def resync(self, ev: CanonicalEvent) -> bool:
        """Whether a resync answer (the publisher's last status) is newer than what was applied."""
        prev = self.last_seq.get((ev.skillset, ev.source))
        if ev.status is None or ev.skillset not in self.live.marking:
            return False
        if prev is not None and prev[0] == ev.epoch and 0 < prev[1] - ev.seq < self.window:
            return False  # a later event of this run already arrived (it carries its own status)
        self.last_seq[(ev.skillset, ev.source)] = (ev.epoch, ev.seq)
        return True

    def status_marking(self, ev: CanonicalEvent) -> int:
        """The marking of ``ev.skillset`` its status gives; raises :class:`~skinet.errors.SourceError` when the
        model cannot read it (a status naming what the model lacks)."""
        if ev.status is None:
            raise ValueError("an event without a status")
        return marking_from_json(self.system, {ev.skillset: ev.status.model_dump()}, "resync")[ev.skillset]

    def adopt(self, ev: CanonicalEvent) -> Step | None:
        """Take a resync answer's status as ``ev.skillset``'s marking without judging how the robot got
        there (the monitor did not know: docs/semantics.md §7 syncing), and count later events of its stream up to
        ``ev.seq`` as history (:meth:`check_seq`).  A step when the marking changed or events of the
        stream that this monitor did not check are covered (its event says which), else None.
        Raises :class:`~skinet.errors.SourceError` for a status the model cannot read."""
        target = self.status_marking(ev)
        stream = (ev.skillset, ev.source)
        prev = self.last_seq.get(stream)
        first = prev[1] + 1 if prev is not None and prev[0] == ev.epoch else 1  # #0: the bridge's first status
        self.last_seq[stream] = self.covered[stream] = (ev.epoch, ev.seq)
        self.last_seq.move_to_end(stream)
        self.counters.resyncs += 1
        # The events the answer covers were not checked here: the step says so plainly (a violation
        # among them cannot show), and is published even when the marking did not move.
        unchecked = "" if first > ev.seq else \
            f"event #{first} of '{ev.source}' not checked" if first == ev.seq else \
            f"events #{first}-#{ev.seq} of '{ev.source}' not checked"
        if self.live.marking[ev.skillset] == target and not unchecked:
            return None
        changed = self.live.marking[ev.skillset] != target
        self.live.marking[ev.skillset] = target
        name = f"{ev.skillset}:resync#{ev.seq}" + (f" ({unchecked})" if unchecked else "")
        return replace(self._step(name, changed, None), unchecked=unchecked)

    def apply(self, ev: CanonicalEvent) -> Step | None:
        """Advance the live marking by ``ev`` (already seq-checked) and build its step.

        None for a status that only confirms the live marking (a bridge's status at
        start-up): it is no step, so that step numbers count the mission's transitions
        as ``skinet demo`` and the simulator do.
        """
        status = ev.status
        observed = None if status is None else (tuple(status.resources.items()), tuple(status.running))
        before = self.live.marking.get(ev.skillset)
        ckey = (ev.skillset, before, ev.transition, observed)
        hit = self._applied.get(ckey)
        if hit is None:
            out = self.live.apply(ev.skillset, ev.transition, None if status is None else status.model_dump())
            hit = (self.live.marking.get(ev.skillset), out.changed, out.divergence)
            if len(self._applied) >= self.cache_size:
                self._applied.clear()
            self._applied[ckey] = hit
        elif before is not None:
            self.live.marking[ev.skillset] = hit[0]  # type: ignore[assignment]
        self.counters.applied += 1
        divergence = _divergence(hit[2], ev)
        if divergence is not None:
            self.counters.divergences += 1
        missed = self._missed(ev, before)
        if ev.transition is None and not hit[1] and divergence is None and not missed:
            return None
        return self._step(event_name(ev), hit[1], divergence, hit[2] or ev.divergence or None, missed)

    def _missed(self, ev: CanonicalEvent, before: int | None) -> list[MissedOutcome]:
        """The event's missed outcomes with the model's inference from the marking before it to the live
        one after it (docs/how-it-works.md, *Missed outcomes*)."""
        if not ev.missed:
            return []
        after = self.live.marking.get(ev.skillset)
        skills = [m.skill for m in ev.missed]
        try:
            net = self.system.component(ev.skillset).net
            found = {i.skill: i for i in infer_outcomes(net, before, after, skills)} \
                if before is not None and after is not None else {}
        except (KeyError, ValueError):  # a skill the model lacks: nothing to infer
            found = {}
        out = []
        for m in ev.missed:
            i = found.get(m.skill)
            out.append(m.model_copy(update={"outcome": i.outcome if i else None,
                                            "candidates": list(i.candidates) if i else []}))
        return out

    def prediction(self, key: MarkingKey | None = None) -> Prediction | None:
        """The prediction for the live marking (``key`` when known), if any (docs/semantics.md §5)."""
        return self.predictions.get(self.key if key is None else key)

    def add_prediction(self, key: MarkingKey, table: RiskTable) -> bool:
        """Remember a predictor's answer for marking ``key``; True when it is the live one."""
        self._tokens += 1
        self.predictions[key] = Prediction(self._tokens, table)
        self.predictions.move_to_end(key)
        while len(self.predictions) > max(1, self.prediction_cache):
            self.predictions.popitem(last=False)
        return key == self.key

    def set_sync(self, sync: Mapping[str, SkillsetSync], stale: tuple[str, float] | None) -> None:
        """The sync fields of the next messages: LiveState.sync, UnsafeReport.state_stale and why (docs/semantics.md §7)."""
        self.sync = {"sync": {n: s.model_dump(mode="json") for n, s in sync.items()},
                     "state_stale": OMIT if stale is None else True,
                     "state_reason": OMIT if stale is None else stale[0],
                     "stale_since": OMIT if stale is None else stale[1]}

    def analysis(self) -> tuple[Analysis, MarkingKey, bool]:
        """Algorithm 1 at the live marking, the marking's key, and whether its prediction is stale."""
        key = self.key
        return self._frame(key).analysis, key, key not in self.predictions

    def refresh(self) -> bytes:
        """The UnsafeReport of the current step again, with the current prediction."""
        return self._frame(self.key).unsafe.fill(self._packer, {"seq": self.seq, "stamp": time.time(), **self.sync})

    def republish(self) -> Step:
        """The messages of the current step again (same seq, a new stamp), e.g. with a new sync state."""
        return self._fill(False, self._last["event"], self._last["divergence"], self._last.get("missed"))

    def _step(self, event: str, changed: bool, divergence: str | None, reason: str | None = None,
              missed: list[MissedOutcome] | None = None) -> Step:
        self.seq += 1
        self._last = {"event": event, "divergence": divergence, "missed": missed or []}
        step = self._fill(changed, event, divergence, missed or [])
        if missed:
            step = replace(step, missed=tuple(missed))
        return step if reason is None else replace(step, reason=reason)

    def _fill(self, changed: bool, event: str, divergence: str | None,
              missed: list[MissedOutcome] | None = None) -> Step:
        key = self.key
        frame = self._frame(key)
        values = {"seq": self.seq, "stamp": time.time(), "event": event, "divergence": divergence, **self.sync,
                  "missed": [m.model_dump(mode="json") for m in missed] if missed else OMIT}
        fill = self._packer
        return Step(self.seq, key, changed, divergence, frame.live.fill(fill, values),
                    frame.verdicts.fill(fill, values), frame.unsafe.fill(fill, values))

    def _frame(self, key: MarkingKey) -> Frame:
        pred = self.predictions.get(key)
        fkey = (key, pred.token if pred else 0)
        frame = self._frames.get(fkey)
        if frame is None:
            frame = self._build(pred)
            if len(self._frames) >= self.cache_size:
                self._frames.clear()
            self._frames[fkey] = frame
        return frame

    def _build(self, pred: Prediction | None) -> Frame:
        """Run Algorithm 1 and build the message bodies (seq and stamp set per step)."""
        name, marking = self.system.name, self.live.marking
        analysis = analyse(self.system, marking, pred.table if pred else None)
        props, unsafe, recovery = analysis_bodies(self.system, analysis)
        step = ("seq", "stamp")
        return Frame(
            Template(LiveState(system=name, seq=0, stamp=0.0, skillsets=statuses(self.system, marking))
                     .model_dump(mode="json"), (*step, "event", "divergence", "sync", "missed")),
            Template(Verdicts(system=name, seq=0, stamp=0.0, properties=props).model_dump(mode="json"), step),
            Template(UnsafeReport(system=name, seq=0, stamp=0.0, unsafe=unsafe, recovery=recovery,
                                  violated=analysis.violated, literal_count=len(analysis.unsafe),
                                  prediction_stale=pred is None).model_dump(mode="json"),
                     (*step, "state_stale", "state_reason", "stale_since")),
            analysis,
        )
