"""Model-backed diagnosis and revision, behind the same interface as the rule ladder.

:class:`Reviser` is the seam :class:`~phyagentos.agent.verifier.SessionVerifier` already
calls (``recovery.plan(session, diagnosis, history=..., upstream=...) -> Revision | None``);
the rule ladder (:class:`~phyagentos.agent.recovery.RecoveryPlanner`) is one
implementation, :class:`ModelReviser` another. The model sees the evidence summary (the
diagnosed cause, its summary and measured facts, the failed attempt's parameters and the
earlier revisions along the lineage) and answers a typed revision under a JSON schema
whose variants are exactly the revisions that could change the outcome
(:meth:`ModelReviser.menu`):

* ``adjust``: one strategy parameter of the skill, set to a value of its declared range
  (:data:`REVISION_SPACE`), among the parameters that can address the cause
  (:data:`PARAMETERS_FOR_CAUSE`) and that an earlier revision for the same cause along
  the lineage did not already change;
* ``insert_observe`` -- a corrective node: the child only looks again (skill ``observe``)
  and the criteria are judged on that view; offered only when the criteria could not be
  judged (``perception_unknown``), since looking again cannot change an unambiguous failure;
* ``re_pick_upstream`` -- a corrective node upstream: the goal node that acquires the object
  is re-opened (``Revision.reopen``) and this node runs again; offered when the object is
  no longer in the hand (``precondition_unmet``, or a slip during a non-acquiring skill)
  and the DAG has such a node; with a slip, the re-pick grips firmer;
* ``switch_skill``: another skill for the same goal (:data:`SKILL_ALTERNATIVES`, e.g. a
  ``place`` whose goal configuration collides becomes a ``place_at`` in an off-centre cell
  of the same region), offered for causes a different placement can address
  (:data:`SWITCH_CAUSES`) and not already tried;
* ``switch_target``: the same node on another target (:class:`~phyagentos.agent.retarget.TargetChooser`:
  the SkillRuntime-Target Selector over TARGETS.md, asked about the positions the failed attempt
  perceived, with the Runtime's IK as reach oracle), offered for causes of the arm's own reach
  or planning (:data:`~phyagentos.agent.retarget.RETARGET_CAUSES`) on a node without upstream
  nodes (another target is another world), once along the lineage; the selector's reasons are
  kept in ``Revision.selection``;
* ``give_up`` with a reason (offered from the second replan on, or when nothing else is left).

Every proposal is checked: the parameter is declared by the skill and its value in range
and a real change; a switched skill's node (same id, target and acceptance criteria) passes
the same goal-graph validator as hand-written graphs and declares every parameter it gets.
A rejected or failed proposal falls back to the rule ladder, and the record says so. Each
revision names the cause it addresses (``cause``) and its proposer (``proposed_by``,
strategy ``model:<...>``), so lessons say which reviser proposed what; its model call (a
:class:`~phyagentos.protocol.ModelCallRecord`: prompt hash, model, parameters, tokens,
latency, raw output and outcome) is in ``Revision.model_calls``, so the child keeps it in its
context, and :meth:`ModelReviser.calls_for` gives it to the revised session's context.

A re-target is offered only when a :class:`~phyagentos.agent.retarget.TargetChooser` is given
(the composition root wires it with the reach oracle).
"""

from __future__ import annotations

import json
import logging
from typing import Any, Mapping, Protocol, Sequence

import yaml

from phyagentos.errors import GoalGraphError
from phyagentos.llm import LLMCall, LLMClient, LLMError, call_record
from phyagentos.protocol import Diagnosis, ModelCallRecord, Revision, SessionRecord

from .goal_graph import parse_goal_graph
from .recovery import (
    ACQUIRING_SKILLS,
    ANOTHER_VIEW_SAMPLES,
    LADDERS,
    SITUATIONAL,
    CapabilityLookup,
    RecoveryPlanner,
    beyond_target,
    prompt_policy_session,
)
from .retarget import RETARGET_CAUSES, TargetChooser
from .skill_catalog import SkillInfo, skill_catalog

