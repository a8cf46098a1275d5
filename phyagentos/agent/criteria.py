"""Acceptance criteria: structured predicates over environment snapshots.

A node's ``accept`` is a mapping (or a list of one-key mappings) from predicate
name to arguments, parsed without ``eval``::

    accept:
      holding: cube                              # the gripper holds cube at the end
      lifted: {object: cube, min_height: 0.05}   # cube rose >= 5 cm (terminal - initial z)
      inside: {object: cube, region: goal}       # cube rests inside the region footprint
      on: {object: blue, support: red}           # blue rests on red
      beside: {object: pudding, landmark: plate, side: right}  # on the viewer's right of the plate
      released: cube                             # the gripper does not hold cube
      still: {max_joint_motion_rad: 0.01}        # the arm did not move
      unchanged: {object: red, tol_m: 0.01}      # red did not move
      articulated: {object: microwave, max: -0.6}  # its joint (rad or m) ends in [min, max]
      articulated: {object: stove, min_fraction: 0.33}  # ... and at least 1/3 along its range_rad (range_m)
      has: {item: wood, min: 1}                  # game: the player's inventory (or a vital) >= min at the end
      achieved: collect_wood                     # game: the achievement is in the player's terminal record

Snapshots are the runtime's *perceived* snapshots (CONTRACT_9 section 3): ``entities``
(name, kind, position (3,) m world, quat_wxyz, size (3,) half extents m, attributes with
``confidence`` 0..1 and ``position_std_m``, the 1-sigma horizontal uncertainty) and
``relations`` (``holding`` from proprioception plus perceived geometry, with a confidence).
Geometric predicates judge the perceived geometry themselves.

Uncertainty (the formula): with sigma the entity's ``position_std_m`` (for a predicate
over two perceived entities or two snapshots, sigma = sqrt(sigma_a^2 + sigma_b^2)), a
criterion is ``satisfied`` only when it holds with a margin of 2 sigma (``inside``: the
centre lies in the region's footprint shrunk by 2 sigma and rests within
``REST_TOL_M + 2 sigma`` of its surface; ``on`` a perceived support: the centre (the model
origin where perception reports one, ``origin_xy``: a moka pot's handle overhangs the burner
plate its body stands on) in its footprint shrunk by 2 sigma, the bottom from
:data:`SUPPORT_FLOOR_M` above the support's bottom (and at most :data:`DISH_DEPTH_M` below its
top: a dish's floor) up to ``REST_TOL_M``
above its top, by 2 sigma; below the top (in a dish), within :data:`DISH_CENTRE_M` of the
support's centre too, else it leans on the rim; on a flat support (no taller than
:data:`DISH_DEPTH_M`: a plate) with its whole footprint over it, or within
:data:`DISH_CENTRE_M` of its centre where it is as wide (not on a floor between walls, perception's
``walls_m``: a compartment's or an open drawer's walls hold what stands in it); ``unchanged``: moved <= tol - 2 sigma; ``lifted``:
rose >= min_height + 2 sigma), ``unsatisfied`` only when it fails by more than 2 sigma,
and ``unknown`` in between (at 2 sigma a Gaussian error crosses the boundary with
probability <= 2.3 %, one-sided). ``on`` and ``inside`` with a container (a perceived
object, e.g. a basket) are judged on the perceived relation ``inside(object, container)``
when perception reports one: the object was seen standing inside the container's segment
(its walls may hide it from other views; perception then reports it ``remembered``); the
centre must lie in the container's footprint by 2 sigma. ``on`` a fixture with a ramp (LIBERO's
wine rack) is judged so on the perceived relation ``leant_on(object, fixture)``: the object seen
lying on the ramp where the hand let it go (``perception.lean``). Without that relation, an object
resting at the rim's height of an open container deeper than :data:`DISH_DEPTH_M`
(``attributes.open_depth_m``, perceived: a basket) is never ``on`` it: it lies on the rim
(LIBERO's ``In`` does not count that), or shows only its part above the walls (in it, but not
seen so: ``unknown`` until it is). Down in such a container (its bottom below the rim by 2
sigma) it is ``on`` it when its centre lies its own short half width inside the footprint by
2 sigma (within the walls), wherever its base (perception sees the floor only as far down as
its views reach). An entity absent from a snapshot, or with
``confidence`` below :data:`CONFIDENCE_MIN`, makes the criterion ``unknown``: never
guessed, never ``success``. One stand-in: the support of ``on`` hidden by what was set on it
(a plate under a mug, seen only as the ring around it) is taken where the initial snapshot saw
it confidently, when the terminal snapshot still sees it, however weakly, within
:data:`SUPPORT_STILL_M` plus 2 sigma of that place (it did not move).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

from phyagentos.errors import VerifierError, format_choices

__all__ = ["Criterion", "CriterionOutcome", "parse_criteria", "PREDICATES", "evaluate", "confidence", "sigma",
           "CONFIDENCE_MIN", "REST_TOL_M", "SUPPORT_FLOOR_M", "DISH_DEPTH_M", "DISH_CENTRE_M", "CLOSED_OPENING_M", "SQUEEZE_EFFORT_N"]

# Tolerances, metres. A resting box's centre sits at its half height above its
# support; 1 cm absorbs contact penetration and settling.
REST_TOL_M = 0.01
#: An object resting on a support has its bottom at least this far (m) above the support's
#: bottom: a dish's floor lies below its rim (LIBERO's plate holds a mug 7.9-9.2 mm over the
#: table), the table beside it does not. Below perception's own threshold for an object
#: standing on something hidden (``perceiver.HIDDEN_SUPPORT_M``, 4 mm), so what perception
#: raises is not undone here.
SUPPORT_FLOOR_M = 0.003
#: ... and at most this far (m) below the support's top (its rim): the depth of a dish's floor
#: under its rim (LIBERO's plate: 2.2 cm); an object deeper down in a tall support's footprint
#: is in it (a bowl in the cabinet's open drawer is not on the cabinet).
DISH_DEPTH_M = 0.03
#: Down in a dish (its bottom below the rim's top), an object rests level within this of the
#: dish's centre (m, by 2 sigma); further out it leans on the rim. Measured on LIBERO's plate
#: (LIBERO-10 task 4, LIBERO-90 tasks 67 and 68): mugs set 1.0-2.5 cm off its centre stood
#: level, one 3.7 cm off leant 7 degrees on the rim; LIBERO's own ``On`` asks 3 cm
#: (``check_ontop`` in its ``base_object_states.py``).
DISH_CENTRE_M = 0.025
#: Perceived entities and relations below this confidence do not count: a criterion
#: naming one is ``unknown``. 0.5: an association no better than a coin flip.
CONFIDENCE_MIN = 0.5
#: How far (m, beyond 2 sigma) a support of ``on`` seen weakly at the end may be from where the
#: initial snapshot saw it confidently, and still stand in for it (a plate hidden by the mug set on it).
SUPPORT_STILL_M = 0.01
#: ``beside``: the gap (m) between the landmark's edge and the object's near face on the side
#: named is at most this: next to it, not across the table. 8 cm: a plate dragged to the front of
#: libero_goal's stove and perceived with its near face 7.6 cm out stood 8.5 cm out, past LIBERO's
#: region for it (8.3 cm), and the 10 cm this was called it there (development scene, seed 505).
BESIDE_REACH_M = 0.08
#: ``beside``: how far across (a fraction of the landmark's half extent that way) the object's
#: centre may stand from the landmark's: in the middle half of its side, where "in front of it"
#: is not in doubt. A plate perceived 2.9 cm off the middle of a stove 19 cm wide stood 4.0 cm
#: off, at the edge of LIBERO's region (4 cm each way) (the same scene).
BESIDE_CENTRED = 0.5
#: ``beside``: the sides a landmark has, as the scene camera shows the table
#: (:data:`phyagentos.geometry.VIEWER_SIDES`: left, right, front towards the viewer, back).
SIDES = ("left", "right", "front", "back")
#: Per-finger opening above which a closed gripper holds *something*, m (CONTRACT_9
#: section 3: holding needs more than ~2 mm).
CLOSED_OPENING_M = 0.002
#: Finger effort above which a closed gripper squeezes something, N (the Franka Hand's
#: fingers move free with a few newtons; CONTRACT_9 section 3's "effort above a threshold").
SQUEEZE_EFFORT_N = 5.0


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
    "beside": (("object", "landmark", "side"), {}, None),
    "still": ((), {"max_joint_motion_rad": 0.01}, None),
    "unchanged": (("object",), {"tol_m": 0.01}, "object"),
    "articulated": (("object",), {"min": -math.inf, "max": math.inf, "min_fraction": -math.inf,
                                  "max_fraction": math.inf}, "object"),
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


def _attr(ent: Mapping, key: str, default: float) -> float:
    value = (ent.get("attributes") or {}).get(key)
    return default if value is None else float(value)


def confidence(ent: Mapping) -> float:
    """An entity's ``attributes.confidence`` (0..1). Declared entities (regions, obstacles)
    and proprioceptive ones carry none and count as certain (1.0)."""
    return _attr(ent, "confidence", 1.0)


def sigma(ent: Mapping) -> float:
    """An entity's 1-sigma horizontal position uncertainty ``attributes.position_std_m``, m
    (0 for declared and proprioceptive entities)."""
    return _attr(ent, "position_std_m", 0.0)


def _holding_relation(snapshot: Mapping, obj: str) -> Mapping | None:
    return next((r for r in snapshot.get("relations", [])
                 if r.get("relation") == "holding" and r.get("object") == obj), None)


def _gripper_squeezing(snapshot: Mapping) -> tuple[float, float] | None:
    """``(opening_m, effort_n)`` of the gripper entity when it squeezes something: opening
    above :data:`CLOSED_OPENING_M` and finger effort above :data:`SQUEEZE_EFFORT_N`;
    ``None`` otherwise or when the snapshot carries no gripper proprioception."""
    grip = next((e for e in snapshot.get("entities", []) if e.get("kind") == "gripper"), None)
    attrs = (grip or {}).get("attributes") or {}
    opening, effort = attrs.get("opening_m"), attrs.get("effort_n")
    if opening is None or effort is None:
        return None
    if float(opening) > CLOSED_OPENING_M and float(effort) > SQUEEZE_EFFORT_N:
        return float(opening), float(effort)
    return None


def _held(snapshot: Mapping, obj: str) -> tuple[bool | None, str]:
    """Whether the gripper holds ``obj``: ``True``/``False``, or ``None`` when the perceived
    relation is below the confidence threshold, or there is no relation while the gripper
    squeezes something and ``obj`` is not seen confidently elsewhere."""
    rel = _holding_relation(snapshot, obj)
    if rel is not None:
        conf = float(rel.get("confidence", 1.0))
        if conf >= CONFIDENCE_MIN:
            return True, f"gripper holds {obj} (confidence {conf:.2f})"
        return None, f"holding {obj} perceived with confidence {conf:.2f} < {CONFIDENCE_MIN}"
    ent = _entities(snapshot).get(obj)
    squeeze = _gripper_squeezing(snapshot)
    if (ent is None or confidence(ent) < CONFIDENCE_MIN) and squeeze is not None:
        return None, (f"gripper squeezes something (opening {squeeze[0] * 1000:.1f} mm, effort {squeeze[1]:.1f} N) "
                      f"and {obj} not seen confidently elsewhere")
    return False, f"gripper does not hold {obj}"


def _need(criterion, refs, *pairs) -> CriterionOutcome | None:
    """``unknown`` if an entity a criterion names is absent from a snapshot, or perceived
    with confidence below :data:`CONFIDENCE_MIN` (never guessed)."""
    for snap_name, snap, key in pairs:
        ent = _entities(snap).get(key)
        if ent is None:
            return CriterionOutcome(criterion, "unknown", f"{key!r} not in the {snap_name} snapshot", refs)
        if confidence(ent) < CONFIDENCE_MIN:
            return CriterionOutcome(criterion, "unknown", f"{key!r} perceived with confidence "
                                    f"{confidence(ent):.2f} < {CONFIDENCE_MIN} in the {snap_name} snapshot", refs)
    return None


def _band(c: Criterion, refs, inside: bool, outside: bool, subject: str, verb: str, detail: str) -> CriterionOutcome:
    """Three-way decision: satisfied with a 2-sigma margin, unsatisfied with a 2-sigma
    margin, else unknown (the uncertainty band straddles the boundary: look again)."""
    if inside:
        return CriterionOutcome(c, "satisfied", f"{subject} {verb}: {detail}", refs)
    if outside:
        return CriterionOutcome(c, "unsatisfied", f"{subject} not {verb}: {detail}", refs)
    return CriterionOutcome(c, "unknown", f"{subject} {verb}? undecided within the perception uncertainty: {detail}",
                            refs)


def _footprint(ent: Mapping, region: Mapping, s: float) -> tuple[bool, bool, str]:
    """(inside with margin, outside with margin, detail) of ``ent``'s centre in ``region``'s
    horizontal footprint and resting on its surface, with uncertainty ``s`` (m, 1 sigma)."""
    (x, y, z), (hx, hy, _) = ent["position"], region["size"]
    cx, cy, cz = region["position"]
    dx, dy = abs(x - cx), abs(y - cy)
    rest_z = cz + ent["size"][2]
    dz = abs(z - rest_z)
    m = 2.0 * s
    inside = dx <= hx - m and dy <= hy - m and dz <= REST_TOL_M + m
    outside = dx > hx + m or dy > hy + m or dz > REST_TOL_M + m
    return inside, outside, (f"|dx|={dx:.3f} m (<= {hx:.3f}), |dy|={dy:.3f} m (<= {hy:.3f}), z={z:.3f} m "
                             f"(rest {rest_z:.3f} +- {REST_TOL_M}), 2 sigma {m:.3f} m")


def evaluate(criterion: Criterion, initial: Mapping, terminal: Mapping, *, refs: tuple[str, ...] = ()) -> CriterionOutcome:
    """Judge one criterion on the initial and terminal (perceived) snapshots.

    Returns ``unknown`` (never a guess) when an entity the criterion names is absent
    from the evidence or perceived with confidence below :data:`CONFIDENCE_MIN`, or when
    the 2-sigma uncertainty band of a perceived position straddles the criterion's
    boundary (see the module docstring).
    """
    return _EVALUATORS[criterion.name](criterion, initial, terminal, refs)


def _eval_holding(c, initial, terminal, refs):
    held, detail = _held(terminal, c.args["object"])
    return CriterionOutcome(c, {True: "satisfied", False: "unsatisfied", None: "unknown"}[held], detail, refs)


def _eval_released(c, initial, terminal, refs):
    obj = c.args["object"]
    held, detail = _held(terminal, obj)
    if held is None:
        return CriterionOutcome(c, "unknown", detail, refs)
    return CriterionOutcome(c, "unsatisfied" if held else "satisfied",
                            f"gripper {'still holds' if held else 'released'} {obj}", refs)


def _eval_lifted(c, initial, terminal, refs):
    obj = c.args["object"]
    if (miss := _need(c, refs, ("initial", initial, obj), ("terminal", terminal, obj))):
        return miss
    e0, e1 = _entities(initial)[obj], _entities(terminal)[obj]
    dz = e1["position"][2] - e0["position"][2]
    need = float(c.args["min_height"])
    m = 2.0 * math.hypot(sigma(e0), sigma(e1))
    return _band(c, refs, dz >= need + m, dz < need - m, obj, "lifted",
                 f"rose {dz:.3f} m (need >= {need}, 2 sigma {m:.3f} m)")


def _contained(c, refs, terminal, obj, container, relation: str = "inside") -> CriterionOutcome | None:
    """The verdict of ``obj`` in/on ``container`` when perception reports the relation
    ``inside(obj, container)`` (the object was seen standing inside the container's segment,
    e.g. from above, between its walls), or ``relation`` instead (``leant_on``: seen lying on
    a fixture's ramp where the hand let it go, ``perception.lean``): satisfied when that
    relation's confidence is at least :data:`CONFIDENCE_MIN`, the gripper has let go and the
    object's centre lies in the container's footprint shrunk by 2 sigma; unsatisfied when it
    lies outside it by 2 sigma or is still held; else unknown. ``None`` when no such relation
    is reported (the geometric tests then decide)."""
    rel = next((r for r in terminal.get("relations", []) if r.get("relation") == relation
                and r.get("subject") == obj and r.get("object") == container), None)
    if rel is None:
        return None
    verb = "inside" if relation == "inside" else relation.replace("_", " ")
    conf = float(rel.get("confidence", 1.0))
    if conf < CONFIDENCE_MIN:
        return CriterionOutcome(c, "unknown", f"{obj} {verb} {container} perceived with confidence {conf:.2f} "
                                f"< {CONFIDENCE_MIN}", refs)
    ents = _entities(terminal)
    o, s = ents[obj], ents[container]
    m = 2.0 * math.hypot(sigma(o), sigma(s))
    dx, dy = abs(o["position"][0] - s["position"][0]), abs(o["position"][1] - s["position"][1])
    sx, sy = s["size"][:2]
    held, _ = _held(terminal, obj)
    src = (o.get("attributes") or {}).get("source", "perceived")
    return _band(c, refs, dx <= sx - m and dy <= sy - m and held is False, dx > sx + m or dy > sy + m or bool(held),
                 obj, f"{verb} {container}", f"seen {verb} it (relation confidence {conf:.2f}, {src}); |dx|={dx:.3f} "
                 f"(<= {sx:.3f}), |dy|={dy:.3f} (<= {sy:.3f}), 2 sigma {m:.3f} m")


def _eval_inside(c, initial, terminal, refs):
    obj, region = c.args["object"], c.args["region"]
    if (miss := _need(c, refs, ("terminal", terminal, obj), ("terminal", terminal, region))):
        return miss
    if (held_in := _contained(c, refs, terminal, obj, region)) is not None:
        return held_in
    ents = _entities(terminal)
    held, _ = _held(terminal, obj)
    inside, outside, detail = _footprint(ents[obj], ents[region], sigma(ents[obj]))
    if held:
        inside, outside, detail = False, True, detail + "; still held by the gripper"
    return _band(c, refs, inside and held is False, outside, obj, f"inside {region}", detail)


def _still_support(initial: Mapping, terminal: Mapping, support: str) -> Mapping | None:
    """The initial snapshot's confident sighting of ``support`` when the terminal snapshot sees it
    only weakly (below :data:`CONFIDENCE_MIN`: hidden by what was set on it) within
    :data:`SUPPORT_STILL_M` + 2 sigma of it, horizontally; else None."""
    e0, e1 = _entities(initial).get(support), _entities(terminal).get(support)
    if e0 is None or e1 is None or confidence(e0) < CONFIDENCE_MIN or confidence(e1) >= CONFIDENCE_MIN:
        return None
    d = math.hypot(e1["position"][0] - e0["position"][0], e1["position"][1] - e0["position"][1])
    return e0 if d <= SUPPORT_STILL_M + 2.0 * math.hypot(sigma(e0), sigma(e1)) else None


def _in_frame_of(ent: Mapping, dx: float, dy: float) -> tuple[float, float]:
    """``(|dx'|, |dy'|)``, m: the horizontal offset (``dx``, ``dy``) world m along the x and y axes
    of ``ent``'s box, turned by its yaw about z (``quat_wxyz``; a box turned with what it stands
    for, such as a drawer's floor in a turned cabinet); the world axes for an unturned box."""
    from phyagentos.geometry import quat_yaw  # noqa: PLC0415 - numpy only where a turned support is judged

    q = ent.get("quat_wxyz")
    if not q or len(q) != 4:
        return abs(dx), abs(dy)
    yaw = quat_yaw(q)
    c, s = math.cos(yaw), math.sin(yaw)
    return abs(c * dx + s * dy), abs(-s * dx + c * dy)


def _eval_on(c, initial, terminal, refs):
    obj, support = c.args["object"], c.args["support"]
    still = _still_support(initial, terminal, support)
    if (miss := _need(c, refs, ("terminal", terminal, obj), *(() if still else (("terminal", terminal, support),)))):
        return miss
    if (held_in := _contained(c, refs, terminal, obj, support)) is not None:  # a container: resting in it
        return held_in
    if (leant := _contained(c, refs, terminal, obj, support, "leant_on")) is not None:  # lying on its ramp
        return leant
    ents = _entities(terminal)
    o, s = ents[obj], still or ents[support]
    m = 2.0 * math.hypot(sigma(o), sigma(s))
    # the support's top face is at its centre + half height; a dish's floor (a plate's) lies
    # below its rim: the object's bottom may rest up to DISH_DEPTH_M below that top, never
    # down at the table the support stands on
    top = s["position"][2] + s["size"][2]
    floor = max(s["position"][2] - s["size"][2] + SUPPORT_FLOOR_M, top - DISH_DEPTH_M)
    z = o["position"][2]
    bottom = z - o["size"][2]
    sx, sy = s["size"][:2]
    dx, dy = _in_frame_of(s, o["position"][0] - s["position"][0], o["position"][1] - s["position"][1])
    held, _ = _held(terminal, obj)
    rests = floor <= bottom <= top + REST_TOL_M + m  # floor: a height threshold, not widened by the horizontal sigma
    # down in a dish (below its rim): level only near its centre, else it leans on the rim; on a
    # flat support (a plate, no taller than a dish is deep): its whole footprint over it, or
    # within DISH_CENTRE_M of its centre when it is as wide (a bowl set off a plate's middle
    # rests on its rim and the table)
    in_dish = bottom < top - REST_TOL_M
    # an open container deeper than a dish (perception's ``open_depth_m``: a basket) is not
    # stood on: what rests at its rim's height lies on the rim, or shows only its part above
    # the walls; in it is what perception sees inside it (the inside relation, above)
    depth = _attr(s, "open_depth_m", 0.0)
    deep = depth > DISH_DEPTH_M
    on_rim = deep and not in_dish
    # ... and down in one, an object stands inside its walls: its centre at least its own short
    # half width in from them (by 2 sigma), wherever on the floor (perception reads the floor
    # only as far down as it sees it, and an object's base there is hidden: no floor bound)
    short = float(min(o["size"][0], o["size"][1]))
    down_in = (deep and bottom < top - REST_TOL_M - m and dx <= sx - short - m and dy <= sy - short - m
               and held is False)
    flat = 2.0 * s["size"][2] <= DISH_DEPTH_M
    # a floor between walls (a caddy's compartment, an open drawer: perception's ``walls_m``): the walls hold
    # what stands on it (a book upright in a slot 5.8 cm wide), nothing leans off it on a rim
    walled = _attr(s, "walls_m", 0.0) > 0.0
    reach = (DISH_CENTRE_M if in_dish else (max(DISH_CENTRE_M, min(sx, sy) - max(o["size"][:2])) if flat else math.inf)
             ) if not walled else math.inf
    # how far off the support's centre: from the object's model origin where perception gives
    # it (a mug's: its cup's axis, moved towards its handle), else from its centre
    origin = (o.get("attributes") or {}).get("origin_xy")
    if not (isinstance(origin, (list, tuple)) and len(origin) == 2):
        origin = None
    # ... and whether it stands over the support's footprint: from that origin too (a moka pot's
    # handle overhangs a stove's burner plate its body stands on; LIBERO's ``On`` onto a site
    # asks the same of the model origin: ``SiteObject.under``, libero/envs/objects/site_object.py)
    if origin is not None:
        off = math.hypot(float(origin[0]) - s["position"][0], float(origin[1]) - s["position"][1])
        m_off = 2.0 * math.hypot(_attr(o, "origin_std_m", sigma(o)), sigma(s))
        fx, fy = _in_frame_of(s, float(origin[0]) - s["position"][0], float(origin[1]) - s["position"][1])
    else:
        off, m_off, fx, fy = math.hypot(dx, dy), m, dx, dy
    inside = (rests and fx <= sx - m_off and fy <= sy - m_off and held is False and off <= reach - m_off
              and not on_rim or down_in)
    outside = (bottom > top + REST_TOL_M + m or (bottom < floor - m and not deep) or fx > sx + m_off
               or fy > sy + m_off or bool(held) or (off > reach + m_off and not deep))
    return _band(c, refs, inside, outside, obj, f"on {support}",
                 f"|dx|={dx:.3f}, |dy|={dy:.3f}, z={z:.3f} (top {top:.3f}), 2 sigma {m:.3f} m"
                 + (f"; its origin {off:.3f} m off the centre, |dx|={fx:.3f}, |dy|={fy:.3f} (reach {reach:.3f}, "
                    f"2 sigma {m_off:.3f})" if origin is not None else "")
                 + (f"; at the rim of an open container {depth:.3f} m deep: in it only where seen inside it"
                    if on_rim else "")
                 + (f"; down in an open container at least {depth:.3f} m deep, inside its walls" if down_in else "")
                 + (f"; {support} where the initial snapshot saw it (seen weakly there now)" if still else ""))


def _extent(ent: Mapping, d: tuple[float, float]) -> float:
    """Half extent (m) of ``ent``'s box (``quat_wxyz``, half ``size``) along the horizontal unit vector ``d``."""
    from phyagentos.geometry import quat_to_matrix  # noqa: PLC0415 - numpy only where a beside is judged

    R = quat_to_matrix(ent.get("quat_wxyz") or (1.0, 0.0, 0.0, 0.0))
    return float(abs(R.T @ (d[0], d[1], 0.0)) @ [float(h) for h in ent["size"]])


def _body(ent: Mapping) -> Mapping:
    """``ent`` as a landmark: a fixture's whole body (``attributes.body``: position, yaw, size) where
    perception reports one (its entity's box is its place patch: the stove's burner), else itself."""
    body = (ent.get("attributes") or {}).get("body")
    if not (isinstance(body, Mapping) and len(body.get("position") or ()) == 3 and len(body.get("size") or ()) == 3):
        return ent
    from phyagentos.geometry import yaw_quat  # noqa: PLC0415 - numpy only where a beside is judged

    return {**ent, "position": list(body["position"]), "size": list(body["size"]),
            "quat_wxyz": yaw_quat(float(body.get("yaw") or 0.0))}


def _eval_beside(c, initial, terminal, refs):
    """``object`` on the table on the viewer's ``side`` of ``landmark`` (left, right, front: towards the
    viewer, back): its centre beyond the landmark's edge that way by 2 sigma (a fixture's whole body,
    not its place patch: :func:`_body`), its near face at most :data:`BESIDE_REACH_M` beyond that edge,
    level with the landmark across (within :data:`BESIDE_CENTRED` of its half extent), its bottom at the landmark's bottom (both
    on the same surface), not held. The viewer's right is the perceived snapshot's ``viewer.right_xy``
    (the scene camera's image x axis on the table; the other sides from it:
    :func:`phyagentos.geometry.viewer_side_xy`); without it, unknown."""
    obj, landmark, side = c.args["object"], c.args["landmark"], c.args["side"]
    if side not in SIDES:
        return CriterionOutcome(c, "unknown", f"side {side!r} is not one of {format_choices(SIDES)}", refs)
    still = _still_support(initial, terminal, landmark)
    if (miss := _need(c, refs, ("terminal", terminal, obj), *(() if still else (("terminal", terminal, landmark),)))):
        return miss
    right = (terminal.get("viewer") or {}).get("right_xy")
    if not right or len(right) != 2:
        return CriterionOutcome(c, "unknown", "the snapshot says nothing of the viewer's left and right", refs)
    if not math.hypot(float(right[0]), float(right[1])) > 0:
        return CriterionOutcome(c, "unknown", "the snapshot's viewer.right_xy is zero", refs)
    from phyagentos.geometry import viewer_side_xy  # noqa: PLC0415 - numpy only where a beside is judged

    dx, dy = viewer_side_xy(right, side)
    d = (float(dx), float(dy))
    across = (-d[1], d[0])
    o, lm = _entities(terminal)[obj], _body(still or _entities(terminal)[landmark])
    rel = (o["position"][0] - lm["position"][0], o["position"][1] - lm["position"][1])
    along = rel[0] * d[0] + rel[1] * d[1]
    lateral = abs(rel[0] * across[0] + rel[1] * across[1])
    edge, width, face = _extent(lm, d), BESIDE_CENTRED * _extent(lm, across), _extent(o, d)
    dz = abs((o["position"][2] - o["size"][2]) - (lm["position"][2] - lm["size"][2]))
    m = 2.0 * math.hypot(sigma(o), sigma(lm))
    held, _ = _held(terminal, obj)
    gap = along - face - edge
    inside = (edge + m < along and gap <= BESIDE_REACH_M - m and lateral <= width - m
              and dz <= REST_TOL_M + m and held is False)
    outside = (along < edge - m or gap > BESIDE_REACH_M + m or lateral > width + m
               or dz > REST_TOL_M + m or bool(held))
    return _band(c, refs, inside, outside, obj, f"on the {side} of {landmark}",
                 f"{along:.3f} m its way from the centre (edge {edge:.3f}; its near face {gap:.3f} m beyond it, "
                 f"reach {BESIDE_REACH_M}), {lateral:.3f} m across (<= {width:.3f}), bottoms {dz:.3f} m apart, "
                 f"2 sigma {m:.3f} m")


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
    e0, e1 = _entities(initial)[obj], _entities(terminal)[obj]
    d = math.dist(e0["position"], e1["position"])
    tol = float(c.args["tol_m"])
    m = 2.0 * math.hypot(sigma(e0), sigma(e1))
    return _band(c, refs, d <= tol - m, d > tol + m, obj, "unchanged",
                 f"moved {d:.3f} m (tolerance {tol}, 2 sigma {m:.3f} m)")


def _eval_articulated(c, initial, terminal, refs):
    obj = c.args["object"]
    if (miss := _need(c, refs, ("terminal", terminal, obj))):
        return miss
    attrs = _entities(terminal)[obj].get("attributes") or {}
    q = attrs.get("joint_position")
    if q is None:
        return CriterionOutcome(c, "unknown", f"{obj!r} reports no joint_position (not an articulation, or its "
                                              "joint was not seen)", refs)
    lo, hi = float(c.args["min"]), float(c.args["max"])
    fractions = float(c.args["min_fraction"]), float(c.args["max_fraction"])
    if any(math.isfinite(f) for f in fractions):  # bounds along the travel the entity reports
        travel = attrs.get("range_rad", attrs.get("range_m"))  # a hinge's (rad) or a slide's (m)
        if travel is None:
            return CriterionOutcome(c, "unknown", f"{obj!r} reports no range_rad or range_m for min/max_fraction",
                                    refs)
        a, b = (float(v) for v in travel)
        lo = max(lo, a + fractions[0] * (b - a)) if math.isfinite(fractions[0]) else lo
        hi = min(hi, a + fractions[1] * (b - a)) if math.isfinite(fractions[1]) else hi
    # a perceived joint (a knob read from its bar, a drawer from its handle) carries its 1-sigma;
    # a reported one is exact
    m = 2.0 * float(attrs.get("joint_position_std_rad") or attrs.get("joint_position_std_m") or 0.0)
    q = float(q)
    if attrs.get("joint_position_bound") == "lower":
        # the joint is at least q (a drawer the hand pulled open, its handle unseen since): it can
        # confirm an opening, or refute a bound it already passes, never confirm a joint below a max
        return _band(c, refs, lo <= q - m and math.isinf(hi), q - m > hi, obj, "articulated",
                     f"joint at least {q:.3f} (2 sigma {m:.3f}, {attrs.get('joint_source', 'a bound')}) "
                     f"against [{lo:.3f}, {hi:.3f}]")
    return _band(c, refs, lo <= q - m and q + m <= hi, q + m < lo or q - m > hi, obj, "articulated",
                 f"joint at {q:.3f} (2 sigma {m:.3f}) against [{lo:.3f}, {hi:.3f}]")


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
    "beside": _eval_beside,
    "still": _eval_still,
    "unchanged": _eval_unchanged,
    "articulated": _eval_articulated,
    "has": _eval_has,
    "achieved": _eval_achieved,
}
