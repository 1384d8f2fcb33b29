"""``skinet replay BUNDLE --verify``: re-run an incident bundle to the same verdicts (docs/foxglove.md).

The system is rebuilt from the bundle's model attachment (its digests checked
by :func:`skinet.wire.bundle.read_bundle`); the recorded canonical events, in
the order the monitor received them, go through a fresh
:class:`~services.monitor.engine.Engine` (the monitor's own fast path, in
process: sequence check, live marking, Algorithm 1).  A bundle of a stretch (an incident's) starts from
its first recorded state: the engine takes that marking and step number, and the events after it.  At each step the engine
makes, its verdicts are compared with the last recorded ones of that step, and
its unsafe report with the last recorded one: where that one was fresh, the
prediction is computed here too (:func:`skinet.verify.predict.forecast`, the
predictor's own algorithm, with the bundle's budget or :data:`BUDGET`), so
implicit and forced constraints are compared as well; where it was stale, only
what needs no prediction.  A recorded step the re-run never reaches, or a step
it makes that was not recorded, is a difference too.  Cost: O(events) engine
steps plus one exploration per distinct fresh marking.
"""

from __future__ import annotations

from dataclasses import dataclass

from services.monitor.engine import Engine
from skinet.wire.bundle import Bundle
from skinet.wire.codec import decode
from skinet.wire.convert import RiskTable, marking_of, risks, system_from_bundle
from skinet.wire.messages import CanonicalEvent, LiveState, UnsafeReport, Verdicts
from skinet.verify.predict import forecast

BUDGET = 10.0  # seconds of exploration per marking when the bundle does not say the monitor's budget


@dataclass(frozen=True)
class Difference:
    seq: int
    what: str

    def line(self) -> str:
        return f"step {self.seq}: {self.what}"


def _unsafe_set(report: UnsafeReport, fresh: bool) -> set[tuple]:
    return {(e.skillset, e.transition, e.property, e.constraint, e.controllable, e.steps, tuple(e.witness))
            for e in report.unsafe if fresh or e.constraint == "explicit"}


def _show(entries: set[tuple]) -> str:
    return ", ".join(f"{s}:{t} ({p} {c})" for s, t, p, c, *_ in sorted(entries)) or "none"


def verify(bundle: Bundle) -> tuple[int, list[Difference]]:
    """(steps compared, differences) of a re-run of ``bundle``."""
    system = system_from_bundle(bundle.model)
    budget = float(bundle.metadata.get("budget", "")) if _number(bundle.metadata.get("budget")) else BUDGET
    verdicts: dict[int, Verdicts] = {}
    unsafe: dict[int, UnsafeReport] = {}
    events: list[CanonicalEvent] = []
    start = next((e for e in bundle.entries if isinstance(e.message, LiveState)), None)
    floor = start.message.seq + 1 if start is not None and start.message.seq > 0 else 0
    for e in bundle.entries:
        m = e.message
        if start is not None and start.message.seq > 0 and e.t <= start.t:
            continue  # a stretch: the run before its first state is summed up by that state
        if isinstance(m, (Verdicts, UnsafeReport)) and m.seq < floor:
            continue  # of the stretch's first state, or older
        if isinstance(m, Verdicts):
            verdicts[m.seq] = m
        elif isinstance(m, UnsafeReport):
            old = unsafe.get(m.seq)
            if old is None or not (old.prediction_stale is False and m.prediction_stale):
                unsafe[m.seq] = m  # the last fresh one of the step, else the last
        elif isinstance(m, CanonicalEvent):
            events.append(m)
    engine = Engine(system)
    tables: dict[tuple[int, ...], RiskTable] = {}
    differences: list[Difference] = []
    steps = []
    if start is not None and start.message.seq > 0:  # an incident's stretch starts from the state it begins at
        engine.live.marking.update(marking_of(system, start.message.skillsets))
        engine.seq = start.message.seq
    else:
        steps.append(engine.initial())
    for ev in events:
        ok, _note, _resync = engine.check_seq(ev)
        if ok:
            step = engine.apply(ev)
            if step is not None:
                steps.append(step)
    compared = 0
    # A bundle holds a stretch: the steps before its first recorded verdicts are context, and those after its
    # last (the recorder stopped) are not compared.
    first, last = min(verdicts, default=0), max(verdicts, default=-1)
    for step in steps:
        if not first <= step.seq <= last:
            continue
        compared += 1
        got = decode(step.verdicts, Verdicts)
        rec = verdicts.get(step.seq)
        if rec is None:
            differences.append(Difference(step.seq, "the re-run makes this step; no verdicts were recorded for it"))
            continue
        mine = {p.name: p.holds for p in got.properties}
        theirs = {p.name: p.holds for p in rec.properties}
        for name in sorted(set(mine) | set(theirs)):
            if mine.get(name) != theirs.get(name):
                differences.append(Difference(step.seq, f"verdict of {name}: recorded {_holds(theirs.get(name))}, "
                                                        f"re-run {_holds(mine.get(name))}"))
        urec = unsafe.get(step.seq)
        if urec is None:
            continue
        fresh = not urec.prediction_stale
        report = decode(step.unsafe, UnsafeReport)
        if fresh:
            table = tables.get(step.key)
            if table is None:
                marking = _marking(engine, step.key)
                table = tables[step.key] = RiskTable(system, risks(system, marking,
                                                                   forecast(system, marking, budget=budget)))
            saved = dict(engine.live.marking)
            engine.live.marking.update(_marking(engine, step.key))
            engine.add_prediction(step.key, table)
            report = decode(engine.refresh(), UnsafeReport)
            engine.live.marking.update(saved)
        mine_u, theirs_u = _unsafe_set(report, fresh), _unsafe_set(urec, fresh)
        if mine_u != theirs_u:
            differences.append(Difference(step.seq, f"unsafe commands: recorded {_show(theirs_u - mine_u)} not "
                                                    f"re-made; re-run {_show(mine_u - theirs_u)} not recorded"))
    recorded_steps = set(verdicts)
    made = {s.seq for s in steps}
    for seq in sorted(recorded_steps - made):
        differences.append(Difference(seq, "recorded verdicts of a step the re-run never makes"))
    return compared, sorted(differences, key=lambda d: d.seq)


def _marking(engine: Engine, key: tuple[int, ...]) -> dict[str, int]:
    return dict(zip(engine.names, key))


def _holds(v: bool | None) -> str:
    return "none" if v is None else ("holds" if v else "VIOLATED")


def _number(text: str | None) -> bool:
    try:
        return text is not None and float(text) > 0
    except ValueError:
        return False


__all__ = ["Difference", "verify"]


