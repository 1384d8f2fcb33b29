"""The pilot's status as text: one line per change, as ``skinet goal`` and ``skinet watch`` print it
(docs/pilot.md).  Cost: a few string joins per status."""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

from skinet.wire.messages import PilotCommand, PilotStatus


def moves_text(n: int) -> str:
    return f"{n} move{'' if n == 1 else 's'}"


def toml_value(value: Any) -> str:
    """A value as TOML writes it inline (for inputs)."""
    if isinstance(value, Mapping):
        return "{" + ", ".join(f"{k} = {toml_value(v)}" for k, v in value.items()) + "}"
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, bool):
        return "true" if value else "false"
    return json.dumps(value) if isinstance(value, str) else str(value)


def command_text(command: PilotCommand) -> str:
    given = f" with {toml_value(command.inputs)}" if command.inputs else ""
    return f"{command.skillset}:{command.transition}{given}"


def status_line(s: PilotStatus, mode: bool = False) -> str:
    """One line of the pilot's status: ``STATE[: REASON] — goal i/n, next ..., moves left, retries, commands``;
    ``mode``: say the mode too (it has just changed)."""
    parts = [f"now in {s.mode} mode"] if mode else []
    if len(s.goals) > 1 and s.index < len(s.goals):
        parts.append(f"goal {s.index + 1}/{len(s.goals)} {s.goals[s.index]}")
    if s.next is not None:
        parts.append(f"next {command_text(s.next)}")
    if s.moves_left is not None and s.state not in ("reached", "failed", "cancelled"):
        parts.append(f"{moves_text(s.moves_left)} left")
    if s.retries:
        parts.append("retries " + ", ".join(f"{k} {n}" for k, n in sorted(s.retries.items())))
    if s.mode == "drive" or s.commands:
        parts.append(f"{s.commands} command{'' if s.commands == 1 else 's'} sent")
    if s.denied:
        parts.append(f"{s.denied} denied by the check")
    head = s.state + (f": {s.reason}" if s.reason else "")
    return head + (" \u2014 " + ", ".join(parts) if parts else "")


def status_change(s: PilotStatus, shown: tuple | None) -> tuple:
    """What a line shows: a status equal in all of it to the one ``shown`` is no new line (moves left not
    known, None, is no change from those shown)."""
    moves = shown[6] if s.moves_left is None and shown is not None and shown[1] == s.state else s.moves_left
    return (s.goal_id, s.state, s.reason, s.mode, s.index, s.next and s.next.model_dump_json(), moves,
            tuple(sorted(s.retries.items())), s.commands, s.denied)


class StatusLines:
    """One line per change of the pilot's status, as ``skinet goal`` prints them (:func:`status_change`);
    ``say_mode``: a line also says the mode when it has just changed."""

    def __init__(self, say_mode: bool = True):
        self.say_mode = say_mode
        self.shown: tuple | None = None  # what the last line showed

    def line(self, status: PilotStatus) -> str | None:
        """The line ``status`` adds, or None when it shows nothing new."""
        change = status_change(status, self.shown)
        if change == self.shown:
            return None
        switched = self.say_mode and self.shown is not None and self.shown[3] != status.mode
        self.shown = change
        return status_line(status, switched)
