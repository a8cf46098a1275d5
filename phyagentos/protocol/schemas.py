"""Pydantic models of every protocol document and of the session record.

Conventions: timestamps are ISO-8601 strings in UTC (``...Z`` or ``+00:00``);
durations are seconds, lengths metres, angles radians, positions in the world
frame (z up, origin at the robot base). Every model forbids unknown fields so a
typo in a hand-edited document is an error, not silently ignored data.

After changing a model, regenerate the committed JSON Schemas with
``python -c "from phyagentos.protocol import export_json_schemas as e; e('phyagentos/data/protocol/schemas')"``.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from datetime import datetime, timedelta, timezone
from pathlib import Path
from typing import Annotated, Any, Literal, get_args

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, field_validator, model_validator

from phyagentos.errors import format_choices

from .atomic import atomic_write_text

__all__ = [
    "CURRENT_VERSION",
    "SUPPORTED_VERSIONS",
    "SESSION_STATES",
    "TERMINAL_STATES",
    "TASK_NODE_STATES",
    "SESSION_ID_PATTERN",
    "SessionState",
    "TaskNodeState",
    "Timestamp",
    "utc_now_iso",
    "ProtocolModel",
    "VersionedModel",
    "Limits",
    "Lease",
    "RejectionItem",
    "TransitionRecord",
    "ErrorInfo",
    "CriterionResult",
    "Diagnosis",
    "Revision",
    "Verdict",
    "Attempt",
    "SessionResult",
    "ContextItem",
    "SessionContext",
    "SessionRecord",
    "SessionIndexEntry",
    "SessionsIndex",
    "TargetSpec",
    "TargetsDoc",
    "SkillRuntimeSpec",
    "SkillRuntimeDoc",
    "Entity",
    "Relation",
    "EnvironmentDoc",
    "Trial",
    "Lesson",
    "LessonsDoc",
    "KnowledgeEntry",
    "KnowledgeDoc",
    "SkillProcedure",
    "SkillDoc",
    "TaskNode",
    "TaskDoc",
    "LogEntry",
    "LogDoc",
    "Signal",
    "RuntimeSignalDoc",
    "SignalAck",
    "RunRecord",
    "WorkspaceBox",
    "SafetyConfig",
    "SAFETY_VIOLATIONS",
    "CLAMPABLE_VIOLATIONS",
    "SAFETY_FILE",
    "DOCUMENTS",
    "export_json_schemas",
]

CURRENT_VERSION = 1
SUPPORTED_VERSIONS: tuple[int, ...] = (1,)

SessionState = Literal[
    "pending",
    "claimed",
    "preflight_checking",
    "running",
    "finalizing",
    "awaiting_verification",
    "verifying",
    "awaiting_replan",
    "cancelling",
    "succeeded",
    "failed",
    "replanned",
    "timed_out",
    "cancelled",
    "rejected",
]
SESSION_STATES: tuple[str, ...] = get_args(SessionState)
TERMINAL_STATES: tuple[str, ...] = ("succeeded", "failed", "replanned", "timed_out", "cancelled", "rejected")

TaskNodeState = Literal["waiting", "ready", "running", "succeeded", "failed", "blocked", "cancelled"]
TASK_NODE_STATES: tuple[str, ...] = get_args(TaskNodeState)

# Session ids name files (sessions/<id>.md, evidence/<id>/), so no separators.
SESSION_ID_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9._-]{0,127}$"
_NAME_PATTERN = SESSION_ID_PATTERN


def utc_now_iso() -> str:
    """Current time as an ISO-8601 UTC string with microseconds, e.g. ``2024-05-01T12:00:00.000000Z``.

    Microseconds keep creation order stable for sessions submitted in the same millisecond.
    """
    return datetime.now(timezone.utc).isoformat(timespec="microseconds").replace("+00:00", "Z")


def _check_timestamp(value: str) -> str:
    try:
        # Python 3.10's fromisoformat does not accept the "Z" suffix.
        parsed = datetime.fromisoformat(value[:-1] + "+00:00" if value.endswith("Z") else value)
    except ValueError:
        raise ValueError("not an ISO-8601 timestamp (expected e.g. '2024-05-01T12:00:00Z')") from None
    if parsed.utcoffset() != timedelta(0):
        raise ValueError("timestamp must be in UTC with an explicit offset ('Z' or '+00:00')")
    return value


Timestamp = Annotated[
    str,
    AfterValidator(_check_timestamp),
    Field(json_schema_extra={"format": "date-time"}),
]
SessionId = Annotated[str, Field(pattern=SESSION_ID_PATTERN)]
Vec3 = Annotated[list[float], Field(min_length=3, max_length=3)]


def _unique(items: list[Any], attr: str, what: str) -> list[Any]:
    seen: set[str] = set()
    for item in items:
        key = getattr(item, attr)
        if key in seen:
            raise ValueError(f"duplicate {what} {key!r}; each must be unique")
        seen.add(key)
    return items


class StrictNumbers(BaseModel):
    """Mixin of deploy-time schemas: a YAML boolean is never read as a number (``true``
    would otherwise validate as 1 for an int or float field)."""

    @field_validator("*", mode="before")
    @classmethod
    def _no_bool_numbers(cls, value: Any, info: Any) -> Any:
        if isinstance(value, bool) and info.field_name in cls.model_fields:
            ann = cls.model_fields[info.field_name].annotation
            args = [a for arg in (get_args(ann) or (ann,)) for a in (get_args(arg) or (arg,))]
            if bool not in args and any(a in (int, float) for a in args):
                raise ValueError(f"{info.field_name} must be a number, not a boolean ({value})")
        return value


class ProtocolModel(BaseModel):
    """Base of all protocol models: unknown fields are errors."""

    model_config = ConfigDict(extra="forbid")


class VersionedModel(ProtocolModel):
    """A top-level document: carries the protocol ``version`` it was written for."""

    version: int = Field(
        CURRENT_VERSION, strict=True, description="Protocol version of this document."
    )

    @field_validator("version")
    @classmethod
    def _supported_version(cls, value: int) -> int:
        if value not in SUPPORTED_VERSIONS:
            raise ValueError(
                f"unsupported version {value}; supported: {format_choices(SUPPORTED_VERSIONS)}"
            )
        return value


# ---------------------------------------------------------------------------
# Session record parts.


class Limits(ProtocolModel):
    """Per-session time limits, all in seconds."""

    queue_timeout_s: float = Field(600.0, gt=0, description="Max time pending before a runner claims it (s).")
    preflight_timeout_s: float = Field(30.0, gt=0, description="Max time for compatibility preflight (s).")
    execution_timeout_s: float = Field(300.0, gt=0, description="Max time running the skill (s).")
    heartbeat_timeout_s: float = Field(10.0, gt=0, description="Max silence from the runner before timing out (s).")


class Lease(ProtocolModel):
    """A runner's claim on a session; valid until ``expires_at`` (unix seconds)."""

    owner: str = Field(description="Runner identity, e.g. host:pid.")
    token: str = Field(description="Random token; a write must present the current one.")
    expires_at: float = Field(description="Expiry time in unix seconds (time.time()).")


