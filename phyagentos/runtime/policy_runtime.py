"""PolicySkillRuntime: the observation-inference-action loop of the policy-driven flow.

The policy produces actions; the runtime makes them executable, safe and traceable.
One iteration::

    observe the target (observation contract: instruction, proprioception, objects,
      RGB / depth, history)                              collect_observation
    -> PolicyAdapter.encode -> policy server (openpi websocket, timed)   infer
    -> PolicyAdapter.decode -> action chunk (model rate, model units)
    -> truncate to the replanning boundary (chunk mode)
    -> action bridges (gripper remap, units, joint order, ..., resample to the target rate)
    -> SafetyGuard.check (reject / halt / authorised clamp; events in the evidence)
    -> TargetAdapter.stream, one control period at a time (e-stop and cancel checked
       before every period)

Chunk modes (session parameter ``chunk_mode``):

- ``open_loop``: execute the whole chunk, then ask again;
- ``buffered``: execute the first ``replan_every`` steps, drop the rest, ask again
  (receding horizon: the replanning boundary truncates the chunk);
- ``single_step``: execute one step per inference.

Control-rate reconciliation: the model's steps are at its own rate (e.g. 20 Hz); the
resample bridge turns the executed part of a chunk into the target's control rate
(e.g. 500 Hz), continuing from the last commanded state so chunk boundaries are smooth.

Health: before each inference the runtime pings the policy server (heartbeat); each
inference is bounded by ``inference_timeout_s``. A stalled or disconnected policy ends
the session with ``policy.stalled`` / ``policy.disconnected``; a guard or bridge
rejection with its ``safety.*`` code. In every such case the arm is halted first.
The rollout ends when the policy reports ``done`` (an optional key of the action map)
or after ``max_duration_s`` of target time; success is the SessionVerifier's call.
"""

from __future__ import annotations

import inspect
import logging
import math
import time
from collections import deque
from dataclasses import dataclass
from typing import Any, Callable, Mapping

import numpy as np

from phyagentos.errors import ActionBridgeError, PhyAgentOSError, PolicyError, SkillError, format_choices
from phyagentos.policy.adapter import ADAPTERS, PolicyAdapter
from phyagentos.policy.client import PolicyClient
from phyagentos.policy.observation import HistoryEntry, ObjectObservation, Observation, eef_state
from phyagentos.primitives.context import SkillContext
from phyagentos.targets.contract import OscControlled, capabilities_of

from .bridges import ActionChunk, ActionSpec, BridgeChain, ReferenceState
from .builtin_runtime import RunOutcome
from .safety_guard import SafetyGuard
from .skills import SkillRegistry
from .target_adapters import TARGET_ADAPTERS

__all__ = ["CHUNK_MODES", "PolicySettings", "PolicySkillRuntime", "collect_observation", "Observation"]

logger = logging.getLogger(__name__)

CHUNK_MODES = ("open_loop", "buffered", "single_step")
#: The action form of OSC_POSE delta chunks (:class:`~.target_adapters.LiberoOscAdapter`).
OSC_FORM = "osc_pose_delta_chunk"


