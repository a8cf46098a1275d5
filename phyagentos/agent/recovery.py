"""Recovery strategies: what a replanned child session changes, per diagnosed cause.

A strategy sets skill *parameters* (and, for a timeout, limits); the runtime's trees
expose each one as a parameter (``trees/pick.yaml``), so the Runtime stays
strategy-agnostic and the Agent decides. Each cause has an escalation ladder: the
first replan for a cause takes step 1, a second replan for the same cause along the
lineage takes step 2; a step that would change nothing (memory already applied it, or
the skill declares none of its parameters) is skipped, so a retry that cannot change
the outcome is never spent. When the ladder is exhausted, there is no revision and the
verdict is ``failure``. Every revision names the cause it addresses (``cause``) and why
(``rationale``).

=====================  ==========================================================
cause                  ladder (strategy: parameters)
=====================  ==========================================================
perception_unknown     another_view: a child of skill ``observe`` looks again
                       (``samples`` 4) and the criteria are judged on that view;
                       once, then ``failure``
perception_unknown of  push_home_again: the drawer pushed home once more, 1 cm
a drawer pushed home   deeper (``push_to_stop_m`` + 0.01), from where it stands now:
                       the stop met from near shut is judged against a reading taken
                       there (another view would read the same handle); once
object_not_seen        average_frames: observe_samples 4 (once)
perception_error       average_frames: observe_samples 16;
                       average_and_re_observe: observe_samples 32, reobserve_samples 16
object_moved           re_observe: reobserve_samples 1;
                       re_observe_averaged: reobserve_samples 8, observe_samples 8
grasp_missed           re_observe_averaged: observe_samples 8, reobserve_samples 8;
                       another_approach_direction: grasp_candidate + 1
object_slipped         firmer_grip: grip_force_n 40;
                       firmest_grip_slower_transfer: grip_force_n 70,
                       transfer_velocity_scale 0.5, lift_velocity_scale 0.15
collision during a     slower_transfer: transfer_velocity_scale 0.5;
planned motion         another_planner: planner BITstar, transfer_velocity_scale 0.5
collision during a     another_approach_direction: grasp_candidate + 1;
straight-line motion   another_approach_direction: grasp_candidate + 2, approach_height_m 0.15
a push stopped at its  none yet: ``failure`` (an obstruction the push met; a push
effort limit           again from where it stopped starts in contact, and one raised
                       first met the limit again)
goal_in_collision      planning revisions, never re-observation: another_approach:
                       approach_height_m 0.15 (pick: and the next grasp direction);
                       another_placement_pose: place_offset_m [-0.03, 0] (3 cm nearer
                       the base, where the skill declares it), approach_height_m 0.05
start_in_collision     never another planner (no planner plans from an invalid start):
                       the scene or the held object touches the arm: back_off_first:
                       backoff_m 0.10, settle_s 0.5 (where the skill declares them);
                       the arm touches itself (``variant`` ``self``): nothing here,
                       straight to ``switch_target`` (a straight back-off keeps the
                       wrist and jaw as they are)
planning_failed        another_planner: planner BITstar; another_planner: planner PRM
placement_off          average_frames: observe_samples 16;
                       careful_lowering: lower_velocity_scale 0.1, transfer_velocity_scale 0.5
timeout                longer_deadline: execution_timeout_s x 2
criteria_unmet         careful_retry: observe_samples 8, reobserve_samples 8,
                       transfer_velocity_scale 0.5
criteria_unmet of a    push_again_slower: velocity_scale x 0.5: the push again from
push                   where the object stands now (once)
object_slipped in a    the object is no longer in the hand: the upstream pick is
non-acquiring skill    re-opened with the slip ladder's grip step (``Revision.reopen``)
precondition_unmet     re_pick_upstream: the object was released upstream; the
                       coordinator re-opens the upstream node that acquires it
                       (``Revision.reopen``), then runs this node again. Without
                       such a node: ``failure``
ik_unreachable,        none: the pose computed from the perceived object is out of
safety_intervention,   reach (no other parameter brings it closer), a safety stop is
runtime_error          never retried automatically, an error in the software is not
                       fixed by a different strategy
any other cause, in a  the policy ladder (below): retry_from_current_state;
prompt-driven policy   corrected_prompt (``prompt``: what the evidence leaves of the
node's lineage         instruction); builtin_regrasp (skill ``pick``, runtime
                       ``builtin``), then resume_after_regrasp (the policy, the
                       remaining step's prompt). perception_unknown takes its
                       another_view first; timeout, safety_intervention and
                       runtime_error get nothing there
=====================  ==========================================================

**The policy ladder** (issue 29; docs/libero.md, "The policy flow"). A session whose
skill's runtime is ``policy`` and that has a ``prompt`` (a vision-language-action policy:
``libero_policy``) has no strategy parameters to revise; its lineage walks the paper's
recovery variants instead, each once, in the order the node's ``recovery_variants``
parameter names them (default :data:`POLICY_VARIANTS`; ``[retry]`` reproduces a retry-only
baseline, ``[]`` no recovery), all within the episode's step budget:

- ``retry`` (:data:`RETRY`): the policy again from the current state, the same prompt;
- ``corrected_prompt`` (:data:`CORRECTED_PROMPT`): the node's instruction decomposed by
  the Goal Planner's rule reader over the declared scene, each step judged on the failed
  attempt's perceived evidence (:mod:`.instruction_steps`), and the child's ``prompt`` the
  first step left, worded as LIBERO words it (``place the alphabet soup in the basket``
  when the soup is held); skipped when the instruction is not read, every step is done,
  or the prompt would be the one just tried;
- ``builtin_regrasp`` (:data:`BUILTIN_REGRASP`): the child runs the builtin ``pick`` of the
  object the first step left acquires (``Revision.skill``/``runtime``: ``pick`` on the
  ``builtin`` runtime, same target and world); its child, whatever the pick's verdict,
  resumes the policy (:data:`RESUME_AFTER_REGRASP`: the node's skill and runtime again,
  ``prompt`` the step left by the pick's evidence). Skipped when that object is already
  held or no step acquires one, or when the failed attempt's trace says fewer control steps
  are left than a builtin pick takes (:data:`REGRASP_STEPS`).

No rung is taken once the failed policy attempt's trace says the step budget is spent
(``runtime_end``'s ``control_steps`` and ``step_budget``). The ladder is bounded by its
rungs, not by the verifier's ``max_replans`` (:meth:`RecoveryPlanner.replan_budget`).
Every revision records the strategy, the cause it answers and why (the prompt, what the
evidence showed of each step, the steps left); none becomes a lesson (what it corrects is
this episode's progress, not a strategy for another).

**Another arm.** Given a target chooser (:class:`~phyagentos.agent.retarget.TargetChooser`, wired by
the composition root: ``phyagentos run`` and ``plan --run`` do), a cause of the arm's own reach or
planning (``ik_unreachable``, ``start_in_collision`` and ``planning_failed`` once their ladders are spent) moves the node to
another enabled target that has the skill's capabilities and reaches the poses (the selector, asked
about the positions the failed attempt perceived, else the scene's declared ones): strategy
``switch_target``, once along the lineage, only for a node without upstream nodes (another target
is another world). Without a chooser, or when none fits, the ladder ends as before.

Grip forces are per finger (the Franka Hand allows 70 N continuous); planner names are
OMPL planners the runtime offers (``phyagentos.motion.planner.PLANNERS``).

**What the target can do.** A parameter that needs a capability
(:data:`PARAMETER_CAPABILITIES`: ``grip_force_n`` needs ``grip_force``, a hand that takes a force
command) is left out of a revision for a target whose TARGETS.md ``capabilities`` lack it (given
a lookup, wired by the composition root). LIBERO's Panda hand closes on position only: its slip
ladder is the slower lift and transfer of step 2, never a force it would refuse; a step left with
nothing it can change is skipped.

**A held lesson first.** Where the failed session's context holds a verified lesson for
the diagnosed cause (the ContextBuilder holds back lessons whose cause belongs to the scene,
learned on a similar object: ``ContextItem.held``), the first replan for that cause along
the lineage takes the lesson's correction (``proposed_by: memory``), at the ladder rung of
its strategy, so a later replan goes on past it. A held correction that would change
nothing, or that the skill or target cannot take, is passed over for the ladder.

Whatever the cause, when the evidence shows the hand was left below
:data:`CLEARANCE_Z_M` (a failed approach can pin or tip the object), the child first
backs off and lets the scene settle (:data:`SITUATIONAL` parameters ``backoff_m`` 0.10,
``settle_s`` 0.5). These describe the situation the attempt left, not the correction,
so lessons do not keep them.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any, Callable, Collection, Mapping, Sequence

from phyagentos.protocol import Diagnosis, Revision, SessionRecord, Workspace

from .instruction_steps import HELD, same_prompt
from .skill_catalog import SkillInfo, skill_catalog

__all__ = ["Strategy", "LADDERS", "RecoveryPlanner", "SITUATIONAL", "CLEARANCE_Z_M", "RE_PICK", "ACQUIRING_SKILLS",
           "ANOTHER_VIEW_SAMPLES", "PARAMETER_CAPABILITIES", "CapabilityLookup", "beyond_target", "MEMORY",
           "targets_capabilities", "POLICY_VARIANTS", "POLICY_STRATEGIES", "RETRY", "CORRECTED_PROMPT",
           "BUILTIN_REGRASP", "RESUME_AFTER_REGRASP", "RECOVERY_VARIANTS_PARAM", "REGRASP_STEPS",
           "prompt_policy_session", "check_recovery_variants"]

#: ``proposed_by`` of a revision taken from a lesson held in the session's context.
MEMORY = "memory"

logger = logging.getLogger(__name__)

#: Parameters a revision sets because of where the failed attempt left the world.
SITUATIONAL: Mapping[str, Any] = {"backoff_m": 0.10, "settle_s": 0.5}
#: Terminal tcp height (m above the table) below which a retry backs off first.
CLEARANCE_Z_M = 0.15

Adjust = Callable[[Mapping[str, Any]], dict[str, Any]]
#: Target name -> its TARGETS.md ``capabilities`` (``None``: not known, nothing is left out).
CapabilityLookup = Callable[[str], Collection[str] | None]
#: Strategy parameters a target must declare a capability for: a grip force needs a hand that
#: takes a force command (``grip_force``: the MuJoCo tabletop Franka's; LIBERO's Panda hand and
#: the SO-101 jaws close on position only).
PARAMETER_CAPABILITIES: Mapping[str, str] = {"grip_force_n": "grip_force"}


def targets_capabilities(workspace: Workspace) -> CapabilityLookup:
    """Target name -> its TARGETS.md ``capabilities`` in ``workspace`` (read when asked:
    TARGETS.md may change while a run goes on); ``None`` for a target TARGETS.md does not list.
    The AgentCoordinator's default ladder and the composition root's revisers use it."""

    def lookup(name: str) -> frozenset[str] | None:
        spec = next((t for t in workspace.read("TARGETS").data.targets if t.name == name), None)
        return frozenset(spec.capabilities) if spec is not None else None

    return lookup


def beyond_target(parameters: Collection[str], target: str, capabilities: CapabilityLookup | None) -> set[str]:
    """The ``parameters`` ``target`` cannot act on: those whose capability
    (:data:`PARAMETER_CAPABILITIES`) its TARGETS.md entry lacks; none when ``capabilities``
    is ``None`` or does not know the target."""
    caps = capabilities(target) if capabilities is not None else None
    if caps is None:
        return set()
    return {p for p in parameters if p in PARAMETER_CAPABILITIES and PARAMETER_CAPABILITIES[p] not in caps}


@dataclass(frozen=True)
class Strategy:
    """One recovery step.

    Attributes:
        name: strategy name recorded in the revision and in lessons.
        description: what it does, for humans.
        parameters: skill parameter -> new value, or a function of the current
            parameters returning such a mapping (for relative changes).
        limits: session limit -> factor applied to the current value.
        skill: skill the child runs instead of the session's (``observe`` for another view).
    """

    name: str
    description: str
    parameters: Mapping[str, Any] | Adjust = field(default_factory=dict)
    limits: Mapping[str, float] = field(default_factory=dict)
    skill: str | None = None

    def values(self, current: Mapping[str, Any]) -> dict[str, Any]:
        return dict(self.parameters(current) if callable(self.parameters) else self.parameters)


def _next_candidate(offset: int, **extra: Any) -> Adjust:
    def adjust(current: Mapping[str, Any]) -> dict[str, Any]:
        return {"grasp_candidate": int(current.get("grasp_candidate", 0)) + offset, **extra}
    return adjust


def _next_candidate_if_pick(**extra: Any) -> Adjust:
    # grasp_candidate is filtered out for skills that do not declare it (place)
    return _next_candidate(1, **extra)


#: Strategy of a precondition failure after an upstream release.
RE_PICK = "re_pick_upstream"
#: Skills that put an object into the gripper: a session of another skill that lost the
#: object (a slip during a place's transfer) cannot get it back itself; the upstream node
#: of one of these is re-opened instead, with the slip's correction.
ACQUIRING_SKILLS = frozenset({"pick", "policy_pick"})
#: Causes that belong to the arm, not to the world: another arm may reach or plan what this
#: one cannot (the ladder's re-target rung, :mod:`.retarget`).
RETARGET_CAUSES = frozenset({"ik_unreachable", "planning_failed", "start_in_collision"})


#: The skill parameter of a drawer pushed home (``slide_drawer``'s ``push_to_stop_m``, m): a
#: session with it above 0 whose verdict is unknown takes ``perception_unknown/push_home``.
PUSH_PARAM = "push_to_stop_m"

#: Frames the ``another_view`` child fuses. Each frame renders and segments every camera
#: (about 0.3-0.7 s for two RGB-D cameras on the shared 2-core machine); 4 frames keep an
#: observation well inside the runner's 10 s heartbeat timeout.
ANOTHER_VIEW_SAMPLES = 4

#: A push again from where the object stands now, at half the speed (its start, direction and
#: length come from the new observation): after a push left it short or past, or stopped at
#: its effort limit.
_PUSH_AGAIN_SLOWER = Strategy(
    "push_again_slower", "push the object again from where it stands now, at half the speed",
    lambda current: {"velocity_scale": round(0.5 * float(current.get("velocity_scale") or 0.05), 4)})

LADDERS: Mapping[str, tuple[Strategy, ...]] = {
    "perception_unknown": (
        Strategy("another_view", f"look again ({ANOTHER_VIEW_SAMPLES} frames) and judge on that view",
                 {"samples": ANOTHER_VIEW_SAMPLES}, skill="observe"),
    ),
    # a close whose stop was met outside the reading's band (the reading off by more than 2
    # sigma): a second push starts near shut, where the band is judged against a fresh reading
    "perception_unknown/push_home": (
        Strategy("push_home_again", "push the drawer home once more, 1 cm deeper, from where it stands now",
                 lambda current: {PUSH_PARAM: round(min(float(current.get(PUSH_PARAM) or 0.0) + 0.01, 0.1), 3)}),
    ),
    "goal_in_collision": (
        Strategy("another_approach", "approach the goal from 15 cm (pick: with the next grasp direction), "
                 "so the goal configuration changes", _next_candidate_if_pick(approach_height_m=0.15)),
        Strategy("another_placement_pose", "set the object down 3 cm nearer the robot base inside the region, "
                 "from a 5 cm approach", {"place_offset_m": [-0.03, 0.0], "approach_height_m": 0.05}),
    ),
    "object_not_seen": (
        Strategy("average_frames", "fuse 4 perception frames so the object is found and told apart",
                 {"observe_samples": 4}),
    ),
    "perception_error": (
        Strategy("average_frames", "average 16 perception frames before computing the grasp",
                 {"observe_samples": 16}),
        Strategy("average_and_re_observe", "average 32 frames, then look again (16 frames) from the pre-grasp pose",
                 {"observe_samples": 32, "reobserve_samples": 16}),
    ),
    "object_moved": (
        Strategy("re_observe", "look again from the pre-grasp pose and grasp where the object is now",
                 {"reobserve_samples": 1}),
        Strategy("re_observe_averaged", "average 8 frames at both observations",
                 {"reobserve_samples": 8, "observe_samples": 8}),
    ),
    "grasp_missed": (
        Strategy("re_observe_averaged", "average 8 frames and look again from the pre-grasp pose",
                 {"observe_samples": 8, "reobserve_samples": 8}),
        Strategy("another_approach_direction", "use the next top-down grasp direction", _next_candidate(1)),
    ),
    "object_slipped": (
        Strategy("firmer_grip", "close with 40 N per finger", {"grip_force_n": 40.0}),
        Strategy("firmest_grip_slower_transfer", "close with 70 N per finger and lift and transfer slower",
                 {"grip_force_n": 70.0, "transfer_velocity_scale": 0.5, "lift_velocity_scale": 0.15}),
    ),
    "collision/planned": (
        Strategy("slower_transfer", "transfer at half speed", {"transfer_velocity_scale": 0.5}),
        Strategy("another_planner", "plan with BIT* and transfer at half speed",
                 {"planner": "BITstar", "transfer_velocity_scale": 0.5}),
    ),
    "collision/cartesian": (
        Strategy("another_approach_direction", "use the next top-down grasp direction", _next_candidate(1)),
        Strategy("another_approach_direction", "turn the grasp once more and approach from 15 cm",
                 _next_candidate(2, approach_height_m=0.15)),
    ),
    # a contact motion (a push) stopped at its effort limit, the hand left on the object: no
    # strategy yet (a push again plans from the fingers on the object and the table, and one
    # raised first met the limit again: docs/libero.md, fortieth pass)
    "collision/contact": (),
    "start_in_collision": (
        Strategy("back_off_first", "raise the hand 10 cm and let the scene settle before planning, so the start "
                 "configuration clears what it touches", {"backoff_m": 0.10, "settle_s": 0.5}),
    ),
    # the arm's own links: a straight back-off keeps the wrist and the jaw as they are
    "start_in_collision/self": (),
    "planning_failed": (
        Strategy("another_planner", "plan with BIT*", {"planner": "BITstar"}),
        Strategy("another_planner", "plan with PRM", {"planner": "PRM"}),
    ),
    "ik_unreachable": (),
    "placement_off": (
        Strategy("average_frames", "average 16 perception frames of the held object", {"observe_samples": 16}),
        Strategy("careful_lowering", "lower at a third of the speed, transfer at half speed",
                 {"lower_velocity_scale": 0.1, "transfer_velocity_scale": 0.5}),
    ),
    "timeout": (
        Strategy("longer_deadline", "double the execution deadline", limits={"execution_timeout_s": 2.0}),
    ),
    # a push that left the object short of (or past) where it was to go: push it again, slower,
    # from where it stands now (the push's start and length come from the new observation)
    "criteria_unmet/push": (
        _PUSH_AGAIN_SLOWER,
    ),
    "criteria_unmet": (
        Strategy("careful_retry", "average 8 frames, look again before grasping, transfer at half speed",
                 {"observe_samples": 8, "reobserve_samples": 8, "transfer_velocity_scale": 0.5}),
    ),
}


#: The policy flow's recovery variants (module doc, "The policy ladder"), in ladder order.
POLICY_VARIANTS = ("retry", "corrected_prompt", "builtin_regrasp")
#: Strategy names the policy ladder records (``Revision.strategy``); the re-grasp takes two rungs.
RETRY, CORRECTED_PROMPT = "retry_from_current_state", "corrected_prompt"
BUILTIN_REGRASP, RESUME_AFTER_REGRASP = "builtin_regrasp", "resume_after_regrasp"
POLICY_STRATEGIES = frozenset({RETRY, CORRECTED_PROMPT, BUILTIN_REGRASP, RESUME_AFTER_REGRASP})
#: Each variant's rungs, in order.
_RUNGS: Mapping[str, tuple[str, ...]] = {"retry": (RETRY,), "corrected_prompt": (CORRECTED_PROMPT,),
                                         "builtin_regrasp": (BUILTIN_REGRASP, RESUME_AFTER_REGRASP)}
#: The skill parameter of a policy node that names its variants (a list of :data:`POLICY_VARIANTS`).
RECOVERY_VARIANTS_PARAM = "recovery_variants"
#: Control steps (LIBERO's 20 Hz) a builtin re-grasp is expected to need: a builtin pick on the
#: LIBERO target spends about 135 (docs/libero.md: transfer, approach, close, lift at its joint
#: speeds), plus a margin. The builtin runtime does not stop at the budget, so the ladder takes the
#: re-grasp only with at least this many left.
REGRASP_STEPS = 150
#: Causes after which a policy lineage gets no revision: a safety stop, an error in the software (a
#: stalled server, a refused connection), the session's deadline (the episode's own budget bounds it).
_POLICY_EXCLUDED = frozenset({"safety_intervention", "runtime_error", "timeout"})


def prompt_policy_session(session: SessionRecord, history: Sequence[SessionRecord] = ()) -> SessionRecord | None:
    """The nearest session of ``session``'s lineage (itself first) that ran a prompt-driven policy
    skill (runtime ``policy``, a ``prompt`` parameter), or ``None``: the policy ladder's lineage."""
    for rec in [session, *reversed(history)]:
        if rec.skill_runtime == "policy" and isinstance(rec.parameters.get("prompt"), str):
            return rec
    return None