class RejectionItem(ProtocolModel):
    """One reason a preflight rejected a session, phrased so a human can fix it."""

    code: str
    field: str
    expected: str
    found: str
    fix: str


class TransitionRecord(ProtocolModel):
    """One lifecycle transition, appended and never rewritten."""

    at: Timestamp
    source: str
    dest: str
    event: str


class ErrorInfo(ProtocolModel):
    """An error that ended an attempt: exception class (or code) and message."""

    code: str
    message: str


class CriterionResult(ProtocolModel):
    """Outcome of one acceptance predicate."""

    name: str
    predicate: str
    status: Literal["satisfied", "unsatisfied", "unknown"]
    reason: str
    evidence: list[str] = Field(default_factory=list, description="Evidence file paths or keys consulted.")


class Diagnosis(ProtocolModel):
    """Why an attempt did not succeed, derived from its evidence (``phyagentos.agent.diagnosis``)."""

    cause: str = Field(description="Taxonomy code, e.g. 'perception_error', 'object_slipped'.")
    category: str = Field(description="Error category: perception, execution, planning, timeout, safety, "
                                      "precondition or unknown.")
    summary: str
    facts: dict[str, Any] = Field(default_factory=dict, description="Measured quantities behind the diagnosis (SI units).")
    evidence: list[str] = Field(default_factory=list, description="Evidence files consulted, workspace-relative.")


