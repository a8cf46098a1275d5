"""Verifier accuracy against ground truth: the confusion matrix of verdicts (issue 9, part 4).

Scoring is a composition-root concern: it reads ``evidence/<session>/ground_truth.yaml``
(the privileged channel the runner writes beside every bundle, CONTRACT_9 section 2),
rebuilds exact snapshots from it and judges the session's acceptance criteria on them
with the same predicates the SessionVerifier uses (:func:`phyagentos.agent.criteria.evaluate`)
-- with confidence 1 and zero position uncertainty, so every band collapses to the exact
boundary. That is the *truth* of each criterion; the verifier's recorded status (on the
perceived snapshots) is compared with it.

Per criterion (status the verifier recorded x truth):

==================  =====================================================================
true_success        verifier ``satisfied``, truth met
false_success       verifier ``satisfied``, truth unmet ("self-deception")
true_failure        verifier ``unsatisfied`` or ``unknown``, truth unmet
false_failure       verifier ``unsatisfied``, truth met
unknown_met         verifier ``unknown``, truth met (no claim made: counted apart, it
                    costs another view, never a false success)
==================  =====================================================================

Per session: verdict ``success`` versus *every* criterion met in truth (a ``replan`` or
``failure`` verdict counts as "not success"). Rates: ``false_success_rate`` =
false successes / sessions scored (the issue's "<= 1 % over at least 200 sessions"),
``false_success_given_unmet`` = false successes / sessions truth says failed, and
``false_failure_rate`` = false failures / sessions scored, ``false_failure_given_met``
= false failures / sessions truth says succeeded. Criteria whose truth cannot be
computed from ground truth (``still``: no joint state in it; ``articulated`` without a
joint record) are counted as ``unscorable`` and left out; a session with an unscorable
criterion is not scored as a session (its truth is unknown: the kitchen's ``articulated``
and ``inside`` beside a scorable ``released`` would otherwise make every kitchen failure a
"false failure"), only its scorable criteria are.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

import numpy as np

from phyagentos.agent.criteria import Criterion, evaluate, parse_criteria
from phyagentos.errors import BenchError
from phyagentos.geometry import quat_to_matrix
from phyagentos.yamlsource import read_yaml

__all__ = ["wilson_interval", "GROUND_TRUTH_FILE", "truth_snapshot", "truth_of_criteria", "score_session", "confusion",
           "load_ground_truth", "judged_ground_truth", "acting_ancestor"]

GROUND_TRUTH_FILE = "ground_truth.yaml"
_SESSION_CELLS = ("true_success", "false_success", "true_failure", "false_failure")
_CRITERION_CELLS = (*_SESSION_CELLS, "unknown_met", "unscorable")


def load_ground_truth(bundle_dir: Path) -> dict[str, Any] | None:
    """``ground_truth.yaml`` of an evidence bundle directory, or ``None`` if absent/unreadable."""
    path = Path(bundle_dir) / GROUND_TRUTH_FILE
    try:
        data = read_yaml(path, error=BenchError)
    except (OSError, BenchError):
        return None
    return data if isinstance(data, dict) else None


def acting_ancestor(session: Any, lookup: Callable[[str], Any]) -> Any:
    """The acting ancestor an *another view* child (``recovery.skill`` ``observe``) judges
    again: the nearest ancestor of another skill with evidence, found through ``lookup``
    (session id -> session record, or None when unknown); None for any other session."""
    if session.recovery is None or session.recovery.skill != "observe":
        return None
    parent = session.parent_session_id
    while parent and (anc := lookup(parent)) is not None:
        if anc.skill != "observe" and anc.attempts and anc.attempts[-1].evidence:
            return anc
        parent = anc.parent_session_id
    return None


def judged_ground_truth(gt: Mapping[str, Any] | None, acting_gt: Mapping[str, Any] | None) -> Mapping[str, Any] | None:
    """The ground truth an *another view* child's verdict is about: its own terminal state
    with the initial state of the acting session whose criteria it judges again (the
    coordinator judges the acting session's evidence with the child's terminal snapshot,
    :mod:`phyagentos.agent.coordinator`). Scored against its own initial state, a confirmed
    ``lifted`` would be false: the child starts with the object already raised. ``gt``
    unchanged when either is missing."""
    if not gt or not acting_gt or acting_gt.get("initial") is None:
        return gt
    return {**gt, "initial": acting_gt["initial"]}


def _vertical_half_extent(shape: str | None, half_extents, quat_wxyz) -> float:
    """World-frame vertical half extent, m, of a ``box`` (``|R[2, :]| @ h``), ``sphere`` (its
    radius) or ``cylinder`` (axis along local z: ``|R22| h_z + sqrt(1 - R22^2) r``) with
    half extents ``half_extents`` (3,) m in its own frame and orientation ``quat_wxyz``;
    any other shape keeps its own z half extent."""
    h = np.asarray(half_extents, dtype=float)
    r = quat_to_matrix(quat_wxyz)
    if shape == "box":
        return float(np.abs(r[2]) @ h)
    if shape == "sphere":
        return float(h[0])
    if shape == "cylinder":
        c = min(1.0, abs(float(r[2, 2])))
        return float(c * h[2] + math.sqrt(max(0.0, 1.0 - c * c)) * h[0])
    return float(h[2])


def truth_snapshot(state: Mapping[str, Any] | None, scene: Mapping[str, Any] | None) -> dict[str, Any]:
    """An exact ENVIRONMENT-style snapshot from one ground-truth state.

    Args:
        state: ``ground_truth.yaml``'s ``initial`` or ``terminal`` (objects with
            ``position`` (3,) m, ``quat_wxyz``, ``half_extents`` (3,) m where known; ``held``).
            An object without extents gets no ``size``: a criterion that needs one is then
            not computable (:func:`truth_of_criteria` gives ``None``).
        scene: its ``scene_record`` (regions with ``center`` (2,) and ``half_extents`` (2,) m,
            obstacles), for the regions the criteria name.
    """
    state = state or {}
    ents: list[dict[str, Any]] = []
    for name, o in (state.get("objects") or {}).items():
        if not isinstance(o, Mapping) or o.get("position") is None:
            continue
        ent: dict[str, Any] = {"name": name, "kind": "object", "position": list(o["position"]),
                               "quat_wxyz": list(o.get("quat_wxyz", [1, 0, 0, 0])),
                               "attributes": {"confidence": 1.0, "position_std_m": 0.0}}
        size = o.get("half_extents") or o.get("size")
        if size is not None:
            # (an object whose ground truth has no extents, LIBERO's: the criteria that need
            # them -- on, inside, beside -- are not computable from it, never "unmet")
            if o.get("quat_wxyz") is not None and len(size) == 3:
                # the vertical half extent in the world frame (what the resting height and
                # perception's measured size go by): a box lying on its side rests on another
                # half extent than its own z
                size = [float(size[0]), float(size[1]), _vertical_half_extent(o.get("shape"), size, o["quat_wxyz"])]
            ent["size"] = list(size)
        ents.append(ent)
        if o.get("joint_position") is not None:
            ents[-1]["attributes"]["joint_position"] = o["joint_position"]
    for r in (scene or {}).get("regions") or ():
        cz = float(r["center"][2]) if len(r.get("center", ())) > 2 else 0.0
        ents.append({"name": r["name"], "kind": "region", "position": [float(r["center"][0]), float(r["center"][1]), cz],
                     "quat_wxyz": [1, 0, 0, 0], "size": [float(r["half_extents"][0]), float(r["half_extents"][1]), 0.0],
                     "attributes": {}})
    held = list(state.get("held") or ())
    relations = [{"subject": "gripper", "relation": "holding", "object": n, "confidence": 1.0} for n in held]
    return {"entities": ents, "relations": relations}


def truth_of_criteria(accept: Any, gt: Mapping[str, Any]) -> list[tuple[Criterion, bool | None]]:
    """Each acceptance criterion with its truth (``None``: not computable from ground truth)."""
    scene = gt.get("scene_record") or {}
    s0, s1 = truth_snapshot(gt.get("initial"), scene), truth_snapshot(gt.get("terminal"), scene)
    out = []
    for c in parse_criteria(accept):
        if c.name == "still":
            out.append((c, None))
            continue
        try:
            o = evaluate(c, s0, s1)
        except (KeyError, IndexError, TypeError, ValueError):  # a target whose ground truth lacks the geometry
            out.append((c, None))
            continue
        out.append((c, {"satisfied": True, "unsatisfied": False}.get(o.status)))
    return out


def score_session(*, accept: Any, verdict: Mapping[str, Any] | None, gt: Mapping[str, Any] | None) -> dict[str, Any]:
    """Confusion cells of one verified session.

    Args:
        accept: the session's acceptance criteria.
        verdict: its recorded verdict (``verdict`` and ``criteria`` with ``predicate`` and
            ``status``), as a mapping.
        gt: its ``ground_truth.yaml``; ``None`` makes the session unscored.

    Returns ``{"session": cell | None, "criteria": [{"predicate", "status", "truth", "cell"}],
    "truth_met": bool | None}``.
    """
    if gt is None or not verdict:
        return {"session": None, "criteria": [], "truth_met": None}
    recorded = {c.get("predicate"): c.get("status") for c in verdict.get("criteria") or ()}
    rows = []
    truths = []
    for c, truth in truth_of_criteria(accept, gt):
        status = recorded.get(c.text)
        if truth is None or status is None:
            cell = "unscorable"
        elif status == "satisfied":
            cell = "true_success" if truth else "false_success"
        elif status == "unknown":
            cell = "unknown_met" if truth else "true_failure"
        else:
            cell = "false_failure" if truth else "true_failure"
        rows.append({"predicate": c.text, "status": status, "truth": truth, "cell": cell})
        if truth is not None:
            truths.append(truth)
    if not truths or len(truths) < len(rows):  # some criterion's truth unknown: the session's too
        return {"session": None, "criteria": rows, "truth_met": None}
    met = all(truths)
    success = verdict.get("verdict") == "success"
    cell = ("true_success" if met else "false_success") if success else ("false_failure" if met else "true_failure")
    return {"session": cell, "criteria": rows, "truth_met": met}


def _rate(k: int, n: int) -> float | None:
    return round(100.0 * k / n, 3) if n else None


def wilson_interval(k: int, n: int, *, z: float = 1.96) -> tuple[float, float] | None:
    """Wilson score interval of a rate ``k / n`` (Wilson 1927, JASA 22:209), in percent
    (``z = 1.96``: 95 %); ``None`` for ``n == 0``."""
    if not n:
        return None
    p = k / n
    d = 1.0 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return (round(100.0 * max(0.0, c - h), 3), round(100.0 * min(1.0, c + h), 3))


def _predicate_rates(row: Mapping[str, int]) -> dict[str, Any]:
    """Per-criterion rates: false success = ``false_success`` / scored, false failure =
    (``false_failure`` + ``unknown_met``: not satisfied while met) / scored, with Wilson
    95 % intervals (percent)."""
    n = sum(v for k, v in row.items() if k != "unscorable")
    ff = row["false_failure"] + row["unknown_met"]
    return {"scored": n, "false_success_pct": _rate(row["false_success"], n),
            "false_success_ci95_pct": wilson_interval(row["false_success"], n),
            "false_failure_pct": _rate(ff, n), "false_failure_ci95_pct": wilson_interval(ff, n)}


def confusion(scores: Iterable[Mapping[str, Any]]) -> dict[str, Any]:
    """Aggregate :func:`score_session` results (each with an optional ``session_id``) into the
    per-session and per-criterion confusion matrices with rates in percent and the ids
    behind every false success and false failure."""
    sessions = {k: 0 for k in _SESSION_CELLS}
    criteria = {k: 0 for k in _CRITERION_CELLS}
    per_predicate: dict[str, dict[str, int]] = {}
    false_success, false_failure, unscored = [], [], []
    for s in scores:
        sid = s.get("session_id")
        if s.get("session") is None:
            unscored.append(sid)
        else:
            sessions[s["session"]] += 1
            if s["session"] == "false_success":
                false_success.append(sid)
            elif s["session"] == "false_failure":
                false_failure.append(sid)
        for c in s.get("criteria") or ():
            criteria[c["cell"]] += 1
            name = c["predicate"].split("(", 1)[0]
            per_predicate.setdefault(name, {k: 0 for k in _CRITERION_CELLS})[c["cell"]] += 1
    n = sum(sessions.values())
    unmet = sessions["false_success"] + sessions["true_failure"]
    met = sessions["true_success"] + sessions["false_failure"]
    return {
        "sessions_scored": n, "sessions_unscored": len(unscored), "unscored_sessions": unscored,
        "session_matrix": sessions, "criterion_matrix": criteria, "per_predicate": per_predicate,
        "false_success_rate_pct": _rate(sessions["false_success"], n),
        "false_success_given_unmet_pct": _rate(sessions["false_success"], unmet),
        "false_failure_rate_pct": _rate(sessions["false_failure"], n),
        "false_failure_given_met_pct": _rate(sessions["false_failure"], met),
        "false_success_sessions": false_success, "false_failure_sessions": false_failure,
        "false_success_ci95_pct": wilson_interval(sessions["false_success"], n),
        "false_failure_ci95_pct": wilson_interval(sessions["false_failure"], n),
        "per_predicate_rates": {k: _predicate_rates(row) for k, row in per_predicate.items()},
    }
