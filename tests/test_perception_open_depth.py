"""An open container's depth, perceived (issue 28): a basket's rim is not a shelf.

Synthetic segments for the three shapes :func:`phyagentos.perception.detect.open_depth` must
tell apart, and the recorded LIBERO frames of ``test_perception_drawer_inside.py`` for real
bowls, a ramekin, a plate and a cookie box.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from phyagentos.perception.detect import OPEN_WALL_M, open_depth

sys.path.insert(0, str(Path(__file__).parent))


def _box_surface(half, top, *, floor=None, step=0.004):
    """Points of a box-shaped segment seen from above: its rim walls (with their outer and inner
    faces from the table up to ``top``) and, open, its floor at ``floor``; or, solid, its top face."""
    hx, hy = half
    xs, ys = np.arange(-hx, hx + 1e-9, step), np.arange(-hy, hy + 1e-9, step)
    gx, gy = (a.ravel() for a in np.meshgrid(xs, ys))
    edge = (np.abs(gx) > hx - 0.008) | (np.abs(gy) > hy - 0.008)
    pts, h = [], []
    if floor is None:
        pts.append(np.column_stack([gx, gy]))
        h.append(np.full(gx.size, top))
    else:
        pts.append(np.column_stack([gx[edge], gy[edge]]))
        h.append(np.full(int(edge.sum()), top))  # the rim
        pts.append(np.column_stack([gx[~edge], gy[~edge]]))
        h.append(np.full(int((~edge).sum()), floor))
    for z in np.arange(0.005, top, 0.01):  # the near wall's outer face
        x = np.arange(-hx, hx + 1e-9, step)
        pts.append(np.column_stack([x, np.full(x.size, -hy)]))
        h.append(np.full(x.size, z))
    return np.vstack(pts), np.concatenate(h)


def test_a_baskets_floor_far_below_its_rim_is_its_open_depth():
    xy, h = _box_surface((0.1, 0.08), 0.08, floor=0.008)
    assert open_depth(xy, h, np.zeros(2), 0.0, np.array([0.1, 0.08]), 0.08) == pytest.approx(0.072, abs=0.003)


def test_a_solid_top_has_no_open_depth():
    xy, h = _box_surface((0.06, 0.04), 0.05)
    assert open_depth(xy, h, np.zeros(2), 0.0, np.array([0.06, 0.04]), 0.05) == 0.0


def test_a_mug_on_a_plate_seen_as_one_segment_is_no_open_container():
    """The plate's low edge round a tall middle: no rim at the top all round."""
    r = np.linspace(0.0, 0.069, 30)
    a = np.linspace(0.0, 2.0 * math.pi, 72, endpoint=False)
    rr, aa = (v.ravel() for v in np.meshgrid(r, a))
    xy = np.column_stack([rr * np.cos(aa), rr * np.sin(aa)])
    h = np.where(rr < 0.04, 0.12, 0.015)  # the mug's top 12 cm up, the plate's rim 1.5 cm
    assert open_depth(xy, h, np.zeros(2), 0.0, np.array([0.069, 0.069]), 0.12) == 0.0


def test_too_small_a_footprint_for_an_inside_reads_no_depth():
    half = np.array([OPEN_WALL_M + 0.005, OPEN_WALL_M + 0.005])
    xy, h = _box_surface(tuple(half), 0.06, floor=0.005)
    assert open_depth(xy, h, np.zeros(2), 0.0, half, 0.06) == 0.0


def test_libero_bowls_and_the_ramekin_are_open_the_cookie_box_is_solid():
    """Recorded frames of a generated libero_spatial task-4 scene (LIBERO's sampler, never an
    init state). The bowls are seen 4.9-5.1 cm tall, the ramekin 4.2 cm."""
    from test_perception_drawer_inside import _observe, _recorded

    frames, proprio, meta = _recorded()
    seen, _ = _observe(meta["declared"], meta, frames, proprio)
    for bowl in ("akita_black_bowl_1", "akita_black_bowl_2"):
        assert 0.035 <= seen[bowl]["attributes"]["open_depth_m"] <= 0.05, seen[bowl]
    assert 0.025 <= seen["glazed_rim_porcelain_ramekin_1"]["attributes"]["open_depth_m"] <= 0.045
    assert "open_depth_m" not in seen["cookies_1"]["attributes"]
    assert seen["plate_1"]["attributes"].get("open_depth_m", 0.0) < 0.03  # a dish, not a container to fall in