class ModelCallRecord(ProtocolModel):
    """One language-model call made for a session (by the Goal Planner, a reviser or the agent runtime)."""

    role: Literal["planner", "reviser", "agent_runtime"] = Field(description="Who called the model.")
    purpose: str = Field(description="What the call was for: plan, repair, revise, act.")
    provider: str = Field(description="llama.cpp or openai.")
    model: str
    prompt_sha256: str = Field(description="SHA-256 (first 16 hex) of messages and output schema.")
    parameters: dict[str, Any] = Field(default_factory=dict, description="Sampling settings sent: temperature, "
                                                                         "seed, max_tokens, constrained.")
    prompt_tokens: int = Field(0, ge=0)
    completion_tokens: int = Field(0, ge=0)
    latency_s: float = Field(0.0, ge=0, description="Wall time of the call (s).")
    output: str = Field("", description="The model's raw answer (text).")
    outcome: str = Field(description="What became of the answer: accepted, refused, rejected, repaired, gave_up, "
                                     "fallback, error.")
    detail: str = Field("", description="Why (a validator's message, the fallback's reason).")
    ref: str | None = Field(None, description="Where the full record is (plan directory or evidence), "
                                              "workspace-relative.")


class Revision(ProtocolModel):
    """A recovery strategy applied to a session: the parameters its child runs with."""

    strategy: str = Field(description="Recovery strategy name, e.g. 're_observe', 'firmer_grip'.")
    cause: str = Field(description="Diagnosed cause the strategy answers.")
    step: int = Field(1, ge=1, description="Escalation step along the lineage (1 = first replan).")
    parameters: dict[str, Any] = Field(default_factory=dict, description="Skill parameters set to new values.")
    limits: dict[str, float] = Field(default_factory=dict, description="Session limits set to new values (s).")
    rationale: str = ""
    skill: str | None = Field(None, description="Skill the child runs instead of the node's (e.g. 'observe': "
                                                "another view of the same world); None: the node's skill.")
    reopen: str | None = Field(None, description="Upstream goal node re-opened before this node runs again "
                                                 "(e.g. re-pick after the object was released).")
    runtime: str | None = Field(None, description="SkillRuntime the child runs with instead of the node's (with "
                                                  "skill: the switched skill's own, e.g. 'builtin' for a re-grasp "
                                                  "of a policy node); None: the node's, or the switched skill's "
                                                  "manifest runtime.")
    proposed_by: str = Field("rules", description="The reviser that proposed it: rules or model.")
    target: str | None = Field(None, description="Target the child runs on instead of the node's (a re-target to "
                                                 "another capable target, chosen by the SkillRuntime-Target "
                                                 "Selector); None: the node's target.")
    selection: dict[str, str] = Field(default_factory=dict, description="With target: the selector's reason per "
                                                                        "target (why this one, why not the others).")
    model_calls: list[ModelCallRecord] = Field(default_factory=list, description="Model calls behind it.")


class Verdict(ProtocolModel):
    """The verifier's judgement of an attempt."""

    verdict: Literal["success", "failure", "replan"]
    reason: str
    criteria: list[CriterionResult] = Field(default_factory=list)
    verifier: str = "predicates"
    at: Timestamp
    evidence: list[str] = Field(default_factory=list, description="Evidence files the verdict rests on, workspace-relative.")
    diagnosis: Diagnosis | None = Field(None, description="Diagnosed cause when the verdict is not success.")
    revision: Revision | None = Field(None, description="The revision a 'replan' verdict proposes for the child session.")


class Attempt(ProtocolModel):
    """One execution attempt of a session (timings in seconds)."""

    number: int = Field(ge=1)
    started_at: Timestamp
    ended_at: Timestamp | None = None
    runner: str | None = None
    outcome: str | None = None
    error: ErrorInfo | None = None
    evidence: str | None = Field(None, description="Evidence bundle path, relative to the workspace.")
    verdict: Verdict | None = None
    timings: dict[str, float] = Field(default_factory=dict, description="Phase durations in seconds.")


class SessionResult(ProtocolModel):
    """Summary written when a session reaches a terminal state."""

    status: str
    verdict: str | None = None
    reason: str = ""
    duration_s: float = Field(ge=0, description="Wall time from claim to terminal state (s).")
    evidence: str | None = Field(None, description="Evidence bundle path, relative to the workspace.")
    error: ErrorInfo | None = Field(
        None, description="Attributed error that ended the session (code from docs/ERRORS.md), if any."
    )


class ContextItem(ProtocolModel):
    """One memory item the ContextBuilder injected into a session, with provenance."""

    kind: Literal["lesson", "knowledge", "procedure"]
    id: str
    summary: str
    provenance: list[str] = Field(default_factory=list, description="Session ids the item was verified on.")
    applied: dict[str, Any] = Field(default_factory=dict, description="Parameter values this item set (empty: informative only).")
    held: dict[str, Any] = Field(default_factory=dict, description=(
        "A situational lesson's correction, held back until its cause recurs in this session's lineage: "
        "cause, strategy, parameters, skill (empty: none)."))


