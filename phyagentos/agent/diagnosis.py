"""Diagnosis: why an attempt failed, read from its evidence bundle into a fixed taxonomy.

Only what a robot has counts (issue 9, part 5): the *perceived* snapshots before and
after the session (``initial.yaml``, ``terminal.yaml``: entities with confidence and
position uncertainty, relations from perceived geometry plus proprioception), the trace
the runtime recorded (perceived observations, the grasp computed from which perceived
pose, gripper commands with opening and effort, proprioception samples while holding,
the wrist-load mass estimate, slips the runtime detected, IK and planner reports), the
runtime's outcome and the safety and target events. The simulator's privileged channel
is never read, so a cause is inferred the way it would be on hardware.

=====================  ============  =====================================================
cause                  category      evidence
=====================  ============  =====================================================
safety_intervention    safety        a ``safety.*`` event
timeout                timeout       runtime outcome ``timed_out``
precondition_unmet     execution     the skill needed the object in hand and the gripper
                                     held nothing before anything closed (after an
                                     upstream release: recovery re-opens the upstream pick)
ik_unreachable         policy        ``ik.*`` error: no configuration reaches the pose
                                     computed from the perceived object (never retried)
start_in_collision     policy        the planner refused the start configuration: it is
                                     itself in contact (``collision_at_start`` in a ``plan``
                                     entry, with ``start_contact``: ``self``, ``held_object``,
                                     ``environment``, ``joint_limit``; or "start configuration
                                     is invalid" in the runtime's message). Another planner
                                     cannot help: recovery backs off or re-targets
goal_in_collision      policy        the planner reports the goal configuration itself in
                                     collision (``collision_at_goal`` in a ``plan`` entry, or
                                     "goal configuration is invalid")
planning_failed        policy        other ``planning.*``, ``timing.*``, ``motion.*`` error
collision              execution     a tracking error during a motion (``facts.variant``:
                                     ``planned`` transfer or ``cartesian`` straight move),
                                     or a contact motion stopped at its effort limit
                                     (``contact.excessive_force``: a push that met more
                                     than the object; ``facts.variant`` ``contact``)
object_slipped         execution     while holding, a ``slip`` entry, the opening closing by
                                     more than :data:`SLIP_OPENING_DROP_M`, or the wrist load
                                     dropping below :data:`SLIP_LOAD_RATIO` of its level
                                     after lift; or ``grasp.slipped`` after a close
perception_error       perception    the grasp missed and the observation it used was
                                     uncertain (``position_std_m`` above
                                     :data:`PERCEPTION_STD_TOL_M` or confidence below
                                     :data:`CONFIDENCE_MIN`)
object_moved           perception    the grasp missed and the object is now perceived more
                                     than :data:`MOVED_TOL_M` (+ 2 sigma) from where the
                                     grasp aimed
grasp_missed           execution     the gripper closed on an object to an opening below
                                     :data:`MISSED_OPENING_M` (on nothing), or
                                     ``grasp.missed``, perception consistent (a hand
                                     closed with no object to take, to push or hook
                                     with, grasps nothing by design)
perception_unknown     perception    a criterion could not be judged: the object was not
                                     seen, or only with low confidence
object_not_seen        perception    ``perception.*`` error: the skill's own observation did
                                     not find the object (not seen, or ambiguous)
runtime_error          execution     the runtime raised (``target.error``, ...)
placement_off          execution     released, but not where the criteria ask
criteria_unmet         verifier      the runtime completed and nothing above explains it
=====================  ============  =====================================================

Categories follow the paper's error taxonomy (perception, policy, adapter, execution,
timeout, safety, verifier). Rules are applied in the order of the table.
"""

from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

from phyagentos.protocol import Diagnosis, SessionRecord

__all__ = ["CAUSES", "CONFIDENCE_MIN", "MISSED_OPENING_M", "MOVED_TOL_M", "PERCEPTION_STD_TOL_M",
           "SLIP_LOAD_RATIO", "SLIP_OPENING_DROP_M", "diagnose", "subject_object", "perceived_position", "slip_seen"]

