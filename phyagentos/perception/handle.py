"""A round body with a handle: where a mug's cup stands and which way its handle points.

A mug's footprint is its round cup and, on one side, its handle. The minimum-area rectangle
of its points (:func:`phyagentos.perception.detect.fit_cluster`) centres it between the two,
0.6-0.8 cm off the cup's axis towards the handle on LIBERO's mugs, and a round fit throws the
handle's direction away. This module finds both from the footprint's outline, RGB-D only
(``fit_cluster`` passes the points of the segment's upper part, :data:`UPPER_FRACTION`):

1. about a first guess of the centre, the outline is the farthest point in each of
   :data:`OUTLINE_BINS` angular sectors;
2. a circle is fitted to the outline by least squares (the algebraic fit of Kasa 1976,
   "A circle fitting procedure and its error analysis", IEEE Trans. Instrum. Meas. 25(1)),
   dropping the sectors that lie off it by more than :data:`CIRCLE_TOL_M` (or 2.5 times
   their median residual) and fitting again; the centre moves to the circle's and the
   outline is taken again (:data:`ROUNDS` rounds);
3. the body is round when at least :data:`MIN_ROUND_FRACTION` of the sectors lie on the
   circle; it has a handle when at least :data:`MIN_HANDLE_POINTS` points stand more than
   :data:`HANDLE_BEYOND_M` outside it, :data:`HANDLE_SPAN_FRACTION` of them within
   :data:`HANDLE_SPAN_RAD` of their mean direction (a box's four corners stand out on every
   side, and its outline is no circle).

Measured on LIBERO's three mugs in generated LIBERO-10 task 4 scenes (the sampler's, seeds
500-503, never an init state): the fitted axis 0.4-2.1 mm from the cup's (the cup's from a
circle through the visual mesh), against 1.7-8.4 mm for the rectangle's centre; the handle's
direction within 0-8 degrees (one mug seen in part: 27).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "RoundBody",
    "round_body",
    "UPPER_FRACTION",
    "OUTLINE_BINS",
    "CIRCLE_TOL_M",
    "ROUNDS",
    "MIN_ROUND_FRACTION",
    "HANDLE_BEYOND_M",
    "MIN_HANDLE_POINTS",
    "HANDLE_SPAN_RAD",
    "HANDLE_SPAN_FRACTION",
    "REACH_PERCENTILE",
]

#: The outline is taken from the points of a segment higher than this fraction of its height
#: above its lowest (2nd percentile): a mug set on a plate, split from it, keeps a ring of the
#: plate's rim at the plate's height, which a circle through the outline would follow.
UPPER_FRACTION = 0.4
#: Angular sectors of the outline (10 degrees each).
OUTLINE_BINS = 36
#: An outline sector lies on the circle within this (or 2.5 times the sectors' median
#: residual, the larger), m: a few depth samples at LIBERO's camera ranges.
CIRCLE_TOL_M = 0.003
#: Fit-and-recentre rounds: the first guess (the rectangle's centre) is off by up to half the
#: handle's length; two rounds bring the outline's sectors round the axis.
ROUNDS = 3
#: At least this fraction of the sectors seen lies on the circle: a round body.
MIN_ROUND_FRACTION = 0.6
#: A handle's points stand at least this far outside the circle, m (LIBERO's mug handles reach
#: 2-3 cm out from the cup; the rim's own noise stays within :data:`CIRCLE_TOL_M`).
HANDLE_BEYOND_M = 0.008
#: ... and there are at least this many of them.
MIN_HANDLE_POINTS = 5
#: ... :data:`HANDLE_SPAN_FRACTION` of them within this angle of their mean direction, rad (a
#: handle is narrow; a box's corners point four ways; a stray depth sample may point anywhere).
HANDLE_SPAN_RAD = math.radians(45.0)
HANDLE_SPAN_FRACTION = 0.9
#: A handle's reach is this percentile of its points' distance from the axis along its direction
#: (its outer face, a stray depth sample aside).
REACH_PERCENTILE = 95.0


@dataclass(frozen=True)
class RoundBody:
    """A round body and its handle, world frame.

    Attributes:
        axis_xy: (2,) where the body's axis meets the ground plane, m.
        radius_m: the outline's radius, m.
        handle_xy: (2,) unit vector from the axis towards the handle.
        reach_m: how far from the axis the handle reaches along ``handle_xy``, m (the
            :data:`REACH_PERCENTILE` th percentile of its points' reach); None when not measured.
    """

    axis_xy: np.ndarray
    radius_m: float
    handle_xy: np.ndarray
    reach_m: float | None = None

    def local(self, position_xy: np.ndarray, yaw: float) -> "RoundBody":
        """This body in the frame of an object at ``position_xy`` ((2,) world, m) turned
        ``yaw`` (rad about world z)."""
        c, s = math.cos(yaw), math.sin(yaw)
        R_t = np.array([[c, s], [-s, c]])
        return RoundBody(R_t @ (self.axis_xy - np.asarray(position_xy, float)[:2]), self.radius_m, R_t @ self.handle_xy,
                         self.reach_m)

    def turned(self, angle_rad: float) -> "RoundBody":
        """This body turned ``angle_rad`` (rad) about its frame's z axis (re-expressed in a frame
        turned by ``-angle_rad``)."""
        c, s = math.cos(angle_rad), math.sin(angle_rad)
        R = np.array([[c, -s], [s, c]])
        return RoundBody(R @ self.axis_xy, self.radius_m, R @ self.handle_xy, self.reach_m)

    def placed(self, T: np.ndarray) -> "RoundBody":
        """This body (given in an object's frame) in the world, the object's pose being ``T``
        ((4, 4) world from object); the handle's direction as it shows on the ground plane."""
        T = np.asarray(T, float)
        u = T[:2, :2] @ self.handle_xy
        n = float(np.hypot(u[0], u[1]))
        return RoundBody(T[:2, :2] @ self.axis_xy + T[:2, 3], self.radius_m, u / n if n > 0 else self.handle_xy,
                         self.reach_m)


def _circle(p: np.ndarray) -> tuple[np.ndarray, float]:
    """Kasa's algebraic circle fit of (N, 2) points: (centre (2,), radius)."""
    A = np.column_stack([2.0 * p, np.ones(p.shape[0])])
    b = np.einsum("ni,ni->n", p, p)
    sol = np.linalg.solve(np.einsum("ni,nj->ij", A, A) + 1e-12 * np.eye(3), np.einsum("ni,n->i", A, b))
    c = sol[:2]
    return c, math.sqrt(max(float(sol[2] + c @ c), 1e-12))


def _outline(xy: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """(K, 2): the farthest point of ``xy`` from ``centre`` in each angular sector that has one."""
    d = xy - centre
    rad = np.hypot(d[:, 0], d[:, 1])
    k = (((np.arctan2(d[:, 1], d[:, 0]) + math.pi) / (2.0 * math.pi)) * OUTLINE_BINS).astype(int) % OUTLINE_BINS
    order = np.lexsort((rad, k))  # by sector, then radius: the last of each sector is its farthest
    last = np.r_[k[order][1:] != k[order][:-1], True]
    return xy[order[last]]


def round_body(xy: np.ndarray, centre_xy: np.ndarray) -> RoundBody | None:
    """The round body with a handle that the footprint ``xy`` ((N, 2) world points, m) shows,
    from a first guess of its centre ``centre_xy`` ((2,), m) -- or None: too few points, an
    outline that is no circle, or no handle (module docstring)."""
    xy = np.asarray(xy, dtype=float)
    if xy.shape[0] < 20:
        return None
    c = np.asarray(centre_xy, dtype=float)
    r, on = 0.0, np.zeros(0, dtype=bool)
    for _ in range(ROUNDS):
        ring = _outline(xy, c)
        if ring.shape[0] < OUTLINE_BINS // 3:
            return None
        on = np.ones(ring.shape[0], dtype=bool)
        for _ in range(4):
            if on.sum() < 3:
                return None
            c, r = _circle(ring[on])
            res = np.abs(np.linalg.norm(ring - c, axis=1) - r)
            on = res <= max(CIRCLE_TOL_M, 2.5 * float(np.median(res[on])))
    if on.mean() < MIN_ROUND_FRACTION:
        return None
    d = xy - c
    out = np.hypot(d[:, 0], d[:, 1]) > r + HANDLE_BEYOND_M
    if int(out.sum()) < MIN_HANDLE_POINTS:
        return None
    v = d[out].sum(axis=0)
    n = float(np.hypot(v[0], v[1]))
    if n <= 0.0:
        return None
    u = v / n
    cos = (d[out] @ u) / np.hypot(d[out][:, 0], d[out][:, 1])
    if float(np.mean(cos >= math.cos(HANDLE_SPAN_RAD))) < HANDLE_SPAN_FRACTION:
        return None
    reach = float(np.percentile(d[out] @ u, REACH_PERCENTILE))
    return RoundBody(axis_xy=c, radius_m=r, handle_xy=u, reach_m=reach)