class SessionContext(ProtocolModel):
    """What the ContextBuilder retrieved for a session and what it changed."""

    conditions: dict[str, Any] = Field(default_factory=dict, description="Goal, skill, target, object and scene conditions.")
    risk_factors: list[str] = Field(default_factory=list)
    items: list[ContextItem] = Field(default_factory=list)
    parameters: dict[str, Any] = Field(default_factory=dict, description="Parameters set from memory (over the node's own).")
    built_at: Timestamp
    model_calls: list[ModelCallRecord] = Field(default_factory=list, description="Every language-model call made "
                                                                                 "for this session, in order.")


class SessionRecord(VersionedModel):
    """A session: one skill invocation on one target; the YAML of ``sessions/<id>.md``.

    ``transitions`` and ``attempts`` are append-only (see ``Workspace.save_session``).
    """

    session_id: SessionId
    run_id: str
    goal_graph: str | None = Field(None, description="Goal graph file or name this session came from.")
    node: str = Field(description="Goal graph node id this session executes.")
    parent_session_id: SessionId | None = None
    child_session_ids: list[str] = Field(default_factory=list)
    depends_on: list[str] = Field(default_factory=list, description="Goal graph node ids.")
    skill: str
    skill_runtime: str = "builtin"
    target: str
    parameters: dict[str, Any] = Field(default_factory=dict)
    preconditions: list[Any] = Field(default_factory=list)
    accept: dict[str, Any] | list[dict[str, Any]] = Field(
        default_factory=dict, description="Acceptance criteria: predicate -> arguments, or a list of one-key mappings."
    )
    limits: Limits = Field(default_factory=Limits)
    scene: dict[str, Any] | None = None
    seed: int | None = None
    evaluation: dict[str, Any] | None = Field(
        None, description="Benchmark evaluation configuration (suite, task, episode, split, memory mode, perturbation); "
        "None outside a benchmark."
    )
    context: SessionContext | None = Field(None, description="Memory the ContextBuilder injected, with provenance.")
    recovery: Revision | None = Field(None, description="For a replanned child: the revision it runs with.")
    state: SessionState = "pending"
    created_at: Timestamp
    updated_at: Timestamp
    lease: Lease | None = None
    adapter_plan: dict[str, Any] | None = None
    tool_manifest: dict[str, Any] | None = None
    rejection: list[RejectionItem] = Field(default_factory=list)
    transitions: list[TransitionRecord] = Field(default_factory=list)
    attempts: list[Attempt] = Field(default_factory=list)
    result: SessionResult | None = None

    @property
    def is_terminal(self) -> bool:
        """True when ``state`` is one of :data:`TERMINAL_STATES`."""
        return self.state in TERMINAL_STATES


# ---------------------------------------------------------------------------
# Workspace documents.


class SessionIndexEntry(ProtocolModel):
    """One row of the SESSIONS.md index."""

    session_id: SessionId
    node: str
    skill: str
    target: str
    state: SessionState
    updated_at: Timestamp
    parent_session_id: str | None = None
    run_id: str | None = None
    owner: str | None = Field(None, description="Lease owner (supervisor) while the session holds a lease.")


class SessionsIndex(VersionedModel):
    """SESSIONS.md: a bounded view of active sessions plus the most recent terminal ones.

    Sessions holding a lease are always listed; waiting ones (pending, awaiting
    verification or replan) and terminal ones are capped, and ``counts`` gives the
    exact number of active sessions per state, so the view stays small however long
    the queue or the history is.
    """

    sessions: list[SessionIndexEntry] = Field(default_factory=list)
    counts: dict[str, int] = Field(
        default_factory=dict, description="Active (non-terminal) sessions per state, listed or not."
    )

    @field_validator("sessions")
    @classmethod
    def _unique_ids(cls, value: list[SessionIndexEntry]) -> list[SessionIndexEntry]:
        return _unique(value, "session_id", "session_id")


class TargetSpec(ProtocolModel):
    """A robot, simulation or game a session can run on."""

    name: str = Field(pattern=_NAME_PATTERN)
    kind: Literal["simulation", "real_robot", "game"]
    driver: str
    enabled: bool = True
    capabilities: list[str]
    observations: list[str]
    action: dict[str, Any] = Field(description="Action space, e.g. {space, dof, gripper, control_rate_hz}.")
    endpoint: str | None = None
    constraints: dict[str, Any] = Field(default_factory=dict)
    scene: dict[str, Any] = Field(default_factory=dict)


