"""Zenoh keys of a skillset manager's topics, as ROS 2 gateways carry them (ZENOH.md).

A manager declares its topics relative to its node (``~/spot_skillset/status``,
corpus README), so a topic's fully qualified name is the node name plus the
node-relative topic.  Two ways of getting ROS 2 traffic onto Zenoh:

- ``zenoh-bridge-ros2dds``: key = the FQN without its leading slash, below the
  bridge's optional ``namespace``; the payload is the CDR sample as is.
- ``rmw_zenoh``: key = ``<domain>/<FQN without leading slash>/<DDS type name>/<type
  hash>``; every sample carries a 33-byte attachment (sequence number, source
  timestamp, GID); every node, publisher and subscription declares a liveliness
  token under ``@ros2_lv/<domain>/`` (:class:`RosEntity`).  On Humble the type hash
  is ``TypeHashNotSupported`` (ros2/rmw_zenoh#388).

Pure functions; the type hash comes from ``rosbags`` (``Typestore.hash_rihs01``).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

from skinet.lang.model import Skillset
from skinet.ros.interfaces import (
    event_request_topic,
    event_response_topic,
    skill_topic,
    skill_type,
    status_request_topic,
    status_topic,
    topic_prefix,
)
from skinet.ros.typestore import msg_typename

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

EMPTY_TYPE = "std_msgs/msg/Empty"
ATTACHMENT_SIZE = 33
GID_SIZE = 16

TopicKind = Literal[
    "status", "status_request", "event_request", "event_response",
    "skill_request", "skill_response", "skill_interrupt",
]


@dataclass(frozen=True)
class ManagerTopic:
    """One topic of a manager that the simulator or the bridge uses (corpus README)."""

    kind: TopicKind
    topic: str  # node-relative: ``spot_skillset/skill/teleop/request``
    typename: str  # full ROS type name: ``spot_skillset_interfaces/msg/SkillsetStatus``
    skill: str | None = None  # the skill's model name for skill topics


def manager_topics(skillset: Skillset) -> list[ManagerTopic]:
    """Status, event and skill request/response/interrupt topics of ``skillset``'s manager.

    Data and progress topics are left out: they carry no model-level change.
    """
    t = lambda name: msg_typename(skillset, name)  # noqa: E731
    out = [
        ManagerTopic("status", status_topic(skillset), t("SkillsetStatus")),
        ManagerTopic("status_request", status_request_topic(skillset), EMPTY_TYPE),
        ManagerTopic("event_request", event_request_topic(skillset), t("EventRequest")),
        ManagerTopic("event_response", event_response_topic(skillset), t("EventResponse")),
    ]
    for k in skillset.skills:
        out += [
            ManagerTopic("skill_request", skill_topic(skillset, k, "request"), t(skill_type(k, "Request")), k.name),
            ManagerTopic("skill_response", skill_topic(skillset, k, "response"), t(skill_type(k, "Response")), k.name),
            ManagerTopic("skill_interrupt", skill_topic(skillset, k, "interrupt"), t("SkillInterrupt"), k.name),
        ]
    return out


def topic_fqn(manager: str, topic: str) -> str:
    """``/spot/spot_skillset_manager`` + ``spot_skillset/status`` -> ``/spot/spot_skillset_manager/spot_skillset/status``."""
    node = manager.strip("/")
    if not node:
        raise ValueError("a manager node name is needed (e.g. /spot/spot_skillset_manager)")
    return f"/{node}/{topic.strip('/')}"


def bridge_key(manager: str, topic: str, namespace: str = "") -> str:
    """Key of a topic through ``zenoh-bridge-ros2dds`` (its ``namespace`` option prefixes it)."""
    key = topic_fqn(manager, topic).lstrip("/")
    ns = namespace.strip("/")
    return f"{ns}/{key}" if ns else key


def dds_type_name(typename: str) -> str:
    """``std_msgs/msg/String`` -> ``std_msgs::msg::dds_::String_`` (the DDS name rmw uses)."""
    pkg, sub, name = typename.split("/")
    return f"{pkg}::{sub}::dds_::{name}_"


def type_hash(store: Typestore, typename: str) -> str:
    """``RIHS01_<sha256>``, the hash ``rmw_zenoh`` puts in its keys."""
    return store.hash_rihs01(typename)


def rmw_zenoh_key(manager: str, topic: str, typename: str, hash_: str = "*", domain: int = 0) -> str:
    """Key of a topic through ``rmw_zenoh``; ``hash_="*"`` matches any type hash (subscribers)."""
    return f"{domain}/{topic_fqn(manager, topic).lstrip('/')}/{dds_type_name(typename)}/{hash_}"


@dataclass(frozen=True)
class KeyStyle:
    """How topics map to keys: ``zenoh-bridge-ros2dds`` (default) or ``rmw_zenoh``.

    ``humble``: ``rmw_zenoh`` on Humble, whose keys and tokens carry
    ``TypeHashNotSupported`` instead of a RIHS01 hash (ros2/rmw_zenoh#388).
    """

    rmw_zenoh: bool = False
    namespace: str = ""  # zenoh-bridge-ros2dds namespace
    domain: int = 0  # ROS domain id (rmw_zenoh)
    humble: bool = False

    def type_hash(self, store: Typestore, typename: str) -> str:
        """The type hash ``rmw_zenoh`` puts in keys and tokens for ``typename``."""
        return NO_TYPE_HASH if self.humble else type_hash(store, typename)

    def key(self, manager: str, topic: ManagerTopic, store: Typestore | None = None) -> str:
        """Publication key (with the exact type hash when ``store`` is given) or subscription key."""
        if not self.rmw_zenoh:
            return bridge_key(manager, topic.topic, self.namespace)
        hash_ = self.type_hash(store, topic.typename) if store is not None else "*"
        return rmw_zenoh_key(manager, topic.topic, topic.typename, hash_, self.domain)

    def name_key(self, name: str, typename: str, store: Typestore | None = None) -> str:
        """Key of any ROS 2 topic or service ``name`` (``/navigate_to_pose/_action/status``) of type
        ``typename`` (a service: ``lifecycle_msgs/srv/GetState``); the type hash is ``*`` without ``store``."""
        fqn = "/" + name.strip("/")
        if not self.rmw_zenoh:
            ns = self.namespace.strip("/")
            return f"{ns}{fqn}" if ns else fqn[1:]
        hash_ = self.type_hash(store, typename) if store is not None else "*"
        return f"{self.domain}{fqn}/{dds_type_name(typename)}/{hash_}"

    def _node(self, manager: str) -> str:
        node = topic_fqn(manager, "")[1:].rstrip("/")
        if self.rmw_zenoh:
            return f"{self.domain}/{node}"
        ns = self.namespace.strip("/")
        return f"{ns}/{node}" if ns else node

    def all_topics(self, manager: str, skillset: Skillset) -> str:
        """One key expression for every topic of the manager (``.../spot_skillset/**``).

        One subscriber on it sees the samples in the order they were sent, which
        separate subscribers per key do not guarantee (their callbacks run on
        different threads).
        """
        return f"{self._node(manager)}/{topic_prefix(skillset)}/**"

    def topic(self, manager: str, key: str) -> str | None:
        """Node-relative topic of a key matched by :meth:`all_topics` (``None`` if not the manager's)."""
        head = self._node(manager) + "/"
        if not key.startswith(head):
            return None
        rest = key[len(head):]
        if self.rmw_zenoh:
            parts = rest.split("/")
            if len(parts) < 3:
                return None
            rest = "/".join(parts[:-2])  # drop the DDS type name and the type hash
        return rest


# -- rmw_zenoh liveliness tokens (graph discovery: ``ros2 node list``, ``ros2 topic info``) ----------

LIVELINESS_PREFIX = "@ros2_lv"
NO_TYPE_HASH = "TypeHashNotSupported"  # rmw_zenoh on Humble
DEFAULT_QOS = "::,:,:,:,,"  # reliable, volatile, keep last 10: every field at rmw's default is left empty
EntityKind = Literal["NN", "MP", "MS", "SS", "SC"]  # node, publisher, subscription, service, client


@dataclass(frozen=True)
class RosEntity:
    """One ``rmw_zenoh`` liveliness token, parsed (names demangled, ``/`` restored)."""

    domain: int
    zid: str  # the Zenoh session id, hexadecimal
    node_id: int
    entity_id: int
    kind: EntityKind
    enclave: str
    namespace: str  # ``/`` for none
    node: str
    topic: str = ""  # fully qualified; empty for a node
    dds_type: str = ""  # ``std_msgs::msg::dds_::Empty_``
    type_hash: str = ""  # ``RIHS01_...`` or ``TypeHashNotSupported``
    qos: str = ""

    def token(self) -> str:
        """The token's key: ``@ros2_lv/<domain>/<zid>/<node id>/<entity id>/<kind>/<enclave>/<namespace>/<node>``
        then, for a topic, ``/<topic>/<dds type>/<type hash>/<qos>`` (``/`` in names written ``%``)."""
        parts = [LIVELINESS_PREFIX, str(self.domain), self.zid, str(self.node_id), str(self.entity_id), self.kind,
                 _mangle(self.enclave), _mangle(self.namespace), self.node]
        if self.topic:
            parts += [_mangle(self.topic), self.dds_type, self.type_hash, self.qos]
        return "/".join(parts)

    @property
    def node_fqn(self) -> str:
        return f"{self.namespace.rstrip('/')}/{self.node}"


def _mangle(name: str) -> str:
    return name.replace("/", "%")


def node_entity(domain: int, zid: str, node_id: int, fqn: str, enclave: str = "/") -> RosEntity:
    """The node token of the node with fully qualified name ``fqn`` (``/spot/spot_skillset_manager``)."""
    namespace, _, node = topic_fqn(fqn, "x")[:-2].rpartition("/")
    return RosEntity(domain, zid, node_id, node_id, "NN", enclave, namespace or "/", node)


def topic_entity(node: RosEntity, entity_id: int, kind: EntityKind, topic: str, typename: str, type_hash_: str,
                 qos: str = DEFAULT_QOS) -> RosEntity:
    """The token of a publisher (``MP``) or subscription (``MS``) of ``node`` on the FQN ``topic``."""
    return RosEntity(node.domain, node.zid, node.node_id, entity_id, kind, node.enclave, node.namespace, node.node,
                     topic, dds_type_name(typename), type_hash_, qos)


def parse_liveliness_token(key: str) -> RosEntity | None:
    """The entity of an ``rmw_zenoh`` token key; ``None`` when ``key`` is not one."""
    parts = key.split("/")
    if len(parts) not in (9, 13) or parts[0] != LIVELINESS_PREFIX or parts[5] not in ("NN", "MP", "MS", "SS", "SC"):
        return None
    try:
        domain, node_id, entity_id = int(parts[1]), int(parts[3]), int(parts[4])
    except ValueError:
        return None
    names = [p.replace("%", "/") for p in parts[6:9]]
    topic = parts[9:] if len(parts) == 13 else ["", "", "", ""]
    return RosEntity(domain, parts[2], node_id, entity_id, parts[5], *names,  # type: ignore[arg-type]
                     topic[0].replace("%", "/"), topic[1], topic[2], topic[3])


def liveliness_key_expr(domain: int) -> str:
    """Every ``rmw_zenoh`` token of ``domain`` (subscribe with history to see those already declared)."""
    return f"{LIVELINESS_PREFIX}/{domain}/**"


def rmw_attachment(sequence: int, timestamp_ns: int, gid: bytes) -> bytes:
    """The 33-byte ``rmw_zenoh`` attachment: int64 sequence, int64 timestamp, GID length byte + GID."""
    if len(gid) != GID_SIZE:
        raise ValueError(f"a GID has {GID_SIZE} bytes, got {len(gid)}")
    return struct.pack("<qqB", sequence, timestamp_ns, GID_SIZE) + gid


ADVANCED_CACHE = "@adv/**"  # zenoh-ext: where an AdvancedPublisher's cache answers (transient local topics)


def history_selector(key: str) -> str:
    """The selector that asks the caches of the advanced publishers on ``key`` for their samples
    (``zenoh-bridge-ros2dds`` and ``rmw_zenoh`` keep a transient local topic's last samples there)."""
    return f"{key}/{ADVANCED_CACHE}"


def parse_rmw_attachment(data: bytes) -> tuple[int, int, bytes]:
    """``(sequence, timestamp_ns, gid)`` of an ``rmw_zenoh`` attachment; ``ValueError`` if malformed."""
    if len(data) != ATTACHMENT_SIZE or data[16] != GID_SIZE:
        raise ValueError(f"not an rmw_zenoh attachment ({len(data)} bytes)")
    sequence, timestamp = struct.unpack_from("<qq", data)
    return sequence, timestamp, bytes(data[17:])


__all__ = [
    "ADVANCED_CACHE", "ATTACHMENT_SIZE", "DEFAULT_QOS", "history_selector", "EMPTY_TYPE", "EntityKind", "KeyStyle", "LIVELINESS_PREFIX", "ManagerTopic",
    "NO_TYPE_HASH",
    "RosEntity", "TopicKind", "bridge_key", "dds_type_name", "liveliness_key_expr", "manager_topics", "node_entity",
    "parse_liveliness_token", "parse_rmw_attachment", "rmw_attachment", "rmw_zenoh_key", "topic_entity", "topic_fqn",
    "type_hash",
]
