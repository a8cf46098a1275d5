"""SessionRunner: owns one session's interaction with its target, tick by tick.

It runs inside the runner process (:mod:`phyagentos.runtime.worker`). After a passed
preflight it prepares the session while the WatchdogSupervisor persists ``start``
(:meth:`SessionRunner.prepare`: it acquires the target in the state the episode left
it, snapshots the initial world and builds the skill context; nothing moves and
nothing is written but a camera target's perception frames). Once ``start`` is on
disk and ``go`` arrives it writes ``task.yaml``, the checkpoint of the target's state
and the initial snapshot, builds the skill's tree in the BuiltinSkillRuntime
(or dispatches to another SkillRuntime), ticks it (checking the cancel token and the
execution deadline between ticks, beating the heartbeat and checkpointing the target
after each), reports that the skill stopped, snapshots the terminal world and writes
the evidence bundle (:meth:`SessionRunner._write_bundle`).

The runner never writes the session file: the supervisor is its single writer and
turns the returned :class:`AttemptReport` into the attempt and the next transition.
Judging the outcome is the SessionVerifier's job, never the controller's.

:meth:`SessionRunner.recover` is the other entry point: after a runner died or was
killed, a fresh runner restores the last checkpoint, halts the target, persists the
halted state and writes a terminal snapshot, so the verifier judges from a fresh
observation and nothing moves before it has.
"""

from __future__ import annotations

import logging
import os
import shutil
import time
import traceback
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from importlib import import_module
from pathlib import Path
from typing import Any, Callable

from phyagentos.errors import PhyAgentOSError, SupervisorError
from phyagentos.primitives.context import CancelToken, SkillContext
from phyagentos.primitives.observation import has_cameras, make_perceiver, perceive_now
from phyagentos.protocol import EnvironmentDoc, SessionRecord, Workspace, dump_yaml, errorcodes
from phyagentos.protocol import utc_now_iso as utc_now  # not .lifecycle: the runner needs no statechart (transitions)
from phyagentos.protocol.atomic import atomic_write_text, file_identity

from .builtin_runtime import BuiltinSkillRuntime, RunOutcome
from .evidence_images import save_scene_image
from .recording import RecordingConfig, SessionRecorder
from .safety_guard import SafetyGuard
from .target_pool import TargetPool
from .tree_status import TreeStatusPublisher

__all__ = ["SessionRunner", "AttemptReport", "write_environment", "write_ground_truth", "SKILL_RUNTIMES",
           "GROUND_TRUTH_FILE"]

#: The privileged channel of a bundle (CONTRACT_9 section 2): simulator truth for
#: benchmark scoring and tests only; not listed in bundle.yaml, never in the trace.
GROUND_TRUTH_FILE = "ground_truth.yaml"



class _SkillRuntimes(Mapping):
    """Skill runtime classes by SKILLRUNTIME.md name, each imported on first lookup: a
    runner of builtin skills never loads the policy client (websockets, asyncio, ssl) or
    the LLM client (issue 12: they are the runner's imports the bare script does not have)."""

    _MODULES = {"policy": (".policy_runtime", "PolicySkillRuntime"), "agent": (".agent_runtime", "AgentSkillRuntime")}

    def __getitem__(self, name: str):
        module, cls = self._MODULES[name]
        return getattr(import_module(module, __package__), cls)

    def __iter__(self):
        return iter(self._MODULES)

    def __len__(self) -> int:
        return len(self._MODULES)


#: Skill runtimes besides the builtin one, by SKILLRUNTIME.md name (built with the skill
#: registry); the class is imported when a session first asks for it.
SKILL_RUNTIMES: Mapping[str, type] = _SkillRuntimes()

logger = logging.getLogger(__name__)

# The session fields that define the task, copied into the evidence bundle (task.yaml).
_TASK_FIELDS = {"session_id", "run_id", "goal_graph", "node", "parent_session_id", "skill", "skill_runtime", "target",
                "parameters", "accept", "limits", "scene", "seed", "context", "recovery"}


def _task_yaml(rec: SessionRecord) -> str:
    """``task.yaml`` of an evidence bundle: the session's task fields as YAML."""
    return dump_yaml(rec.model_dump(mode="json", include=_TASK_FIELDS))


