"""How alike the object a memory item was learned on is to a session's object: the
similarity that scopes lessons, knowledge and procedures (issue 29, part 3).

An item applies to a session only where it was learned on the same embodiment and skill,
and on an object that is the same thing as far as the robot can tell:

- **category**: where either side's object has a class the user declared (``mug``, or a
  LIBERO category such as ``cream_cheese``), both must declare the same one. A lesson
  learned on the cream cheese is never applied to the butter, whatever their sizes;
- **shape**: the shape classes (perceived, else declared: box | cylinder | sphere | mesh)
  must agree where both are known (``unknown`` agrees with anything);
- **size**: the (3,) full extents in m (perceived, else declared), the two horizontal ones
  sorted so that a turned object compares equal, give the score
  ``exp(-z**2 / 2)`` with ``z = max_i |a_i - b_i| / (SIZE_REL_SIGMA * max(a_i, b_i) + SIZE_ABS_SIGMA)``;
- **situation**: the item's situational risk factors (:data:`SITUATIONAL_RISKS`: clutter, a
  slip seen earlier, a heavy load) must all hold in the session. The geometric ones
  (small, large, round) follow from the size and shape compared above and are not compared
  again.

The similarity is the size score (1.0 for the same extents), 0.0 when any rule above fails;
an item is retrieved at :data:`MIN_SIMILARITY` or more. Colour is left out: the same
category's mean colour moves with the light (LIBERO's black bowl reads 0.71 in one scene
class and 0.55 in another), while its size does not.

Where either side has no size (an item written before this scheme, or an object declared
without one), the rule is the older exact one (:func:`~.conditions.scope_matches`): equal
object class, the item's risk factors a subset of the session's.

Constants: the size tolerance covers how much perceived extents of one category differ
between scenes, from the LIBERO looks the perceiver measured on generated scenes of each
suite (22 categories measured in two or more of 17 bench workspaces, 2026-11-25):
horizontal extents agree within 15 % (alphabet soup 6.79-6.82 cm, milk 4.3-5.0 cm),
heights within 1.2 cm (cream cheese 1.95-3.1 cm: the box's top reads differently against
different tables). Every category scores 0.68 or more against its own looks in other
scenes; a 4 cm and an 8 cm cube score 0.08. Geometry alone cannot keep categories apart
(cream cheese against butter: 0.96), hence the category rule.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

from .conditions import Conditions, migrate_scope, scope_matches

__all__ = ["ObjectProfile", "profile", "similarity", "MIN_SIMILARITY", "SIZE_REL_SIGMA", "SIZE_ABS_SIGMA",
           "SITUATIONAL_RISKS"]

#: Relative part of the 1-sigma size tolerance per extent (see the module docstring).
SIZE_REL_SIGMA = 0.10
#: Absolute part of the 1-sigma size tolerance per extent, m (see the module docstring).
SIZE_ABS_SIGMA = 0.01
#: An item is retrieved at this similarity or more (z <= 1.18 on the worst extent).
MIN_SIMILARITY = 0.5
#: Risk factors that describe the situation rather than the object's geometry.
SITUATIONAL_RISKS = frozenset({"clutter", "slipped_before", "heavy_object"})


@dataclass(frozen=True)
class ObjectProfile:
    """What a scope or a session's conditions say about the object, for comparing.

    Attributes:
        embodiment, skill: where and by what the item was learned.
        object_class: declared class, else ``<shape>-<size band>``.
        category: the declared class, or ``None`` when the user declared none.
        shape: box | cylinder | sphere | mesh, or ``None`` when unknown.
        size_m: (3,) full extents in m, the horizontal two sorted, or ``None``.
        risk_factors: all risk factors recorded.
    """

    embodiment: str | None
    skill: str | None
    object_class: str | None
    category: str | None
    shape: str | None
    size_m: tuple[float, float, float] | None
    risk_factors: frozenset[str]


def _size(value: Any) -> tuple[float, float, float] | None:
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        return None
    try:
        sx, sy, sz = (float(v) for v in value)
    except (TypeError, ValueError):
        return None
    if min(sx, sy, sz) <= 0.0 or not all(math.isfinite(v) for v in (sx, sy, sz)):
        return None
    a, b = sorted((sx, sy))
    return (a, b, sz)


def profile(item: Mapping[str, Any]) -> ObjectProfile:
    """The :class:`ObjectProfile` of a lesson's ``scope`` (``category``, ``shape`` and
    ``size_m`` at its top level, see :meth:`Conditions.scope`) or of a knowledge entry's or
    procedure's ``conditions`` (the same inside ``object_properties``). Never raises."""
    item = migrate_scope(item)
    raw = item.get("object_properties")
    props: Mapping[str, Any] = raw if isinstance(raw, Mapping) else {}
    category = item.get("category", props.get("class"))
    shape = item.get("shape", props.get("shape"))
    return ObjectProfile(
        embodiment=item.get("embodiment"), skill=item.get("skill"), object_class=item.get("object_class"),
        category=category if isinstance(category, str) else None,
        shape=shape if isinstance(shape, str) and shape != "unknown" else None,
        size_m=_size(item.get("size_m", props.get("size_m"))),
        risk_factors=frozenset(item.get("risk_factors") or ()))


def similarity(item: Mapping[str, Any], conditions: Conditions) -> float:
    """How far a memory item learned under ``item`` (a lesson's scope, a knowledge entry's
    or procedure's conditions) applies under ``conditions``: 0.0 (not at all) to 1.0 (the
    same object in the same situation). See the module docstring for the rules."""
    mine, theirs = profile(item), profile(conditions.scope())
    if mine.embodiment != theirs.embodiment or mine.skill != theirs.skill:
        return 0.0
    if mine.size_m is None or theirs.size_m is None:
        return 1.0 if scope_matches(item, conditions) else 0.0
    if not (mine.risk_factors & SITUATIONAL_RISKS) <= theirs.risk_factors:
        return 0.0
    if (mine.category is not None or theirs.category is not None) and mine.category != theirs.category:
        return 0.0
    if mine.shape is not None and theirs.shape is not None and mine.shape != theirs.shape:
        return 0.0
    z = max(abs(a - b) / (SIZE_REL_SIGMA * max(a, b) + SIZE_ABS_SIGMA) for a, b in zip(mine.size_m, theirs.size_m))
    return math.exp(-0.5 * z * z)
