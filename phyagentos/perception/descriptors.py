"""Declared object descriptors: what the user said an object looks like (never its pose).

CONTRACT_9 section 3: ``name``, optional ``class``, ``shape`` (box | cylinder | sphere),
``colour`` (a name or an sRGB triple in [0, 1]) and an approximate ``size_m``. ``size_m`` is
the object's *full* dimensions in metres: three numbers (x, y, z: edge lengths; diameter for
round footprints; the order of x and y does not matter) or one number (its largest
dimension). This matches ``MuJoCoArmTarget.describe_declared`` (``2 * half_extents``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from phyagentos.errors import format_choices
from phyagentos.perception.errors import PerceptionError

__all__ = ["ObjectDescriptor", "SHAPES", "COLOUR_NAMES", "descriptors_from_declared"]

SHAPES: tuple[str, ...] = ("box", "cylinder", "sphere")

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

    Raises:
        PerceptionError: empty name, unknown shape or colour name, values out of range.
    """

    name: str
    cls: str | None = None
    shape: str | None = None
    colour_rgb: tuple[float, float, float] | None = None
    size_m: tuple[float, float, float] | float | None = None

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

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "ObjectDescriptor":
        """From a declared-object mapping (keys ``name``, ``class``, ``shape``, ``colour`` or
        ``colour_rgb``, ``size_m``; other keys such as ``mass`` are rejected: never declared).

        Raises:
            PerceptionError: not a mapping, an unknown key, or a bad value.
        """
        if not isinstance(d, Mapping):
            raise PerceptionError(f"a declared object must be a mapping, got {type(d).__name__}")
        valid = {"name", "class", "cls", "shape", "colour", "colour_rgb", "color", "color_rgb", "size_m"}
        unknown = set(d) - valid
        if unknown:
            raise PerceptionError(
                f"declared object {d.get('name')!r}: unknown key(s) {format_choices(unknown)}; "
                f"valid keys: {format_choices(valid)}"
            )
        colour = next((d[k] for k in ("colour_rgb", "colour", "color_rgb", "color") if d.get(k) is not None), None)
        return cls(name=d.get("name"), cls=d.get("class", d.get("cls")), shape=d.get("shape"),
                   colour_rgb=colour, size_m=d.get("size_m"))

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
