"""Fixtures: large declared things (a cabinet, a stove, a rack) perceived by their measured look.

A fixture is declared like an object (``{name, class}``) plus its *look*, measured on the
fixture's model (never on a scene an Agent is judged on): ``size_m`` -- the full extents of
its perceived body, ``[long side, short side, height of its top above the support]``, m --
and optionally ``place`` -- where on it things are set down, relative to the perceived body:
``{offset_m: [dx, dy] (world frame, from the body's footprint centre to the place patch's
centre), half_extents_m: [hx, hy] (world axes), height_m: the patch's surface above the
support}``. Without ``place`` the body's top is the place patch. A fixture with a rotary control
(LIBERO's stove knob) declares ``knob: {offset_m: [dx, dy] (world frame, from the body's
footprint centre to the knob's vertical axis), top_m: the knob's top above the support,
rest_yaw_rad: the world yaw (mod pi) of its grip bar at joint position 0, range_rad: [lo, hi]
the joint's travel}``, all from the fixture's model: :func:`knob_reading` reads the joint's
position from the bar's orientation in each observation. A fixture with drawers (LIBERO's
cabinets) declares ``drawers: [{name, handle_offset_m: [dx, dy] (world frame, from the body's
footprint centre to the handle's centre with the drawer shut), height_m: the handle's centre
above the support, half_length_m: half the handle's length across the drawer, axis_xy: (2,) world
unit direction the drawer opens along, travel_m: [lo, hi] the opening's range (m the drawer stands
out from shut; the model's joint mapped so that it grows outward), face_m: the handle's outer
face along ``axis_xy`` from its centre as the cameras see it}]``, all at turn 0 and from the
fixture's model: :func:`drawer_reading` reads each opening from where its handle stands. A
fixture with compartments (LIBERO's desk caddy) declares ``compartments: [{name (the model's word),
offset_m: [dx, dy] (world frame, from the body's footprint centre), half_extents_m: [hx, hy] (world
axes), height_m: its floor above the support}]``, at turn 0 and from the model; the perceiver
names each by the viewer's side of the fixture it lies on (:func:`compartment_sides`). A
fixture with a door on a vertical hinge declares ``door:`` (:class:`~phyagentos.perception.door.DoorLook`,
in its model frame, which needs ``root``); it is fitted without its open door
(:func:`without_door`).

:func:`detect_fixtures` finds them in the object cloud (all heights up to the raised crop),
segmented by the perceiver's own clustering (position and colour,
:func:`~phyagentos.perception.detect.cluster`), each segment's footprint the minimum-area
rectangle of its points and its top the :data:`TOP_PERCENTILE` th percentile of their
heights; a segment is a fixture when its footprint sides and top each lie within
:data:`SIZE_TOL_FRACTION` (plus :data:`SIZE_TOL_M`) of the look; a candidate is one segment
or two adjacent ones (:data:`JOIN_GAP_M`: a fixture whose parts differ in colour); each
fixture takes the best fitting candidate (sum of relative size errors), no segment going to
two fixtures. A candidate must also show its place patch at the surface's height and, for a
fixture with a knob, no non-bar where the knob would be; either way round (:data:`TURNS`:
the other way only where its knob is read). A fixture merged with something else into one
larger segment (LIBERO's cabinet with the wine rack beside it, in some generated scenes) does
not fit: it is not seen in that observation, unless it has a knob, by which it is then looked
for (:func:`find_by_knob`). The perceiver keeps a fixture where it was once seen (fixtures do
not move); a knob turns, so it is read in every observation.

Nothing here reads a simulator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Mapping, Sequence

import numpy as np

from phyagentos.errors import format_choices
from phyagentos.geometry import turned_xy
from phyagentos.perception.cloud import Cloud
from phyagentos.perception.config import PerceptionConfig
from phyagentos.perception.detect import _rect, cluster
from phyagentos.perception.door import DoorLook, InsideLook, thin_parts_removed
from phyagentos.perception.errors import PerceptionError
from phyagentos.perception.values import finite_floats as _floats

__all__ = ["FixtureLook", "LeanLook", "RootLook", "ROOT_YAW_MAX_RAD", "FixtureSighting", "KnobLook", "DrawerLook",
           "drawer_reading", "drawer_band",
           "drawer_entity_name", "CompartmentLook", "compartment_sides", "compartment_entity_name",
           "DRAWER_BAND_M", "DRAWER_BEYOND_M", "DRAWER_FRONT_FRACTION", "DRAWER_ABOVE_M",
           "DRAWER_LEVEL_TOL_M", "DRAWER_STRAIGHT_TOL_M", "DRAWER_FRONT_BEHIND_M", "DRAWER_FRONT_MIN_POINTS",
           "DRAWER_FRONT_SPAN_M", "DRAWER_WINDOW_M", "DRAWER_MIN_POINTS", "DRAWER_MIN_SPAN",
           "DRAWER_SIGMA_M", "DRAWER_STOP_SIGMA_M", "fixtures_from_declared", "segments", "bodies",
           "detect_fixtures", "CLAIMED_EDGE_M",
           "find_by_knob", "knob_band", "knob_reading", "patch_cover", "JOIN_GAP_M", "SIZE_TOL_FRACTION",
           "SIZE_TOL_M", "TOP_PERCENTILE", "MIN_POINTS", "KNOB_RADIUS_M", "KNOB_BAND", "KNOB_MIN_POINTS",
           "KNOB_SEEN_POINTS", "KNOB_MIN_ELONGATION", "KNOB_ALONG_STD_M", "KNOB_ACROSS_STD_MAX_M", "KNOB_TOP_TOL_M", "KNOB_SIGMA_RAD",
           "KNOB_SEARCH_GRID_M", "KNOB_BODY_COVER",
           "find_by_drawers", "without_door", "edge_yaw", "EDGE_YAW_SPAN_RAD", "EDGE_YAW_STEP_RAD", "EDGE_BIN_M",
           "DRAWER_FOUND_MIN", "DRAWER_FOUND_SHUT_M", "KNOB_TALL_COVER", "KNOB_SURFACE_COVER",
           "PATCH_COVER", "PATCH_TOL_M", "TURNS"]

#: Fewest points (on the perceiver's voxel grid) of a fixture's segment.
MIN_POINTS = 200
#: Two segments whose footprints come this close may be one fixture's parts, m.
JOIN_GAP_M = 0.01
#: Percentile of a segment's heights taken as its top (the highest points are edges, rims,
#: knobs; a small thing on top adds a few points).
TOP_PERCENTILE = 97.0
#: A segment fits a look when each footprint side and the top lie within this fraction of
#: the look's (plus :data:`SIZE_TOL_M`). On generated libero_goal scenes a fixture seen whole
#: varies by < 1 cm; LIBERO's plate (0.14 m, 1.8 cm high) lies 0.16 m short of the stove's
#: long side (0.30 m), far outside (docs/libero.md, "Fixtures").
SIZE_TOL_FRACTION = 0.15
SIZE_TOL_M = 0.015
#: What a found fixture claims of the points when the missing ones are looked for again
#: (:func:`detect_fixtures`): its footprint and model box grown by this, m (a look's sides fit
#: within :data:`SIZE_TOL_M`; a neighbour's edge a little inside the growth is not needed to
#: fit it).
CLAIMED_EDGE_M = 0.01


#: Points within this horizontal distance of a knob's axis are its own, m (LIBERO's stove knob:
#: a 10 cm bar, 2.4 cm thick, on a dial; its burner plate starts 5.5 cm from the axis but
#: 2 cm lower).
KNOB_RADIUS_M = 0.06
#: A knob's bar is read from its points in the top part of its height: above this fraction of
#: its top (the dial and the burner beside it are lower).
KNOB_BAND = 0.6
#: Fewest such points (on the perceiver's voxel grid) for a reading (LIBERO's agentview and
#: wrist views of the stove knob: 330-500).
KNOB_MIN_POINTS = 30
#: A fixture is not taken where this many points stand at its knob's place and read as no bar
#: (fewer: the knob is hidden in part, by the arm or from the cameras' angle; LIBERO's stove
#: knob seen whole: 100-500; seen in part on generated libero_spatial scenes: 10-40).
KNOB_SEEN_POINTS = 80
#: The bar's horizontal spread along its long axis over that across it (standard deviations)
#: must reach this for a reading: a round blob has no orientation (the bar: 3.1-3.4).
KNOB_MIN_ELONGATION = 2.0
#: The bar's spread (standard deviation) along and across it must lie in these bounds, m:
#: LIBERO's stove knob reads 0.024-0.026 along and 0.0074-0.0083 across; a pan's handle or
#: rim where a knob is expected does not fit (on LIBERO-90 task 44 a frying pan beside the
#: stove was once taken for it, and its handle for the knob).
KNOB_ALONG_STD_M: tuple[float, float] = (0.016, 0.034)
KNOB_ACROSS_STD_MAX_M = 0.012
#: ... and the 90th percentile of its points' heights at most this above the knob's top, m
#: (LIBERO's stove knob: at its top, 0.059 m; a black bowl's rim beside it reads 0.071 m).
KNOB_TOP_TOL_M = 0.008
#: 1-sigma uncertainty of a knob reading, rad: on LIBERO's stove knob turned to 0-2 rad on
#: generated scenes (``bench/libero_knob.py``, 54 readings) the errors' root mean square was
#: 0.045 rad, their 95th percentile 0.081 and their largest 0.12, at 2 rad (docs/libero.md,
#: "Turning the stove on").
KNOB_SIGMA_RAD = 0.06


@dataclass(frozen=True)
class KnobLook:
    """A fixture's rotary control about a vertical axis (module docstring); m and rad, world
    frame."""

    offset_m: tuple[float, float]
    top_m: float
    rest_yaw_rad: float
    range_rad: tuple[float, float]

    @classmethod
    def from_dict(cls, d: Any, fixture: str) -> "KnobLook":
        """From ``{offset_m, top_m, rest_yaw_rad, range_rad}``.

        Raises:
            PerceptionError: a missing or unknown key (the valid ones listed) or a malformed value.
        """
        keys = ("offset_m", "top_m", "rest_yaw_rad", "range_rad")
        d = _keyed(d, keys, fixture, "knob")
        off = _floats(d["offset_m"], 2, f"fixture {fixture!r}: knob.offset_m")
        top = _floats([d["top_m"]], 1, f"fixture {fixture!r}: knob.top_m")[0]
        rest = _floats([d["rest_yaw_rad"]], 1, f"fixture {fixture!r}: knob.rest_yaw_rad")[0]
        lo, hi = _floats(d["range_rad"], 2, f"fixture {fixture!r}: knob.range_rad")
        if top <= 0 or not lo < hi or hi - lo >= math.pi:
            raise PerceptionError(f"fixture {fixture!r}: knob needs top_m > 0 and a range lo < hi spanning less than "
                                  f"pi rad (a bar reads the same turned by pi), got {d!r}")
        return cls(off, top, rest, (lo, hi))  # type: ignore[arg-type]

    def as_dict(self) -> dict[str, Any]:
        """The mapping :meth:`from_dict` reads."""
        return {"offset_m": list(self.offset_m), "top_m": self.top_m, "rest_yaw_rad": self.rest_yaw_rad,
                "range_rad": list(self.range_rad)}

    def joint_position(self, bar_yaw: float, turn: float = 0.0) -> float:
        """The joint position (rad) of a bar seen at world yaw ``bar_yaw`` (rad, any
        multiple of pi) on a fixture standing ``turn`` rad from how its look was measured:
        its turn from :attr:`rest_yaw_rad` taken in the window of width pi centred on the
        travel (a bar turned by pi looks the same)."""
        lo, hi = self.range_rad
        start = lo - 0.5 * (math.pi - (hi - lo))
        return start + (bar_yaw - self.rest_yaw_rad - turn - start) % math.pi

    def bar_yaw(self, joint_position: float, turn: float = 0.0) -> float:
        """World yaw of the bar (rad) at ``joint_position`` rad on a fixture standing ``turn``
        rad from how its look was measured."""
        return self.rest_yaw_rad + turn + joint_position

    def axis_xy(self, centre_xy: np.ndarray, turn: float = 0.0) -> np.ndarray:
        """(2,) world m: the knob's axis on a body centred at ``centre_xy`` standing ``turn``
        rad from how its look was measured."""
        return np.asarray(centre_xy, float) + turned_xy(self.offset_m, turn)


def knob_band(points: np.ndarray, heights: np.ndarray, knob: KnobLook, centre_xy: np.ndarray,
              turn: float = 0.0) -> np.ndarray:
    """(N,) bool: the points of ``points`` (N, 3) world m, ``heights`` (N,) m above the support,
    where the knob of a fixture whose footprint centre is ``centre_xy`` (2,) world m shows its
    bar: within :data:`KNOB_RADIUS_M` of its axis, between :data:`KNOB_BAND` of its top and 1.5
    cm above it (the fixture standing ``turn`` rad from how its look was measured)."""
    axis = knob.axis_xy(centre_xy, turn)
    return ((np.linalg.norm(points[:, :2] - axis, axis=1) <= KNOB_RADIUS_M) & (heights >= KNOB_BAND * knob.top_m)
            & (heights <= knob.top_m + 0.015))


def knob_reading(points: np.ndarray, heights: np.ndarray, knob: KnobLook, centre_xy: np.ndarray,
                 turn: float = 0.0) -> tuple[float, int] | None:
    """``(bar yaw (rad, world, in (-pi, pi]), points)`` of the knob of a fixture whose body's
    footprint centre is ``centre_xy`` (2,) world m, from the cloud ``points`` (N, 3) world m
    with ``heights`` (N,) m above the support: the principal horizontal axis of the points
    within :data:`KNOB_RADIUS_M` of the knob's axis, between :data:`KNOB_BAND` of its top and
    1.5 cm above it; ``None`` with fewer than :data:`KNOB_MIN_POINTS` points, a spread less
    elongated than :data:`KNOB_MIN_ELONGATION`, one not of a bar's size
    (:data:`KNOB_ALONG_STD_M`, :data:`KNOB_ACROSS_STD_MAX_M`) or taller than the knob
    (:data:`KNOB_TOP_TOL_M`): the arm hides it, something stands there, or it is not a knob.
    The yaw maps to a joint position by :meth:`KnobLook.joint_position`; ``turn``: the
    fixture stands that far (rad) from how its look was measured."""
    near = knob_band(points, heights, knob, centre_xy, turn)
    if int(near.sum()) < KNOB_MIN_POINTS:
        return None
    if float(np.percentile(heights[near], 90)) > knob.top_m + KNOB_TOP_TOL_M:
        return None  # taller than the knob: a bowl's rim, a can
    xy = points[near, :2] - points[near, :2].mean(axis=0)
    w, v = np.linalg.eigh(np.cov(xy.T))
    across, along = math.sqrt(max(float(w[0]), 0.0)), math.sqrt(max(float(w[1]), 0.0))
    if (across <= 0 or along / across < KNOB_MIN_ELONGATION or across > KNOB_ACROSS_STD_MAX_M
            or not KNOB_ALONG_STD_M[0] <= along <= KNOB_ALONG_STD_M[1]):
        return None
    return math.atan2(float(v[1, 1]), float(v[0, 1])), int(near.sum())


#: A drawer's handle is read from the points within this height of its centre, m (LIBERO's
#: cabinet handles: bars 1.6 cm thick on drawer fronts 6.8 cm tall, 7 cm apart).
DRAWER_BAND_M = 0.015
#: ... along the drawer's axis from this far inside its shut position to this far beyond its
#: open stop, m.
DRAWER_WINDOW_M = 0.03
#: Fewest points in that window for a reading (on the perceiver's voxel grid).
DRAWER_MIN_POINTS = 8
#: The handle is the outermost 5 mm slice (with the slice inside it) whose points span at least
#: this fraction of the handle's length across the drawer: a thing narrower than the handle (a
#: bowl's rim, a can) or a few stray points do not read as it.
DRAWER_MIN_SPAN = 0.6
#: The handle's slice is checked this far beyond each end of the handle (less 1 cm), m: a
#: slice that goes on there (more points beyond the ends than :data:`DRAWER_FRONT_FRACTION`
#: of the slice's own) is the drawer's front, seen where its handle is hidden, and gives no
#: reading.
DRAWER_BEYOND_M = 0.04
DRAWER_FRONT_FRACTION = 0.3
#: ... and this far above the band (from 5 mm over it): a slice that goes on up there (more
#: points than :data:`DRAWER_FRONT_FRACTION` of its own) is something taller than the handle's
#: bar standing in front of it (a bowl by the bottom drawer), and the handle is looked for
#: behind it, m.
DRAWER_ABOVE_M = 0.025
#: A handle has its drawer's front behind it: on one side of the handle at least (from 1 cm
#: past its ends to 5 mm inside the drawer's sides), within 2.5 cm of its level and this far
#: behind the slice's outer face (m, LIBERO's cabinet: the front's face 2.4 cm behind the
#: handle's), at least :data:`DRAWER_FRONT_MIN_POINTS` points spanning
#: :data:`DRAWER_FRONT_SPAN_M` across whose face is straight (:func:`_straight`): a bowl's rim
#: in front of the cabinet has its own wall behind it, curving away.
DRAWER_FRONT_BEHIND_M = (0.015, 0.05)
DRAWER_FRONT_MIN_POINTS = 5
DRAWER_FRONT_SPAN_M = 0.03
#: The handle's outer face is straight: the outermost points of its 1 cm bins across lie within
#: this of each other, m (:func:`_straight`).
DRAWER_STRAIGHT_TOL_M = 0.005
#: The handle's slice stands at the handle's level: the median height of its points at most this
#: below the handle's centre, m (the cameras see the bar's top and front: its median is 0-9 mm
#: above the centre; a plate's rim in front of LIBERO's bottom drawer reads 1.1 cm below it).
DRAWER_LEVEL_TOL_M = 0.006
#: A handle's outer face has air in front of it: band points across the slice's span from this
#: far to this far beyond the slice's outermost point, m, more than :data:`DRAWER_AIR_FRACTION`
#: of the slice's own, make the slice the back of a thing standing in front of the handle (the
#: far rim of a bowl by LIBERO-10's bottom drawer, 5 mm from the handle's face at the rim's
#: nearest: its arc, cut at the slice's outer edge, reads as straight as a bar; the bowl goes on
#: outward without a gap, a handle's face does not), and the handle is looked for behind it.
DRAWER_AIR_M = (0.001, 0.004)
DRAWER_AIR_FRACTION = 0.1
#: 1-sigma uncertainty of a drawer reading, m (``bench/libero_drawer.py`` on generated scenes,
#: docs/libero.md, "Drawers": libero_goal's world 0.2-1.9 mm; LIBERO-90 task 0's world 8-16 mm
#: short, every reading within 2 sigma: there the body's visible depth moves its footprint centre
#: against the handle with where the sampler sets the cabinet).
DRAWER_SIGMA_M = 0.01
#: 1-sigma uncertainty of a drawer read shut because the hand pushed it into its shut stop
#: (:meth:`~phyagentos.perception.Perceiver.note_drawer_stop`), m: the hand held the handle and
#: its position is the arm's forward kinematics (millimetres); a drawer at its stop has no play
#: along its axis (LIBERO's cabinet drawers rest 1.7 mm past their joint's zero under 5, 20 and
#: 60 N alike: ``bench/libero_drawer.py --stop``, docs/libero.md, "Closing a drawer").
DRAWER_STOP_SIGMA_M = 0.002
#: How far the hand's travel may exceed a drawer's while the closed fingers pull its handle, m:
#: the bar's play between them (measured pushing the wooden cabinet's top drawer into its stop:
#: it held the hand after 9.9 and 10.2 mm, LIBERO-90 task 0, inits 0 and 1, the training set;
#: docs/libero.md, "Closing a drawer"). A drawer the hand pulled open
#: (:meth:`~phyagentos.perception.Perceiver.note_drawer_opened`) is at least its travel less
#: this out.
DRAWER_HANDLE_PLAY_M = 0.012
_DRAWER_SLICE_M = 0.005


def _keyed(d: Any, keys: Sequence[str] | set[str], fixture: str, part: str) -> Mapping[str, Any]:
    """``d``, a declared ``part`` of ``fixture`` (its knob, lean, root), checked to be a mapping
    with exactly ``keys``.

    Raises:
        PerceptionError: otherwise (the valid keys listed).
    """
    if not isinstance(d, Mapping) or set(d) != set(keys):
        raise PerceptionError(f"fixture {fixture!r}: {part} must be a mapping with keys {format_choices(keys)}, "
                              f"got {d!r}")
    return d


def _part_name(d: Any, keys: tuple[str, ...], fixture: str, kind: str) -> tuple[str, str]:
    """``(name, "fixture 'f': <kind> 'name'")`` of a declared part of ``fixture`` (a drawer, a
    compartment): ``d`` must be a mapping with exactly ``keys``, its ``name`` a non-empty string.

    Raises:
        PerceptionError: otherwise (the valid keys listed).
    """
    if not isinstance(d, Mapping) or set(d) != set(keys):
        raise PerceptionError(f"fixture {fixture!r}: each {kind} must be a mapping with keys "
                              f"{format_choices(keys)}, got {d!r}")
    name = d["name"]
    if not isinstance(name, str) or not name:
        raise PerceptionError(f"fixture {fixture!r}: a {kind} needs a non-empty name, got {name!r}")
    return name, f"fixture {fixture!r}: {kind} {name!r}"


@dataclass(frozen=True)
class DrawerLook:
    """One drawer of a fixture (module docstring): where its handle stands shut, how it opens;
    m, world frame at turn 0."""

    name: str
    handle_offset_m: tuple[float, float]
    height_m: float
    half_length_m: float
    axis_xy: tuple[float, float]
    travel_m: tuple[float, float]
    face_m: float
    half_width_m: float
    top_m: float
    back_m: float

    KEYS = ("name", "handle_offset_m", "height_m", "half_length_m", "axis_xy", "travel_m", "face_m", "half_width_m",
            "top_m", "back_m")

    @property
    def bottom_m(self) -> float:
        """Height of the drawer's underside above the support, m: its front stands as far below
        the handle's centre as above it (LIBERO's cabinet drawers: fronts 6.8 cm tall, the handle
        at their middle; the top drawer's underside 15.5 cm up, from 2 x 18.9 - 22.2), never
        below the support."""
        return max(0.0, 2.0 * self.height_m - self.top_m)

    @classmethod
    def from_dict(cls, d: Any, fixture: str) -> "DrawerLook":
        """From a mapping with the keys :attr:`KEYS` (module docstring; ``half_width_m``: half the
        drawer's width across its axis, ``top_m``: its top above the support, ``back_m``: how far
        the body's back face lies behind its footprint centre along the axis, drawers shut).

        Raises:
            PerceptionError: a missing or unknown key (the valid ones listed) or a malformed value.
        """
        name, what = _part_name(d, cls.KEYS, fixture, "drawer")
        off = _floats(d["handle_offset_m"], 2, f"{what}: handle_offset_m")
        axis = np.asarray(_floats(d["axis_xy"], 2, f"{what}: axis_xy"))
        lo, hi = _floats(d["travel_m"], 2, f"{what}: travel_m")
        height, half_len, face, half_w, top, back = (
            _floats([d[k]], 1, f"{what}: {k}")[0]
            for k in ("height_m", "half_length_m", "face_m", "half_width_m", "top_m", "back_m"))
        if not 0.9 < float(np.linalg.norm(axis)) < 1.1 or not lo < hi or min(height, half_len, half_w, top, back) <= 0:
            raise PerceptionError(f"{what}: needs a unit axis_xy, travel_m lo < hi and positive heights and "
                                  f"lengths, got {d!r}")
        axis = axis / np.linalg.norm(axis)
        return cls(name, off, height, half_len, (float(axis[0]), float(axis[1])), (lo, hi), face,  # type: ignore[arg-type]
                   half_w, top, back)

    def as_dict(self) -> dict[str, Any]:
        """The mapping :meth:`from_dict` reads."""
        return {"name": self.name, "handle_offset_m": list(self.handle_offset_m), "height_m": self.height_m,
                "half_length_m": self.half_length_m, "axis_xy": list(self.axis_xy), "travel_m": list(self.travel_m),
                "face_m": self.face_m, "half_width_m": self.half_width_m, "top_m": self.top_m, "back_m": self.back_m}

    def frame(self, centre_xy: np.ndarray, turn: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(handle centre shut (2,), opening direction u (2,), across v (2,))``, world m, of
        this drawer on a body centred at ``centre_xy`` standing ``turn`` rad from how its look
        was measured."""
        u = turned_xy(self.axis_xy, turn)
        return np.asarray(centre_xy, float) + turned_xy(self.handle_offset_m, turn), u, np.array([-u[1], u[0]])


@dataclass(frozen=True)
class CompartmentLook:
    """One compartment of a fixture (LIBERO's desk caddy has four): an open box among its walls
    that things are set into; m, world frame at turn 0, from the fixture's model.

    ``model_name`` is the model's own word for it (kept to match measurements only): the
    perceiver names a compartment by the viewer's side of the fixture it lies on
    (:func:`compartment_sides`), as a person asking for "the back compartment" sees it."""

    model_name: str
    offset_m: tuple[float, float]
    half_extents_m: tuple[float, float]
    height_m: float

    KEYS = ("name", "offset_m", "half_extents_m", "height_m")

    @classmethod
    def from_dict(cls, d: Any, fixture: str) -> "CompartmentLook":
        """From a mapping with the keys :attr:`KEYS`: ``name`` the model's word for it,
        ``offset_m`` (2,) from the body's footprint centre to the compartment's centre,
        ``half_extents_m`` (2,) its footprint's half extents on the world axes, ``height_m`` its
        floor above the support.

        Raises:
            PerceptionError: a missing or unknown key (the valid ones listed) or a malformed value.
        """
        name, what = _part_name(d, cls.KEYS, fixture, "compartment")
        off = _floats(d["offset_m"], 2, f"{what}: offset_m")
        half = _floats(d["half_extents_m"], 2, f"{what}: half_extents_m")
        height = _floats([d["height_m"]], 1, f"{what}: height_m")[0]
        if min(half) <= 0 or height < 0:
            raise PerceptionError(f"{what}: half_extents_m must be > 0 and height_m >= 0, got {d!r}")
        return cls(name, off, half, height)  # type: ignore[arg-type]

    def box(self, centre_xy: np.ndarray, turn: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """``(centre (2,), half extents on the world axes (2,))``, m, of this compartment in a body
        centred at ``centre_xy`` standing ``turn`` rad (0 or pi, or a quarter turn: the sides
        trade axes) from how its look was measured."""
        half = np.asarray(self.half_extents_m, float)
        if abs(math.sin(turn)) > math.sqrt(0.5):
            half = half[::-1].copy()
        return np.asarray(centre_xy, float) + turned_xy(self.offset_m, turn), half


def compartment_sides(offsets_xy: Sequence[np.ndarray], right_xy: np.ndarray) -> list[str | None]:
    """The viewer's side each compartment lies on (``left`` / ``right`` / ``front`` / ``back``,
    :data:`~phyagentos.geometry.VIEWER_SIDES`), from its centre's offset (2,) from the fixture's
    footprint centre, world m, and the viewer's right on the table ``right_xy`` (2,): the side
    whose direction the offset points along most. Where two compartments take one side, the
    one farther that way keeps it and the other is named by none (``None``): a name must pick
    one compartment."""
    from phyagentos.geometry import VIEWER_SIDES, viewer_side_xy  # noqa: PLC0415

    dirs = {side: viewer_side_xy(right_xy, side) for side in VIEWER_SIDES}
    best = []
    for off in offsets_xy:
        scores = {side: float(np.dot(np.asarray(off, float)[:2], u)) for side, u in dirs.items()}
        side = max(scores, key=scores.__getitem__)
        best.append((side, scores[side]))
    out: list[str | None] = []
    for i, (side, score) in enumerate(best):
        rivals = [sc for j, (sd, sc) in enumerate(best) if j != i and sd == side]
        out.append(side if all(score > sc for sc in rivals) else None)
    return out


def compartment_entity_name(fixture: str, side: str) -> str:
    """The snapshot entity name of ``fixture``'s compartment on the viewer's ``side``:
    ``desk_caddy_1`` 's ``back`` is ``desk_caddy_1_back_compartment``."""
    return f"{fixture}_{side}_compartment"


def drawer_entity_name(fixture: str, drawer: str) -> str:
    """The snapshot entity name of ``fixture``'s drawer ``drawer``: ``wooden_cabinet_1`` 's
    ``top`` is ``wooden_cabinet_1_top_drawer``."""
    return f"{fixture}_{drawer}_drawer"


def drawer_band(points: np.ndarray, heights: np.ndarray, drawer: DrawerLook, centre_xy: np.ndarray,
                turn: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """``(mask (N,) bool, along (N,) m)``: the points of ``points`` (N, 3) world m (``heights``
    (N,) m above the support) where ``drawer`` of a body centred at ``centre_xy`` shows its
    handle (within :data:`DRAWER_BAND_M` of its height, its half length across, and along its
    axis from :data:`DRAWER_WINDOW_M` inside shut to as far beyond its open stop), and every
    point's distance along the opening direction from the handle's shut centre."""
    c0, u, v = drawer.frame(centre_xy, turn)
    rel = points[:, :2] - c0
    along, across = rel @ u, rel @ v
    lo, hi = drawer.travel_m
    mask = ((np.abs(across) <= drawer.half_length_m) & (np.abs(heights - drawer.height_m) <= DRAWER_BAND_M)
            & (along >= lo - DRAWER_WINDOW_M) & (along <= hi + drawer.face_m + DRAWER_WINDOW_M))
    return mask, along


def drawer_reading(points: np.ndarray, heights: np.ndarray, drawer: DrawerLook, centre_xy: np.ndarray,
                   turn: float = 0.0) -> tuple[float, int] | None:
    """``(opening (m the drawer stands out of shut, along its axis), points)`` of ``drawer`` of
    a fixture whose body's footprint centre is ``centre_xy`` (2,) world m, from the cloud
    ``points`` (N, 3) world m with ``heights`` (N,) m above the support: in the handle's
    window (:func:`drawer_band`), the outermost :data:`_DRAWER_SLICE_M` slice along the axis
    whose points (with the slice inside it) span :data:`DRAWER_MIN_SPAN` of the handle's length
    is the handle; its outer face (the 90th percentile of those points along the axis) less the
    look's ``face_m`` is the opening. ``None`` with fewer than :data:`DRAWER_MIN_POINTS` points
    or no slice that wide: the handle is hidden (an open drawer above it, the arm) or not
    there."""
    mask, along = drawer_band(points, heights, drawer, centre_xy, turn)
    if int(mask.sum()) < DRAWER_MIN_POINTS:
        return None
    c0, _, v = drawer.frame(centre_xy, turn)
    across_all = (points[:, :2] - c0) @ v
    a = along[mask]
    across = across_all[mask]
    h_band = heights[mask]
    # the same band just beyond the handle's ends: a drawer's front shows there, a handle does not
    beyond = ((np.abs(across_all) > drawer.half_length_m + 0.01)
              & (np.abs(across_all) <= drawer.half_length_m + DRAWER_BEYOND_M)
              & (np.abs(heights - drawer.height_m) <= DRAWER_BAND_M))
    a_beyond = along[beyond]
    # beside the handle, at its level: the drawer's front, which stands behind a handle's face
    front = ((np.abs(across_all) >= drawer.half_length_m + 0.01) & (np.abs(across_all) <= drawer.half_width_m - 0.005)
             & (np.abs(heights - drawer.height_m) <= DRAWER_BAND_M + 0.01))
    a_front, x_front = along[front], across_all[front]
    # the same slice just above the band: a bar ends there, a bowl or a can goes on
    above = ((np.abs(across_all) <= drawer.half_length_m) & (heights > drawer.height_m + DRAWER_BAND_M + 0.005)
             & (heights <= drawer.height_m + DRAWER_BAND_M + DRAWER_ABOVE_M))
    a_above = along[above]
    need = DRAWER_MIN_SPAN * 2.0 * drawer.half_length_m
    top = float(a.max())
    k = 0
    while top - k * _DRAWER_SLICE_M >= a.min():
        hi = top - k * _DRAWER_SLICE_M
        sel = (a <= hi) & (a > hi - 2 * _DRAWER_SLICE_M)
        if int(sel.sum()) >= 5 and float(np.ptp(across[sel])) >= need:
            in_slice = (a_above <= hi) & (a_above > hi - 2 * _DRAWER_SLICE_M)
            if (int(in_slice.sum()) > DRAWER_FRONT_FRACTION * int(sel.sum())
                    or float(np.median(h_band[sel])) < drawer.height_m - DRAWER_LEVEL_TOL_M):
                k += 1  # taller than a bar (a bowl), or below its level (a plate's rim), in front of it: look behind
                continue
            if not _straight(a, across, sel, hi):
                k += 1  # a rim's arc (a plate tilted against the drawer), not a bar's face: look behind it
                continue
            face = float(a[sel].max())
            in_front = ((a > face + DRAWER_AIR_M[0]) & (a <= face + DRAWER_AIR_M[1])
                        & (across >= float(across[sel].min())) & (across <= float(across[sel].max())))
            if int(in_front.sum()) > DRAWER_AIR_FRACTION * int(sel.sum()):
                k += 1  # no air in front of it: the back of a thing standing before the handle; look behind it
                continue
            wide = int(((a_beyond <= hi) & (a_beyond > hi - 2 * _DRAWER_SLICE_M)).sum())
            if wide > DRAWER_FRONT_FRACTION * int(sel.sum()):
                return None  # as wide as the drawer's front: the handle is hidden (the arm) or gone
            behind = (a_front <= hi - DRAWER_FRONT_BEHIND_M[0]) & (a_front >= hi - DRAWER_FRONT_BEHIND_M[1])
            if not any(int(side.sum()) >= DRAWER_FRONT_MIN_POINTS and float(np.ptp(x_front[side])) >= DRAWER_FRONT_SPAN_M
                       and _straight(a_front, x_front, side, float(a_front[side].max()))
                       for side in (behind & (x_front < 0), behind & (x_front > 0))):
                k += 1  # no flat drawer front beside it (a bowl's rim in front of the cabinet): look behind it
                continue
            return float(np.percentile(a[sel], 90)) - drawer.face_m, int(sel.sum())
        k += 1
    return None


def _straight(a: np.ndarray, across: np.ndarray, sel: np.ndarray, hi: float) -> bool:
    """Whether the slice ``sel`` (ending at ``hi`` m along the drawer's axis) is a straight bar's
    face: over 1 cm bins across its span, the outermost point (along ``a``, of the band's points
    not beyond ``hi``; ``across`` m) of every bin with points lies within
    :data:`DRAWER_STRAIGHT_TOL_M` of the outermost of all (a plate's or a bowl's rim falls away
    toward its ends: 8 mm at 4 cm from the apex of a 10 cm radius)."""
    lo_x, hi_x = float(across[sel].min()), float(across[sel].max())
    keep = (a <= hi) & (across >= lo_x) & (across <= hi_x)
    bins = np.floor((across[keep] - lo_x) / 0.01).astype(int)
    tops = np.full(int(bins.max()) + 1, -np.inf)
    np.maximum.at(tops, bins, a[keep])
    tops = tops[np.isfinite(tops)]
    return bool(tops.max() - tops.min() <= DRAWER_STRAIGHT_TOL_M)


#: A fixture perceived turned by more than this from how its look was measured (beyond the
#: turn of 0 or pi), rad, keeps its look's yaw for its model frame (:meth:`RootLook.pose`): a
#: footprint's long side is read within a few degrees (LIBERO's fixtures stand square to the
#: world), while a nearly square one's can swap sides.
ROOT_YAW_MAX_RAD = math.radians(20.0)


@dataclass(frozen=True)
class LeanLook:
    """Where a thing is let go on a fixture whose place site is a ramp (LIBERO's wine rack:
    a bottle lies back on its upper ramp, its base against the lip at its foot) and how it
    is leant there; m and rad, world axes as measured.

    Attributes:
        offset_m: (2,) the crest (the lip's top) from the body's footprint centre.
        height_m: the crest's height above the support.
        toward_xy: (2,) unit: the way the ramp rises from the crest (the thing's top leans so).
        angle_rad: the ramp's slope: how far from upright the thing is let go.
    """

    offset_m: tuple[float, float]
    height_m: float
    toward_xy: tuple[float, float]
    angle_rad: float

    @classmethod
    def from_dict(cls, d: Any, fixture: str) -> "LeanLook":
        """From ``{offset_m, height_m, toward_xy, angle_rad}``.

        Raises:
            PerceptionError: a missing or unknown key (the valid ones listed) or a malformed
                value (``toward_xy`` not a unit vector, ``angle_rad`` outside (0, pi/2), a
                negative height).
        """
        keys = ("offset_m", "height_m", "toward_xy", "angle_rad")
        d = _keyed(d, keys, fixture, "lean")
        off = _floats(d["offset_m"], 2, f"fixture {fixture!r}: lean.offset_m")
        height = _floats([d["height_m"]], 1, f"fixture {fixture!r}: lean.height_m")[0]
        toward = _floats(d["toward_xy"], 2, f"fixture {fixture!r}: lean.toward_xy")
        angle = _floats([d["angle_rad"]], 1, f"fixture {fixture!r}: lean.angle_rad")[0]
        if height < 0 or abs(math.hypot(*toward) - 1.0) > 0.01 or not 0.0 < angle < 0.5 * math.pi:
            raise PerceptionError(f"fixture {fixture!r}: lean needs height_m >= 0, a unit toward_xy and "
                                  f"0 < angle_rad < pi/2, got {d!r}")
        return cls(off, height, toward, angle)  # type: ignore[arg-type]

    def at(self, centre_xy: np.ndarray, turn: float = 0.0) -> tuple[np.ndarray, float, np.ndarray]:
        """``(crest xy (2,) world m, height above the support m, toward (2,) world unit)`` for a
        body perceived with its footprint centred at ``centre_xy`` (2,), standing ``turn`` rad
        from how the look was measured."""
        return (np.asarray(centre_xy, float) + turned_xy(self.offset_m, turn), float(self.height_m),
                turned_xy(self.toward_xy, turn))


@dataclass(frozen=True)
class RootLook:
    """Where a fixture's model frame stands from its perceived body, measured on generated
    scenes (``phyagentos.targets.libero.descriptors``): ``offset_m`` (3,) world m from the
    footprint's centre on the support to the frame's origin and ``yaw_rad`` the frame's yaw,
    both at turn 0; ``body_yaw_rad`` the body's long side's yaw then (rad, an axis). The height
    is taken from the support, not the body's centre: what the cameras see of a fixture's top
    changes with what stands on it or comes out of it (an open drawer), its base does not."""

    offset_m: tuple[float, float, float]
    yaw_rad: float
    body_yaw_rad: float

    @classmethod
    def from_dict(cls, d: Any, fixture: str) -> "RootLook":
        """From ``{offset_m: [x, y, z], yaw_rad, body_yaw_rad}``.

        Raises:
            PerceptionError: another key set or a malformed value.
        """
        keys = {"offset_m", "yaw_rad", "body_yaw_rad"}
        d = _keyed(d, keys, fixture, "root")
        off = _floats(d["offset_m"], 3, f"fixture {fixture!r}: root.offset_m")
        yaw, body_yaw = _floats([d["yaw_rad"], d["body_yaw_rad"]], 2, f"fixture {fixture!r}: root yaws (rad)")
        return cls(off, yaw, body_yaw)  # type: ignore[arg-type]

    def to_dict(self) -> dict[str, Any]:
        """The mapping :meth:`from_dict` reads."""
        return {"offset_m": list(self.offset_m), "yaw_rad": self.yaw_rad, "body_yaw_rad": self.body_yaw_rad}

    def pose(self, position: np.ndarray, body_yaw: float, turn: float, top_m: float) -> tuple[np.ndarray, float]:
        """``(origin (3,) world m, yaw rad)`` of the model frame of a body perceived centred at
        ``position`` (3,) (z at half its top ``top_m`` m above the support), its long side at
        ``body_yaw`` rad, standing ``turn`` rad (0 or pi) from how the look was measured: the
        look's offset and yaw turned by ``turn`` and by how far the long side stands from the
        look's (an axis: within pi / 2; beyond :data:`ROOT_YAW_MAX_RAD` taken as 0)."""
        delta = (float(body_yaw) - self.body_yaw_rad + 0.5 * math.pi) % math.pi - 0.5 * math.pi
        if abs(delta) > ROOT_YAW_MAX_RAD:
            delta = 0.0
        a = float(turn) + delta
        xy = np.asarray(position, float)[:2] + turned_xy(self.offset_m[:2], a)
        yaw = (self.yaw_rad + a + math.pi) % (2.0 * math.pi) - math.pi
        return np.array([xy[0], xy[1], float(position[2]) - 0.5 * float(top_m) + self.offset_m[2]]), yaw


@dataclass(frozen=True)
class FixtureLook:
    """A declared fixture with its measured look (module docstring); lengths in m."""

    name: str
    cls: str | None
    size_m: tuple[float, float, float]
    place_offset_m: tuple[float, float] | None = None
    place_half_m: tuple[float, float] | None = None
    place_height_m: float | None = None
    knob: KnobLook | None = None
    drawers: tuple[DrawerLook, ...] = ()
    compartments: tuple[CompartmentLook, ...] = ()
    root: RootLook | None = None
    model_box: tuple[tuple[float, float], tuple[float, float]] | None = None
    door: DoorLook | None = None
    inside: InsideLook | None = None
    lean: LeanLook | None = None

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "FixtureLook | None":
        """From a declared fixture ``{name, class, size_m?, place?, knob?, drawers?, compartments?,
        root?, model_box?, door?, inside?, lean?}``; ``None`` when it has no look (``size_m``): such a fixture
        is not perceived. ``lean``: a :class:`LeanLook` (a ramp things are let go leant onto).
        ``model_box``: ``{lo: [x, y], hi: [x, y]}``, m, the footprint of the fixture's fixed parts
        (its model's meshes, no drawer, door or knob) in its model frame; it needs
        ``root`` (where that frame stands from the perceived body), as does ``door``
        (:class:`~phyagentos.perception.door.DoorLook`, in that frame) and ``inside`` (the room
        behind the door, :class:`~phyagentos.perception.door.InsideLook`).

        Raises:
            PerceptionError: an unknown key (the valid ones listed) or a malformed value.
        """
        if not isinstance(d, Mapping):
            raise PerceptionError(f"a declared fixture must be a mapping, got {type(d).__name__}")
        valid = ("name", "class", "size_m", "place", "knob", "drawers", "compartments", "root", "model_box", "door",
                 "inside", "lean")
        unknown = set(d) - set(valid)
        name = d.get("name")
        if unknown:
            raise PerceptionError(f"declared fixture {name!r}: unknown key(s) {format_choices(unknown)}; "
                                  f"valid keys: {format_choices(valid)}")
        if not isinstance(name, str) or not name:
            raise PerceptionError(f"a declared fixture needs a non-empty name, got {name!r}")
        if d.get("size_m") is None:
            return None
        size = _floats(d["size_m"], 3, f"fixture {name!r}: size_m ([long, short, top height], m)")
        knob = KnobLook.from_dict(d["knob"], name) if d.get("knob") is not None else None
        raw_drawers = d.get("drawers") or ()
        if not isinstance(raw_drawers, Sequence) or isinstance(raw_drawers, str):
            raise PerceptionError(f"fixture {name!r}: drawers must be a list, got {raw_drawers!r}")
        drawers = tuple(DrawerLook.from_dict(r, name) for r in raw_drawers)
        if len({dr.name for dr in drawers}) != len(drawers):
            raise PerceptionError(f"fixture {name!r}: a drawer name is used twice: {[dr.name for dr in drawers]}")
        raw_comps = d.get("compartments") or ()
        if not isinstance(raw_comps, Sequence) or isinstance(raw_comps, str):
            raise PerceptionError(f"fixture {name!r}: compartments must be a list, got {raw_comps!r}")
        comps = tuple(CompartmentLook.from_dict(r, name) for r in raw_comps)
        root = RootLook.from_dict(d["root"], name) if d.get("root") is not None else None
        box = _model_box(d.get("model_box"), name, root)
        door = DoorLook.from_dict(d["door"], name) if d.get("door") is not None else None
        if door is not None and root is None:
            raise PerceptionError(f"fixture {name!r}: a door needs the fixture's root (where its model frame stands)")
        inside = InsideLook.from_dict(d["inside"], name) if d.get("inside") is not None else None
        if inside is not None and root is None:
            raise PerceptionError(f"fixture {name!r}: an inside needs the fixture's root (where its model frame stands)")
        lean = LeanLook.from_dict(d["lean"], name) if d.get("lean") is not None else None
        place = d.get("place")
        if place is None:
            return cls(name, d.get("class"), size, knob=knob, drawers=drawers, compartments=comps, root=root,
                       model_box=box, door=door, inside=inside, lean=lean)
        if not isinstance(place, Mapping) or set(place) != {"offset_m", "half_extents_m", "height_m"}:
            raise PerceptionError(f"fixture {name!r}: place must be a mapping with keys "
                                  f"{format_choices(('offset_m', 'half_extents_m', 'height_m'))}, got {place!r}")
        off = _floats(place["offset_m"], 2, f"fixture {name!r}: place.offset_m")
        half = _floats(place["half_extents_m"], 2, f"fixture {name!r}: place.half_extents_m")
        height = _floats([place["height_m"]], 1, f"fixture {name!r}: place.height_m")[0]
        if min(half) <= 0 or height < 0:
            raise PerceptionError(f"fixture {name!r}: place.half_extents_m must be > 0 and height_m >= 0, got {place!r}")
        return cls(name, d.get("class"), size, off, half, height, knob, drawers, comps, root, box, door,  # type: ignore[arg-type]
                   inside, lean)

    def in_model(self, points_xy: np.ndarray, sighting: "FixtureSighting", *, edge_m: float = 0.0) -> np.ndarray:
        """(N,) bool: which of ``points_xy`` (N, 2) world m lie over the footprint of the
        fixture's fixed parts (``model_box`` grown by ``edge_m``), its model frame put where
        ``sighting`` says (:meth:`RootLook.pose`); all False without a model box."""
        xy = np.asarray(points_xy, dtype=float).reshape(-1, 2)
        if self.model_box is None or self.root is None:
            return np.zeros(len(xy), dtype=bool)
        origin, yaw = self.root.pose(sighting.position, sighting.yaw, sighting.turn, sighting.top_m)
        local = _in_frame(xy, origin[:2], yaw)
        lo, hi = np.asarray(self.model_box[0]) - edge_m, np.asarray(self.model_box[1]) + edge_m
        return np.all((local >= lo) & (local <= hi), axis=1)

    def place_patch(self, centre_xy: np.ndarray, half_xy: np.ndarray,
                    turn: float = 0.0) -> tuple[np.ndarray, np.ndarray, float]:
        """``(centre (2,), half extents (2,) on the world axes, surface height above the
        support)`` of the place patch of a body perceived at ``centre_xy`` with footprint half
        extents ``half_xy`` (world axes), m, standing ``turn`` rad (0 or pi: LIBERO's fixtures
        stand square to the world, either way round) from how the look was measured."""
        if self.place_offset_m is None:
            return np.asarray(centre_xy, float), np.asarray(half_xy, float), float(self.size_m[2])
        half = np.asarray(self.place_half_m, float)
        if abs(math.sin(turn)) > math.sqrt(0.5):  # a quarter turn: the patch's sides trade axes
            half = half[::-1].copy()
        return (np.asarray(centre_xy, float) + turned_xy(self.place_offset_m, turn), half,
                float(self.place_height_m or 0.0))


def _model_box(raw: Any, fixture: str, root: RootLook | None) -> tuple[tuple[float, float], tuple[float, float]] | None:
    """A declared ``model_box`` (:meth:`FixtureLook.from_dict`) as ``((lo_x, lo_y), (hi_x, hi_y))``, or None.

    Raises:
        PerceptionError: not ``{lo, hi}``, ``lo`` not below ``hi``, or no ``root`` to place it.
    """
    if raw is None:
        return None
    if not isinstance(raw, Mapping) or set(raw) != {"lo", "hi"}:
        raise PerceptionError(f"fixture {fixture!r}: model_box must be a mapping with keys "
                              f"{format_choices(('lo', 'hi'))}, got {raw!r}")
    lo = _floats(raw["lo"], 2, f"fixture {fixture!r}: model_box.lo")
    hi = _floats(raw["hi"], 2, f"fixture {fixture!r}: model_box.hi")
    if not all(a < b for a, b in zip(lo, hi)):
        raise PerceptionError(f"fixture {fixture!r}: model_box.lo must lie below model_box.hi, got {raw!r}")
    if root is None:
        raise PerceptionError(f"fixture {fixture!r}: a model_box needs the fixture's root (where its model frame stands)")
    return lo, hi  # type: ignore[return-value]


def fixtures_from_declared(declared: Mapping[str, Any] | Sequence[Any]) -> list[FixtureLook]:
    """The fixtures with a look among ``describe_declared()``'s ``fixtures`` (a mapping) or
    a list of fixture mappings; fixtures without a look are left out.

    Raises:
        PerceptionError: a malformed entry or a name used twice.
    """
    items = declared.get("fixtures", []) if isinstance(declared, Mapping) else declared
    out = [f for f in (FixtureLook.from_dict(d) for d in items or ()) if f is not None]
    names = [f.name for f in out]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise PerceptionError(f"declared fixture name(s) used twice: {dup}")
    return out


@dataclass(frozen=True)
class FixtureSighting:
    """A fixture's body in one observation: footprint centre (3,) world m (z at half its top),
    yaw of the footprint's long side (rad, [-pi/2, pi/2)), half extents (3,) (long, short,
    half the top height), axis-aligned footprint half extents (2,), the top above the
    support (m), the supporting coarse points and the relative size error of the fit;
    ``found_by``: ``size`` (a segment fit the look) or ``knob`` (:func:`find_by_knob`);
    ``turn``: how far (rad, 0 or pi) the fixture stands from how its look was measured (its
    place patch and knob are at the look's offsets turned by it)."""

    name: str
    position: np.ndarray
    yaw: float
    half_extents: np.ndarray
    half_xy_world: np.ndarray
    top_m: float
    points: int
    error: float
    found_by: str = "size"
    turn: float = 0.0


def _body(points: np.ndarray, heights: np.ndarray, idx: np.ndarray) -> FixtureSighting:
    xy, h = points[idx, :2], heights[idx]
    centre, yaw, half = _rect(xy)
    top = float(np.percentile(h, TOP_PERCENTILE))
    c, s = abs(math.cos(yaw)), abs(math.sin(yaw))
    half_world = np.array([c * half[0] + s * half[1], s * half[0] + c * half[1]])
    z = float(np.median(points[idx, 2] - h)) + 0.5 * top
    return FixtureSighting("", np.array([centre[0], centre[1], z]), yaw, np.array([half[0], half[1], 0.5 * top]),
                           half_world, top, int(idx.size), 0.0)


def segments(cloud: Cloud, config: PerceptionConfig) -> list[np.ndarray]:
    """Index arrays of the segments of ``cloud`` a fixture may be (the perceiver's clustering,
    :func:`~phyagentos.perception.detect.cluster`; at least :data:`MIN_POINTS` points)."""
    return [idx for idx in cluster(cloud, config) if idx.size >= MIN_POINTS]


def bodies(cloud: Cloud, heights: np.ndarray, config: PerceptionConfig) -> list[FixtureSighting]:
    """Every segment of ``cloud`` (:func:`segments`, on a cloud cropped at the fixtures'
    height) as an unnamed body (``name`` empty, ``error`` 0): footprint, yaw, top
    (``heights``: (N,) m above the support plane); what a look is measured from."""
    return [_body(cloud.points, heights, idx) for idx in segments(cloud, config)]


def _without_drawers(points: np.ndarray, heights: np.ndarray, idx: np.ndarray,
                     look: FixtureLook) -> FixtureSighting | None:
    """The body of segment ``idx`` as ``look`` 's fixture with its drawers shut. A segment
    deeper along the drawers' axis than the look (``2 back_m`` + 1 cm) has drawers out: an open
    drawer moves the front, never the back, so the points farther than ``2 back_m`` from the
    back (the segment's rearmost point along the axis) are left out of the fit and the body's
    centre is put ``back_m`` in front of the back (the look's ``back_m`` is measured with this
    estimator on the shut body). ``None`` when the look's drawers do not share one axis, or
    nothing is left."""
    axes = {d.axis_xy for d in look.drawers}
    if len(axes) != 1:
        return None
    u = np.asarray(next(iter(axes)), float)
    depth = 2.0 * look.drawers[0].back_m
    along = points[idx, :2] @ u
    back = float(along.min())
    if float(along.max()) - back <= depth + 0.01:
        return _body(points, heights, idx)
    keep = idx[along <= back + depth]
    if keep.size < MIN_POINTS:
        return None
    body = _body(points, heights, keep)
    xy = body.position[:2] + u * (back + 0.5 * depth - float(body.position[:2] @ u))
    return replace(body, position=np.array([xy[0], xy[1], body.position[2]]))


def without_door(points: np.ndarray, heights: np.ndarray, idx: np.ndarray) -> FixtureSighting | None:
    """The body of segment ``idx`` without its thin parts seen from above
    (:func:`~phyagentos.perception.door.thin_parts_removed`): a fixture whose door stands open
    (the slab, 2.4 cm thick on LIBERO's microwave, and its handle's bar) fitted by its body
    alone, as its look was measured (door shut: the slab then lies against the body's front
    and is kept). The footprint is turned to the yaw its straight edges show
    (:func:`edge_yaw`), not the minimum-area rectangle's: the cameras see a wedge of such a
    body's top, whose rectangle leans by a few degrees, which the hinge, 19 cm from the
    middle, turns into a centimetre. ``None`` when too little is left."""
    keep = idx[thin_parts_removed(points[idx, :2])]
    if keep.size < MIN_POINTS:
        return None
    body = _body(points, heights, keep)
    xy = points[keep, :2]
    yaw = edge_yaw(xy, body.yaw)
    local = _in_frame(xy, np.zeros(2), yaw)
    lo, hi = local.min(axis=0), local.max(axis=0)
    half = 0.5 * (hi - lo)
    centre = turned_xy(0.5 * (lo + hi), yaw)
    if half[1] > half[0]:  # the long side first, as every footprint
        half, yaw = half[::-1].copy(), yaw + 0.5 * math.pi
    yaw = (yaw + 0.5 * math.pi) % math.pi - 0.5 * math.pi
    c, s = abs(math.cos(yaw)), abs(math.sin(yaw))
    return replace(body, position=np.array([centre[0], centre[1], body.position[2]]), yaw=yaw,
                   half_extents=np.array([half[0], half[1], body.half_extents[2]]),
                   half_xy_world=np.array([c * half[0] + s * half[1], s * half[0] + c * half[1]]))


#: :func:`edge_yaw`: how far from the first guess (rad) and in what steps the yaw is tried, and
#: the histogram's bin, m.
EDGE_YAW_SPAN_RAD, EDGE_YAW_STEP_RAD, EDGE_BIN_M = 0.15, 0.0025, 0.004


def edge_yaw(xy: np.ndarray, guess: float) -> float:
    """The yaw (rad) within :data:`EDGE_YAW_SPAN_RAD` of ``guess`` (a long side's) at which
    the points ``xy`` (N, 2) world m line up best along a long side: the fullest bin
    (:data:`EDGE_BIN_M`) of their coordinates across it (a straight edge, a face seen edge-on,
    is a peak; the long side's, the longest edge, rather than a short side's or a ridge on the
    top that a short side's histogram would also count)."""
    pts = np.asarray(xy, float)
    best, best_yaw = -1.0, float(guess)
    for a in np.arange(-EDGE_YAW_SPAN_RAD, EDGE_YAW_SPAN_RAD + 1e-9, EDGE_YAW_STEP_RAD):
        yaw = float(guess) + float(a)
        v = _in_frame(pts, np.zeros(2), yaw)[:, 1]
        score = float(np.bincount(np.floor((v - v.min()) / EDGE_BIN_M).astype(int)).max())
        if score > best:
            best, best_yaw = score, yaw
    return best_yaw


def _adjacent(a: np.ndarray, b: np.ndarray, points: np.ndarray) -> bool:
    """Whether two segments' axis-aligned footprints overlap when grown by :data:`JOIN_GAP_M`."""
    lo_a, hi_a = points[a, :2].min(axis=0), points[a, :2].max(axis=0)
    lo_b, hi_b = points[b, :2].min(axis=0), points[b, :2].max(axis=0)
    return bool(np.all(lo_a - JOIN_GAP_M <= hi_b) and np.all(lo_b - JOIN_GAP_M <= hi_a))


#: Grid (m) on which candidate knob axes are tried when a fixture with a knob is found by its
#: knob (:func:`find_by_knob`).
KNOB_SEARCH_GRID_M = 0.02
#: A fixture found by its knob needs this fraction of its footprint (the look's, grown by
#: nothing) covered by points at least half its place surface high (its body, or what stands
#: on it), on a 2 cm grid (LIBERO's stove with a bowl on its burner or a pan's handle
#: against it: 0.6-0.9; bare table where a bar-like thing lies: 0).
KNOB_BODY_COVER = 0.5


#: A fixture with a place patch is taken only where at least this fraction of the patch (on
#: a :data:`KNOB_SEARCH_GRID_M` grid) holds a point at least its surface high, less
#: :data:`PATCH_TOL_M`: its surface, or what stands on it (LIBERO's stove burner, bare or
#: under a bowl: 0.8-1.0; the inside of a frying pan of the stove's size, 1-1.5 cm above the
#: table under a 3.1 cm burner surface: low).
PATCH_COVER = 0.5
PATCH_TOL_M = 0.008
#: The ways round a fixture may stand from how its look was measured, rad: LIBERO's fixtures
#: stand square to the world, and LIBERO-PRO's swapped scenes set the stove down the other
#: way round (its knob away from the robot: libero_goal_swap).
TURNS: tuple[float, ...] = (0.0, math.pi)
#: A fixture found by its knob may hold points higher than its top plus 2 cm, away from its
#: place patch (things set there) and its knob, in at most this fraction of its footprint
#: (LIBERO's cabinet, whose handles read as a bar, is 23 cm tall beside a 3 cm stove; the
#: wine rack standing against the stove in libero_goal_swap covers 0.2 of its footprint).
KNOB_TALL_COVER = 0.35
#: ... and its place patch's own surface seen (within :data:`PATCH_TOL_M`) over at least this
#: fraction of it (LIBERO's stove found by its knob, bare burner: 1.0; a cabinet whose handle
#: read as a knob, its front face crossing the patch: 0.27).
KNOB_SURFACE_COVER = 0.5


def _grid_fraction(xy: np.ndarray, half: np.ndarray) -> float:
    """How many :data:`KNOB_SEARCH_GRID_M` cells the points ``xy`` (N, 2) m hold, over the cells
    of a rectangle of half extents ``half`` (2,) m (at least one): the fraction of an area
    the points cover (above 1 when they spill beyond it)."""
    n_cells = max(1, int(round(4 * half[0] * half[1] / KNOB_SEARCH_GRID_M ** 2)))
    if len(xy) == 0:
        return 0.0
    return len(np.unique(np.floor(xy / KNOB_SEARCH_GRID_M).astype(int), axis=0)) / n_cells


def patch_cover(points: np.ndarray, heights: np.ndarray, look: FixtureLook, centre_xy: np.ndarray,
                turn: float = 0.0, *, at_surface: bool = False) -> float:
    """Fraction (0..1) of the place patch of a body of ``look`` centred at ``centre_xy`` (2,)
    world m whose :data:`KNOB_SEARCH_GRID_M` cells hold a point at least the patch's surface
    high less :data:`PATCH_TOL_M` (``points`` (N, 3) world m, ``heights`` (N,) m above the
    support) and standing ``turn`` rad from how its look was measured; with ``at_surface``,
    cells holding a point within :data:`PATCH_TOL_M` of the surface (the patch itself seen, not
    a taller thing over it). 1.0 for a look without a place patch."""
    if look.place_offset_m is None or look.place_half_m is None:
        return 1.0
    centre, half, _ = look.place_patch(centre_xy, np.zeros(2), turn)
    surface = float(look.place_height_m or 0.0)
    high = np.abs(heights - surface) <= PATCH_TOL_M if at_surface else heights >= surface - PATCH_TOL_M
    inside = np.all(np.abs(points[:, :2] - centre) <= half, axis=1) & high
    return min(1.0, _grid_fraction(points[inside, :2] - centre + half, half))


def find_by_knob(points: np.ndarray, heights: np.ndarray, look: FixtureLook) -> FixtureSighting | None:
    """A fixture with a ``knob`` found by its knob where its body did not fit a look (it is
    segmented together with something touching it, a pan's handle, or with a bowl on its
    burner): every cell of a :data:`KNOB_SEARCH_GRID_M` grid over the points in the knob's
    height band is tried as the knob's axis (:func:`knob_reading`); a bar read there puts
    the body's footprint centre at the bar's centre less the knob's offset (where it must read
    as a bar again), either way round (:data:`TURNS`), and the body is
    taken when at least :data:`KNOB_BODY_COVER` of that footprint (the look's size, its long
    side along the knob's offset) holds points at least half the place surface high, its
    place patch is covered (:func:`patch_cover`) with its own surface seen over
    :data:`KNOB_SURFACE_COVER` of it, and at most :data:`KNOB_TALL_COVER` of it away from the
    patch and the knob stands taller than the look. The
    best covered candidate wins. ``points`` (N, 3) world m, ``heights`` (N,) m above the
    support; the sighting's ``error`` is 1 - its cover (a fit by size has its size error)."""
    knob = look.knob
    if knob is None:
        return None
    band = (heights >= KNOB_BAND * knob.top_m) & (heights <= knob.top_m + 0.015)
    if int(band.sum()) < KNOB_MIN_POINTS:
        return None
    bp, bh = points[band], heights[band]
    half = 0.5 * np.asarray(look.size_m[:2], float)
    floor = 0.5 * (look.place_height_m if look.place_height_m is not None else look.size_m[2])
    raised = points[heights >= floor, :2]
    best: tuple[float, FixtureSighting] | None = None
    cells = np.unique(np.floor(bp[:, :2] / KNOB_SEARCH_GRID_M).astype(int), axis=0)
    for turn in TURNS:
        off = turned_xy(knob.offset_m, turn)
        yaw = math.atan2(off[1], off[0]) if np.linalg.norm(off) > 1e-3 else turn
        for cell in cells:
            axis = (cell + 0.5) * KNOB_SEARCH_GRID_M
            reading = knob_reading(bp, bh, knob, axis - off, turn)
            if reading is None:
                continue
            near = np.linalg.norm(bp[:, :2] - axis, axis=1) <= KNOB_RADIUS_M
            centre = bp[near, :2].mean(axis=0) - off
            if knob_reading(bp, bh, knob, centre, turn) is None:
                continue  # centred on what it read, it must still read as a bar (a bowl's rim does not)
            local = _in_frame(raised, centre, yaw)
            inside = local[np.all(np.abs(local) <= half, axis=1)]
            cover = _grid_fraction(inside, half)
            if (cover < KNOB_BODY_COVER or (best is not None and cover <= best[0])
                    or patch_cover(points, heights, look, centre, turn) < PATCH_COVER
                    or patch_cover(points, heights, look, centre, turn, at_surface=True) < KNOB_SURFACE_COVER
                    or _tall_cover(points, heights, look, centre, yaw, axis, turn) > KNOB_TALL_COVER):
                continue
            foot = np.all(np.abs(_in_frame(points[:, :2], centre, yaw)) <= half, axis=1)
            ground = float(np.median(points[foot, 2] - heights[foot]))
            c, sn = abs(math.cos(yaw)), abs(math.sin(yaw))
            hw = np.array([c * half[0] + sn * half[1], sn * half[0] + c * half[1]])
            best = (cover, FixtureSighting(look.name, np.array([centre[0], centre[1], ground + 0.5 * look.size_m[2]]),
                                           yaw, np.array([half[0], half[1], 0.5 * look.size_m[2]]), hw, look.size_m[2],
                                           int(foot.sum()), 1.0 - min(1.0, cover), "knob", turn))
    return best[1] if best is not None else None


#: A fixture found by its drawers (:func:`find_by_drawers`) needs this many of its drawers read
#: shut (within :data:`DRAWER_FOUND_SHUT_M`) where the look puts them.
DRAWER_FOUND_MIN = 2
DRAWER_FOUND_SHUT_M = 0.015


def find_by_drawers(points: np.ndarray, heights: np.ndarray, look: FixtureLook) -> FixtureSighting | None:
    """A fixture with ``drawers`` found by its handles where its body did not fit a look (it is
    segmented together with something standing against it: LIBERO's cabinet with the wine
    rack). Every :data:`KNOB_SEARCH_GRID_M` cell over the points in a drawer's handle band is
    tried as that handle's shut centre; a handle read there (:func:`drawer_reading`) puts the
    body's footprint centre at the cell less the handle's offset, moved along the drawers'
    axis by the opening read and across it to the middle of the handle's outer slice; the body
    is taken where at least :data:`DRAWER_FOUND_MIN` of its drawers then read shut within
    :data:`DRAWER_FOUND_SHUT_M` and :data:`KNOB_BODY_COVER` of its footprint (``back_m`` deep
    along the axis, the look's other side across it) holds points at least half its top high;
    the most drawers read, then the best covered, wins. Drawers all out at the first sighting
    are not found this way. ``points`` (N, 3) world m, ``heights`` (N,) m above the support;
    the sighting's ``error`` is 1 - its cover."""
    if not look.drawers or len({d.axis_xy for d in look.drawers}) != 1:
        return None
    u = np.asarray(look.drawers[0].axis_xy, float)
    v = np.array([-u[1], u[0]])
    half_u = look.drawers[0].back_m
    half_v = 0.5 * max(look.size_m[:2], key=lambda side: abs(side - 2.0 * half_u))
    yaw = math.atan2(float(v[1]), float(v[0]))
    half = np.array([half_v, half_u])
    raised = points[heights >= 0.5 * look.size_m[2], :2]
    # every reading looks only at heights from below the lowest handle's front to above the
    # highest handle (drawer_reading's bands): the search reads the points there once
    levels = [d.height_m for d in look.drawers]
    slab = ((heights >= min(levels) - DRAWER_BAND_M - 0.011)
            & (heights <= max(levels) + DRAWER_BAND_M + DRAWER_ABOVE_M + 0.001))
    all_points, all_heights = points, heights
    order = np.argsort(points[slab, 0])
    points, heights = points[slab][order], heights[slab][order]
    xs = points[:, 0]
    # ... and only within reach of the handle it reads (drawer_reading's windows): a reach of that
    # square about the handle's shut centre, on the points sorted by x
    reach = max(math.hypot(max(d.travel_m[1] + d.face_m, -d.travel_m[0]) + DRAWER_WINDOW_M, d.half_width_m)
                for d in look.drawers) + 0.01

    def read(d: DrawerLook, centre: np.ndarray) -> tuple[float, int] | None:
        c0 = d.frame(centre)[0]
        lo, hi = np.searchsorted(xs, [c0[0] - reach, c0[0] + reach])
        near = np.abs(points[lo:hi, 1] - c0[1]) <= reach
        return drawer_reading(points[lo:hi][near], heights[lo:hi][near], d, centre)

    tried: set[tuple[int, int]] = set()
    best: tuple[tuple[int, float], FixtureSighting] | None = None
    for drawer in look.drawers:
        band = np.abs(heights - drawer.height_m) <= DRAWER_BAND_M
        if int(band.sum()) < DRAWER_MIN_POINTS:
            continue
        for cell in np.unique(np.floor(points[band, :2] / KNOB_SEARCH_GRID_M).astype(int), axis=0):
            centre = (cell + 0.5) * KNOB_SEARCH_GRID_M - np.asarray(drawer.handle_offset_m, float)
            reading = read(drawer, centre)
            if reading is None:
                continue
            centre = centre + u * reading[0]
            c0, _, _ = drawer.frame(centre)
            lo, hi = np.searchsorted(xs, [c0[0] - reach, c0[0] + reach])
            rel, h = points[lo:hi, :2] - c0, heights[lo:hi]
            near = ((np.abs(h - drawer.height_m) <= DRAWER_BAND_M) & (np.abs(rel @ u - drawer.face_m) <= 2 * _DRAWER_SLICE_M)
                    & (np.abs(rel @ v) <= drawer.half_length_m + 0.01))
            if int(near.sum()) < 5:
                continue
            across = rel[near] @ v
            centre = centre + v * 0.5 * float(across.min() + across.max())
            key = (int(round(float(centre[0]) / 0.005)), int(round(float(centre[1]) / 0.005)))
            if key in tried:
                continue
            tried.add(key)
            shut = sum(1 for d in look.drawers
                       if (r := read(d, centre)) is not None and abs(r[0]) <= DRAWER_FOUND_SHUT_M)
            if shut < DRAWER_FOUND_MIN:
                continue
            local = _in_frame(raised, centre, yaw)
            cover = _grid_fraction(local[np.all(np.abs(local) <= half, axis=1)], half)
            if cover < KNOB_BODY_COVER or (best is not None and (shut, cover) <= best[0]):
                continue
            foot = np.all(np.abs(_in_frame(all_points[:, :2], centre, yaw)) <= half, axis=1)
            ground = float(np.median(all_points[foot, 2] - all_heights[foot]))
            c, sn = abs(math.cos(yaw)), abs(math.sin(yaw))
            hw = np.array([c * half[0] + sn * half[1], sn * half[0] + c * half[1]])
            best = ((shut, cover), FixtureSighting(look.name, np.array([centre[0], centre[1], ground + 0.5 * look.size_m[2]]),
                                                   yaw, np.array([half[0], half[1], 0.5 * look.size_m[2]]), hw,
                                                   look.size_m[2], int(foot.sum()), 1.0 - min(1.0, cover), "drawers"))
    return best[1] if best is not None else None


def _tall_cover(points: np.ndarray, heights: np.ndarray, look: FixtureLook, centre: np.ndarray, yaw: float,
                axis: np.ndarray, turn: float = 0.0) -> float:
    """Fraction of the footprint cells (:data:`KNOB_SEARCH_GRID_M`) of a body of ``look`` at
    ``centre`` turned by ``yaw``, away from its place patch and its knob at ``axis``, holding a
    point higher than the look's top plus 2 cm: a taller thing, not this fixture."""
    half = 0.5 * np.asarray(look.size_m[:2], float)
    tall = heights > look.size_m[2] + 0.02
    xy = points[tall, :2]
    keep = np.all(np.abs(_in_frame(xy, centre, yaw)) <= half, axis=1)
    keep &= np.linalg.norm(xy - axis, axis=1) > KNOB_RADIUS_M
    if look.place_offset_m is not None and look.place_half_m is not None:
        patch, patch_half, _ = look.place_patch(centre, np.zeros(2), turn)
        keep &= ~np.all(np.abs(xy - patch) <= patch_half, axis=1)
    return _grid_fraction(xy[keep], half)


def _in_frame(xy: np.ndarray, centre: np.ndarray, yaw: float) -> np.ndarray:
    """``xy`` (N, 2) world m in the frame of a footprint centred at ``centre`` turned by ``yaw``."""
    c, s = math.cos(yaw), math.sin(yaw)
    d = np.asarray(xy, float) - centre
    return np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]])


