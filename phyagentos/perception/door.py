"""A fixture's door on a vertical hinge (LIBERO's microwave): its look and its reading.

A fixture with a door declares ``door:`` in its look (:class:`DoorLook`), measured on the
fixture's model with the door shut (``phyagentos.targets.libero.descriptors``), every length in
the fixture's *model frame* (its root body's frame, which the perceiver puts where it sees the
fixture: :class:`~phyagentos.perception.fixtures.RootLook`):

- ``hinge_m`` (2,): where the hinge's vertical axis stands, m;
- ``shut_yaw_rad``: the direction from the hinge to the door's free edge with the door shut;
- ``sign`` (+1 or -1): the door's direction turns by ``sign x`` the joint's change (the joint's
  axis is up, +1, or down, -1);
- ``range_rad`` [lo, hi] the joint's travel and ``shut_rad`` the end of it at which the door
  is shut;
- ``width_m`` (hinge to free edge), ``thickness_m`` and ``mid_m``: the slab's mid-plane's
  offset from the hinge line along the door's outer normal (the side away from the body when
  shut), m;
- ``outer`` (+1 or -1): the outer normal is the door's direction turned by ``outer x 90``
  degrees (counter-clockwise seen from above for +1);
- ``z_m`` [bottom, top] of the slab above the model frame's origin, m;
- ``handle_r_m``: how far from the hinge along the door its handle's bar stands (m; ``None``:
  no handle), ``handle_out_m`` how far its centre line stands out from the hinge line along
  the outer normal, and ``handle_z_m`` [bottom, top] of the bar above the model frame's origin.

:func:`door_reading` reads the joint's position from the points of the slab's upper part
(clear of what stands on the table below it) within the door's sweep about the hinge;
:func:`thin_parts_removed` lets a fixture's body be fitted without its open door (a slab seen
edge-on from above: a band one or two grid cells wide).

Nothing here reads a simulator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from phyagentos.errors import format_choices
from phyagentos.perception.errors import PerceptionError
from phyagentos.perception.values import finite_floats as _floats

__all__ = ["DoorLook", "InsideLook", "inside_entity_name", "door_reading", "door_points", "thin_parts_removed",
           "DOOR_SIGMA_RAD", "DOOR_STOP_SIGMA_RAD", "DOOR_MIN_POINTS", "DOOR_BAND_M", "DOOR_LINE_M", "DOOR_SWEEP",
           "THIN_CELL_M", "THIN_CELLS"]

#: 1-sigma of a door's joint read from its points (:func:`door_reading`), rad: read on
#: LIBERO-90 task 33's generated scenes 500-503 (LIBERO's sampler, the door 1.38-1.82 rad open),
#: -0.030, -0.017, +0.011 and +0.010 rad from the simulator's joint (the fixture's perceived
#: yaw within 0.004 rad, its hinge within 3 mm).
DOOR_SIGMA_RAD = 0.03
#: 1-sigma of a door pushed into its shut stop, rad: where the joint's stop holds it. Pressed
#: with the hand, LIBERO's microwave door went 0.013-0.023 rad past its stop and came back
#: to it (0.000) when the hand left (LIBERO-90 task 33, generated scenes 500-502).
DOOR_STOP_SIGMA_RAD = 0.005
#: Fewest points a reading needs.
DOOR_MIN_POINTS = 25
#: The slab's band read, m below its top: its upper part only (a mug, 10 cm tall, stands
#: below it on LIBERO's table; the door rises 18.5 cm), and 5 mm under the top edge.
DOOR_BAND_M = (0.07, 0.005)
#: The part of the door's width read, as fractions from the hinge: off the hinge's corner
#: (the fixed parts) and short of the free edge (its handle stands off the face there).
DOOR_SWEEP = (0.3, 0.8)
#: How far from the first direction's line (m) a point is taken for the line fit of
#: :func:`door_reading`: the slab's half thickness (1.2 cm) and its faces' depth noise.
DOOR_LINE_M = 0.025
#: Grid cell and opening size (cells) of :func:`thin_parts_removed`: a part thinner than
#: ``THIN_CELLS`` cells seen from above (a door, 2.4 cm thick, a handle's bar) is removed.
THIN_CELL_M = 0.01
THIN_CELLS = 4


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@dataclass(frozen=True)
class DoorLook:
    """A fixture's door on a vertical hinge, in the fixture's model frame (module docstring);
    lengths in m, angles in rad."""

    hinge_m: tuple[float, float]
    shut_yaw_rad: float
    sign: float
    range_rad: tuple[float, float]
    shut_rad: float
    width_m: float
    thickness_m: float
    mid_m: float
    outer: float
    z_m: tuple[float, float]
    handle_r_m: float | None = None
    handle_out_m: float = 0.0
    handle_z_m: tuple[float, float] | None = None

    KEYS = ("hinge_m", "shut_yaw_rad", "sign", "range_rad", "shut_rad", "width_m", "thickness_m", "mid_m", "outer",
            "z_m", "handle_r_m", "handle_out_m", "handle_z_m")
    #: The handle's bar, m: its radius (a bar thicker than LIBERO's microwave's, 1 cm, is not
    #: declared by the look; the grasp needs only its centre line).
    HANDLE_BAR_RADIUS_M = 0.01

    @classmethod
    def from_dict(cls, d: Any, fixture: str) -> "DoorLook":
        """From the mapping :meth:`to_dict` writes.

        Raises:
            PerceptionError: a missing or unknown key (the valid ones listed), a malformed
                number, a sign or side not +-1, a shut end not an end of the travel, or a
                width, thickness or height span not positive.
        """
        where = f"fixture {fixture!r}: door"
        required = set(cls.KEYS) - {"handle_r_m", "handle_out_m", "handle_z_m"}
        if not isinstance(d, Mapping) or not required <= set(d) or not set(d) <= set(cls.KEYS):
            raise PerceptionError(f"{where} must be a mapping with keys {format_choices(cls.KEYS)} (handle_r_m, "
                                  f"handle_out_m and handle_z_m optional), got {d!r}")
        hinge = _floats(d["hinge_m"], 2, f"{where}.hinge_m")
        travel = _floats(d["range_rad"], 2, f"{where}.range_rad")
        z = _floats(d["z_m"], 2, f"{where}.z_m")
        shut_yaw, sign, shut, width, thick, mid, outer, out = _floats(
            [d["shut_yaw_rad"], d["sign"], d["shut_rad"], d["width_m"], d["thickness_m"], d["mid_m"], d["outer"],
             d.get("handle_out_m", 0.0)], 8, f"{where} numbers")
        handle = None if d.get("handle_r_m") is None else _floats([d["handle_r_m"]], 1, f"{where}.handle_r_m")[0]
        handle_z = None if d.get("handle_z_m") is None else _floats(d["handle_z_m"], 2, f"{where}.handle_z_m")
        if sign not in (1.0, -1.0) or outer not in (1.0, -1.0):
            raise PerceptionError(f"{where}: sign and outer must each be 1 or -1, got {sign!r}, {outer!r}")
        if not travel[0] < travel[1] or shut not in travel:
            raise PerceptionError(f"{where}: range_rad must rise and shut_rad be one of its ends, got {travel!r} "
                                  f"and {shut!r}")
        if width <= 0 or thick <= 0 or not z[0] < z[1]:
            raise PerceptionError(f"{where}: width_m and thickness_m must be > 0 and z_m rise, got {d!r}")
        return cls(hinge, shut_yaw, sign, travel, shut, width, thick, mid, outer, z, handle, out,  # type: ignore[arg-type]
                   handle_z)  # type: ignore[arg-type]

    def to_dict(self) -> dict[str, Any]:
        """The mapping :meth:`from_dict` reads."""
        out = {k: getattr(self, k) for k in self.KEYS}
        for k in ("hinge_m", "range_rad", "z_m", "handle_z_m"):
            out[k] = None if out[k] is None else list(out[k])
        return out

    @property
    def open_rad(self) -> float:
        """The joint's end of travel at which the door stands open farthest, rad."""
        return self.range_rad[0] if self.shut_rad == self.range_rad[1] else self.range_rad[1]

    def hinge_xy(self, origin: np.ndarray, yaw: float) -> np.ndarray:
        """(2,) world m: the hinge's axis for the model frame at ``origin`` (3,) world m turned
        ``yaw`` rad."""
        c, s = math.cos(yaw), math.sin(yaw)
        x, y = self.hinge_m
        return np.asarray(origin, float)[:2] + np.array([c * x - s * y, s * x + c * y])

    def door_yaw(self, q: float, yaw: float) -> float:
        """World yaw (rad) of the direction from the hinge to the free edge at joint ``q``
        (rad), the model frame turned ``yaw``."""
        return _wrap(yaw + self.shut_yaw_rad + self.sign * (float(q) - self.shut_rad))

    def joint_of(self, door_yaw: float, yaw: float) -> float:
        """The joint position (rad) at which the door points along world ``door_yaw``; of
        the two ways round, the one nearer the travel."""
        a = _wrap(float(door_yaw) - yaw - self.shut_yaw_rad)
        q = self.shut_rad + self.sign * a
        lo, hi = self.range_rad
        alt = q - 2.0 * math.pi if q > hi else q + 2.0 * math.pi
        return q if max(lo - q, q - hi, 0.0) <= max(lo - alt, alt - hi, 0.0) else alt

    def outer_normal(self, door_yaw: float) -> np.ndarray:
        """(2,) world unit: the door's outer normal when it points along ``door_yaw``."""
        a = float(door_yaw) + self.outer * 0.5 * math.pi
        return np.array([math.cos(a), math.sin(a)])