def _lineage(session: SessionRecord, history: Sequence[SessionRecord]) -> list[SessionRecord]:
    """``history`` then ``session``, each session once (an another view's judgement passes the
    acting session with the view's lineage, which holds it already)."""
    out: dict[str, SessionRecord] = {}
    for rec in [*history, session]:
        out.setdefault(rec.session_id, rec)
    return list(out.values())


def _budget_left(evidence: Any) -> int | None:
    """Control steps left of the episode's step budget after the attempt whose evidence this is,
    from the policy runtime's ``runtime_end`` trace record (``control_steps`` since the target's
    reset, ``step_budget``); ``None``: the trace does not say (no budget, another runtime)."""
    for record in reversed(list(getattr(evidence, "trace", None) or ())):
        if record.get("kind") == "runtime_end":
            steps, budget = record.get("control_steps"), record.get("step_budget")
            if isinstance(steps, int) and isinstance(budget, int):
                return budget - steps
            return None
    return None


def _ladder_start(history: Sequence[SessionRecord], cause: str) -> int:
    """Index of the first rung the next revision for ``cause`` may take: past every replan for
    that cause along the lineage, and past the highest rung one of them took (rungs it skipped
    because they would change nothing stay skipped)."""
    steps = [rec.attempts[-1].verdict.revision.step for rec in history
             if rec.attempts and rec.attempts[-1].verdict is not None
             and rec.attempts[-1].verdict.revision is not None and rec.attempts[-1].verdict.revision.cause == cause]
    return max([_previous_causes(history).count(cause), *steps])


