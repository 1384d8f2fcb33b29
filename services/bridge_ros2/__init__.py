"""bridge_ros2: skillset manager topics (CDR on Zenoh, or a rosbag2 file) to canonical events (docs/semantics.md §1).

``start_bridge(session, system, typemap)`` runs it live; ``replay_bag(path, system,
typemap, emit)`` replays a recording; the derivation itself is
:mod:`skinet.ros.derive`.  Skillsets bound to plain ROS 2 action servers, lifecycle
nodes and topics (docs/semantics.md §9) have their own live bridge
(:func:`services.bridge_ros2.bound_live.start_bound_bridge`) and replay
(:func:`services.bridge_ros2.bound.replay_bags`); their derivation is
:mod:`skinet.ros.bound`.
"""

from services.bridge_ros2.feed import Feed
from services.bridge_ros2.replay import replay_bag
from services.bridge_ros2.service import Bridge, start_bridge

__all__ = ["Bridge", "Feed", "replay_bag", "start_bridge"]
