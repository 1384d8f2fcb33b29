"""Zenoh key-expression layout, all under ``skinet/<system>/`` (SPEC §1).

========================================  ==================  ==========================
key                                       publisher           payload
========================================  ==================  ==========================
``skinet/<system>/events/<skillset>``     bridge_ros2         :class:`CanonicalEvent`
``skinet/<system>/state``                 monitor             :class:`LiveState`
``skinet/<system>/verdicts``              monitor             :class:`Verdicts`
``skinet/<system>/unsafe``                monitor             :class:`UnsafeReport`
``skinet/<system>/state_space``           monitor             :class:`StateSpaceReport`
``skinet/<system>/predict``               predictor (query)   :class:`PredictRequest` -> :class:`PredictReply`
``skinet/<system>/predict/<instance>``    one predictor       the same, after empty "working" replies
``skinet/<system>/model/<digest>``        monitor (query)     -> :class:`ModelBundle`
``skinet/<system>/check``                 monitor (query)     :class:`CheckRequest` -> :class:`CheckReply`
``skinet/<system>/resync/<skillset>``     bridge_ros2 (query) -> :class:`CanonicalEvent` (last status)
``skinet/<system>/alive/<service>/<id>``  every instance      liveliness token
========================================  ==================  ==========================

Predictors are not tied to one system: they answer on ``skinet/*/predict`` (any
instance) and ``skinet/*/predict/<id>`` (this one), and hold their liveliness token
under ``skinet/_any/alive/predictor/<id>``; a client spreading its queries finds the
ids through the tokens.
"""

from __future__ import annotations

import re

ROOT = "skinet"
ANY_SYSTEM = "_any"
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


def predict(system: str = "*") -> str:
    return f"{ROOT}/{system}/predict"


def predict_instance(system: str, instance: str) -> str:
    """The key of one predictor instance (``instance`` may be ``*``)."""
    return f"{ROOT}/{system}/predict/{instance}"


def model(system: str, digest: str = "*") -> str:
    return f"{ROOT}/{system}/model/{digest}"


def check(system: str) -> str:
    return f"{ROOT}/{system}/check"
def resync(system: str, skillset: str = "*") -> str:
    return f"{ROOT}/{system}/resync/{skillset}"


def alive(system: str, service: str = "*", instance: str = "*") -> str:
    return f"{ROOT}/{system}/alive/{service}/{instance}"
