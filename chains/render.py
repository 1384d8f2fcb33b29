"""Plain-text rendering of core results for the terminal."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from skinet.verify.explain import warning_line
from skinet.system.model import System, marking_to_json
from skinet.verify.algorithm1 import Analysis, UnsafeTransition


def table(rows: Sequence[Sequence[object]], header: Sequence[str]) -> str:
    """Left-aligned columns separated by two spaces."""
    cells = [[str(c) for c in header]] + [[str(c) for c in r] for r in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(header))]
    return "\n".join("  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in cells)


def marking_lines(system: System, marking: Mapping[str, int]) -> list[str]:
    """One line per skillset: resource states and running skills."""
    data = marking_to_json(system, marking)
    width = max(len(n) for n in data)
    lines = []
    for name, entry in data.items():
        res = " ".join(f"{r}={s}" for r, s in entry["resources"].items())
        running = ", ".join(entry["running"]) or "-"
        lines.append(f"  {name.ljust(width)}  {res}; running: {running}")
    return lines


def unsafe_row(u: UnsafeTransition) -> list[object]:
    via = ("via " + " -> ".join(u.witness)) if u.witness else ""
    return [
        u.skillset, u.transition, u.property, u.constraint,
        "controllable" if u.controllable else "uncontrollable",
        "-" if u.steps is None else u.steps, via,
    ]


def analysis_text(system: System, analysis: Analysis, literal: bool) -> str:
    """Algorithm 1's result as the operator sees it; ``literal`` adds the literal algorithm's list."""
    out = [f"system {system.name} at marking:", *marking_lines(system, analysis.marking)]
    status = [f"{p.name} {'VIOLATED' if p.name in analysis.violated else 'holds'}" for p in system.properties]
    out.append("properties: " + (", ".join(status) or "none"))
    out.extend(_unsafe_lines("unsafe transitions", analysis.operator_unsafe()))
    for prop, recovery in analysis.recovery.items():
        names = ", ".join(f"{r.skillset}:{r.transition}" for r in recovery) or "none"
        out.append(f"{prop} is violated now; recovery transitions: {names}")
    if literal:
        out.extend(_unsafe_lines("literal Algorithm 1 (also for properties already violated)", analysis.unsafe))
    return "\n".join(out)


def _unsafe_lines(title: str, unsafe: Sequence[UnsafeTransition]) -> list[str]:
    out = [f"{title} ({len(unsafe)}):"]
    if unsafe:
        header = ["skillset", "transition", "property", "constraint", "control", "steps", "witness"]
        out.extend("  " + line for line in table([unsafe_row(u) for u in unsafe], header).splitlines())
        out.append("why:")
        out.extend("  " + warning_line(u) for u in unsafe)
    return out


def seconds(value: float) -> str:
    return f"{value * 1000:.2f} ms" if value < 1 else f"{value:.2f} s"