class TargetsDoc(VersionedModel):
    """TARGETS.md: the registered targets."""

    targets: list[TargetSpec] = Field(default_factory=list)

    @field_validator("targets")
    @classmethod
    def _unique_names(cls, value: list[TargetSpec]) -> list[TargetSpec]:
        return _unique(value, "name", "target name")


class SkillRuntimeSpec(ProtocolModel):
    """A skill runtime and what it can drive."""

    name: str
    orchestration: str
    target_kinds: list[str]
    action_forms: list[str]
    provides: list[str] = Field(default_factory=list)
    parameters: dict[str, Any] = Field(default_factory=dict)
    adapter_requirements: list[str] = Field(default_factory=list)
    presets: dict[str, dict[str, Any]] = Field(
        default_factory=dict,
        description="Named conventions a session selects with the parameter policy_preset (policy runtime): "
                    "{description, skill, endpoint?, parameters} where parameters override the runtime's.",
    )


class SkillRuntimeDoc(VersionedModel):
    """SKILLRUNTIME.md: the available skill runtimes."""

    runtimes: list[SkillRuntimeSpec] = Field(default_factory=list)

    @field_validator("runtimes")
    @classmethod
    def _unique_names(cls, value: list[SkillRuntimeSpec]) -> list[SkillRuntimeSpec]:
        return _unique(value, "name", "runtime name")


class Entity(ProtocolModel):
    """An object in the scene; pose in the world frame."""

    name: str
    kind: str
    position: Vec3 = Field(description="Position [x, y, z] in metres, world frame.")
    quat_wxyz: Annotated[list[float], Field(min_length=4, max_length=4)] = Field(
        default_factory=lambda: [1.0, 0.0, 0.0, 0.0],
        description="Orientation quaternion [w, x, y, z], world frame.",
    )
    size: Annotated[list[float], Field(min_length=1, max_length=3)] | None = Field(
        None, description="MuJoCo-style geom size in metres (box: 3 half extents; sphere: radius)."
    )
    attributes: dict[str, Any] = Field(default_factory=dict)


class Relation(ProtocolModel):
    """A symbolic relation, e.g. ``cube on table``."""

    subject: str
    relation: str
    object: str
    confidence: float | None = Field(None, ge=0, le=1, description="Perceived relations: 0..1.")


class EnvironmentDoc(VersionedModel):
    """ENVIRONMENT.md: the last observed world state."""

    revision: int = Field(0, ge=0, description="Incremented on every write.")
    target: str | None = None
    session_id: str | None = None
    captured_at: Timestamp | None = None
    sim_time_s: float | None = Field(None, description="Simulation time at capture (s).")
    entities: list[Entity] = Field(default_factory=list)
    relations: list[Relation] = Field(default_factory=list)
    evidence: list[str] = Field(default_factory=list)


class Trial(ProtocolModel):
    """A randomised comparison of a correction: runs assigned to apply it (``with``) or to
    hold it back (``without``), and what happened in each arm.

    Counts are per session of an assigned run: game steps played, deaths (of any cause),
    sessions. A correction that changes survival behaviour is judged on the death rate
    per step of its two arms (``phyagentos.agent.memory.deaths``), not on sessions that
    merely applied it and lived.
    """

    steps_with: int = Field(0, ge=0, description="Game steps played by sessions that applied the correction.")
    deaths_with: int = Field(0, ge=0, description="Deaths (any cause) in sessions that applied it.")
    sessions_with: int = Field(0, ge=0)
    acted_with: int = Field(0, ge=0, description="Sessions of the with-arm in which the correction fired a reflex "
                                                 "that the default would not have fired.")
    steps_without: int = Field(0, ge=0, description="Game steps played by sessions that held it back.")
    deaths_without: int = Field(0, ge=0, description="Deaths (any cause) in sessions that held it back.")
    sessions_without: int = Field(0, ge=0)
    p_value: float | None = Field(None, ge=0, le=1, description="One-sided p of the last decision test "
                                                               "(fewer deaths per step with the correction).")


