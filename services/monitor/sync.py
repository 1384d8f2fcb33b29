"""Honest live state: which skillsets the monitor can vouch for (docs/semantics.md §7), without I/O.

Each skillset is

- ``syncing`` from the start, and whenever its source comes back: the monitor has
  asked the bridge for the skillset's last status (``keys.resync``) and waits for
  the answer;
- ``live`` once the answer is applied and the events up to it have come, for as
  long as its source is heard: a :class:`~skinet.wire.messages.Heartbeat` or an
  event at least every ``bound`` seconds (2 s by default; heartbeats come every
  0.5 s), its liveliness token present, its manager not known to have left, and
  its last status not known by the source to be outdated (``Heartbeat.pending``:
  a restarted manager not heard yet, a cut link; the source then refuses the
  resync query with the same reason until the new status comes);
- ``lost`` when one of those fails, with since when and why (a manager that fell
  silent, answering none of the bridge's last status requests, is lost with the
  bridge's own words: :func:`~services.common.heartbeat.silence`).

History is told from sources and sequence numbers, never from an event's stamp:
events of a skillset that is not live wait in its buffer (at most ``buffer``, the
oldest dropped first) until the resync answers; the service then applies the
answer and hands the buffered events to :meth:`Engine.check_seq`, which counts
those the answer covers (same source and epoch, seq up to the answer's) as
history (:meth:`Engine.adopt`, whose step names the events it did not check).  Time here is the monitor's own monotonic clock,
used only to measure silences; ``since`` is its wall clock, for people.

Cost: O(1) per event, heartbeat entry and token change; :meth:`SyncTracker.tick`
is O(N) for N skillsets.
"""

from __future__ import annotations

import argparse
import math
import os
import time
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

from services.common.heartbeat import is_silence, refusal
from skinet.wire import keys
from skinet.wire.messages import CanonicalEvent, Heartbeat, SkillsetSync

LIVE, SYNCING, LOST = "live", "syncing", "lost"
BOUND = 2.0  # seconds of silence after which a source's skillsets are lost
MIN_BOUND = 1.0  # two heartbeat periods (services/common/heartbeat.py)
RETRY = 1.0  # seconds between resync queries of a skillset that is not live
BUFFER = 4096  # events kept per skillset while it is not live (the bridge's cache holds as many)
STARTED = "the monitor started: waiting for the bridge's resync answer"


@dataclass
class _Source:
    """A publisher of canonical events, as its heartbeats and events show it."""

    heard: float  # monotonic time of its last heartbeat, event or resync answer
    token: str = ""  # the liveliness token its heartbeats name
    epoch: int | None = None
    managers: dict[str, bool | None] = field(default_factory=dict)  # skillset -> present (heartbeat)
    seqs: dict[str, int | None] = field(default_factory=dict)  # skillset -> seq of its last event (heartbeat)
    pending: dict[str, str] = field(default_factory=dict)  # skillset -> why its last status is outdated


@dataclass
class _Skillset:
    state: str
    since: float  # wall clock
    reason: str
    source: str = ""  # the source it was last synced from
    buffer: deque[CanonicalEvent] = field(default_factory=lambda: deque(maxlen=BUFFER))
    asking: bool = False  # a resync query in flight
    asked: float = float("-inf")  # monotonic time of the last resync query
    behind: tuple[str, int, int] | None = None  # (source, epoch, seq): events up to this one are on their way


