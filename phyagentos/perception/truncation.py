"""Objects cut by the image border: seen only in part because they reach out of the view.

A segment whose pixels run up to the border of every camera that saw it may go on beyond
what was seen (a plate at the edge of the table, half out of the agentview frame). Its
measured footprint is then a lower bound, its fitted shape is the shape of what was seen,
not of the object (half a disc fits a box), and its centre lies nearer the image centre than
the object's. Object detection benchmarks keep the same flag for the same reason (KITTI's
``truncated``; Geiger et al. 2012). Association (:func:`~phyagentos.perception.association.cost_matrix`)
then asks a truncated segment's size only not to exceed a look, and not to have the look's
shape.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from phyagentos.perception.cloud import Cloud, transform
from phyagentos.perception.frames import CameraFrame

__all__ = ["BORDER_PX", "BOX_CUT_ALIGN", "EDGE_PERCENTILE", "MIN_CAMERA_POINTS", "complete_box", "complete_round",
           "cut_direction"]

#: A segment's pixel within this many pixels of the image border (after the camera's point
#: stride) touches the border: the strided grid's last row or column lies up to ``stride - 1``
#: pixels inside the border.
BORDER_PX = 1.5

#: Percentile of the seen points taken as an edge, %: robust to a stray point, and shallow: a
#: disc's 2nd percentile lies 4-7 mm inside its edge (the cap there holds 2 % of its points).
EDGE_PERCENTILE = 0.5

#: A box seen in part is completed along one of its own horizontal axes only where the cut runs
#: within this cosine of it (about 30 degrees): a cut across a corner says too little of which
#: side goes on.
BOX_CUT_ALIGN = 0.866

#: Cameras with fewer of a segment's points than this are not counted as having seen it
#: (the same count :meth:`~phyagentos.perception.perceiver.Perceiver` uses for a detection's
#: ``cameras``).
MIN_CAMERA_POINTS = 5


def _at_border(points_world: np.ndarray, frame: CameraFrame, stride: int) -> np.ndarray:
    """(N,) bool: which of (N, 3) world points project within ``BORDER_PX + stride - 1``
    pixels of ``frame``'s image border (pinhole projection, Hartley & Zisserman eq. 6.2)."""
    T_cam_world = np.linalg.inv(frame.T_world_camera)
    pc = transform(T_cam_world, points_world.astype(np.float64))
    z = pc[:, 2]
    out = np.zeros(len(points_world), dtype=bool)
    ok = z > 1e-6
    if not np.any(ok):
        return out
    intr = frame.intrinsics
    u = intr.fx * pc[ok, 0] / z[ok] + intr.cx
    v = intr.fy * pc[ok, 1] / z[ok] + intr.cy
    margin = BORDER_PX + max(0, stride - 1)
    out[ok] = (u <= margin) | (v <= margin) | (u >= intr.width - 1 - margin) | (v >= intr.height - 1 - margin)
    return out


def cut_direction(cloud: Cloud, index: np.ndarray, frames: Sequence[CameraFrame],
                  strides: Sequence[int]) -> np.ndarray | None:
    """Where a segment cut by the image border goes out of view, or None when it is not cut.

    A segment is cut when at least one camera saw it (``MIN_CAMERA_POINTS`` points or more)
    and, in each camera that did, some of its points lie at the image border.

    Args:
        cloud: the observation's object cloud (``cloud.camera`` indexes ``frames``).
        index: (K,) indices into ``cloud`` of the segment's points.
        frames: the observation's camera frames, in the cloud's camera order.
        strides: (len(frames),) pixel stride each camera's points were sampled at.

    Returns:
        (2,) unit vector in the world's horizontal plane from the centroid of the segment's
        points towards the centroid of those at the border (the side the object may go on
        beyond what was seen), or None.
    """
    idx = np.asarray(index)
    if idx.size == 0:
        return None
    cams = cloud.camera[idx]
    border: list[np.ndarray] = []
    for c in np.unique(cams):
        mine = idx[cams == c]
        if mine.size < MIN_CAMERA_POINTS or int(c) >= len(frames):
            continue
        at = _at_border(cloud.points[mine], frames[int(c)], int(strides[int(c)]))
        if not np.any(at):
            return None  # one camera saw all of it
        border.append(cloud.points[mine[at], :2])
    if not border:
        return None
    d = np.mean(np.concatenate(border), axis=0) - np.mean(cloud.points[idx, :2], axis=0)
    n = float(np.linalg.norm(d))
    return d / n if n > 1e-6 else None