def inside_entity_name(fixture: str) -> str:
    """The entity name of the room behind ``fixture``'s door: ``microwave_1_inside``."""
    return f"{fixture}_inside"


@dataclass(frozen=True)
class InsideLook:
    """The room behind a fixture's door, in the fixture's model frame (its root body's; m):
    ``lo_m`` / ``hi_m`` (2,) the footprint's corners on the frame's axes, ``floor_m`` and
    ``roof_m`` above the frame's origin, ``mouth`` (2,) the unit outward normal of the door's
    side (measured on the model with the door shut: ``phyagentos.targets.libero.descriptors``)."""

    lo_m: tuple[float, float]
    hi_m: tuple[float, float]
    floor_m: float
    roof_m: float
    mouth: tuple[float, float]

    KEYS = ("lo_m", "hi_m", "floor_m", "roof_m", "mouth")

    @classmethod
    def from_dict(cls, d: Any, fixture: str) -> "InsideLook":
        """From the mapping :meth:`to_dict` writes.

        Raises:
            PerceptionError: other keys, a malformed number, a footprint or height span that
                does not rise, or a mouth that is not a unit vector.
        """
        where = f"fixture {fixture!r}: inside"
        if not isinstance(d, Mapping) or set(d) != set(cls.KEYS):
            raise PerceptionError(f"{where} must be a mapping with keys {format_choices(cls.KEYS)}, got {d!r}")
        lo, hi = _floats(d["lo_m"], 2, f"{where}.lo_m"), _floats(d["hi_m"], 2, f"{where}.hi_m")
        floor, roof = _floats([d["floor_m"], d["roof_m"]], 2, f"{where} floor_m, roof_m")
        mouth = _floats(d["mouth"], 2, f"{where}.mouth")
        if not (lo[0] < hi[0] and lo[1] < hi[1] and floor < roof) or abs(math.hypot(*mouth) - 1.0) > 1e-3:
            raise PerceptionError(f"{where}: lo_m must lie below hi_m, floor_m below roof_m, and mouth be a unit "
                                  f"vector, got {d!r}")
        return cls(lo, hi, floor, roof, mouth)  # type: ignore[arg-type]

    def to_dict(self) -> dict[str, Any]:
        """The mapping :meth:`from_dict` reads."""
        return {"lo_m": list(self.lo_m), "hi_m": list(self.hi_m), "floor_m": self.floor_m, "roof_m": self.roof_m,
                "mouth": list(self.mouth)}

    def world(self, origin: np.ndarray, yaw: float) -> tuple[np.ndarray, np.ndarray, float, float, float, np.ndarray]:
        """``(centre (2,), half extents (2,) on the frame's axes, frame yaw, floor z, roof z,
        mouth (2,))`` in the world (m, rad), the model frame at ``origin`` (3,) turned ``yaw``."""
        c, s = math.cos(yaw), math.sin(yaw)
        rot = np.array([[c, -s], [s, c]])
        lo, hi = np.asarray(self.lo_m, float), np.asarray(self.hi_m, float)
        centre = np.asarray(origin, float)[:2] + rot @ (0.5 * (lo + hi))
        z0 = float(origin[2])
        return centre, 0.5 * (hi - lo), float(yaw), z0 + self.floor_m, z0 + self.roof_m, rot @ np.asarray(self.mouth)


