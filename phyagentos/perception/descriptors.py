"""Declared object descriptors: what the user said an object looks like (never its pose).

CONTRACT_9 section 3: ``name``, optional ``class``, ``shape`` (box | cylinder | sphere),
``colour`` (a name or an sRGB triple in [0, 1]) and an approximate ``size_m``. ``size_m`` is
the object's *full* dimensions in metres: three numbers (x, y, z: edge lengths; diameter for
round footprints; the order of x and y does not matter) or one number (its largest
dimension). This matches ``MuJoCoArmTarget.describe_declared`` (``2 * half_extents``).

A look measured from many sightings (LIBERO's, :mod:`phyagentos.targets.libero.descriptors`)
may also say how it varies with the view: ``size_range_m`` (the smallest and the largest full
size it was seen with: a carton seen face-on measures 3 cm deep, seen at 45 degrees 5 cm) and
``shapes`` (the fraction of sightings classified as each shape: a carton's gable top reads as a
cylinder one time in five). Association then costs a size within the range nothing and a shape
by how rarely it was seen (:mod:`phyagentos.perception.association`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from phyagentos.errors import format_choices
from phyagentos.perception.errors import PerceptionError

__all__ = ["ObjectDescriptor", "SpatialReference", "SHAPES", "COLOUR_NAMES", "WHERE_RELATIONS",
           "MAX_HANDLE_ORIGIN_M", "descriptors_from_declared"]

#: The largest ``handle_origin_m`` a descriptor may give, m: an object's origin half a table's
#: reach off its body is a mistake in the look, not a handle.
MAX_HANDLE_ORIGIN_M = 0.1

SHAPES: tuple[str, ...] = ("box", "cylinder", "sphere")

#: Relations a :class:`SpatialReference` may use, with how many landmarks each names.
WHERE_RELATIONS: dict[str, int] = {"between": 2, "next_to": 1, "on": 1, "in": 1, "table_center": 0, "left": 0,
                                   "right": 0, "front": 0, "back": 0, "middle": 0}


@dataclass(frozen=True)
class SpatialReference:
    """Which of several identical declared objects is meant, by a spatial relation to other
    declared things (``the black bowl next to the ramekin``): ``SpatialReference(relation,
    of=(), part=None)``.

    Attributes:
        relation: one of :data:`WHERE_RELATIONS`: ``between`` two landmarks (nearest the
            segment joining their centres), ``next_to`` one (nearest it), ``on`` one (over its
            footprint and raised off the table), ``in`` one (within its footprint; raised off
            the table when the landmark is not perceived), ``table_center`` (nearest the centre
            of the perceived table top; no landmark), ``left`` / ``right`` (furthest to the
            viewer's left / right, as the scene camera sees the table: the plate on the left;
            no landmark), ``front`` / ``back`` (nearest the viewer / furthest from it across
            the table: the black bowl at the front; no landmark), ``middle`` (of three or more
            look-alikes, the one whose furthest fellow is nearest: the middle black bowl; no
            landmark).
        of: the landmarks' declared names (objects or fixtures), as many as the relation takes.
        part: the part of the landmark meant (``top drawer``): a drawer narrows ``in`` to that
            drawer's inside (:func:`~.association.part_landmark`); a level that is no drawer
            (``top shelf``) leaves the reference unresolved; other parts are informative.

    Raises:
        PerceptionError: an unknown relation (the valid ones listed), the wrong number of
            landmarks, a landmark name that is not a non-empty string.
    """

    relation: str
    of: tuple[str, ...] = ()
    part: str | None = None

    def __post_init__(self) -> None:
        if self.relation not in WHERE_RELATIONS:
            raise PerceptionError(f"spatial reference: relation {self.relation!r} is not one of "
                                  f"{format_choices(WHERE_RELATIONS)}")
        of = (self.of,) if isinstance(self.of, str) else tuple(self.of or ())
        if not all(isinstance(n, str) and n for n in of):
            raise PerceptionError(f"spatial reference: landmarks must be declared names, got {self.of!r}")
        want = WHERE_RELATIONS[self.relation]
        if len(of) != want:
            raise PerceptionError(f"spatial reference: {self.relation!r} takes {want} landmark(s), got {len(of)}: "
                                  f"{list(of)}")
        if self.part is not None and not isinstance(self.part, str):
            raise PerceptionError(f"spatial reference: part must be text, got {self.part!r}")
        object.__setattr__(self, "of", of)

    @classmethod
    def from_value(cls, value: "SpatialReference | Mapping[str, Any]") -> "SpatialReference":
        """From a mapping ``{relation, of?, part?}`` (as a scene declares it) or a reference.

        Raises:
            PerceptionError: not a mapping, an unknown key (the valid ones listed), a bad value.
        """
        if isinstance(value, SpatialReference):
            return value
        if not isinstance(value, Mapping):
            raise PerceptionError(f"spatial reference must be a mapping {{relation, of, part}}, got {value!r}")
        unknown = set(value) - {"relation", "of", "part"}
        if unknown:
            raise PerceptionError(f"spatial reference: unknown key(s) {format_choices(unknown)}; valid keys: "
                                  f"{format_choices(('relation', 'of', 'part'))}")
        return cls(relation=value.get("relation"), of=tuple(value.get("of") or ()), part=value.get("part"))

    def to_dict(self) -> dict[str, Any]:
        """Plain data (the inverse of :meth:`from_value`)."""
        out: dict[str, Any] = {"relation": self.relation}
        if self.of:
            out["of"] = list(self.of)
        if self.part:
            out["part"] = self.part
        return out

#: sRGB in [0, 1] of the colour names a descriptor may use (CSS basic colours, with
#: "orange", "purple", "cyan" and "grey" at their common CSS values).
COLOUR_NAMES: dict[str, tuple[float, float, float]] = {
    "red": (0.85, 0.15, 0.12),
    "green": (0.15, 0.70, 0.25),
    "blue": (0.15, 0.35, 0.85),
    "yellow": (0.95, 0.80, 0.10),
    "orange": (0.95, 0.50, 0.10),
    "purple": (0.60, 0.20, 0.75),
    "cyan": (0.10, 0.75, 0.80),
    "white": (0.95, 0.95, 0.95),
    "black": (0.08, 0.08, 0.08),
    "grey": (0.50, 0.50, 0.50),
    "gray": (0.50, 0.50, 0.50),
}


@dataclass(frozen=True)
class ObjectDescriptor:
    """A declared object: ``ObjectDescriptor(name, cls=None, shape=None, colour_rgb=None, size_m=None)``.

    Attributes:
        name: the object's declared name (becomes the entity name when associated).
        cls: the user's object class ("mug"), informative only.
        shape: ``box`` | ``cylinder`` | ``sphere`` or None. A declared ``mesh`` (a scene
            object shaped by a mesh file) becomes None: the detector classifies only the
            primitives, so a mesh object is matched by colour and size (its bounding box).
        colour_rgb: sRGB in [0, 1] (a colour name from :data:`COLOUR_NAMES` is converted).
        size_m: full dimensions, m: ``(x, y, z)`` or a float (largest dimension).
        where: which of several identical declared objects this one is, by a spatial relation
            (:class:`SpatialReference`; a mapping is converted), or None. Association resolves
            it on the perceived positions of its landmarks until the object has a track.
        size_range_m: ``((long, short, height) smallest, (long, short, height) largest)`` full
            size seen, m, or None; needs ``size_m`` (3 numbers) within it.
        shapes: ``{shape: fraction of sightings}`` (fractions in [0, 1], summing to at most 1),
            or None; when given it prices a shape instead of ``shape``. Kept as sorted
            ``(shape, fraction)`` pairs (the descriptor stays hashable).
        handle_origin_m: for an object with a handle (a mug), how far its model's origin -- the
            point its pose names, the one a task's checker measures -- lies from its round
            body's axis towards the handle, m (>= 0), or None. Perception then reports where
            that point is (``origin_xy``, :mod:`phyagentos.perception.handle`).

    Raises:
        PerceptionError: empty name, unknown shape or colour name, values out of range, a
            malformed ``where`` or one naming the object itself as its landmark.
    """

    name: str
    cls: str | None = None
    shape: str | None = None
    colour_rgb: tuple[float, float, float] | None = None
    size_m: tuple[float, float, float] | float | None = None
    where: SpatialReference | None = None
    size_range_m: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None
    shapes: Mapping[str, float] | tuple[tuple[str, float], ...] | None = None
    handle_origin_m: float | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise PerceptionError(f"object descriptor name must be a non-empty string, got {self.name!r}")
        where = f"object {self.name!r}"
        if self.name.startswith("unknown_"):
            raise PerceptionError(f"{where}: names starting with 'unknown_' are reserved for unassociated clusters")
        if self.shape == "mesh":
            object.__setattr__(self, "shape", None)
        if self.shape is not None and self.shape not in SHAPES:
            raise PerceptionError(f"{where}: shape {self.shape!r} is not one of {format_choices(SHAPES)}")
        c = self.colour_rgb
        if isinstance(c, str):
            if c.lower() not in COLOUR_NAMES:
                raise PerceptionError(f"{where}: colour {c!r} is not one of {format_choices(COLOUR_NAMES)}")
            object.__setattr__(self, "colour_rgb", COLOUR_NAMES[c.lower()])
        elif c is not None:
            try:
                rgb = tuple(float(v) for v in c)
            except (TypeError, ValueError):
                raise PerceptionError(f"{where}: colour_rgb must be 3 numbers in [0, 1] or a name, got {c!r}") from None
            if len(rgb) == 4:
                rgb = rgb[:3]  # rgba: drop alpha
            if len(rgb) != 3 or not all(0.0 <= v <= 1.0 for v in rgb):
                raise PerceptionError(f"{where}: colour_rgb must be 3 numbers in [0, 1], got {c!r}")
            object.__setattr__(self, "colour_rgb", rgb)
        s = self.size_m
        if s is not None:
            if isinstance(s, (int, float)) and not isinstance(s, bool):
                vals: tuple[float, ...] = (float(s),)
            else:
                try:
                    vals = tuple(float(v) for v in s)
                except (TypeError, ValueError):
                    raise PerceptionError(f"{where}: size_m must be a number or 3 numbers (m), got {s!r}") from None
                if len(vals) != 3:
                    raise PerceptionError(f"{where}: size_m must have 3 numbers (x, y, z full size, m), got {s!r}")
            if not all(math.isfinite(v) and v > 0 for v in vals):
                raise PerceptionError(f"{where}: size_m must be > 0 and finite, got {s!r}")
            object.__setattr__(self, "size_m", vals[0] if len(vals) == 1 else vals)
        if self.where is not None:
            try:
                ref = SpatialReference.from_value(self.where)  # type: ignore[arg-type]
            except PerceptionError as exc:
                raise PerceptionError(f"{where}: {exc}") from None
            if self.name in ref.of:
                raise PerceptionError(f"{where}: its spatial reference names the object itself as a landmark")
            object.__setattr__(self, "where", ref)
        self._check_spread(where)
        h = self.handle_origin_m
        if h is not None:
            try:
                h = float(h)
            except (TypeError, ValueError):
                raise PerceptionError(f"{where}: handle_origin_m must be a number (m), got {self.handle_origin_m!r}") from None
            if not (math.isfinite(h) and 0.0 <= h <= MAX_HANDLE_ORIGIN_M):
                raise PerceptionError(f"{where}: handle_origin_m must be in [0, {MAX_HANDLE_ORIGIN_M}] m, got {h!r}")
            object.__setattr__(self, "handle_origin_m", h)

    def _check_spread(self, where: str) -> None:
        """Validate and normalise ``size_range_m`` and ``shapes``."""
        r = self.size_range_m
        if r is not None:
            try:
                lo, hi = (tuple(float(v) for v in row) for row in r)
            except (TypeError, ValueError):
                raise PerceptionError(f"{where}: size_range_m must be two rows of 3 numbers (smallest, largest "
                                      f"full size, m), got {r!r}") from None
            want = self.size_vector()
            if len(lo) != 3 or len(hi) != 3 or not all(math.isfinite(v) and v > 0 for v in lo + hi):
                raise PerceptionError(f"{where}: size_range_m must be two rows of 3 positive numbers (m), got {r!r}")
            if want is None or not all(a - 1e-9 <= w <= b + 1e-9 for a, w, b in zip(lo, want, hi)):
                raise PerceptionError(f"{where}: size_range_m {r!r} must hold size_m (3 numbers, sorted long, "
                                      f"short, height: {None if want is None else want.tolist()})")
            object.__setattr__(self, "size_range_m", (lo, hi))
        sh = self.shapes
        if sh is not None:
            if not isinstance(sh, Mapping) or not sh:
                raise PerceptionError(f"{where}: shapes must be a mapping {{shape: fraction}}, got {sh!r}")
            unknown = set(sh) - set(SHAPES)
            if unknown:
                raise PerceptionError(f"{where}: shapes: {format_choices(unknown)} not one of {format_choices(SHAPES)}")
            try:
                fr = {k: float(v) for k, v in sh.items()}
            except (TypeError, ValueError):
                raise PerceptionError(f"{where}: shapes: fractions must be numbers, got {sh!r}") from None
            if not all(0.0 <= v <= 1.0 for v in fr.values()) or sum(fr.values()) > 1.0 + 0.01:  # fractions rounded to 3 places
                raise PerceptionError(f"{where}: shapes: fractions must lie in [0, 1] and sum to at most 1, got {sh!r}")
            object.__setattr__(self, "shapes", tuple(sorted(fr.items())))  # hashable, as the descriptor is

    def shape_mismatch(self, shape: str) -> float | None:
        """How much a detection classified ``shape`` disagrees with this look, 0..1: with
        ``shapes``, ``1 -`` its fraction over the most frequent shape's (the look's usual shape
        costs nothing, one never seen as much as a plain mismatch); else 1 for a shape other
        than ``shape``, 0 for the same; None when no shape is declared."""
        if self.shapes is not None:
            fractions = dict(self.shapes)
            most = max(fractions.values())
            return 1.0 - float(fractions.get(shape, 0.0)) / most if most > 0 else 0.0
        if self.shape is None:
            return None
        return 0.0 if shape == self.shape else 1.0

    def size_error(self, measured: np.ndarray, *, at_least: bool | Sequence[bool] = False) -> float | None:
        """Mean absolute error (m) of ``measured`` (3,) full size sorted (long, short,
        height) against the declared size: outside ``size_range_m`` when given (0 within it),
        else against ``size_m``; None without a 3-number size. ``at_least``: ``measured``
        is a lower bound (an object seen in part, cut by the image border): only a measured
        size above the declared one counts; a (3,) mask: so for those dimensions only (the
        lower part of a stack, covered by what rests on it: its footprint, not its height)."""
        want = self.size_vector()
        if want is None:
            return None
        m = np.asarray(measured, float)
        lower = np.broadcast_to(np.asarray(at_least, dtype=bool), m.shape)
        if self.size_range_m is not None:
            lo, hi = (np.asarray(v, float) for v in self.size_range_m)
            under = np.where(lower, 0.0, lo - m)
            return float(np.mean(np.maximum(0.0, np.maximum(under, m - hi))))
        return float(np.mean(np.where(lower, np.maximum(0.0, m - want), np.abs(m - want))))

    def looks_like(self, other: "ObjectDescriptor") -> bool:
        """Same declared look (class, shape, colour, size): association cannot tell the two apart."""
        return (self.cls, self.shape, self.colour_rgb, self.size_m, self.size_range_m, self.shapes) == (
            other.cls, other.shape, other.colour_rgb, other.size_m, other.size_range_m, other.shapes)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "ObjectDescriptor":
        """From a declared-object mapping (keys ``name``, ``class``, ``shape``, ``colour`` or
        ``colour_rgb``, ``size_m``, ``where``, ``size_range_m``, ``shapes``, ``handle_origin_m``; other keys such
        as ``mass`` are rejected: never declared).

        Raises:
            PerceptionError: not a mapping, an unknown key, or a bad value.
        """
        if not isinstance(d, Mapping):
            raise PerceptionError(f"a declared object must be a mapping, got {type(d).__name__}")
        valid = {"name", "class", "cls", "shape", "colour", "colour_rgb", "color", "color_rgb", "size_m", "where",
                 "size_range_m", "shapes", "handle_origin_m"}
        unknown = set(d) - valid
        if unknown:
            raise PerceptionError(
                f"declared object {d.get('name')!r}: unknown key(s) {format_choices(unknown)}; "
                f"valid keys: {format_choices(valid)}"
            )
        colour = next((d[k] for k in ("colour_rgb", "colour", "color_rgb", "color") if d.get(k) is not None), None)
        return cls(name=d.get("name"), cls=d.get("class", d.get("cls")), shape=d.get("shape"),
                   colour_rgb=colour, size_m=d.get("size_m"), where=d.get("where"),
                   size_range_m=d.get("size_range_m"), shapes=d.get("shapes"), handle_origin_m=d.get("handle_origin_m"))

    def size_vector(self) -> np.ndarray | None:
        """(3,) full size sorted as (long horizontal, short horizontal, height), or None."""
        if self.size_m is None or isinstance(self.size_m, float):
            return None
        x, y, z = self.size_m
        return np.array([max(x, y), min(x, y), z])


def descriptors_from_declared(declared: Mapping[str, Any] | Sequence[Any]) -> list[ObjectDescriptor]:
    """Descriptors from ``describe_declared()``'s ``{"objects": [...]}`` or a list of mappings
    / descriptors.

    Raises:
        PerceptionError: malformed entries or duplicate names.
    """
    items = declared.get("objects", []) if isinstance(declared, Mapping) else declared
    out = [o if isinstance(o, ObjectDescriptor) else ObjectDescriptor.from_dict(o) for o in items]
    names = [o.name for o in out]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise PerceptionError(f"declared object name(s) used twice: {dup}")
    return out
