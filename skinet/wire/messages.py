"""Messages exchanged over Zenoh (docs/semantics.md §1), as pydantic models.

Every message carries ``v``, the schema version; a receiver rejects other
versions.  JSON Schemas in ``schemas/`` are generated from these models
(``python -m skinet.wire.schemas``) and a test fails when they drift.

Fields added to a message after its first version are listed in its
``OMIT_AT_DEFAULT``: senders leave them out while they hold their default
(:func:`skinet.wire.codec.encode`), so a receiver that predates them (and
rejects unknown fields) still reads every message that has nothing new to tell
it, and refuses, rather than misreads, one that has (schemas/README.md).
"""

from __future__ import annotations

from typing import Any, ClassVar, Literal

from pydantic import BaseModel, ConfigDict, Field

from skinet.wire.limits import MAX_BUDGET, MIN_BUDGET

SCHEMA_VERSION = 1
MAX_CHECK_WAIT = 30.0  # seconds a check request may wait for a synced state and a fresh prediction
MAX_DIVERGENCES = 256  # entries a Divergences message lists (the monitor's last ones)


class _Message(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)
    OMIT_AT_DEFAULT: ClassVar[tuple[str, ...]] = ()
    v: Literal[1] = Field(SCHEMA_VERSION, description="schema version")


class SkillsetStatus(BaseModel):
    """Observed state of one skillset: resource states and running skills."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    resources: dict[str, str] = Field(default_factory=dict, description="resource -> state")
    running: list[str] = Field(default_factory=list, description="skills running or interrupting")


class MissedOutcome(BaseModel):
    """A skill found ended after a gap while its response never came (docs/how-it-works.md, *Missed outcomes*).

    The bridge names the skill and the gap; the monitor adds what the model infers
    (:func:`skinet.net.outcomes.infer_outcomes`)."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    skillset: str
    skill: str
    gap: str = Field(description="the gap it ended in, in the operator's words (e.g. 'the link to manager "
                                 "/spot/spot_skillset_manager was down 12.4 s')")
    outcome: str | None = Field(None, description="the outcome the model makes unique, a transition name such as "
                                                  "'teleop.success.done' (None: unknown, or not inferred yet)")
    candidates: list[str] = Field(default_factory=list, description=(
        "the success and failure modes that explain the observed status (several: the model cannot tell them "
        "apart; none: no mode does); empty in the bridge's events"))


class CanonicalEvent(_Message):
    """A model-level event of one skillset, published by the bridge."""

    system: str
    skillset: str
    seq: int = Field(ge=0, description="per-skillset sequence number, +1 per event")
    stamp: float = Field(description="source time, seconds since the epoch")
    source: str = Field("", description="publishing instance")
    epoch: int = Field(0, ge=0, description="run of the publisher: a new number at each start (the bridge: its "
                                            "start time in ms); seq restarts within a new epoch")
    transition: str | None = Field(None, description="logical transition, e.g. 'teleop.start'; None: status only")
    status: SkillsetStatus | None = Field(None, description="status observed after the event, when known")
    info: str = Field("", description="free text from the manager (response name, ids)")
    restart: bool = Field(False, description="the skillset's manager restarted: this status starts afresh, "
                                             "and info says why and how its state differs")
    divergence: str = Field("", description="a model divergence the bridge found (a binding's drift, docs/semantics.md §9), "
                                            "with the message that showed it; the monitor reports it even when "
                                            "the status matches its marking")
    missed: list[MissedOutcome] = Field(
        default_factory=list, description="running skills this status shows ended without their response "
                                          "(missed outcomes, named with the gap; the monitor infers the outcome)")

    OMIT_AT_DEFAULT = ("restart", "divergence", "missed")


class PropertyVerdict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)
    name: str
    holds: bool