def door_reading(points: np.ndarray, door: DoorLook, origin: np.ndarray, yaw: float) -> tuple[float, int] | None:
    """``(joint position rad, points read)`` of ``door`` for the fixture's model frame at
    ``origin`` (3,) world m turned ``yaw`` rad, from ``points`` (N, 3) world m; None when fewer
    than :data:`DOOR_MIN_POINTS` are read.

    The points read lie in the slab's upper band (:data:`DOOR_BAND_M` under its top), at
    :data:`DOOR_SWEEP` of its width from the hinge (not kept off the fixed parts' footprint: a
    shut door lies within it on LIBERO's microwave, whose panel stands as far out; the body's
    own walls there lie the other way round the hinge, out of the joint's travel). A first
    direction is the median of their bearings about the hinge, each taken on the slab's
    mid-plane (less the angle the mid-plane's offset makes at its radius); the reading is the
    direction of the line through the points within :data:`DOOR_LINE_M` of that one (their
    principal axis): a face seen, whichever it is, lies along the door, where a bearing about
    the hinge leans by half the thickness over the radius (0.05-0.07 rad on LIBERO's microwave,
    seen by its inner face). Mapped to the joint (:meth:`DoorLook.joint_of`), kept within 0.2
    rad of the travel and taken at its end when past it.
    """
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    hinge = door.hinge_xy(origin, yaw)
    top = float(origin[2]) + door.z_m[1]
    sel = (p[:, 2] >= top - DOOR_BAND_M[0]) & (p[:, 2] <= top - DOOR_BAND_M[1])
    v = p[sel, :2] - hinge
    r = np.linalg.norm(v, axis=1)
    lo, hi = DOOR_SWEEP[0] * door.width_m, DOOR_SWEEP[1] * door.width_m
    keep = (r >= lo) & (r <= hi)
    v, r = v[keep], r[keep]
    if len(v) < DOOR_MIN_POINTS:
        return None
    along = np.sqrt(np.maximum(r ** 2 - door.mid_m ** 2, 1e-9))
    bearing = np.arctan2(v[:, 1], v[:, 0]) - np.arctan2(door.outer * door.mid_m, along)
    qs = np.array([door.joint_of(float(b), yaw) for b in bearing])
    ok = (qs >= door.range_rad[0] - 0.2) & (qs <= door.range_rad[1] + 0.2)
    if int(ok.sum()) < DOOR_MIN_POINTS:
        return None
    first = door.door_yaw(float(np.median(qs[ok])), yaw)
    u = np.array([math.cos(first), math.sin(first)])
    line = v[np.abs(v @ np.array([-u[1], u[0]]) - door.outer * door.mid_m) <= DOOR_LINE_M]
    if len(line) < DOOR_MIN_POINTS:
        return None
    axis = np.linalg.eigh(np.cov(line.T))[1][:, -1]
    axis = axis if float(axis @ u) > 0 else -axis
    q = door.joint_of(math.atan2(float(axis[1]), float(axis[0])), yaw)
    if not door.range_rad[0] - 0.2 <= q <= door.range_rad[1] + 0.2:
        return None
    # a door stands within its travel: a reading past a stop is the stop (a shut door read 0.04-0.1 rad
    # into its body, LIBERO-90 task 35's generated scenes)
    return float(min(max(q, door.range_rad[0]), door.range_rad[1])), int(len(line))


