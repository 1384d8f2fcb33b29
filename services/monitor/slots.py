"""Fair shares of the monitor's waiting check requests (issue 31; docs/deployment.md "Rate limits per client").

A check request may ask to wait for a synced state and a fresh prediction
(``CheckRequest.wait``); the monitor keeps at most ``capacity`` of them
(:data:`services.monitor.service.MAX_WAITING`).  While a slot is free anybody takes it.  When all are
taken, a client takes the oldest slot of the client holding the most, provided that holder has more
slots than the newcomer: the request it held is answered at once, as it stands (its reply says
whether the state or the prediction is stale, as any request that could not wait).  So one client,
or one name, cannot hold every slot against the others: each of ``n`` clients asking keeps at least
``capacity // n`` slots, and a client over that share is the one answered early.

Cost: O(``capacity``) per request that asks to wait.
"""

from __future__ import annotations

from collections import Counter

FREE = -1  # fair_slot's answer when a slot is free


def fair_slot(holders: list[str], client: str, capacity: int) -> int | None:
    """Where ``client`` may wait, ``holders`` being the clients of the waiting requests, oldest first:
    :data:`FREE` for a free slot, the index of the request to answer now to make room, or None
    when ``client`` already has as many slots as anybody (it is answered at once)."""
    if len(holders) < capacity:
        return FREE
    counts = Counter(holders)
    most = max(counts.values())
    if most <= counts[client]:
        return None
    return next(i for i, holder in enumerate(holders) if counts[holder] == most)