class SkillsetSync(BaseModel):
    """How far the monitor vouches for one skillset's marking (docs/semantics.md §7, honest live state)."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    state: Literal["live", "syncing", "lost"] = Field(
        description="live: synced from its source, which is heard; syncing: waiting for the source's resync "
                    "answer (the monitor started, or the source came back); lost: the source went quiet")
    since: float = Field(description="when this state began, the monitor's clock (seconds since the epoch)")
    reason: str = Field("", description="why it is not live, in the operator's words (empty when live)")
    source: str = Field("", description="the publisher of its events the monitor follows ('' before the first sync)")


class LiveState(_Message):
    """The monitor's live marking after an event."""

    OMIT_AT_DEFAULT = ("sync", "missed")
    system: str
    seq: int = Field(ge=0, description="monitor publication counter")
    stamp: float
    skillsets: dict[str, SkillsetStatus]
    event: str = Field("", description="the event that led here, 'skillset:transition#seq'")
    divergence: str | None = Field(None, description="why the model could not explain the event")
    sync: dict[str, SkillsetSync] = Field(
        default_factory=dict, description="per skillset, whether the monitor can vouch for its marking; every "
                                          "skillset is listed (absent: a monitor older than this field)")
    missed: list[MissedOutcome] = Field(
        default_factory=list, description="the missed outcomes this step found, with the monitor's inference "
                                          "(outcome None: unknown; consumers must not assume one)")


class Verdicts(_Message):
    system: str
    seq: int = Field(ge=0)
    stamp: float
    properties: list[PropertyVerdict]


class UnsafeEntry(BaseModel):
    """One unsafe transition of Algorithm 1 (docs/semantics.md §5), the worst kind over its variants."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    skillset: str
    transition: str
    kind: str = Field(description="transition kind: event, start, invariant, interrupt, success, failure")
    controllable: bool
    property: str
    constraint: Literal["explicit", "implicit", "forced", "unknown"] = Field(
        description="explicit > implicit > forced > unknown: violated at once, inevitably (AF), "
                    "reachable by skill outcomes alone, undecided")
    steps: int | None = Field(None, description="steps to the violation: 0 explicit; the bound (literal AF) or "
                                                "the fewest (fair AF, forced)")
    witness: list[str] = Field(default_factory=list, description="'skillset:transition' per step to the violation")
    reason: str = Field("", description="why, in the operator's words")


class RecoveryEntry(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)
    property: str
    skillset: str
    transition: str
    controllable: bool


class UnsafeReport(_Message):
    """Algorithm 1's result after an event (operator view plus the literal count)."""

    system: str
    seq: int = Field(ge=0)
    stamp: float
    unsafe: list[UnsafeEntry]
    recovery: list[RecoveryEntry] = Field(default_factory=list)
    violated: list[str] = Field(default_factory=list)
    literal_count: int = Field(0, description="size of the literal algorithm's list (paper Fig. 3)")
    prediction_stale: bool = Field(description="True when implicit constraints are not up to date")
    state_stale: bool = Field(False, description="True when a skillset is not live (LiveState.sync): the "
                                                 "marking judged is the last one known")
    state_reason: str = Field("", description="why the state is stale, in the operator's words")
    stale_since: float | None = Field(None, description="since when it is stale (the monitor's clock)")

    OMIT_AT_DEFAULT = ("state_stale", "state_reason", "stale_since")


class StateSpaceReport(_Message):
    """The paper's ``state_space`` topic."""

    system: str
    stamp: float
    time: float = Field(description="exploration seconds")
    timeout_reached: bool
    depth: int
    markings: int
    edges: int


class ModelBundle(_Message):
    """Every source a predictor needs to rebuild the system."""

    OMIT_AT_DEFAULT = ("commanded",)
    system: str
    digest: str
    skillsets: list[tuple[str, str, str]] = Field(description="(file name, .rl text, manager node)")
    properties: str
    properties_name: str = "properties"
    commanded: dict[str, list[str]] = Field(
        default_factory=dict, description="per skillset, the events its binding says are commanded (controllable, "
                                          "docs/semantics.md §9), sorted; skillsets without any are left out")


