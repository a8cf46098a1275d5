"""Point clouds: RGB-D back-projection, support-plane fit, workspace crop and robot masks.

Every function is vectorised numpy; arrays are world-frame metres unless a docstring says
otherwise.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from functools import lru_cache
from typing import Sequence

import numpy as np

from phyagentos.perception.config import PerceptionConfig
from phyagentos.perception.errors import PerceptionError
from phyagentos.perception.frames import CameraFrame, CameraIntrinsics, Proprioception

__all__ = [
    "Cloud",
    "Plane",
    "RobotCapsule",
    "backproject",
    "heights_above",
    "merge_clouds",
    "fit_support_plane",
    "object_mask",
    "capsule_mask",
    "gripper_mask",
    "box_mask",
    "voxel_downsample",
    "transform",
    "dot3",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Cloud:
    """A coloured point cloud.

    Attributes:
        points: (N, 3) world-frame positions, m.
        rgb: (N, 3) uint8 colours.
        range_m: (N,) depth along the capturing camera's optical axis, m.
        camera: (N,) int index of the capturing camera in the observation.
    """

    points: np.ndarray
    rgb: np.ndarray
    range_m: np.ndarray
    camera: np.ndarray

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def select(self, mask: np.ndarray) -> "Cloud":
        """The sub-cloud where ``mask`` ((N,) bool or an index array) holds."""
        return Cloud(self.points[mask], self.rgb[mask], self.range_m[mask], self.camera[mask])


@dataclass(frozen=True)
class Plane:
    """The support plane n . p = d (unit normal ``n`` pointing up, world frame).

    Attributes:
        normal: (3,) unit normal, world frame, n_z > 0.
        offset_m: d, m.
        inliers: number of points that supported it (0 when the prior plane was used).
        fitted: False when too few table points were seen and the prior height was used.
    """

    normal: np.ndarray
    offset_m: float
    inliers: int
    fitted: bool

    def height(self, points: np.ndarray) -> np.ndarray:
        """(N,) signed height (m) of (N, 3) points above the plane."""
        return dot3(points, self.normal) - self.offset_m

    def z_at(self, xy: np.ndarray) -> float:
        """World z (m) of the plane below world point ``xy`` (2,)."""
        n = self.normal
        return float((self.offset_m - n[0] * xy[0] - n[1] * xy[1]) / n[2])


@dataclass(frozen=True)
class RobotCapsule:
    """A capsule (segment p0-p1 with a radius) enclosing one robot link, world frame, m.

    The caller (the target, from its forward kinematics) may pass these to mask the arm;
    the gripper box around the tcp is always masked.
    """

    p0: tuple[float, float, float]
    p1: tuple[float, float, float]
    radius_m: float


def transform(T: np.ndarray, p: np.ndarray) -> np.ndarray:
    """(N, 3) points ``p`` mapped by the (4, 4) pose ``T`` (in ``p``'s dtype).

    Written as three broadcast multiply-adds rather than a matrix product: tiny (N, 3) x
    (3, 3) products go to a multithreaded BLAS, which on a loaded 2-core machine is 10-50x
    slower than this (measured, see docs/perception.md).
    """
    R = T[:3, :3].astype(p.dtype)
    t = T[:3, 3].astype(p.dtype)
    return p[:, 0:1] * R[:, 0] + p[:, 1:2] * R[:, 1] + p[:, 2:3] * R[:, 2] + t


def dot3(p: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(N,) dot products of (N, 3) ``p`` with (3,) ``v`` (no BLAS, see :func:`transform`)."""
    v = np.asarray(v, dtype=p.dtype)
    return p[:, 0] * v[0] + p[:, 1] * v[1] + p[:, 2] * v[2]


@lru_cache(maxsize=16)
def _rays(intr: CameraIntrinsics, stride: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Sampled pixel rows/cols and their normalised ray directions (x/z, y/z) for ``intr``."""
    v = np.arange(0, intr.height, stride)
    u = np.arange(0, intr.width, stride)
    uu, vv = np.meshgrid(u, v)
    xr = ((uu - intr.cx) / intr.fx).astype(np.float32).ravel()
    yr = ((vv - intr.cy) / intr.fy).astype(np.float32).ravel()
    return vv.ravel(), uu.ravel(), xr, yr


def backproject(frame: CameraFrame, *, stride: int, min_depth_m: float, max_depth_m: float,
                camera_index: int = 0, pixels: np.ndarray | None = None) -> Cloud:
    """Back-project every ``stride``-th pixel of an RGB-D frame into the world frame.

    A pixel (u, v) with metric depth d gives p_cam = (d (u - cx)/fx, d (v - cy)/fy, d) in the
    OpenCV optical frame and p_world = R p_cam + t with (R, t) from ``frame.T_world_camera``
    (Hartley & Zisserman, Multiple View Geometry, eq. 6.8 inverted). Pixels with depth 0
    (no return) or outside [min_depth_m, max_depth_m] are dropped. ``pixels`` optionally
    restricts the result to those indices into the strided pixel grid.

    Raises:
        PerceptionError: the frame has no depth image.
    """
    if frame.depth_m is None:
        raise PerceptionError(f"camera {frame.sensor!r} has no depth image; perception needs RGB-D")
    vv, uu, xr, yr = _rays(frame.intrinsics, stride)
    if pixels is not None:
        vv, uu, xr, yr = vv[pixels], uu[pixels], xr[pixels], yr[pixels]
    d = frame.depth_m[vv, uu]
    keep = (d >= min_depth_m) & (d <= max_depth_m)
    d = d[keep]
    pc = np.stack([xr[keep] * d, yr[keep] * d, d], axis=1)
    pts = transform(frame.T_world_camera, pc)
    rgb = frame.rgb[vv[keep], uu[keep]]
    cam = np.full(d.shape[0], camera_index, dtype=np.int16)
    return Cloud(pts, rgb, d, cam)


def heights_above(frame: CameraFrame, plane: "Plane", *, stride: int) -> tuple[np.ndarray, np.ndarray]:
    """``(depth, height)``: (M,) depth and height above ``plane`` of every strided pixel, m.

    Uses that height is linear in depth along a pixel's ray:
    h = d * (n . R r) + (n . t - offset) with r = ((u - cx)/fx, (v - cy)/fy, 1), so no
    3-D point is formed (the cheap pre-filter before :func:`backproject` of the candidates).
    """
    vv, uu, xr, yr = _rays(frame.intrinsics, stride)
    T = frame.T_world_camera
    k = (T[:3, :3].T @ plane.normal).astype(np.float32)
    d = frame.depth_m[vv, uu]
    h = d * (xr * k[0] + yr * k[1] + k[2]) + np.float32(plane.normal @ T[:3, 3] - plane.offset_m)
    return d, h


def merge_clouds(clouds: Sequence[Cloud]) -> Cloud:
    """Concatenate clouds (their ``camera`` indices are kept)."""
    if len(clouds) == 1:
        return clouds[0]
    return Cloud(
        np.concatenate([c.points for c in clouds]),
        np.concatenate([c.rgb for c in clouds]),
        np.concatenate([c.range_m for c in clouds]),
        np.concatenate([c.camera for c in clouds]),
    )


def fit_support_plane(points: np.ndarray, config: PerceptionConfig, *,
                      rng: np.random.Generator | None = None) -> Plane:
    """Fit the table plane by RANSAC near the prior height, then least squares on the inliers.

    Hypotheses come from random point triples among the points within
    ``table.search_margin_m`` of ``table.expected_height_m``; each is scored on (at most)
    4096 of those points, planes tilted more than ``table.max_tilt_rad`` are rejected, and
    the winner is refined by the total-least-squares plane (SVD) of its inliers (Fischler &
    Bolles 1981). With fewer than ``table.min_inliers`` inliers the prior horizontal plane
    z = expected_height_m is returned with ``fitted=False``.
    """
    tc = config.table
    prior = Plane(np.array([0.0, 0.0, 1.0]), tc.expected_height_m, 0, False)
    near = points[np.abs(points[:, 2] - tc.expected_height_m) < tc.search_margin_m]
    if near.shape[0] < tc.min_inliers:
        log.debug("support plane: %d points near the prior height, using the prior", near.shape[0])
        return prior
    rng = rng if rng is not None else np.random.default_rng(0)
    sample = near if near.shape[0] <= 4096 else near[rng.choice(near.shape[0], 4096, replace=False)]
    sample = sample.astype(np.float64)  # a mixed float32 @ float64 product skips BLAS (20x slower)
    idx = rng.integers(0, sample.shape[0], size=(tc.ransac_iterations, 3))
    a, b, c = sample[idx[:, 0]], sample[idx[:, 1]], sample[idx[:, 2]]
    n = np.cross(b - a, c - a).astype(np.float64)
    norm = np.linalg.norm(n, axis=1)
    ok = norm > 1e-9
    n[ok] /= norm[ok, None]
    n[n[:, 2] < 0] *= -1.0
    ok &= n[:, 2] > np.cos(tc.max_tilt_rad)
    if not np.any(ok):
        return prior
    n, a = n[ok], a[ok]
    d = np.einsum("ij,ij->i", n, a)
    resid = np.abs(sample[:, 0:1] * n[:, 0] + sample[:, 1:2] * n[:, 1] + sample[:, 2:3] * n[:, 2] - d)  # (M, K)
    scores = (resid < tc.inlier_threshold_m).sum(axis=0)
    best = int(np.argmax(scores))
    inl = sample[resid[:, best] < tc.inlier_threshold_m]
    if inl.shape[0] < tc.min_inliers:
        return prior
    centre = inl.mean(axis=0)
    # total least squares: the normal is the eigenvector of the smallest eigenvalue
    q = inl - centre
    cov = np.einsum("ni,nj->ij", q, q) / q.shape[0]
    _, vecs = np.linalg.eigh(cov)
    normal = vecs[:, 0] if vecs[2, 0] > 0 else -vecs[:, 0]
    if normal[2] < np.cos(tc.max_tilt_rad):
        return prior
    return Plane(normal, float(normal @ centre), int(scores[best]), True)


def object_mask(points: np.ndarray, plane: Plane, config: PerceptionConfig) -> tuple[np.ndarray, np.ndarray]:
    """``(mask, height)``: points above the plane and inside the workspace crop.

    Keeps points with ``table.object_min_height_m < height < workspace.max_height_m`` inside
    the workspace xy rectangle and outside the base exclusion disc around ``workspace.base_xy_m``.
    """
    ws = config.workspace
    h = plane.height(points)
    x, y = points[:, 0], points[:, 1]
    m = (h > config.table.object_min_height_m) & (h < ws.max_height_m)
    m &= (x > ws.x_m[0]) & (x < ws.x_m[1]) & (y > ws.y_m[0]) & (y < ws.y_m[1])
    if ws.base_exclusion_radius_m > 0:
        bx, by = ws.base_xy_m
        m &= (x - bx) ** 2 + (y - by) ** 2 > ws.base_exclusion_radius_m ** 2
    return m, h


def box_mask(points: np.ndarray, T_world_box: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(N,) bool: points inside the box [lo, hi] (3,) expressed in the frame ``T_world_box``."""
    q = points - T_world_box[:3, 3].astype(points.dtype)
    R = T_world_box[:3, :3].astype(points.dtype)
    local = q[:, 0:1] * R[0] + q[:, 1:2] * R[1] + q[:, 2:3] * R[2]  # R^T q
    return np.all((local >= lo) & (local <= hi), axis=1)


def gripper_mask(points: np.ndarray, proprio: Proprioception, config: PerceptionConfig) -> np.ndarray:
    """(N,) bool: points inside the gripper box around the tcp (``robot_mask`` in the tcp frame)."""
    rm = config.robot_mask
    lo = np.array([-rm.gripper_half_x_m, -rm.gripper_half_y_m, rm.gripper_z_m[0]])
    hi = np.array([rm.gripper_half_x_m, rm.gripper_half_y_m, rm.gripper_z_m[1]])
    return box_mask(points, proprio.tcp_pose, lo, hi)


def capsule_mask(points: np.ndarray, capsules: Sequence[RobotCapsule], margin_m: float) -> np.ndarray:
    """(N,) bool: points within (radius + margin) of any capsule's segment."""
    out = np.zeros(points.shape[0], dtype=bool)
    for cap in capsules:
        p0, p1 = np.asarray(cap.p0, float), np.asarray(cap.p1, float)
        seg = p1 - p0
        L2 = float(seg @ seg)
        rel = points - p0
        t = np.clip(dot3(rel, seg) / L2, 0.0, 1.0) if L2 > 0 else np.zeros(points.shape[0])
        dist2 = np.sum((rel - t[:, None] * seg) ** 2, axis=1)
        out |= dist2 < (cap.radius_m + margin_m) ** 2
    return out


def voxel_downsample(cloud: Cloud, voxel_m: float) -> Cloud:
    """Keep one point (the first) per occupied voxel of edge ``voxel_m`` (0 = unchanged)."""
    if voxel_m <= 0 or len(cloud) == 0:
        return cloud
    keys = np.floor(cloud.points / voxel_m).astype(np.int64)
    keys -= keys.min(axis=0)
    dims = keys.max(axis=0) + 1
    flat = (keys[:, 0] * dims[1] + keys[:, 1]) * dims[2] + keys[:, 2]
    _, first = np.unique(flat, return_index=True)
    return cloud.select(np.sort(first))