def _previous_causes(history: Sequence[SessionRecord]) -> list[str]:
    causes = []
    for rec in history:
        verdict = rec.attempts[-1].verdict if rec.attempts else None
        if verdict is not None and verdict.diagnosis is not None:
            causes.append(verdict.diagnosis.cause)
    return causes


def check_recovery_variants(variants: Any) -> tuple[str, ...]:
    """``variants`` (a policy node's ``recovery_variants``: a list, or one name) as a tuple, each
    one of :data:`POLICY_VARIANTS` once.

    Raises:
        ValueError: not a list of names, an unknown variant (the known ones listed), or one named twice.
    """
    out = (variants,) if isinstance(variants, str) else tuple(variants) if isinstance(variants, (list, tuple)) else None
    if out is None or not all(isinstance(v, str) for v in out):
        raise ValueError(f"{RECOVERY_VARIANTS_PARAM} must be a list of {list(POLICY_VARIANTS)}, got {variants!r}")
    unknown = [v for v in out if v not in POLICY_VARIANTS]
    if unknown:
        raise ValueError(f"unknown policy recovery variant(s) {unknown}; the variants: {list(POLICY_VARIANTS)}")
    if len(set(out)) != len(out):
        raise ValueError(f"policy recovery variants named twice: {list(out)}")
    return out