class PredictRequest(_Message):
    # Strict: a budget sent as "1.0" or true, or a seq as 1.0, is refused, not converted.
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)
    system: str
    digest: str
    seq: int = Field(ge=0, description="monitor query counter")
    skillsets: dict[str, SkillsetStatus] = Field(description="the live marking")
    budget: float = Field(1.0, ge=MIN_BUDGET, le=MAX_BUDGET, allow_inf_nan=False,
                          description="exploration time budget, seconds (a number from 0.05 to 86400)")
    af: dict[str, Literal["fair", "literal"]] = Field(
        default_factory=dict, description="AF per property (docs/semantics.md §6.2); properties not listed use fair AF")


class Risk(BaseModel):
    """mu1 verdict of one marking reachable in one step, for one property."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    skillsets: dict[str, SkillsetStatus]
    property: str
    status: Literal["dangerous", "undecided"]
    af: Literal["fair", "literal"] = Field("fair", description="the AF that decided it (docs/semantics.md §6.2)")
    steps: int | None = None
    witness: list[str] = Field(default_factory=list)


class PredictReply(_Message):
    system: str
    digest: str
    seq: int
    ok: bool
    error: str = ""
    instance: str = ""
    report: StateSpaceReport | None = None
    risks: list[Risk] = Field(default_factory=list, description="non-safe one-step successors; others are safe")


class CheckRequest(_Message):
    """Is ``skillset:transition`` safe to fire now?  Asked on ``skinet/<system>/check``."""

    OMIT_AT_DEFAULT = ("wait", "policy")
    skillset: str
    transition: str = Field(description="logical transition, e.g. 'go_to_waypoint.start'")
    wait: float = Field(0.0, ge=0, le=MAX_CHECK_WAIT,
                        description="seconds the monitor may wait for a synced state and a fresh prediction "
                                    "before it answers (0: answer at once)")
    policy: str | None = Field(None, description="answer under this policy ('warn', 'strict' or "
                                                 "'KIND=ACTION,...') instead of the monitor's own")


class CheckReason(BaseModel):
    """One property the transition puts at risk (an operator-view unsafe entry, docs/semantics.md §5)."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    property: str
    constraint: str = Field(description="explicit, implicit, forced or unknown (any kind the monitor reports)")
    action: Literal["allow", "warn", "deny"] = Field(description="what the policy does with this constraint kind")
    controllable: bool
    steps: int | None = None
    witness: list[str] = Field(default_factory=list, description="'skillset:transition' names to the violation")
    reason: str = Field("", description="why, in the operator's words (as in UnsafeEntry)")


class CheckReply(_Message):
    """The monitor's answer from its live Algorithm 1 state (docs/semantics.md §7)."""

    system: str
    skillset: str
    transition: str
    ok: bool = Field(description="False: the request could not be judged (see error and candidates)")
    decision: Literal["allow", "warn", "deny"] | None = Field(None, description="None when ok is False")
    reasons: list[CheckReason] = Field(default_factory=list)
    enabled: bool = Field(False, description="the transition is firable at the live marking")
    violated: list[str] = Field(default_factory=list, description="properties violated now")
    recovers: list[str] = Field(default_factory=list, description="violated properties it restores")
    prediction_stale: bool = False
    seq: int = Field(0, ge=0, description="the monitor step the answer is about")
    policy: str = Field("", description="the policy that answered, e.g. 'explicit=warn,forced=warn,...'")
    error: str = ""
    candidates: list[str] = Field(default_factory=list, description="close names, on an unknown name")
    state_stale: bool = Field(False, description="True when a skillset is not live: the answer is about the last "
                                                 "marking known (decision at least warn, reason state_unknown)")
    state_reason: str = Field("", description="why the state is stale, in the operator's words")

    OMIT_AT_DEFAULT = ("state_stale", "state_reason")