@dataclass(frozen=True)
class PolicySettings:
    """How a policy session runs (SKILLRUNTIME.md ``policy`` parameters, overridden by
    the session's parameters of the same name).

    Attributes:
        endpoint: ``ws://host:port`` of the policy server.
        chunk_mode: one of :data:`CHUNK_MODES`.
        replan_every: model steps executed per chunk in ``buffered`` mode (>= 1).
        inference_timeout_s: longest wait for one inference before ``policy.stalled``, s.
        heartbeat_timeout_s: longest wait for a pong before ``policy.stalled``, s.
        open_timeout_s: handshake + metadata bound, s.
        max_duration_s: target-time budget of the rollout, s.
        history: observation history length (steps).
        halt_settle_s: target time the halted arm is held so it comes to rest, s.
        max_steps: the episode's step budget in the target's control steps since its reset
            (LIBERO: env steps after the settle steps; every session of the episode, a
            retry included, draws on what is left); ``None``: no step budget.
        max_steps_by_suite: the budget by the target's benchmark suite (``query_state()``'s
            ``suite``), e.g. openpi's LIBERO example: 220 / 280 / 300 / 520 for
            libero_spatial / libero_object / libero_goal / libero_10; used when
            ``max_steps`` is not set.
        preset: the SKILLRUNTIME.md preset these settings came from (recorded only).
    """

    endpoint: str
    chunk_mode: str = "buffered"
    replan_every: int = 5
    inference_timeout_s: float = 5.0
    heartbeat_timeout_s: float = 1.0
    open_timeout_s: float = 2.0
    max_duration_s: float = 30.0
    history: int = 8
    halt_settle_s: float = 0.3
    max_steps: int | None = None
    max_steps_by_suite: Mapping[str, int] | None = None
    preset: str | None = None

    @classmethod
    def resolve(cls, runtime_params: Mapping[str, Any], session_params: Mapping[str, Any],
                declared_endpoint: str | None, presets: Mapping[str, Mapping[str, Any]] | None = None) -> "PolicySettings":
        """Merge runtime defaults, the preset the session names (``policy_preset``, one of
        SKILLRUNTIME.md's ``presets``), the skill's endpoint and session overrides, in that order.

        Raises:
            ValueError: an unknown preset or chunk mode, or a non-positive number (message names it).
        """
        known = set(cls.__dataclass_fields__) - {"endpoint", "preset"}
        merged: dict[str, Any] = {k: v for k, v in runtime_params.items() if k in known}
        name = session_params.get("policy_preset")
        preset: Mapping[str, Any] = {}
        if name is not None:
            if name not in (presets or {}):
                raise ValueError(f"policy_preset {name!r} is not one of SKILLRUNTIME.md's presets: "
                                 f"{format_choices(presets or {})}")
            preset = (presets or {})[name]
            merged.update({k: v for k, v in (preset.get("parameters") or {}).items() if k in known})
            merged["preset"] = str(name)
        merged.update({k: v for k, v in session_params.items() if k in known})
        endpoint = (session_params.get("policy_endpoint") or declared_endpoint or preset.get("endpoint")
                    or runtime_params.get("endpoint"))
        if not endpoint:
            raise ValueError("no policy endpoint: set the session parameter policy_endpoint or policy.endpoint in the skill")
        s = cls(endpoint=str(endpoint), **merged)
        if s.chunk_mode not in CHUNK_MODES:
            raise ValueError(f"chunk_mode {s.chunk_mode!r} is not one of {format_choices(CHUNK_MODES)}")
        for name in ("replan_every", "inference_timeout_s", "heartbeat_timeout_s", "open_timeout_s", "max_duration_s", "history"):
            v = getattr(s, name)
            if not isinstance(v, (int, float)) or isinstance(v, bool) or not v > 0 or not math.isfinite(v):
                raise ValueError(f"{name} must be a number > 0, got {v!r}")
        budgets = {"max_steps": s.max_steps} if s.max_steps is not None else {}
        if s.max_steps_by_suite is not None:
            if not isinstance(s.max_steps_by_suite, Mapping):
                raise ValueError(f"max_steps_by_suite must map suite names to step counts, got {s.max_steps_by_suite!r}")
            budgets.update({f"max_steps_by_suite.{k}": v for k, v in s.max_steps_by_suite.items()})
        for name, v in budgets.items():
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise ValueError(f"{name} must be an integer >= 1 (control steps), got {v!r}")
        return s

    def step_budget(self, suite: str | None) -> int | None:
        """The episode's budget in control steps for a target on ``suite`` (``None``: none).

        Raises:
            ValueError: ``max_steps_by_suite`` is set, ``max_steps`` is not, and the suite
                is not in it (the known suites named).
        """
        if self.max_steps is not None:
            return int(self.max_steps)
        if self.max_steps_by_suite is None:
            return None
        if suite not in self.max_steps_by_suite:
            raise ValueError(f"no step budget for suite {suite!r}; max_steps_by_suite has "
                             f"{format_choices(self.max_steps_by_suite)} (set max_steps)")
        return int(self.max_steps_by_suite[suite])

    def steps_per_chunk(self, horizon: int) -> int:
        """Model steps executed from a chunk of ``horizon`` before asking again."""
        return {"open_loop": horizon, "buffered": min(self.replan_every, horizon), "single_step": 1}[self.chunk_mode]


