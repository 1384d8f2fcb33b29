"""A bound robot's action servers, lifecycle nodes and topics on real DDS, as ``rmw_cyclonedds`` runs them (docs/semantics.md §9).

:class:`DdsBoundRobot` serves the protocols of :mod:`services.simulator.protocols` on a
CycloneDDS participant (PyPI ``cyclonedds``), laid out as ROS 2 nodes lay them out,
so that ``zenoh-bridge-ros2dds`` routes them to Zenoh exactly as it routes a robot:

- a service ``S`` is a reader of ``rq/<S>Request`` and a writer of ``rr/<S>Reply``
  (types ``<pkg>::<srv|action>::dds_::<Name>_Request_`` / ``_Response_``); every
  request and reply starts with rmw_cyclonedds' 16-byte request header (the
  client's GUID and a sequence number, echoed in the reply), declared here as two
  leading fields: the request's own fields follow at offset 16, so their CDR is
  the same;
- an action ``A`` is the services ``A/_action/send_goal``, ``cancel_goal`` and
  ``get_result`` and the writers of ``rt/A/_action/status`` (reliable, transient
  local, keep last 1) and ``rt/A/_action/feedback``: with all five, the gateway
  creates an action server route (``AS`` liveliness token, queryables, a cached
  status publisher);
- a lifecycle node ``N``: the services ``N/get_state`` and ``N/change_state`` and the writer of
  ``rt/N/transition_event``; bound topics: a writer each;
- ``ros_discovery_info`` lists the nodes (one per action server, one per lifecycle
  node, ``/robot_topics`` for the topics) with their readers' and writers' GIDs.

Operators' goals and cancels reach it through the gateway (Zenoh queries); the
robot's side (:meth:`finish`, :meth:`lifecycle`, :meth:`publish`) is called directly.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

from cyclonedds.core import Listener, Policy, Qos
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.idl import IdlStruct, make_idl_struct, types
from cyclonedds.internal import InvalidSample
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic

from services.simulator.dds import DISCOVERY_TOPIC, discovery_types, gid_size, idl_types, loopback_config
from services.simulator.protocols import ABORTED, SUCCEEDED, ActionLogic, LifecycleLogic
from skinet.ros.actions import message
from skinet.ros.binding import (
    CANCEL_TYPE, CHANGE_STATE_TYPE, GET_STATE_TYPE, STATUS_TYPE, TRANSITION_EVENT_TYPE, Binding, ResourceBinding,
    SkillBinding,
)
from skinet.ros.definitions import rihs01
from skinet.ros.keys import dds_type_name
from skinet.ros.typestore import encode
from skinet.system.model import System

if TYPE_CHECKING:
    from skinet.ros.typestore import Typestore

log = logging.getLogger("skinet.simulator")

HEADER = 16  # rmw_cyclonedds' request header: client GUID (uint64) and sequence number (int64)


class DdsBoundRobot:
    """The bound interfaces of ``system`` as ROS 2 nodes on DDS domain ``domain`` (close with :meth:`close`)."""

    def __init__(self, system: System, bindings: Mapping[str, Binding], *, domain: int = 0, distro: str = "jazzy",
                 config: str | None = None):
        self.system = system
        self.bindings = dict(bindings)
        self.gid_size = gid_size(distro)
        self._domain = Domain(domain, config if config is not None else loopback_config())
        self.participant = DomainParticipant(domain)
        self._entities: list[Any] = []
        self._nodes: dict[str, tuple[list[bytes], list[bytes]]] = {}  # node -> (reader GIDs, writer GIDs)
        self._writers: dict[str, tuple[DataWriter, type[IdlStruct]]] = {}  # DDS topic -> writer, class
        self.actions: dict[tuple[str, str], ActionLogic] = {}
        self._skill_of: dict[int, SkillBinding] = {}  # id(ActionLogic) -> its binding
        self.lifecycles: dict[tuple[str, str], LifecycleLogic] = {}
        for name, b in self.bindings.items():
            store = b.store
            skillset = system.component(name).skillset
            for s in b.skills:
                node = f"{s.action}_server"
                logic = ActionLogic(store, s.type)
                self.actions[(name, s.skill)] = logic
                self._skill_of[id(logic)] = s
                self._service(node, s.name("send_goal"), f"{s.type}_SendGoal", store,
                              lambda data, reply, logic=logic: self._send_goal(logic, data, reply))
                self._service(node, s.name("cancel_goal"), CANCEL_TYPE, store,
                              lambda data, reply, logic=logic: self._cancel(logic, data, reply))
                self._service(node, s.name("get_result"), f"{s.type}_GetResult", store,
                              lambda data, reply, logic=logic: self._get_result(logic, data, reply))
                self._writer(node, s.name("status"), STATUS_TYPE, store, transient_local=True)
                self._writer(node, s.name("feedback"), f"{s.type}_FeedbackMessage", store)
            for r in b.resources:
                if r.lifecycle:
                    initial = dict(r.states).get(skillset.resource(r.resource).initial, 1)
                    lifecycle = LifecycleLogic(store, initial)
                    self.lifecycles[(name, r.resource)] = lifecycle
                    self._service(r.lifecycle, r.get_state, GET_STATE_TYPE, store,
                                  lambda data, reply, lc=lifecycle: self._get_state(lc, reply))
                    self._service(r.lifecycle, r.change_state, CHANGE_STATE_TYPE, store,
                                  lambda data, reply, lc=lifecycle, rb=r: self._change_state(lc, rb, data, reply))
                    self._writer(r.lifecycle, r.transition_event, TRANSITION_EVENT_TYPE, store)
                else:
                    self._writer("/robot_topics", r.topic, r.type, store)
            for e in b.events:
                self._writer("/robot_topics", e.topic, e.type, store)
        self._publish_discovery()

    # -- DDS entities -------------------------------------------------------------------------

    def _qos(self, store: Typestore, typename: str, transient_local: bool = False, depth: int = 10) -> Qos:
        policies = [Policy.Reliability.Reliable(max_blocking_time=10**8),
                    Policy.Durability.TransientLocal if transient_local else Policy.Durability.Volatile,
                    Policy.History.KeepLast(depth), Policy.DataRepresentation(use_cdrv0_representation=True)]
        if self.gid_size == 16:
            policies.append(Policy.Userdata(f"typehash={rihs01(store, typename)};".encode()))
        return Qos(*policies)

    def _gid(self, entity: Any) -> bytes:
        return entity.get_guid().bytes.ljust(self.gid_size, b"\0")

    def _topic(self, name: str, cls: type[IdlStruct]) -> Topic:
        topic = Topic(self.participant, name, cls, qos=Qos(Policy.DataRepresentation(use_cdrv0_representation=True)))
        self._entities.append(topic)
        return topic

    def _writer(self, node: str, topic: str, typename: str, store: Typestore, transient_local: bool = False) -> None:
        cls = idl_types(store, [typename])[typename]
        qos = self._qos(store, typename, transient_local, 1 if transient_local else 10)
        writer = DataWriter(self.participant, self._topic("rt" + topic, cls), qos=qos)
        self._nodes.setdefault(node, ([], []))[1].append(self._gid(writer))
        self._writers["rt" + topic] = (writer, cls)
        self._entities.append(writer)

    def _service(self, node: str, service: str, typename: str, store: Typestore,
                 handle: Callable[[bytes, Callable[[bytes], None]], None]) -> None:
        """A service server: ``handle(request CDR, reply)``, ``reply(response CDR)`` answering that request."""
        classes = idl_types(store, [f"{typename}_Request", f"{typename}_Response"])
        request, response = (self._with_header(classes[f"{typename}_{part}"], f"{typename}_{part}")
                             for part in ("Request", "Response"))
        qos = self._qos(store, typename)
        writer = DataWriter(self.participant, self._topic(f"rr{service}Reply", response), qos=qos)

        def on_data_available(reader: DataReader) -> None:
            for sample in reader.take(N=64):
                if isinstance(sample, InvalidSample):  # a writer's disposal or unregistration: no request
                    continue
                raw = sample.serialize(use_version_2=False)
                header = raw[4:4 + HEADER]

                def reply(payload: bytes, header: bytes = header) -> None:  # rosbags CDR of the response
                    writer.write(response.deserialize(payload[:4] + header + payload[4:]))

                try:
                    handle(raw[:4] + raw[4 + HEADER:], reply)
                except Exception:  # a simulated server never stops (docs/semantics.md §7)
                    log.exception("%s: request not handled", service)

        reader = DataReader(self.participant, self._topic(f"rq{service}Request", request), qos=qos,
                            listener=Listener(on_data_available=on_data_available))
        readers, writers = self._nodes.setdefault(node, ([], []))
        readers.append(self._gid(reader))
        writers.append(self._gid(writer))
        self._entities += [reader, writer]

    @staticmethod
    def _with_header(cls: type[IdlStruct], typename: str) -> type[IdlStruct]:
        fields = {"client_guid": types.uint64, "sequence": types.int64, **cls.__annotations__}
        return make_idl_struct(cls.__name__, dds_type_name(typename).replace("::", "."), fields)

    def _write(self, topic: str, payload: bytes) -> None:
        writer, cls = self._writers["rt" + topic]
        writer.write(cls.deserialize(payload))

    def _publish_discovery(self) -> None:
        """``ros_discovery_info`` as rmw publishes it: this participant's nodes and their entities."""
        gid_cls, node_cls, info_cls = discovery_types(self.gid_size)
        topic = self._topic(DISCOVERY_TOPIC, info_cls)
        writer = DataWriter(self.participant, topic, qos=Qos(
            Policy.Reliability.Reliable(max_blocking_time=10**8), Policy.Durability.TransientLocal,
            Policy.History.KeepLast(1), Policy.DataRepresentation(use_cdrv0_representation=True)))
        nodes = []
        for fqn, (readers, writers) in self._nodes.items():
            namespace, _, name = fqn.rpartition("/")
            nodes.append(node_cls(node_namespace=namespace or "/", node_name=name,
                                  reader_gid_seq=[gid_cls(data=list(g)) for g in readers],
                                  writer_gid_seq=[gid_cls(data=list(g)) for g in writers]))
        writer.write(info_cls(gid=gid_cls(data=list(self._gid(self.participant))), node_entities_info_seq=nodes))
        self._entities.append(writer)

    # -- the servers ----------------------------------------------------------------------------

    def _outputs(self, logic: ActionLogic, outputs: list[tuple[str, bytes]]) -> None:
        skill = self._skill_of[id(logic)]
        for kind, payload in outputs:
            self._write(skill.name(kind), payload)

    def _send_goal(self, logic: ActionLogic, data: bytes, reply: Callable[[bytes], None]) -> None:
        with logic.lock:
            done = logic.send_goal(data)
            if done is not None:
                reply(done[0])
                self._outputs(logic, done[1])

    def _cancel(self, logic: ActionLogic, data: bytes, reply: Callable[[bytes], None]) -> None:
        with logic.lock:
            done = logic.cancel(data)
            if done is not None:
                answer, outputs, due = done
                self._outputs(logic, outputs[:1])
                reply(answer)
                self._outputs(logic, outputs[1:])
                for later, payload in due:
                    later(payload)

    def _get_result(self, logic: ActionLogic, data: bytes, reply: Callable[[bytes], None]) -> None:
        with logic.lock:
            answer = logic.get_result(data, reply)
            if answer is not None:
                reply(answer)

    @staticmethod
    def _get_state(lifecycle: LifecycleLogic, reply: Callable[[bytes], None]) -> None:
        with lifecycle.lock:
            reply(lifecycle.get_state())

    def _change_state(self, lifecycle: LifecycleLogic, resource: ResourceBinding, data: bytes,
                      reply: Callable[[bytes], None]) -> None:
        with lifecycle.lock:
            answer, events = lifecycle.change_state(data)
            for payload in events:
                self._write(resource.transition_event, payload)
            reply(answer)

    # -- the robot's side -------------------------------------------------------------------------

    def finish(self, skillset: str, skill: str, kind: str, result: Mapping[str, Any] | None = None) -> bool:
        """End ``skill``'s latest active goal: ``success`` (SUCCEEDED) or ``failure`` (ABORTED)."""
        logic = self.actions[(skillset, skill)]
        with logic.lock:
            done = logic.finish(SUCCEEDED if kind == "success" else ABORTED, result or {})
            if done is None:
                return False
            self._outputs(logic, done[0])
            for later, payload in done[1]:
                later(payload)
            return True

    def lifecycle(self, skillset: str, resource: str, state: str) -> None:
        """Take a lifecycle node to the model state ``state`` (two TransitionEvents)."""
        binding = self.bindings[skillset]
        r = next(r for r in binding.resources if r.resource == resource)
        logic = self.lifecycles[(skillset, resource)]
        with logic.lock:
            for payload in logic.transition(dict(r.states)[state]):
                self._write(r.transition_event, payload)

    def publish(self, skillset: str, topic: str, fields: Mapping[str, Any]) -> None:
        binding = self.bindings[skillset]
        typename = binding.topics()[topic]
        self._write(topic, encode(binding.store, typename, message(binding.store, typename, fields)))

    def close(self) -> None:
        """Leave the DDS domain (the gateway sees the nodes go)."""
        if self._entities:
            self._entities.clear()
            self._writers.clear()
            self.participant.__del__()  # deletes its readers and writers too
            self._domain.__del__()


__all__ = ["DdsBoundRobot"]
