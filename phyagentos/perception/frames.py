"""Sensor data types: a camera's intrinsics, one captured RGB-D frame, one proprioception sample.

These are the value objects the targets produce (``MuJoCoArmTarget.capture`` /
``.proprioception``) and the perception pipeline consumes (issue 9, CONTRACT_9.md section 1).
Every array is validated on construction (shape, dtype, finite values); a bad frame raises
:class:`~phyagentos.perception.errors.PerceptionError` before anything uses it.

Conventions:

* the world frame is the target's MuJoCo world frame (z up, tabletop at z = 0 for the tabletop
  targets);
* a camera's *optical* frame follows OpenCV: x right, y down, z forward (along the viewing
  direction). A pixel (u, v) with metric depth d back-projects to
  ``p_cam = (d (u - cx) / fx, d (v - cy) / fy, d)`` and ``p_world = T_world_camera @ p_cam``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from phyagentos.perception.errors import PerceptionError

__all__ = ["CameraIntrinsics", "CameraFrame", "Proprioception"]


def _finite_number(owner: str, name: str, value, *, positive: bool = False) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise PerceptionError(f"{owner}.{name} must be a number, got {type(value).__name__}")
    if not math.isfinite(float(value)):
        raise PerceptionError(f"{owner}.{name} must be finite, got {value!r}")
    if positive and float(value) <= 0.0:
        raise PerceptionError(f"{owner}.{name} must be > 0, got {value!r}")


def _array(owner: str, name: str, value, shape: tuple, *, kinds: str = "fiu") -> np.ndarray:
    """Check ``value`` is an ndarray of ``shape`` (None = any length) with a numeric dtype."""
    if not isinstance(value, np.ndarray):
        raise PerceptionError(f"{owner}.{name} must be a numpy array, got {type(value).__name__}")
    if value.ndim != len(shape) or any(s is not None and s != d for s, d in zip(shape, value.shape)):
        want = "(" + ", ".join("n" if s is None else str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"
        raise PerceptionError(f"{owner}.{name} must have shape {want}, got {value.shape}")
    if value.dtype.kind not in kinds:
        raise PerceptionError(f"{owner}.{name} must have a numeric dtype, got {value.dtype}")
    if value.dtype.kind == "f" and not np.all(np.isfinite(value)):
        raise PerceptionError(f"{owner}.{name} contains NaN or infinite values")
    return value


def _rigid(owner: str, name: str, T) -> None:
    _array(owner, name, T, (4, 4), kinds="f")
    R = T[:3, :3]
    if not np.allclose(T[3], (0.0, 0.0, 0.0, 1.0), atol=1e-6):
        raise PerceptionError(f"{owner}.{name} last row must be [0, 0, 0, 1], got {T[3].tolist()}")
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-4) or np.linalg.det(R) < 0.0:
        raise PerceptionError(f"{owner}.{name} rotation part is not a proper rotation matrix")


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics in the OpenCV convention (pixels; (0, 0) is the top-left pixel centre).

    Raises:
        PerceptionError: non-positive size or focal length, or non-finite values.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    def __post_init__(self) -> None:
        for name in ("width", "height"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v <= 0:
                raise PerceptionError(f"CameraIntrinsics.{name} must be a positive int, got {v!r}")
        for name in ("fx", "fy"):
            _finite_number("CameraIntrinsics", name, getattr(self, name), positive=True)
        for name in ("cx", "cy"):
            _finite_number("CameraIntrinsics", name, getattr(self, name))

    def matrix(self) -> np.ndarray:
        """(3, 3) camera matrix K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] in pixels."""
        return np.array(
            [[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]], dtype=float
        )

    @classmethod
    def from_fovy(cls, width: int, height: int, fovy_deg: float) -> "CameraIntrinsics":
        """Intrinsics of an ideal pinhole with vertical field of view ``fovy_deg`` (MuJoCo's
        ``cam_fovy``): ``fy = (height / 2) / tan(fovy / 2)``, square pixels (``fx = fy``),
        principal point at the image centre ``((width - 1) / 2, (height - 1) / 2)``.

        Raises:
            PerceptionError: fovy outside (0, 180) degrees or a bad image size.
        """
        _finite_number("CameraIntrinsics", "fovy_deg", fovy_deg, positive=True)
        if not 0.0 < float(fovy_deg) < 180.0:
            raise PerceptionError(f"fovy_deg must be in (0, 180), got {fovy_deg!r}")
        f = 0.5 * height / math.tan(math.radians(float(fovy_deg)) / 2.0)
        return cls(
            width=int(width), height=int(height), fx=f, fy=f,
            cx=(width - 1) / 2.0, cy=(height - 1) / 2.0,
        )


@dataclass(frozen=True)
class CameraFrame:
    """One captured camera image (RGB and optional metric depth) with its pose and time.

    Attributes:
        sensor: sensor name from sensors.yaml, e.g. ``"overview"``, ``"wrist"``.
        frame_id: optical frame name, e.g. ``"overview_optical"``.
        stamp_s: target clock (sim time) at capture, s.
        intrinsics: pinhole intrinsics of ``rgb`` and ``depth_m`` (same resolution).
        T_world_camera: (4, 4) pose of the optical frame (x right, y down, z forward) in the
            world frame.
        rgb: (H, W, 3) uint8 image.
        depth_m: (H, W) float32 metres along the optical z axis, 0 = no return; None for an
            RGB-only camera.

    Raises:
        PerceptionError: a shape, dtype or non-finite value that breaks these rules.
    """

    sensor: str
    frame_id: str
    stamp_s: float
    intrinsics: CameraIntrinsics
    T_world_camera: np.ndarray
    rgb: np.ndarray
    depth_m: np.ndarray | None

    def __post_init__(self) -> None:
        owner = f"CameraFrame({self.sensor!r})"
        for name in ("sensor", "frame_id"):
            v = getattr(self, name)
            if not isinstance(v, str) or not v:
                raise PerceptionError(f"{owner}.{name} must be a non-empty string, got {v!r}")
        _finite_number(owner, "stamp_s", self.stamp_s)
        if not isinstance(self.intrinsics, CameraIntrinsics):
            raise PerceptionError(
                f"{owner}.intrinsics must be CameraIntrinsics, got {type(self.intrinsics).__name__}"
            )
        _rigid(owner, "T_world_camera", self.T_world_camera)
        h, w = self.intrinsics.height, self.intrinsics.width
        _array(owner, "rgb", self.rgb, (h, w, 3))
        if self.rgb.dtype != np.uint8:
            raise PerceptionError(f"{owner}.rgb must be uint8, got {self.rgb.dtype}")
        if self.depth_m is not None:
            _array(owner, "depth_m", self.depth_m, (h, w))
            if self.depth_m.dtype != np.float32:
                raise PerceptionError(f"{owner}.depth_m must be float32, got {self.depth_m.dtype}")
            if np.any(self.depth_m < 0.0):
                raise PerceptionError(f"{owner}.depth_m must be >= 0 (0 = no return)")


@dataclass(frozen=True)
class Proprioception:
    """One sample of the robot's own sensors.

    Attributes:
        stamp_s: target clock at the sample, s.
        joint_names: names of the n arm joints, in the order of the arrays below.
        joint_positions: (n,) rad.
        joint_velocities: (n,) rad/s.
        joint_efforts: (n,) N*m, actuator forces (MuJoCo ``actuator_force``).
        gripper_opening_m: opening per finger, m (0 = closed).
        gripper_effort_n: finger actuator force, N (squeeze; 0 when open and free).
        wrist_force_n: (3,) N in the wrist sensor frame, or None without an F/T sensor.
        wrist_torque_nm: (3,) N*m in the wrist sensor frame, or None.
        tcp_pose: (4, 4) forward kinematics of the tool site in the world frame.
        finger_offsets_m: (2,) m: how far each finger stands from the tcp along the closing
            axis (tcp y), the finger on the tcp's +y side first, then the one on its -y side,
            each 0 at the middle and positive when open; ``None`` for a hand that reports only
            its opening (fingers coupled, as the Franka Hand's are). A hand whose fingers are
            driven apart (robosuite's Panda gripper in LIBERO: one position servo per finger)
            tells from it which finger stopped on something.

    Raises:
        PerceptionError: mismatched lengths, wrong shapes or non-finite values.
    """

    stamp_s: float
    joint_names: tuple[str, ...]
    joint_positions: np.ndarray
    joint_velocities: np.ndarray
    joint_efforts: np.ndarray
    gripper_opening_m: float
    gripper_effort_n: float
    wrist_force_n: np.ndarray | None
    wrist_torque_nm: np.ndarray | None
    tcp_pose: np.ndarray
    finger_offsets_m: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        owner = "Proprioception"
        _finite_number(owner, "stamp_s", self.stamp_s)
        if not isinstance(self.joint_names, tuple) or not all(
            isinstance(n, str) for n in self.joint_names
        ):
            raise PerceptionError(f"{owner}.joint_names must be a tuple of str")
        n = len(self.joint_names)
        for name in ("joint_positions", "joint_velocities", "joint_efforts"):
            _array(owner, name, getattr(self, name), (n,))
        _finite_number(owner, "gripper_opening_m", self.gripper_opening_m)
        _finite_number(owner, "gripper_effort_n", self.gripper_effort_n)
        for name in ("wrist_force_n", "wrist_torque_nm"):
            v = getattr(self, name)
            if v is not None:
                _array(owner, name, v, (3,))
        _rigid(owner, "tcp_pose", self.tcp_pose)
        if self.finger_offsets_m is not None:
            f = self.finger_offsets_m
            if not isinstance(f, tuple) or len(f) != 2:
                raise PerceptionError(f"{owner}.finger_offsets_m must be a tuple of 2 numbers (m) or None, got {f!r}")
            for k, v in enumerate(f):
                _finite_number(owner, f"finger_offsets_m[{k}]", v)
