"""perception.yaml: the perception pipeline's deploy-time parameters (a frozen pydantic model).

The template is ``protocol/perception.yaml``; :meth:`PerceptionConfig.default` equals it
(a test pins that). Like ``safety.yaml`` it is read-only at run time: nothing on the memory
or self-evolution path writes it. Units: metres, radians, seconds, newtons; colours as
CIELAB distances (CIE 1976 Delta E*ab).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from phyagentos.protocol.codec import parse_yaml, read_yaml
from phyagentos.protocol.schemas import StrictNumbers, VersionedModel

__all__ = [
    "PerceptionConfig",
    "CloudConfig",
    "DepthNoiseConfig",
    "TableConfig",
    "WorkspaceConfig",
    "RobotMaskConfig",
    "ClusteringConfig",
    "ShapeConfig",
    "AssociationConfig",
    "FusionConfig",
    "HoldingConfig",
    "RelationsConfig",
    "PERCEPTION_FILE",
    "template_path",
]

#: File name of the workspace's perception configuration.
PERCEPTION_FILE = "perception.yaml"


def template_path() -> Path:
    """The shipped template ``protocol/perception.yaml`` (``PHYAGENTOS_HOME`` aware)."""
    from phyagentos import resources

    return resources.templates_dir() / PERCEPTION_FILE


class _Section(StrictNumbers):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class CloudConfig(_Section):
    sample_width_px: int = Field(
        320, le=4096, ge=16, description="Pixel stride per camera = ceil(width / sample_width_px)."
    )
    voxel_size_m: float = Field(
        0.003, le=0.5, ge=0, description="Voxel grid for the object points (0 = no voxel filter)."
    )
    min_depth_m: float = Field(0.05, le=10.0, ge=0, description="Returns closer than this are dropped.")
    max_depth_m: float = Field(3.0, le=20.0, gt=0, description="Returns farther than this are dropped.")


class DepthNoiseConfig(_Section):
    """1-sigma depth noise model sigma(z) = base_m + quadratic_per_m * z**2 (structured-light
    and stereo sensors have noise quadratic in range; Khoshelham & Elberink 2012)."""

    base_m: float = Field(0.0005, le=0.1, ge=0)
    quadratic_per_m: float = Field(0.0015, le=0.1, ge=0)


class TableConfig(_Section):
    expected_height_m: float = Field(0.0, ge=-10.0, le=10.0, description="Prior support height (world z), m.")
    search_margin_m: float = Field(
        0.04, le=1.0, gt=0, description="Plane hypotheses use points within this of the prior height."
    )
    inlier_threshold_m: float = Field(0.004, le=0.5, gt=0, description="RANSAC inlier distance, m.")
    ransac_iterations: int = Field(64, le=10_000, ge=1)
    max_tilt_rad: float = Field(0.15, le=1.58, gt=0, description="Reject planes tilted more than this.")
    min_inliers: int = Field(200, le=1_000_000, ge=3, description="Below this the prior plane is used.")
    object_min_height_m: float = Field(
        0.005, le=1.0, gt=0, description="Points this far above the plane belong to objects."
    )


class WorkspaceConfig(_Section):
    x_m: tuple[float, float] = (-0.30, 1.00)
    y_m: tuple[float, float] = (-0.75, 0.75)
    max_height_m: float = Field(0.20, le=10.0, gt=0, description="Points higher above the plane are dropped.")
    base_exclusion_radius_m: float = Field(
        0.18, le=5.0, ge=0, description="Points within this xy radius of the robot base are dropped."
    )
    base_xy_m: tuple[float, float] = (0.0, 0.0)

    @model_validator(mode="after")
    def _ordered(self):
        for name in ("x_m", "y_m"):
            lo, hi = getattr(self, name)
            if not lo < hi:
                raise ValueError(f"workspace.{name} must be [min, max] with min < max, got {[lo, hi]}")
        return self


class RobotMaskConfig(_Section):
    """Box around the gripper in the tcp frame (z out of the gripper, y along the fingers)."""

    gripper_half_x_m: float = Field(0.05, le=1.0, gt=0)
    gripper_half_y_m: float = Field(0.12, le=1.0, gt=0)
    gripper_z_m: tuple[float, float] = (-0.22, 0.05)
    capsule_margin_m: float = Field(0.01, le=1.0, ge=0, description="Added to caller-given capsule radii.")


class ClusteringConfig(_Section):
    method: Literal["kdtree", "sklearn"] = Field(
        "kdtree", description="DBSCAN implementation: scipy cKDTree (default, faster here) or scikit-learn."
    )
    eps_m: float = Field(0.010, le=1.0, gt=0, description="DBSCAN neighbourhood radius (xyz part), m.")
    min_samples: int = Field(6, le=10_000, ge=1, description="DBSCAN core-point neighbour count.")
    chromaticity_scale: float = Field(
        0.08, le=1000.0, gt=0, description="(r, g) chromaticity difference that counts as one eps of distance."
    )
    lightness_scale: float = Field(
        1.0, le=1000.0, gt=0, description="Intensity (r+g+b)/768 difference that counts as one eps."
    )
    min_points: int = Field(25, le=1_000_000, ge=1, description="Smaller clusters are dropped as noise.")
    glimpse_min_points: int = Field(
        12, le=1_000_000, ge=0,
        description="Left-over object points (in no segment) connected at glimpse_radius_m, at least this many, "
                    "rising glimpse_min_height_m and glimpse_clearance_m from every segment of their colour, are a "
                    "glimpse: never named, but a rival that leaves a declared look-alike unseen (perception.glimpse; "
                    "0: no glimpses).",
    )
    glimpse_radius_m: float = Field(0.015, le=1.0, gt=0, description="Neighbour distance of a glimpse's points, m.")
    glimpse_min_height_m: float = Field(
        0.015, le=1.0, ge=0,
        description="A glimpse rises at least this far above the support plane (98th percentile of its points), m: "
                    "lower left-overs are table-level clutter (a shadow's edge, a fixture's foot), not an object.")
    glimpse_clearance_m: float = Field(
        0.03, le=1.0, ge=0, description="A glimpse lies at least this far (horizontally) from every segment, m.")
    split_max_cost: float = Field(
        1.5, le=1000.0, ge=0,
        description="A segment larger than every declared object is split into parts (perception.split) only when "
                    "each part matches a declared look at an association cost at most this (0: never split).",
    )
    split_size_tolerance: float = Field(
        0.10, le=10.0, ge=0, description="A segment is larger than a declared object when a dimension exceeds "
                                         "its by this fraction plus split_size_margin_m.",
    )
    split_size_margin_m: float = Field(0.008, le=1.0, ge=0, description="See split_size_tolerance, m.")
    split_max_neck_ratio: float = Field(
        0.6, le=1.0, ge=0,
        description="The footprint partition (perception.split.footprint_cut) is tried only where the footprint's "
                    "neck is at most this fraction of the narrower side's width (two touching disks: about 0.4; "
                    "two boxes face to face: 1; 0: never).",
    )


class ShapeConfig(_Section):
    top_band_m: float = Field(0.006, le=1.0, gt=0, description="Points this close to the top form the top face.")
    box_corner_fraction: float = Field(
        0.07, ge=0, le=1, description="Top-face points outside the rectangle's inscribed ellipse >= this: box."
    )
    sphere_residual: float = Field(
        0.06, le=1000.0, gt=0, description="Sphere-fit RMS residual below this x radius + the noise term: sphere."
    )
    sphere_noise_factor: float = Field(
        0.6, le=1000.0, ge=0, description="Noise term of the sphere test: this x depth sigma at the object's range."
    )
    sphere_height_tolerance: float = Field(
        0.2, le=1000.0, gt=0, description="|height - diameter| / diameter below this for a sphere."
    )
    sphere_bulge_min: float = Field(
        0.25, le=1000.0, ge=0,
        description="A sphere's points' median height stands at least -this x r above its fitted centre "
                    "(a ball seen from above bulges towards the cameras; a bowl's inside does not).",
    )
    colour_from: Literal["top", "all", "vivid"] = Field(
        "top", description="Median colour of the top-face points (top), of every point of the segment (all), or "
                           "of its most chromatic third (vivid)."
    )


class AssociationConfig(_Section):
    colour_scale_lab: float = Field(25.0, le=1000.0, gt=0, description="Delta E*ab per unit cost.")
    lightness_weight: float = Field(0.35, le=1000.0, ge=0, description="Weight of Delta L* (shading).")
    size_scale_m: float = Field(0.01, le=10.0, gt=0, description="Size error (m) per unit cost.")
    shape_cost: float = Field(2.0, le=1000.0, ge=0, description="Cost of a shape mismatch.")
    position_scale_m: float = Field(
        0.05, le=10.0, gt=0, description="Distance from an existing track (m) per unit cost."
    )
    gate_cost: float = Field(3.0, le=1000.0, gt=0, description="Pairs costing more are never associated.")
    ambiguity_margin: float = Field(
        0.5, le=1000.0, ge=0, description="Runner-up cost within this of the best: ambiguous -> unknown."
    )
    relation_margin_m: float = Field(
        0.03, le=10.0, ge=0, description="A spatial reference picks a detection only when the runner-up's "
                                         "relation score (m) is at least this much worse; else unresolved."
    )
    off_table_m: float = Field(
        0.02, le=10.0, gt=0, description="A detection whose bottom (or lowest points) is this far above the "
                                         "support plane is off the table (on or in something), m."
    )
    viewer_camera: str | None = Field(
        None, description="The camera whose image left and right are the viewer's (a spatial reference 'the plate "
                          "on the left'); null: the first camera of each observation (sensors.yaml order)."
    )


class FusionConfig(_Section):
    position_floor_m: float = Field(
        0.002, le=10.0, ge=0, description="Systematic per-view position error (1 sigma), m."
    )
    yaw_floor_rad: float = Field(0.03, le=3.15, ge=0, description="Systematic per-view yaw error, rad.")
    process_noise_m_per_sqrt_s: float = Field(
        0.002, le=10.0, ge=0, description="Random-walk growth of a track's std when unobserved."
    )
    innovation_gate_sigma: float = Field(
        4.0, le=1000.0, gt=0, description="A measurement this many sigmas from its track restarts it."
    )
    min_confidence: float = Field(0.05, ge=0, le=1, description="Entities below are reported unknown.")


class HoldingConfig(_Section):
    min_opening_m: float = Field(0.001, le=1.0, ge=0, description="Per finger; below: closed on nothing.")
    width_margin_m: float = Field(0.01, le=1.0, ge=0, description="Gap may exceed the width by this.")
    width_undershoot_m: float = Field(0.012, le=1.0, ge=0, description="Gap may fall short of the width by this.")
    min_effort_n: float = Field(5.0, le=10_000.0, ge=0, description="Finger force meaning a squeeze, N.")
    wrist_load_margin_n: float = Field(
        0.3, le=10_000.0, ge=0, description="Wrist load above the open-gripper baseline after lift, N."
    )
    lift_height_m: float = Field(0.03, le=10.0, ge=0, description="tcp this far above the grasp height = lifted.")
    capture_radius_m: float = Field(
        0.06, le=10.0, gt=0, description="A track this close to the tcp when the gripper closed can be held."
    )
    rim_wall_m: float = Field(
        0.003, le=0.05, gt=0,
        description="Assumed wall of an open container (a bowl) held by its rim, m: what the fingers then close on "
                    "(motion.rim_grasp.DEFAULT_RIM_WALL_M: the LIBERO akita bowl's 2.6 mm wall).",
    )
    handled_wall_m: float = Field(
        0.007, le=0.05, gt=0,
        description="Assumed wall of a container with a handle (a mug) held by its rim, m "
                    "(motion.rim_grasp.DEFAULT_HANDLED_WALL_M: LIBERO's mugs, 4.9-8.2 mm).",
    )
    handle_bar_m: float = Field(
        0.016, le=0.05, gt=0,
        description="Assumed width of a handle's bar held across (a mug taken by its handle, "
                    "motion.handle_grasp), m: LIBERO's mugs' model bars, 1.4-1.75 cm.",
    )


class RelationsConfig(_Section):
    on_gap_m: float = Field(0.015, le=1.0, gt=0, description="|bottom(A) - top(B)| for A on B.")
    min_confidence: float = Field(0.5, ge=0, le=1, description="Relations below are not reported.")


class PerceptionConfig(StrictNumbers, VersionedModel):
    """perception.yaml (see ``protocol/perception.yaml`` for every field's meaning)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    cloud: CloudConfig = Field(default_factory=CloudConfig)
    depth_noise: DepthNoiseConfig = Field(default_factory=DepthNoiseConfig)
    table: TableConfig = Field(default_factory=TableConfig)
    workspace: WorkspaceConfig = Field(default_factory=WorkspaceConfig)
    robot_mask: RobotMaskConfig = Field(default_factory=RobotMaskConfig)
    clustering: ClusteringConfig = Field(default_factory=ClusteringConfig)
    shape: ShapeConfig = Field(default_factory=ShapeConfig)
    association: AssociationConfig = Field(default_factory=AssociationConfig)
    fusion: FusionConfig = Field(default_factory=FusionConfig)
    holding: HoldingConfig = Field(default_factory=HoldingConfig)
    relations: RelationsConfig = Field(default_factory=RelationsConfig)

    @classmethod
    def default(cls) -> "PerceptionConfig":
        """The defaults, equal to the shipped template ``protocol/perception.yaml``."""
        return cls()

    @classmethod
    def from_yaml(cls, path: str | os.PathLike[str]) -> "PerceptionConfig":
        """Read and validate a perception.yaml.

        Raises:
            DocumentError: malformed YAML, unknown key or bad value, with ``path:line``.
            OSError: the file cannot be read.
        """
        return read_yaml(path, cls)

    @classmethod
    def for_workspace(cls, root: str | os.PathLike[str]) -> "PerceptionConfig":
        """The workspace's ``perception.yaml`` if it has one, else :meth:`default`.

        Raises:
            DocumentError: the workspace's file is malformed (it is never overwritten).
        """
        path = Path(root) / PERCEPTION_FILE
        return cls.from_yaml(path) if path.is_file() else cls.default()

    @classmethod
    def from_text(cls, text: str, *, path: str | None = None) -> "PerceptionConfig":
        """Parse perception.yaml text (``path`` only labels errors)."""
        return parse_yaml(text, cls, path=path)

    def stride_for(self, width_px: int) -> int:
        """Pixel stride for an image ``width_px`` wide (every stride-th row and column)."""
        return max(1, -(-int(width_px) // self.cloud.sample_width_px))

    def depth_sigma_m(self, depth_m):
        """1-sigma depth noise (m) at ``depth_m`` (scalar or array, m)."""
        return self.depth_noise.base_m + self.depth_noise.quadratic_per_m * depth_m * depth_m