__all__ = ["Reviser", "ModelReviser", "REVISION_SPACE", "DEFAULTS", "NEVER_RETRY", "PARAMETERS_FOR_CAUSE",
           "SKILL_ALTERNATIVES", "SWITCH_CAUSES"]

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
#: Causes no reviser retries: a safety stop is never retried automatically; a software error
#: is not fixed by another strategy (as the rule ladder).
NEVER_RETRY = frozenset({"safety_intervention", "runtime_error"})
#: Which strategy parameters can address which cause (a parameter outside its cause's list
#: cannot change the outcome: e.g. a goal configuration in collision is not moved by a slower
#: transfer or more perception frames). Causes not listed: every parameter of the skill.
PARAMETERS_FOR_CAUSE: Mapping[str, frozenset[str]] = {
    "perception_error": frozenset({"observe_samples", "reobserve_samples"}),
    "object_not_seen": frozenset({"observe_samples"}),
    "object_moved": frozenset({"observe_samples", "reobserve_samples"}),
    "grasp_missed": frozenset({"observe_samples", "reobserve_samples", "grasp_candidate", "approach_velocity_scale"}),
    "object_slipped": frozenset({"grip_force_n", "lift_velocity_scale", "transfer_velocity_scale"}),
    "collision": frozenset({"transfer_velocity_scale", "planner", "grasp_candidate", "approach_height_m",
                            "approach_velocity_scale"}),
    "goal_in_collision": frozenset({"approach_height_m", "grasp_candidate"}),
    "planning_failed": frozenset({"planner", "approach_height_m"}),
    "start_in_collision": frozenset({"backoff_m", "settle_s"}),  # not the planner: the start itself is invalid
    "placement_off": frozenset({"observe_samples", "lower_velocity_scale", "transfer_velocity_scale"}),
    "ik_unreachable": frozenset(),  # the pose is out of reach: no parameter brings it closer
    "perception_unknown": frozenset(),  # nothing failed in the world: look again instead
    "precondition_unmet": frozenset(),  # the object is not in the hand: re-pick upstream instead
}
#: Another skill for the same goal (same object and region, same effect on the gripper),
#: with the parameter variants the switch may use: a ``place`` becomes a ``place_at`` in the
#: first or last of three cells along the region's longer axis (skills/place_at.yaml).
SKILL_ALTERNATIVES: Mapping[str, Mapping[str, tuple[Mapping[str, Any], ...]]] = {
    "place": {"place_at": ({"slots": 3, "slot": 0}, {"slots": 3, "slot": 2})},
}
#: Causes a different placement (another skill for the same goal) can address.
SWITCH_CAUSES = frozenset({"goal_in_collision", "placement_off", "planning_failed", "collision", "criteria_unmet"})

_SYSTEM = (
    "You repair failed robot skill attempts. Given why the attempt failed, choose ONE revision that addresses "
    "the cause, or give up. Examples: object slipped -> stronger grip_force_n; grasp missed or perception error "
    "-> more observe_samples or reobserve_samples; collision -> lower transfer_velocity_scale or another planner; "
    "the goal pose collides -> switch_skill to place the object elsewhere in the region; the object is no longer "
    "in the hand -> re_pick_upstream; the result could not be seen -> insert_observe; the pose is out of this "
    "arm's reach -> switch_target to an arm that reaches it."
)
_GIVE_UP_REASONS = ["safety_stop", "software_error", "nothing_left"]


class Reviser(Protocol):
    """What the SessionVerifier calls for the revision of a ``replan`` verdict."""

    def plan(self, session: SessionRecord, diagnosis: Diagnosis, *,
             history: Sequence[SessionRecord] = (), upstream: str | None = None,
             evidence: Any = None) -> Revision | None:
        """The revision for ``session``'s child, or ``None`` (the verdict becomes ``failure``). ``upstream``:
        the goal node upstream that acquires the session's object (for a re-pick), if any; ``evidence``: the
        failed attempt's evidence bundle (``None``: not given)."""
        ...


def _call_text(call: LLMCall) -> str:
    return (f"{call.provider} {call.model}, prompt {call.prompt_sha256}, {call.prompt_tokens}+{call.completion_tokens} "
            f"tokens, {call.latency_s:.2f} s")