def _which_way(points: np.ndarray, heights: np.ndarray, look: FixtureLook, centre: np.ndarray) -> float | None:
    """Which way round (a turn of :data:`TURNS`, rad) a body of ``look``'s size centred at
    ``centre`` stands, judged by its place patch (:func:`patch_cover`) and its knob; None when
    neither way fits. A way fits when its place patch is covered (:data:`PATCH_COVER`) and,
    for a look with a knob, no non-bar stands where its knob would be (fewer than
    :data:`KNOB_SEEN_POINTS` points there -- the arm hides the knob -- do not count against
    it); a way other than the look's own (turn 0) only where the knob is read there (a place
    patch alone does not tell a fixture's ends apart). Of the ways that fit, one where the knob
    is read wins, then the better covered patch, then the look's own."""
    best: tuple[tuple[bool, float, bool], float] | None = None
    for turn in TURNS:
        cover = patch_cover(points, heights, look, centre, turn)
        if cover < PATCH_COVER:
            continue
        read = False
        if look.knob is not None:
            read = knob_reading(points, heights, look.knob, centre, turn) is not None
            if not read and int(knob_band(points, heights, look.knob, centre, turn).sum()) >= KNOB_SEEN_POINTS:
                continue
        if turn != 0.0 and not read:
            continue  # the other way round only on the evidence of its knob read there
        rank = (read, cover, turn == 0.0)
        if best is None or rank > best[0]:
            best = (rank, turn)
    return None if best is None else best[1]