class RecoveryPlanner:
    """Chooses the revision of a ``replan`` verdict.

    Args:
        ladders: cause -> escalation ladder (default :data:`LADDERS`).
        skills: skill name -> :class:`SkillInfo` (default: the shipped manifests);
            a revision only sets parameters the session's skill declares.
        retarget: chooses another capable target for ``switch_target`` (``None``: never).
        capabilities: target name -> its TARGETS.md capabilities; a revision leaves out the
            parameters the session's target cannot act on (:func:`beyond_target`). ``None``:
            every declared parameter is offered.
        policy_variants: the policy ladder's variants, in order, for a node whose parameters do
            not name them (``recovery_variants``); a subset of :data:`POLICY_VARIANTS`.
        regrasp_skill: the builtin skill of the re-grasp (its manifest's runtime is the child's).
        regrasp_steps: control steps the re-grasp needs left of the step budget (:data:`REGRASP_STEPS`).

    Raises:
        ValueError: a variant not in :data:`POLICY_VARIANTS`, or named twice.
    """

    def __init__(self, ladders: Mapping[str, Sequence[Strategy]] | None = None,
                 skills: Mapping[str, SkillInfo] | None = None, retarget: Any = None,
                 capabilities: CapabilityLookup | None = None, *,
                 policy_variants: Sequence[str] = POLICY_VARIANTS, regrasp_skill: str = "pick",
                 regrasp_steps: int = REGRASP_STEPS):
        self.ladders = dict(LADDERS if ladders is None else ladders)
        self.capabilities = capabilities
        self._skills = skills
        self.policy_variants = check_recovery_variants(policy_variants)
        self.regrasp_skill = regrasp_skill
        self.regrasp_steps = int(regrasp_steps)
        self._upstream_skill = "pick"
        #: a :class:`~phyagentos.agent.retarget.TargetChooser` (``choose(session, cause=...) -> Selection``),
        #: or ``None``: no re-target
        self.retarget = retarget

    @property
    def skills(self) -> Mapping[str, SkillInfo]:
        if self._skills is None:
            self._skills = skill_catalog()
        return self._skills

    def plan(self, session: SessionRecord, diagnosis: Diagnosis, *,
             history: Sequence[SessionRecord] = (), upstream: str | None = None,
             evidence: Any = None) -> Revision | None:
        """The revision for ``session``'s child, or ``None`` when no strategy is left.

        Args:
            session: the session that failed (its parameters are the starting point).
            diagnosis: why it failed.
            history: its ancestors, oldest first; earlier replans for the same cause
                move along the ladder.
            upstream: for ``precondition_unmet``, the goal node upstream that acquires
                the object (the coordinator finds it in the DAG); ``None``: no re-pick.
            evidence: the failed attempt's :class:`~phyagentos.agent.verifier.EvidenceBundle`
                (the policy ladder reads its perceived snapshots and its trace's step count);
                ``None``: the policy ladder's corrected prompt and re-grasp are not offered.

        Raises:
            ValueError: a policy node's ``recovery_variants`` is malformed (the Session Compiler
                refuses such a node before it runs).
        """
        policy = prompt_policy_session(session, history)
        if policy is not None:
            if diagnosis.cause in _POLICY_EXCLUDED:
                return None
            viewed = any(rec.recovery is not None and rec.recovery.skill == "observe"
                         for rec in _lineage(session, history))
            if diagnosis.cause != "perception_unknown" or viewed:  # else: another view first (below)
                return self._policy_plan(session, diagnosis, history, policy, evidence)
        if diagnosis.cause == "precondition_unmet":
            if upstream is None or _previous_causes(history).count(diagnosis.cause) >= 1:
                return None  # nothing upstream to redo, or a re-pick already did not help
            return Revision(strategy=RE_PICK, cause=diagnosis.cause, step=1, reopen=upstream,
                            rationale=f"addresses {diagnosis.cause}: {diagnosis.summary} -> re-open upstream node "
                                      f"{upstream!r} (acquire the object again), then run this node again")
        if diagnosis.cause == "object_slipped" and session.skill not in ACQUIRING_SKILLS:
            # the object fell out during this skill: only the upstream pick can take it again,
            # and it does so with the slip's correction (grip) applied to the pick
            if upstream is None:
                return None
            ladder = self.ladders.get("object_slipped", ())
            allowed = self._settable(self._upstream_skill, session.target)
            for step in range(_ladder_start(history, diagnosis.cause), len(ladder)):
                values = {k: v for k, v in ladder[step].values({}).items() if k in allowed}
                if values:
                    return Revision(strategy=ladder[step].name, cause=diagnosis.cause, step=step + 1,
                                    parameters=values, reopen=upstream,
                                    rationale=f"addresses {diagnosis.cause}: {diagnosis.summary} -> re-open upstream "
                                              f"node {upstream!r} and {ladder[step].description}, then run this "
                                              f"node again")
            return None
        variant = diagnosis.facts.get("variant")
        if diagnosis.cause == "perception_unknown" and float(session.parameters.get(PUSH_PARAM) or 0.0) > 0:
            variant = "push_home"
        elif diagnosis.cause == "criteria_unmet" and session.skill == "push":
            variant = "push"
        ladder = self.ladders.get(f"{diagnosis.cause}/{variant}", self.ladders.get(diagnosis.cause, ()))
        current = dict(session.parameters)
        start = _ladder_start(history, diagnosis.cause)
        if start == 0 and (held := self._held(session, diagnosis, ladder)) is not None:
            return held
        for step in range(start, len(ladder)):
            strategy = ladder[step]
            allowed = self._settable(strategy.skill or session.skill, session.target)
            base = {} if strategy.skill else current
            values = {k: v for k, v in strategy.values(current).items() if k in allowed and base.get(k) != v}
            limits = {k: round(getattr(session.limits, k) * f, 3) for k, f in strategy.limits.items()
                      if hasattr(session.limits, k)}
            if not values and not limits:
                continue
            if not strategy.skill and float(diagnosis.facts.get("tcp_end_z_m", 1.0)) < CLEARANCE_Z_M:
                values.update({k: v for k, v in SITUATIONAL.items() if k in allowed and current.get(k) != v})
            return Revision(strategy=strategy.name, cause=diagnosis.cause, step=step + 1, parameters=values,
                            limits=limits, skill=strategy.skill, runtime=self._runtime_of(strategy.skill),
                            rationale=f"addresses {diagnosis.cause}: {diagnosis.summary} -> {strategy.description}")
        return self._switch_target(session, diagnosis, history, step=len(ladder) + 1)

    def _runtime_of(self, skill: str | None) -> str | None:
        """The runtime ``skill``'s manifest names (``None``: no skill, or not known)."""
        info = self.skills.get(skill) if skill else None
        return info.runtime if info is not None else None

    def rungs(self, policy: SessionRecord) -> tuple[str, ...]:
        """The policy ladder's rungs (strategy names, in order) for the lineage of policy session
        ``policy``: its ``recovery_variants`` parameter's, else :attr:`policy_variants`.

        Raises:
            ValueError: an unknown variant, or one named twice.
        """
        named = policy.parameters.get(RECOVERY_VARIANTS_PARAM)
        variants = self.policy_variants if named is None else check_recovery_variants(named)
        return tuple(r for v in variants for r in _RUNGS[v])

    def replan_budget(self, session: SessionRecord, history: Sequence[SessionRecord] = ()) -> int | None:
        """The replans ``session``'s lineage may take, or ``None`` (the verifier's ``max_replans``
        applies): for a prompt-driven policy's lineage, one per rung of its ladder (the re-grasp
        two) plus the another views it took (a view only looks again)."""
        policy = prompt_policy_session(session, history)
        if policy is None:
            return None
        views = sum(1 for rec in _lineage(session, history) if rec.skill == "observe")
        return len(self.rungs(policy)) + views

    def _policy_plan(self, session: SessionRecord, diagnosis: Diagnosis, history: Sequence[SessionRecord],
                     policy: SessionRecord, evidence: Any) -> Revision | None:
        """The next rung of the policy ladder (module doc) for ``session``'s child, or ``None``."""
        lineage = _lineage(session, history)
        rungs = self.rungs(policy)
        taken = [rec.recovery.step for rec in lineage if rec.recovery is not None
                 and rec.recovery.strategy in POLICY_STRATEGIES]
        left = _budget_left(evidence)
        if left is not None and left <= 0:
            return None  # the episode's budget is spent: a child would end at once
        root = next(rec for rec in lineage if rec.skill_runtime == "policy" and isinstance(rec.parameters.get("prompt"),
                                                                                          str))
        instruction, tried = str(root.parameters["prompt"]), str(policy.parameters["prompt"])
        why = f"addresses {diagnosis.cause}: {diagnosis.summary} -> "
        budget = f" ({left} control steps left of the episode's budget)" if left is not None else ""
        after_regrasp = session.recovery is not None and session.recovery.strategy == BUILTIN_REGRASP
        for index in range(max(taken, default=0), len(rungs)):
            rung, step = rungs[index], index + 1
            if after_regrasp != (rung == RESUME_AFTER_REGRASP):
                continue  # the continuation follows a re-grasp, and only it
            if rung == RESUME_AFTER_REGRASP:
                left_over = self._remaining(instruction, session, evidence, tried=tried)
                if isinstance(left_over, str):
                    return None  # nothing left that a prompt names (every step done, or not read)
                return Revision(strategy=rung, cause=diagnosis.cause, step=step, skill=policy.skill,
                                runtime=policy.skill_runtime, parameters={"prompt": left_over.prompt},
                                rationale=f"{why}after the builtin re-grasp the policy continues with prompt "
                                          f"{left_over.prompt!r} ({left_over.progress}){budget}")
            if rung == RETRY:
                return Revision(strategy=rung, cause=diagnosis.cause, step=step,
                                rationale=f"{why}run the policy again from the current state with the same prompt "
                                          f"{tried!r}{budget}")
            left_over = self._remaining(instruction, session, evidence, tried=tried)
            if isinstance(left_over, str):
                logger.info("session %s: %s skipped: %s", session.session_id, rung, left_over)
                continue
            if rung == CORRECTED_PROMPT:
                if same_prompt(left_over.prompt, tried):
                    continue  # the prompt just tried: it would change nothing
                return Revision(strategy=rung, cause=diagnosis.cause, step=step,
                                parameters={"prompt": left_over.prompt},
                                rationale=f"{why}prompt {left_over.prompt!r}: what the evidence leaves of "
                                          f"{instruction!r} ({left_over.progress}){budget}")
            if rung == BUILTIN_REGRASP:
                obj = left_over.step.acquires
                if obj is None or left_over.status == HELD:
                    continue  # no object to take, or it is in the hand already
                if left is not None and left < self.regrasp_steps:
                    continue  # a builtin pick would run past the budget
                return Revision(strategy=rung, cause=diagnosis.cause, step=step, skill=self.regrasp_skill,
                                runtime=self._runtime_of(self.regrasp_skill), parameters={"object": obj},
                                rationale=f"{why}builtin {self.regrasp_skill} of {obj} (the step "
                                          f"{left_over.step.prompt()!r} acquires it; {left_over.progress}), then the "
                                          f"policy continues with the step left{budget}")
        return None

    @staticmethod
    def _remaining(instruction: str, session: SessionRecord, evidence: Any, *, tried: str):
        """:func:`~.instruction_steps.remaining_prompt` of ``instruction`` on ``evidence`` over
        ``session``'s declared scene, or why there is none (a string)."""
        from .declared import declared_scene  # noqa: PLC0415
        from .instruction_steps import InstructionNotRead, decompose, remaining_prompt, step_status  # noqa: PLC0415

        if evidence is None:
            return "no evidence to judge the steps on"
        try:
            steps = decompose(instruction, declared_scene(session.scene))
        except InstructionNotRead as exc:
            return f"the instruction's steps are not read: {exc}"
        left_over = remaining_prompt(steps, step_status(steps, evidence), tried=tried)
        return left_over if left_over is not None else "the evidence shows every step done"

    def _settable(self, skill: str, target: str) -> frozenset[str]:
        """The optional (strategy) parameters of ``skill`` that ``target`` can act on."""
        info = self.skills.get(skill)
        allowed = info.optional if info is not None else frozenset()
        return frozenset(allowed - beyond_target(allowed, target, self.capabilities))

    def _held(self, session: SessionRecord, diagnosis: Diagnosis, ladder: Sequence[Strategy]) -> Revision | None:
        """The revision from the first lesson ``session``'s context holds for the diagnosed
        cause, or ``None`` (none held, or it would change nothing the skill and target take)."""
        items = session.context.items if session.context is not None else ()
        for item in items:
            held = item.held
            if item.kind != "lesson" or held.get("cause") != diagnosis.cause:
                continue
            skill = held.get("skill") or None
            allowed = self._settable(skill or session.skill, session.target)
            base = {} if skill else dict(session.parameters)
            values = {k: v for k, v in (held.get("parameters") or {}).items() if k in allowed and base.get(k) != v}
            if not values:
                continue
            if not skill and float(diagnosis.facts.get("tcp_end_z_m", 1.0)) < CLEARANCE_Z_M:
                values.update({k: v for k, v in SITUATIONAL.items() if k in allowed and base.get(k) != v})
            names = [strategy.name for strategy in ladder]
            name = str(held.get("strategy") or "lesson")
            return Revision(strategy=name, cause=diagnosis.cause, step=names.index(name) + 1 if name in names else 1,
                            parameters=values, skill=skill, proposed_by=MEMORY,
                            rationale=f"addresses {diagnosis.cause}: {diagnosis.summary} -> lesson {item.id} "
                                      f"learned on a similar object ({name})")
        return None

    def _switch_target(self, session: SessionRecord, diagnosis: Diagnosis, history: Sequence[SessionRecord], *,
                       step: int) -> Revision | None:
        """The node on another target that reaches it (see the module docstring), or ``None``."""

        if self.retarget is None or diagnosis.cause not in RETARGET_CAUSES:
            return None
        if any(rec.recovery is not None and rec.recovery.target for rec in [*history, session]):
            return None  # once along the lineage
        chosen = self.retarget.choose(session, cause=diagnosis.cause)
        if chosen.target is None:
            return None
        why = chosen.reasons.get(chosen.target, "")
        return Revision(strategy=f"switch_target_to_{chosen.target}", cause=diagnosis.cause, step=step,
                        target=chosen.target, selection=dict(chosen.reasons),
                        rationale=f"addresses {diagnosis.cause}: {diagnosis.summary} -> run node {session.node!r} on "
                                  f"{chosen.target} instead of {session.target} ({why})")
