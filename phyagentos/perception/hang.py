"""How a round body held by its rim hangs in the hand, read from a camera that does not ride on it.

A mug taken by its rim pivots about the finger pads under its own weight once it is lifted: the
pads' squeeze holds its weight, not the turn. The held object's pose that the hand carries (its
pose when the fingers closed, rigid in the tcp frame) then puts its base where it is not. On
LIBERO's development split (LIBERO-10 task 4, LIBERO's placement sampler, seeds 500-503, never
an init state) the white-and-yellow mug hung 7.3-7.5 degrees off vertical once lifted, its base
1.5-1.7 cm nearer the fingers than the carried pose said; set down by that pose, its origin came
to rest 1.9-2.2 cm from the plate's centre instead of the intended 0.9 (the verifier's ``on``
left it undecided, its reach 2.5 cm).

:func:`hang_offset` measures the shift where the base is: the lowest points of the held body
(the part of it below the fingers the perceiver keeps apart as hanging from the hand), from the
cameras whose optical centre stands more than :data:`HAND_CAMERA_M` from the tcp, fitted slice
by slice to circles about one centre. Each slice's radius is the base's as the same cameras saw
it while the body stood (:func:`base_profile`), counted up from the body's lowest points both
times: the centre of a circle fitted to an arc seen from one side moves about 1 mm along the
view for each mm of radius, and LIBERO's mugs taper (the porcelain mug 3.1 cm across the radius
at its base, 4.2 cm 3 cm up; 4.8 cm for its outline with the handle). On those four scenes the
fit put the mugs' base axes within 1-3 mm of the true ones (the carried pose: 7-17 mm). A camera
riding on the hand looks down into the body, at its inside and floor: left out of both.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "BASE_RANK",
    "HAND_CAMERA_M",
    "HANG_BAND_M",
    "HANG_MAX_M",
    "HANG_MIN_ARC_RAD",
    "HANG_MIN_POINTS",
    "HANG_RMS_M",
    "HANG_SLICE_M",
    "HANG_SLICES",
    "HANG_SLICE_POINTS",
    "HANG_TRIM_M",
    "base_profile",
    "hang_offset",
    "scene_camera_mask",
]

#: A camera whose optical centre stands this close to the tcp or closer rides on the hand, m
#: (robosuite's Panda eye-in-hand camera: about 0.1 m from the tcp; LIBERO's agentview: about
#: 1 m).
HAND_CAMERA_M = 0.25
#: The band above the body's base that is fitted, m: the part that lands first (a tilt moves
#: higher slices less), in :data:`HANG_SLICES` slices of :data:`HANG_SLICE_M`, each with its own
#: radius (LIBERO's porcelain mug widens from 3.1 to 4.2 cm within its lowest 3 cm).
HANG_BAND_M = 0.03
#: Height of one slice of the base band, m.
HANG_SLICE_M = 0.005
#: Slices in the base band.
HANG_SLICES = int(round(HANG_BAND_M / HANG_SLICE_M))
#: Fewest points in a slice for its radius, seen standing.
HANG_SLICE_POINTS = 5
#: A body's base is its this-many-th lowest point (0: the lowest): the lowest few may be strays.
BASE_RANK = 2
#: The largest shift believed, m: a body 10 cm below the pads turned 15 degrees moves 2.6 cm;
#: a larger one is another thing's points (or the fit's failure), and the carried pose stands.
HANG_MAX_M = 0.03
#: Fewest points in the band for a fit.
HANG_MIN_POINTS = 15
#: The band's points must cover at least this arc of the circle about the fitted centre, rad:
#: a short arc leaves the centre free along it.
HANG_MIN_ARC_RAD = math.radians(60.0)
#: Points farther than this off the circle after the first fit are dropped before the second
#: (a handle standing out of the body, a stray pixel at a depth edge), m.
HANG_TRIM_M = 0.006
#: Largest RMS distance of the kept points from the fitted circle, m.
HANG_RMS_M = 0.003


def scene_camera_mask(camera_index: np.ndarray, camera_positions: np.ndarray, tcp_position: np.ndarray) -> np.ndarray:
    """(N,) bool: the points (``camera_index`` (N,) int, into ``camera_positions`` (C, 3) world
    optical centres, m) taken by a camera that does not ride on the hand (its centre more than
    :data:`HAND_CAMERA_M` from ``tcp_position`` (3,) world, m)."""
    cams = np.asarray(camera_positions, dtype=float).reshape(-1, 3)
    off_hand = np.linalg.norm(cams - np.asarray(tcp_position, dtype=float)[:3], axis=1) > HAND_CAMERA_M
    return off_hand[np.asarray(camera_index, dtype=int)]


def _slices(h: np.ndarray) -> np.ndarray:
    """(N,) int: the :data:`HANG_SLICE_M` slice of the base band each height ``h`` (N,) m above
    the base falls in; -1 outside the band."""
    k = np.floor(np.asarray(h, dtype=float) / HANG_SLICE_M).astype(int)
    return np.where((k >= 0) & (k < HANG_SLICES), k, -1)


def _base_z(z: np.ndarray) -> float:
    """The height (world z, m) of a body's base: its :data:`BASE_RANK` th lowest point (the
    lowest few may be strays at a depth edge)."""
    z = np.asarray(z, dtype=float)
    return float(np.partition(z, min(BASE_RANK, z.size - 1))[min(BASE_RANK, z.size - 1)])


def base_profile(points: np.ndarray, *, axis_xy: np.ndarray, outline_radius_m: float) -> np.ndarray | None:
    """The radius of a standing round body's base, slice by slice, as the cameras see it.

    Args:
        points: (N, 3) world points of the body, m, from the cameras that do not ride on the
            hand (:func:`scene_camera_mask`).
        axis_xy: (2,) world, m: its axis (its round body's, fitted to its outline).
        outline_radius_m: its outline's radius, m: no slice of its base is wider.

    Returns:
        (:data:`HANG_SLICES`,) m: slice ``k`` (``k`` to ``k + 1`` times :data:`HANG_SLICE_M`
        above its base, :func:`_base_z`) the median distance of its points from the axis,
        0 (unknown) with fewer than :data:`HANG_SLICE_POINTS` points or a median not within half
        to all of ``outline_radius_m``; None when fewer than two slices are known.

    Its base is its lowest points, not the support plane: the plane the perceiver fits to
    LIBERO-10's living-room table lies 1.2 cm under the table top the objects rest on, and in
    the hand the same points are the lowest again.
    """
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    axis = np.asarray(axis_xy, dtype=float)[:2]
    if p.shape[0] <= BASE_RANK:
        return None
    k = _slices(p[:, 2] - _base_z(p[:, 2]))
    r = np.hypot(p[:, 0] - axis[0], p[:, 1] - axis[1])
    out = np.zeros(HANG_SLICES)
    for j in range(HANG_SLICES):
        rj = r[k == j]
        if rj.size >= HANG_SLICE_POINTS:
            m = float(np.median(rj))
            out[j] = m if 0.5 * outline_radius_m <= m <= outline_radius_m else 0.0
    return out if int((out > 0.0).sum()) >= 2 else None


def _fit_centre(xy: np.ndarray, radius_m: np.ndarray, start: np.ndarray, iterations: int = 30) -> np.ndarray:
    """Centre (2,) m about which the points ``xy`` (N, 2) lie nearest their radii ``radius_m``
    ((N,) m) in the least squares sense (Gauss-Newton from ``start``)."""
    c = np.asarray(start, dtype=float).copy()
    for _ in range(iterations):
        d = xy - c
        n = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)
        u = d / n[:, None]
        r = n - radius_m  # residuals; d r / d c = -u
        step, *_ = np.linalg.lstsq(-u, -r, rcond=None)
        c = c + step
        if float(np.hypot(*step)) < 1e-6:
            break
    return c


def _arc_rad(xy: np.ndarray, centre: np.ndarray) -> float:
    """The angle (rad) the points ``xy`` (N, 2) span about ``centre`` (2,): 2 pi less the widest
    empty gap between their bearings."""
    a = np.sort(np.arctan2(xy[:, 1] - centre[1], xy[:, 0] - centre[0]))
    gaps = np.diff(np.r_[a, a[0] + 2.0 * math.pi])
    return float(2.0 * math.pi - gaps.max())


def hang_offset(points: np.ndarray, *, axis_xy: np.ndarray, profile: np.ndarray) -> np.ndarray | None:
    """How far (world x, y, m) the held body's base hangs from where its carried pose puts its
    axis, or None where the points do not tell.

    Args:
        points: (N, 3) world points, m: the part of the held body below the fingers, seen by a
            camera that does not ride on the hand (:func:`scene_camera_mask`).
        axis_xy: (2,) world, m: where the carried pose puts the body's axis.
        profile: (:data:`HANG_SLICES`,) m: its base's radius slice by slice, as seen while it
            stood (:func:`base_profile`; 0: unknown).

    The points within the largest radius + :data:`HANG_MAX_M` of the axis are taken as the body's;
    their lowest (:func:`_base_z`) as its base; each in a slice of known radius is fitted to the
    circle of that radius about one centre (Gauss-Newton from the axis; then again without the
    points more than :data:`HANG_TRIM_M` off).

    Returns:
        (2,) world shift, m, of the fitted centre from ``axis_xy``; None with fewer than
        :data:`HANG_MIN_POINTS` points in slices of known radius, an arc shorter than
        :data:`HANG_MIN_ARC_RAD`, an RMS residual above :data:`HANG_RMS_M`, or a shift larger
        than :data:`HANG_MAX_M`.
    """
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    axis = np.asarray(axis_xy, dtype=float)[:2]
    prof = np.asarray(profile, dtype=float).reshape(-1)
    if prof.shape != (HANG_SLICES,) or not np.all(np.isfinite(prof)) or not (prof > 0.0).any() \
            or p.shape[0] < HANG_MIN_POINTS:
        return None
    p = p[np.hypot(p[:, 0] - axis[0], p[:, 1] - axis[1]) <= float(prof.max()) + HANG_MAX_M]
    if p.shape[0] < HANG_MIN_POINTS:
        return None
    k = _slices(p[:, 2] - _base_z(p[:, 2]))
    known = k >= 0
    known[known] = prof[k[known]] > 0.0
    if int(known.sum()) < HANG_MIN_POINTS:
        return None
    xy, r = p[known, :2], prof[k[known]]
    c = _fit_centre(xy, r, axis)
    keep = np.abs(np.hypot(xy[:, 0] - c[0], xy[:, 1] - c[1]) - r) <= HANG_TRIM_M
    if int(keep.sum()) < HANG_MIN_POINTS:
        return None
    xy, r = xy[keep], r[keep]
    c = _fit_centre(xy, r, c)
    res = np.hypot(xy[:, 0] - c[0], xy[:, 1] - c[1]) - r
    shift = c - axis
    if (float(np.sqrt(np.mean(res ** 2))) > HANG_RMS_M or _arc_rad(xy, c) < HANG_MIN_ARC_RAD
            or float(np.hypot(*shift)) > HANG_MAX_M):
        return None
    return shift