def write_environment(workspace: Workspace, snapshot: dict, *, target: str, session_id: str, evidence: list[str]) -> None:
    """Replace ENVIRONMENT.md's data with ``snapshot`` (a perceived snapshot: entities carry
    their confidence and the frames behind them) and bump its revision."""

    def apply(doc: EnvironmentDoc) -> EnvironmentDoc:
        return EnvironmentDoc(
            version=doc.version,
            revision=doc.revision + 1,
            target=target,
            session_id=session_id,
            captured_at=utc_now(),
            sim_time_s=snapshot.get("sim_time_s", snapshot.get("stamp_s")),
            entities=snapshot.get("entities", []),
            relations=snapshot.get("relations", []),
            evidence=evidence,
        )

    workspace.update("ENVIRONMENT", apply)


def _observe(target, perceiver, evidence_dir, rel: str, tag: str) -> dict:
    """The world as the robot perceives it (cameras + proprioception through the session's
    Perceiver); a target without cameras gives its own observation (``snapshot``)."""
    snap = perceive_now(target, perceiver, evidence_dir=evidence_dir, evidence_rel=rel, tag=tag)
    return snap if snap is not None else target.snapshot()


def _relinked(snapshot: dict, source_rel: str, rel: str, root) -> dict | None:
    """``snapshot`` (the terminal view of the bundle ``source_rel``) as the initial view of
    the bundle ``rel``: its frames (``frames/terminal_*``) hard-linked, else copied, to
    ``frames/initial_*`` here and every reference to them rewritten, ``same_world_as``
    naming the snapshot it repeats; None if its frames are gone (then perceive)."""
    root = Path(root)
    source, here = root / source_rel / "frames", root / rel / "frames"
    frames = sorted(source.glob("terminal_*")) if source.is_dir() else []
    if not frames:
        return None
    here.mkdir(parents=True, exist_ok=True)
    try:
        for src in frames:
            dst = here / ("initial_" + src.name[len("terminal_"):])
            try:
                os.link(src, dst)
            except FileExistsError:
                pass
            except OSError:
                shutil.copyfile(src, dst)
    except OSError:
        return None
    old, new = f"{source_rel}/frames/terminal_", f"{rel}/frames/initial_"

    def walk(x):
        if isinstance(x, dict):
            return {k: walk(v) for k, v in x.items()}
        if isinstance(x, list):
            return [walk(v) for v in x]
        return new + x[len(old):] if isinstance(x, str) and x.startswith(old) else x

    out = walk(snapshot)
    out["same_world_as"] = f"{source_rel}/terminal.yaml"
    return out


def _perception_config(workspace: Workspace):
    return workspace.root / "perception.yaml"


def _truth(target) -> dict | None:
    return target.ground_truth()


def write_ground_truth(directory, target, *, initial: dict | None, terminal: dict | None) -> None:
    """Write ``ground_truth.yaml`` = ``{initial, terminal, scene_record, benchmark}``: the
    simulator's truth at the start and end of the attempt, the physical scene the target
    was built from (``scene_record``: the randomised draw with masses and frictions), and
    the target's own success signals (``benchmark``, e.g. FrankaKitchen's task completions).
    Nothing is written for a target without a ground-truth channel (a real robot)."""
    if initial is None and terminal is None:
        return
    doc = {"initial": initial, "terminal": terminal, "scene_record": target.scene_record(),
           "benchmark": target.benchmark_signals()}
    atomic_write_text(directory / GROUND_TRUTH_FILE, dump_yaml(doc))


