"""bridge_ros2 on Zenoh: manager topics in, canonical events out (docs/semantics.md §1).

Subscribes to each manager's ``status``, ``event_request``, ``event_response`` and
``skill/<k>/response`` on the keys of :mod:`skinet.ros.keys` (as
``zenoh-bridge-ros2dds`` or ``rmw_zenoh`` carry them) and publishes the derived
:class:`~skinet.wire.messages.CanonicalEvent` on ``keys.events(system, skillset)``
with ``CongestionControl.BLOCK`` (ZENOH.md) and a cache from which a monitor
recovers what it missed during an outage (:mod:`services.common.events`).

The manager's status is volatile (corpus README) and published on change only: the
bridge sends ``status_request`` at start-up, repeats it every 0.5 s up to every
``poll`` seconds until each manager has answered, then goes on asking every ``poll``
seconds (anti-entropy, default 1 s; ``--status-poll``).  Any status counts as an
answer.  A manager that answered none of the last ``silent_after`` requests (default
3) is listed as gone in the heartbeat, with why in its ``pending`` (the monitor then
counts its skillset ``lost``); its next status closes the gap as after a cut link, and
a skill found ended in that status without its response is named in the event's
``missed`` with the gap (docs/how-it-works.md, *Missed outcomes*).  This is the one
way to know a manager is there in the plain ``zenoh-bridge-ros2dds`` layout, where
nothing announces it; its cost is one request and one status per manager and poll.  It also asks as soon as a manager can hear it: liveliness tokens announce
the manager's ``status_request`` subscription (``rmw_zenoh``: the node's own token,
whose type hash also gives the key on Humble; ``zenoh-bridge-ros2dds``: the token of
the gateway's route).  A token that comes back, a status from a new publisher GID or
with its sequence number going back (``rmw_zenoh`` attachments), or skill ids reset
to '' mean the manager restarted: the bridge asks again and the next status is a new
initial status whose ``info`` says how it differs from the last one (docs/semantics.md §7).  With
``rmw_zenoh`` the bridge declares its own node, subscription and publisher tokens.
A monitor that missed events, or that starts, asks ``keys.resync(system, skillset)``:
the bridge answers with the skillset's last status (numbered as its last event) and
asks the manager for a fresh one; while it knows that status to be outdated (its
manager restarted or left, or the link was cut, and no new status came yet) it
answers an error saying so instead, and its heartbeat lists the skillset as
``pending`` (sent at once), so that no monitor vouches for the old status.  What
managers publish while the bridge's session has lost every router is lost (their
topics are volatile): the first status after such a cut is a counted resync whose
event says so, and every manager is asked again when the link is back
(:mod:`services.bridge_ros2.link`).  Every 0.5 s it publishes a
:class:`~skinet.wire.messages.Heartbeat` (:mod:`services.common.heartbeat`): its
token, and per skillset its last event's number and whether the manager is present
(its token seen, gone, or never announced), so that a monitor can tell a silent
bridge from a quiet robot (docs/semantics.md §7).

One subscriber per manager covers all its topics (``.../<skillset>_skillset/**``):
separate subscribers per key would run their callbacks on different threads and
lose the order between a response and the status that follows it.  The callback
only queues the samples; one worker thread (:class:`~services.bridge_ros2.worker.Worker`,
shared with the bound skillsets' bridge of the same process) feeds them in arrival
order, so derivation never runs on Zenoh's threads.
"""

from __future__ import annotations

import argparse
import logging
import os
import re
import threading
import time
from collections.abc import Callable, Mapping
from typing import Any

import zenoh

from services.bridge_ros2.feed import Counters, Feed
from services.bridge_ros2.link import watch_link
from services.bridge_ros2.worker import Worker
from services.common.cli import default_instance_id
from services.common.events import event_publisher
from services.common.heartbeat import refusal, silence
from services.common.zenoh_config import undeclare
from services.common.ros_liveliness import declare_node
from skinet.ros.keys import (
    EMPTY_TYPE, EntityKind, KeyStyle, ManagerTopic, RosEntity, liveliness_key_expr, manager_topics,
    parse_liveliness_token, rmw_attachment, rmw_zenoh_key, topic_fqn,
)
from skinet.ros.typestore import default_instance, encode
from skinet.system.model import System
from skinet.wire import keys
from skinet.wire.codec import encode as wire_encode
from skinet.wire.messages import CanonicalEvent, HeartbeatSkillset

log = logging.getLogger("skinet.bridge_ros2")

