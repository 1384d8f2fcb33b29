"""Operator timelines in the spirit of the seed paper's Fig. 3 and Fig. 4.

:func:`draw` turns parsed monitor log entries (:mod:`skinet.wire.log`) into a
matplotlib figure: x is time in seconds from the first message; the upper
panel has one lane per resource (its state as a step line with state labels),
per skill (bars while it runs), per property (red where VIOLATED) and one
event lane per skillset; the lower panel plots the number of unsafe
transitions (operator view, and the literal algorithm's count dashed).
Lanes come from the system when known (argument, or a ``ModelBundle`` entry
in the log), else from what the log shows.  Uses the Agg canvas only.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from skinet.errors import SkinetError
from skinet.system.model import System
from skinet.wire.convert import system_from_bundle
from skinet.wire.log import Entry
from skinet.wire.messages import CanonicalEvent, LiveState, ModelBundle, UnsafeReport, Verdicts

SKILLSET_COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#17becf", "#bcbd22")
STATE_FILLS = ("#eef3fa", "#fdf0e1", "#eaf6ea", "#f6ecf7", "#f5efe9", "#eef7f8")
HOLDS, VIOLATED, FLAGGED = "#dff0d8", "#d62728", "#e8a0a0"
# How a lane is hatched while one of its commands is flagged, per constraint kind (docs/semantics.md §5), least severe first.
FLAG_STYLES = {
    "unknown": ("#aaaaaa", "...."),
    "forced": ("#ff7f0e", "\\\\\\\\"),
    "implicit": ("#9467bd", "xxxx"),
    "explicit": (FLAGGED, "////"),
}
PREDICTED = "#ff7f0e"
MARKERS = {"command": ">", "outcome": "o", "interrupt": "s", "invariant": "X", "event": "D", "status": "|"}
LANE_HEIGHT_IN = 0.34  # figure inches per lane


@dataclass
class Lanes:
    """What the upper panel shows, top to bottom within each skillset."""

    skillsets: list[str] = field(default_factory=list)
    resources: dict[str, list[tuple[str, list[str]]]] = field(default_factory=dict)  # skillset -> (name, states)
    skills: dict[str, list[str]] = field(default_factory=dict)
    properties: list[str] = field(default_factory=list)

    def labels(self) -> list[str]:
        """Lane labels, top to bottom, as drawn on the y axis."""
        out = [f"{ss} events" for ss in self.skillsets]
        for ss in self.skillsets:
            out += [f"{ss}.{r}" for r, _ in self.resources[ss]]
            out += [f"{ss}.{k}" for k in self.skills[ss]]
        return out + [f"property {p}" for p in self.properties]


def lanes_of(entries: Sequence[Entry], system: System | None = None) -> Lanes:
    """Lanes from ``system``, else from the log's model bundle, else from what the log shows."""
    if system is None:
        system = _bundled_system(entries)
    lanes = Lanes()
    if system is not None:
        for c in system.components:
            lanes.skillsets.append(c.name)
            lanes.resources[c.name] = [(r.name, list(r.states)) for r in c.skillset.resources]
            lanes.skills[c.name] = [k.name for k in c.skillset.skills]
        lanes.properties = [p.name for p in system.properties]
    for e in entries:  # anything observed but unknown gets a lane too
        m = e.message
        if isinstance(m, LiveState):
            for ss, status in m.skillsets.items():
                known = dict(_ensure(lanes, ss))
                for r, s in status.resources.items():
                    if r not in known:
                        known[r] = [s]
                        lanes.resources[ss].append((r, known[r]))
                    elif s not in known[r]:
                        known[r].append(s)
                for k in status.running:
                    _add(lanes.skills[ss], k)
        elif isinstance(m, CanonicalEvent) and m.transition and "." in m.transition:
            _ensure(lanes, m.skillset)
            _add(lanes.skills[m.skillset], m.transition.split(".", 1)[0])
        elif isinstance(m, Verdicts):
            for v in m.properties:
                _add(lanes.properties, v.name)
    return lanes


