"""``rmw_zenoh`` liveliness tokens of a node of ours, so that ROS 2 graph tools see it.

``ros2 node list`` and ``ros2 topic info`` over ``rmw_zenoh`` list what the tokens
under ``@ros2_lv/<domain>/`` declare (token layout: :class:`skinet.ros.keys.RosEntity`).
:func:`declare_node` declares a node token and one token per publisher or
subscription; undeclaring them (or closing the session) makes the node disappear.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable
from typing import Any

import zenoh

from skinet.ros.keys import EntityKind, RosEntity, node_entity, topic_entity

_ids = itertools.count(1)  # entity ids, unique in the process (rmw_zenoh numbers them per session)


def declare_node(session: zenoh.Session, domain: int, fqn: str,
                 topics: Iterable[tuple[EntityKind, str, str, str]]) -> tuple[list[RosEntity], list[Any]]:
    """Tokens of the node ``fqn`` and of its ``(kind, topic FQN, ROS type name, type hash)`` entities.

    Returns the entities and the declared tokens (undeclare them to leave the graph).
    """
    node = node_entity(domain, str(session.zid()), next(_ids), fqn)
    entities = [node] + [topic_entity(node, next(_ids), kind, topic, typename, hash_)
                         for kind, topic, typename, hash_ in topics]
    return entities, [session.liveliness().declare_token(e.token()) for e in entities]


__all__ = ["declare_node"]