class HeartbeatSkillset(BaseModel):
    """What a heartbeat says of one skillset."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    seq: int | None = Field(None, ge=0, description="seq of its last event (None: none published yet)")
    manager: bool | None = Field(None, description="its manager is present (true), left (false), or not announced "
                                                   "(null: the gateway declares no liveliness for it)")


class Heartbeat(_Message):
    """A publisher of canonical events is alive (docs/semantics.md §7): every ``period`` seconds on
    ``skinet/<system>/heartbeat/<source>``."""

    system: str
    source: str = Field(description="the publisher, as in its events' source")
    epoch: int = Field(ge=0, description="its run, as in its events' epoch")
    period: float = Field(gt=0, description="seconds between heartbeats")
    token: str = Field("", description="the liveliness token it holds, e.g. 'skinet/spot_arm/alive/bridge_ros2/x'")
    skillsets: dict[str, HeartbeatSkillset] = Field(description="the skillsets whose events it publishes")
    pending: dict[str, str] = Field(
        default_factory=dict, description="skillsets whose last status the publisher knows to be outdated, with "
                                          "why (a restarted manager not heard yet, a link cut, an interface not "
                                          "read yet or gone): a monitor must not vouch for it (docs/semantics.md §7)")

    OMIT_AT_DEFAULT = ("pending",)


class Divergence(BaseModel):
    """One model divergence, manager restart or violation onset the monitor met (docs/semantics.md §7), as operator views
    list it."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    n: int = Field(ge=0, description="its number in the monitor's run, from 0")
    kind: Literal["divergence", "restart", "violation"] = Field(
        description="divergence: the model could not explain the event; restart: the skillset's manager "
                    "restarted (reason then says whether the model could explain its new state); violation: "
                    "a property became violated at this step (reason names it), kept for views that join later")
    seq: int = Field(ge=0, description="the monitor step it made, or the step shown when it made none")
    stamp: float = Field(description="when the monitor met it (its clock, seconds since the epoch)")
    skillset: str
    event: str = Field(description="the event, 'skillset:transition#seq' as in LiveState.event")
    reason: str = Field("", description="why the model could not explain it ('' when it could)")
    info: str = Field("", description="what the bridge said (CanonicalEvent.info)")


class Divergences(_Message):
    """The model divergences, manager restarts and violation onsets of the monitor's run so far, the last
    ``MAX_DIVERGENCES``
    (docs/semantics.md §7): published on ``skinet/<system>/divergences`` when the list changes, and answered on ``get``."""

    system: str
    monitor: str = Field(description="the monitor's instance id: a new one starts a new list")
    stamp: float
    older: int = Field(0, ge=0, description="entries of this run left out before the first one listed")
    entries: list[Divergence] = Field(default_factory=list, description="oldest first, numbered n = older, ...")


class FedResult(BaseModel):
    """One result of the monitor in a :class:`ResultFeed`."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    kind: Literal["divergences", "state", "verdicts", "unsafe", "state_space"] = Field(
        description="the key it was published on: skinet/<system>/<kind>")
    message: dict[str, Any] = Field(description="the message as published there: a Divergences, LiveState, "
                                                "Verdicts, UnsafeReport or StateSpaceReport (its own schema)")


class ResultFeed(_Message):
    """The monitor's results in rounds, for views on the robot's own cores (docs/foxglove.md): published on
    ``skinet/<system>/@feed`` once per round while results come (every FEED_ROUND s, every FEED_FLOOD_ROUND s while
    more than FEED_STEPS steps come in one; skinet/wire/limits.py), only while someone subscribes to it."""

    system: str
    monitor: str = Field(description="the monitor's instance id: a new one starts seq again")
    seq: int = Field(ge=1, description="rounds this monitor published, +1 each: a gap is a round lost")
    round: float = Field(ge=0, description="seconds the round gathered results")
    skipped: int = Field(0, ge=0, description="steps of the round left out: past FEED_STEPS steps in a round "
                                              "only the last result of each kind is kept (the divergence list "
                                              "names the onset of every violation at its own step)")
    results: list[FedResult] = Field(default_factory=list, description="in the order they were published, or "
                                                                       "past FEED_STEPS the last of each kind")


class PlanBranch(BaseModel):
    """Another result of a plan step (:class:`skinet.plan.Branch`): ``then`` is ``retry`` or ``continue``
    (at ``step``), ``route`` (its own ``steps``, then on at ``step``) or ``reached``."""

    skillset: str
    transition: str = Field(description="the outcome; for a command with several results, the command itself")
    then: Literal["retry", "continue", "route", "reached"]
    step: str | None = Field(None, description="the step it goes on at, e.g. '2' or '2.1'")
    steps: list[PlanStep] = Field(default_factory=list, description="its own steps (then = route)")


class PlanStep(BaseModel):
    """One step of a plan's favourable path (:class:`skinet.plan.Step`), as ``skinet plan --json`` shows it."""

    number: str = Field(description="'2', or '2.1' inside the route of a branch of step 2")
    skillset: str = Field(description="the command's skillset; for waiting, the expected outcome's")
    action: str = Field(description="'SKILL.start', 'SKILL.interrupt' or 'wait'")
    expect: str | None = Field(None, description="waiting: the favourable outcome, e.g. 'init_power.success.powered_on'")
    inputs: dict[str, Any] | None = Field(None, description="a start's input values")
    branches: list[PlanBranch] = Field(default_factory=list, description="the other outcomes of this step")


