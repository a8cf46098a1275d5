"""LIBERO looks measured once and shipped with the package (``phyagentos/data/libero/looks.json``).

A LIBERO bench declares each object's and fixture's look (size, colour, shape; a fixture's
top, drawers, door) as a user would, measured by the project's perceiver on scenes of LIBERO's
placement sampler (never an init state): :func:`phyagentos.bench.libero._descriptors` and
:func:`phyagentos.bench.libero._fixture_looks`. Measuring costs about 15-25 s per world on
two CPU cores (a LIBERO world built and rendered on ten generated scenes), and every fresh
workspace paid it for every world of its suite. The measurement is deterministic (the same
sightings, run twice), so it is done once, by ``scripts/measure_libero_looks.py``, for the
worlds of LIBERO's five suites (``libero_spatial``, ``libero_object``, ``libero_goal``,
``libero_10``, ``libero_90``; LIBERO-PRO's swapped and reworded suites share their worlds) and
shipped. A world not shipped (LIBERO-PRO's replaced objects and distractors) is measured in
the workspace as before; ``phyagentos bench --measure-looks`` measures every world again
(another renderer, another asset version).

The file holds, per kind (``descriptors``: each world's sightings of its object categories;
``fixtures``: each world's fixture looks), the method it was measured by and its worlds, keyed
as the workspace caches key them. An entry of another method than the code's is never used.
Bench bookkeeping only (a Runtime-side calibration the bench writes into the goal graph, as a
user declares a scene); the Agent plane never reads it.
"""

from __future__ import annotations

import json
import logging
from functools import lru_cache
from pathlib import Path
from typing import Any, Literal

__all__ = ["SHIPPED_LOOKS", "Kind", "shipped_worlds"]

logger = logging.getLogger(__name__)

#: The shipped file (package data).
SHIPPED_LOOKS = Path(__file__).resolve().parent.parent / "data" / "libero" / "looks.json"

Kind = Literal["descriptors", "fixtures"]


@lru_cache(maxsize=4)
def _load(path: str, mtime_ns: int) -> dict[str, Any]:
    try:
        doc = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        logger.warning("LIBERO shipped looks %s unreadable (%s): every world is measured", path, exc)
        return {}
    return doc if isinstance(doc, dict) else {}


def shipped_worlds(kind: Kind, method: str, *, path: Path | None = None) -> dict[str, dict[str, Any]]:
    """The shipped worlds of ``kind`` measured by ``method``: ``{world key: entry}``, each
    entry as the workspace cache keeps it (``measured_as`` and ``sightings`` for
    descriptors, ``measured_as`` and ``looks`` for fixtures). Empty when the file is missing
    or unreadable (logged), or was measured by another method (the code's method changed
    and the file was not measured again: ``scripts/measure_libero_looks.py``).

    Args:
        kind: ``"descriptors"`` or ``"fixtures"``.
        method: the method the caller measures by (``_LOOKS_METHOD``, ``_FIXTURE_LOOKS_METHOD``).
        path: the file; default :data:`SHIPPED_LOOKS`.

    Raises:
        ValueError: ``kind`` is neither ``"descriptors"`` nor ``"fixtures"``.
    """
    if kind not in ("descriptors", "fixtures"):
        raise ValueError(f"unknown kind of looks {kind!r}; valid: 'descriptors', 'fixtures'")
    p = Path(path) if path is not None else SHIPPED_LOOKS
    try:
        mtime = p.stat().st_mtime_ns
    except OSError:
        return {}
    part = _load(str(p), mtime).get(kind) or {}
    if part.get("method") != method:
        if part:
            logger.warning("LIBERO shipped %s looks were measured by %r, the code measures by %r: not used",
                           kind, part.get("method"), method)
        return {}
    worlds = part.get("worlds")
    return dict(worlds) if isinstance(worlds, dict) else {}
