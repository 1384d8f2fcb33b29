"""Messages exchanged over Zenoh (SPEC §1), as pydantic models.

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

from typing import ClassVar, Literal

from pydantic import BaseModel, ConfigDict, Field

from skinet.wire.limits import MIN_BUDGET

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
    divergence: str = Field("", description="a model divergence the bridge found (a binding's drift, SPEC §9), "
                                            "with the message that showed it; the monitor reports it even when "
                                            "the status matches its marking")

    OMIT_AT_DEFAULT = ("restart", "divergence")


class PropertyVerdict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)
    name: str
    holds: bool


class SkillsetSync(BaseModel):
    """How far the monitor vouches for one skillset's marking (SPEC §7, honest live state)."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    state: Literal["live", "syncing", "lost"] = Field(
        description="live: synced from its source, which is heard; syncing: waiting for the source's resync "
                    "answer (the monitor started, or the source came back); lost: the source went quiet")
    since: float = Field(description="when this state began, the monitor's clock (seconds since the epoch)")
    reason: str = Field("", description="why it is not live, in the operator's words (empty when live)")
    source: str = Field("", description="the publisher of its events the monitor follows ('' before the first sync)")


class LiveState(_Message):
    """The monitor's live marking after an event."""

    OMIT_AT_DEFAULT = ("sync",)
    system: str
    seq: int = Field(ge=0, description="monitor publication counter")
    stamp: float
    skillsets: dict[str, SkillsetStatus]
    event: str = Field("", description="the event that led here, 'skillset:transition#seq'")
    divergence: str | None = Field(None, description="why the model could not explain the event")
    sync: dict[str, SkillsetSync] = Field(
        default_factory=dict, description="per skillset, whether the monitor can vouch for its marking; every "
                                          "skillset is listed (absent: a monitor older than this field)")


class Verdicts(_Message):
    system: str
    seq: int = Field(ge=0)
    stamp: float
    properties: list[PropertyVerdict]


class UnsafeEntry(BaseModel):
    """One unsafe transition of Algorithm 1 (SPEC §5), the worst kind over its variants."""

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

    system: str
    digest: str
    skillsets: list[tuple[str, str, str]] = Field(description="(file name, .rl text, manager node)")
    properties: str
    properties_name: str = "properties"


class PredictRequest(_Message):
    # Strict: a budget sent as "1.0" or true, or a seq as 1.0, is refused, not converted.
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)
    system: str
    digest: str
    seq: int = Field(ge=0, description="monitor query counter")
    skillsets: dict[str, SkillsetStatus] = Field(description="the live marking")
    budget: float = Field(1.0, ge=MIN_BUDGET, allow_inf_nan=False,
                          description="exploration time budget, seconds (a number; at least 0.05)")
    af: dict[str, Literal["fair", "literal"]] = Field(
        default_factory=dict, description="AF per property (SPEC §6.2); properties not listed use fair AF")


class Risk(BaseModel):
    """mu1 verdict of one marking reachable in one step, for one property."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    skillsets: dict[str, SkillsetStatus]
    property: str
    status: Literal["dangerous", "undecided"]
    af: Literal["fair", "literal"] = Field("fair", description="the AF that decided it (SPEC §6.2)")
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
    """One property the transition puts at risk (an operator-view unsafe entry, SPEC §5)."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    property: str
    constraint: str = Field(description="explicit, implicit, forced or unknown (any kind the monitor reports)")
    action: Literal["allow", "warn", "deny"] = Field(description="what the policy does with this constraint kind")
    controllable: bool
    steps: int | None = None
    witness: list[str] = Field(default_factory=list, description="'skillset:transition' names to the violation")
    reason: str = Field("", description="why, in the operator's words (as in UnsafeEntry)")


class CheckReply(_Message):
    """The monitor's answer from its live Algorithm 1 state (SPEC §7)."""

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
    """A publisher of canonical events is alive (SPEC §7): every ``period`` seconds on
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
                                          "read yet or gone): a monitor must not vouch for it (SPEC §7)")

    OMIT_AT_DEFAULT = ("pending",)


class Divergence(BaseModel):
    """One model divergence or manager restart the monitor met (SPEC §7), as operator views list it."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    n: int = Field(ge=0, description="its number in the monitor's run, from 0")
    kind: Literal["divergence", "restart"] = Field(
        description="divergence: the model could not explain the event; restart: the skillset's manager "
                    "restarted (reason then says whether the model could explain its new state)")
    seq: int = Field(ge=0, description="the monitor step it made, or the step shown when it made none")
    stamp: float = Field(description="when the monitor met it (its clock, seconds since the epoch)")
    skillset: str
    event: str = Field(description="the event, 'skillset:transition#seq' as in LiveState.event")
    reason: str = Field("", description="why the model could not explain it ('' when it could)")
    info: str = Field("", description="what the bridge said (CanonicalEvent.info)")


class Divergences(_Message):
    """The model divergences and manager restarts of the monitor's run so far, the last ``MAX_DIVERGENCES``
    (SPEC §7): published on ``skinet/<system>/divergences`` when the list changes, and answered on ``get``."""

    system: str
    monitor: str = Field(description="the monitor's instance id: a new one starts a new list")
    stamp: float
    older: int = Field(0, ge=0, description="entries of this run left out before the first one listed")
    entries: list[Divergence] = Field(default_factory=list, description="oldest first, numbered n = older, ...")


MESSAGES: dict[str, type[BaseModel]] = {
    m.__name__: m
    for m in (CanonicalEvent, LiveState, Verdicts, UnsafeReport, StateSpaceReport, ModelBundle, PredictRequest, PredictReply,
              CheckRequest, CheckReply, Heartbeat, Divergences)
}
