"""A ROS 2 service client on Zenoh keys, as ``zenoh-bridge-ros2dds`` or ``rmw_zenoh`` carry services.

A ROS 2 service is a queryable on the service's key (:meth:`skinet.ros.keys.KeyStyle.name_key`):
the CDR request is the query's payload, the CDR response its reply.  ``rmw_zenoh``
servers also read the client's GID and a sequence number from the query's
attachment (:func:`skinet.ros.keys.rmw_attachment`) and echo it in their reply.
The type hash in the key is ``*``: a server is found even when the hash of its type
differs from the one our definitions give (the CDR must still match).
"""

from __future__ import annotations

import itertools
import os
import time

import zenoh

from skinet.ros.keys import KeyStyle, rmw_attachment


class ServiceClient:
    """Calls ROS 2 services of any type through ``session`` (one GID, one sequence of requests)."""

    def __init__(self, session: zenoh.Session, style: KeyStyle):
        self.session = session
        self.style = style
        self.gid = os.urandom(16)
        self._sequence = itertools.count(1)

    def call(self, name: str, typename: str, payload: bytes, timeout: float) -> bytes | None:
        """The response to ``payload`` from the server of ``name`` (``/dock_robot/_action/send_goal``, of type
        ``typename``), or ``None`` when none answered within ``timeout`` seconds."""
        attachment = rmw_attachment(next(self._sequence), time.time_ns(), self.gid) if self.style.rmw_zenoh else None
        for reply in self.session.get(self.style.name_key(name, typename), payload=payload, attachment=attachment,
                                      timeout=timeout):
            if reply.ok is not None:
                return reply.ok.payload.to_bytes()
        return None


__all__ = ["ServiceClient"]