def collect_observation(target: Any, *, instruction: str, focus: str | None,
                        cameras: Mapping[tuple[str, str], tuple[int, int]], history: deque,
                        sizes: Mapping[str, Any], eef: bool = False) -> Observation:
    """The observation contract from a target (``observe()``, ``render()``).

    Args:
        cameras: ``(source, camera)`` (source ``rgb`` / ``depth``) -> ``(height, width)`` to render.
        history: recent :class:`HistoryEntry` items (oldest first), copied in.
        sizes: object name -> half extents (3,) m.
        eef: also read the end-effector state (``target.osc_proprio()``, see
            :func:`~phyagentos.policy.observation.eef_state`); a target that is not
            :class:`~phyagentos.targets.contract.OscControlled` leaves it ``None``.
    """
    o = target.observe()
    objects = {name: ObjectObservation(pose=np.asarray(T), half_extents=np.asarray(sizes.get(name, (0.0, 0.0, 0.0))))
               for name, T in o.get("objects", {}).items()}
    images: dict[tuple[str, str], np.ndarray] = {}
    has_depth = capabilities_of(target).has_sensor("depth")
    for (source, cam), (h, w) in cameras.items():
        if source == "rgb":
            # Policy frames skip shadows where the target can (about 4x cheaper under OSMesa).
            extra = {"shadows": False} if "shadows" in inspect.signature(target.render).parameters else {}
            images[(source, cam)] = target.render(camera=cam, width=w, height=h, **extra)
        elif source == "depth" and has_depth:
            images[(source, cam)] = target.render_depth(camera=cam, width=w, height=h)
    rgb = next((v for (src, _), v in images.items() if src == "rgb"), None)
    depth = next((v for (src, _), v in images.items() if src == "depth"), None)
    state = None
    if eef and isinstance(target, OscControlled):
        state = eef_state(target.osc_proprio())
    return Observation(instruction=instruction, time_s=float(o["time"]), joint_positions=np.asarray(o["arm_qpos"]),
                       joint_velocities=np.asarray(o["arm_qvel"]), gripper_opening_m=float(o["gripper_opening_m"]),
                       objects=objects, focus=focus, rgb=rgb, depth=depth, history=tuple(history), images=images,
                       eef_state=state)


class PolicySkillRuntime:
    """Runs skills whose manifests name ``runtime: policy`` (see the module docstring).

    Args:
        skills: the skill manifests.
        client_factory: opens a :class:`PolicyClient` (``uri, open_timeout_s``).
    """

    name = "policy"

    def __init__(self, skills: SkillRegistry, *, client_factory: Callable[..., PolicyClient] = PolicyClient):
        self.skills = skills
        self.client_factory = client_factory

    def run(self, skill: str, ctx: SkillContext, *, deadline: float,
            heartbeat: Callable[[], None] | None = None) -> RunOutcome:
        """Roll the policy out on ``ctx.target`` until done, the budget, cancel or an error.

        ``ctx.plan`` is the session's AdapterPlan (as a dict) from preflight and
        ``ctx.guard`` the session's SafetyGuard.
        """
        plan = ctx.plan or {}
        pol = plan.get("policy") or {}
        if ctx.guard is None or not pol:
            raise SkillError(f"skill {skill!r}: the policy runtime needs the AdapterPlan of preflight and a SafetyGuard")
        settings = PolicySettings(**pol["settings"])
        adapter_cls = ADAPTERS[plan["policy_adapter"]]
        adapter: PolicyAdapter = adapter_cls.from_declaration(pol["inputs"], max_opening_m=pol.get("max_opening_m") or 0.04)
        policy_spec = ActionSpec.from_dict(pol["action"], where="adapter_plan.policy.action")
        target_spec = ActionSpec.from_dict(plan["target_action"], where="adapter_plan.target_action")
        chain = BridgeChain.from_declarations(plan["action_bridges"])
        mismatch = chain.check(policy_spec, target_spec)
        if mismatch:  # preflight passed this plan; a mismatch now means it was edited
            raise SkillError(f"adapter plan no longer type-checks: {'; '.join(map(str, mismatch))}")
        target_adapter = TARGET_ADAPTERS[plan["target_adapter"]](ctx.target)
        return _Rollout(ctx, settings, adapter, policy_spec, chain, target_adapter, pol, self.client_factory,
                        deadline, heartbeat, osc=plan.get("action_form") == OSC_FORM).run()


