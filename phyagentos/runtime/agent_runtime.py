"""AgentSkillRuntime: agent-directed tool execution (``runtime: agent``).

The Runtime plane executing a model's chosen operations. Each step it

1. observes through the session's :class:`~phyagentos.runtime.target_handle.TargetSessionHandle`
   (``observe``: joint positions, gripper opening, tool height),
2. asks the language model (:mod:`phyagentos.llm`, plane-neutral; the same model the
   Agent plane uses, from ``llm.yaml``/environment, offline by default) to choose ONE
   operation from the session's TargetToolManifest, under a JSON schema whose variants
   are exactly the granted operations with enumerated arguments (:func:`operation_menu`),
3. invokes it through the handle -- argument checks, the tool manifest and the
   SafetyGuard apply to every command, as in any flow -- and records the step (the
   model call's provider, model, prompt hash, tokens and latency; the operation and its
   result or refusal) in the trace, which is evidence,

until the model chooses ``finish``, ``max_steps`` steps or ``max_duration_s`` of wall
time are spent, the deadline passes or the session is cancelled. A SafetyGuard refusal
ends the session (outcome ``failed`` with the guard's ``safety.*`` code; the handle
halts the target when the guard says so); a refused argument or operation is told to
the model and counts as a step.

Arguments are enumerated, never free numbers: ``set_gripper`` opening 0, 0.02 or 0.04 m;
``hold`` 0.5 or 1.0 s; ``move_joints`` to a named configuration relative to the one the
session started in (``start``; ``wrist_left``/``wrist_right``: the last joint turned
-/+ 0.3 rad). Success is still the SessionVerifier's to judge from the evidence.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from contextlib import contextmanager
from typing import Any, Callable, Iterator, Mapping

import numpy as np

from phyagentos.errors import PhyAgentOSError, SafetyError, SkillError, TargetError
from phyagentos.llm import LLMClient, LLMError, call_record, load_llm_config, make_client

from .builtin_runtime import RunOutcome
from .skills import SkillRegistry
from .target_handle import TargetSessionHandle

__all__ = ["AgentSkillRuntime", "AGENT_OPERATIONS", "operation_menu"]

logger = logging.getLogger(__name__)

#: Operations an agent-directed session asks for at preflight (granted subject to the tool policy).
AGENT_OPERATIONS = ("observe", "move_joints", "set_gripper", "hold")
#: Wrist turn of the named configurations, rad.
WRIST_TURN_RAD = 0.3
_OPENINGS = (0.0, 0.02, 0.04)
_HOLDS = (0.5, 1.0)
_POSES = ("start", "wrist_left", "wrist_right")

_SYSTEM = ("You control a robot arm through operations. Each turn choose ONE operation that brings the goal "
           "closer. Choose finish only when every part of the goal is done. Never repeat an operation that "
           "already succeeded.")

#: How often the runner's heartbeat is stamped while the model is loaded or thinks, s
#: (a tenth of the supervisor's default 10 s heartbeat timeout).
THINKING_BEAT_S = 1.0

_client_cache: dict[str, LLMClient] = {}


@contextmanager
def _beating(alive: Callable[[], None] | None, *, until: float) -> Iterator[None]:
    """Stamp ``alive`` (:attr:`~phyagentos.primitives.context.SkillContext.alive`: the
    runner's heartbeat alone, safe from another thread) every :data:`THINKING_BEAT_S` s from
    a helper thread while the body runs (a model being loaded or choosing the next
    operation: the runner is working, not stuck), never past ``until`` (``time.monotonic()``
    s: the session's deadline or wall budget), so a model call that hangs beyond the
    session's time still goes stale and the WatchdogSupervisor ends the session with
    ``heartbeat.runner``."""
    if alive is None:
        yield
        return
    done = threading.Event()

    def beat() -> None:
        while not done.wait(THINKING_BEAT_S) and time.monotonic() < until:
            alive()

    helper = threading.Thread(target=beat, name="agent-runtime-thinking", daemon=True)
    helper.start()
    try:
        yield
    finally:
        done.set()
        helper.join()


def _default_client() -> LLMClient:
    if "default" not in _client_cache:
        _client_cache["default"] = make_client(load_llm_config())
    return _client_cache["default"]


def operation_menu(granted: tuple[str, ...], *, allow_finish: bool = True,
                   done: frozenset[tuple[str, Any]] = frozenset()) -> dict[str, Any]:
    """JSON schema of one step: an ``anyOf`` over the granted operations (plus ``finish`` when
    ``allow_finish``) with enumerated arguments; ``done`` holds ``(operation, argument value)``
    pairs already carried out, which are not offered again (the loop never repeats itself)."""
    def variant(op: str, arg: str | None = None, values: tuple = ()) -> dict[str, Any] | None:
        props: dict[str, Any] = {"operation": {"enum": [op]}}
        if arg:
            left = [v for v in values if (op, v) not in done]
            if not left:
                return None
            props[arg] = {"enum": left}
        elif (op, None) in done:
            return None
        return {"type": "object", "properties": props, "required": list(props), "additionalProperties": False}

    variants = []
    if "set_gripper" in granted:
        variants.append(variant("set_gripper", "opening_m", _OPENINGS))
    if "hold" in granted:
        variants.append(variant("hold", "duration_s", _HOLDS))
    if "move_joints" in granted:
        variants.append(variant("move_joints", "pose", _POSES))
    if "observe" in granted:
        variants.append(variant("observe"))
    variants = [v for v in variants if v is not None]
    if allow_finish:
        variants.append(variant("finish", None))
    return {"anyOf": variants}


def _record(reply: Any, outcome: str, detail: str) -> dict[str, Any]:
    """The step's :class:`~phyagentos.protocol.ModelCallRecord` as a JSON mapping (trace values are JSON)."""
    return call_record(reply.call, role="agent_runtime", output=reply.text, outcome=outcome,
                       detail=detail).model_dump(mode="json")


class AgentSkillRuntime:
    """Runs skills whose manifests name ``runtime: agent`` (see the module docstring).

    Args:
        skills: the skill manifests.
        client_factory: returns the :class:`~phyagentos.llm.LLMClient` (default: the configured model,
            loaded once per process).
    """

    name = "agent"

    def __init__(self, skills: SkillRegistry, *, client_factory: Callable[[], LLMClient] = _default_client):
        self.skills = skills
        self.client_factory = client_factory

    def run(self, skill: str, ctx: Any, *, deadline: float, heartbeat: Callable[[], None] | None = None) -> RunOutcome:
        """Drive ``ctx.target`` through a TargetSessionHandle until finish, a budget, cancel or a safety stop.

        ``ctx.plan`` is the session's AdapterPlan (its ``agent.operations`` are the granted
        operations); ``ctx.guard`` the session's SafetyGuard. Raises :class:`SkillError` without them.
        """
        plan = ctx.plan or {}
        agent = plan.get("agent") or {}
        if ctx.guard is None or not agent.get("operations"):
            raise SkillError(f"skill {skill!r}: the agent runtime needs the AdapterPlan of preflight and a SafetyGuard")
        params = dict(ctx.params)
        goal = str(params.get("goal", "")).strip()
        max_steps = int(params.get("max_steps", 8))
        max_wall = float(params.get("max_duration_s", 60.0))
        handle = TargetSessionHandle(ctx.target, agent["operations"], guard=ctx.guard, trace=ctx.trace,
                                     heartbeat=heartbeat)
        granted = tuple(op for op in handle.operations if op in AGENT_OPERATIONS)
        done: set[tuple[str, Any]] = set()
        start_q = np.asarray(ctx.target.arm_qpos(), dtype=float)
        try:
            with _beating(getattr(ctx, "alive", None), until=min(deadline, time.monotonic() + max_wall)):
                client = self.client_factory()
        except LLMError as exc:
            return RunOutcome(status="error", error_code="agent.model_unavailable", message=str(exc))
        history: list[str] = []
        started = time.monotonic()
        ctx.actuation_starts()  # the model's first step follows
        for step in range(1, max_steps + 1):
            if ctx.cancel.is_set():
                return RunOutcome(status="cancelled", message="cancelled", ticks=step - 1)
            if time.monotonic() > deadline:
                return RunOutcome(status="timed_out", error_code="timeout.execution", message="deadline passed",
                                  ticks=step - 1)
            if time.monotonic() - started > max_wall:
                return RunOutcome(status="failed", error_code="agent.budget_exhausted",
                                  message=f"max_duration_s {max_wall} s spent without finish", ticks=step - 1)
            state = handle.call("observe") if "observe" in granted else handle.state
            obs = (f"gripper opening {state.get('gripper_opening_m', 0.0):.3f} m, tool height "
                   f"{state.get('tcp', {}).get('position', [0, 0, 0])[2]:.3f} m, "
                   f"wrist {state.get('arm_qpos', [0.0] * 7)[-1] - start_q[-1]:+.2f} rad from start")
            prompt = "\n".join([f"Goal: {goal}", f"Now: {obs}", "Done so far: " + ("; ".join(history) or "nothing"),
                                "Next operation?"])
            try:
                with _beating(getattr(ctx, "alive", None), until=min(deadline, started + max_wall)):
                    reply = client.complete([{"role": "system", "content": _SYSTEM}, {"role": "user", "content": prompt}],
                                            # ``finish`` is offered once something was done: a session never
                                            # ends without acting; nothing already done is offered again.
                                            schema=operation_menu(granted, allow_finish=bool(history),
                                                                  done=frozenset(done)),
                                            max_tokens=40, purpose="act")
            except LLMError as exc:
                ctx.trace.record("agent_step", step=step, ok=False, error=str(exc))
                return RunOutcome(status="failed", error_code="agent.model_error", message=str(exc), ticks=step)
            try:
                choice = reply.json()
            except LLMError as exc:
                ctx.trace.record("agent_step", step=step, ok=False, error=str(exc), call=reply.call.to_dict(),
                                 model_call=_record(reply, "rejected", str(exc)))
                return RunOutcome(status="failed", error_code="agent.model_error", message=str(exc), ticks=step)
            op = choice.get("operation") if isinstance(choice, dict) else None
            # the record the session's context keeps (the coordinator copies it from this trace)
            record = {"step": step, "choice": choice, "call": reply.call.to_dict(),
                      "model_call": _record(reply, "accepted" if op else "rejected",
                                            f"operation {op}" if op else "no operation in the answer")}
            if op == "finish":
                ctx.trace.record("agent_step", ok=True, **record)
                return RunOutcome(status="completed", message=f"finished after {step - 1} operation(s): "
                                                              f"{'; '.join(history) or 'none'}", ticks=step)
            try:
                result = self._invoke(handle, op, choice, start_q)
            except SafetyError as exc:
                ctx.trace.record("agent_step", ok=False, refused_by="safety_guard", code=exc.code, **record)
                return RunOutcome(status="failed", error_code=exc.code, message=str(exc), ticks=step)
            except (TargetError, KeyError, TypeError, ValueError) as exc:
                ctx.trace.record("agent_step", ok=False, refused_by="target_session_handle", error=str(exc), **record)
                history.append(f"{op} refused ({exc})")
                done.add((op, next((v for k, v in choice.items() if k != "operation"), None)))
                continue
            except PhyAgentOSError as exc:
                ctx.trace.record("agent_step", ok=False, error=str(exc), **record)
                return RunOutcome(status="error", error_code=getattr(exc, "code", None) or "agent.error",
                                  message=str(exc), ticks=step)
            ctx.trace.record("agent_step", ok=True, result=result, **record)
            history.append(self._summary(op, choice))
            done.add((op, next((v for k, v in choice.items() if k != "operation"), None)))
        return RunOutcome(status="failed", error_code="agent.budget_exhausted",
                          message=f"{max_steps} steps without finish: {'; '.join(history)}", ticks=max_steps)

    @staticmethod
    def _summary(op: str, choice: Mapping[str, Any]) -> str:
        args = ", ".join(f"{k}={v}" for k, v in choice.items() if k != "operation")
        return f"{op}({args}) ok"

    @staticmethod
    def _invoke(handle: TargetSessionHandle, op: str | None, choice: Mapping[str, Any], start_q: np.ndarray) -> Any:
        if op == "observe":
            state = handle.call("observe")
            return {"gripper_opening_m": state.get("gripper_opening_m")}
        if op == "set_gripper":
            out = handle.call("set_gripper", opening_m=float(choice["opening_m"]))
        elif op == "hold":
            out = handle.call("hold", duration_s=float(choice["duration_s"]))
        elif op == "move_joints":
            q = start_q.copy()
            q[-1] += {"start": 0.0, "wrist_left": -WRIST_TURN_RAD, "wrist_right": WRIST_TURN_RAD}[choice["pose"]]
            now = np.asarray(handle.call("observe")["arm_qpos"], dtype=float)
            if np.max(np.abs(q - now)) < 1e-3:  # nothing to command (a zero-length move is not a trajectory)
                return {"moved": False, "reason": f"already at {choice['pose']}"}
            out = handle.call("move_joints", q=q.tolist(), speed_scale=0.3)
        else:
            raise TargetError(f"unknown operation {op!r}")
        return json.loads(json.dumps(out, default=float))