class Lesson(ProtocolModel):
    """A failure analysed into a correction, with the evidence it came from."""

    id: str
    objective: str
    evidence: list[str]
    cause: str
    correction: str
    verified: bool = False
    verified_by: list[str] = Field(default_factory=list, description="Session ids that confirmed the correction.")
    scope: dict[str, Any] = Field(default_factory=dict)
    provenance: list[str] = Field(default_factory=list)
    strategy: str = Field("", description="Recovery strategy that proposed the correction.")
    proposed_by: str = Field("rules", description="The reviser that proposed the correction: rules or model "
                                                  "('rules+model' when a lineage's cumulative correction took both).")
    skill: str | None = Field(None, description="Skill the correction runs instead of the failed session's "
                                                "(a skill switch), if any.")
    target: str | None = Field(None, description="Target the correction runs on instead of the failed session's "
                                                 "(a re-target), if any.")
    revision: dict[str, Any] = Field(default_factory=dict, description="Skill parameter values the correction sets.")
    confirmations: int = Field(0, ge=0, description="Verdicts that confirmed the correction (success).")
    refutations: int = Field(0, ge=0, description="Verdicts where the correction did not succeed.")
    refuted_by: list[str] = Field(default_factory=list, description="Session ids whose verdict did not confirm it.")
    trial: Trial | None = Field(None, description="A randomised with/without comparison that decides the lesson "
                                                  "(survival corrections), if any.")
    updated_at: Timestamp | None = None


class LessonsDoc(VersionedModel):
    """LESSONS.md: verified lessons, and candidate corrections no verdict has confirmed yet."""

    lessons: list[Lesson] = Field(default_factory=list)
    candidates: list[Lesson] = Field(
        default_factory=list, description="Proposed corrections awaiting a confirming verdict (not lessons yet)."
    )

    @field_validator("lessons", "candidates")
    @classmethod
    def _unique_ids(cls, value: list[Lesson]) -> list[Lesson]:
        return _unique(value, "id", "lesson id")


class KnowledgeEntry(ProtocolModel):
    """A reusable pattern with its success statistics."""

    id: str
    pattern: str
    conditions: dict[str, Any] = Field(default_factory=dict)
    provenance: list[str] = Field(default_factory=list)
    successes: int = Field(0, ge=0)
    attempts: int = Field(0, ge=0)
    parameters: dict[str, Any] = Field(default_factory=dict, description="Strategy parameters of the pattern.")
    initial_states: list[str] = Field(
        default_factory=list, description="Distinct initial states it succeeded from (bounded sample of fingerprints)."
    )
    updated_at: Timestamp | None = None

    @model_validator(mode="after")
    def _successes_within_attempts(self) -> KnowledgeEntry:
        if self.successes > self.attempts:
            raise ValueError(f"successes ({self.successes}) exceed attempts ({self.attempts})")
        return self


class KnowledgeDoc(VersionedModel):
    """KNOWLEDGE.md: consolidated, verified knowledge."""

    entries: list[KnowledgeEntry] = Field(default_factory=list)

    @field_validator("entries")
    @classmethod
    def _unique_ids(cls, value: list[KnowledgeEntry]) -> list[KnowledgeEntry]:
        return _unique(value, "id", "knowledge id")


class SkillProcedure(ProtocolModel):
    """A procedure verified often enough across varied initial states to be reused as is."""

    name: str
    base_skill: str = Field(description="The skill it runs (skills/<name>.yaml).")
    description: str = ""
    conditions: dict[str, Any] = Field(default_factory=dict, description="Where it applies (target, skill, object, risks).")
    parameters: dict[str, Any] = Field(default_factory=dict, description="Strategy parameters it fixes.")
    knowledge_id: str = Field(description="The KNOWLEDGE.md entry it was promoted from.")
    provenance: list[str] = Field(default_factory=list, description="Session ids that verified it.")
    successes: int = Field(0, ge=0)
    attempts: int = Field(0, ge=0)
    distinct_initial_states: int = Field(0, ge=0)
    promoted_at: Timestamp
    updated_at: Timestamp | None = None


class SkillDoc(VersionedModel):
    """SKILL.md: promoted, repeatedly verified procedures (procedural memory)."""

    procedures: list[SkillProcedure] = Field(default_factory=list)

    @field_validator("procedures")
    @classmethod
    def _unique_names(cls, value: list[SkillProcedure]) -> list[SkillProcedure]:
        return _unique(value, "name", "procedure name")


class TaskNode(ProtocolModel):
    """One goal graph node and the sessions that executed it."""

    id: str
    skill: str
    target: str
    depends_on: list[str] = Field(default_factory=list, description="Node ids.")
    state: TaskNodeState
    session_ids: list[str] = Field(default_factory=list)


class TaskDoc(VersionedModel):
    """TASK.md: the current run's goal graph progress."""

    run_id: str | None = None
    goal_graph: str | None = None
    nodes: list[TaskNode] = Field(default_factory=list)

    @field_validator("nodes")
    @classmethod
    def _unique_ids(cls, value: list[TaskNode]) -> list[TaskNode]:
        return _unique(value, "id", "node id")


