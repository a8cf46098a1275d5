"""``sensors.yaml``: what each target's robot can measure (cameras, joints, gripper, wrist F/T).

Deploy-time configuration like ``safety.yaml``: frozen models, read-only at run time.
One entry per target name (as in TARGETS.md); each a list of :class:`SensorSpec`.
Units: pixels, degrees (``fovy_deg``), Hz, metres.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Literal

from pydantic import ConfigDict, Field, model_validator

from .codec import read_yaml
from .schemas import ProtocolModel, StrictNumbers, VersionedModel

__all__ = ["SENSOR_KINDS", "SensorMount", "CameraNoiseSpec", "RealCameraSpec", "SensorSpec", "SensorsConfig",
           "SENSORS_FILE", "read_sensors"]

SENSORS_FILE = "sensors.yaml"
SENSOR_KINDS: tuple[str, ...] = ("rgbd_camera", "rgb_camera", "joint_state", "gripper", "force_torque")
_CAMERAS = ("rgbd_camera", "rgb_camera")


class SensorMount(StrictNumbers, ProtocolModel):
    """Where a sensor sits: a model body (its extrinsics follow that body) and, for a
    camera, the model camera that renders it (default: the sensor's name), or a site."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    body: str | None = Field(None, description="Model body the sensor is fixed to ('world' for a fixed camera).")
    camera: str | None = Field(None, description="Model camera rendering this sensor (default: the sensor name).")
    site: str | None = Field(None, description="Model site of a force/torque sensor.")


class CameraNoiseSpec(StrictNumbers, ProtocolModel):
    """Noise of a simulated camera, drawn from the episode seed.

    ``depth_sigma_per_m2``: depth noise sigma = k * z^2 (structured-light/stereo depth error
    grows with the square of the distance; Khoshelham & Elberink 2012, Sensors 12(2): about
    1.5 mm at 1 m for the Kinect). ``rgb_sigma``: per-pixel Gaussian noise in 8-bit counts.
    ``lighting_jitter``: sigma of a per-episode brightness gain around 1 (lighting variation).
    """

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    depth_sigma_per_m2: float = Field(0.0015, ge=0, le=0.1)
    rgb_sigma: float = Field(2.0, ge=0, le=64)
    lighting_jitter: float = Field(0.08, ge=0, le=0.5)


class RealCameraSpec(StrictNumbers, ProtocolModel):
    """A physical camera of a real target (issue 32): opened with OpenCV's ``VideoCapture``
    by ``device`` (an index such as 0, or a path such as ``/dev/video2`` or a video file),
    with its calibrated pinhole ``intrinsics`` (pixels, OpenCV convention, at the sensor's
    width x height) and, for a fixed camera, the pose of its optical frame (x right, y
    down, z forward) in the world: ``position_m`` and ``quat_wxyz``."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    device: int | str = Field(description="OpenCV VideoCapture index or path.")
    fx: float = Field(gt=0, le=100_000, description="Focal length along x, pixels.")
    fy: float = Field(gt=0, le=100_000, description="Focal length along y, pixels.")
    cx: float = Field(ge=-100_000, le=100_000, description="Principal point x, pixels.")
    cy: float = Field(ge=-100_000, le=100_000, description="Principal point y, pixels.")
    position_m: tuple[float, float, float] = Field(description="Optical frame origin in the world, m.")
    quat_wxyz: tuple[float, float, float, float] = Field(description="Optical frame orientation in the world.")


class SensorSpec(StrictNumbers, ProtocolModel):
    """One sensor of a target."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    name: str = Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_\-]+$")
    kind: Literal["rgbd_camera", "rgb_camera", "joint_state", "gripper", "force_torque"]
    frame_id: str = Field(min_length=1, max_length=128, description="Frame the measurements are expressed in.")
    rate_hz: float = Field(gt=0, le=10000, description="Nominal sample rate, Hz.")
    width: int | None = Field(None, gt=0, le=4096, description="Image width, pixels (cameras).")
    height: int | None = Field(None, gt=0, le=4096, description="Image height, pixels (cameras).")
    fovy_deg: float | None = Field(None, gt=0, lt=180, description="Vertical field of view, degrees (cameras).")
    mount: SensorMount = Field(default_factory=SensorMount)
    noise: CameraNoiseSpec = Field(default_factory=CameraNoiseSpec)
    real: RealCameraSpec | None = Field(None, description="A physical camera (real targets): device and "
                                                          "calibration; None: rendered by the target's model.")

    @model_validator(mode="after")
    def _camera_fields(self) -> "SensorSpec":
        if self.kind in _CAMERAS and (self.width is None or self.height is None):
            raise ValueError(f"sensor {self.name!r}: a camera needs width and height (pixels)")
        if self.real is not None and self.kind not in _CAMERAS:
            raise ValueError(f"sensor {self.name!r}: only cameras can be real (kind {self.kind!r})")
        return self

    @property
    def camera_name(self) -> str:
        """Model camera that renders this sensor."""
        return self.mount.camera or self.name


class SensorsConfig(StrictNumbers, VersionedModel):
    """``sensors.yaml``: ``targets: {target name: [SensorSpec, ...]}``."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    targets: dict[str, tuple[SensorSpec, ...]] = Field(default_factory=dict)

    @model_validator(mode="after")
    def _unique(self) -> "SensorsConfig":
        for target, sensors in self.targets.items():
            names = [s.name for s in sensors]
            dup = sorted({n for n in names if names.count(n) > 1})
            if dup:
                raise ValueError(f"target {target!r}: sensor name(s) {dup} used twice")
        return self

    def for_target(self, name: str) -> tuple[SensorSpec, ...]:
        """The sensors of target ``name`` (empty if it declares none)."""
        return tuple(self.targets.get(name, ()))


def read_sensors(workspace_root: str | os.PathLike[str] | None = None) -> SensorsConfig:
    """The workspace's ``sensors.yaml``, or the shipped template's when the workspace has
    none (a workspace created before the file existed) or no workspace is given.

    Raises:
        DocumentError: the file is malformed (path and line in the message).
    """
    if workspace_root is not None:
        path = Path(workspace_root) / SENSORS_FILE
        if path.is_file():
            return read_yaml(path, SensorsConfig)
    from phyagentos.resources import templates_dir  # noqa: PLC0415

    return read_yaml(templates_dir() / SENSORS_FILE, SensorsConfig)
