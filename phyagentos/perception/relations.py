"""Relations from perceived geometry and proprioception (never from simulator contacts).

* ``inside(X, region)``: X rests on the table and its centre lies in the region's rectangle;
  confidence Phi(margin / sigma) with margin the signed distance of the centre to the nearest
  region edge (positive inside) and sigma X's ``position_std_m``.
* ``on(A, B)``: A's bottom is within ``relations.on_gap_m`` of B's top and A's centre lies
  over B's footprint; ``on(X, table)`` for objects resting on the support plane.
* ``holding(gripper, X)`` (CONTRACT_9 section 3): the gap between the fingers (2 x the
  per-finger opening) is consistent with X's perceived width across the fingers
  (> 2 x ``holding.min_opening_m``, < width + ``width_margin_m``, > width -
  ``width_undershoot_m``), the finger effort is above ``holding.min_effort_n``, and, once
  lifted, the wrist load exceeds the open-gripper baseline by ``wrist_load_margin_n``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from phyagentos.perception.config import PerceptionConfig
from phyagentos.perception.errors import PerceptionError
from phyagentos.perception.frames import Proprioception

__all__ = ["Region", "regions_from", "normal_cdf", "inside_confidence", "on_confidence",
           "width_across_fingers", "HoldingEvidence", "holding_evidence"]


def normal_cdf(x: float) -> float:
    """Standard normal CDF Phi(x)."""
    return 0.5 * (1.0 + math.erf(x / math.sqrt(2.0)))


@dataclass(frozen=True)
class Region:
    """A declared axis-aligned region on the table: centre (x, y) and half extents, m."""

    name: str
    center: tuple[float, float]
    half_extents: tuple[float, float]


def regions_from(items: Sequence[Any] | Mapping[str, Any] | None) -> list[Region]:
    """Regions from ``describe_declared()['regions']`` mappings, ``RegionSpec`` objects or a
    ``{"regions": [...]}`` mapping.

    Raises:
        PerceptionError: an entry without name, center (2 numbers) and half_extents (2 numbers).
    """
    if items is None:
        return []
    if isinstance(items, Mapping):
        items = items.get("regions", [])
    out = []
    for it in items:
        get = it.get if isinstance(it, Mapping) else (lambda k, _it=it: getattr(_it, k, None))
        name, c, he = get("name"), get("center"), get("half_extents")
        try:
            c2 = (float(c[0]), float(c[1]))
            he2 = (float(he[0]), float(he[1]))
        except (TypeError, ValueError, IndexError):
            raise PerceptionError(
                f"region {name!r} needs center [x, y] and half_extents [hx, hy] (m), got {c!r}, {he!r}"
            ) from None
        if not isinstance(name, str) or not name:
            raise PerceptionError(f"a region needs a non-empty name, got {name!r}")
        out.append(Region(name, c2, he2))
    return out


def inside_confidence(position: np.ndarray, std_m: float, region: Region) -> float:
    """Phi(signed distance of ``position``'s xy to the region's nearest edge / std)."""
    margin = min(region.half_extents[i] - abs(float(position[i]) - region.center[i]) for i in range(2))
    return normal_cdf(margin / max(std_m, 1e-4))


def _footprint_margins(xy: np.ndarray, centre: np.ndarray, yaw: float, half: np.ndarray, shape: str) -> np.ndarray:
    """(N,) how far, m, each of the points ``xy`` ((N, 2) or (2,) world) lies inside the
    footprint at ``centre`` ((2,) or (3,) world, m) turned ``yaw`` (rad) with half extents
    ``half`` (m): a box's least margin over its two axes, else a disc of radius ``half[0]``'s;
    negative outside."""
    d = np.asarray(xy, dtype=float).reshape(-1, 2) - np.asarray(centre, dtype=float)[:2]
    if shape != "box":
        return float(half[0]) - np.linalg.norm(d, axis=1)
    c, s = math.cos(yaw), math.sin(yaw)
    u, v = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]
    return np.minimum(float(half[0]) - np.abs(u), float(half[1]) - np.abs(v))


def _footprint_margin(xy: np.ndarray, centre: np.ndarray, yaw: float, half: np.ndarray, shape: str) -> float:
    """:func:`_footprint_margins` of the one point ``xy`` (2,) world, m."""
    return float(_footprint_margins(xy, centre, yaw, half, shape)[0])


def on_confidence(upper: Mapping[str, Any], lower: Mapping[str, Any], config: PerceptionConfig) -> float:
    """Confidence that entity ``upper`` rests on ``lower`` (dicts with position, yaw, half,
    shape, bottom, top, std)."""
    gap = abs(upper["bottom"] - lower["top"])
    if gap > config.relations.on_gap_m:
        return 0.0
    margin = _footprint_margin(upper["position"][:2], lower["position"], lower["yaw"], lower["half"], lower["shape"])
    sigma = math.hypot(upper["std"], lower["std"])
    return normal_cdf(margin / max(sigma, 1e-4)) * (1.0 - gap / config.relations.on_gap_m * 0.5)


def width_across_fingers(half_extents: np.ndarray, yaw: float, shape: str, tcp_pose: np.ndarray) -> float:
    """Full width (m) of an object's footprint along the tcp's y axis (the finger motion)."""
    if shape != "box":
        return 2.0 * float(half_extents[0])
    ay = tcp_pose[:3, 1]
    ang = math.atan2(ay[1], ay[0]) - yaw
    return 2.0 * (abs(half_extents[0] * math.cos(ang)) + abs(half_extents[1] * math.sin(ang)))


@dataclass(frozen=True)
class HoldingEvidence:
    """Proprioceptive evidence for ``holding`` one object (all forces in N, lengths in m)."""

    consistent_width: bool
    gap_m: float
    width_m: float
    effort_n: float
    wrist_load_n: float | None
    lifted: bool
    confidence: float


def holding_evidence(proprio: Proprioception, *, width_m: float, baseline_n: float | None,
                     grasp_height_m: float | None, config: PerceptionConfig) -> HoldingEvidence:
    """Judge whether the gripper holds an object of perceived width ``width_m``.

    ``baseline_n``: wrist force magnitude with the gripper open and free (None if unknown or
    no F/T sensor); ``grasp_height_m``: tcp z when the grasp closed (None if unknown).
    """
    hc = config.holding
    gap = 2.0 * proprio.gripper_opening_m
    ok_width = (gap > 2.0 * hc.min_opening_m) and (width_m - hc.width_undershoot_m < gap < width_m + hc.width_margin_m)
    effort = abs(proprio.gripper_effort_n)
    conf = (1.0 - math.exp(-effort / max(hc.min_effort_n, 1e-6))) if effort >= hc.min_effort_n else 0.0
    if not ok_width:
        conf = 0.0
    load = None
    lifted = grasp_height_m is not None and float(proprio.tcp_pose[2, 3]) > grasp_height_m + hc.lift_height_m
    if proprio.wrist_force_n is not None and baseline_n is not None:
        load = float(np.linalg.norm(proprio.wrist_force_n)) - baseline_n
        if lifted:
            conf *= normal_cdf((load - hc.wrist_load_margin_n) / max(0.5 * hc.wrist_load_margin_n, 0.05))
    return HoldingEvidence(ok_width, gap, width_m, effort, load, lifted, conf)
