"""Geom kinds for contact classification and small conversions the arm's parts share."""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["K_NONE", "K_ENV", "K_ROBOT", "K_FINGER", "K_OBJECT", "floats"]

#: Kinds of geoms, for classifying contacts: none, environment (table, walls), robot links,
#: fingers, objects.
K_NONE, K_ENV, K_ROBOT, K_FINGER, K_OBJECT = 0, 1, 2, 3, 4


def floats(v: Any) -> list[float]:
    """``v`` (any array-like) flattened to plain floats."""
    return [float(x) for x in np.asarray(v, dtype=float).reshape(-1)]
