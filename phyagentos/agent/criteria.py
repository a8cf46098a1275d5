"""Acceptance criteria: structured predicates over environment snapshots.

A node's ``accept`` is a mapping (or a list of one-key mappings) from predicate
name to arguments, parsed without ``eval``::

    accept:
      holding: cube                              # the gripper holds cube at the end
      lifted: {object: cube, min_height: 0.05}   # cube rose >= 5 cm (terminal - initial z)
      inside: {object: cube, region: goal}       # cube rests inside the region footprint
      on: {object: blue, support: red}           # blue rests on red
      released: cube                             # the gripper does not hold cube
      still: {max_joint_motion_rad: 0.01}        # the arm did not move
      unchanged: {object: red, tol_m: 0.01}      # red did not move
      articulated: {object: microwave, max: -0.6}  # its joint (rad or m) ends in [min, max]
      has: {item: wood, min: 1}                  # game: the player's inventory (or a vital) >= min at the end
      achieved: collect_wood                     # game: the achievement is in the player's terminal record

Snapshots are ENVIRONMENT-style mappings: ``entities`` (name, kind, position (3,) m
world, quat_wxyz, size (3,) half extents m, attributes) and ``relations``. The
predicates judge geometry themselves rather than trusting the target's relations,
so a mis-reporting target cannot pass its own exam.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

from phyagentos.errors import VerifierError, format_choices

__all__ = ["Criterion", "CriterionOutcome", "parse_criteria", "PREDICATES", "evaluate"]

# Tolerances, metres. A resting box's centre sits at its half height above its
# support; 1 cm absorbs contact penetration and settling.
REST_TOL_M = 0.01


@dataclass(frozen=True)
class Criterion:
    """One parsed acceptance predicate: ``name`` with normalised ``args``."""

    name: str
    args: Mapping[str, Any]
    text: str  # compact human form, e.g. "inside(object=cube, region=goal)"


@dataclass(frozen=True)
class CriterionOutcome:
    """Judgement of one criterion: status satisfied / unsatisfied / unknown."""

    criterion: Criterion
    status: str
    reason: str
    evidence: tuple[str, ...] = field(default_factory=tuple)


# predicate -> (required args, optional args with defaults, positional shorthand arg)
_SIGNATURES: dict[str, tuple[tuple[str, ...], dict[str, Any], str | None]] = {
    "holding": (("object",), {}, "object"),
    "released": (("object",), {}, "object"),
    "lifted": (("object",), {"min_height": 0.05}, "object"),
    "inside": (("object", "region"), {}, None),
    "on": (("object", "support"), {}, None),
    "still": ((), {"max_joint_motion_rad": 0.01}, None),
    "unchanged": (("object",), {"tol_m": 0.01}, "object"),
    "articulated": (("object",), {"min": -math.inf, "max": math.inf}, "object"),
    "has": (("item",), {"min": 1.0, "entity": "player"}, "item"),
    "achieved": (("achievement",), {"entity": "player"}, "achievement"),
}
PREDICATES = tuple(sorted(_SIGNATURES))


def parse_criteria(accept: Any, *, where: str = "accept") -> list[Criterion]:
    """Parse an ``accept`` block into :class:`Criterion` objects.

    Args:
        accept: mapping name -> args, or a list of one-key mappings.
        where: location prefix for error messages (e.g. ``"goal.yaml:12"``).

    Raises:
        VerifierError: unknown predicate (valid ones listed), missing or unknown
            arguments, or a non-numeric threshold.
    """
    if accept is None:
        return []
    items: list[tuple[str, Any]] = []
    if isinstance(accept, Mapping):
        items = list(accept.items())
    elif isinstance(accept, list):
        for entry in accept:
            if not isinstance(entry, Mapping) or len(entry) != 1:
                raise VerifierError(f"{where}: list entries must be one-key mappings like {{holding: cube}}, found {entry!r}")
            items.extend(entry.items())
    else:
        raise VerifierError(f"{where}: accept must be a mapping or list, found {type(accept).__name__}")
    out = []
    for name, raw in items:
        if name not in _SIGNATURES:
            raise VerifierError(f"{where}: unknown predicate {name!r}; valid predicates: {format_choices(PREDICATES)}")
        required, optional, shorthand = _SIGNATURES[name]
        if isinstance(raw, Mapping):
            args = dict(raw)
        elif raw is None and not required:
            args = {}
        elif shorthand is not None and isinstance(raw, str):
            args = {shorthand: raw}
        else:
            raise VerifierError(f"{where}: {name}: expected a mapping with {format_choices(required + tuple(optional))}, found {raw!r}")
        missing = [a for a in required if a not in args]
        unknown = [a for a in args if a not in required and a not in optional]
        if missing or unknown:
            raise VerifierError(
                f"{where}: {name}: missing {missing or 'nothing'}, unknown {unknown or 'nothing'}; "
                f"arguments: {format_choices(required + tuple(optional))}"
            )
        for key, default in optional.items():
            args.setdefault(key, default)
            if isinstance(default, float) and not isinstance(args[key], (int, float)):
                raise VerifierError(f"{where}: {name}.{key} must be a number, found {args[key]!r}")
        text = f"{name}(" + ", ".join(f"{k}={v}" for k, v in args.items()) + ")"
        out.append(Criterion(name=name, args=args, text=text))
    return out


def _entities(snapshot: Mapping) -> dict[str, Mapping]:
    return {e["name"]: e for e in snapshot.get("entities", [])}


def _holding(snapshot: Mapping, obj: str) -> bool:
    return any(r.get("relation") == "holding" and r.get("object") == obj for r in snapshot.get("relations", []))


def _rests_inside(ent: Mapping, region: Mapping) -> tuple[bool, str]:
    (x, y, z), (hx, hy, _) = ent["position"], region["size"]
    cx, cy, cz = region["position"]
    dx, dy = abs(x - cx), abs(y - cy)
    in_xy = dx <= hx and dy <= hy
    rest_z = cz + ent["size"][2]
    resting = abs(z - rest_z) <= REST_TOL_M
    return in_xy and resting, (
        f"|dx|={dx:.3f} m (<= {hx:.3f}), |dy|={dy:.3f} m (<= {hy:.3f}), z={z:.3f} m (rest {rest_z:.3f} +- {REST_TOL_M})"
    )


def evaluate(criterion: Criterion, initial: Mapping, terminal: Mapping, *, refs: tuple[str, ...] = ()) -> CriterionOutcome:
    """Judge one criterion on the initial and terminal snapshots.

    Returns ``unknown`` (never a guess) when an entity the criterion names is
    absent from the evidence.
    """
    return _EVALUATORS[criterion.name](criterion, initial, terminal, refs)


def _need(criterion, refs, *pairs) -> CriterionOutcome | None:
    for snap_name, snap, key in pairs:
        if key not in _entities(snap):
            return CriterionOutcome(criterion, "unknown", f"{key!r} not in the {snap_name} snapshot", refs)
    return None


def _eval_holding(c, initial, terminal, refs):
    obj = c.args["object"]
    if (miss := _need(c, refs, ("terminal", terminal, obj))):
        return miss
    ok = _holding(terminal, obj)
    return CriterionOutcome(c, "satisfied" if ok else "unsatisfied", f"gripper {'holds' if ok else 'does not hold'} {obj}", refs)


def _eval_released(c, initial, terminal, refs):
    obj = c.args["object"]
    if (miss := _need(c, refs, ("terminal", terminal, obj))):
        return miss
    ok = not _holding(terminal, obj)
    return CriterionOutcome(c, "satisfied" if ok else "unsatisfied", f"gripper {'released' if ok else 'still holds'} {obj}", refs)


def _eval_lifted(c, initial, terminal, refs):
    obj = c.args["object"]
    if (miss := _need(c, refs, ("initial", initial, obj), ("terminal", terminal, obj))):
        return miss
    dz = _entities(terminal)[obj]["position"][2] - _entities(initial)[obj]["position"][2]
    ok = dz >= float(c.args["min_height"])
    return CriterionOutcome(c, "satisfied" if ok else "unsatisfied", f"{obj} rose {dz:.3f} m (need >= {c.args['min_height']})", refs)


def _eval_inside(c, initial, terminal, refs):
    obj, region = c.args["object"], c.args["region"]
    if (miss := _need(c, refs, ("terminal", terminal, obj), ("terminal", terminal, region))):
        return miss
    ents = _entities(terminal)
    ok, detail = _rests_inside(ents[obj], ents[region])
    if _holding(terminal, obj):
        ok, detail = False, detail + "; still held by the gripper"
    return CriterionOutcome(c, "satisfied" if ok else "unsatisfied", f"{obj} {'inside' if ok else 'not inside'} {region}: {detail}", refs)


def _eval_on(c, initial, terminal, refs):
    obj, support = c.args["object"], c.args["support"]
    if (miss := _need(c, refs, ("terminal", terminal, obj), ("terminal", terminal, support))):
        return miss
    ents = _entities(terminal)
    # the support's top face is at its centre + half height
    top = ents[support]["position"][2] + ents[support]["size"][2]
    z = ents[obj]["position"][2]
    resting = abs(z - (top + ents[obj]["size"][2])) <= REST_TOL_M
    sx, sy = ents[support]["size"][:2]
    dx = abs(ents[obj]["position"][0] - ents[support]["position"][0])
    dy = abs(ents[obj]["position"][1] - ents[support]["position"][1])
    ok = resting and dx <= sx and dy <= sy and not _holding(terminal, obj)
    return CriterionOutcome(c, "satisfied" if ok else "unsatisfied",
                            f"{obj} {'on' if ok else 'not on'} {support}: |dx|={dx:.3f}, |dy|={dy:.3f}, z={z:.3f} (top {top:.3f})", refs)


def _eval_still(c, initial, terminal, refs):
    def joints(snap):
        for e in snap.get("entities", []):
            q = e.get("attributes", {}).get("joint_positions")
            if q is not None:
                return q
        return None

    q0, q1 = joints(initial), joints(terminal)
    if q0 is None or q1 is None:
        return CriterionOutcome(c, "unknown", "joint positions missing from a snapshot", refs)
    motion = max(abs(a - b) for a, b in zip(q0, q1))
    ok = motion <= float(c.args["max_joint_motion_rad"])
    return CriterionOutcome(c, "satisfied" if ok else "unsatisfied",
                            f"largest joint motion {motion:.4f} rad (limit {c.args['max_joint_motion_rad']})", refs)


def _eval_unchanged(c, initial, terminal, refs):
    obj = c.args["object"]
    if (miss := _need(c, refs, ("initial", initial, obj), ("terminal", terminal, obj))):
        return miss
    p0, p1 = _entities(initial)[obj]["position"], _entities(terminal)[obj]["position"]
    d = math.dist(p0, p1)
    ok = d <= float(c.args["tol_m"])
    return CriterionOutcome(c, "satisfied" if ok else "unsatisfied", f"{obj} moved {d:.3f} m (tolerance {c.args['tol_m']})", refs)


def _eval_articulated(c, initial, terminal, refs):
    obj = c.args["object"]
    if (miss := _need(c, refs, ("terminal", terminal, obj))):
        return miss
    q = (_entities(terminal)[obj].get("attributes") or {}).get("joint_position")
    if q is None:
        return CriterionOutcome(c, "unknown", f"{obj!r} reports no joint_position (not an articulation?)", refs)
    lo, hi = float(c.args["min"]), float(c.args["max"])
    ok = lo <= float(q) <= hi
    return CriterionOutcome(c, "satisfied" if ok else "unsatisfied",
                            f"{obj} joint at {float(q):.3f} ({'within' if ok else 'outside'} [{lo}, {hi}])", refs)


def _player(c, snap, name, refs):
    ent = _entities(snap).get(c.args["entity"])
    if ent is None:
        return None, CriterionOutcome(c, "unknown", f"{c.args['entity']!r} not in the {name} snapshot", refs)
    return ent.get("attributes") or {}, None


def _eval_has(c, initial, terminal, refs):
    attrs, miss = _player(c, terminal, "terminal", refs)
    if miss:
        return miss
    item = c.args["item"]
    counts = {**(attrs.get("inventory") or {}), **(attrs.get("vitals") or {})}
    if item not in counts:
        return CriterionOutcome(c, "unknown", f"the player's inventory reports no {item!r}", refs)
    n, need = counts[item], float(c.args["min"])
    ok = n >= need
    return CriterionOutcome(c, "satisfied" if ok else "unsatisfied", f"{item}: {n} (need >= {need:g})", refs)


def _eval_achieved(c, initial, terminal, refs):
    attrs, miss = _player(c, terminal, "terminal", refs)
    if miss:
        return miss
    if "achievements" not in attrs:
        return CriterionOutcome(c, "unknown", "the terminal snapshot reports no achievements", refs)
    a = c.args["achievement"]
    ok = a in attrs["achievements"]
    return CriterionOutcome(c, "satisfied" if ok else "unsatisfied",
                            f"{a} {'unlocked' if ok else 'not unlocked'} (step {attrs.get('step')})", refs)


_EVALUATORS: dict[str, Callable] = {
    "holding": _eval_holding,
    "released": _eval_released,
    "lifted": _eval_lifted,
    "inside": _eval_inside,
    "on": _eval_on,
    "still": _eval_still,
    "unchanged": _eval_unchanged,
    "articulated": _eval_articulated,
    "has": _eval_has,
    "achieved": _eval_achieved,
}
