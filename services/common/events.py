"""Canonical events that survive a router restart or a short partition (issue 14; docs/semantics.md §7).

Zenoh's own means, from ``zenoh.ext`` (eclipse-zenoh 1.10): the bridge publishes
with an :class:`~zenoh.ext.AdvancedPublisher` that keeps its last ``cache`` events
per key and sends a heartbeat with its last sequence number; the monitor follows
with an :class:`~zenoh.ext.AdvancedSubscriber` that, on a heartbeat (every 0.5 s; the
sporadic kind recovered nothing after a router restart here) or an event
showing a gap, queries the publisher's cache for what it missed and delivers
everything in order.  What cannot be recovered (more than ``cache`` events
published during the outage) is reported to ``on_miss`` with its count, and the
monitor then resyncs from the bridge's status.

Measured on loopback (router killed for 3 s while 40 events/s flowed): every
event delivered in order about 2 s after the router came back.  A subscriber
history of N samples also bounds recovery to N, so none is asked for.  A
subscriber that starts late still gets the whole cache (it recovers everything
before the first heartbeat's sequence number): the monitor counts the events its
resync answer covers as ``history`` and does not apply them
(:mod:`services.monitor.sync`; never by their stamps).  These heartbeats are
internal to zenoh.ext; the monitor hears the bridge's own
(:mod:`services.common.heartbeat`).
"""

from __future__ import annotations

from collections.abc import Callable

import zenoh
import zenoh.ext as zext

CACHE = 4096  # events kept per skillset: 10 s of outage at 400 events/s
HEARTBEAT = 0.5  # seconds between the publisher's heartbeats (its last sequence number)


def event_publisher(session: zenoh.Session, key: str, cache: int = CACHE) -> zext.AdvancedPublisher:
    """A publisher for ``key`` whose last ``cache`` samples subscribers can recover."""
    block = zenoh.CongestionControl.BLOCK
    return zext.declare_advanced_publisher(
        session, key, congestion_control=block,
        cache=zext.CacheConfig(cache, replies_config=zext.RepliesConfig(congestion_control=block)),
        sample_miss_detection=zext.MissDetectionConfig(heartbeat=HEARTBEAT),
        publisher_detection=True)


def event_subscriber(session: zenoh.Session, key: str, handler: object,
                     on_miss: Callable[[int], None]) -> tuple[zext.AdvancedSubscriber, object]:
    """A subscriber on ``key`` recovering missed samples from advanced publishers' caches,
    and the listener calling ``on_miss(count)`` for samples that could not be recovered."""
    sub = zext.declare_advanced_subscriber(session, key, handler, recovery=zext.RecoveryConfig(heartbeat=True),
                                           subscriber_detection=True)
    return sub, sub.sample_miss_listener(lambda miss: on_miss(miss.nb))