def complete_round(points_xy: np.ndarray, cut: np.ndarray, radius_m: float) -> np.ndarray:
    """The centre of a round object of known radius seen only in part.

    The side of the seen part away from the cut is the object's own edge; the centre lies one
    radius from it, towards the cut. Across the cut, a disc cut by a straight border is seen
    symmetric about the line through its centre, so the centre lies midway across what was
    seen.

    Args:
        points_xy: (N, 2) world x, y of the seen part's points, m.
        cut: (2,) unit vector towards where it runs out of view (:func:`cut_direction`).
        radius_m: the object's radius (its look's), m.

    Returns:
        (2,) world x, y of the centre, m; never further from the cut than the seen part's own
        centroid.
    """
    pts = np.asarray(points_xy, float)
    d = np.asarray(cut, float) / max(float(np.linalg.norm(cut)), 1e-12)
    e = np.array([-d[1], d[0]])
    a, b = pts @ d, pts @ e
    along = max(float(np.percentile(a, EDGE_PERCENTILE)) + float(radius_m), float(np.mean(a)))
    across = 0.5 * (float(np.percentile(b, EDGE_PERCENTILE)) + float(np.percentile(b, 100.0 - EDGE_PERCENTILE)))
    return along * d + across * e


def complete_box(points_xy: np.ndarray, cut: np.ndarray, centre_xy: np.ndarray, yaw_rad: float,
                 half_xy: np.ndarray, size_xy: tuple[float, float]) -> tuple[np.ndarray, np.ndarray] | None:
    """The footprint of a box of known size seen only in part, or None where the part says too
    little.

    The box's axis that the cut runs along (within :data:`BOX_CUT_ALIGN`) is the one it goes on
    beyond what was seen: the seen part's edge away from the cut is the box's own edge, and its
    centre lies half the box's length that way from it, towards the cut. Across the cut it is
    seen whole, so the centre there is the seen part's. Of the look's two horizontal sizes, the
    one nearer the side seen whole lies across the cut, the other along it.

    Args:
        points_xy: (N, 2) world x, y of the seen part's points, m.
        cut: (2,) unit vector towards where it runs out of view (:func:`cut_direction`).
        centre_xy: (2,) world x, y of the seen part's fitted centre, m.
        yaw_rad: the seen part's fitted yaw about world z, rad (its half extents' axes).
        half_xy: (2,) the seen part's fitted half extents along those axes, m.
        size_xy: the look's two horizontal full sizes, m (either order).

    Returns:
        ``((2,) world x, y of the centre, m, (2,) half extents along the same axes, m)``, or
        None where the cut runs across a corner, no side goes on beyond the seen part by more
        than :data:`EDGE_PERCENTILE`'s few millimetres, or the box's length is shorter than what
        was seen (the part is no part of it).
    """
    d = np.asarray(cut, float) / max(float(np.linalg.norm(cut)), 1e-12)
    c, s = float(np.cos(yaw_rad)), float(np.sin(yaw_rad))
    axes = np.array([[c, s], [-s, c]])
    align = axes @ d
    i = int(np.argmax(np.abs(align)))
    if abs(float(align[i])) < BOX_CUT_ALIGN:
        return None
    half = np.asarray(half_xy, float)
    a, b = sorted((float(size_xy[0]), float(size_xy[1])))
    across = 2.0 * float(half[1 - i])
    length = b if abs(a - across) <= abs(b - across) else a  # the side seen whole is the nearer size
    if length < 2.0 * float(half[i]):
        return None
    way = axes[i] * (1.0 if float(align[i]) > 0.0 else -1.0)  # the box's axis, towards the cut
    pts = np.asarray(points_xy, float)
    edge = float(np.percentile(pts @ way, EDGE_PERCENTILE))
    centre = np.asarray(centre_xy, float)
    along = edge + 0.5 * length - float(centre @ way)  # how far the centre moves towards the cut
    if along <= 0.0 or along > 0.5 * length:
        return None
    out = half.copy()
    out[i] = 0.5 * length
    return centre + along * way, out
