"""Model-backed diagnosis and revision, behind the same interface as the rule ladder.

:class:`Reviser` is the seam :class:`~phyagentos.agent.verifier.SessionVerifier` already
calls (``recovery.plan(session, diagnosis, history=...) -> Revision | None``); the rule
ladder (:class:`~phyagentos.agent.recovery.RecoveryPlanner`) is one implementation,
:class:`ModelReviser` another. The model sees the evidence summary (the diagnosed cause,
its summary and measured facts, the failed attempt's parameters and the earlier
revisions along the lineage) and answers a typed revision under a JSON schema:

* ``adjust``: one strategy parameter of the skill set to one of the values of its
  declared range (:data:`REVISION_SPACE`; only parameters the skill declares), or
* ``give_up`` with a reason (a safety stop, a software error, nothing left to try).

The proposal is checked (parameter declared by the skill, value in range, a real
change); a rejected or failed proposal falls back to the rule ladder, and the record
says so. The strategy name carries the proposer -- ``model:<parameter>`` or the ladder's
own name -- so lessons (which key on the strategy and record whether a later verdict
confirmed it) say which reviser proposed what. The model call (provider, model, prompt
hash, tokens, latency) is written into the revision's ``rationale``, which the child
session keeps as its ``recovery``.

Not implemented (the Revision record carries parameters and limits only): inserting a
corrective node upstream, or switching skill or target.
"""

from __future__ import annotations

import json
import logging
from typing import Any, Mapping, Protocol, Sequence

from phyagentos.llm import LLMCall, LLMClient, LLMError
from phyagentos.protocol import Diagnosis, Revision, SessionRecord

from .recovery import SITUATIONAL, RecoveryPlanner
from .skill_catalog import SkillInfo, skill_catalog

__all__ = ["Reviser", "ModelReviser", "REVISION_SPACE", "DEFAULTS", "NEVER_RETRY"]

logger = logging.getLogger(__name__)

#: Declared ranges of the strategy parameters a reviser may set (values offered to the model).
#: Grip force per finger, N: the Franka Hand allows 70 N continuous (Franka Emika datasheet).
#: Velocity scales are fractions of the joint limits (trees/*.yaml). Planners: OMPL planners
#: the runtime offers (phyagentos.motion.planner.PLANNERS). Frame counts: perception averaging.
REVISION_SPACE: Mapping[str, tuple[Any, ...]] = {
    "observe_samples": (1, 4, 8, 16, 32),
    "reobserve_samples": (1, 4, 8, 16),
    "grasp_candidate": (0, 1, 2, 3),
    "grip_force_n": (10.0, 20.0, 40.0, 70.0),
    "transfer_velocity_scale": (0.25, 0.5, 0.75, 1.0),
    "lift_velocity_scale": (0.1, 0.15, 0.3),
    "lower_velocity_scale": (0.1, 0.2, 0.3),
    "approach_velocity_scale": (0.1, 0.2, 0.3),
    "approach_height_m": (0.08, 0.10, 0.15),
    "planner": ("RRTConnect", "BITstar", "PRM"),
}
#: The skills' defaults of those parameters (skills/*.yaml descriptions; ``grip_force_n`` null =
#: about 10 N on a 4 cm box): proposing the default of an unset parameter changes nothing.
DEFAULTS: Mapping[str, Any] = {
    "observe_samples": 1, "reobserve_samples": 0, "grasp_candidate": 0, "grip_force_n": 10.0,
    "transfer_velocity_scale": 1.0, "lift_velocity_scale": 0.3, "lower_velocity_scale": 0.3,
    "approach_velocity_scale": 0.3, "approach_height_m": 0.10, "planner": "RRTConnect",
}
#: Causes no reviser retries: a safety stop is never retried automatically; a software
#: error or a missing upstream result is not fixed by a parameter (as the rule ladder).
NEVER_RETRY = frozenset({"safety_intervention", "runtime_error", "precondition_unmet"})