POLL = 1.0  # seconds between status requests to each manager (anti-entropy; $SKINET_STATUS_POLL)
SILENT_AFTER = 3  # unanswered status requests after which a manager counts as gone
PLUGIN_TOKENS = "@/*/@ros2_lv/MS/**"  # zenoh-bridge-ros2dds: one token per route to a DDS subscription


def default_poll() -> float:
    """``$SKINET_STATUS_POLL`` (seconds between status requests) when set to a positive number, else :data:`POLL`:
    how ``skinet run``, the embedded chain and the compose services set the period of a bridge they start."""
    text = os.environ.get("SKINET_STATUS_POLL", "")
    return poll_seconds(text, " (from $SKINET_STATUS_POLL)") if text else POLL


def poll_seconds(text: str, origin: str = "") -> float:
    """A status-request period in seconds, 0.05 to 3600; raises ValueError with a one-line reason."""
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"the status-request period must be a number of seconds, got '{text}'{origin}") from None
    if not 0.05 <= value <= 3600:
        raise ValueError(f"the status-request period must be 0.05 to 3600 s, got '{text}'{origin}")
    return value


def add_status_poll_args(parser: argparse.ArgumentParser) -> None:
    """``--status-poll S`` and ``--silent-after N`` (the bridge's anti-entropy)."""
    env = os.environ.get("SKINET_STATUS_POLL")

    def period(text: str) -> float:
        try:
            return poll_seconds(text, " (from $SKINET_STATUS_POLL)" if env == text else "")
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    def count(text: str) -> int:
        if not text.isdigit() or not 1 <= int(text) <= 1000:
            raise argparse.ArgumentTypeError(f"not a count from 1 to 1000: '{text}'")
        return int(text)

    parser.add_argument("--status-poll", type=period, default=env or str(POLL), metavar="S",
                        help="seconds between status requests to each manager (anti-entropy: a manager publishes "
                             f"on change only); default $SKINET_STATUS_POLL or {POLL:g}")
    parser.add_argument("--silent-after", type=count, default=SILENT_AFTER, metavar="N",
                        help="unanswered status requests after which a manager's skillset is lost "
                             f"(default: {SILENT_AFTER})")


def default_source(instance: str | None = None) -> str:
    """``bridge_ros2/<instance>``: a new stream of sequence numbers per run for the monitor."""
    return f"bridge_ros2/{instance or default_instance_id()}"