class LogEntry(ProtocolModel):
    """One line of the human-readable event log."""

    at: Timestamp
    session_id: str | None = None
    node: str | None = None
    event: str
    state: str | None = None
    message: str = ""


class LogDoc(VersionedModel):
    """LOG.md: the most recent log entries (older ones live in log/archive-YYYY-MM.jsonl)."""

    entries: list[LogEntry] = Field(default_factory=list)


class Signal(ProtocolModel):
    """An operator signal; ``session_id`` None addresses every session."""

    id: str
    kind: Literal["cancel", "pause", "resume", "estop", "clear_estop"]
    session_id: str | None = None
    issued_by: str
    issued_at: Timestamp
    reason: str = ""


class SignalAck(ProtocolModel):
    """A supervisor's record that it acted on a signal (appended, never rewritten)."""

    signal_id: str
    by: str = Field(description="Supervisor identity (host:pid:tag).")
    at: Timestamp
    result: str = Field(description="What the supervisor did, e.g. 'paused' or 'cancelled session s1'.")


class RuntimeSignalDoc(VersionedModel):
    """RUNTIME_SIGNAL.md: signals from operators to the runtime, and who handled them."""

    signals: list[Signal] = Field(default_factory=list)
    handled: list[SignalAck] = Field(default_factory=list)

    @field_validator("signals")
    @classmethod
    def _unique_ids(cls, value: list[Signal]) -> list[Signal]:
        return _unique(value, "id", "signal id")


class RunRecord(VersionedModel):
    """``runs/<run_id>/RUN.md``: one submitted goal graph, so any Agent process can continue it.

    The validated graph is copied next to it (``graph_file``), so editing or deleting
    the original after submit changes nothing.
    """

    run_id: SessionId
    goal_graph: str = Field(description="Path the goal graph was submitted from.")
    graph_file: str = Field(description="Workspace-relative path of the submitted copy.")
    seed: int | None = None
    target: str | None = Field(None, description="Target that overrides every node's target, if any.")
    submitted_at: Timestamp
    submitted_by: str = ""
    state: Literal["active", "finished"] = "active"
    finished_at: Timestamp | None = None
    succeeded: bool | None = None
    error: str | None = Field(None, description="Why the run was set aside (a stored document that no longer "
                                                "validates, with file and line), if it was.")


# ---------------------------------------------------------------------------
# safety.yaml


