"""Glimpses: something seen by too few points to be a segment, which still rivals a name.

Clustering (:func:`~phyagentos.perception.detect.cluster`) drops groups smaller than
``clustering.min_points`` and points that are not density-connected in position and colour.
A thin object far from the cameras can fall through both: a blue cylinder 2.1 cm across and
5.4 cm tall, 0.9 m from the overview camera and cut by the wrist camera's border, leaves 30
scattered points, split by its shading. Dropping it is right for naming (30 points do not say
what it is) but wrong for the *other* names: a look-alike elsewhere (a blue distractor of the
same hue, seen whole) was then the only blue thing in view, was named as the declared object,
picked, placed and confirmed: a false success (the randomised tabletop, ``two_step_sort``
seeds 30025 and 30027).

A glimpse is a group of left-over object points (points in no segment), connected at
``clustering.glimpse_radius_m``, of at least ``clustering.glimpse_min_points`` points, rising
``clustering.glimpse_min_height_m`` or more above the support plane (a patch 7 mm high, 18
points at the foot of LIBERO-10 task 2's stove, rivalled the moka pot's look and the frying
pan's: both went unseen, 4 of 10 episodes lost), that
lies at least ``clustering.glimpse_clearance_m`` from every segment of a colour like its own
and not among any segment's points (:data:`EDGE_M`): the ragged edge of a segment, its mixed
pixels, is part of that segment's object, not another object; a blue thing 6 mm from a yellow
box is not the box's edge. A glimpse
is never named and never an entity; it only rivals: a declared object whose best sighting
is no clearly better match for its look than a glimpse is ambiguous, so it stays unseen
(:func:`rival`). Its size is a lower bound (seen in part, as a segment cut by the image
border: :mod:`.truncation`), its shape unknown, its colour the median of its upper third of
points (a segment's is its top face's: the sides are in shade; the 30 points above have a
median 0.44 blue, their upper third 0.81, the declared 0.80).

A rival seen once stays one while its place is hidden (:func:`carry_over`): the arm over a
glimpse, or over a look-alike segment left unknown (the perceiver keeps those as glimpses
too), does not make the other look-alike the object. On the randomised tabletop a blue
distractor was named while the arm hid the blue object in one observation, and its track then
won every later tie: three false successes (seeds 30019, 30033, 30034). A kept rival is
dropped once a segment stands at its place again (that segment is judged on its own) or a
camera sees past its place to what lies behind (:func:`seen_empty`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from phyagentos.perception.cloud import Cloud, transform
from phyagentos.perception.colour import lab_distance, srgb_to_lab
from phyagentos.perception.config import PerceptionConfig
from phyagentos.perception.descriptors import ObjectDescriptor
from phyagentos.perception.detect import Detection
from phyagentos.perception.frames import CameraFrame

__all__ = ["EDGE_COLOUR_COST", "EDGE_M", "Glimpse", "SEEN_EMPTY_M", "carry_over", "glimpses", "glimpse_cost", "rival", "seen_empty"]

#: Left-over points near a segment are its edge when their colour is at most this association
#: colour cost from the segment's (Delta E*ab 37.5 at the default 25 per unit): mixed pixels at
#: an edge blend the object with what lies behind it; another object's colour is further off.
EDGE_COLOUR_COST = 1.5

#: Left-over points whose median distance to the nearest segment point is below this lie among
#: that segment's points (its rim's mixed pixels, blended with the table: 39 such points of a
#: rendered blue cylinder lie a median 1.6 mm from its segment), m.
EDGE_M = 0.01

#: A camera sees a remembered glimpse's place empty where its depth there lies at least this
#: much beyond the glimpse's centre, m (it sees the table behind where the thing stood).
SEEN_EMPTY_M = 0.02


@dataclass(frozen=True)
class Glimpse:
    """Left-over object points that may be another object, seen in part.

    Attributes:
        position: (3,) world centre of its points, m.
        size_m: (3,) seen full size (long, short horizontal side of the axis-aligned box,
            height of the points above the support plane), m: a lower bound.
        colour_rgb: (3,) median sRGB of its upper third of points, in [0, 1].
        colour_lab: (3,) CIELAB of ``colour_rgb``.
        points: how many points it has.
    """

    position: np.ndarray
    size_m: np.ndarray
    colour_rgb: np.ndarray
    colour_lab: np.ndarray
    points: int

    def to_dict(self) -> dict:
        """Plain data (lists of floats) for :meth:`from_dict`."""
        return {"position": [float(v) for v in self.position], "size_m": [float(v) for v in self.size_m],
                "colour_rgb": [float(v) for v in self.colour_rgb], "points": int(self.points)}

    @classmethod
    def of_detection(cls, det: Detection) -> "Glimpse":
        """A segment left unknown as a look-alike, kept as a rival: its centre, its sorted full
        size (long, short, height), its top-face colour and point count."""
        full = 2.0 * np.asarray(det.half_extents, float)
        return cls(position=np.asarray(det.position, float).copy(),
                   size_m=np.array([max(full[0], full[1]), min(full[0], full[1]), full[2]]),
                   colour_rgb=np.asarray(det.colour_rgb, float), colour_lab=np.asarray(det.colour_lab, float),
                   points=int(det.points))

    @classmethod
    def from_dict(cls, d) -> "Glimpse":
        """The glimpse :meth:`to_dict` wrote. Raises KeyError, TypeError or ValueError on another layout."""
        rgb = np.asarray(d["colour_rgb"], dtype=np.float64).reshape(3)
        return cls(position=np.asarray(d["position"], dtype=np.float64).reshape(3),
                   size_m=np.asarray(d["size_m"], dtype=np.float64).reshape(3), colour_rgb=rgb,
                   colour_lab=srgb_to_lab(rgb[None, :])[0], points=int(d["points"]))


def _like_colour(lab_a: np.ndarray, lab_b: np.ndarray, config: PerceptionConfig) -> bool:
    """Whether two CIELAB colours (3,) are alike: an association colour cost at most
    :data:`EDGE_COLOUR_COST`."""
    ac = config.association
    return float(lab_distance(lab_a, lab_b, lightness_weight=ac.lightness_weight)) / ac.colour_scale_lab \
        <= EDGE_COLOUR_COST


def glimpses(cloud: Cloud, heights: np.ndarray, segments: Sequence[np.ndarray],
             config: PerceptionConfig, segment_lab: Sequence[np.ndarray] | None = None) -> list[Glimpse]:
    """The glimpses among ``cloud``'s points that no segment holds (module docstring).

    Args:
        cloud: the object cloud the segments were found in (world frame).
        heights: (N,) each point's height above the support plane, m.
        segments: index arrays into ``cloud``, one per segment (detections, their parts).
        config: ``clustering.glimpse_min_points`` (0: none), ``glimpse_radius_m``,
            ``glimpse_min_height_m``, ``glimpse_clearance_m``.
        segment_lab: (3,) CIELAB colour of each segment, or None. Given, points within the
            clearance of a segment are its edge only where their colour is near the segment's
            (an association colour cost at most :data:`EDGE_COLOUR_COST`): a blue cylinder
            6 mm from a yellow box is another object, not the box's edge.

    Returns:
        The glimpses, most points first.
    """
    cc = config.clustering
    n = len(cloud)
    if cc.glimpse_min_points <= 0 or n == 0:
        return []
    used = np.zeros(n, bool)
    for idx in segments:
        used[np.asarray(idx, dtype=np.int64)] = True
    left = np.flatnonzero(~used)
    if left.size < cc.glimpse_min_points:
        return []
    pts = cloud.points[left].astype(np.float64)
    pairs = cKDTree(pts).query_pairs(cc.glimpse_radius_m, output_type="ndarray")
    graph = coo_matrix((np.ones(pairs.shape[0], np.int8), (pairs[:, 0], pairs[:, 1])), shape=(left.size,) * 2)
    _, comp = connected_components(graph, directed=False)
    owner = np.full(n, -1, dtype=np.int64)
    for s_i, idx in enumerate(segments):
        owner[np.asarray(idx, dtype=np.int64)] = s_i
    seg_pts = np.flatnonzero(used)
    seg_tree = cKDTree(cloud.points[seg_pts, :2].astype(np.float64)) if seg_pts.size else None
    out = []
    for k in np.flatnonzero(np.bincount(comp) >= cc.glimpse_min_points):
        members = left[comp == k]
        xy = cloud.points[members, :2].astype(np.float64)
        # the colour of its upper third, as a segment's is its top face's (its sides are in shade)
        upper = members[np.argsort(-heights[members])[:max(5, members.size // 3)]]
        rgb = np.median(cloud.rgb[upper].astype(np.float64), axis=0) / 255.0
        lab = srgb_to_lab(rgb[None, :])[0]
        if seg_tree is not None:
            near, at = seg_tree.query(xy, k=1)
            if float(np.median(near)) < EDGE_M:
                continue  # its points lie among a segment's: that segment's rim, of whatever colour
            close = np.unique(owner[seg_pts[at[near < cc.glimpse_clearance_m]]])
            if segment_lab is None and close.size:
                continue  # a segment's own ragged edge
            if segment_lab is not None and any(_like_colour(lab, segment_lab[int(c)], config) for c in close):
                continue  # a segment's own ragged edge
        top = float(np.percentile(heights[members], 98))
        if top < cc.glimpse_min_height_m:
            continue  # table-level clutter
        lo, hi = xy.min(axis=0), xy.max(axis=0)
        side = np.sort(hi - lo)[::-1]
        out.append(Glimpse(position=cloud.points[members].astype(np.float64).mean(axis=0),
                           size_m=np.array([side[0], side[1], top]),
                           colour_rgb=rgb, colour_lab=lab, points=int(members.size)))
    out.sort(key=lambda g: -g.points)
    return out


def glimpse_cost(g: Glimpse, desc: ObjectDescriptor, config: PerceptionConfig) -> float:
    """Association cost of ``g`` for ``desc`` on the terms a segment cut by the image border
    gets (:func:`~phyagentos.perception.association.cost_matrix`): colour, and size only
    where the glimpse is larger than the declared look; no shape."""
    ac = config.association
    c = 0.0
    if desc.colour_rgb is not None:
        want = srgb_to_lab(np.array([desc.colour_rgb], dtype=np.float64))[0]
        c += float(lab_distance(g.colour_lab, want, lightness_weight=ac.lightness_weight)) / ac.colour_scale_lab
    if desc.size_m is not None:
        if desc.size_vector() is None:
            c += max(0.0, float(g.size_m.max()) - float(desc.size_m)) / ac.size_scale_m
        else:
            err = desc.size_error(g.size_m, at_least=True)
            c += float(err or 0.0) / ac.size_scale_m
    return c


def rival(cost: float, desc: ObjectDescriptor, found: Sequence[Glimpse], config: PerceptionConfig) -> Glimpse | None:
    """The glimpse that matches ``desc``'s look about as well as its best sighting does (at
    an association cost at most ``cost + association.ambiguity_margin`` and within the gate),
    else None. ``cost``: that sighting's look cost (colour, size, shape; no track term)."""
    ac = config.association
    for g in found:
        c = glimpse_cost(g, desc, config)
        if c <= ac.gate_cost and c <= cost + ac.ambiguity_margin:
            return g
    return None