class _Rollout:
    """One session's loop; kept apart so the runtime itself holds no session state."""

    def __init__(self, ctx, settings, adapter, policy_spec, chain, target_adapter, pol, client_factory, deadline, heartbeat,
                 *, osc: bool = False):
        self.ctx, self.s, self.adapter, self.spec, self.chain = ctx, settings, adapter, policy_spec, chain
        self.osc = osc
        self.tadapter, self.pol, self.client_factory = target_adapter, pol, client_factory
        self.deadline, self.heartbeat = deadline, heartbeat
        self.guard: SafetyGuard = ctx.guard
        self.history: deque = deque(maxlen=settings.history)
        #: the episode's step budget in control steps (``None``: none), once :meth:`run` knows it
        self.step_budget: int | None = None
        self.steps_run = 0

    def run(self) -> RunOutcome:
        ctx, s = self.ctx, self.s
        target = ctx.target
        params = dict(ctx.params)
        instruction = str(self.pol.get("instruction", "")).format(**params)
        focus = params.get("object")
        sizes = {e["name"]: e.get("size") for e in target.snapshot()["entities"] if e.get("kind") == "object"}
        self.guard.sync(target.arm_qpos())
        gripper_cmd = float(target.gripper_opening())
        t_start = float(target.sim_time)
        inferences = 0
        client = None
        budget = self.step_budget = self._budget()
        self.steps_run = 0
        output_max_m = float(target.osc_limits()["output_max"][0]) if self.osc else 0.0
        try:
            with ctx.profiler.section("policy_connect"):
                client = self.client_factory(s.endpoint, open_timeout_s=s.open_timeout_s)
            ctx.trace.record("policy_connect", endpoint=s.endpoint, handshake_s=round(client.handshake_s, 6),
                             policy=str(client.metadata.get("policy", "")), chunk_mode=s.chunk_mode)
            ctx.actuation_starts()  # connected: the first inference follows
            while True:
                if ctx.cancel.is_set():
                    return self._end("cancelled", "cancelled.operator", ctx.cancel.reason or "cancel requested", inferences)
                if time.monotonic() > self.deadline:
                    return self._end("timed_out", "timeout.execution", "execution timeout exceeded", inferences)
                if self.guard.estop_engaged():
                    self.tadapter.halt(settle_s=s.halt_settle_s)
                    return self._end("failed", "safety.estop", f"e-stop engaged: {self.guard.estop.reason}", inferences)
                if float(target.sim_time) - t_start >= s.max_duration_s:
                    return self._end("completed", None, f"policy ran its budget of {s.max_duration_s} s", inferences)
                left = None
                if budget is not None:
                    since_reset = self._control_steps_since_reset()
                    used = since_reset if since_reset is not None else self.steps_run
                    left = budget - used
                    if left <= 0:
                        return self._end("completed", None, f"step budget spent: {used} of {budget} control steps since "
                                                            "the target's reset", inferences)
                with ctx.profiler.section("policy_heartbeat"):
                    client.heartbeat(timeout_s=s.heartbeat_timeout_s)
                with ctx.profiler.section("observe"):
                    obs = collect_observation(target, instruction=instruction, focus=focus, cameras=self.adapter.cameras(),
                                              history=self.history, sizes=sizes, eef=self.adapter.needs_eef_state())
                    inputs = self.adapter.encode(obs)
                with ctx.profiler.section("policy_inference"):
                    response = client.infer(inputs, timeout_s=s.inference_timeout_s)
                inferences += 1
                raw = self.adapter.decode(response)
                k = s.steps_per_chunk(raw.shape[0])
                if left is not None:
                    k = min(k, left)  # the step budget ends inside this chunk
                executed = raw[:k]
                q_ref, qd_ref = self.guard.reference
                with ctx.profiler.section("bridges"):
                    # The whole chunk goes through the bridges (the resampling spline sees the
                    # model's full intent); the replanning boundary truncates the result.
                    full = self.chain.apply(ActionChunk(raw, self.spec.rate_hz),
                                            ReferenceState(q=q_ref, qd=qd_ref, gripper=gripper_cmd))
                    n_exec = max(1, int(round(k * full.rate_hz / self.spec.rate_hz)))
                    chunk = ActionChunk(full.values[:n_exec], full.rate_hz)
                with ctx.profiler.section("safety_guard"):
                    if self.osc:
                        start = (target.osc_proprio()["eef_pos"] if obs.eef_state is None else obs.eef_state[:3])
                        decision = self.guard.check_osc_deltas(chunk.values, dt=chunk.dt, eef_position=start,
                                                               output_max_m=output_max_m, source=f"policy chunk {inferences}")
                    else:
                        decision = self.guard.check(chunk.values, dt=chunk.dt, source=f"policy chunk {inferences}")
                phase = response.get("phase")
                ctx.trace.record("policy_chunk", n=inferences, t_target_s=round(obs.time_s, 4),
                                 latency_ms=round(client.latencies_s[-1] * 1e3, 3), horizon=int(raw.shape[0]), executed=k,
                                 target_steps=int(chunk.values.shape[0]) if chunk.values.ndim == 2 else 0,
                                 phase=str(phase) if phase is not None else None, guard=decision.outcome)
                if not decision.admitted:
                    self.tadapter.halt(settle_s=s.halt_settle_s)
                    self.guard.sync(target.arm_qpos())
                    return self._end("failed", decision.code, f"SafetyGuard {decision.outcome}: {decision.message}", inferences)
                actions = decision.actions
                with ctx.profiler.section("simulation"):
                    result = self.tadapter.stream(actions, dt=chunk.dt, q_ref=q_ref, estop=self.guard.estop, cancel=ctx.cancel)
                self.steps_run += int(round(result.steps * self.spec.rate_hz / full.rate_hz))
                if result.stopped:
                    self._commit(actions[: max(result.steps, 1)], chunk.dt)
                    if result.stopped == "estop":
                        self.guard.estop_engaged()
                        self.tadapter.halt(settle_s=s.halt_settle_s)
                        return self._end("failed", "safety.estop", f"e-stop engaged: {self.guard.estop.reason}", inferences)
                    self.tadapter.halt(settle_s=s.halt_settle_s)
                    return self._end("cancelled", "cancelled.operator", ctx.cancel.reason or "cancel requested", inferences)
                self._commit(actions, chunk.dt)
                gripper_cmd = float(actions[-1, -1]) if actions.shape[1] == 8 else gripper_cmd
                self.history.append(HistoryEntry(time_s=obs.time_s, joint_positions=obs.joint_positions,
                                                 action=np.asarray(executed[-1], dtype=float)))
                if self.heartbeat is not None:
                    self.heartbeat()
                if bool(response.get("done", False)):
                    if not self.osc:  # LIBERO's controller holds by itself; holding would spend budget
                        target.hold(duration_s=s.halt_settle_s)
                    return self._end("completed", None, f"policy reported done after {inferences} inference(s)", inferences)
        except PolicyError as exc:
            self._halt_after_error(exc.code, str(exc), layer="policy_monitor")
            return self._end("error", exc.code, str(exc), inferences)
        except ActionBridgeError as exc:
            self._halt_after_error(exc.code, str(exc), layer=f"action_bridge:{exc.bridge}")
            return self._end("failed", exc.code, str(exc), inferences)
        except PhyAgentOSError as exc:
            self._halt_after_error("target.error", str(exc), layer="target")
            return self._end("error", "target.error", str(exc), inferences)
        finally:
            if client is not None:
                lat = np.array(client.latencies_s) * 1e3
                ctx.trace.record("policy_end", inferences=len(lat),
                                 latency_ms_p50=round(float(np.percentile(lat, 50)), 3) if len(lat) else None,
                                 latency_ms_p99=round(float(np.percentile(lat, 99)), 3) if len(lat) else None,
                                 latency_ms_max=round(float(lat.max()), 3) if len(lat) else None,
                                 heartbeat_rtt_ms_max=round(max(client.ping_rtts_s) * 1e3, 3) if client.ping_rtts_s else None)
                client.close()

    def _commit(self, actions: np.ndarray, dt: float) -> None:
        """Move the guard's reference past what was sent (OSC: to the measured joints)."""
        if self.osc:
            self.guard.sync(self.ctx.target.arm_qpos())
        else:
            self.guard.commit(actions, dt=dt)

    def _budget(self) -> int | None:
        """The episode's step budget (:meth:`PolicySettings.step_budget`) for this target."""
        if self.s.max_steps is None and self.s.max_steps_by_suite is None:
            return None
        suite = self.ctx.target.query_state().get("suite")
        try:
            return self.s.step_budget(suite)
        except ValueError as exc:
            raise SkillError(str(exc)) from None

    def _control_steps_since_reset(self) -> int | None:
        """Control steps (at the policy's rate) the target has run since its reset, from its
        ``observe()['env_steps']`` (physics steps); ``None`` when it does not count them (the
        budget then counts this session's steps only)."""
        target = self.ctx.target
        env_steps = target.observe().get("env_steps")
        if env_steps is None:
            return None
        return int(round(int(env_steps) * float(target.timestep) * self.spec.rate_hz))

    def _halt_after_error(self, code: str, message: str, *, layer: str) -> None:
        """Halt the arm and record the intervention (safety codes are what the verifier counts)."""
        ctx = self.ctx
        try:
            self.tadapter.halt(settle_s=self.s.halt_settle_s)
            self.guard.sync(ctx.target.arm_qpos())
        except PhyAgentOSError:
            logger.exception("halting after %s failed", code)
        ctx.events.append({"code": code, "check": code.split(".", 1)[-1], "outcome": "halt", "layer": layer,
                           "flow": "policy", "message": message,
                           "target_time_s": round(float(ctx.target.sim_time), 6)})
        logger.warning("policy session halted: %s: %s", code, message)

    def _end(self, status: str, code: str | None, message: str, inferences: int) -> RunOutcome:
        """Record the end (``runtime_end``; with a step budget also ``control_steps``, the
        target's control steps since its reset, and ``step_budget``, so that the Agent sees
        what is left of the episode) and return the outcome."""
        if status == "failed" and code is not None:
            self.ctx.fail(code, "policy", message)
        budget: dict[str, int] = {}
        if self.step_budget is not None:
            try:
                since_reset = self._control_steps_since_reset()
            except PhyAgentOSError:  # a target that failed cannot say; this session's own count stands in
                since_reset = None
            budget = {"control_steps": since_reset if since_reset is not None else self.steps_run,
                      "step_budget": int(self.step_budget)}
        self.ctx.trace.record("runtime_end", status=status, ticks=inferences, message=message, **budget)
        return RunOutcome(status=status, error_code=code, failed_primitive="policy" if status == "failed" else None,
                          message=message, ticks=inferences)
