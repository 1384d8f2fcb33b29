"""Zenoh key-expression layout, all under ``skinet/<system>/`` (docs/semantics.md §1).

========================================  ==================  ==========================
key                                       publisher           payload
========================================  ==================  ==========================
``skinet/<system>/events/<skillset>``     bridge_ros2         :class:`CanonicalEvent`
``skinet/<system>/state``                 monitor             :class:`LiveState`
``skinet/<system>/verdicts``              monitor             :class:`Verdicts`
``skinet/<system>/unsafe``                monitor             :class:`UnsafeReport`
``skinet/<system>/state_space``           monitor             :class:`StateSpaceReport`
``skinet/<system>/divergences``           monitor             :class:`Divergences`
``skinet/<system>/@feed``                 monitor             :class:`ResultFeed` (the five above, in rounds)
``skinet/<system>/predict/<client>``      predictor (query)   :class:`PredictRequest` -> :class:`PredictReply`
``skinet/<system>/predict/<client>/<i>``  one predictor ``i`` the same, after empty "working" replies
``skinet/<system>/model/<digest>``        monitor (query)     -> :class:`ModelBundle`
``skinet/<system>/check/<client>``        monitor (query)     :class:`CheckRequest` -> :class:`CheckReply`
``skinet/<system>/resync/<skillset>``     bridge_ros2 (query) -> :class:`CanonicalEvent` (last status)
``skinet/<system>/heartbeat/<source>``    bridge_ros2         :class:`Heartbeat` (every 0.5 s)
``skinet/<system>/alive/<service>/<id>``  every instance      liveliness token
``skinet/<system>/pilot/goal/<client>``   pilot (query)       :class:`PilotGoalRequest` -> :class:`PilotGoalReply`
``skinet/<system>/pilot/status``          pilot               :class:`PilotStatus` (and on ``get``)
========================================  ==================  ==========================

Predictors are not tied to one system: they answer on ``skinet/*/predict/*`` (any
instance) and ``skinet/*/predict/*/<id>`` (this one), and hold their liveliness token
under ``skinet/_any/alive/predictor/<id>``; a client spreading its queries finds the
ids through the tokens.

``<client>`` is the querier's identity, its router login (issue 14): the router's
access control lets user ``U`` query only keys whose client chunk is ``U``, so the
chunk cannot be forged there, and the predictor and the monitor's check keep a
request budget per client (:mod:`services.common.ratelimit`).  A session without a
login uses :data:`LOCAL_CLIENT`.
"""

from __future__ import annotations

import re

ROOT = "skinet"
ANY_SYSTEM = "_any"
LOCAL_CLIENT = "local"  # the client chunk of a session without a login
_CHUNK = re.compile(r"^[A-Za-z0-9_\-.]+$")


def check_chunk(value: str, what: str) -> str:
    """A key chunk must be non-empty and free of ``/``, ``*``, ``$``, ``?`` and ``#``."""
    if not _CHUNK.match(value):
        raise ValueError(f"{what} '{value}' cannot be used in a Zenoh key (letters, digits, _ - . only)")
    return value


def events(system: str, skillset: str = "*") -> str:
    return f"{ROOT}/{system}/events/{skillset}"


def state(system: str) -> str:
    return f"{ROOT}/{system}/state"


def verdicts(system: str) -> str:
    return f"{ROOT}/{system}/verdicts"


def unsafe(system: str) -> str:
    return f"{ROOT}/{system}/unsafe"


def state_space(system: str) -> str:
    return f"{ROOT}/{system}/state_space"


def divergences(system: str) -> str:
    return f"{ROOT}/{system}/divergences"


def feed(system: str) -> str:
    """A verbatim chunk (``@``): ``skinet/<system>/**`` does not match it, so a recorder's wildcard never makes
    the monitor gather and send rounds; only a subscriber of this very key does."""
    return f"{ROOT}/{system}/@feed"


def predict(system: str, client: str) -> str:
    """The shared prediction key of ``client`` (any instance answers)."""
    return f"{ROOT}/{system}/predict/{client}"


def predict_instance(system: str, client: str, instance: str) -> str:
    """The key of one predictor instance asked by ``client`` (either may be ``*``)."""
    return f"{ROOT}/{system}/predict/{client}/{instance}"


def model(system: str, digest: str = "*") -> str:
    return f"{ROOT}/{system}/model/{digest}"


def check(system: str, client: str) -> str:
    """The monitor's command check asked by ``client``."""
    return f"{ROOT}/{system}/check/{client}"


def pilot_goal(system: str, client: str) -> str:
    """The pilot's goal queryable asked by ``client``."""
    return f"{ROOT}/{system}/pilot/goal/{client}"


def pilot_status(system: str) -> str:
    return f"{ROOT}/{system}/pilot/status"


def client_of(key: str) -> str | None:
    """The client chunk of a ``predict`` or ``check`` key (``skinet/<system>/<kind>/<client>[/...]``)
    or of a pilot goal key (``skinet/<system>/pilot/goal/<client>``); None when the key has none or
    it is not a plain name (a wildcard)."""
    parts = key.split("/")
    at = 4 if len(parts) > 2 and parts[2] == "pilot" else 3
    if len(parts) <= at or not _CHUNK.match(parts[at]):
        return None
    return parts[at]


def resync(system: str, skillset: str = "*") -> str:
    return f"{ROOT}/{system}/resync/{skillset}"


def heartbeat(system: str, source: str = "**") -> str:
    """Where the publisher ``source`` of a system's events says it is alive (``**``: every one)."""
    if source != "**":
        for chunk in source.split("/"):
            check_chunk(chunk, "source")
    return f"{ROOT}/{system}/heartbeat/{source}"


def alive(system: str, service: str = "*", instance: str = "*") -> str:
    return f"{ROOT}/{system}/alive/{service}/{instance}"