PlanBranch.model_rebuild()


class PilotCommand(BaseModel):
    """A command of the pilot (docs/semantics.md §8): ``skillset:transition`` with a start's input values."""

    skillset: str
    transition: str = Field(description="'SKILL.start' or 'SKILL.interrupt'")
    inputs: dict[str, Any] = Field(default_factory=dict)


INTERRUPT_STATES = ("pending", "sent", "interrupted", "ended", "not interrupted")  # PilotStatus.interrupts
OPEN_INTERRUPTS = ("pending", "sent")  # those whose outcome is yet to come
PILOT_STATES = ("idle", "waiting for monitor", "planning", "guiding", "driving", "waiting for outcome", "paused",
                "reached", "failed", "cancelled")


class PilotGoalRequest(_Message):
    """Asked on ``skinet/<system>/pilot/goal/<client>`` (docs/semantics.md §8, the pilot): set a goal or a mission,
    switch mode, cancel, pause or resume.  ``goals`` (goal texts) and ``mission`` (a goals file's TOML
    text) are read as ``skinet plan`` reads them; errors come back with ``mission_name:line:col``."""

    OMIT_AT_DEFAULT = ("answer", "recover", "interrupt")
    system: str
    op: Literal["goal", "mode", "cancel", "pause", "resume", "confirm"] = Field(
        "goal", description="goal: set goals (or mission); mode: switch to `mode`; cancel, pause, resume the goal; "
                            "confirm: answer the outcome the pilot awaits (`answer`)")
    goals: list[str] = Field(default_factory=list, description="'reach FORMULA', 'run SKILLSET:SKILL[.success.MODE]'")
    inputs: dict[str, dict[str, Any]] = Field(default_factory=dict, description="skill -> its input values "
                                                                                "(for the goals given as text)")
    mission: str = Field("", description="a goals file's text ([[goals]] with reach or run, and inputs): "
                                         "planned after `goals`")
    mission_name: str = Field("goals.toml", description="the goals file's name, for error positions")
    mode: Literal["guide", "drive"] = Field("guide", description="guide: publish the next command; "
                                                                 "drive: also send it to the robot")
    replace: bool = Field(False, description="replace a goal that runs (otherwise such a request is rejected)")
    max_retries: int = Field(3, ge=1, le=100, description="failures of one skill after which the goal fails")
    answer: Literal["success", "failure", "rerun"] | None = Field(
        None, description="confirm: how the skill whose outcome is unknown ended (success, failure), or rerun: it "
                          "did not do its work, start it again (no retry counted)")
    recover: bool = Field(False, description="from a marking outside Safe (a property violated or forced), first "
                                             "send one of the admissible commands that lead back into Safe (the "
                                             "plan's recovery), then plan again; otherwise such a goal is rejected")
    interrupt: bool = Field(False, description=(
        "cancel: also interrupt the skills the pilot started for the goal that still run, each after the check "
        "allows it (PilotStatus.interrupts); without it they run on. Never a skill someone else started"))


