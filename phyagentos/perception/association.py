"""Association of detections to declared objects (Hungarian assignment with gating).

Cost of detection i for descriptor j (only the attributes the descriptor declares count):

* colour: Delta E*ab (CIE 1976) between the detection's median top-face colour and the
  declared colour, Delta L* weighted by ``lightness_weight`` (shading and lighting change
  L* most), divided by ``colour_scale_lab``;
* size: mean absolute error of the sorted full dimensions (or of the largest one) / ``size_scale_m``;
* shape: ``shape_cost`` when the classes differ;
* track: distance to the descriptor's current track / ``position_scale_m``, capped at 1
  (tie-breaker between otherwise identical objects; objects do move between observations).

The optimal assignment is :func:`scipy.optimize.linear_sum_assignment` (Kuhn 1955), with
a "no match" option at ``gate_cost`` for every detection and descriptor. A pair costing more
than ``gate_cost`` is never associated; a match whose margin (the cost of the best
assignment without it minus the optimum) is below ``ambiguity_margin`` is ambiguous: the
detection stays ``unknown`` and the object unseen.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy.optimize import linear_sum_assignment

from phyagentos.perception.colour import lab_distance, srgb_to_lab
from phyagentos.perception.config import PerceptionConfig
from phyagentos.perception.descriptors import ObjectDescriptor
from phyagentos.perception.detect import Detection

__all__ = ["Association", "cost_matrix", "associate", "match_confidence"]


@dataclass(frozen=True)
class Association:
    """Result: ``matches`` maps detection index -> (descriptor index, cost, margin);
    ``ambiguous`` lists detection indices withheld because of a too small margin."""

    matches: dict[int, tuple[int, float, float]]
    ambiguous: tuple[int, ...]


def _size_error(det: Detection, desc: ObjectDescriptor) -> float | None:
    if desc.size_m is None:
        return None
    full = 2.0 * np.asarray(det.half_extents, float)
    measured = np.array([max(full[0], full[1]), min(full[0], full[1]), full[2]])
    want = desc.size_vector()
    if want is None:
        return abs(float(measured.max()) - float(desc.size_m))
    return float(np.mean(np.abs(measured - want)))


def cost_matrix(detections: Sequence[Detection], descriptors: Sequence[ObjectDescriptor],
                config: PerceptionConfig, track_positions: Sequence[np.ndarray | None] = ()) -> np.ndarray:
    """(n_detections, n_descriptors) association costs (see the module docstring)."""
    ac = config.association
    C = np.zeros((len(detections), len(descriptors)))
    desc_lab = [None if d.colour_rgb is None else srgb_to_lab(np.array([d.colour_rgb]))[0] for d in descriptors]
    for i, det in enumerate(detections):
        for j, desc in enumerate(descriptors):
            c = 0.0
            if desc_lab[j] is not None:
                c += float(lab_distance(det.colour_lab, desc_lab[j], lightness_weight=ac.lightness_weight)) / ac.colour_scale_lab
            err = _size_error(det, desc)
            if err is not None:
                c += err / ac.size_scale_m
            if desc.shape is not None and desc.shape != det.shape:
                c += ac.shape_cost
            tp = track_positions[j] if j < len(track_positions) else None
            if tp is not None:
                c += min(1.0, float(np.linalg.norm(det.position[:2] - tp[:2])) / ac.position_scale_m)
            C[i, j] = c
    return C


_FORBIDDEN = 1e6


def _padded(C: np.ndarray, gate: float) -> np.ndarray:
    """The assignment problem with "no match" options: ``[[C, U], [V, 0]]`` where a
    detection left unknown (U, diagonal) or a descriptor left unseen (V, diagonal) costs
    ``gate``; pairs above the gate are forbidden."""
    n, m = C.shape
    P = np.full((n + m, m + n), _FORBIDDEN)
    P[:n, :m] = np.where(C <= gate, C, _FORBIDDEN)
    P[np.arange(n), m + np.arange(n)] = gate
    P[n + np.arange(m), np.arange(m)] = gate
    P[n:, m:] = 0.0
    return P


def _total(P: np.ndarray) -> float:
    r, c = linear_sum_assignment(P)
    return float(P[r, c].sum())


def associate(C: np.ndarray, config: PerceptionConfig) -> Association:
    """Gated, margin-checked optimal assignment on the cost matrix ``C``.

    The margin of a match (i, j) is how much the best assignment that does *not* give
    descriptor j to detection i costs more than the optimum (every detection may stay
    unknown and every descriptor unseen at ``gate_cost``): a look-alike whose own detection
    is explained better elsewhere is no rival, two that could swap at little cost are."""
    ac = config.association
    if C.size == 0:
        return Association({}, ())
    P = _padded(C, ac.gate_cost)
    rows, cols = linear_sum_assignment(P)
    best = float(P[rows, cols].sum())
    n, m = C.shape
    matches: dict[int, tuple[int, float, float]] = {}
    ambiguous: list[int] = []
    for i, j in zip(rows, cols):
        if i >= n or j >= m:
            continue
        c = float(C[i, j])
        if c > ac.gate_cost:
            continue
        forbid = P.copy()
        forbid[i, j] = _FORBIDDEN
        margin = max(0.0, _total(forbid) - best)
        if margin < ac.ambiguity_margin:
            # every detection within the margin for this descriptor is a candidate: none is named
            rivals = np.flatnonzero(C[:, j] <= c + ac.ambiguity_margin)
            ambiguous.extend(int(r) for r in rivals if int(r) not in ambiguous)
            if int(i) not in ambiguous:
                ambiguous.append(int(i))
            continue
        matches[int(i)] = (int(j), c, margin)
    ambiguous = [i for i in ambiguous if i not in matches]
    return Association(matches, tuple(ambiguous))


def match_confidence(cost: float, margin: float, config: PerceptionConfig) -> float:
    """0..1 association confidence: exp(-cost^2 / 2) * (1 - exp(-margin / ambiguity_margin))."""
    m = config.association.ambiguity_margin
    margin_term = 1.0 - math.exp(-margin / m) if m > 0 else 1.0
    return math.exp(-0.5 * cost * cost) * margin_term