def _earlier(session: SessionRecord, history: Sequence[SessionRecord]) -> list[Revision]:
    """The revisions already spent along the lineage: those the sessions ran with, and those their
    verdicts proposed (a re-pick upstream runs on another node, so only the verdict records it)."""
    out: list[Revision] = []
    for rec in [*history, session]:
        verdict = rec.attempts[-1].verdict if rec is not session and rec.attempts else None
        for rev in (rec.recovery, verdict.revision if verdict is not None else None):
            if rev is not None and rev not in out:
                out.append(rev)
    return out


def _label(params: Mapping[str, Any]) -> str:
    return "_".join(f"{k}_{v}" for k, v in sorted(params.items())) or "defaults"


def _variant(action: str, **enums: Sequence[Any]) -> dict[str, Any]:
    props: dict[str, Any] = {"action": {"enum": [action]}, **{k: {"enum": list(v)} for k, v in enums.items()}}
    return {"type": "object", "properties": props, "required": list(props), "additionalProperties": False}


class ModelReviser:
    """Revisions proposed by a language model, checked, with the rule ladder as fallback.

    Args:
        client: the model.
        fallback: the rule ladder used when the model's proposal is rejected or the call
            fails (``None``: no fallback, the verdict becomes ``failure``).
        skills: skill catalog (default: the shipped manifests).
        retarget: chooses another capable target for ``switch_target`` (``None``: never offered).
        capabilities: target name -> its TARGETS.md capabilities: a parameter the session's
            target cannot act on is never offered (:func:`~phyagentos.agent.recovery.beyond_target`).
    """

    def __init__(self, client: LLMClient, *, fallback: RecoveryPlanner | None = None,
                 skills: Mapping[str, SkillInfo] | None = None, retarget: TargetChooser | None = None,
                 capabilities: CapabilityLookup | None = None):
        self.client = client
        self.fallback = fallback
        self.capabilities = capabilities
        self._skills = skills
        self.retarget = retarget
        self.calls: list[LLMCall] = []
        self.proposals: list[dict[str, Any]] = []
        self._records: dict[str, list[ModelCallRecord]] = {}
        # (session, attempt, cause) -> the revision given: a verdict judged again (the coordinator
        # re-judges once a failed attempt's images exist) gets the same answer without a second call
        self._given: dict[tuple[str, int, str], Revision | None] = {}

    @property
    def skills(self) -> Mapping[str, SkillInfo]:
        if self._skills is None:
            self._skills = skill_catalog()
        return self._skills

    def replan_budget(self, session: SessionRecord, history: Sequence[SessionRecord] = ()) -> int | None:
        """The fallback's bound on ``session``'s lineage (:meth:`RecoveryPlanner.replan_budget`), or
        ``None`` (the verifier's ``max_replans``)."""
        return self.fallback.replan_budget(session, history) if self.fallback is not None else None

    def calls_for(self, session_id: str) -> list[ModelCallRecord]:
        """The model calls made to revise ``session_id`` (taken once: the coordinator puts them in its context)."""
        return self._records.pop(session_id, [])

    # -- the menu --------------------------------------------------------------

    def menu(self, session: SessionRecord, diagnosis: Diagnosis, *, history: Sequence[SessionRecord] = (),
             upstream: str | None = None) -> list[dict[str, Any]]:
        """The JSON-schema variants of the revisions that could change the outcome (empty: none)."""
        cause = diagnosis.cause
        earlier = _earlier(session, history)
        same_cause = [r for r in earlier if r.cause == cause]
        variants: list[dict[str, Any]] = []
        if cause in NEVER_RETRY:
            return []
        lost = cause == "precondition_unmet" or (cause == "object_slipped" and session.skill not in ACQUIRING_SKILLS)
        if lost:  # the object is not in the hand: only taking it again can help
            if upstream is not None and not any(r.reopen for r in same_cause):
                variants.append(_variant("re_pick_upstream"))
            return variants
        if cause == "perception_unknown":
            if not any(r.skill == "observe" for r in same_cause):
                variants.append(_variant("insert_observe"))
            return variants
        if cause in RETARGET_CAUSES and self.retarget is not None and not any(r.target for r in earlier):
            chosen = self.retarget.choose(session, cause=cause)
            if chosen.target is not None:
                variants.append(_variant("switch_target", target=[chosen.target]))
        for p, values in self._adjustable(session, cause, same_cause).items():
            variants.append(_variant("adjust", parameter=[p], value=values))
        if cause in SWITCH_CAUSES:
            tried = {(r.skill, _label({k: v for k, v in r.parameters.items() if k in ("slot", "slots")}))
                     for r in earlier if r.skill}
            for skill, options in SKILL_ALTERNATIVES.get(session.skill, {}).items():
                labels = [_label(o) for o in options if (skill, _label(o)) not in tried]
                if skill in self.skills and labels:
                    variants.append(_variant("switch_skill", skill=[skill], option=labels))
        return variants

    def _adjustable(self, session: SessionRecord, cause: str, same_cause: Sequence[Revision]) -> dict[str, list[Any]]:
        info = self.skills.get(session.skill)
        relevant = PARAMETERS_FOR_CAUSE.get(cause)
        # a parameter an earlier revision for this same cause already changed did not fix it
        spent = {k for r in same_cause for k in r.parameters if k not in SITUATIONAL}
        spent |= beyond_target(REVISION_SPACE, session.target, self.capabilities)
        out: dict[str, list[Any]] = {}
        for p in sorted(REVISION_SPACE):
            if info is None or p not in info.optional or p in spent or (relevant is not None and p not in relevant):
                continue
            values = [v for v in REVISION_SPACE[p] if v != session.parameters.get(p, DEFAULTS.get(p))]
            if values:
                out[p] = values
        return out

    # -- planning --------------------------------------------------------------

    def plan(self, session: SessionRecord, diagnosis: Diagnosis, *,
             history: Sequence[SessionRecord] = (), upstream: str | None = None,
             evidence: Any = None) -> Revision | None:
        """See :class:`Reviser`. Never raises for a bad model answer: it falls back (and records why).
        No model call is made when no revision could change the outcome, nor twice for one attempt.
        A prompt-driven policy's lineage (:func:`~phyagentos.agent.recovery.prompt_policy_session`)
        gets the fallback's policy ladder: the model has no menu of prompts."""
        if self.fallback is not None and prompt_policy_session(session, history) is not None:
            return self.fallback.plan(session, diagnosis, history=history, upstream=upstream, evidence=evidence)
        key = (session.session_id, len(session.attempts), diagnosis.cause)
        if key in self._given:
            return self._given[key]
        revision = self._plan(session, diagnosis, history=history, upstream=upstream)
        self._given[key] = revision
        return revision

    def _plan(self, session: SessionRecord, diagnosis: Diagnosis, *,
              history: Sequence[SessionRecord], upstream: str | None) -> Revision | None:
        record: dict[str, Any] = {"session": session.session_id, "cause": diagnosis.cause}
        variants = self.menu(session, diagnosis, history=history, upstream=upstream)
        if not variants:
            record.update(proposed_by="policy", revision=None,
                          why="no revision can change the outcome" if diagnosis.cause not in NEVER_RETRY
                          else f"{diagnosis.cause} is never retried")
            self.proposals.append(record)
            return None
        current = dict(session.parameters)
        earlier = _earlier(session, history)
        if earlier:  # a retryable cause is retried at least once: giving up is offered from the second replan on
            variants.append(_variant("give_up", reason=_GIVE_UP_REASONS))
        facts = ", ".join(f"{k}={v}" for k, v in diagnosis.facts.items() if not isinstance(v, (dict, list)))
        lines = [f"Skill: {session.skill} on {session.target}, object {current.get('object', '?')}",
                 f"Failure: {diagnosis.cause} ({diagnosis.category}): {diagnosis.summary}",
                 f"Measured: {facts or 'nothing'}",
                 "Current parameters: " + (", ".join(f"{k}={v}" for k, v in current.items()) or "none"),
                 "Already tried: " + ("; ".join(f"{r.strategy} {r.parameters}" for r in earlier) or "nothing"),
                 "You may: " + "; ".join(self._describe(v) for v in variants)]
        messages = [{"role": "system", "content": _SYSTEM}, {"role": "user", "content": "\n".join(lines)}]
        schema = {"anyOf": variants}
        try:
            reply = self.client.complete(messages, schema=schema, max_tokens=60, purpose="revise")
        except LLMError as exc:
            return self._fall_back(record, session, diagnosis, history, upstream, str(exc), None)
        self.calls.append(reply.call)
        record["call"] = reply.call.to_dict()
        record["output"] = reply.text
        try:
            proposal = reply.json()
            revision = self._check(proposal, session, diagnosis, current, history, upstream, variants, reply.call)
        except (LLMError, ValueError) as exc:
            return self._fall_back(record, session, diagnosis, history, upstream, str(exc), reply)
        outcome = "accepted" if revision is not None else "gave_up"
        rec = call_record(reply.call, role="reviser", output=reply.text, outcome=outcome,
                          detail=revision.strategy if revision is not None else f"gave up: {proposal.get('reason')}")
        self._records.setdefault(session.session_id, []).append(rec)
        if revision is not None:
            revision = revision.model_copy(update={"model_calls": [rec]})
        record["proposed_by"] = "model" if revision is not None else "model:give_up"
        record["revision"] = revision.model_dump(mode="json") if revision is not None else None
        self.proposals.append(record)
        return revision

    @staticmethod
    def _describe(variant: Mapping[str, Any]) -> str:
        props = variant["properties"]
        action = props["action"]["enum"][0]
        if action == "adjust":
            return f"adjust {props['parameter']['enum'][0]} to one of {props['value']['enum']}"
        if action == "switch_skill":
            return f"switch_skill to {props['skill']['enum'][0]} ({', '.join(props['option']['enum'])})"
        if action == "switch_target":
            return f"switch_target to {props['target']['enum'][0]}"
        return action

    def _fall_back(self, record: dict[str, Any], session: SessionRecord, diagnosis: Diagnosis,
                   history: Sequence[SessionRecord], upstream: str | None, why: str, reply: Any) -> Revision | None:
        record["rejected"] = why
        logger.info("model revision for %s rejected: %s", session.session_id, why)
        revision = None
        if self.fallback is not None:
            revision = self.fallback.plan(session, diagnosis, history=history, upstream=upstream)
        if reply is not None:
            rec = call_record(reply.call, role="reviser", output=reply.text,
                              outcome="fallback" if revision is not None else "rejected", detail=why)
            self._records.setdefault(session.session_id, []).append(rec)
            if revision is not None:
                revision = revision.model_copy(update={"model_calls": [rec]})
        if revision is not None:
            revision = revision.model_copy(update={
                "rationale": f"{revision.rationale} [rule ladder; model proposal rejected: {why}]"})
        record["proposed_by"] = "rules" if revision is not None else "none"
        record["revision"] = revision.model_dump(mode="json") if revision is not None else None
        self.proposals.append(record)
        return revision

    # -- checks ----------------------------------------------------------------

    def _check(self, proposal: Any, session: SessionRecord, diagnosis: Diagnosis, current: Mapping[str, Any],
               history: Sequence[SessionRecord], upstream: str | None,
               variants: Sequence[Mapping[str, Any]], call: LLMCall) -> Revision | None:
        if not isinstance(proposal, dict):
            raise ValueError(f"not a typed revision: {proposal!r}")
        if proposal.get("action") == "adjust":  # the specific reason first (logged, and told in the record)
            param, value = proposal.get("parameter"), proposal.get("value")
            info = self.skills.get(session.skill)
            if param not in REVISION_SPACE or info is None or param not in info.optional:
                raise ValueError(f"parameter {param!r} is not a strategy parameter of {session.skill}")
            if value not in REVISION_SPACE[param]:
                raise ValueError(f"{param}={value!r} is outside its declared range {list(REVISION_SPACE[param])}")
            if current.get(param, DEFAULTS.get(param)) == value:
                raise ValueError(f"{param} is already {value!r}: the revision changes nothing")
        if not any(self._fits(proposal, v) for v in variants):
            raise ValueError(f"not one of the offered revisions: {proposal!r}; offered: "
                             f"{'; '.join(self._describe(v) for v in variants)}")
        action, cause = proposal["action"], diagnosis.cause
        step = 1 + sum(1 for r in history if r.attempts and r.attempts[-1].verdict is not None
                       and r.attempts[-1].verdict.diagnosis is not None
                       and r.attempts[-1].verdict.diagnosis.cause == cause)
        common = dict(cause=cause, step=step, proposed_by="model")
        by = f"proposed by the model: {_call_text(call)}"
        if action == "give_up":
            logger.info("model gives up on %s: %s", session.session_id, proposal.get("reason"))
            return None
        if action == "insert_observe":
            return Revision(strategy="model:another_view", skill="observe", parameters={"samples": ANOTHER_VIEW_SAMPLES},
                            rationale=f"addresses {cause}: {diagnosis.summary} -> insert an observe node: look again "
                                      f"({ANOTHER_VIEW_SAMPLES} frames) and judge on that view ({by})", **common)
        if action == "re_pick_upstream":
            grip = {}
            if cause == "object_slipped":
                info = self.skills.get("pick")
                for strategy in LADDERS.get("object_slipped", ()):
                    grip = {k: v for k, v in strategy.values({}).items() if info is not None and k in info.optional}
                    if grip:
                        break
            return Revision(strategy="model:re_pick_upstream", reopen=upstream, parameters=grip,
                            rationale=f"addresses {cause}: {diagnosis.summary} -> insert a re-pick: re-open upstream "
                                      f"node {upstream!r}{' with ' + str(grip) if grip else ''}, then run this node "
                                      f"again ({by})", **common)
        if action == "switch_target":
            chosen = self.retarget.choose(session, cause=cause)
            if chosen.target != proposal["target"]:
                raise ValueError(f"target {proposal['target']!r} is not the selector's choice {chosen.target!r}")
            why = chosen.reasons.get(chosen.target, "")
            return Revision(strategy=f"model:switch_target_to_{chosen.target}", target=chosen.target,
                            selection=dict(chosen.reasons),
                            rationale=f"addresses {cause}: {diagnosis.summary} -> run node {session.node!r} on "
                                      f"{chosen.target} instead of {session.target} ({why}; {by})", **common)
        if action == "switch_skill":
            skill = proposal["skill"]
            option = next(o for o in SKILL_ALTERNATIVES[session.skill][skill] if _label(o) == proposal["option"])
            info = self.skills[skill]
            params = {k: v for k, v in current.items() if k in info.required}
            params.update({k: v for k, v in current.items() if k in info.optional and k not in SITUATIONAL})
            params.update(option)
            self._validate_node(session, skill, params)
            return Revision(strategy=f"model:switch_to_{skill}", skill=skill, parameters=params,
                            rationale=f"addresses {cause}: {diagnosis.summary} -> switch skill {session.skill} -> "
                                      f"{skill} ({_label(option)}) for the same goal ({by})", **common)
        param, value = proposal["parameter"], proposal["value"]
        values = {param: value}
        if float(diagnosis.facts.get("tcp_end_z_m", 1.0)) < 0.15:  # same situational back-off as the ladder
            info = self.skills.get(session.skill)
            values.update({k: v for k, v in SITUATIONAL.items()
                           if info is not None and k in info.optional and current.get(k) != v})
        return Revision(strategy=f"model:{param}", parameters=values,
                        rationale=f"addresses {cause}: {diagnosis.summary} -> set {param}={value} ({by})", **common)

    @staticmethod
    def _fits(proposal: Mapping[str, Any], variant: Mapping[str, Any]) -> bool:
        props = variant["properties"]
        return set(proposal) == set(props) and all(proposal[k] in spec["enum"] for k, spec in props.items())

    def _validate_node(self, session: SessionRecord, skill: str, params: Mapping[str, Any]) -> None:
        """The switched node passes the goal-graph validator, and the skill declares every parameter."""
        info = self.skills[skill]
        undeclared = sorted(set(params) - info.parameters)
        missing = sorted(info.required - set(params))
        if undeclared or missing:
            raise ValueError(f"{skill} does not take {undeclared} or lacks {missing}")
        node = {"id": session.node, "skill": skill, "target": session.target, "params": json.loads(json.dumps(params)),
                "accept": session.accept}
        text = yaml.safe_dump({"version": 1, "name": "revision", "nodes": [node]}, sort_keys=False)
        try:
            parse_goal_graph(text, path=f"<revision of {session.session_id}>", skills=list(self.skills),
                             targets=[session.target])
        except GoalGraphError as exc:
            raise ValueError(f"the switched node is invalid: {exc}") from exc