#: cause -> (category, one-line meaning)
CAUSES: dict[str, tuple[str, str]] = {
    "safety_intervention": ("safety", "a SafetyGuard intervention stopped the session"),
    "timeout": ("timeout", "the execution deadline passed"),
    "precondition_unmet": ("execution", "the session started without what it needs (the object in hand)"),
    "ik_unreachable": ("policy", "no joint configuration reaches the pose computed from the perceived object"),
    "start_in_collision": ("policy", "the arm's start configuration is itself in contact: no planner plans from it"),
    "goal_in_collision": ("policy", "the goal configuration itself collides (placement pose or approach)"),
    "planning_failed": ("policy", "no collision-free path or timing was found"),
    "collision": ("execution", "unexpected contact stopped a motion"),
    "object_slipped": ("execution", "the object slipped out of, or dropped from, the grasp"),
    "perception_error": ("perception", "the perceived object pose used for the motion was uncertain"),
    "object_moved": ("perception", "the object was not where the grasp aimed when the gripper arrived"),
    "grasp_missed": ("execution", "the gripper closed on nothing although perception was consistent"),
    "perception_unknown": ("perception", "the object was not seen, or not confidently enough, to judge"),
    "object_not_seen": ("perception", "the skill's observation did not find the object (unseen or ambiguous)"),
    "runtime_error": ("execution", "the runtime raised an error"),
    "placement_off": ("execution", "the object was released, but not where the criteria ask"),
    "criteria_unmet": ("verifier", "the runtime completed, the criteria are not met, no finer cause found"),
}

#: Per-finger opening after a close below which the gripper closed on nothing, m
#: (CONTRACT_9 section 3: holding needs more than ~2 mm).
MISSED_OPENING_M = 0.002
#: Opening decrease while holding that signals a slip, m (CONTRACT_9 section 5).
SLIP_OPENING_DROP_M = 0.003
#: Wrist load falling below this fraction of its post-lift level signals a slip
#: (CONTRACT_9 section 5: a drop by more than 50 %).
SLIP_LOAD_RATIO = 0.5
#: Peak wrist load below which a drop is not judged, N (about 50 g: below it the load is
#: within the wrist sensor's noise and the hand model's error).
MIN_SLIP_LOAD_N = 0.45
#: Perceived 1-sigma horizontal uncertainty above which an observation is too uncertain
#: for a top-down grasp, m: half the ~1.5 cm grasp tolerance of a 4 cm box measured on
#: the tabletop scene (3 cm along the fingers still grasps, 2.5 cm across them does not).
PERCEPTION_STD_TOL_M = 0.0075
#: Confidence below which a perceived entity does not count (same as the verifier's).
CONFIDENCE_MIN = 0.5
#: Horizontal displacement between where a grasp aimed and where the object is perceived
#: afterwards above which it "moved", m (added to 2 sigma of the two observations).
MOVED_TOL_M = 0.015


def _xy_dist(a: Sequence[float], b: Sequence[float]) -> float:
    a, b = (x["position"] if isinstance(x, dict) else x for x in (a, b))  # CONTRACT_9 observe entries
    return math.hypot(float(a[0]) - float(b[0]), float(a[1]) - float(b[1]))


def _entity(snapshot: Mapping, name: str) -> Mapping | None:
    return next((e for e in snapshot.get("entities", []) if e.get("name") == name), None)


def _holding(snapshot: Mapping, name: str) -> bool:
    return any(r.get("relation") == "holding" and r.get("object") == name
               and float(r.get("confidence", 1.0)) >= CONFIDENCE_MIN for r in snapshot.get("relations", []))