def detect_fixtures(cloud: Cloud, heights: np.ndarray, looks: Sequence[FixtureLook],
                    config: PerceptionConfig) -> dict[str, FixtureSighting]:
    """``{fixture name: sighting}`` of the declared fixtures found in ``cloud`` (world m,
    every height up to the raised crop) with ``heights`` ((N,) m above the support plane);
    see the module docstring. A candidate body is one segment or the union of two adjacent
    ones (a fixture whose parts differ in colour -- the stove's knobs and its burner -- may
    come out as two segments); the candidates a fixture takes share no segment. A fixture
    with a ``knob`` is not taken where something other than a bar stands at the knob's offset
    from the candidate's centre (:func:`knob_reading`; fewer than :data:`KNOB_SEEN_POINTS`
    seen there -- the arm hides the knob -- do not count against it), and a fixture with a
    place patch only where that patch is covered (:func:`patch_cover`), either way round
    (:func:`_which_way`, :data:`TURNS`); one with a knob that no candidate fits is looked for
    by its knob (:func:`find_by_knob`).

    The fixtures still missing are looked for again in what the found ones leave (their
    footprints and model boxes grown by :data:`CLAIMED_EDGE_M`, at every height, taken out
    and the rest segmented anew): a fixture standing against another can come out in one
    segment with it (libero_goal's wine rack against the cabinet, 54 cm across in one dark
    segment, at inits 5 and 9 of task 9)."""
    if not looks:
        return {}
    out = _found(cloud, heights, looks, config)
    missing = [look for look in looks if look.name not in out]
    if not out or not missing:
        return out
    by_name = {look.name: look for look in looks}
    xy = cloud.points[:, :2]
    claimed = np.zeros(len(xy), dtype=bool)
    for name, s in out.items():
        claimed |= np.all(np.abs(_in_frame(xy, s.position[:2], s.yaw)) <= s.half_extents[:2] + CLAIMED_EDGE_M, axis=1)
        claimed |= by_name[name].in_model(xy, s, edge_m=CLAIMED_EDGE_M)
    if claimed.any() and not claimed.all():
        out.update(_found(cloud.select(~claimed), heights[~claimed], missing, config))
    return out