@dataclass(frozen=True)
class AttemptReport:
    """What the runner tells the supervisor about one attempt (becomes ``Attempt`` fields).

    Attributes:
        outcome: ``completed``, ``failed``, ``cancelled``, ``timed_out``, ``error`` or
            (from :meth:`SessionRunner.recover`) ``unknown``.
        error_code, message: attribution (docs/ERRORS.md), if any.
        evidence: bundle directory relative to the workspace.
        timings: wall time per category (s).
        ticks: behaviour-tree ticks.
    """

    outcome: str
    error_code: str | None
    message: str
    evidence: str
    timings: dict[str, float]
    ticks: int = 0

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass
class _Preparation:
    """What :meth:`SessionRunner.prepare` set up for the first tick (None: not reached)."""

    evidence_dir: Path
    rel: str  # the evidence directory relative to the workspace
    started: float  # time.perf_counter() when preparing began
    spec: Any = None  # the session's TargetSpec
    target: Any = None
    ctx: SkillContext | None = None
    runtime: Any = None  # the SkillRuntime that ticks the skill
    initial: dict | None = None  # initial snapshot (the perceived view)
    task_text: str | None = None  # task.yaml as written on go
    initial_text: str | None = None  # initial.yaml as written on go
    initial_scene: Any = None  # the initial scene for the background image writer (EvidenceImageWriter.scene)
    initial_truth: dict | None = None  # simulator truth, for ground_truth.yaml only
    perceiver: Any = None
    extra: dict[str, str] = field(default_factory=dict)  # bundle files besides the standard ones
    image_events: list = field(default_factory=list)
    error: tuple[BaseException, str] | None = None  # (exception, formatted traceback)
    duration_s: float = 0.0