def seen_empty(g: Glimpse, frames: Sequence[CameraFrame], *, margin_m: float = SEEN_EMPTY_M) -> bool:
    """Whether some camera of ``frames`` sees past ``g``'s centre (pinhole projection,
    Hartley & Zisserman eq. 6.2): its depth at the centre's pixel lies more than ``margin_m``
    beyond the centre, so nothing stands there any more. A camera that does not see the place
    (outside its image, or something nearer in front of it) says nothing."""
    for f in frames:
        if f.depth_m is None:
            continue
        pc = transform(np.linalg.inv(f.T_world_camera), g.position[None, :])[0]
        if pc[2] <= 1e-6:
            continue
        intr = f.intrinsics
        u = int(round(intr.fx * pc[0] / pc[2] + intr.cx))
        v = int(round(intr.fy * pc[1] / pc[2] + intr.cy))
        if not (0 <= u < intr.width and 0 <= v < intr.height):
            continue
        d = float(f.depth_m[v, u])
        if np.isfinite(d) and d > pc[2] + margin_m:
            return True
    return False


def carry_over(previous: Sequence[Glimpse], current: Sequence[Glimpse], segment_xy: Sequence[np.ndarray],
               frames: Sequence[CameraFrame], config: PerceptionConfig,
               segment_lab: Sequence[np.ndarray] | None = None) -> list[Glimpse]:
    """The glimpses to keep after an observation: ``current`` ones, and each ``previous`` one
    that no current glimpse repeats, that no segment now explains and whose place no camera
    sees empty (:func:`seen_empty`): something seen in part once stays a rival while the arm
    hides its place.

    Args:
        previous: the glimpses kept so far.
        current: the glimpses of this observation (:func:`glimpses`).
        segment_xy: (k, 2) world x, y of each segment's points, m.
        frames: this observation's cameras.
        config: ``clustering.glimpse_clearance_m``: a segment with a point this near explains
            a kept glimpse (is the object there now), where its colour is like the glimpse's
            (:data:`EDGE_COLOUR_COST`, with ``segment_lab``) or ``segment_lab`` is None.
        segment_lab: (3,) CIELAB colour of each segment, or None.
    """
    kept = list(current)
    if not previous:
        return kept
    clear = config.clustering.glimpse_clearance_m
    trees = [cKDTree(np.asarray(xy, dtype=np.float64)) for xy in segment_xy if len(xy)]
    labs = [lab for xy, lab in zip(segment_xy, segment_lab or [None] * len(segment_xy)) if len(xy)]
    for g in previous:
        if any(float(np.linalg.norm(g.position[:2] - c.position[:2])) < clear for c in current):
            continue
        if any(tree.query(g.position[:2], k=1)[0] < clear and (lab is None or _like_colour(g.colour_lab, lab, config))
               for tree, lab in zip(trees, labs)):
            continue
        if seen_empty(g, frames):
            continue
        kept.append(g)
    return kept
