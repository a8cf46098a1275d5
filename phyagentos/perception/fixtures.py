"""Fixtures: large declared things (a cabinet, a stove, a rack) perceived by their measured look.

A fixture is declared like an object (``{name, class}``) plus its *look*, measured on the
fixture's model (never on a scene an Agent is judged on): ``size_m`` -- the full extents of
its perceived body, ``[long side, short side, height of its top above the support]``, m --
and optionally ``place`` -- where on it things are set down, relative to the perceived body:
``{offset_m: [dx, dy] (world frame, from the body's footprint centre to the place patch's
centre), half_extents_m: [hx, hy] (world axes), height_m: the patch's surface above the
support}``. Without ``place`` the body's top is the place patch.

:func:`detect_fixtures` finds them in the object cloud (all heights up to the raised crop),
segmented by the perceiver's own clustering (position and colour,
:func:`~phyagentos.perception.detect.cluster`), each segment's footprint the minimum-area
rectangle of its points and its top the :data:`TOP_PERCENTILE` th percentile of their
heights; a segment is a fixture when its footprint sides and top each lie within
:data:`SIZE_TOL_FRACTION` (plus :data:`SIZE_TOL_M`) of the look; a candidate is one segment
or two adjacent ones (:data:`JOIN_GAP_M`: a fixture whose parts differ in colour); each
fixture takes the best fitting candidate (sum of relative size errors), no segment going to
two fixtures. A fixture merged with something else into one larger segment (LIBERO's cabinet
with the wine rack beside it, in some generated scenes) does not fit: it is not seen in that
observation (the perceiver keeps a fixture where it was once seen: fixtures do not move).

Nothing here reads a simulator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Mapping, Sequence

import numpy as np

from phyagentos.errors import format_choices
from phyagentos.perception.cloud import Cloud
from phyagentos.perception.config import PerceptionConfig
from phyagentos.perception.detect import _rect, cluster
from phyagentos.perception.errors import PerceptionError

__all__ = ["FixtureLook", "FixtureSighting", "fixtures_from_declared", "segments", "bodies", "detect_fixtures", "JOIN_GAP_M",
           "SIZE_TOL_FRACTION", "SIZE_TOL_M", "TOP_PERCENTILE", "MIN_POINTS"]

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


@dataclass(frozen=True)
class FixtureLook:
    """A declared fixture with its measured look (module docstring); lengths in m."""

    name: str
    cls: str | None
    size_m: tuple[float, float, float]
    place_offset_m: tuple[float, float] | None = None
    place_half_m: tuple[float, float] | None = None
    place_height_m: float | None = None

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "FixtureLook | None":
        """From a declared fixture ``{name, class, size_m?, place?}``; ``None`` when it has no
        look (``size_m``): such a fixture is not perceived.

        Raises:
            PerceptionError: an unknown key (the valid ones listed) or a malformed value.
        """
        if not isinstance(d, Mapping):
            raise PerceptionError(f"a declared fixture must be a mapping, got {type(d).__name__}")
        valid = ("name", "class", "size_m", "place")
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
        place = d.get("place")
        if place is None:
            return cls(name, d.get("class"), size)
        if not isinstance(place, Mapping) or set(place) != {"offset_m", "half_extents_m", "height_m"}:
            raise PerceptionError(f"fixture {name!r}: place must be a mapping with keys "
                                  f"{format_choices(('offset_m', 'half_extents_m', 'height_m'))}, got {place!r}")
        off = _floats(place["offset_m"], 2, f"fixture {name!r}: place.offset_m")
        half = _floats(place["half_extents_m"], 2, f"fixture {name!r}: place.half_extents_m")
        height = _floats([place["height_m"]], 1, f"fixture {name!r}: place.height_m")[0]
        if min(half) <= 0 or height < 0:
            raise PerceptionError(f"fixture {name!r}: place.half_extents_m must be > 0 and height_m >= 0, got {place!r}")
        return cls(name, d.get("class"), size, off, half, height)  # type: ignore[arg-type]

    def place_patch(self, centre_xy: np.ndarray, half_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        """``(centre (2,), half extents (2,) on the world axes, surface height above the
        support)`` of the place patch of a body perceived at ``centre_xy`` with footprint half
        extents ``half_xy`` (world axes), m."""
        if self.place_offset_m is None:
            return np.asarray(centre_xy, float), np.asarray(half_xy, float), float(self.size_m[2])
        return (np.asarray(centre_xy, float) + np.asarray(self.place_offset_m), np.asarray(self.place_half_m, float),
                float(self.place_height_m or 0.0))


def _floats(value: Any, n: int, what: str) -> tuple[float, ...]:
    try:
        out = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise PerceptionError(f"{what} must be {n} numbers, got {value!r}") from None
    if len(out) != n or not all(math.isfinite(v) for v in out):
        raise PerceptionError(f"{what} must be {n} finite numbers, got {value!r}")
    return out


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
    support (m), the supporting coarse points and the relative size error of the fit."""

    name: str
    position: np.ndarray
    yaw: float
    half_extents: np.ndarray
    half_xy_world: np.ndarray
    top_m: float
    points: int
    error: float


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


def _adjacent(a: np.ndarray, b: np.ndarray, points: np.ndarray) -> bool:
    """Whether two segments' axis-aligned footprints overlap when grown by :data:`JOIN_GAP_M`."""
    lo_a, hi_a = points[a, :2].min(axis=0), points[a, :2].max(axis=0)
    lo_b, hi_b = points[b, :2].min(axis=0), points[b, :2].max(axis=0)
    return bool(np.all(lo_a - JOIN_GAP_M <= hi_b) and np.all(lo_b - JOIN_GAP_M <= hi_a))


def detect_fixtures(cloud: Cloud, heights: np.ndarray, looks: Sequence[FixtureLook],
                    config: PerceptionConfig) -> dict[str, FixtureSighting]:
    """``{fixture name: sighting}`` of the declared fixtures found in ``cloud`` (world m,
    every height up to the raised crop) with ``heights`` ((N,) m above the support plane);
    see the module docstring. A candidate body is one segment or the union of two adjacent
    ones (a fixture whose parts differ in colour -- the stove's knobs and its burner -- may
    come out as two segments); the candidates a fixture takes share no segment."""
    if not looks:
        return {}
    points = cloud.points
    segs = segments(cloud, config)
    cands: list[tuple[frozenset[int], np.ndarray]] = [(frozenset([i]), idx) for i, idx in enumerate(segs)]
    for i in range(len(segs)):
        for j in range(i + 1, len(segs)):
            if _adjacent(segs[i], segs[j], points):
                cands.append((frozenset([i, j]), np.concatenate([segs[i], segs[j]])))
    fits: list[tuple[float, frozenset[int], FixtureSighting]] = []
    for parts, idx in cands:
        body = _body(points, heights, idx)
        seen = (2.0 * float(body.half_extents[0]), 2.0 * float(body.half_extents[1]), body.top_m)
        for look in looks:
            errs = [abs(a - b) / (SIZE_TOL_FRACTION * b + SIZE_TOL_M) for a, b in zip(seen, look.size_m)]
            if max(errs) > 1.0:
                continue
            fits.append((float(sum(errs)), parts, replace(body, name=look.name, error=float(sum(errs)))))
    out: dict[str, FixtureSighting] = {}
    used: set[int] = set()
    for _, parts, sighting in sorted(fits, key=lambda f: f[0]):
        if sighting.name in out or parts & used:
            continue
        out[sighting.name] = sighting
        used |= parts
    return out
