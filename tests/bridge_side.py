"""The bridge's side of the wire contract, for tests and benchmarks that feed a monitor events of
their own (schemas/README.md): canonical events, the liveliness token, heartbeats and resync answers.

The real bridge derives events from manager messages (``services/bridge_ros2``); this stand-in
publishes the events a test names and follows them on the model to answer resyncs, so that a
monitor syncs from it as from the bridge (docs/semantics.md §7).
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import zenoh

from services.common.events import event_publisher
from services.common.heartbeat import HeartbeatPublisher
from skinet.system.load import load_system
from skinet.system.live import LiveSystem
from skinet.system.model import System
from skinet.wire import keys
from skinet.wire.codec import decode, encode
from skinet.wire.convert import statuses
from skinet.wire.messages import CanonicalEvent, HeartbeatSkillset, LiveState, SkillsetStatus

REPO = Path(__file__).resolve().parents[1]


class BridgeSide:
    """Publishes CanonicalEvents like the bridge, numbering them per skillset, and speaks the rest of
    the bridge's side of the contract (schemas/README.md): its liveliness token, a heartbeat every
    0.5 s (:class:`HeartbeatPublisher`) and resync answers, the status after the last event sent
    (followed on the model; before any event, the initial status, numbered 0: the first event sent
    is #1).  When a monitor of the system is alive, it returns once that monitor is synced, so that
    the first events are live, not history (docs/semantics.md §7)."""

    def __init__(self, session: zenoh.Session, system: str = "spot_arm", source: str = "test", *,
                 model: System | None = None, epoch: int = 0, advanced: bool = False, cache: int = 4096,
                 heartbeat: bool = True, wait: bool = True):
        self.session, self.system, self.source, self.epoch = session, system, source, epoch
        if model is None and (REPO / "skillsets" / f"{system}.toml").exists():
            model = load_system(REPO / "skillsets" / f"{system}.toml")[0]
        self.model = model
        self.live = LiveSystem(self.model) if self.model is not None else None
        self.seq: dict[str, int] = {}
        self.sent: dict[int, float] = {}
        self._advanced = {} if advanced else None
        self._cache = cache
        self.token = keys.alive(system, "bridge_ros2", f"{source.replace('/', '-')}-{os.getpid()}-{id(self)}")
        self._token = session.liveliness().declare_token(self.token)
        self._resync = session.declare_queryable(keys.resync(system, "*"), self._on_resync)
        self._heartbeat = HeartbeatPublisher(session, system, source, epoch, self.token, self._beat) \
            if heartbeat else None
        if wait:
            self.synced(must=False)

    def _beat(self) -> dict[str, HeartbeatSkillset]:
        return {c.name: HeartbeatSkillset(seq=self.seq.get(c.name, 0)) for c in self.model.components} \
            if self.model is not None else {}

    def _on_resync(self, query: zenoh.Query) -> None:
        with query:
            skillset = str(query.key_expr).rsplit("/", 1)[-1]
            if self.live is None or skillset not in self.live.marking:
                return
            status = statuses(self.model, self.live.marking)[skillset]
            ev = CanonicalEvent(system=self.system, skillset=skillset, seq=self.seq.get(skillset, 0), stamp=0.0,
                                source=self.source, epoch=self.epoch, status=status, info="resync")
            query.reply(keys.resync(self.system, skillset), encode(ev))

    def synced(self, timeout: float = 10.0, must: bool = True) -> None:
        """Wait until the system's monitor says every skillset is live (``must``: fail without a monitor)."""
        deadline = time.monotonic() + timeout
        while True:
            states = [decode(r.ok.payload.to_bytes(), LiveState) for r in
                      self.session.get(keys.state(self.system), timeout=2.0) if r.ok is not None]
            if not states and not must:
                return
            if states and states[-1].sync and all(s.state == "live" for s in states[-1].sync.values()):
                return
            if time.monotonic() > deadline:
                raise AssertionError(f"the monitor of {self.system} not synced within {timeout} s: "
                                     f"{states[-1].sync if states else 'no monitor'}")
            time.sleep(0.02)

    def send(self, skillset: str, transition: str | None, status: dict | None = None, seq: int | None = None,
             stamp: float | None = None, info: str = "", restart: bool = False) -> int:
        last = self.seq.get(skillset, 0)
        if seq is None:
            seq = last + 1
        self.seq[skillset] = max(seq, last)
        if self.live is not None and seq > last and (transition is not None or status is not None):
            self.live.apply(skillset, transition, status)  # what a bridge's last status would say
        ev = CanonicalEvent(system=self.system, skillset=skillset, seq=seq,
                            stamp=time.time() if stamp is None else stamp, source=self.source, epoch=self.epoch,
                            transition=transition, status=None if status is None else SkillsetStatus(**status),
                            info=info, restart=restart)
        self.raw(skillset, encode(ev))
        return seq

    def raw(self, skillset: str, payload: bytes) -> None:
        if self._advanced is not None:
            if skillset not in self._advanced:
                self._advanced[skillset] = event_publisher(self.session, keys.events(self.system, skillset),
                                                           cache=self._cache)
            self._advanced[skillset].put(payload)
            return
        self.session.put(keys.events(self.system, skillset), payload,
                         congestion_control=zenoh.CongestionControl.BLOCK, express=True)

    def close(self) -> None:
        """Stop being a bridge: the token goes, heartbeats and resync answers stop."""
        if self._heartbeat is not None:
            self._heartbeat.close()
        for d in (self._token, self._resync, *(self._advanced or {}).values()):
            try:
                d.undeclare()
            except zenoh.ZError:
                pass
