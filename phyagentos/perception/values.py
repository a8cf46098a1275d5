"""Numbers read out of a declared look (a fixture's, its door's): the check every look's parser
shares."""

from __future__ import annotations

import math
from typing import Any

from phyagentos.perception.errors import PerceptionError

__all__ = ["finite_floats"]


def finite_floats(value: Any, n: int, what: str) -> tuple[float, ...]:
    """``value`` as ``n`` finite floats.

    Raises:
        PerceptionError: not ``n`` numbers, or one not finite (``what`` names the field).
    """
    try:
        out = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise PerceptionError(f"{what} must be {n} numbers, got {value!r}") from None
    if len(out) != n or not all(math.isfinite(v) for v in out):
        raise PerceptionError(f"{what} must be {n} finite numbers, got {value!r}")
    return out