class PilotGoalReply(_Message):
    """The pilot's answer to a :class:`PilotGoalRequest`."""

    system: str
    accepted: bool
    reason: str = Field("", description="why it was rejected, in the operator's words ('' when accepted)")
    goal_id: int = Field(0, ge=0, description="the pilot's number for the goal (0: none)")
    answer: Literal["strong", "cyclic", "none", "unknown"] | None = Field(
        None, description="the plan's answer for the first goal from the live marking (None: not planned)")
    moves: int | None = None
    steps: list[PlanStep] = Field(default_factory=list, description="the plan's first steps")


class PilotStatus(_Message):
    """The pilot's status (docs/semantics.md §8): published on ``skinet/<system>/pilot/status`` at every change, and
    answered on ``get`` there."""

    OMIT_AT_DEFAULT = ("unknown", "notes", "interrupts")
    system: str
    pilot: str = Field(description="the pilot's instance id")
    seq: int = Field(ge=0, description="publication counter")
    stamp: float
    state: Literal[PILOT_STATES] = Field(  # type: ignore[valid-type]
        description="'paused', 'failed' and 'waiting for monitor' give their `reason`")
    reason: str = Field("", description="why paused, failed, cancelled or waiting, in the operator's words")
    goal_id: int = Field(0, ge=0, description="the current or last goal (0: none yet)")
    client: str = Field("", description="who set the goal (its router login)")
    mode: Literal["guide", "drive"] = "guide"
    goals: list[str] = Field(default_factory=list, description="the mission's goals, as text")
    index: int = Field(0, ge=0, description="the position of the goal being followed in `goals`")
    answer: Literal["strong", "cyclic", "none", "unknown"] | None = None
    moves_left: int | None = Field(None, description="moves to the goal (strong: at most; cyclic: if favourable)")
    next: PilotCommand | None = Field(None, description="the command the plan gives now (None: wait or none)")
    steps: list[PlanStep] = Field(default_factory=list, description=(
        "the plan's expected steps from the marking it was made at (kept while it covers the live marking; "
        "`moves_left` and `next` are from the live marking)"))
    retries: dict[str, int] = Field(default_factory=dict, description="'skillset:skill' -> its failures in this goal")
    commands: int = Field(0, ge=0, description="commands sent to the robot for this goal")
    denied: int = Field(0, ge=0, description="commands the check denied (a defect: never sent)")
    state_seq: int = Field(0, ge=0, description="the monitor's LiveState.seq this status is about")
    unknown: MissedOutcome | None = Field(None, description=(
        "a skill that ended unseen and whose outcome the pilot cannot tell: it is paused until an operator "
        "answers with op confirm"))
    notes: list[str] = Field(default_factory=list, description=(
        "what the pilot assumed or was told during this goal, oldest first (its last ones): outcomes inferred "
        "after a gap, the operator's interrupts and answers, commands other than the one it suggested"))
    interrupts: dict[str, Literal[INTERRUPT_STATES]] = Field(  # type: ignore[valid-type]
        default_factory=dict, description=(
            "after a cancel with interrupt: 'skillset:skill' of each skill the pilot started that still ran -> "
            "pending (to be checked and sent; `next` is its interrupt), sent, interrupted, ended (before its "
            "interrupt: nothing left to do) or not interrupted (the check did not allow it, the robot refused it, "
            "or the pilot can no longer tell that the run is the one it started; the reason says why)"))


MESSAGES: dict[str, type[BaseModel]] = {
    m.__name__: m
    for m in (CanonicalEvent, LiveState, Verdicts, UnsafeReport, StateSpaceReport, ModelBundle, PredictRequest, PredictReply,
              CheckRequest, CheckReply, Heartbeat, Divergences, PilotGoalRequest, PilotGoalReply,
              PilotStatus, ResultFeed)
}