class Bridge:
    """A running bridge; see :func:`start_bridge`.  ``worker``: the derivation thread to share with the
    bound skillsets' bridge of the same process (their events then keep their arrival order with the
    managers'); by default its own."""

    def __init__(self, session: zenoh.Session, system: System, typemap: Mapping[str, str], *,
                 style: KeyStyle = KeyStyle(), instance_id: str | None = None, source: str | None = None,
                 request_status: bool = True, retry: float = 0.5, extra_types: Mapping[str, str] | None = None,
                 hold: float = 0.5, worker: Worker | None = None, poll: float | None = None, silent_after: int = SILENT_AFTER):
        self.session = session
        self.system = system
        self.style = style
        self.instance_id = keys.check_chunk(instance_id or default_instance_id(), "instance id")
        self.worker = Worker() if worker is None else worker
        self._own_worker = worker is None
        self.feed = Feed(system, typemap, source or default_source(self.instance_id), extra_types, hold=hold,
                         epoch=self.worker.epoch, order=self.worker.order)
        self._fed = self.worker.lock  # held while the worker derives
        self._stop = threading.Event()
        self._lock = threading.Lock()  # request sequence numbers, learned type hashes, live tokens
        self._subscribers: list[Any] = []
        self._events: dict[str, Any] = {}
        self._requests: dict[str, tuple[str, ManagerTopic, bytes]] = {}  # skillset -> (manager, topic, CDR)
        self._hashes: dict[str, str] = {}  # skillset -> status_request type hash learned from the manager's token
        self._present: dict[str, str] = {}  # skillset -> token of its manager's status_request subscription
        self._gone: set[str] = set()  # skillsets whose manager's token went away (and has not come back)
        self._cuts = 0  # times the link to every router was lost (see _on_cut)
        self._cuts_seen: dict[str, int] = {}  # skillset -> _cuts when its manager's token last appeared
        self.poll, self.silent_after = default_poll() if poll is None else poll, silent_after
        self._unanswered: dict[str, int] = {}  # skillset -> status requests sent since its last status
        self._silent: dict[str, tuple[str, float]] = {}  # skillset -> (why, clock time of its last status)
        self._last_answer: dict[str, float] = {}  # skillset -> clock time of its manager's last status
        self.polls: dict[str, list[int]] = {}  # skillset -> [status requests sent, statuses received]
        self._sequence = 0
        self._gid = os.urandom(16)  # rmw_zenoh attachments of the status requests
        own: list[tuple[EntityKind, str, str, str]] = []  # rmw_zenoh graph entities of the bridge
        for name, m in self.feed.managers.items():
            manager = m.component.manager
            self._events[name] = event_publisher(session, keys.events(system.name, name))
            watched = {t.topic: t for t in m.topics}
            # On Zenoh's own thread: a Python thread per subscriber (indirect) would let one manager's
            # messages overtake another's, and the monitor follow an interleaving the robot never took.
            self._subscribers.append(session.declare_subscriber(
                style.all_topics(manager, m.component.skillset),
                zenoh.handlers.Callback(self._callback(name, manager, watched), indirect=False)))
            req = next(t for t in manager_topics(m.component.skillset) if t.kind == "status_request")
            self._requests[name] = (manager, req, encode(m.store, EMPTY_TYPE, default_instance(m.store, EMPTY_TYPE)))
            own += [("MS", topic_fqn(manager, t.topic), t.typename, style.type_hash(m.store, t.typename))
                    for t in m.topics]
            own.append(("MP", topic_fqn(manager, req.topic), req.typename, style.type_hash(m.store, req.typename)))
        self._resync = session.declare_queryable(keys.resync(system.name, "*"), self._on_resync)
        self._pending_seen: dict[str, str] = {}  # what the last heartbeat said was pending (see _notice)
        self._heartbeat = self.worker.beacon(session, system.name, self.feed.source, self.instance_id, self._beat,
                                             self._pending)
        self._ros_tokens: list[Any] = []
        self.graph: list[RosEntity] = []  # rmw_zenoh: the bridge's node and topics as ROS tools see them
        if style.rmw_zenoh:
            node = "/skinet_bridge_" + re.sub(r"[^A-Za-z0-9_]", "_", self.instance_id)
            self.graph, self._ros_tokens = declare_node(session, style.domain, node, own)
        self.worker.publishers.update(self._events)
        self.worker.add_timer(self.feed.deadline, self.feed.expire)
        self.worker.add_follow_up(self._notice)
        # Managers (or the gateway's routes to them) announce themselves by liveliness tokens:
        # ask a manager for its status as soon as it can hear us, and again when it comes back.
        self._subscribers.append(session.liveliness().declare_subscriber(
            liveliness_key_expr(style.domain) if style.rmw_zenoh else PLUGIN_TOKENS, self._on_token, history=True))
        self._request = request_status
        self._linker = threading.Thread(target=watch_link, args=(session, self._stop, self._on_cut, self._on_back),
                                        name="bridge_ros2-link", daemon=True)
        self._linker.start()
        self._asker = None
        if request_status:
            self._asker = threading.Thread(target=self._ask_status, args=(retry,), name="bridge_ros2-status",
                                           daemon=True)
            self._asker.start()
        log.info("bridge for %s: %s keys, events on %s", system.name,
                 "rmw_zenoh" if style.rmw_zenoh else "zenoh-bridge-ros2dds", keys.events(system.name, "*"))

    @property
    def counters(self) -> Counters:
        """Messages fed, events published, malformed payloads (updated by the worker thread)."""
        return self.feed.counters

    def _callback(self, skillset: str, manager: str,
                  watched: dict[str, ManagerTopic]) -> Callable[[zenoh.Sample], None]:
        def on_sample(sample: zenoh.Sample) -> None:
            topic = watched.get(self.style.topic(manager, str(sample.key_expr)) or "")
            if topic is not None:
                attachment = sample.attachment.to_bytes() if sample.attachment is not None else None
                payload = sample.payload.to_bytes()
                back = self._answered(skillset) if topic.kind == "status" else None
                if back is None:
                    self.worker.put(lambda: self.feed.feed(skillset, topic, payload, attachment))
                else:
                    def returned() -> list[CanonicalEvent]:
                        if self.feed.managers[skillset].resync in ("", back[1]):  # a cut link says so itself
                            self.feed.resync(skillset, back[0])
                        return self.feed.feed(skillset, topic, payload, attachment)
                    self.worker.put(returned)
                    self._notice()

        return on_sample

    def _notice(self) -> None:
        """Send a heartbeat at once when the skillsets whose status is outdated changed (a monitor
        must stop vouching for them now, not up to a period later)."""
        pending = self._pending()
        if pending != self._pending_seen:
            self._pending_seen = pending
            self._heartbeat.poke()

    def _on_resync(self, query: zenoh.Query) -> None:
        with query:
            skillset = str(query.key_expr).rsplit("/", 1)[-1]
            if skillset not in self.feed.managers:
                return
            with self._fed:
                why = self._outdated(skillset)
                ev = None if why else self.feed.last_status(skillset)
            if why:  # never vouch for a status known to be outdated (docs/semantics.md §7)
                query.reply_err(refusal(self.feed.source, skillset, why))
            elif ev is not None:
                query.reply(keys.resync(self.system.name, skillset), wire_encode(ev))
            self.request_status(skillset)

    def _answered(self, skillset: str) -> tuple[str, str] | None:
        """A status of ``skillset`` came (on Zenoh's thread): its manager answers.  Returns the gap it
        closes and why the manager was silent, when it had fallen silent (None otherwise)."""
        with self._lock:
            self._unanswered[skillset] = 0
            self._last_answer[skillset] = time.monotonic()
            self.polls.setdefault(skillset, [0, 0])[1] += 1
            silent = self._silent.pop(skillset, None)
        if silent is None:
            return None
        manager = self._requests[skillset][0]
        gap = f"the link to {manager} was down {time.monotonic() - silent[1]:.1f} s"
        log.warning("%s: manager %s answers again (%s)", skillset, manager, gap)
        return gap, silent[0]

    def _outdated(self, skillset: str) -> str:
        """Why ``skillset``'s last status is not its manager's current one ('' when it may be)."""
        with self._lock:
            gone = skillset in self._gone
            silent = self._silent.get(skillset)
        if silent is not None:
            return silent[0]
        if gone:
            return f"its manager {self._requests[skillset][0]} left"
        return self.feed.outdated(skillset)

    def _pending(self) -> dict[str, str]:
        """The heartbeat's ``pending``: skillsets whose last status is outdated, with why."""
        with self._fed:
            return {n: why for n in self.feed.managers if (why := self._outdated(n))}

    # -- status requests ------------------------------------------------------------------

    def _manager_of_token(self, key: str) -> tuple[str, str] | None:
        """(skillset, type hash) when ``key`` is the token of a manager's status_request subscription."""
        if self.style.rmw_zenoh:
            entity = parse_liveliness_token(key)
            if entity is None or entity.kind != "MS":  # the bridge subscribes to no status_request
                return None
            for name, (manager, req, _) in self._requests.items():
                if entity.topic == topic_fqn(manager, req.topic):
                    return name, entity.type_hash
            return None
        parts = key.split("/")  # @/<zid>/@ros2_lv/MS/<key with / as §>/<type>/<qos>
        if len(parts) < 5 or parts[3] != "MS":
            return None
        route = parts[4].replace("§", "/")
        for name, (manager, req, _) in self._requests.items():
            if route == self.style.key(manager, req):
                return name, ""
        return None

    def _on_token(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        found = self._manager_of_token(key)
        if found is None:
            return
        name, hash_ = found
        if sample.kind != zenoh.SampleKind.PUT:
            with self._lock:
                if self._present.get(name) == key:
                    del self._present[name]
                    self._gone.add(name)
                    log.warning("%s: manager %s left (its status_request subscription is gone)", name,
                                self._requests[name][0])
            self._notice()  # its last status is outdated now
            return
        with self._lock:
            if hash_:
                self._hashes[name] = hash_
            # Only a manager seen before can come back.  The tokens present at start-up come as
            # the subscriber's history, with no mark and no order against the topics' samples:
            # on a loaded start they arrive after the first status, and are no restart.  Nor is
            # a token that left with our link (cut since it last appeared): the resync after the
            # cut covers it (_on_cut), and a manager that restarted meanwhile shows it in
            # its status (skill ids reset, a new publisher).
            back = name not in self._present and self._cuts_seen.get(name) == self._cuts and \
                self.feed.managers[name].deriver.last is not None
            self._present[name] = key
            self._gone.discard(name)
            self._cuts_seen[name] = self._cuts
        if back:
            with self._fed:
                self.feed.restarted(name, "the manager (or its gateway) came back")
            self.worker.put(lambda: [])  # a status it held is released: the worker publishes its events
        self._notice()
        self.request_status(name)

    def _beat(self) -> dict[str, HeartbeatSkillset]:
        """Per skillset, the seq of its last event and whether its manager is present (the heartbeat)."""
        with self._lock:
            present, gone = set(self._present) - set(self._silent), self._gone | set(self._silent)
        # A silent manager is gone even while its token stays (a frozen process holds it for the lease).
        return {name: HeartbeatSkillset(seq=m.seq - 1 if m.seq else None,
                                        manager=True if name in present else False if name in gone else None)
                for name, m in self.feed.managers.items()}

    def _on_cut(self) -> None:
        """The session lost every router: what a manager publishes meanwhile is lost (its topics are
        volatile).  Each skillset's next status closes the gap (counted, and said by its event)."""
        with self._lock:
            self._cuts += 1
        log.warning("link to the router(s) lost: manager messages may be lost until it is back")
        # Queued behind every sample received before the cut, ahead of every one after it.
        self.worker.put(self._cut)

    def _cut(self) -> list[CanonicalEvent]:
        for name in self.feed.managers:
            self.feed.resync(name, "the link to the managers was cut")
        return []

    def _on_back(self) -> None:
        log.warning("link to the router(s) back: asking every manager for its status")
        if self._request:
            for name in self.feed.managers:
                self.request_status(name)

    def request_status(self, skillset: str) -> None:
        """Ask ``skillset``'s manager to publish its status."""
        manager, topic, payload = self._requests[skillset]
        attachment = None
        with self._lock:
            if self.style.rmw_zenoh:
                self._sequence += 1
                attachment = rmw_attachment(self._sequence, time.time_ns(), self._gid)
                key = rmw_zenoh_key(manager, topic.topic, topic.typename,
                                    self._hashes.get(skillset) or self.style.type_hash(
                                        self.feed.managers[skillset].store, topic.typename), self.style.domain)
            else:
                key = self.style.key(manager, topic)
        self.session.put(key, payload, attachment=attachment, congestion_control=zenoh.CongestionControl.BLOCK)

    def _ask_status(self, retry: float) -> None:
        """Ask every manager for its status (polls counted in :attr:`polls`): every ``retry`` seconds, doubling up to every ``poll``
        seconds, while one has not answered yet; then every ``poll`` seconds (anti-entropy).  A manager
        that answered before and none of the last ``silent_after`` requests falls silent (:meth:`_fall_silent`)."""
        delay = retry
        while not self._stop.is_set():
            missing = [n for n in self.feed.managers if not self.feed.has_status(n)]
            for name in self.feed.managers:
                with self._lock:
                    unanswered = self._unanswered.get(name, 0)
                    heard = self.polls.get(name, [0, 0])[1] > 0
                    silent = name in self._silent
                if heard and not silent and unanswered >= self.silent_after:
                    self._fall_silent(name)
                with self._lock:
                    self._unanswered[name] = self._unanswered.get(name, 0) + 1
                    self.polls.setdefault(name, [0, 0])[0] += 1
                self.request_status(name)
            delay = min(delay * 2, self.poll) if missing else self.poll
            self._stop.wait(delay)

    def _fall_silent(self, skillset: str) -> None:
        """``skillset``'s manager answered none of the last ``silent_after`` requests: gone (heartbeat),
        its last status outdated, and its next status closes a gap."""
        manager = self._requests[skillset][0]
        why = silence(manager, self.silent_after, self.poll)
        with self._lock:
            self._silent[skillset] = (why, self._last_answer.get(skillset, time.monotonic()))
        log.warning("%s: %s", skillset, why)

        def gap() -> list[CanonicalEvent]:
            if not self.feed.managers[skillset].resync:  # a cut link already said why
                self.feed.resync(skillset, why)
            return []
        self.worker.put(gap)
        self._notice()

    def wait_statuses(self, counts: Mapping[str, int], timeout: float = 5.0) -> bool:
        """Wait until ``counts[skillset]`` statuses of each skillset were handled and their events published.

        With :meth:`services.simulator.Simulator.statuses_published` this tells a test
        (or an embedded demo) that the bridge has caught up with the simulator.
        """
        with self._fed:
            return self._fed.wait_for(
                lambda: all(self.feed.statuses.get(k, 0) >= n for k, n in counts.items()), timeout)

    def close(self) -> None:
        """Stop asking, let the worker finish what is queued, undeclare everything."""
        if self._stop.is_set():
            return
        self._stop.set()
        self.worker.release(self._beat)
        undeclare(self._resync, *self._ros_tokens, *self._subscribers)
        if self._own_worker:
            self.worker.close()
        else:
            self.worker.wait_idle()
        if self._asker is not None:
            self._asker.join(5.0)
        self._linker.join(5.0)
        for name in self._events:
            self.worker.publishers.pop(name, None)
        undeclare(*self._events.values())


def start_bridge(session: zenoh.Session, system: System, typemap: Mapping[str, str], **options: Any) -> Bridge:
    """Start a bridge for every manager of ``system`` on ``session``; options as :class:`Bridge`."""
    return Bridge(session, system, typemap, **options)


__all__ = ["POLL", "SILENT_AFTER", "Bridge", "default_source", "start_bridge"]
