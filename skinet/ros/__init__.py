"""ROS 2 side of a skillset: type maps, interface messages, CDR type store.

Pure functions only (no file I/O): :mod:`skinet.ros.typemap` parses a type-map
JSON text, :mod:`skinet.ros.interfaces` generates the ``.msg`` definitions and
topic names of a generated skillset manager, :mod:`skinet.ros.typestore` turns
them into a ``rosbags`` type store for CDR encoding and decoding.
"""

from skinet.ros.interfaces import generate_messages, package_name
from skinet.ros.typemap import parse_typemap

__all__ = ["generate_messages", "package_name", "parse_typemap"]
