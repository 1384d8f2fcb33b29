"""Simulated skillset managers on Zenoh, as a ROS 2 gateway would carry them (docs/semantics.md §7).

Each skillset of the system gets a :class:`~services.simulator.manager.Manager`
behind the manager's topics on the keys of :mod:`skinet.ros.keys`
(``zenoh-bridge-ros2dds`` layout by default, ``rmw_zenoh`` with its type hashes
and 33-byte attachments on request), with CDR payloads of the generated types.

Inputs (``status_request``, ``event_request``, ``skill/<k>/request``,
``skill/<k>/interrupt``) are handled under one lock per manager, like the
generated node's mutex, and the resulting messages are published in order with
``CongestionControl.BLOCK`` (ZENOH.md).  The simulated implementations are
driven by method calls: :meth:`Simulator.terminate`, :meth:`Simulator.raise_event`;
an interruption of an ``interrupting true`` skill completes at once.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import zenoh

from services.common.ros_liveliness import declare_node
from services.common.zenoh_config import undeclare
from services.simulator.driver import StepRun, drive
from services.simulator.manager import INTERRUPTING, READY, RUNNING, Manager, Message
from skinet.mission.scenario import Scenario
from skinet.ros.keys import KeyStyle, ManagerTopic, manager_topics, rmw_attachment, topic_fqn
from skinet.ros.typestore import build_typestore, decode, encode
from skinet.system.model import Component, System

if TYPE_CHECKING:
    from skinet.ros.typestore import Typestore

log = logging.getLogger("skinet.simulator")

INPUTS = ("status_request", "event_request", "skill_request", "skill_interrupt")
OUTPUTS = ("status", "event_response", "skill_response")


@dataclass
class _Node:
    """One simulated manager node and its Zenoh declarations."""

    component: Component
    store: Typestore
    manager: Manager
    topics: dict[str, ManagerTopic]  # node-relative topic -> topic
    publishers: dict[str, Any]  # node-relative topic -> zenoh.Publisher (outputs)
    lock: threading.Lock
    gid: bytes
    sequence: int = 0
    statuses: int = 0  # SkillsetStatus messages published
    handled: dict[str, int] = field(default_factory=dict)  # node-relative input topic -> inputs handled
    tokens: list[Any] = field(default_factory=list)  # rmw_zenoh liveliness tokens of the node


class Simulator:
    """Every skillset manager of ``system`` on ``session`` (close with :meth:`close`)."""

    def __init__(
        self,
        session: zenoh.Session,
        system: System,
        typemap: Mapping[str, str],
        *,
        style: KeyStyle = KeyStyle(),
        clock: Callable[[], float] = time.time,
        extra_types: Mapping[str, str] | None = None,
    ):
        self.session = session
        self.system = system
        self.style = style
        self._clock = clock
        self._cond = threading.Condition()
        self._subscribers: list[Any] = []
        # Called with (skillset, skill, request id) under the manager's lock whenever a request starts a skill
        # (a simulated implementation, services.simulator.world, ends it later): keep them short.
        self.on_start: list[Callable[[str, str, str], None]] = []
        self.nodes: dict[str, _Node] = {}
        for comp in system.components:
            store = build_typestore(comp.skillset, typemap, extra_types)
            manager = Manager(comp.skillset, store, info=comp.manager or f"{comp.name}_skillset_manager", clock=clock)
            topics = {t.topic: t for t in manager_topics(comp.skillset)}
            node = _Node(comp, store, manager, topics, {}, threading.Lock(), os.urandom(16))
            self._open(node)
            self.nodes[comp.name] = node
            log.info("simulated manager %s of skillset %s", comp.manager, comp.name)

    # -- transport (Zenoh here; services.simulator.dds overrides these for DDS) -------------

    def _open(self, node: _Node) -> None:
        """Declare the node's output publishers and one subscriber for its inputs."""
        comp = node.component
        for t in node.topics.values():
            if t.kind in OUTPUTS:
                key = self.style.key(comp.manager, t, node.store)
                node.publishers[t.topic] = self.session.declare_publisher(
                    key, congestion_control=zenoh.CongestionControl.BLOCK)
        # One subscriber for all inputs keeps their order (see services.bridge_ros2.service).
        inputs = {t.topic: t for t in node.topics.values() if t.kind in INPUTS}

        def on_sample(sample: zenoh.Sample) -> None:
            topic = inputs.get(self.style.topic(comp.manager, str(sample.key_expr)) or "")
            if topic is not None:  # else one of the manager's own outputs
                self._receive(node, topic, sample.payload.to_bytes())

        self._subscribers.append(self.session.declare_subscriber(
            self.style.all_topics(comp.manager, comp.skillset), on_sample))
        self._declare_node(node)

    def _declare_node(self, node: _Node) -> None:
        """rmw_zenoh: the node's liveliness tokens, as rmw_zenoh declares them (graph discovery)."""
        if not self.style.rmw_zenoh:
            return
        entities = [("MP" if t.kind in OUTPUTS else "MS", topic_fqn(node.component.manager, t.topic), t.typename,
                     self.style.type_hash(node.store, t.typename))
                    for t in node.topics.values() if t.kind in OUTPUTS or t.kind in INPUTS]
        _, node.tokens = declare_node(self.session, self.style.domain, node.component.manager, entities)

    def _send(self, node: _Node, topic: str, payload: bytes) -> None:
        """Publish one CDR message of ``node`` on its node-relative ``topic``."""
        attachment = None
        if self.style.rmw_zenoh:
            node.sequence += 1
            attachment = rmw_attachment(node.sequence, time.time_ns(), node.gid)
        node.publishers[topic].put(payload, attachment=attachment)

    def _receive(self, node: _Node, topic: ManagerTopic, payload: bytes) -> None:
        """Handle one CDR input of ``node`` (from any transport) and count it."""
        try:
            self._handle(node, topic, decode(node.store, topic.typename, payload))
        except Exception as exc:  # bad CDR (rosbags raises several types); never crash (docs/semantics.md §7)
            log.warning("%s: %s ignored: %s", node.component.name, topic.topic, exc)
        finally:
            self._count(node, topic.topic)

    def _handle(self, node: _Node, topic: ManagerTopic, msg: Any) -> None:
        m = node.manager
        started = False
        with node.lock:
            if topic.kind == "status_request":
                out = m.status_request()
            elif topic.kind == "event_request":
                out = m.event_request(msg.id, msg.name)
            elif topic.kind == "skill_request":
                skill = m.skills[topic.skill or ""]
                idle = skill.state == READY
                out = m.skill_request(topic.skill or "", msg.id, msg.input)
                started = idle and skill.state == RUNNING
            else:
                out = m.interrupt(topic.skill or "", msg.id)
                if not out:
                    log.info("%s: interrupt '%s' of %s ignored (not the running id or not running)",
                             node.component.name, msg.id, topic.skill)
                elif m.skills[topic.skill or ""].state == INTERRUPTING:
                    out += m.interrupted(topic.skill or "")  # the implementation stops at once
            self._publish(node, out)
            for hook in self.on_start if started else ():
                hook(node.component.name, topic.skill or "", msg.id)

    def _publish(self, node: _Node, messages: list[Message]) -> None:
        if not node.publishers:
            return  # closed
        for message in messages:
            self._send(node, message.topic, encode(node.store, message.typename, message.msg))
            node.statuses += message.topic == node.manager.status_topic

    def _count(self, node: _Node, topic: str) -> None:
        with self._cond:
            node.handled[topic] = node.handled.get(topic, 0) + 1
            self._cond.notify_all()

    def statuses_published(self) -> dict[str, int]:
        """SkillsetStatus messages published so far, per skillset."""
        out = {}
        for name, node in self.nodes.items():
            with node.lock:
                out[name] = node.statuses
        return out

    def commands_handled(self) -> int:
        """Skill requests and interrupts handled so far, by every manager (an operator's or a pilot's commands)."""
        with self._cond:
            return sum(n for node in self.nodes.values() for topic, n in node.handled.items()
                       if node.topics[topic].kind in ("skill_request", "skill_interrupt"))

    def handled(self, skillset: str, topic: str) -> int:
        """Inputs handled so far on a node-relative topic (for callers waiting on their request)."""
        with self._cond:
            return self.nodes[skillset].handled.get(topic, 0)

    def wait_handled(self, skillset: str, topic: str, count: int, timeout: float = 5.0) -> bool:
        """Wait until ``count`` inputs in total were handled on ``topic`` of ``skillset``'s manager."""
        node = self.nodes[skillset]
        with self._cond:
            return self._cond.wait_for(lambda: node.handled.get(topic, 0) >= count, timeout)

    # -- the simulated skill implementations ------------------------------------------------

    def terminate(self, skillset: str, skill: str, kind: str, mode: str = "", id_: str | None = None) -> bool:
        """End a running skill in a success or failure mode; False when it is not running (or, given
        ``id_``, when the execution running is another one)."""
        node = self.nodes[skillset]
        with node.lock:
            if id_ is not None and node.manager.skills[skill].id != id_:
                return False
            out = node.manager.terminate(skill, kind, mode)
            self._publish(node, out)
        return bool(out)

    def raise_event(self, skillset: str, event: str) -> None:
        """An event raised by the implementation itself (response id = status info)."""
        node = self.nodes[skillset]
        with node.lock:
            self._publish(node, node.manager.raise_event(event))

    def skill_status(self, skillset: str, skill: str) -> tuple[bool, str]:
        """(running or interrupting, id of the current or last execution), as the status shows them."""
        node = self.nodes[skillset]
        with node.lock:
            s = node.manager.skills[skill]
            return s.state != READY, s.id

    def drive(self, scenario: Scenario, speed: float = 1.0,
              on_step: Callable[[StepRun], None] | None = None) -> list[StepRun]:
        """Play ``scenario``: operator requests and skill outcomes at ``t / speed`` (see :func:`drive`)."""
        return drive(self, scenario, speed, on_step)

    def restart(self, skillset: str) -> None:
        """The manager of ``skillset`` restarts: initial state, new GID and sequence numbers, new tokens.

        Like a restarted node, it publishes nothing until asked (``status_request``)
        or until something changes.
        """
        node = self.nodes[skillset]
        with node.lock:
            m = node.manager
            node.manager = Manager(m.skillset, node.store, info=m.info, clock=self._clock)
            node.gid, node.sequence = os.urandom(16), 0
            undeclare(*node.tokens)
            self._declare_node(node)

    def close(self) -> None:
        """Undeclare everything (the session stays open: it may be shared).

        Publishers are undeclared under each manager's lock: undeclaring one while a
        Zenoh thread publishes on it fails ("Already borrowed").
        """
        subscribers, self._subscribers = self._subscribers, []
        undeclare(*subscribers)
        for node in self.nodes.values():
            with node.lock:
                publishers, node.publishers = list(node.publishers.values()), {}
                undeclare(*publishers, *node.tokens)


__all__ = ["Simulator"]
