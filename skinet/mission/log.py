"""A replayed mission as the monitor log it would have produced (docs/mission.md, docs/semantics.md §1).

:func:`records_to_log` turns the :class:`~skinet.mission.scenario.StepRecord` list of
:func:`~skinet.mission.scenario.replay` into the messages seen on ``skinet/<system>/**``
during the run: the model bundle, then per step the bridge's
:class:`CanonicalEvent` and the monitor's :class:`LiveState`,
:class:`Verdicts`, :class:`UnsafeReport` (and :class:`StateSpaceReport` when
predicting), stamped with the step time, and after a step the model does not
allow the monitor's :class:`Divergences` list so far.  Steps where the operator only
*considers* a command publish nothing.  Pure: no I/O.
"""

from __future__ import annotations

from collections.abc import Sequence

from skinet.system.live import LiveSystem
from skinet.mission.scenario import Scenario, StepRecord
from skinet.system.model import Marking, System
from skinet.verify.algorithm1 import analyse
from skinet.verify.predict import forecast
from skinet.wire import keys
from skinet.wire.convert import analysis_bodies, bundle, state_space_report, statuses
from skinet.wire.log import Entry
from skinet.wire.messages import (
    CanonicalEvent, Divergence, Divergences, LiveState, SkillsetSync, UnsafeReport, Verdicts,
)

SOURCE = "replay"
MONITOR = "demo"  # the monitor instance id of the log's divergence list
# A replayed scenario's marking is known at every step: each skillset is live from the run's start (t = 0), as
# a synced monitor's (docs/operator.md, "Honest live state").
_LIVE = SkillsetSync(state="live", since=0.0, source=SOURCE)


def records_to_log(
    system: System, scenario: Scenario, records: Sequence[StepRecord], predict: bool = True, budget: float = 5.0
) -> list[Entry]:
    """The log of one replayed run (``records`` from ``replay(system, scenario)``).

    Markings are recomputed from the scenario and Algorithm 1 is run again on
    each, as the monitor does; raises ``ValueError`` when ``records`` do not
    belong to ``scenario``.
    """
    if [r.step for r in records] != list(scenario.steps):
        raise ValueError(f"records do not match the steps of scenario '{scenario.name}'")
    name = system.name
    model = bundle(system)
    out = [Entry(0.0, keys.model(name, model.digest), "ModelBundle", model)]
    live = LiveSystem(system)
    out += _monitor_step(system, live.marking, 0, 0.0, "", None, predict, budget)
    seqs: dict[str, int] = {}
    step_seq = 0
    diverged: list[Divergence] = []
    for r in records:
        s = r.step
        if s.transition is None:
            continue
        live.apply(s.skillset, s.transition)
        seq = seqs[s.skillset] = seqs.get(s.skillset, -1) + 1
        status = statuses(system, live.marking).get(s.skillset)
        event = CanonicalEvent(system=name, skillset=s.skillset, seq=seq, stamp=s.t, source=SOURCE,
                               transition=s.transition, status=status, info=s.note)
        out.append(Entry(s.t, keys.events(name, s.skillset), "CanonicalEvent", event))
        step_seq += 1
        published = _monitor_step(system, live.marking, step_seq, s.t, f"{s.skillset}:{s.transition}#{seq}",
                                  r.divergence, predict, budget)
        if r.divergence:
            diverged.append(Divergence(n=len(diverged), kind="divergence", seq=step_seq, stamp=s.t,
                                       skillset=s.skillset, event=f"{s.skillset}:{s.transition}#{seq}",
                                       reason=r.divergence, info=s.note))
            published.append(Entry(s.t, keys.divergences(name), "Divergences", Divergences(
                system=name, monitor=MONITOR, stamp=s.t, entries=list(diverged))))
        verdicts = next(e.message for e in published if isinstance(e.message, Verdicts))
        if {v.name: v.holds for v in verdicts.properties} != r.holds:
            raise ValueError(f"step {r.index}: verdicts differ from the record (not a replay of this scenario?)")
        out += published
    return out


def _monitor_step(system: System, marking: Marking, seq: int, t: float, event: str, divergence: str | None,
                  predict: bool, budget: float) -> list[Entry]:
    """What the monitor publishes after one step: state, verdicts, unsafe (and state space)."""
    name = system.name
    prediction = forecast(system, marking, budget=budget) if predict else None
    analysis = analyse(system, marking, prediction)
    props, unsafe, recovery = analysis_bodies(system, analysis)
    out = [
        Entry(t, keys.state(name), "LiveState", LiveState(
            system=name, seq=seq, stamp=t, skillsets=statuses(system, marking), event=event, divergence=divergence,
            sync={k: _LIVE for k in statuses(system, marking)})),
        Entry(t, keys.verdicts(name), "Verdicts", Verdicts(system=name, seq=seq, stamp=t, properties=props)),
        Entry(t, keys.unsafe(name), "UnsafeReport", UnsafeReport(
            system=name, seq=seq, stamp=t, unsafe=unsafe, recovery=recovery, violated=analysis.violated,
            literal_count=len(analysis.unsafe), prediction_stale=not predict)),
    ]
    if prediction is not None:
        out.append(Entry(t, keys.state_space(name), "StateSpaceReport", state_space_report(system, prediction, t)))
    return out


__all__ = ["records_to_log"]
