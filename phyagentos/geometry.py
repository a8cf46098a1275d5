"""Rotations and poses: the project's one set of quaternion, matrix and transform helpers.

Conventions (MuJoCo's, which every target here uses): quaternions are ``(w, x, y, z)``
(Hamilton product, scalar first); rotation matrices are (3, 3) and act on column vectors;
a pose is a (4, 4) homogeneous transform ``T`` with ``T @ [p, 1]`` mapping a point from
the child frame to the parent frame; angles in rad, lengths in m.

Plain NumPy, no MuJoCo: both planes import it (import-linter keeps it free of either).
:func:`matrix_to_quat` follows MuJoCo's ``mju_mat2Quat`` branch for branch, so a quaternion
computed here equals the one MuJoCo would store (a test checks both on random rotations).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

__all__ = ["quat_to_matrix", "matrix_to_quat", "quat_multiply", "yaw_quat", "quat_yaw", "look_at_quat",
           "rotation_about", "pose_matrix", "turned_xy", "VIEWER_SIDES", "viewer_side_xy"]


def quat_to_matrix(q: Sequence[float]) -> np.ndarray:
    """(3, 3) rotation of the quaternion ``q`` ``(w, x, y, z)``, normalised first.

    Raises:
        ValueError: ``q`` does not have 4 finite entries or is zero.
    """
    w, x, y, z = _unit(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def matrix_to_quat(R: np.ndarray | Sequence[float]) -> list[float]:
    """Unit quaternion ``[w, x, y, z]`` of a rotation ``R`` ((3, 3) or row-major (9,)), as
    plain floats; MuJoCo's ``mju_mat2Quat`` (engine_util_spatial.c): the trace branch when
    the trace is positive, else the branch of the largest diagonal entry.
    """
    m = np.asarray(R, dtype=float).reshape(9)
    tr = m[0] + m[4] + m[8]
    if tr > 0:
        q = [0.5 * math.sqrt(1 + tr), 0.0, 0.0, 0.0]
        q[1] = 0.25 * (m[7] - m[5]) / q[0]
        q[2] = 0.25 * (m[2] - m[6]) / q[0]
        q[3] = 0.25 * (m[3] - m[1]) / q[0]
    elif m[0] > m[4] and m[0] > m[8]:
        q = [0.0, 0.5 * math.sqrt(1 + m[0] - m[4] - m[8]), 0.0, 0.0]
        q[0] = 0.25 * (m[7] - m[5]) / q[1]
        q[2] = 0.25 * (m[1] + m[3]) / q[1]
        q[3] = 0.25 * (m[2] + m[6]) / q[1]
    elif m[4] > m[8]:
        q = [0.0, 0.0, 0.5 * math.sqrt(1 - m[0] + m[4] - m[8]), 0.0]
        q[0] = 0.25 * (m[2] - m[6]) / q[2]
        q[1] = 0.25 * (m[1] + m[3]) / q[2]
        q[3] = 0.25 * (m[5] + m[7]) / q[2]
    else:
        q = [0.0, 0.0, 0.0, 0.5 * math.sqrt(1 - m[0] - m[4] + m[8])]
        q[0] = 0.25 * (m[3] - m[1]) / q[3]
        q[1] = 0.25 * (m[2] + m[6]) / q[3]
        q[2] = 0.25 * (m[5] + m[7]) / q[3]
    n = math.sqrt(sum(v * v for v in q))
    return [float(v / n) for v in q]


def quat_multiply(a: Sequence[float], b: Sequence[float]) -> list[float]:
    """Hamilton product ``a * b`` of two ``(w, x, y, z)`` quaternions (rotate by ``b``,
    then by ``a``), as plain floats; MuJoCo's ``mju_mulQuat``."""
    aw, ax, ay, az = (float(v) for v in a)
    bw, bx, by, bz = (float(v) for v in b)
    return [aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw]


def yaw_quat(yaw: float) -> list[float]:
    """``[w, x, y, z]`` of a rotation by ``yaw`` rad about +z."""
    return [math.cos(yaw / 2.0), 0.0, 0.0, math.sin(yaw / 2.0)]


