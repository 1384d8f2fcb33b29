"""The dashboard's goal box (docs/semantics.md §8, issue 24 item 4): a form into a pilot request, errors placed.

The page sends what the operator typed: one goal per line, skill inputs as
TOML, the mode, whether to replace the goal that runs.  :func:`goal_request`
checks it against the model when the dashboard has one (its system file, or
the monitor's model bundle), so a typo is shown at once and in place even with
no pilot running; the pilot checks again.  An error, local or in the pilot's
reply (``<goal 2>:1:7: error: ...``), becomes a :class:`Placed`: the field
(``goals`` or ``inputs``), the line of that field and the column, for the page
to point at.  Pure, no I/O; cost linear in the text.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

from skinet.errors import Pos, SkinetError, SourceError
from skinet.plan.goal import parse_goal
from skinet.plan.goalfile import nested
from skinet.plan.inputs import parse_inputs
from skinet.system.model import System
from skinet.files.toml import parse_toml
from skinet.wire.messages import PilotGoalRequest

INPUTS_SOURCE = "<inputs>"
_PLACE = re.compile(r"^(?P<source>.+?):(?P<line>\d+):(?P<column>\d+): error: (?P<message>.*)$", re.S)
_GOAL_SOURCE = re.compile(r"^<goal(?: (?P<n>\d+))?>$")


@dataclass(frozen=True)
class Placed:
    """An error and where the page shows it: ``field`` ``goals`` (``line``: the goal's line in the box)
    or ``inputs``, or None when it is about neither."""

    message: str
    field: str | None = None
    line: int | None = None
    column: int | None = None
    detail: str = ""  # the message without its SOURCE:LINE:COL: error: prefix

    def json(self) -> dict[str, Any]:
        return {"error": self.message, "detail": self.detail or self.message, "field": self.field, "line": self.line,
                "column": self.column}


class GoalFormError(SkinetError):
    """A goal form that cannot be sent; ``placed`` says where."""

    def __init__(self, placed: Placed):
        super().__init__(placed.message)
        self.placed = placed


def goal_lines(text: str) -> list[tuple[int, str]]:
    """(line number in the box, goal) for every line that is not blank."""
    return [(n, line.strip()) for n, line in enumerate(text.splitlines(), 1) if line.strip()]


def _source(n: int, several: bool) -> str:
    return f"<goal {n}>" if several else "<goal>"  # as skinet plan and skinet goal name them


def goal_request(system_name: str, form: dict[str, Any], model: System | None) -> PilotGoalRequest:
    """The request for a submitted form (``op``, ``goals``, ``inputs``, ``mode``, ``replace``; ``answer`` for
    ``confirm``);
    raises :class:`GoalFormError` for what cannot be sent, placed in the form."""
    op = form.get("op", "goal")
    mode = form.get("mode", "guide")
    if op not in ("goal", "mode", "cancel", "pause", "resume", "confirm") or mode not in ("guide", "drive"):
        raise GoalFormError(Placed(f"unknown operation '{op}' or mode '{mode}'"))
    if op == "confirm":  # the answer about an outcome the pilot could not see
        answer = form.get("answer")
        if answer not in ("success", "failure", "rerun"):
            raise GoalFormError(Placed(f"unknown answer '{answer}': success, failure or rerun"))
        return PilotGoalRequest(system=system_name, op=op, mode=mode, answer=answer)
    if op != "goal":
        return PilotGoalRequest(system=system_name, op=op, mode=mode)
    text, inputs_text = str(form.get("goals", "")), str(form.get("inputs", "") or "")
    goals = goal_lines(text)
    if not goals:
        raise GoalFormError(Placed("type a goal first, e.g. reach spot:Standing, or run spot:init_power", "goals", 1, 1))
    try:
        inputs = parse_toml(inputs_text, INPUTS_SOURCE) if inputs_text.strip() else {}
        if model is not None:
            lines = inputs_text.splitlines()
            checked = parse_inputs(model, inputs, INPUTS_SOURCE,
                                   lambda keys: nested(lines, Pos(1, 1), keys) if keys else None) if inputs else {}
            for n, (_, goal) in enumerate(goals, 1):
                parse_goal(model, goal, checked, _source(n, len(goals) > 1))
    except SourceError as exc:
        raise GoalFormError(place(str(exc.diagnostics[0]), [n for n, _ in goals])) from None
    return PilotGoalRequest(system=system_name, op="goal", goals=[g for _, g in goals], inputs=inputs, mode=mode,
                            replace=bool(form.get("replace")))


def place(reason: str, lines: list[int]) -> Placed:
    """Where an error message ``SOURCE:LINE:COL: error: ...`` points in the form whose goals are on ``lines``
    of the box (a reason without a position is placed nowhere)."""
    m = _PLACE.match(reason.strip())
    if m is None:
        return Placed(reason)
    line, column, detail = int(m["line"]), int(m["column"]), m["message"]
    if m["source"] == INPUTS_SOURCE:
        return Placed(reason, "inputs", line, column, detail)
    goal = _GOAL_SOURCE.match(m["source"])
    if goal is None:
        return Placed(reason)
    n = int(goal["n"] or 1)
    if not 1 <= n <= len(lines) or line != 1:  # a goal is one line of the box
        return Placed(reason)
    return Placed(reason, "goals", lines[n - 1], column, detail)
