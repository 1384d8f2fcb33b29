"""Simulated skillset managers on real DDS, as ROS 2 nodes with ``rmw_cyclonedds`` run them.

:class:`DdsSimulator` is the :class:`~services.simulator.service.Simulator` (same
:class:`~services.simulator.manager.Manager` semantics, same scenario driver) with a
real CycloneDDS participant (PyPI ``cyclonedds``) as transport instead of Zenoh keys,
so that ``zenoh-bridge-ros2dds`` routes it exactly as it routes a robot:

- each manager topic is the DDS topic ``rt/<fully qualified name>`` of type
  ``<package>::msg::dds_::<Name>_``, reliable, volatile, keep-last 10 (rmw defaults);
  samples are XCDR1 (``DataRepresentation(use_cdrv0_representation=True)``), as rmw
  writes them; since Iron the readers and writers carry ``typehash=RIHS01_...;`` in
  their USER_DATA;
- the participant publishes ``ros_discovery_info`` (``rmw_dds_common``'s
  ``ParticipantEntitiesInfo``: one ``NodeEntitiesInfo`` per manager node with the GIDs
  of its readers and writers), with 24-byte GIDs for Humble and 16-byte ones from
  Iron on: without it ``zenoh-bridge-ros2dds`` creates no route.

The DDS types are built from the skillset's ``rosbags`` type store
(:func:`idl_types`); the managers' messages are rosbags CDR decoded by CycloneDDS
and re-encoded by it, and inputs go the other way, so both CDR implementations meet
on every message.  Operator requests of :meth:`DdsSimulator.drive` are still put on
Zenoh (``style`` keys): they reach the managers through the gateway.

Cost: one DDS reader or writer per manager topic; per message one rosbags encoding
and one CycloneDDS decoding (or the reverse).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable, Mapping
from typing import TYPE_CHECKING, Any

import zenoh
from cyclonedds.core import Listener, Policy, Qos
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.idl import IdlStruct, make_idl_struct, types
from cyclonedds.internal import InvalidSample
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from rosbags.interfaces import Nodetype

from services.simulator.service import INPUTS, OUTPUTS, Simulator, _Node
from skinet.ros.keys import KeyStyle, dds_type_name, topic_fqn, type_hash
from skinet.system.model import System

if TYPE_CHECKING:
    from skinet.ros.typestore import Typestore

log = logging.getLogger("skinet.simulator")

# rmw_dds_common/msg/Gid: char[24] up to Humble, uint8[16] from Iron on.
OLD_GIDS = ("foxy", "galactic", "humble")


def gid_size(distro: str) -> int:
    """Bytes of a GID in ``ros_discovery_info`` for a ROS 2 distribution (lower case name)."""
    return 24 if distro in OLD_GIDS else 16

DISCOVERY_TOPIC = "ros_discovery_info"
_BASE = {
    "bool": bool, "byte": types.uint8, "char": types.uint8, "octet": types.uint8, "string": str,
    **{n: getattr(types, n) for n in ("int8", "int16", "int32", "int64", "uint8", "uint16", "uint32", "uint64",
                                      "float32", "float64")},
}


def loopback_config(interface: str = "127.0.0.1", peers: Iterable[str] = ("127.0.0.1",),
                    max_participants: int = 32) -> str:
    """CycloneDDS XML for unicast discovery on ``interface`` (``lo`` has no multicast).

    Every participant of the domain on the host needs it (``CYCLONEDDS_URI`` for the
    others): each takes the first free participant index and pings the peers' first
    ``max_participants`` indices.
    """
    peer_list = "".join(f'<Peer address="{p}"/>' for p in peers)
    return (f'<CycloneDDS><Domain Id="any"><General><Interfaces><NetworkInterface address="{interface}"/>'
            f"</Interfaces><AllowMulticast>false</AllowMulticast></General><Discovery>"
            f"<ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>{max_participants}"
            f"</MaxAutoParticipantIndex><Peers>{peer_list}</Peers></Discovery></Domain></CycloneDDS>")


def idl_types(store: Typestore, typenames: Iterable[str]) -> dict[str, type[IdlStruct]]:
    """CycloneDDS classes of ``typenames`` and the types they use, named as rmw names them on DDS."""
    out: dict[str, type[IdlStruct]] = {}

    def field_type(desc: Any) -> Any:
        kind, arg = desc
        if kind == Nodetype.BASE:
            return _BASE[arg[0]]
        if kind == Nodetype.NAME:
            return build(arg)
        sub, length = arg
        if kind == Nodetype.ARRAY:
            return types.array[field_type(sub), length]
        return types.sequence[field_type(sub), length] if length else types.sequence[field_type(sub)]

    def build(typename: str) -> type[IdlStruct]:
        if typename not in out:
            _, fielddefs = store.fielddefs[typename]
            fields = {name: field_type(desc) for name, desc in fielddefs}
            out[typename] = make_idl_struct(typename.rsplit("/", 1)[-1], dds_type_name(typename).replace("::", "."),
                                            fields)
        return out[typename]

    for name in typenames:
        build(name)
    return out


def discovery_types(size: int) -> tuple[type[IdlStruct], type[IdlStruct], type[IdlStruct]]:
    """``rmw_dds_common`` ``Gid``, ``NodeEntitiesInfo`` and ``ParticipantEntitiesInfo`` with GIDs of ``size`` bytes."""
    gid = make_idl_struct("Gid", "rmw_dds_common.msg.dds_.Gid_", {"data": types.array[types.uint8, size]})
    node = make_idl_struct("NodeEntitiesInfo", "rmw_dds_common.msg.dds_.NodeEntitiesInfo_", {
        "node_namespace": types.bounded_str[256], "node_name": types.bounded_str[256],
        "reader_gid_seq": types.sequence[gid], "writer_gid_seq": types.sequence[gid]})
    participant = make_idl_struct("ParticipantEntitiesInfo", "rmw_dds_common.msg.dds_.ParticipantEntitiesInfo_", {
        "gid": gid, "node_entities_info_seq": types.sequence[node]})
    return gid, node, participant


class DdsSimulator(Simulator):
    """Every skillset manager of ``system`` as ROS 2 nodes on DDS domain ``domain``.

    ``session`` and ``style`` are those of the operator (:meth:`drive`): a Zenoh
    session reaching the gateway and the keys the gateway uses.  ``distro`` sets the
    ``ros_discovery_info`` format (``humble`` and older: 24-byte GIDs; ``iron``,
    ``jazzy`` and later: 16 bytes and type hashes in USER_DATA).  ``config`` is CycloneDDS
    XML (default: :func:`loopback_config`).
    """

    def __init__(self, session: zenoh.Session, system: System, typemap: Mapping[str, str], *, domain: int = 0,
                 distro: str = "jazzy", config: str | None = None, style: KeyStyle = KeyStyle(),
                 **options: Any):
        self.distro = distro
        self.gid_size = gid_size(distro)
        self._domain = Domain(domain, config if config is not None else loopback_config())
        self.participant = DomainParticipant(domain)
        self._entities: list[Any] = []  # readers and writers, kept alive
        self._node_gids: dict[str, tuple[list[bytes], list[bytes]]] = {}  # manager -> (reader, writer) GIDs
        self._classes: dict[str, dict[str, type[IdlStruct]]] = {}  # skillset -> ROS type name -> DDS class
        super().__init__(session, system, typemap, style=style, **options)
        self._discovery = self._publish_discovery()

    def _qos(self, store: Typestore, typename: str) -> Qos:
        policies = [Policy.Reliability.Reliable(max_blocking_time=10**8), Policy.Durability.Volatile,
                    Policy.History.KeepLast(10), Policy.DataRepresentation(use_cdrv0_representation=True)]
        if self.gid_size == 16:
            policies.append(Policy.Userdata(f"typehash={type_hash(store, typename)};".encode()))
        return Qos(*policies)

    def _gid(self, entity: Any) -> bytes:
        return entity.get_guid().bytes.ljust(self.gid_size, b"\0")

    def _open(self, node: _Node) -> None:
        manager = node.component.manager
        classes = idl_types(node.store, {t.typename for t in node.topics.values()})
        readers, writers = self._node_gids.setdefault(manager, ([], []))
        self._classes[node.component.name] = classes
        for t in node.topics.values():
            if t.kind not in INPUTS and t.kind not in OUTPUTS:
                continue
            topic = Topic(self.participant, "rt" + topic_fqn(manager, t.topic), classes[t.typename],
                          qos=Qos(Policy.DataRepresentation(use_cdrv0_representation=True)))
            qos = self._qos(node.store, t.typename)
            if t.kind in OUTPUTS:
                writer = DataWriter(self.participant, topic, qos=qos)
                node.publishers[t.topic] = writer
                writers.append(self._gid(writer))
            else:
                reader = DataReader(self.participant, topic, qos=qos,
                                    listener=Listener(on_data_available=self._on_data(node, t)))
                readers.append(self._gid(reader))
                self._entities.append(reader)
            self._entities.append(topic)

    def _on_data(self, node: _Node, topic: Any) -> Callable[[DataReader], None]:
        def on_data_available(reader: DataReader) -> None:
            for sample in reader.take(N=64):
                if not isinstance(sample, InvalidSample):  # a writer's disposal or unregistration: no data
                    self._receive(node, topic, sample.serialize(use_version_2=False))

        return on_data_available

    def _send(self, node: _Node, topic: str, payload: bytes) -> None:
        cls = self._classes[node.component.name][node.topics[topic].typename]
        node.publishers[topic].write(cls.deserialize(payload))

    def _publish_discovery(self) -> DataWriter:
        """``ros_discovery_info`` as rmw publishes it: this participant's nodes and their entities."""
        gid_cls, node_cls, info_cls = discovery_types(self.gid_size)
        topic = Topic(self.participant, DISCOVERY_TOPIC, info_cls,
                      qos=Qos(Policy.DataRepresentation(use_cdrv0_representation=True)))
        writer = DataWriter(self.participant, topic, qos=Qos(
            Policy.Reliability.Reliable(max_blocking_time=10**8), Policy.Durability.TransientLocal,
            Policy.History.KeepLast(1), Policy.DataRepresentation(use_cdrv0_representation=True)))
        nodes = []
        for manager, (readers, writers) in self._node_gids.items():
            namespace, _, name = topic_fqn(manager, "x")[:-2].rpartition("/")
            nodes.append(node_cls(node_namespace=namespace or "/", node_name=name,
                                  reader_gid_seq=[gid_cls(data=list(g)) for g in readers],
                                  writer_gid_seq=[gid_cls(data=list(g)) for g in writers]))
        writer.write(info_cls(gid=gid_cls(data=list(self._gid(self.participant))), node_entities_info_seq=nodes))
        self._entities += [topic, writer]
        return writer

    def close(self) -> None:
        """Leave the DDS domain (the gateway sees the nodes go)."""
        for node in self.nodes.values():
            with node.lock:
                node.publishers = {}
        if self._entities:
            self._entities.clear()
            self.participant.__del__()  # deletes its readers and writers too
            self._domain.__del__()


__all__ = ["DdsSimulator", "gid_size", "discovery_types", "idl_types", "loopback_config"]