@dataclass
class SessionRunner:
    """Runs the runtime phase of one started session (state ``running`` on entry).

    Attributes:
        workspace: the protocol workspace.
        record: the session; its runtime fields (:data:`~.session_basis.RUNTIME_FIELDS`)
            as the supervisor persisted them with ``start``.
        runtime: the BuiltinSkillRuntime that builds and ticks skill trees.
        targets: target pool carrying world state between sessions.
        cancel: cancellation token (set from the supervisor's control messages).
        heartbeat: stamps the shared runner heartbeat: called after every tick, and
            between the steps of setting the session up and of writing its evidence
            (building a target or perceiving the initial scene can take longer than a
            tick: the runner is working, not silent).
        on_finished: called once with the RunOutcome when the skill stops, before the
            evidence is written (the supervisor fires ``finish`` or ``cancel``).
        on_execution_clock: called with the ``time.monotonic()`` value at which this
            session's execution clock starts (``limits.execution_timeout_s`` counts from
            there, after the session was set up); the worker shares it with the
            supervisor, whose own execution deadline counts from the same instant.
        checkpoint_interval_s: the target state is persisted at most this often (s of
            wall time) while the skill runs, and always before the first tick.
    """

    workspace: Workspace
    record: SessionRecord
    runtime: BuiltinSkillRuntime
    targets: TargetPool
    cancel: CancelToken
    heartbeat: Callable[[], None] | None = None
    on_finished: Callable[[RunOutcome], None] | None = None
    on_execution_clock: Callable[[float], None] | None = None
    checkpoint_interval_s: float = 0.25
    #: EvidenceImageWriter (runtime/evidence_writer.py) that renders the images off the
    #: critical path; None renders them here, synchronously.
    images: Any = None
    recorder: SessionRecorder | None = None  # [view hook, issue 13] set by run() under --record
    _prepared: _Preparation | None = field(default=None, init=False, repr=False)

    def _image(self, target, path, events: list, *, scene: Any = None):
        if self.images is not None:
            return self.images.capture(target, path, events=events, scene=scene)
        return save_scene_image(target, path, events=events)

    def _tick(self, target) -> Callable[[], None]:
        last = [time.monotonic()]

        def tick() -> None:
            self._beat()
            if self.recorder is not None:  # [view hook, issue 13]
                self.recorder.tick()
            now = time.monotonic()
            if target is not None and now - last[0] >= self.checkpoint_interval_s:
                self.targets.checkpoint(self.record, target)
                last[0] = time.monotonic()

        return tick

    def _beat(self) -> None:
        if self.heartbeat is not None:
            self.heartbeat()

    def run(self) -> AttemptReport:
        """Execute the session; returns the attempt report (not a verdict).

        Sets the session up (:meth:`prepare`) unless that was done already, then ticks
        the skill. Never raises for a failing skill or target: errors become outcome
        ``error`` with their code, and the evidence bundle is written in every case.
        """
        ahead = self._prepared is not None
        if not ahead:
            self.prepare()
        return self._actuate(ahead=ahead)

    def prepare(self) -> None:
        """Everything before the first tick that commands no motion and writes nothing
        (but a camera target's perception frames of the initial snapshot): the target
        acquired in the state its episode left it (a simulator resets to the run's seed
        at the run's first session), the initial snapshot, the skill context with its
        SafetyGuard. The worker
        calls it right after a passed preflight, while the supervisor makes ``start``
        durable, and :meth:`run` writes ``task.yaml``, the checkpoint and the initial
        snapshot and ticks on ``go`` (writing them here would put their journal commits
        into the supervisor's fsync of ``start``). Called at most once.

        An error while preparing is kept and becomes the attempt's ``error`` outcome when
        :meth:`run` is called, exactly as if it had been raised there.

        Raises:
            SupervisorError: called a second time (a SessionRunner prepares its session once).
        """
        if self._prepared is not None:
            raise SupervisorError(f"session {self.record.session_id}: SessionRunner.prepare called twice; "
                                  "build a new SessionRunner for another attempt")
        clock = time.perf_counter()
        rec = self.record
        evidence_dir = self.workspace.evidence_dir(rec.session_id)
        prep = _Preparation(evidence_dir=evidence_dir, rel=evidence_dir.relative_to(self.workspace.root).as_posix(),
                            started=clock)
        self._prepared = prep
        try:
            prep.task_text = _task_yaml(rec)
            prep.spec = next(t for t in self.workspace.read("TARGETS").data.targets if t.name == rec.target)
            # A session whose TargetToolManifest grants no operation (e.g. skill ``noop``)
            # never opens its target: no snapshots, no images, nothing to halt.
            needs_target = rec.tool_manifest is None or bool(rec.tool_manifest.get("operations"))
            if not needs_target:
                prep.ctx = SkillContext(target=None, params=dict(rec.parameters), seed=rec.seed, cancel=self.cancel,
                                        plan=rec.adapter_plan)
            else:
                target = prep.target = self.targets.acquire(rec, prep.spec)  # may build it: seconds
                self._beat()
                prep.initial_truth = _truth(target)
                if has_cameras(target):
                    prep.perceiver = make_perceiver(target, _perception_config(self.workspace))
                prep.initial = self._initial_view(prep.spec, target, prep.perceiver, evidence_dir, prep.rel)
                self._beat()
                if prep.initial is not None:  # serialised and captured now, written on go
                    prep.initial_text = dump_yaml(prep.initial)
                    if self.images is not None and hasattr(self.images, "scene"):
                        prep.initial_scene = self.images.scene(target)
                prep.ctx = SkillContext(target=target, params=dict(rec.parameters), seed=rec.seed, cancel=self.cancel,
                                        plan=rec.adapter_plan, perceiver=prep.perceiver, evidence_dir=evidence_dir,
                                        evidence_rel=prep.rel)
                # Every command of either flow passes the same guard; its interventions land in ctx.events.
                # (a game target has no arm: nothing for the guard to bound)
                if target.kind != "game":
                    prep.ctx.guard = SafetyGuard.for_target(target, self.workspace.read_safety(),
                                                            events=prep.ctx.events, flow=rec.skill_runtime)
            prep.runtime = self.runtime if rec.skill_runtime == self.runtime.name else \
                SKILL_RUNTIMES[rec.skill_runtime](self.runtime.skills)
        except Exception as exc:  # noqa: BLE001 - becomes the attempt's error outcome in run()
            prep.error = (exc, traceback.format_exc())
        prep.duration_s = time.perf_counter() - clock

    def _write_preparation(self, prep: _Preparation) -> None:
        """What preparing produced, written before the first tick: ``task.yaml``, the
        target's checkpoint and the initial snapshot and image."""
        rec = self.record
        atomic_write_text(prep.evidence_dir / "task.yaml",
                          prep.task_text or _task_yaml(rec))
        prep.extra["task"] = "task.yaml"
        if prep.target is None:
            return
        # Before anything moves: a recovering supervisor restores from here at worst.
        self.targets.checkpoint(rec, prep.target)
        self._beat()
        if prep.initial is not None:
            atomic_write_text(prep.evidence_dir / "initial.yaml", prep.initial_text or dump_yaml(prep.initial))
            if name := self._image(prep.target, prep.evidence_dir / "initial.png", prep.image_events,
                                   scene=prep.initial_scene):
                prep.extra["initial_image"] = name

    def discard(self) -> None:
        """Undo a :meth:`prepare` whose session was not started (no ``go``): its owed
        images are dropped and, for a session without an earlier attempt, its evidence
        directory (which then holds nothing but what preparing wrote) is removed. The
        target stays in the pool as it was (nothing moved it); its kept view is spent,
        so the next session on it observes afresh."""
        prep, self._prepared = self._prepared, None
        if prep is None:
            return
        if self.images is not None and hasattr(self.images, "discard"):
            self.images.discard(prep.evidence_dir)
        if not self.record.attempts:
            shutil.rmtree(prep.evidence_dir, ignore_errors=True)

    @property
    def prepared(self) -> bool:
        """Whether :meth:`prepare` ran (and :meth:`discard` did not undo it)."""
        return self._prepared is not None

    def _actuate(self, *, ahead: bool) -> AttemptReport:
        rec = self.record
        prep = self._prepared
        spec, evidence_dir, rel, started = prep.spec, prep.evidence_dir, prep.rel, prep.started
        target, ctx, initial, initial_truth, perceiver = prep.target, prep.ctx, prep.initial, prep.initial_truth, \
            prep.perceiver
        image_events = prep.image_events
        try:
            self._write_preparation(prep)
            if prep.error is not None:
                raise prep.error[0]
            runtime = prep.runtime
            clock = time.monotonic()
            deadline = clock + rec.limits.execution_timeout_s
            if self.on_execution_clock is not None:
                self.on_execution_clock(clock)
            ctx.on_observation = lambda snap: write_environment(
                self.workspace, snap, target=rec.target, session_id=rec.session_id, evidence=[f"{rel}/trace.jsonl"])
            # The skill's first tick: the SkillRuntime calls ctx.actuation_starts() right before
            # it (after building and setting up its tree). Hand-off latency is measured up to
            # here (bench/end_to_end.py); stamped now too, for a runtime that fails before.
            self._actuation_started_at = utc_now()

            def actuation_starts() -> None:
                self._actuation_started_at = utc_now()

            ctx.on_actuation_start = actuation_starts
            ctx.alive = self._beat  # shared memory stamps only: safe from a runtime's helper thread
            # [view hook, issue 13] live tree.json (<= 10 Hz, no fsync) and, under --record, the video.
            ctx.tree_observer = TreeStatusPublisher(evidence_dir / "tree.json", session_id=rec.session_id,
                                                    sim_clock=lambda: target.sim_time)
            self.recorder = self._start_recorder(target, evidence_dir, image_events, seed=rec.seed)
            outcome = runtime.run(rec.skill, ctx, deadline=deadline, heartbeat=self._tick(target))
        except PhyAgentOSError as exc:
            # an error raised on purpose says what and where (e.g. "sensors.yaml: camera ..."):
            # its message, not a traceback (kept at debug level)
            logger.error("session %s: runtime error: %s", rec.session_id, exc)
            logger.debug("session %s: runtime error", rec.session_id, exc_info=exc)
            outcome = RunOutcome(status="error", error_code=getattr(exc, "code", None) or errorcodes.TARGET_ERROR,
                                 message=str(exc), ticks=0)
        except Exception as exc:  # noqa: BLE001 - a bug must still halt the target and leave evidence
            logger.error("session %s: unexpected runtime error", rec.session_id, exc_info=exc)
            trace = prep.error[1] if prep.error is not None and prep.error[0] is exc else traceback.format_exc()
            outcome = RunOutcome(status="error", error_code=errorcodes.RUNTIME_ERROR,
                                 message=f"{type(exc).__name__}: {exc}\n{trace}", ticks=0)
        self._actuation_ended_at = utc_now()
        # Evidence besides snapshots and trace: the task definition and RGB images.
        # Image events join the session's events. Truth goes to ground_truth.yaml only.
        extra = dict(prep.extra)
        if self.on_finished is not None:
            self.on_finished(outcome)
        self._beat()
        if self.recorder is not None:  # [view hook, issue 13] joins the encoder before the bundle
            extra.update(self.recorder.close(heartbeat=self.heartbeat))
            self.recorder = None
        if (evidence_dir / "tree.json").exists():
            extra["tree"] = "tree.json"
        if (evidence_dir / "tree_history.json").exists():
            extra["tree_history"] = "tree_history.json"
        terminal = None
        if target is not None:
            try:
                terminal = _observe(target, perceiver, evidence_dir, rel, "terminal")
            except Exception as exc:  # noqa: BLE001 - evidence must still be written
                logger.exception("session %s: terminal observation failed", rec.session_id)
                terminal = {"stamp_s": target.sim_time, "sim_time_s": target.sim_time, "entities": [],
                            "relations": [], "error": f"{type(exc).__name__}: {exc}"}
        if target is not None and perceiver is not None and terminal is not None and "error" not in terminal:
            # The next session on this target starts from this world if nothing moves it.
            self.targets.keep_view(rec, spec, target, {"snapshot": terminal, "evidence": rel},
                                   key=self._perception_key())
        if target is not None:
            if name := self._image(target, evidence_dir / "terminal.png", image_events):
                extra["terminal_image"] = name
            write_ground_truth(evidence_dir, target, initial=initial_truth, terminal=_truth(target))
            if ctx is not None:
                ctx.events.extend(image_events)
            if outcome.status in ("cancelled", "timed_out", "error"):
                target.halt()
            self.targets.release(rec, target)
        files = self._write_bundle(evidence_dir, rec, ctx, outcome, initial, terminal, time.perf_counter() - started,
                                   extra_files=extra)
        if terminal is not None:
            write_environment(self.workspace, terminal, target=rec.target, session_id=rec.session_id,
                              evidence=[f"{rel}/{files['terminal']}"])
        logger.info("session %s: runtime %s in %.2f s (%d ticks)", rec.session_id, outcome.status,
                    time.perf_counter() - started, outcome.ticks)
        return AttemptReport(outcome=outcome.status, error_code=outcome.error_code, message=outcome.message,
                             evidence=rel, ticks=outcome.ticks,
                             timings={**(dict(ctx.profiler.totals) if ctx else {}), "set_up": round(prep.duration_s, 6),
                                      "set_up_before_go": round(prep.duration_s if ahead else 0.0, 6)})

    def _perception_key(self) -> tuple | None:
        """What a kept view depends on besides the world: the identity of the workspace's
        perception.yaml (None without one)."""
        return file_identity(_perception_config(self.workspace))

    def _initial_view(self, spec, target, perceiver, evidence_dir, rel: str) -> dict:
        """The initial snapshot: the previous session's terminal one when the target is
        provably in the world it saw (:meth:`TargetPool.take_view`: same run, same live
        target, equal world digest, same perception configuration; a view is used once),
        with its frames linked into this bundle as ``frames/initial_<sensor>.png`` and
        ``same_world_as`` naming the snapshot it repeats; else a fresh observation."""
        view = self.targets.take_view(self.record, spec, target, key=self._perception_key()) \
            if perceiver is not None else None
        snap = _relinked(view["snapshot"], view["evidence"], rel, self.workspace.root) if view else None
        if snap is not None:
            logger.debug("session %s: initial view is %s", self.record.session_id, snap["same_world_as"])
            return snap
        return _observe(target, perceiver, evidence_dir, rel, "initial")

    @staticmethod
    def _start_recorder(target, evidence_dir, events: list, *, seed: int | None) -> SessionRecorder | None:
        """[view hook, issue 13] A recorder when PHYAGENTOS_RECORD asks for one; never fails the session."""
        config = RecordingConfig.from_env()
        if not config.enabled or target is None:
            return None
        try:
            return SessionRecorder(target, evidence_dir, config, seed=seed)
        except PhyAgentOSError as exc:
            logger.warning("no recording of %s: %s", evidence_dir.name, exc)
            events.append({"code": "target.render_unavailable", "message": f"recording: {exc}"})
            return None

    def recover(self, *, status: str, error_code: str, message: str) -> AttemptReport:
        """Put the target of a session whose runner died (or was killed) in a safe state
        and write the evidence a verifier needs; never moves the target.

        Restores the last checkpoint of ``targets/<name>/state.npz`` (written before the
        first tick and periodically while the skill ran), halts the target (the arm
        holds where it is), persists the halted state and writes ``terminal.yaml``
        (plus ``initial.yaml`` if the dead runner never wrote it: nothing had moved
        then), ``events.yaml`` with the recovery event and ``bundle.yaml`` whose
        outcome is ``status`` (``unknown``, ``cancelled`` or ``timed_out``).

        Raises:
            TargetError: the target cannot be rebuilt or its state restored.
        """
        rec = self.record
        spec = next(t for t in self.workspace.read("TARGETS").data.targets if t.name == rec.target)
        evidence_dir = self.workspace.evidence_dir(rec.session_id)
        rel = evidence_dir.relative_to(self.workspace.root).as_posix()
        started = time.perf_counter()
        target = self.targets.acquire(rec, spec)
        target.halt()
        self.targets.checkpoint(rec, target)
        perceiver = make_perceiver(target, _perception_config(self.workspace)) if has_cameras(target) else None
        terminal = _observe(target, perceiver, evidence_dir, rel, "terminal")
        truth_path = evidence_dir / GROUND_TRUTH_FILE
        if not truth_path.exists():
            write_ground_truth(evidence_dir, target, initial=None, terminal=_truth(target))
        initial_path = evidence_dir / "initial.yaml"
        if not initial_path.exists():
            atomic_write_text(initial_path, dump_yaml(terminal))
        ctx = SkillContext(target=target, params=dict(rec.parameters), seed=rec.seed)
        ctx.events.append({"code": error_code, "message": message, "recovered": True,
                           "checkpoint": f"targets/{rec.target}/state.npz"})
        outcome = RunOutcome(status=status, error_code=error_code, message=message, ticks=0)
        extra = {"task": "task.yaml"} if (evidence_dir / "task.yaml").exists() else {}
        files = self._write_bundle(evidence_dir, rec, ctx, outcome, {}, terminal, time.perf_counter() - started,
                                   extra_files=extra)
        write_environment(self.workspace, terminal, target=rec.target, session_id=rec.session_id,
                          evidence=[f"{rel}/{files['terminal']}"])
        logger.warning("session %s: recovered target %s after %s (%s)", rec.session_id, rec.target, error_code, status)
        return AttemptReport(outcome=status, error_code=error_code, message=message, evidence=rel, timings={})

    def _write_bundle(self, directory, rec, ctx, outcome, initial, terminal, wall_s, extra_files=None) -> dict:
        files = {"bundle": "bundle.yaml", "trace": "trace.jsonl", "events": "events.yaml", **(extra_files or {})}
        if initial is not None:
            files["initial"] = "initial.yaml"
        if terminal is not None:
            files["terminal"] = "terminal.yaml"
            atomic_write_text(directory / "terminal.yaml", dump_yaml(terminal))
        events = list(ctx.events) if ctx else []
        atomic_write_text(directory / "events.yaml", dump_yaml(events))
        if ctx is not None:
            ctx.trace.write(directory / "trace.jsonl")
        else:
            (directory / "trace.jsonl").write_text("", encoding="utf-8")
        bundle = {
            "session_id": rec.session_id,
            "node": rec.node,
            "skill": rec.skill,
            "target": rec.target,
            "files": files,
            "outcome": {
                "status": outcome.status,
                "error_code": outcome.error_code,
                "failed_primitive": outcome.failed_primitive,
                "message": outcome.message,
                "ticks": outcome.ticks,
                "wall_time_s": round(wall_s, 4),
                "sim_time_s": terminal.get("sim_time_s") if terminal else None,
                # UTC time the first tick started (everything before it is framework set-up).
                "actuation_started_at": getattr(self, "_actuation_started_at", None),
                "actuation_ended_at": getattr(self, "_actuation_ended_at", None),
            },
            "timings_s": {k: round(v, 4) for k, v in (ctx.profiler.totals.items() if ctx else [])},
        }
        atomic_write_text(directory / "bundle.yaml", dump_yaml(bundle))
        return files