def draw(entries: Sequence[Entry], title: str = "", system: System | None = None) -> Figure:
    """The timeline figure of a monitor log; raises :class:`SkinetError` without any LiveState."""
    entries = sorted(entries, key=lambda e: e.t)
    states = [e for e in entries if isinstance(e.message, LiveState)]
    if not states:
        raise SkinetError("no LiveState message in the log: nothing to draw")
    t0 = entries[0].t
    last = entries[-1].t - t0
    end = last + max(2.0, 0.02 * last)
    lanes = lanes_of(entries, system)
    labels = lanes.labels()
    height = LANE_HEIGHT_IN * len(labels) + 3.6 + 0.2 * ((len(lanes.skillsets) + 8) // 11)  # extra legend rows
    fig = Figure(figsize=(15, height), dpi=100)
    FigureCanvasAgg(fig)
    top_in, bottom_in = LANE_HEIGHT_IN * len(labels), 2.0
    grid = fig.add_gridspec(2, 1, height_ratios=[top_in, bottom_in], hspace=0.08,
                            left=0.15, right=0.98, top=1 - 0.45 / height, bottom=1.05 / height)
    ax = fig.add_subplot(grid[0])
    low = fig.add_subplot(grid[1], sharex=ax)
    y = {label: len(labels) - 1 - i for i, label in enumerate(labels)}  # top lane first
    colour = {ss: SKILLSET_COLOURS[i % len(SKILLSET_COLOURS)] for i, ss in enumerate(lanes.skillsets)}

    _events(ax, entries, t0, y, colour)
    _resources_and_skills(ax, states, t0, end, lanes, y, colour)
    _properties(ax, entries, t0, end, lanes, y)
    _flagged(ax, entries, t0, end, y)
    _unsafe(low, entries, t0, end)
    onsets = violations(entries)
    for t, _p in onsets:
        for a in (ax, low):
            a.axvline(t - t0, color=VIOLATED, linestyle=":", linewidth=1.0, zorder=0.5)
    summary = "no violation" if not onsets else f"{len(onsets)} violation{'s' * (len(onsets) > 1)}: " + ", ".join(
        f"{p} at {f'{t - t0:.1f}'.removesuffix('.0')} s" for t, p in onsets)

    ax.set_yticks(range(len(labels)), labels=list(reversed(labels)), fontsize=8)
    for tick in ax.get_yticklabels():
        ss = tick.get_text().split(".", 1)[0].split(" ", 1)[0]
        tick.set_color(colour.get(ss, "black") if not tick.get_text().startswith("property") else "black")
    ax.set_ylim(-0.6, len(labels) - 0.4)
    ax.set_xlim(0, end)
    ax.grid(axis="x", color="#dddddd", linewidth=0.6)
    ax.set_axisbelow(True)
    ax.tick_params(axis="x", labelbottom=False)
    for i in range(len(labels) - 1):
        ax.axhline(i + 0.5, color="#e6e6e6", linewidth=0.5, zorder=0)
    ax.set_title(title, fontsize=12, loc="left")
    ax.set_title(summary, fontsize=10, loc="right", color=VIOLATED if onsets else "#2b7a2b")
    low.set_xlabel("time (s)")
    handles = _legend(lanes, colour)
    fig.legend(handles=handles, loc="lower center", ncol=min(len(handles), 11), fontsize=7.5, frameon=False,
               handlelength=1.5, columnspacing=1.1, handletextpad=0.5, bbox_to_anchor=(0.5, 0.0))
    return fig


def _events(ax: Axes, entries: Sequence[Entry], t0: float, y: dict[str, int], colour: dict[str, str]) -> None:
    """Markers on each skillset's event lane (from the bridge's events, else the monitor's states)."""
    events = [(e.t, e.message.skillset, e.message.transition) for e in entries if isinstance(e.message, CanonicalEvent)]
    if not events:
        for e in entries:
            m = e.message
            if isinstance(m, LiveState) and ":" in m.event:
                ss, rest = m.event.split(":", 1)
                name = rest.rsplit("#", 1)[0]
                events.append((e.t, ss, None if name == "status" else name))
    groups: dict[tuple[str, str], list[float]] = {}
    for t, ss, transition in events:
        if f"{ss} events" in y:
            groups.setdefault((ss, _kind(transition)), []).append(t - t0)
    for (ss, kind), xs in groups.items():
        ax.scatter(xs, [y[f"{ss} events"]] * len(xs), marker=MARKERS[kind], s=26, color=colour.get(ss, "black"),
                   edgecolors=None if kind == "status" else "black", linewidths=0.4, zorder=3)  # "|" has no face
    for e in entries:
        m = e.message
        if isinstance(m, LiveState) and m.divergence and ":" in m.event:
            lane = y.get(f"{m.event.split(':', 1)[0]} events")
            if lane is not None:
                ax.annotate("divergence", (e.t - t0, lane), xytext=(0, 7), textcoords="offset points",
                            fontsize=6, color=VIOLATED, ha="center")


def _resources_and_skills(ax: Axes, states: Sequence[Entry], t0: float, end: float, lanes: Lanes,
                          y: dict[str, int], colour: dict[str, str]) -> None:
    times = [e.t - t0 for e in states] + [end]
    spans = list(zip(times[:-1], times[1:]))
    for ss in lanes.skillsets:
        for r, known in lanes.resources[ss]:
            lane = y[f"{ss}.{r}"]
            values = [_resource(e.message, ss, r) for e in states]
            _resource_lane(ax, lane, spans, values, known, colour[ss])
        for k in lanes.skills[ss]:
            lane = y[f"{ss}.{k}"]
            runs = _merge([s for s, e in zip(spans, states) if _running(e.message, ss, k)])
            if runs:
                ax.broken_barh([(a, b - a) for a, b in runs], (lane - 0.32, 0.64), facecolors=colour[ss],
                               edgecolor="black", linewidth=0.4, zorder=2)


def _resource_lane(ax: Axes, lane: int, spans: list[tuple[float, float]], values: list[str | None],
                   states: list[str], col: str) -> None:
    """The state of one resource: shaded segments, a step line between state levels, labels."""
    n = max(len(states), 2)
    level = {s: lane - 0.3 + 0.6 * i / (n - 1) for i, s in enumerate(states)}
    segments: list[tuple[float, float, str]] = []
    for (a, b), v in zip(spans, values):
        if v is None:
            continue
        if segments and segments[-1][2] == v and segments[-1][1] == a:
            segments[-1] = (segments[-1][0], b, v)
        else:
            segments.append((a, b, v))
    xs: list[float] = []
    ys: list[float] = []
    width = ax.get_figure().get_size_inches()[0] * 0.83  # plot width, inches
    per_s = width / max(spans[-1][1], 1e-9) if spans else 1.0
    free = float("-inf")  # where the next label may start without overlapping the previous one
    fills: dict[int, list[tuple[float, float]]] = {}
    for a, b, v in segments:
        fills.setdefault(states.index(v) if v in states else 0, []).append((a, b - a))
        xs += [a, b]
        ys += [level.get(v, lane)] * 2
        if a >= free:  # about 0.055 inch per character at 6.5 pt
            ax.text(a + 0.04 / per_s, level.get(v, lane) + 0.04, v, fontsize=6.5, va="bottom", ha="left",
                    color="#333333", zorder=4, clip_on=True)
            free = a + (0.055 * len(v) + 0.12) / per_s
    for i, bars in fills.items():
        ax.broken_barh(bars, (lane - 0.42, 0.84), facecolors=STATE_FILLS[i % len(STATE_FILLS)], linewidth=0, zorder=1)
    ax.plot(xs, ys, color=col, linewidth=1.4, zorder=3, solid_joinstyle="miter")


def _properties(ax: Axes, entries: Sequence[Entry], t0: float, end: float, lanes: Lanes, y: dict[str, int]) -> None:
    verdicts = [e for e in entries if isinstance(e.message, Verdicts)]
    times = [e.t - t0 for e in verdicts] + [end]
    for p in lanes.properties:
        lane = y[f"property {p}"]
        values = [{v.name: v.holds for v in e.message.properties}.get(p) for e in verdicts]  # type: ignore[union-attr]
        for status, fill in ((True, HOLDS), (False, VIOLATED)):
            bars = [(a, b - a) for (a, b), ok in zip(zip(times[:-1], times[1:]), values) if ok is status and b > a]
            ax.broken_barh(bars, (lane - 0.38, 0.76), facecolors=fill, linewidth=0, zorder=1)
        for a, b in _merge([(a, b) for (a, b), ok in zip(zip(times[:-1], times[1:]), values) if ok is False]):
            ax.annotate(f"VIOLATED at {f'{a:.1f}'.removesuffix('.0')} s", (b, lane), xytext=(3, 0), textcoords="offset points", fontsize=7,
                        color=VIOLATED, weight="bold", va="center", ha="left", zorder=4)


def violations(entries: Sequence[Entry]) -> list[tuple[float, str]]:
    """(time, property) each time a property goes from holding (or unknown) to violated."""
    last: dict[str, bool] = {}
    out = []
    for e in sorted(entries, key=lambda e: e.t):
        if isinstance(e.message, Verdicts):
            for v in e.message.properties:
                if not v.holds and last.get(v.name, True):
                    out.append((e.t, v.name))
                last[v.name] = v.holds
    return out


def flagged(entries: Sequence[Entry], end: float,
            kinds: Sequence[str] = tuple(FLAG_STYLES)) -> dict[str, list[tuple[float, float]]]:
    """Per skill lane (``skillset.skill``), the times its commands are flagged unsafe (operator view).

    Only flags whose constraint is in ``kinds`` count (default: every kind).
    """
    reports = [e for e in sorted(entries, key=lambda e: e.t) if isinstance(e.message, UnsafeReport)]
    times = [e.t for e in reports] + [end]
    spans: dict[str, list[tuple[float, float]]] = {}
    for (a, b), e in zip(zip(times[:-1], times[1:]), reports):
        assert isinstance(e.message, UnsafeReport)
        for lane in {f"{u.skillset}.{u.transition.split('.', 1)[0]}" for u in e.message.unsafe
                     if u.controllable and "." in u.transition and u.constraint in kinds}:
            spans.setdefault(lane, []).append((a, b))
    return {lane: _merge(runs) for lane, runs in spans.items()}


def _flagged(ax: Axes, entries: Sequence[Entry], t0: float, end: float, y: dict[str, int]) -> None:
    """Hatch a skill's lane while one of its commands is flagged unsafe, one hatch per constraint kind."""
    for kind, (colour, hatch) in FLAG_STYLES.items():
        for label, runs in flagged(entries, end + t0, (kind,)).items():
            if label in y:
                ax.broken_barh([(a - t0, b - a) for a, b in runs], (y[label] - 0.45, 0.9), facecolors="none",
                               edgecolors=colour, hatch=hatch, linewidth=0, zorder=1.5)


def _unsafe(ax: Axes, entries: Sequence[Entry], t0: float, end: float) -> None:
    reports = [e for e in entries if isinstance(e.message, UnsafeReport)]
    if not reports:
        ax.text(0.5, 0.5, "no UnsafeReport in the log", transform=ax.transAxes, ha="center", va="center")
        return
    xs = [e.t - t0 for e in reports] + [end]
    ops = [len(e.message.unsafe) for e in reports]  # type: ignore[union-attr]
    lit = [e.message.literal_count for e in reports]  # type: ignore[union-attr]
    ax.step(xs, lit + lit[-1:], where="post", color="#555555", linestyle="--", linewidth=1.1, zorder=3,
            label="literal Algorithm 1 count")
    ax.step(xs, ops + ops[-1:], where="post", color="#d62728", linewidth=1.8, label="operator view (properties that hold now)")
    ax.fill_between(xs, ops + ops[-1:], step="post", color="#d62728", alpha=0.12)
    ahead = [sum(u.constraint in ("implicit", "forced") for u in e.message.unsafe) for e in reports]  # type: ignore[union-attr]
    if any(ahead):
        ax.step(xs, ahead + ahead[-1:], where="post", color=PREDICTED, linewidth=1.6, zorder=4,
                label="predicted ahead (implicit or forced)")
    top = max(max(lit), max(ops), 1)
    ax.set_ylim(0, top * 1.35 + 0.5)
    ax.set_ylabel("unsafe\ntransitions", fontsize=9)
    ax.grid(color="#dddddd", linewidth=0.6)
    ax.legend(loc="upper right", fontsize=7.5, frameon=False)


def _legend(lanes: Lanes, colour: dict[str, str]) -> list:
    items: list = [Patch(facecolor=colour[ss], edgecolor="black", linewidth=0.4, label=f"{ss} skill running")
                   for ss in lanes.skillsets]
    items.append(Line2D([], [], color="#555555", linewidth=1.4, label="resource state"))
    for kind, (edge, hatch) in reversed(FLAG_STYLES.items()):
        items.append(Patch(facecolor="none", edgecolor=edge, hatch=hatch, linewidth=0, label=f"command flagged {kind}"))
    items.append(Patch(facecolor=HOLDS, label="property holds"))
    items.append(Patch(facecolor=VIOLATED, label="property VIOLATED"))
    for kind in ("command", "outcome", "interrupt", "invariant", "event"):
        items.append(Line2D([], [], marker=MARKERS[kind], linestyle="", color="#bbbbbb", markeredgecolor="black",
                            markeredgewidth=0.4, markersize=5, label=kind))
    return items


def _kind(transition: str | None) -> str:
    """Marker kind of a logical transition name (docs/semantics.md §3 naming)."""
    if transition is None:
        return "status"
    parts = transition.split(".")
    if len(parts) == 1:
        return "event"
    return {"start": "command", "interrupt": "interrupt", "inv": "invariant"}.get(parts[1], "outcome")


def _bundled_system(entries: Sequence[Entry]) -> System | None:
    for e in entries:
        if isinstance(e.message, ModelBundle):
            try:
                return system_from_bundle(e.message)
            except SkinetError:
                return None
    return None


def _ensure(lanes: Lanes, ss: str) -> list[tuple[str, list[str]]]:
    if ss not in lanes.resources:
        lanes.skillsets.append(ss)
        lanes.resources[ss] = []
        lanes.skills[ss] = []
    return lanes.resources[ss]


def _add(items: list[str], name: str) -> None:
    if name not in items:
        items.append(name)


def _resource(m: object, ss: str, r: str) -> str | None:
    assert isinstance(m, LiveState)
    status = m.skillsets.get(ss)
    return None if status is None else status.resources.get(r)


def _running(m: object, ss: str, k: str) -> bool:
    assert isinstance(m, LiveState)
    status = m.skillsets.get(ss)
    return status is not None and k in status.running


def _merge(spans: list[tuple[float, float]]) -> list[tuple[float, float]]:
    out: list[tuple[float, float]] = []
    for a, b in spans:
        if out and out[-1][1] >= a:
            out[-1] = (out[-1][0], max(out[-1][1], b))
        elif b > a:
            out.append((a, b))
    return out


__all__ = ["Lanes", "draw", "flagged", "lanes_of", "violations"]
