"""Association of detections to declared objects (Hungarian assignment with gating).

Cost of detection i for descriptor j (only the attributes the descriptor declares count):

* colour: Delta E*ab (CIE 1976) between the detection's median top-face colour and the
  declared colour, Delta L* weighted by ``lightness_weight`` (shading and lighting change
  L* most), divided by ``colour_scale_lab``;
* size: mean absolute error of the sorted full dimensions (or of the largest one) / ``size_scale_m``;
* shape: ``shape_cost`` when the classes differ;
* track: distance to the descriptor's current track / ``position_scale_m``, capped at 1
  (tie-breaker between otherwise identical objects; objects do move between observations).

The optimal assignment is :func:`scipy.optimize.linear_sum_assignment` (Kuhn 1955). A pair
costing more than ``gate_cost`` is never associated; an assignment whose runner-up (another
descriptor for that detection, or another detection for that descriptor) is within
``ambiguity_margin`` is ambiguous: the detection stays ``unknown`` and the object unseen.
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


def associate(C: np.ndarray, config: PerceptionConfig) -> Association:
    """Gated, margin-checked optimal assignment on the cost matrix ``C``."""
    ac = config.association
    if C.size == 0:
        return Association({}, ())
    gated = np.where(C <= ac.gate_cost, C, 1e6)
    rows, cols = linear_sum_assignment(gated)
    matches: dict[int, tuple[int, float, float]] = {}
    ambiguous: list[int] = []
    for i, j in zip(rows, cols):
        c = float(C[i, j])
        if c > ac.gate_cost:
            continue
        others = np.concatenate([np.delete(C[i, :], j), np.delete(C[:, j], i)])
        others = others[others <= ac.gate_cost]
        runner_up = float(others.min()) if others.size else ac.gate_cost
        margin = max(0.0, runner_up - c) if others.size else max(0.0, ac.gate_cost - c) + ac.ambiguity_margin
        if others.size and margin < ac.ambiguity_margin:
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