_SYSTEM = (
    "You repair failed robot skill attempts. Given why the attempt failed and its parameters, choose ONE "
    "parameter change that addresses the cause, or give up. Examples: object slipped -> stronger grip_force_n; "
    "grasp missed or perception error -> more observe_samples or reobserve_samples; collision -> lower "
    "transfer_velocity_scale or another planner; no path -> another planner; unreachable -> another grasp_candidate."
)


class Reviser(Protocol):
    """What the SessionVerifier calls for the revision of a ``replan`` verdict."""

    def plan(self, session: SessionRecord, diagnosis: Diagnosis, *,
             history: Sequence[SessionRecord] = ()) -> Revision | None:
        """The revision for ``session``'s child, or ``None`` (the verdict becomes ``failure``)."""
        ...


def _call_text(call: LLMCall) -> str:
    return (f"{call.provider} {call.model}, prompt {call.prompt_sha256}, {call.prompt_tokens}+{call.completion_tokens} "
            f"tokens, {call.latency_s:.2f} s")


class ModelReviser:
    """Revisions proposed by a language model, checked, with the rule ladder as fallback.

    Args:
        client: the model.
        fallback: the rule ladder used when the model's proposal is rejected or the call
            fails (``None``: no fallback, the verdict becomes ``failure``).
        skills: skill catalog (default: the shipped manifests).
    """

    def __init__(self, client: LLMClient, *, fallback: RecoveryPlanner | None = None,
                 skills: Mapping[str, SkillInfo] | None = None):
        self.client = client
        self.fallback = fallback
        self._skills = skills
        self.calls: list[LLMCall] = []
        self.proposals: list[dict[str, Any]] = []

    @property
    def skills(self) -> Mapping[str, SkillInfo]:
        if self._skills is None:
            self._skills = skill_catalog()
        return self._skills

    def schema(self, allowed: Sequence[str], *, may_give_up: bool = True,
               current: Mapping[str, Any] | None = None) -> dict[str, Any]:
        """The typed revision: ``adjust`` one allowed parameter to a value of its range other than its
        current (or default) value, or (when ``may_give_up``) ``give_up`` with a reason."""
        variants: list[dict[str, Any]] = []
        current = current or {}
        for p in allowed:
            values = [v for v in REVISION_SPACE[p] if v != current.get(p, DEFAULTS.get(p))]
            if not values:
                continue
            variants.append({
                "type": "object",
                "properties": {"action": {"enum": ["adjust"]}, "parameter": {"enum": [p]},
                               "value": {"enum": values}, "reason": {"enum": ["addresses_cause"]}},
                "required": ["action", "parameter", "value", "reason"], "additionalProperties": False})
        if may_give_up or not variants:
            variants.append({
                "type": "object",
                "properties": {"action": {"enum": ["give_up"]}, "parameter": {"enum": ["none"]},
                               "value": {"enum": ["none"]},
                               "reason": {"enum": ["safety_stop", "software_error", "nothing_left"]}},
                "required": ["action", "parameter", "value", "reason"], "additionalProperties": False})
        return {"anyOf": variants}

    def plan(self, session: SessionRecord, diagnosis: Diagnosis, *,
             history: Sequence[SessionRecord] = ()) -> Revision | None:
        """See :class:`Reviser`. Never raises for a bad model answer: it falls back (and records why)."""
        if diagnosis.cause in NEVER_RETRY:
            self.proposals.append({"session": session.session_id, "cause": diagnosis.cause, "proposed_by": "policy",
                                   "revision": None})
            return None
        info = self.skills.get(session.skill)
        allowed = sorted(p for p in REVISION_SPACE if info is not None and p in info.optional)
        current = dict(session.parameters)
        earlier = [r.recovery for r in [*history, session] if r.recovery is not None]
        facts = ", ".join(f"{k}={v}" for k, v in diagnosis.facts.items() if not isinstance(v, (dict, list)))
        lines = [f"Skill: {session.skill} on {session.target}, object {current.get('object', '?')}",
                 f"Failure: {diagnosis.cause} ({diagnosis.category}): {diagnosis.summary}",
                 f"Measured: {facts or 'nothing'}",
                 "Current parameters: " + (", ".join(f"{p}={current[p]}" for p in allowed if p in current)
                                           or "all defaults"),
                 "Already tried: " + ("; ".join(f"{r.strategy} {r.parameters}" for r in earlier) or "nothing"),
                 "Parameters you may change: " + ", ".join(f"{p} {list(REVISION_SPACE[p])}" for p in allowed)]
        messages = [{"role": "system", "content": _SYSTEM}, {"role": "user", "content": "\n".join(lines)}]
        record: dict[str, Any] = {"session": session.session_id, "cause": diagnosis.cause}
        try:
            # A retryable cause is retried at least once: giving up is offered from the second replan on.
            schema = self.schema(allowed, may_give_up=bool(earlier), current=current)
            reply = self.client.complete(messages, schema=schema, max_tokens=60, purpose="revise")
            self.calls.append(reply.call)
            record["call"] = reply.call.to_dict()
            record["output"] = reply.text
            proposal = reply.json()
            revision = self._check(proposal, session, diagnosis, current, allowed, history, reply.call)
        except (LLMError, ValueError) as exc:
            record["rejected"] = str(exc)
            logger.info("model revision for %s rejected: %s", session.session_id, exc)
            revision = None
            if self.fallback is not None:
                revision = self.fallback.plan(session, diagnosis, history=history)
                if revision is not None:
                    revision = revision.model_copy(update={
                        "rationale": f"{revision.rationale} [rule ladder; model proposal rejected: {exc}]"})
            record["proposed_by"] = "rules" if revision is not None else "none"
        else:
            record["proposed_by"] = "model" if revision is not None else "model:give_up"
        record["revision"] = revision.model_dump(mode="json") if revision is not None else None
        self.proposals.append(record)
        return revision

    def _check(self, proposal: Any, session: SessionRecord, diagnosis: Diagnosis, current: Mapping[str, Any],
               allowed: Sequence[str], history: Sequence[SessionRecord], call: LLMCall) -> Revision | None:
        if not isinstance(proposal, dict) or proposal.get("action") not in ("adjust", "give_up"):
            raise ValueError(f"not a typed revision: {proposal!r}")
        if proposal["action"] == "give_up":
            logger.info("model gives up on %s: %s", session.session_id, proposal.get("reason"))
            return None
        param, value = proposal.get("parameter"), proposal.get("value")
        if param not in allowed:
            raise ValueError(f"parameter {param!r} is not a strategy parameter of {session.skill}; allowed: {allowed}")
        if value not in REVISION_SPACE[param]:
            raise ValueError(f"{param}={value!r} is outside its declared range {list(REVISION_SPACE[param])}")
        if current.get(param, DEFAULTS.get(param)) == value:
            raise ValueError(f"{param} is already {value!r}: the revision changes nothing")
        values = {param: value}
        if float(diagnosis.facts.get("tcp_end_z_m", 1.0)) < 0.15:  # same situational back-off as the ladder
            info = self.skills.get(session.skill)
            values.update({k: v for k, v in SITUATIONAL.items()
                           if info is not None and k in info.optional and current.get(k) != v})
        step = 1 + sum(1 for r in history if r.attempts and r.attempts[-1].verdict is not None
                       and r.attempts[-1].verdict.diagnosis is not None
                       and r.attempts[-1].verdict.diagnosis.cause == diagnosis.cause)
        return Revision(strategy=f"model:{param}", cause=diagnosis.cause, step=step, parameters=values,
                        rationale=f"{diagnosis.summary} -> set {param}={value} (proposed by the model: "
                                  f"{_call_text(call)})")