def quat_yaw(q: Sequence[float]) -> float:
    """Yaw, rad in (-pi, pi], of the quaternion ``q`` ``(w, x, y, z)``: the heading of its
    rotated x axis in the world's xy plane (the inverse of :func:`yaw_quat` for a turn about z;
    ZYX Euler angles' first, e.g. Diebel, "Representing Attitude", 2006, eq. 290)."""
    w, x, y, z = (float(v) for v in q)
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def look_at_quat(eye: Sequence[float], target: Sequence[float], up: Sequence[float] = (0.0, 0.0, 1.0)) -> list[float]:
    """``[w, x, y, z]`` of a MuJoCo camera at ``eye`` (3,) looking at ``target`` (3,), its
    image's up direction towards ``up`` (3,), all in the parent frame, m. A MuJoCo camera
    looks along its -z axis with +y up in the image.

    Raises:
        ValueError: ``eye`` equals ``target`` or the view direction is parallel to ``up``.
    """
    eye_v = np.asarray(eye, dtype=float)
    fwd = np.asarray(target, dtype=float) - eye_v
    if not np.linalg.norm(fwd) > 0:
        raise ValueError(f"look_at_quat: eye {list(eye)} equals target {list(target)}")
    fwd /= np.linalg.norm(fwd)
    x = np.cross(fwd, np.asarray(up, dtype=float))
    if not np.linalg.norm(x) > 1e-12:
        raise ValueError(f"look_at_quat: the view direction {fwd.tolist()} is parallel to up {list(up)}")
    x /= np.linalg.norm(x)
    y = np.cross(x, fwd)
    return matrix_to_quat(np.column_stack([x, y, -fwd]))


def rotation_about(axis: Sequence[float], angle: float) -> np.ndarray:
    """(3, 3) rotation by ``angle`` rad about ``axis`` (3,) (normalised first), by
    Rodrigues' formula ``I + sin(a) K + (1 - cos(a)) K^2``, ``K`` the cross-product matrix."""
    k = np.asarray(axis, dtype=float)
    k = k / np.linalg.norm(k)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * K @ K


def pose_matrix(position: Sequence[float], rotation: Sequence[float] | np.ndarray) -> np.ndarray:
    """(4, 4) transform from a position (3,) in m and a rotation: a ``(w, x, y, z)``
    quaternion (4,), a row-major matrix (9,) as MuJoCo's ``xmat``, or a (3, 3) matrix.

    Raises:
        ValueError: ``rotation`` has another shape.
    """
    r = np.asarray(rotation, dtype=float)
    T = np.eye(4)
    if r.shape == (4,):
        T[:3, :3] = quat_to_matrix(r)
    elif r.size == 9:
        T[:3, :3] = r.reshape(3, 3)
    else:
        raise ValueError(f"pose_matrix: rotation must be a quaternion (4,) or a matrix (9,) or (3, 3), got shape "
                         f"{r.shape}")
    T[:3, 3] = np.asarray(position, dtype=float).reshape(3)
    return T


def turned_xy(xy: Sequence[float], angle: float) -> np.ndarray:
    """(2,) ``xy`` (m) turned ``angle`` rad about the vertical (counter-clockwise seen from above)."""
    c, s = math.cos(angle), math.sin(angle)
    x, y = float(xy[0]), float(xy[1])
    return np.array([c * x - s * y, s * x + c * y])


#: The sides of a thing as a viewer sees it on the table: ``left`` / ``right`` (the camera image's x
#: axis), ``front`` (towards the viewer) and ``back`` (away from it).
VIEWER_SIDES = ("left", "right", "front", "back")


def viewer_side_xy(right_xy: Sequence[float], side: str) -> np.ndarray:
    """(2,) unit vector on the table, world frame, pointing to the viewer's ``side`` of a thing.

    ``right_xy`` is the viewer's right on the table (the scene camera's image x axis projected
    on it, any length). With z up, a camera's right is its forward direction crossed with up,
    so towards the viewer (``front``) is the right turned a quarter turn clockwise seen from
    above: ``(right_y, -right_x)``.

    Raises:
        ValueError: ``side`` is not one of :data:`VIEWER_SIDES`, or ``right_xy`` is not two finite
            numbers, not both 0.
    """
    if side not in VIEWER_SIDES:
        raise ValueError(f"side must be one of {', '.join(VIEWER_SIDES)}, got {side!r}")
    r = np.asarray(right_xy, dtype=float).reshape(-1)
    n = float(np.linalg.norm(r)) if r.shape == (2,) else float("nan")
    if not (math.isfinite(n) and n > 1e-12):
        raise ValueError(f"right_xy must be 2 finite numbers, not both 0, got {right_xy!r}")
    r = r / n
    front = np.array([r[1], -r[0]])
    return {"right": r, "left": -r, "front": front, "back": -front}[side]


def _unit(q: Sequence[float]) -> tuple[float, float, float, float]:
    v = [float(x) for x in q]
    n = math.sqrt(sum(x * x for x in v)) if len(v) == 4 else float("nan")
    if not (math.isfinite(n) and n > 0):
        raise ValueError(f"a quaternion must have 4 finite entries, not all zero; got {list(q)}")
    return v[0] / n, v[1] / n, v[2] / n, v[3] / n