def perceived_position(record: Any) -> tuple[list[float], float, float] | None:
    """``(position (3,) m, position_std_m, confidence)`` of an ``observe`` entry's object
    record (CONTRACT_9 section 5); a bare position list counts as std 0, confidence 1."""
    if isinstance(record, Mapping) and "position" in record:
        return (list(record["position"]), float(record.get("position_std_m") or 0.0),
                float(record.get("confidence", 1.0)))
    if isinstance(record, (list, tuple)) and len(record) >= 2:
        return list(record), 0.0, 1.0
    return None


def subject_object(session: SessionRecord) -> str | None:
    """The object a session manipulates: its ``object`` parameter, else the first
    object an acceptance criterion names."""
    obj = session.parameters.get("object")
    if isinstance(obj, str):
        return obj
    items = session.accept.items() if isinstance(session.accept, Mapping) else \
        [kv for d in session.accept for kv in d.items()]
    for _, args in items:
        if isinstance(args, str):
            return args
        if isinstance(args, Mapping) and isinstance(args.get("object"), str):
            return args["object"]
    return None


def _make(cause: str, summary: str, facts: dict, evidence: Sequence[str]) -> Diagnosis:
    return Diagnosis(cause=cause, category=CAUSES[cause][0], summary=summary,
                     facts={k: (round(v, 4) if isinstance(v, float) else v) for k, v in facts.items()},
                     evidence=list(evidence))


def _slip_from_proprio(trace: Sequence[Mapping], start: int, obj: str | None) -> dict | None:
    """A slip seen in the trace after index ``start`` (the last close): a ``slip`` entry,
    or proprioception samples whose opening closed or whose wrist load dropped."""
    for r in trace[start:]:
        if r.get("kind") == "gripper" and r.get("command") == "open":
            return None  # released on purpose from here on
        if r.get("kind") == "slip" and r.get("object") in (None, obj):
            return {"slip_source": "runtime", "opening_drop_m": r.get("opening_drop_m"),
                    "load_drop_n": r.get("load_drop_n"), "slip_leaf": r.get("leaf")}
    samples = []
    for r in trace[start:]:
        if r.get("kind") == "gripper" and r.get("command") == "open":
            break
        if r.get("kind") == "proprio" and r.get("opening_m") is not None:
            samples.append(r)
    if len(samples) < 2:
        return None
    first_open = float(samples[0]["opening_m"])
    for r in samples[1:]:
        drop = first_open - float(r["opening_m"])
        if drop > SLIP_OPENING_DROP_M:
            return {"slip_source": "opening", "opening_drop_m": drop, "slip_phase": r.get("phase")}
    # the load is judged on samples taken while carrying: the samples around a gripper
    # command (before_/after_) include contact forces of the fingers and the table
    loaded = [float(r["wrist_load_n"]) for r in samples if r.get("wrist_load_n") is not None
              and not str(r.get("phase", "")).startswith(("before_", "after_"))]
    if loaded:
        peak = max(loaded)
        after = loaded[loaded.index(peak):]
        if peak >= MIN_SLIP_LOAD_N and min(after) < SLIP_LOAD_RATIO * peak:
            return {"slip_source": "wrist_load", "load_drop_n": peak - min(after), "load_peak_n": peak}
    return None


#: Public name of the slip rule (the held-object model applies the same one).
slip_seen = _slip_from_proprio


