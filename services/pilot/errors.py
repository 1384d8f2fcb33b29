"""What acting on the robot can raise: a command not sent (:class:`ActError`) or refused by the robot
with nothing changed (:class:`Refused`) (docs/pilot.md)."""

from __future__ import annotations


class ActError(Exception):
    """The command could not be sent; ``reason`` says why, in the operator's words."""

    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason


class Refused(ActError):
    """The robot answered the command with a refusal (a start the manager refused): nothing changed there."""
