"""A thing the hand let go leant onto a fixture's ramp, found lying there.

LIBERO's wine rack holds a bottle lying back on its upper ramp, its base against the lip at the
ramp's foot (:class:`~phyagentos.perception.fixtures.LeanLook`: the crest, the way the ramp
rises and its slope, measured from the rack's own collision geometry on generated scenes). The
perceiver takes every point over a fixture's footprint up to its top for the fixture's own, so
a bottle lying there was taken for the rack and only its neck showed above it, as an unknown
segment: the verdict on "on the rack" was "cannot judge" in every episode.

What lies on the ramp stands above the ramp's plane (through the crest, rising at the ramp's
slope), where the rack itself has nothing: on libero_goal task 9's recorded scene before the
place (init 0, read to find the failure, not fitted to), 5 of the rack's points stood more than
:data:`LEAN_CLEAR_M` above that plane, all on its top's spike; after the place, 394, the
bottle's. Those points, where the hand let an object go, are that object lying on the ramp when
their extent and colour are the object's (:func:`find_leant`); anything else is not named.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from phyagentos.perception.cloud import Cloud
from phyagentos.perception.colour import lab_distance, srgb_to_lab

__all__ = ["LEAN_CLEAR_M", "LEAN_BASE_M", "LEAN_SLACK_M", "LEAN_POINTS_SCALE", "LeantSighting", "on_ramp",
           "LEAN_TILT_TOL_RAD", "LEAN_HEADING_TOL_RAD", "find_leant", "leant_confidence"]

#: Points more than this above the ramp's plane are something lying on it, not the fixture, m
#: (module docstring: the rack alone shows 5 such points, on its top's spike, a bottle on it 394).
LEAN_CLEAR_M = 0.015
#: ... counted from this far before the crest, m, along the way the ramp rises (the base rests
#: against the lip, the crest's own top).
LEAN_BASE_M = 0.02
#: What shows may exceed the object's own length and width by this, m (a voxel either side and
#: depth noise; LIBERO's wine bottle, 15.6 cm long, showed 13 cm along the ramp).
LEAN_SLACK_M = 0.03
#: Lying on the ramp, an object's axis runs up it: its tilt from upright within this of the
#: ramp's own (90 degrees less the slope), rad. A cylinder on the rack's 31-degree ramp tilts 59
#: degrees; the bottle's points on it ran at 57 (the recorded scene above), its body frame at 50
#: (its neck and shoulder lift it off the ramp). Anything lying otherwise is not named.
LEAN_TILT_TOL_RAD = math.radians(20.0)
#: ... and the horizontal part of its axis within this of the way the ramp rises, rad (a bottle
#: lying across the rack's top is not on its ramp).
LEAN_HEADING_TOL_RAD = math.radians(30.0)
#: Confidence from the count ``n`` of points found: ``1 - exp(-n / LEAN_POINTS_SCALE)`` (as for a
#: thing let go into a container, ``perceiver._released_inside``): the rack's 5 stray points give
#: 0.15, a bottle's 394 give 1.0.
LEAN_POINTS_SCALE = 30.0


@dataclass(frozen=True)
class LeantSighting:
    """What shows of an object lying on a fixture's ramp.

    Attributes:
        position: (3,) the centroid of the points found, world m.
        axis: (3,) unit, the principal direction of those points, world, pointing up the ramp.
        tilt_rad: the angle of ``axis`` from upright, rad.
        length_m: their extent along ``axis``, m.
        width_m: their extent across it, horizontally, m.
        lowest_z_m: the lowest point's world z, m.
        colour_rgb: (3,) median colour in 0..1.
        points: how many points.
        cameras: the indices of the cameras that saw them (``Cloud.camera``).
    """

    position: np.ndarray
    axis: np.ndarray
    tilt_rad: float
    length_m: float
    width_m: float
    lowest_z_m: float
    colour_rgb: np.ndarray
    points: int
    cameras: tuple[int, ...]


def on_ramp(points: np.ndarray, crest: np.ndarray, toward_xy: np.ndarray, slope_rad: float,
            footprint: tuple[np.ndarray, float, np.ndarray]) -> np.ndarray:
    """(N,) bool: which of ``points`` ((N, 3) world m) lie on the ramp rather than being it.

    Args:
        points: (N, 3) world m.
        crest: (3,) the ramp's crest (its lip's top), world m.
        toward_xy: (2,) unit, world: the way the ramp rises from the crest.
        slope_rad: the ramp's slope from horizontal, rad.
        footprint: ``(centre (2,) world m, yaw rad, half extents (2,) m)`` of the fixture's body
            (grown by what the caller allows at its edge).

    A point qualifies when it lies over the footprint, no more than :data:`LEAN_BASE_M` before
    the crest, and more than :data:`LEAN_CLEAR_M` above the plane through the crest rising at
    ``slope_rad`` along ``toward_xy``."""
    p = np.asarray(points, float)
    u = np.asarray(toward_xy, float)
    rel = p - np.asarray(crest, float)
    along = rel[:, :2] @ u
    above = -math.sin(slope_rad) * along + math.cos(slope_rad) * rel[:, 2]
    centre, yaw, half = footprint
    c, s = math.cos(yaw), math.sin(yaw)
    d = p[:, :2] - np.asarray(centre, float)
    local = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]], axis=1)
    over = np.all(np.abs(local) <= np.asarray(half, float), axis=1)
    return over & (along >= -LEAN_BASE_M) & (above > LEAN_CLEAR_M)


def find_leant(cloud: Cloud, mask: np.ndarray, *, toward_xy: np.ndarray) -> LeantSighting | None:
    """What the points of ``cloud`` selected by ``mask`` ((N,) bool, :func:`on_ramp`) show, or
    None when fewer than 3 are selected. ``toward_xy`` ((2,) unit, world) orients the axis up the
    ramp."""
    idx = np.flatnonzero(mask)
    if idx.size < 3:
        return None
    p = cloud.points[idx].astype(float)
    centre = p.mean(axis=0)
    _, _, vt = np.linalg.svd(p - centre, full_matrices=False)
    axis = vt[0]
    if float(axis[:2] @ np.asarray(toward_xy, float)) + float(axis[2]) < 0.0:
        axis = -axis
    along = (p - centre) @ axis
    across_dir = np.cross([0.0, 0.0, 1.0], axis)
    n = float(np.linalg.norm(across_dir))
    across = (p - centre) @ (across_dir / n) if n > 1e-9 else np.zeros(len(p))
    return LeantSighting(position=centre, axis=axis, tilt_rad=float(math.acos(min(1.0, abs(float(axis[2]))))),
                         length_m=float(np.ptp(along)), width_m=float(np.ptp(across)), lowest_z_m=float(p[:, 2].min()),
                         colour_rgb=np.median(cloud.rgb[idx], axis=0) / 255.0, points=int(idx.size),
                         cameras=tuple(int(c) for c in np.unique(cloud.camera[idx])))


def leant_confidence(sighting: LeantSighting, *, length_m: float, width_m: float, colour_rgb: np.ndarray,
                     toward_xy: np.ndarray, slope_rad: float, colour_scale_lab: float,
                     lightness_weight: float) -> float:
    """Confidence 0..1 that ``sighting`` is an object ``length_m`` long (its longest side, m) and
    ``width_m`` wide (its widest across, m) of colour ``colour_rgb`` ((3,) 0..1) lying on a ramp
    rising along ``toward_xy`` ((2,) unit, world) at ``slope_rad``: 0 when what shows is longer
    or wider than the object by more than :data:`LEAN_SLACK_M` (something else, or more than it,
    lies there), or does not run up the ramp (:data:`LEAN_TILT_TOL_RAD`,
    :data:`LEAN_HEADING_TOL_RAD`); else the count's confidence (:data:`LEAN_POINTS_SCALE`) times
    ``exp(-d^2 / 2)``, ``d`` the colours' Delta E*ab (L* weighted by ``lightness_weight``) over
    ``colour_scale_lab``, the association's own colour scale."""
    if sighting.length_m > length_m + LEAN_SLACK_M or sighting.width_m > width_m + LEAN_SLACK_M:
        return 0.0
    if abs(sighting.tilt_rad - (0.5 * math.pi - slope_rad)) > LEAN_TILT_TOL_RAD:
        return 0.0
    horizontal = sighting.axis[:2]
    norm = float(np.linalg.norm(horizontal))
    if norm < 1e-9 or float(horizontal @ np.asarray(toward_xy, float)) / norm < math.cos(LEAN_HEADING_TOL_RAD):
        return 0.0
    lab = srgb_to_lab(np.array([sighting.colour_rgb, np.asarray(colour_rgb, float)], dtype=float))
    d = float(lab_distance(lab[0], lab[1], lightness_weight=lightness_weight)) / colour_scale_lab
    return (1.0 - math.exp(-sighting.points / LEAN_POINTS_SCALE)) * math.exp(-0.5 * d * d)