def diagnose(session: SessionRecord, evidence: Any, *, unknown: Sequence[str] = ()) -> Diagnosis:
    """Diagnose an unsuccessful attempt of ``session`` from its :class:`EvidenceBundle`.

    Args:
        session: the session whose attempt is diagnosed.
        evidence: its evidence bundle (perceived snapshots, trace, events, outcome).
        unknown: texts of criteria the verifier could not judge (perception missing).

    Returns a :class:`~phyagentos.protocol.Diagnosis` whose ``facts`` hold the measured
    quantities (metres, newtons) and whose ``evidence`` lists the files consulted. Never
    raises on incomplete evidence: missing parts make rules not apply, down to
    ``criteria_unmet``.
    """
    refs = list(evidence.refs("initial", "terminal", "trace", "events"))
    outcome = evidence.outcome or {}
    code = str(outcome.get("error_code") or "")
    leaf = str(outcome.get("failed_primitive") or "")
    message = str(outcome.get("message") or "")
    facts: dict[str, Any] = {"runtime_status": outcome.get("status"), "error_code": code or None,
                             "failed_primitive": leaf or None}

    safety = [str(e.get("code")) for e in evidence.events if str(e.get("code", "")).startswith("safety.")]
    if safety:
        return _make("safety_intervention", f"SafetyGuard intervened: {', '.join(sorted(set(safety)))}",
                     {**facts, "violations": sorted(set(safety))}, refs)
    if outcome.get("status") == "timed_out" or code.startswith("timeout."):
        return _make("timeout", "the execution deadline passed before the skill finished", facts, refs)

    obj = subject_object(session)
    facts["object"] = obj
    eT = _entity(evidence.terminal, obj) if obj else None
    trace = list(evidence.trace)
    # a close names the object it takes; one with none closes the empty hand to push or hook with
    closes = [i for i, r in enumerate(trace)
              if r.get("kind") == "gripper" and r.get("command") == "close" and r.get("object")]
    last_close = trace[closes[-1]] if closes else None
    held_at_start = bool(obj) and _holding(evidence.initial, obj)
    held_at_end = bool(obj) and _holding(evidence.terminal, obj)
    tcp = _entity(evidence.terminal, "tcp")
    if tcp is not None:
        facts["tcp_end_z_m"] = float(tcp["position"][2])  # how low the hand was left (recovery backs off)
    if last_close is not None:
        for key in ("opening_m", "effort_n", "closed_on_something"):
            if last_close.get(key) is not None:
                facts[f"close_{key}"] = last_close[key]
    missed = last_close is not None and (
        last_close.get("closed_on_something") is False
        or (last_close.get("opening_m") is not None and float(last_close["opening_m"]) < MISSED_OPENING_M))
    if missed or code == "grasp.missed":
        facts["missed_grasp"] = True

    # 1. the session needed the object in hand and had nothing before anything closed
    if code == "grasp.slipped" and not held_at_start and not closes:
        return _make("precondition_unmet", f"{obj} was not in the gripper when the session started "
                     f"(released upstream): the object has to be picked again",
                     {**facts, "needs": "object_in_hand", "upstream": "acquire"}, refs)
    # 2. motion generation
    if code.startswith("ik."):
        return _make("ik_unreachable", f"{leaf or 'IK'}: {message}".strip(), facts, refs)
    at_goal = any(r.get("kind") == "plan" and r.get("collision_at_goal") for r in trace) or \
        "goal configuration is invalid" in message
    starts = [r for r in trace if r.get("kind") == "plan" and r.get("collision_at_start")]
    if code.startswith(("planning.", "timing.", "motion.")):
        if starts or "start configuration is invalid" in message:
            contact = str(starts[-1].get("start_contact") or "unknown") if starts else "unknown"
            pairs = starts[-1].get("colliding_pairs") if starts else None
            what = {"self": "the arm touches itself", "held_object": "the held object touches the arm",
                    "environment": "the arm touches the scene", "joint_limit": "a joint is past its limit"
                    }.get(contact, "it is in contact")
            return _make("start_in_collision", f"{leaf or 'planning'}: the start configuration is invalid ({what}): "
                         f"{message}".strip(),
                         {**facts, "collision_at_start": True, "variant": contact,
                          **({"colliding_pairs": pairs} if pairs else {})}, refs)
        if at_goal:
            return _make("goal_in_collision", f"{leaf or 'planning'}: the goal configuration collides: {message}",
                         {**facts, "collision_at_goal": True}, refs)
        return _make("planning_failed", f"{leaf or 'planning'}: {message}".strip(), facts, refs)
    if code.startswith("execution."):
        # The planned transfer (the move_to subtree's "Execute" leaf) or a straight-line
        # move (approach, lift, lower ...): recovery differs.
        facts["variant"] = "planned" if leaf == "Execute" else "cartesian"
        errs = [float(r["max_tracking_error_rad"]) for r in trace
                if r.get("kind") == "execute_end" and r.get("max_tracking_error_rad") is not None]
        if errs:
            facts["max_tracking_error_rad"] = max(errs)
        return _make("collision", f"{leaf or 'execution'}: {message}".strip(), facts, refs)
    # 3. a slip, from proprioception after the last close on something (or from the start
    #    of a session that began with the object in hand)
    if (closes and not missed) or (held_at_start and not closes):
        slip = _slip_from_proprio(trace, closes[-1] + 1 if closes else 0, obj)
        if slip is not None or (code == "grasp.slipped" and not held_at_end):
            facts.update(slip or {"slip_source": "check_holding"})
            where = f"detected by {leaf}" if code == "grasp.slipped" and leaf else f"seen in {facts['slip_source']}"
            return _make("object_slipped", f"{obj} slipped out of the grasp ({where})", facts, refs)
    # 4. a missed grasp: was the observation it used uncertain, did the object move, or neither?
    if missed or code == "grasp.missed":
        grasps = [r for r in trace if r.get("kind") == "grasp_pose" and r.get("object") == obj]
        observations = [perceived_position((r.get("objects") or {}).get(obj)) for r in trace
                        if r.get("kind") == "observe" and obj in (r.get("objects") or {})]
        observations = [o for o in observations if o is not None]
        aimed = grasps[-1].get("observed_position") if grasps else None
        used = None
        if observations:
            used = observations[-1]
            if aimed is not None:
                used = min(observations, key=lambda o: _xy_dist(o[0], aimed))
            aimed = aimed if aimed is not None else used[0]
            facts.update(perceived=list(used[0]), perceived_std_m=used[1], perceived_confidence=used[2])
            if used[1] > PERCEPTION_STD_TOL_M or used[2] < CONFIDENCE_MIN:
                return _make("perception_error",
                             f"the grasp used an uncertain observation of {obj} (sigma {used[1] * 100:.1f} cm, "
                             f"confidence {used[2]:.2f}) and closed on nothing", facts, refs)
        if aimed is not None and eT is not None:
            attrs = eT.get("attributes") or {}
            if float(attrs.get("confidence", 1.0)) >= CONFIDENCE_MIN:
                now_std = float(attrs.get("position_std_m") or 0.0)
                d = _xy_dist(eT["position"], aimed)
                facts["moved_since_observation_m"] = d
                if d > MOVED_TOL_M + 2.0 * (now_std + (used[1] if used else 0.0)):
                    return _make("object_moved", f"{obj} is now perceived {d * 100:.1f} cm from where the grasp "
                                 f"aimed: it was not there when the gripper arrived", facts, refs)
        return _make("grasp_missed", f"the gripper closed on nothing at {obj}'s perceived position "
                     f"(opening {facts.get('close_opening_m', 'n/a')} m)", facts, refs)
    if code.startswith("perception."):
        return _make("object_not_seen", f"{leaf or 'observation'}: {message}".strip(), facts, refs)
    if code == "contact.excessive_force":  # met more than it was to move: an obstruction, not a software error
        return _make("collision", f"{leaf or 'contact'}: {message}".strip(), {**facts, "variant": "contact"}, refs)
    if code:
        return _make("runtime_error", f"{code}: {message}".strip(), facts, refs)
    if unknown:
        return _make("perception_unknown", "not judged from what was perceived: " + "; ".join(unknown),
                     {**facts, "unknown": list(unknown)}, refs)
    released = held_at_start or (bool(closes) and any(r.get("kind") == "gripper" and r.get("command") == "open"
                                                      for r in trace[closes[-1] + 1:]))
    if eT is not None and obj and not held_at_end and released:
        return _make("placement_off", f"{obj} was released where the criteria do not accept it", facts, refs)
    return _make("criteria_unmet", "the runtime completed but the acceptance criteria are not met", facts, refs)