class SyncTracker:
    """Sync state of every skillset of a system (not thread-safe: the monitor holds its lock)."""

    def __init__(self, names: Iterable[str], *, bound: float = BOUND, retry: float = RETRY, buffer: int = BUFFER,
                 system: str = "", clock: Callable[[], float] = time.monotonic, wall: Callable[[], float] = time.time):
        """``system``: its name, for the liveliness token of a source named ``<service>/<instance>``
        (a bridge's default) before a heartbeat names it."""
        self.bound, self.retry, self.clock, self.wall, self.system = bound, retry, clock, wall, system
        now = wall()
        self.skillsets = {n: _Skillset(SYNCING, now, STARTED, buffer=deque(maxlen=buffer)) for n in names}
        self.sources: dict[str, _Source] = {}
        self.gone: set[str] = set()  # liveliness tokens seen deleted and not back
        self.overflow = 0  # buffered events dropped (a gap the resync answer or check_seq then shows)
        self.version = 0  # grows whenever :meth:`message` would change

    # -- reading --------------------------------------------------------------------------

    def live(self, name: str) -> bool:
        s = self.skillsets.get(name)
        return s is None or s.state == LIVE  # unknown skillsets are not tracked (the engine reports them)

    def all_live(self) -> bool:
        return all(s.state == LIVE for s in self.skillsets.values())

    def message(self) -> dict[str, SkillsetSync]:
        return {n: SkillsetSync(state=s.state, since=s.since, reason=s.reason, source=s.source)
                for n, s in self.skillsets.items()}

    def stale(self) -> tuple[str, float] | None:
        """(why, since when) when some skillset is not live, in the operator's words; None when all are."""
        out = [(n, s) for n, s in self.skillsets.items() if s.state != LIVE]
        if not out:
            return None
        since = min(s.since for _, s in out)
        return "; ".join(f"{n} {s.state} since {_clock(s.since)}: {s.reason}" for n, s in out), since

    # -- inputs ---------------------------------------------------------------------------

    def hold(self, ev: CanonicalEvent) -> bool:
        """Note ``ev``'s source as heard; True when ``ev`` must wait (its skillset is not live), and then
        buffer it (a lost skillset whose events come again is syncing).  Events of the stream a skillset
        catches up on (:meth:`synced` with ``upto``) do not wait: they are what it waits for."""
        self._heard(ev.source)
        s = self.skillsets.get(ev.skillset)
        if s is None or s.state == LIVE:
            return False
        if s.state == SYNCING and s.behind is not None and s.behind[:2] == (ev.source, ev.epoch):
            return False
        if len(s.buffer) == s.buffer.maxlen:
            self.overflow += 1
        s.buffer.append(ev)
        if s.state == LOST:
            self._set(ev.skillset, SYNCING, f"events from '{ev.source}' again: waiting for its resync answer")
        return True

    def heartbeat(self, hb: Heartbeat, superseded: Iterable[str] = ()) -> None:
        """A heartbeat of ``hb.source``: it is heard; a manager that left loses its skillset; a
        lost skillset it publishes is syncing again; a skillset whose last status it says is
        outdated (``hb.pending``) is syncing until its resync answers.  ``superseded``: skillsets
        for which an event newer than the heartbeat's ``seq`` was already applied (its ``pending``
        is older news there)."""
        src = self._heard(hb.source)
        restarted = src.epoch is not None and src.epoch != hb.epoch
        src.token, src.epoch = hb.token, hb.epoch
        src.managers = {n: b.manager for n, b in hb.skillsets.items()}
        src.seqs = {n: b.seq for n, b in hb.skillsets.items()}
        src.pending = {n: why for n, why in hb.pending.items() if n not in superseded}
        for name, beat in hb.skillsets.items():
            s = self.skillsets.get(name)
            if s is None:
                continue
            outdated = src.pending.get(name, "")
            refused = refusal(hb.source, name, outdated)
            if beat.manager is False:
                if s.state != LOST or s.source == hb.source:
                    self._set(name, LOST, refused if is_silence(outdated) else
                              f"its manager left (said '{hb.source}')", hb.source)
            elif s.state == LOST and (s.source in ("", hb.source) or not self._heard_recently(s.source)):
                self._set(name, SYNCING, refused if outdated else
                          f"'{hb.source}' is heard again: waiting for its resync answer")
            elif s.state == LIVE and s.source == hb.source and restarted:
                self._set(name, SYNCING, f"'{hb.source}' restarted (epoch {hb.epoch}): waiting for its resync answer")
            elif outdated and (s.state == LIVE and s.source == hb.source or
                               s.state == SYNCING and s.source in ("", hb.source)):
                s.behind = None
                self._set(name, SYNCING, refused)

    def outdated(self, name: str, source: str) -> bool:
        """Whether ``source``'s last heartbeat says ``name``'s last status is outdated (no use asking it)."""
        src = self.sources.get(source)
        return src is not None and name in src.pending

    def token(self, key: str, alive: bool) -> None:
        """A liveliness token under ``skinet/<system>/alive/`` appeared or vanished."""
        if alive:
            self.gone.discard(key)
            for name, s in self.skillsets.items():
                src = self.sources.get(s.source)
                if s.state == LOST and src is not None and src.token == key:
                    self._set(name, SYNCING, f"'{s.source}' is back: waiting for its resync answer")
            return
        self.gone.add(key)
        for name, s in self.skillsets.items():
            src = self.sources.get(s.source)
            if s.state != LOST and src is not None and src.token == key:
                self._set(name, LOST, f"the liveliness token of '{s.source}' is gone (it stopped, or its link did)")

    def synced(self, name: str, source: str, epoch: int, upto: int | None = None) -> list[CanonicalEvent]:
        """The resync answer of ``source`` was applied: ``name`` is live; returns its buffered events.

        ``upto``: the answer is the status after event ``upto`` of that stream, which has not been
        applied yet (events still on their way, e.g. recovered from the bridge's cache after an
        outage): ``name`` stays syncing, its events of that stream no longer wait (:meth:`hold`),
        until :meth:`caught_up`."""
        s = self.skillsets[name]
        self._heard(source).epoch = epoch
        self._vouch(name, source, epoch, upto)
        out = list(s.buffer)
        s.buffer.clear()
        return out

    def _vouch(self, name: str, source: str, epoch: int, upto: int | None = None) -> None:
        """``name`` follows ``source``: live, unless the source is known gone or the answer is ahead."""
        s = self.skillsets[name]
        src = self._heard(source)
        s.behind = None
        if src.managers.get(name) is False:
            why = src.pending.get(name, "")
            self._set(name, LOST, refusal(source, name, why) if is_silence(why) else
                      f"its manager left (said '{source}')", source)
        elif src.token and src.token in self.gone:
            self._set(name, LOST, f"the liveliness token of '{source}' is gone (it stopped, or its link did)", source)
        elif upto is not None:
            s.behind = (source, epoch, upto)
            self._set(name, SYNCING, f"catching up: events up to #{upto} from '{source}' are on their way", source)
        else:
            self._set(name, LIVE, "", source)

    def caught_up(self, name: str, source: str, epoch: int, seq: int | None = None) -> None:
        """``name`` applied the stream of ``source`` and ``epoch`` up to ``seq`` (None: the answer it waited
        behind was adopted): live once that reaches the answer of :meth:`synced`."""
        s = self.skillsets.get(name)
        if s is None or s.behind is None or s.behind[:2] != (source, epoch) or \
                (seq is not None and seq < s.behind[2]):
            return
        self._vouch(name, source, epoch)

    def asking(self, name: str) -> bool:
        """Whether to send a resync query for ``name`` now (none in flight); marks one in flight."""
        s = self.skillsets.get(name)
        if s is None or s.asking:
            return False
        s.asking, s.asked = True, self.clock()
        return True

    def answered(self, name: str, replied: bool, refused: str = "", failed: str = "", key: str = "",
                 timeout: float = 0.0) -> None:
        """The resync query of ``name`` ended; ``replied``: an answer was applied; ``refused``: the error
        a source answered instead (its status is outdated, and why); ``failed``: the error Zenoh itself
        answered (``Timeout``: a source is there but did not answer), never shown bare: the reason says
        what was asked (``key``), of whom, and for how long (``timeout`` seconds)."""
        s = self.skillsets.get(name)
        if s is None:
            return
        s.asking = False
        if replied or s.state == LIVE or s.behind is not None:
            return
        heard = [(n, src) for n, src in self.sources.items() if name in src.seqs and self._heard_recently(n)]
        on = f" on {key}" if key else ""
        within = f" within {timeout:g} s" if timeout > 0 else ""
        if refused:
            why = refused
        elif failed:
            who = f"'{heard[0][0]}'" if heard else "the bridge"
            if failed == "Timeout":
                why = f"the resync query to {who}{on} got no answer{within} (Timeout)"
            else:
                why = f"the resync query to {who}{on} failed: {failed}"
        elif not heard:
            why = "no bridge answered the resync query"
        elif heard[0][1].seqs[name] is None:
            why = f"'{heard[0][0]}' has no status of {name} yet (its manager has not answered)"
        else:
            why = f"the resync query to '{heard[0][0]}'{on} got no answer{within}"
        if s.state == SYNCING and s.reason != why:
            self._set(name, SYNCING, why)

    def tick(self) -> list[str]:
        """Lose the skillsets whose source went quiet; returns those whose resync is due again."""
        now = self.clock()
        due = []
        for name, s in self.skillsets.items():
            if s.state == LIVE:
                src = self.sources.get(s.source)
                if src is None or now - src.heard > self.bound:
                    self._set(name, LOST, f"nothing heard from '{s.source}' for {self.bound:g} s (no heartbeat, "
                                          "no event)")
            elif s.state == SYNCING and s.behind is None and not s.asking and now - s.asked >= self.retry:
                due.append(name)
        return due

    # -- helpers --------------------------------------------------------------------------

    def _heard(self, source: str) -> _Source:
        src = self.sources.get(source)
        if src is None:
            if len(self.sources) >= 64:  # forged source names cost nothing: forget the quietest
                del self.sources[min(self.sources, key=lambda n: self.sources[n].heard)]
            src = self.sources[source] = _Source(self.clock(), token=self._token_of(source))
        src.heard = self.clock()
        return src

    def _token_of(self, source: str) -> str:
        """The token a source ``<service>/<instance>`` holds by the bridge's convention (its heartbeats
        may name another): known at once, before the first heartbeat comes (up to 0.5 s)."""
        parts = source.split("/")
        if not self.system or len(parts) != 2:
            return ""
        try:
            return keys.alive(self.system, keys.check_chunk(parts[0], "service"), keys.check_chunk(parts[1], "id"))
        except ValueError:
            return ""

    def _heard_recently(self, source: str) -> bool:
        src = self.sources.get(source)
        return src is not None and self.clock() - src.heard <= self.bound

    def _set(self, name: str, state: str, reason: str, source: str | None = None) -> None:
        s = self.skillsets[name]
        if state != SYNCING:
            s.behind = None
        source = s.source if source is None else source
        if (s.state, s.reason, s.source) == (state, reason, source):
            return
        s.source = source
        if s.state != state:
            s.since = self.wall()
        s.state, s.reason = state, reason
        self.version += 1


def _clock(t: float) -> str:
    """``t`` as the local time of day, for messages (HH:MM:SS)."""
    return time.strftime("%H:%M:%S", time.localtime(t))


def add_lost_after_arg(parser: argparse.ArgumentParser) -> None:
    """``--lost-after S`` (default ``$SKINET_LOST_AFTER`` or 2), at least :data:`MIN_BOUND`."""
    env = os.environ.get("SKINET_LOST_AFTER")

    def bound(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not (math.isfinite(value) and value >= MIN_BOUND):
            origin = " (from $SKINET_LOST_AFTER)" if env == text else ""
            raise argparse.ArgumentTypeError(f"expected a number of seconds >= {MIN_BOUND:g} (two heartbeat "
                                             f"periods), got '{text}'{origin}")
        return value

    parser.add_argument("--lost-after", type=bound, default=env or str(BOUND), metavar="S",
                        help="seconds without a heartbeat or event from a skillset's bridge after which the "
                             "skillset is lost: checks then answer state_unknown until it has resynced "
                             f"(default: $SKINET_LOST_AFTER or {BOUND:g})")
