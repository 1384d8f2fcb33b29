"""How the pilot acts on the robot (docs/semantics.md §8, *The pilot*; §9, *Acting*).

An :class:`Actuator` sends one :class:`~skinet.wire.messages.PilotCommand`
(``SKILL.start`` with its inputs, ``SKILL.interrupt``, or an event a binding commands)
and says what it sent,
for the log; it raises :class:`ActError` with the reason when it cannot.  Which
protocol carries a skill is decided in one place, :func:`route`, and
:class:`Routed` (the pilot's :func:`default_actuator`) sends each command
through the actuator of its route: the :class:`ManagerActuator` speaks a
generated skillset manager's request protocol, as an operator GUI does
(:mod:`skinet.ros.requests`); skills bound to ROS 2 actions (docs/semantics.md §9) and the events
a binding commands go to the :class:`~services.pilot.bound_act.BoundActuator` (a goal,
a cancel request, a lifecycle transition, a topic message).

An interrupt needs the running execution's id.  The manager's own
``SkillsetStatus`` says it: the actuator follows each manager's status topic and,
when the last one it saw does not show the skill running (or it saw none), asks
for it (``status_request``) and waits up to ``STATUS_WAIT`` for one that does.
A start waits (up to ``REACT_WAIT``) for the manager's answer: the status showing
its id, or a refusal (``ALREADY_RUNNING``, ``PRECONDITION_FAILURE``...), raised as
:class:`Refused` since such a refusal changes nothing the monitor could show.
A pilot's start ids are ``<instance>-<n>``.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, Literal, Protocol

import zenoh

from services.pilot.errors import ActError, Refused
from services.common.requests import Requests
from services.common.zenoh_config import undeclare
from skinet.errors import SkinetError
from skinet.ros.derive import SkillView
from skinet.ros.keys import KeyStyle, manager_topics
from skinet.ros.requests import (
    plain_inputs, request_inputs, skill_ids, skill_interrupt, skill_request, start_refusal, status_request,
)
from skinet.ros.typestore import build_typestore
from skinet.system.model import Component, System
from skinet.wire.messages import PilotCommand

if TYPE_CHECKING:
    from skinet.ros.typestore import Typestore

log = logging.getLogger("skinet.pilot")
STATUS_WAIT = 1.0  # seconds an interrupt waits for a status showing its skill running, when the last does not
REACT_WAIT = 1.0  # seconds a start waits for the manager's answer (its status, or a refusal) before it returns
READY = 0  # SkillXStatus.state
MAX_REQUESTS = 64  # start requests remembered per skill (their inputs, by execution id)


class Actuator(Protocol):
    """What the pilot needs to act."""

    def send(self, command: PilotCommand) -> str:
        """Send ``command``; returns what was sent (for the log); raises :class:`ActError`."""
        ...

    def close(self) -> None: ...


def inputs_problem(actuator: object, skillset: str, skill: str, inputs: Mapping[str, Any]) -> str | None:
    """Why ``actuator`` could not send a start of ``skillset:skill`` with ``inputs``, when it can tell before
    sending (its optional ``problem`` method: a bound skill's goal message, docs/semantics.md §9), else None."""
    check = getattr(actuator, "problem", None)
    return check(skillset, skill, inputs) if check is not None else None


def route(system: System, skillset: str, skill: str) -> Literal["manager", "binding"]:
    """The protocol that carries ``skillset:skill``'s commands: ``binding`` when its skillset is bound to
    plain ROS 2 interfaces (docs/semantics.md §9: the binding's action), else ``manager`` (the manager's requests)."""
    return "binding" if system.component(skillset).binding else "manager"


def responder(system: System, skillset: str, skill: str) -> str:
    """Who must react to a command of ``skillset:skill``, in the operator's words (``no response from ...``):
    its manager node, or, for a bound skill (:func:`route`), its action server."""
    if route(system, skillset, skill) == "binding":
        if skill in system.component(skillset).commanded:  # a commanded event: its resource's interface
            return f"the interface of {skillset}'s commanded resource ({skill})"
        return f"the action server of {skillset}:{skill}"
    return system.component(skillset).manager or skillset


class ManagerActuator:
    """Commands as ``Skill<K>Request`` and ``SkillInterrupt`` on the managers' topics (keys of ``style``).

    ``typemap`` is the system's type map (``[system] types``): a skillset whose interface messages
    cannot be built from it is refused at each command, with the type map's error as the reason."""

    def __init__(self, session: zenoh.Session, system: System, typemap: Mapping[str, str] | None = None,
                 style: KeyStyle = KeyStyle(), instance: str = "pilot"):
        self.system, self.instance = system, instance
        self._stores: dict[str, Typestore] = {}
        self._problems: dict[str, str] = {}
        for c in system.components:
            if route(system, c.name, "") == "binding":
                continue
            if not c.manager:
                self._problems[c.name] = f"skillset {c.name} names no manager node (manager = ... in the system file)"
                continue
            try:
                self._stores[c.name] = build_typestore(c.skillset, typemap or {})
            except SkinetError as exc:
                self._problems[c.name] = f"the interface messages of {c.name} cannot be built: {exc}"
        nodes = [(system.component(name), store) for name, store in self._stores.items()]
        self._requests = Requests(session, nodes, style)
        self._lock = threading.Condition()
        self._ids: dict[str, dict[str, SkillView]] = {}  # skillset -> skill -> state and id, from its status
        self._count = 0
        self._starts: dict[str, tuple[str, str, str]] = {}  # start id -> (skillset, skill, refusal or "")
        self._requested: dict[tuple[str, str], dict[str, dict[str, Any]]] = {}  # (skillset, skill) -> id -> inputs
        # One subscriber per manager keeps its messages in order: a refusal comes before the status after it.
        self.style = style
        self._topics = {c.name: {t.topic: t for t in manager_topics(c.skillset)} for c, _ in nodes}
        self._subs = [session.declare_subscriber(style.all_topics(c.manager, c.skillset),
                                                 lambda s, c=c: self._on_sample(c, s)) for c, _ in nodes]

    def _on_sample(self, component: Component, sample: zenoh.Sample) -> None:
        topic = self._topics[component.name].get(self.style.topic(component.manager, str(sample.key_expr)) or "")
        if topic is None or topic.kind not in ("status", "skill_response", "skill_request"):
            return  # interrupts and the other outputs
        store, skillset = self._stores[component.name], component.skillset
        try:
            if topic.kind == "skill_request":  # anyone's start (ours too): its inputs, by execution id
                id_, inputs = request_inputs(store, skillset, topic.skill or "", sample.payload.to_bytes())
                with self._lock:
                    seen = self._requested.setdefault((component.name, topic.skill or ""), {})
                    seen.pop(id_, None)
                    seen[id_] = inputs
                    while len(seen) > MAX_REQUESTS:
                        del seen[next(iter(seen))]
                return
            if topic.kind == "status":
                ids = skill_ids(store, skillset, sample.payload.to_bytes())
                with self._lock:
                    self._ids[component.name] = ids
                    self._lock.notify_all()
                return
            refusal = start_refusal(store, skillset, topic.skill or "", sample.payload.to_bytes())
        except Exception as exc:  # a malformed message must not stop the pilot (docs/semantics.md §7)
            log.warning("%s of %s not understood: %s", topic.topic, component.manager, exc)
            return
        if refusal is None:
            return
        id_, why = refusal
        with self._lock:
            for start, (ss, skill, _) in self._starts.items():
                # ALREADY_RUNNING names the running execution, not the refused one
                if (ss, skill) == (component.name, topic.skill) and (start == id_ or why.startswith("ALREADY")):
                    self._starts[start] = (ss, skill, why)
            self._lock.notify_all()

    def send(self, command: PilotCommand) -> str:
        skillset, (skill, _, kind) = command.skillset, command.transition.partition(".")
        if skillset not in self._stores:
            raise ActError(self._problems.get(skillset) or f"{skillset}:{skill} is bound to a ROS 2 interface; "
                                                            "this actuator speaks only the managers' protocol")
        c = self.system.component(skillset)
        store = self._stores[skillset]
        if kind == "start":
            with self._lock:
                id_ = f"{self.instance}-{self._count + 1}"
                try:
                    request = skill_request(store, c.skillset, skill, id_, command.inputs)
                except (ValueError, KeyError, TypeError) as exc:
                    raise ActError(f"cannot encode {skillset}:{command.transition}: {exc}") from None
                self._count += 1
                self._starts[id_] = (skillset, skill, "")
            key = self._requests.put(skillset, *request)
            with self._lock:  # the manager's answer: its status with the new id, or a refusal before it
                self._lock.wait_for(lambda: self._starts[id_][2] or self._shows(skillset, skill, id_), REACT_WAIT)
                refusal = self._starts.pop(id_)[2]
            if refusal:
                raise Refused(f"{c.manager} refused {skillset}:{command.transition}: {refusal}")
            return f"{command.transition} (id '{id_}'{_inputs(command.inputs)}) on {key}"
        if kind == "interrupt":
            id_ = self._running_id(c, store, skill)
            key = self._requests.put(skillset, *skill_interrupt(store, c.skillset, skill, id_))
            return f"{command.transition} (running id '{id_}') on {key}"
        raise ActError(f"{skillset}:{command.transition} is not a command (SKILL.start or SKILL.interrupt)")

    def start_inputs(self, skillset: str, skill: str, given: Mapping[str, Any]) -> tuple[bool, dict[str, Any]] | None:
        """Whether the execution of ``skillset:skill`` its manager's last status shows (running, or the last
        one) was started with ``given`` (fields left out at their defaults), with the inputs its request
        carried; None when that request was not heard (or the status not seen)."""
        store = self._stores.get(skillset)
        with self._lock:
            view = self._ids.get(skillset, {}).get(skill)
            inputs = None if view is None else self._requested.get((skillset, skill), {}).get(view.id)
        if store is None or inputs is None:
            return None
        try:
            wanted = plain_inputs(store, self.system.component(skillset).skillset, skill, given)
        except (ValueError, KeyError, TypeError):
            return False, inputs
        return wanted == inputs, inputs

    def ask_status(self, skillset: str) -> str:
        """Ask ``skillset``'s manager for its status (``status_request``); what was sent, for the log."""
        if skillset not in self._stores:
            raise ActError(self._problems.get(skillset) or f"{skillset} has no manager this actuator speaks to")
        c = self.system.component(skillset)
        key = self._requests.put(skillset, *status_request(self._stores[skillset], c.skillset))
        return f"status_request on {key}"

    def _shows(self, skillset: str, skill: str, id_: str) -> bool:
        """Whether the manager's last status shows ``id_`` as ``skill``'s execution (lock held)."""
        view = self._ids.get(skillset, {}).get(skill)
        return view is not None and view.id == id_

    def _running_id(self, c: Component, store: Typestore, skill: str) -> str:
        """The id of ``skill``'s running execution, as the manager's last status shows it.  A last status that
        shows it not running may predate its start (the monitor hears the start through the bridge, the actuator
        the status on its own subscription): the actuator asks for the status and waits up to ``STATUS_WAIT``
        for one that shows it running."""
        def running() -> bool:
            view = self._ids.get(c.name, {}).get(skill)
            return view is not None and view.state != READY

        with self._lock:
            if not running():
                self._requests.put(c.name, *status_request(store, c.skillset))
                self._lock.wait_for(running, STATUS_WAIT)
            view = self._ids.get(c.name, {}).get(skill)
        if view is None:
            raise ActError(f"the running id of {c.name}:{skill} is unknown: no status from {c.manager} "
                           f"within {STATUS_WAIT:g} s")
        if view.state == READY:
            raise ActError(f"{c.name}:{skill} is not running according to {c.manager}'s last status")
        return view.id

    def close(self) -> None:
        undeclare(*self._subs)
        self._requests.close()


class Routed:
    """Sends each command through the actuator of its :func:`route` (``manager`` or ``binding``)."""

    def __init__(self, system: System, actuators: Mapping[str, Actuator]):
        self.system, self.actuators = system, dict(actuators)

    def problem(self, skillset: str, skill: str, inputs: Mapping[str, Any]) -> str | None:
        """What the actuator of the skill's route says of a start with ``inputs`` (see :func:`inputs_problem`)."""
        try:
            actuator = self.actuators.get(route(self.system, skillset, skill))
        except KeyError:
            return None
        return inputs_problem(actuator, skillset, skill, inputs) if actuator is not None else None

    def start_inputs(self, skillset: str, skill: str, given: Mapping[str, Any]) -> tuple[bool, dict[str, Any]] | None:
        """What the managers' actuator says of the inputs of ``skillset:skill``'s last start (see
        :meth:`ManagerActuator.start_inputs`); None for a bound skill."""
        check = getattr(self.actuators.get("manager"), "start_inputs", None)
        return None if check is None else check(skillset, skill, given)  # type: ignore[no-any-return]

    def ask_status(self, skillset: str) -> str:
        """Ask ``skillset``'s manager for its status (a bound skillset has none: :class:`ActError`)."""
        ask = getattr(self.actuators.get("manager"), "ask_status", None)
        if ask is None:
            raise ActError(f"this pilot cannot ask {skillset} for its status")
        return str(ask(skillset))

    def send(self, command: PilotCommand) -> str:
        skill = command.transition.partition(".")[0]
        try:
            way = route(self.system, command.skillset, skill)
        except KeyError:
            raise ActError(f"unknown skillset '{command.skillset}' of {self.system.name}") from None
        actuator = self.actuators.get(way)
        if actuator is None:
            raise ActError(f"{command.skillset}:{skill} is bound to a ROS 2 interface (docs/semantics.md §9), and this pilot "
                           "cannot act through bindings")
        return actuator.send(command)

    def close(self) -> None:
        for actuator in self.actuators.values():
            actuator.close()


def default_actuator(session: zenoh.Session, system: System, typemap: Mapping[str, str] | None = None,
                     style: KeyStyle = KeyStyle(), instance: str = "pilot",
                     bindings: Mapping[str, Any] | None = None) -> Actuator:
    """The pilot's default: each skill through the protocol :func:`route` gives it, on the keys of ``style``:
    a :class:`ManagerActuator` for the managers' skillsets, a
    :class:`~services.pilot.bound_act.BoundActuator` for the bound ones (``bindings``: skillset name ->
    :class:`~skinet.ros.binding.Binding`, read from the system's binding files when not given; a binding
    that does not load raises :class:`~skinet.errors.SourceError`)."""
    actuators: dict[str, Actuator] = {"manager": ManagerActuator(session, system, typemap, style, instance)}
    if any(c.binding for c in system.components):
        from services.pilot.bound_act import BoundActuator  # only systems with bindings need it
        from skinet.system.load import load_bindings

        if bindings is None:
            bindings, _ = load_bindings(system)
        actuators["binding"] = BoundActuator(session, bindings, style=style,
                                             skillsets={c.name: c.skillset for c in system.components})
    return Routed(system, actuators)


def _inputs(inputs: Mapping[str, object]) -> str:
    return f", inputs {dict(inputs)}" if inputs else ""


__all__ = ["ActError", "Actuator", "ManagerActuator", "Refused", "Routed", "default_actuator", "inputs_problem",
           "responder", "route"]