def _found(cloud: Cloud, heights: np.ndarray, looks: Sequence[FixtureLook],
           config: PerceptionConfig) -> dict[str, FixtureSighting]:
    """One pass of :func:`detect_fixtures` over ``cloud``'s segments."""
    points = cloud.points
    segs = segments(cloud, config)
    cands: list[tuple[frozenset[int], np.ndarray]] = [(frozenset([i]), idx) for i, idx in enumerate(segs)]
    for i in range(len(segs)):
        for j in range(i + 1, len(segs)):
            if _adjacent(segs[i], segs[j], points):
                cands.append((frozenset([i, j]), np.concatenate([segs[i], segs[j]])))
    fits: list[tuple[float, frozenset[int], FixtureSighting]] = []
    for parts, idx in cands:
        whole = _body(points, heights, idx)
        for look in looks:
            body = (_without_drawers(points, heights, idx, look) if look.drawers
                    else without_door(points, heights, idx) if look.door is not None else whole)
            if body is None:
                continue
            seen = (2.0 * float(body.half_extents[0]), 2.0 * float(body.half_extents[1]), body.top_m)
            errs = [abs(a - b) / (SIZE_TOL_FRACTION * b + SIZE_TOL_M) for a, b in zip(seen, look.size_m)]
            if max(errs) > 1.0:
                continue
            turn = _which_way(points, heights, look, body.position[:2])
            if turn is None:
                continue
            fits.append((float(sum(errs)), parts, replace(body, name=look.name, error=float(sum(errs)), turn=turn)))
    out: dict[str, FixtureSighting] = {}
    used: set[int] = set()
    for _, parts, sighting in sorted(fits, key=lambda f: f[0]):
        if sighting.name in out or parts & used:
            continue
        out[sighting.name] = sighting
        used |= parts
    for look in looks:  # a fixture with a knob or drawers that no segment fits: found by them
        if look.name not in out and (look.knob is not None or look.drawers):
            found = (find_by_knob(points, heights, look) if look.knob is not None
                     else find_by_drawers(points, heights, look))
            if found is not None:
                out[look.name] = found
    return out
