"""Association of detections to declared objects (Hungarian assignment with gating).

Cost of detection i for descriptor j (only the attributes the descriptor declares count):

* colour: Delta E*ab (CIE 1976) between the detection's median top-face colour and the
  declared colour, Delta L* weighted by ``lightness_weight`` (shading and lighting change
  L* most), divided by ``colour_scale_lab``;
* size: mean absolute error of the sorted full dimensions (or of the largest one) / ``size_scale_m``;
  with a declared ``size_range_m``, only the part outside the range counts; for a detection
  cut by the image border (``truncated``, :mod:`.truncation`) only the part above it; for the
  lower part of a stack covered by what rests on it (``covered``, :mod:`.split`), its
  footprint's sides only below :data:`COVERED_MIN_SHOWN` of the look's and above it, its
  height as any; for the upper part of a stack whose foot may be hidden in what it stands in
  (``foot_hidden_m``), its height only outside the range from its height as seen to that plus
  the hidden depth;
* shape: ``shape_cost`` when the classes differ; with declared ``shapes`` (the fraction of a
  look's sightings per shape), ``shape_cost`` times ``1 -`` the detection's shape's fraction
  over the most frequent one's (:meth:`~.descriptors.ObjectDescriptor.shape_mismatch`);
  nothing for a truncated or covered detection (its shape is the part's);
* track: distance to the descriptor's current track / ``position_scale_m``, capped at 1
  (tie-breaker between otherwise identical objects; objects do move between observations).

An object declared with a spatial reference (``where``: :class:`~.descriptors.SpatialReference`)
among look-alikes is resolved first (:func:`resolve_reference`): the detection its relation
picks out on the perceived landmarks becomes its only admissible one, or none when the
relation cannot be resolved; the look-alikes then share the rest by the ordinary assignment.

The optimal assignment is :func:`scipy.optimize.linear_sum_assignment` (Kuhn 1955), with
a "no match" option at ``gate_cost`` for every detection and descriptor. A pair costing more
than ``gate_cost`` is never associated; a match whose margin (the cost of the best
assignment without it minus the optimum) is below ``ambiguity_margin`` is ambiguous: the
detection stays ``unknown`` and the object unseen.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np
from scipy.optimize import linear_sum_assignment

from phyagentos.geometry import VIEWER_SIDES, viewer_side_xy
from phyagentos.perception.colour import lab_distance, srgb_to_lab
from phyagentos.perception.config import PerceptionConfig
from phyagentos.perception.descriptors import ObjectDescriptor
from phyagentos.perception.detect import Detection

__all__ = ["FORBIDDEN_COST", "COVERED_MIN_SHOWN", "Association", "Landmark", "ReferenceResolution", "cost_matrix", "track_costs",
           "associate", "match_confidence", "resolve_reference", "forbid_except"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Association:
    """Result: ``matches`` maps detection index -> (descriptor index, cost, margin);
    ``ambiguous`` lists detection indices withheld because of a too small margin."""

    matches: dict[int, tuple[int, float, float]]
    ambiguous: tuple[int, ...]


def _size_error(det: Detection, desc: ObjectDescriptor) -> float | None:
    if desc.size_m is None:
        return None
    full = 2.0 * np.asarray(det.half_extents, float)
    measured = np.array([max(full[0], full[1]), min(full[0], full[1]), full[2]])
    if desc.size_vector() is None:
        err = float(measured.max()) - float(desc.size_m)
        return max(0.0, err) if det.truncated or det.covered else abs(err)
    if det.truncated and not det.cut_by_body:  # cut by the border: every dimension a lower bound
        return desc.size_error(measured, at_least=True)
    if det.cut_by_room:  # seen through a room's mouth: its footprint a lower bound, its height as measured
        return desc.size_error(measured, at_least=(True, True, False))
    if det.covered or det.cut_by_body:
        # under what rests on it, or cut by a cabinet's body (in its open drawer): its footprint a
        # lower bound, at least COVERED_MIN_SHOWN of each side showing; its height as measured
        err = desc.size_error(measured, at_least=(True, True, False))
        want = desc.size_vector()
        return err + float(np.sum(np.maximum(0.0, COVERED_MIN_SHOWN * want[:2] - measured[:2]))) / 3.0
    if det.foot_hidden_m > 0.0:
        # its foot in what it stands in (a mug in a plate's well): at least as tall as seen, at
        # most by the hidden depth more
        err = desc.size_error(measured, at_least=(False, False, True))
        lo = float(desc.size_range_m[0][2]) if desc.size_range_m is not None else float(desc.size_vector()[2])
        return err + max(0.0, lo - (float(measured[2]) + det.foot_hidden_m)) / 3.0
    return desc.size_error(measured)


def cost_matrix(detections: Sequence[Detection], descriptors: Sequence[ObjectDescriptor],
                config: PerceptionConfig, track_positions: Sequence[np.ndarray | None] = ()) -> np.ndarray:
    """(n_detections, n_descriptors) association costs (see the module docstring)."""
    ac = config.association
    C = np.zeros((len(detections), len(descriptors)))
    desc_lab = [None if d.colour_rgb is None else srgb_to_lab(np.array([d.colour_rgb]))[0] for d in descriptors]
    for i, det in enumerate(detections):
        for j, desc in enumerate(descriptors):
            c = 0.0
            if desc_lab[j] is not None:
                c += float(lab_distance(det.colour_lab, desc_lab[j], lightness_weight=ac.lightness_weight)) / ac.colour_scale_lab
            err = _size_error(det, desc)
            if err is not None:
                c += err / ac.size_scale_m
            mismatch = None if det.truncated or det.covered else desc.shape_mismatch(det.shape)
            if mismatch:
                c += ac.shape_cost * mismatch
            C[i, j] = c
    return C + track_costs(detections, len(descriptors), config, track_positions) if track_positions else C


def track_costs(detections: Sequence[Detection], n_descriptors: int, config: PerceptionConfig,
                track_positions: Sequence[np.ndarray | None]) -> np.ndarray:
    """(n_detections, n_descriptors) the tracks' tie-breaker alone: the horizontal distance (m)
    from each detection to each descriptor's track / ``position_scale_m``, capped at 1; 0
    where a descriptor has no track (``None``, or beyond ``track_positions``)."""
    ac = config.association
    T = np.zeros((len(detections), n_descriptors))
    for j, tp in enumerate(track_positions[:n_descriptors]):
        if tp is None:
            continue
        for i, det in enumerate(detections):
            T[i, j] = min(1.0, float(np.linalg.norm(det.position[:2] - tp[:2])) / ac.position_scale_m)
    return T


#: The lower part of a stack (``Detection.covered``) shows at least this fraction of each side
#: of its look's footprint: what rests on it hides its top and its far side, not its near face
#: (a bowl on a ramekin leaves a crescent 9 x 6 cm of the ramekin's 9 cm; a cookie box under a
#: bowl shows 8.3 x 6.2 cm of its 8.5 x 6.4). Its sides count only below this fraction of the
#: look's and above the look's.
COVERED_MIN_SHOWN = 0.5
_FORBIDDEN = 1e6
#: A cost above any gate: the pair is never associated.
FORBIDDEN_COST = _FORBIDDEN


def _padded(C: np.ndarray, gate: float) -> np.ndarray:
    """The assignment problem with "no match" options: ``[[C, U], [V, 0]]`` where a
    detection left unknown (U, diagonal) or a descriptor left unseen (V, diagonal) costs
    ``gate``; pairs above the gate are forbidden."""
    n, m = C.shape
    P = np.full((n + m, m + n), _FORBIDDEN)
    P[:n, :m] = np.where(C <= gate, C, _FORBIDDEN)
    P[np.arange(n), m + np.arange(n)] = gate
    P[n + np.arange(m), np.arange(m)] = gate
    P[n:, m:] = 0.0
    return P


def _total(P: np.ndarray) -> float:
    r, c = linear_sum_assignment(P)
    return float(P[r, c].sum())


def associate(C: np.ndarray, config: PerceptionConfig, *,
              interchangeable: Sequence[Sequence[int]] = ()) -> Association:
    """Gated, margin-checked optimal assignment on the cost matrix ``C``.

    The margin of a match (i, j) is how much the best assignment that does *not* give
    descriptor j to detection i costs more than the optimum (every detection may stay
    unknown and every descriptor unseen at ``gate_cost``): a look-alike whose own detection
    is explained better elsewhere is no rival, two that could swap at little cost are.
    ``interchangeable``: groups of descriptor indices that nothing tells apart and nothing asks
    to (identical objects, none named by a spatial reference: "both moka pots"); for a match
    that looks like them (a cost no higher than ``clustering.split_max_cost``, at which a
    split's part is accepted) the margin of (i, j) is then that of the best assignment giving
    detection i to no member of j's group, so a swap between them is no rival, and the track
    cost in ``C`` keeps each one's identity."""
    ac = config.association
    if C.size == 0:
        return Association({}, ())
    P = _padded(C, ac.gate_cost)
    rows, cols = linear_sum_assignment(P)
    best = float(P[rows, cols].sum())
    n, m = C.shape
    matches: dict[int, tuple[int, float, float]] = {}
    ambiguous: list[int] = []
    for i, j in zip(rows, cols):
        if i >= n or j >= m:
            continue
        c = float(C[i, j])
        if c > ac.gate_cost:
            continue
        forbid = P.copy()
        # a twin's swap is no rival only for a sighting that looks like them (within the cost a
        # split's part is accepted at): two alike boxes merged into one segment name neither
        group = next((list(g) for g in interchangeable if j in g), [j])
        forbid[i, group if c <= config.clustering.split_max_cost else [j]] = _FORBIDDEN
        margin = max(0.0, _total(forbid) - best)
        if margin < ac.ambiguity_margin:
            # every detection within the margin for this descriptor is a candidate: none is named
            rivals = np.flatnonzero(C[:, j] <= c + ac.ambiguity_margin)
            ambiguous.extend(int(r) for r in rivals if int(r) not in ambiguous)
            if int(i) not in ambiguous:
                ambiguous.append(int(i))
            continue
        matches[int(i)] = (int(j), c, margin)
    ambiguous = [i for i in ambiguous if i not in matches]
    return Association(matches, tuple(ambiguous))


def match_confidence(cost: float, margin: float, config: PerceptionConfig) -> float:
    """0..1 association confidence: exp(-cost^2 / 2) * (1 - exp(-margin / ambiguity_margin))."""
    m = config.association.ambiguity_margin
    margin_term = 1.0 - math.exp(-margin / m) if m > 0 else 1.0
    return math.exp(-0.5 * cost * cost) * margin_term


# -- spatial references -------------------------------------------------------------------------------


@dataclass(frozen=True)
class Landmark:
    """What perception knows now of a landmark of a spatial reference (world frame, m):
    ``position`` (3,) centre, ``half_extents`` (3,), ``yaw`` rad about z, ``shape``,
    ``bottom_m`` its bottom's height above the support plane."""

    name: str
    position: np.ndarray
    half_extents: np.ndarray
    yaw: float
    shape: str
    bottom_m: float

    @property
    def top_m(self) -> float:
        """Top height above the support plane, m."""
        return self.bottom_m + 2.0 * float(self.half_extents[2])


@dataclass(frozen=True)
class ReferenceResolution:
    """How a spatial reference was resolved in one observation: ``detection`` the index
    picked (None: unresolved), ``reason`` in words, ``scores`` ``(detection index, score)``
    of every candidate (smaller is better; m for the distance relations, 0/1 for on/in)."""

    name: str
    relation: str
    detection: int | None
    reason: str
    scores: tuple[tuple[int, float], ...] = ()

    def to_dict(self, detections: Sequence[Detection] = ()) -> dict:
        """Plain data for the perceived snapshot (``references``)."""
        out: dict = {"relation": self.relation, "resolved": self.detection is not None, "reason": self.reason}
        if self.detection is not None and self.detection < len(detections):
            out["position"] = [round(float(v), 4) for v in detections[self.detection].position]
        return out


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """Distance (m) of point ``p`` (2,) to the segment ``a``-``b`` (2,) in the plane."""
    ab = b - a
    t = float(np.clip(np.dot(p - a, ab) / max(float(np.dot(ab, ab)), 1e-12), 0.0, 1.0))
    return float(np.linalg.norm(p - (a + t * ab)))


def _over(det: Detection, lm: Landmark) -> bool:
    """``det``'s centre lies over ``lm``'s footprint (1 cm of slack)."""
    from phyagentos.perception.relations import _footprint_margin  # noqa: PLC0415

    return _footprint_margin(det.position[:2], lm.position, lm.yaw, lm.half_extents, lm.shape) >= -0.01


def _rests_on(det: Detection, lm: Landmark, config: PerceptionConfig) -> bool:
    """``det`` stands on ``lm``: its centre over ``lm``'s footprint and its bottom within
    ``relations.on_gap_m`` of ``lm``'s top."""
    return _over(det, lm) and abs(float(det.bottom_m) - lm.top_m) <= config.relations.on_gap_m


def _off_table(det: Detection, config: PerceptionConfig) -> bool:
    return max(float(det.bottom_m), float(det.low_m)) >= config.association.off_table_m


#: Words that name a level of a landmark (a part of it at one height): a reference to one that
#: names no drawer is left unresolved by :func:`resolve_reference`, not read as the whole landmark.
_LEVELS = frozenset({"top", "middle", "bottom", "upper", "lower", "layer", "level", "tier", "shelf"})


def part_landmark(of: str, part: str | None) -> str | None:
    """The landmark name of a drawer named as the part of a fixture (``of``
    ``wooden_cabinet_1``, ``part`` ``top drawer`` -> ``wooden_cabinet_1_top_drawer``, the
    perceiver's entity of that drawer, whose inside is its landmark while it stands open), or
    ``None`` when ``part`` names no drawer (the reference is to the whole landmark)."""
    words = (part or "").split()
    if len(words) != 2 or words[1] != "drawer":
        return None
    return f"{of}_{words[0]}_drawer"


def resolve_reference(desc: ObjectDescriptor, candidates: Sequence[int], detections: Sequence[Detection],
                      landmarks: Mapping[str, Landmark], config: PerceptionConfig, *,
                      look_alikes: int = 1, table_centre_xy: np.ndarray | None = None,
                      viewer_right_xy: np.ndarray | None = None) -> ReferenceResolution:
    """Which detection the spatial reference ``desc.where`` picks out, from perceived positions only.

    Args:
        desc: a declared object with ``where`` (:class:`~.descriptors.SpatialReference`).
        candidates: indices into ``detections`` that look like ``desc`` (within the gate) and
            are no landmark's.
        detections: this observation's detections (world frame, m).
        landmarks: the landmarks perceived now (or remembered by their tracks), by name; a
            name absent here is not perceived (a fixture, or an object not seen).
        config: ``association.relation_margin_m`` and ``association.off_table_m`` are used.
        look_alikes: how many declared objects look like ``desc`` (itself included): fewer
            candidates than that and the one meant may be the one not seen, so nothing is picked.
        table_centre_xy: (2,) centre of the perceived table top, world m, or None (not known).
        viewer_right_xy: (2,) unit vector, world frame: the viewer's right on the table (the
            scene camera's image x axis, horizontal), or None (no camera seen).

    The relations: ``between`` -- the smallest distance to the segment joining the two
    landmarks' centres; ``next_to`` -- the smallest distance to the landmark's centre less its
    footprint radius; ``table_center`` -- the smallest distance to ``table_centre_xy``;
    ``left`` / ``right`` -- the furthest along the viewer's left / right (``viewer_right_xy``:
    LIBERO's instructions name left and right as its agentview camera shows the table, e.g.
    LIBERO-90's "the left plate" is the plate at table y -0.3 m, seen on the image's left);
    ``front`` / ``back`` -- the nearest the viewer / the furthest from it along the viewer's
    horizontal line of sight (:func:`~phyagentos.geometry.viewer_side_xy`; LIBERO-90's "the black bowl at the front"
    stands nearest its agentview camera, on the table's far side from the robot); ``middle`` --
    of at least three candidates, the one whose furthest fellow candidate is nearest (the one
    between the others: LIBERO-90's "the middle black bowl" of three); each picks the best
    candidate when the runner-up scores at least ``relation_margin_m`` worse.
    ``on``/``in`` a perceived landmark: the one candidate over its footprint (raised off the
    table, for ``on``); ``in`` a drawer of it (``part`` ``top drawer``: :func:`part_landmark`):
    the one candidate off the table over the inside of that drawer, which must be seen
    standing open (a landmark the perceiver adds for each open drawer); a landmark not
    perceived (a fixture without a look, or one not seen): the one candidate off the table
    (bottom at least ``off_table_m`` above it) and resting on no other perceived landmark (a
    bowl on the cabinet is not on the stove) while the others rest on the table -- being on or
    in something other than the table is what perception can see.

    Returns:
        The resolution; ``detection`` None (the object stays unseen) with the reason when a
        landmark needed is not perceived, too few look-alikes are seen, or no candidate (or
        more than one) satisfies the relation clearly enough. Never a guess.
    """
    ref = desc.where
    if ref is None:
        raise ValueError(f"object {desc.name!r} has no spatial reference")
    rel = ref.relation
    margin = config.association.relation_margin_m

    def unresolved(reason: str, scores: tuple = ()) -> ReferenceResolution:
        return ReferenceResolution(desc.name, rel, None, reason, scores)

    cands = list(candidates)
    if not cands:
        return unresolved("no detection looks like it")
    if len(cands) < look_alikes:
        return unresolved(f"{len(cands)} of the {look_alikes} look-alikes seen: the one meant may be the one not seen")
    missing = [n for n in ref.of if n not in landmarks]
    if rel in ("between", "next_to", "table_center", "middle", *VIEWER_SIDES):
        if missing:
            return unresolved(f"landmark(s) {', '.join(missing)} not perceived")
        xy = {i: np.asarray(detections[i].position[:2], float) for i in cands}
        if rel in VIEWER_SIDES:
            if viewer_right_xy is None:
                pair = "left and right" if rel in ("left", "right") else "front and back"
                return unresolved(f"no camera says where the viewer's {pair} are")
            towards = viewer_side_xy(np.asarray(viewer_right_xy, float)[:2], rel)
            scores = {i: -float(np.dot(p, towards)) for i, p in xy.items()}  # smaller is better: furthest that way
        elif rel == "middle":
            if len(xy) < 3:
                return unresolved(f"middle: {len(xy)} candidates seen; the middle one is one of at least three")
            scores = {i: max(float(np.linalg.norm(p - q)) for j, q in xy.items() if j != i) for i, p in xy.items()}
        elif rel == "between":
            a, b = (np.asarray(landmarks[n].position[:2], float) for n in ref.of)
            scores = {i: _segment_distance(p, a, b) for i, p in xy.items()}
        elif rel == "next_to":
            lm = landmarks[ref.of[0]]
            radius = float(np.hypot(lm.half_extents[0], lm.half_extents[1])) if lm.shape == "box" \
                else float(max(lm.half_extents[0], lm.half_extents[1]))
            scores = {i: max(0.0, float(np.linalg.norm(p - lm.position[:2])) - radius) for i, p in xy.items()}
        else:
            if table_centre_xy is None:
                return unresolved("the table's centre is not perceived")
            c = np.asarray(table_centre_xy, float)[:2]
            scores = {i: float(np.linalg.norm(p - c)) for i, p in xy.items()}
        ranked = sorted(scores.items(), key=lambda kv: kv[1])
        table = tuple((i, round(v, 4)) for i, v in ranked)
        if len(ranked) > 1 and ranked[1][1] - ranked[0][1] < margin:
            return unresolved(f"{rel}: the two best candidates score {ranked[0][1]:.3f} and {ranked[1][1]:.3f} m, "
                              f"within {margin:.3f} m", table)
        return ReferenceResolution(desc.name, rel, ranked[0][0],
                                   f"{rel}: scores {ranked[0][1]:.3f} m"
                                   + (f", runner-up {ranked[1][1]:.3f} m" if len(ranked) > 1 else ""), table)
    # on / in
    off = {i: _off_table(detections[i], config) for i in cands}
    drawer = part_landmark(ref.of[0], ref.part)
    if drawer is None and set((ref.part or "").split()) & _LEVELS:
        # "the top layer of the cabinet" read as no drawer: never widened to the whole landmark (the bowl
        # standing on the cabinet is not the one in its top drawer)
        return unresolved(f"{rel}: the {ref.part} of {ref.of[0]} is not a part perception reads (a drawer: "
                          f"top, middle or bottom drawer)")
    if drawer is not None:  # "in the top drawer of the cabinet": inside that drawer, standing open, only
        inside = landmarks.get(drawer)
        if inside is None:
            return unresolved(f"{rel}: the {ref.part} of {ref.of[0]} is not seen open")
        ok = [i for i in cands if _over(detections[i], inside) and off[i]]
        table = tuple((i, 0.0 if i in ok else 1.0) for i in cands)
        if len(ok) != 1:
            return unresolved(f"{rel}: {len(ok)} candidates inside {drawer}", table)
        return ReferenceResolution(desc.name, rel, ok[0], f"{rel}: the one candidate inside {drawer}", table)
    lm_seen = landmarks.get(ref.of[0])
    if lm_seen is not None:
        ok = [i for i in cands if _over(detections[i], lm_seen) and (rel == "in" or off[i])]
        how = f"over {lm_seen.name}'s footprint" + (" and off the table" if rel == "on" else "")
    else:
        elsewhere = {i: [n for n, lm in landmarks.items() if _rests_on(detections[i], lm, config)] for i in cands}
        ok = [i for i in cands if off[i] and not elsewhere[i]]
        on_other = sorted({n for i in cands if off[i] for n in elsewhere[i]})
        how = f"off the table ({ref.of[0]} is not perceived)" + (
            f", besides those on {', '.join(on_other)}" if on_other else "")
    table = tuple((i, 0.0 if i in ok else 1.0) for i in cands)
    if len(ok) != 1:
        return unresolved(f"{rel}: {len(ok)} candidates {how}", table)
    return ReferenceResolution(desc.name, rel, ok[0], f"{rel}: the one candidate {how}", table)


def forbid_except(C: np.ndarray, j: int, keep: int | None) -> np.ndarray:
    """``C`` with descriptor ``j`` admissible only for detection ``keep`` (None: for none):
    every other pair of column ``j`` costs more than any gate."""
    out = C.copy()
    col = out[:, j].copy()
    out[:, j] = _FORBIDDEN
    if keep is not None:
        out[keep, j] = col[keep]
    return out