class WorkspaceBox(StrictNumbers, ProtocolModel):
    """Axis-aligned box (metres, world frame) the end effector must stay inside."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    min: Vec3
    max: Vec3

    @model_validator(mode="after")
    def _ordered(self) -> WorkspaceBox:
        for axis, lo, hi in zip("xyz", self.min, self.max):
            if lo > hi:
                raise ValueError(f"workspace_box min.{axis} ({lo}) is greater than max.{axis} ({hi})")
        return self


#: Violation codes of the SafetyGuard, one per check (``safety.<check>``).
SAFETY_VIOLATIONS: tuple[str, ...] = (
    "safety.dtype",
    "safety.shape",
    "safety.nan",
    "safety.joint_limit",
    "safety.workspace",
    "safety.velocity",
    "safety.acceleration",
    "safety.duration",
    "safety.rate",
    "safety.estop",
)
#: Violations with a semantics-preserving bound the guard can apply when authorised:
#: clip into the joint range, rate-limit the motion, truncate the command.
CLAMPABLE_VIOLATIONS: tuple[str, ...] = (
    "safety.joint_limit",
    "safety.velocity",
    "safety.acceleration",
    "safety.duration",
)
SafetyOutcome = Literal["reject", "halt"]


def _default_outcomes() -> dict[str, SafetyOutcome]:
    # Malformed or ill-timed commands are dropped (the arm keeps its last admitted
    # command); commands that would move the arm somewhere unsafe stop it.
    return {
        "safety.dtype": "reject",
        "safety.shape": "reject",
        "safety.nan": "reject",
        "safety.joint_limit": "halt",
        "safety.workspace": "halt",
        "safety.velocity": "halt",
        "safety.acceleration": "halt",
        "safety.duration": "reject",
        "safety.rate": "reject",
        "safety.estop": "halt",
    }


class SafetyConfig(StrictNumbers, VersionedModel):
    """safety.yaml: limits the SafetyGuard enforces on every command.

    Read-only by construction (a frozen model): the runtime loads it once per session
    from the deploy-time file, and nothing on the memory / self-evolution path
    (LESSONS.md, KNOWLEDGE.md, SKILL.md) is ever merged into it.
    """

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    joint_position_margin_rad: float = Field(
        0.0, le=1.0, ge=0, description="Keep joints this far (rad) inside the model's position limits."
    )
    max_joint_velocity_scale: float = Field(
        1.0, gt=0, le=1, description="Fraction of the model's joint velocity limits allowed."
    )
    max_joint_acceleration_rad_s2: float = Field(10.0, le=1000.0, gt=0, description="Joint acceleration bound (rad/s^2).")
    workspace_box: WorkspaceBox = Field(
        default_factory=lambda: WorkspaceBox(min=[-0.2, -0.8, -0.01], max=[1.0, 0.8, 1.2])
    )
    max_command_duration_s: float = Field(30.0, le=3600.0, gt=0, description="Longest single command (s).")
    max_command_rate_hz: float = Field(1000.0, le=100_000.0, gt=0, description="Highest command rate (Hz).")
    clamp_allowed: tuple[str, ...] = Field(
        default_factory=tuple, description="Violation codes that may be clamped instead of rejected."
    )
    violation_outcomes: dict[str, SafetyOutcome] = Field(
        default_factory=_default_outcomes,
        description="Outcome per violation code when it is not clamped: 'reject' drops the command "
        "(the arm keeps its last admitted command), 'halt' drops it and stops the arm.",
    )

    @field_validator("clamp_allowed")
    @classmethod
    def _clampable(cls, value: tuple[str, ...]) -> tuple[str, ...]:
        for code in value:
            if code not in CLAMPABLE_VIOLATIONS:
                raise ValueError(
                    f"{code!r} cannot be clamped; clampable violations: {format_choices(CLAMPABLE_VIOLATIONS)}"
                )
        return value

    @field_validator("violation_outcomes")
    @classmethod
    def _known_outcomes(cls, value: dict[str, str]) -> dict[str, str]:
        for code in value:
            if code not in SAFETY_VIOLATIONS:
                raise ValueError(f"unknown violation code {code!r}; valid: {format_choices(SAFETY_VIOLATIONS)}")
        if value.get("safety.estop", "halt") != "halt":
            raise ValueError("'safety.estop' must be 'halt': an engaged e-stop always stops the arm")
        return {**_default_outcomes(), **value}


# ---------------------------------------------------------------------------
# Registry and JSON Schema export.

SAFETY_FILE = "safety.yaml"

DOCUMENTS: Mapping[str, tuple[str, type[VersionedModel]]] = {
    "SESSIONS": ("SESSIONS.md", SessionsIndex),
    "TARGETS": ("TARGETS.md", TargetsDoc),
    "SKILLRUNTIME": ("SKILLRUNTIME.md", SkillRuntimeDoc),
    "ENVIRONMENT": ("ENVIRONMENT.md", EnvironmentDoc),
    "LESSONS": ("LESSONS.md", LessonsDoc),
    "KNOWLEDGE": ("KNOWLEDGE.md", KnowledgeDoc),
    "SKILL": ("SKILL.md", SkillDoc),
    "TASK": ("TASK.md", TaskDoc),
    "LOG": ("LOG.md", LogDoc),
    "RUNTIME_SIGNAL": ("RUNTIME_SIGNAL.md", RuntimeSignalDoc),
}


def _schema_models() -> dict[str, type[BaseModel]]:
    models: dict[str, type[BaseModel]] = {name.lower(): model for name, (_, model) in DOCUMENTS.items()}
    models["session"] = SessionRecord
    models["run"] = RunRecord
    models["safety"] = SafetyConfig
    return models


def export_json_schemas(directory: str | Path) -> list[Path]:
    """Write ``<name>.schema.json`` (JSON Schema 2020-12) for every document model.

    Names are the lower-cased ``DOCUMENTS`` keys plus ``session`` (the
    ``sessions/<id>.md`` record) and ``safety`` (``safety.yaml``). Creates
    ``directory`` if needed; returns the written paths, sorted.

    Raises:
        OSError: the directory cannot be created or written.
    """
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for name, model in sorted(_schema_models().items()):
        schema = {"$schema": "https://json-schema.org/draft/2020-12/schema", **model.model_json_schema()}
        path = out / f"{name}.schema.json"
        atomic_write_text(path, json.dumps(schema, indent=2, ensure_ascii=False) + "\n")
        written.append(path)
    return written