def door_points(points: np.ndarray, door: DoorLook, origin: np.ndarray, yaw: float, q: float, *,
                margin_m: float) -> np.ndarray:
    """(N,) bool: which of ``points`` (N, 3) world m lie on ``door`` (its slab and handle,
    grown by ``margin_m`` m) at joint ``q`` rad, for the fixture's model frame at ``origin``
    (3,) world m turned ``yaw`` rad: the fixture's own points, not an object's."""
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    a = door.door_yaw(q, yaw)
    u = np.array([math.cos(a), math.sin(a)])
    n = door.outer_normal(a)
    v = p[:, :2] - door.hinge_xy(origin, yaw)
    along, across = v @ u, v @ n
    half = 0.5 * door.thickness_m
    reach = max(door.mid_m + half, door.handle_out_m + door.HANDLE_BAR_RADIUS_M)
    z0, z1 = float(origin[2]) + door.z_m[0], float(origin[2]) + door.z_m[1]
    return ((along >= -margin_m) & (along <= door.width_m + margin_m)
            & (across >= door.mid_m - half - margin_m) & (across <= reach + margin_m)
            & (p[:, 2] >= z0 - margin_m) & (p[:, 2] <= z1 + margin_m))


def thin_parts_removed(xy: np.ndarray) -> np.ndarray:
    """(N,) bool: which of ``xy`` (N, 2) world m lie in the largest part at least
    :data:`THIN_CELLS` cells of :data:`THIN_CELL_M` across both ways (a morphological opening
    of their occupancy grid, then its largest connected piece): a body's top, not a door or a
    bar seen from above, nor the knot of a handle's stand-offs at a door's free end."""
    from scipy.ndimage import binary_opening, label  # noqa: PLC0415

    pts = np.asarray(xy, dtype=float).reshape(-1, 2)
    if len(pts) == 0:
        return np.zeros(0, dtype=bool)
    ij = np.floor((pts - pts.min(axis=0)) / THIN_CELL_M).astype(int)
    grid = np.zeros(tuple(ij.max(axis=0) + 1), dtype=bool)
    grid[ij[:, 0], ij[:, 1]] = True
    kept = binary_opening(grid, structure=np.ones((THIN_CELLS, THIN_CELLS), dtype=bool))
    labels, n = label(kept, structure=np.ones((3, 3), dtype=bool))
    if n > 1:
        kept = labels == 1 + int(np.argmax(np.bincount(labels.ravel())[1:]))
    return kept[ij[:, 0], ij[:, 1]]
