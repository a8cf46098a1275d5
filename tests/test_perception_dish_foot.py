"""What stands in a dish has its foot hidden by the dish's rim (``Detection.foot_hidden_m``).

LIBERO-10 task 4: the yellow and white mug let go on its plate (3 cm tall) makes one segment with
it. Cut at a height step at the plate's rim, the part above is the mug less its foot, 9.5 cm
tall for its look's 11.6, and cost 1.52 against the split's limit of 1.5: no cut admissible, the
plate not seen, and the mug's place judged on the plate as remembered. An upper part standing
within a lower part that shows all round it may have its foot below the cut; its height is then
scored only outside the range from what shows to that plus the depth hidden
(:func:`phyagentos.perception.split._rested`, :func:`phyagentos.perception.association.cost_matrix`).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from phyagentos.perception import ObjectDescriptor, PerceptionConfig
from phyagentos.perception.association import cost_matrix
from phyagentos.perception.cloud import Plane
from phyagentos.perception.colour import srgb_to_lab
from phyagentos.perception.detect import Detection
from phyagentos.perception.split import _rested

PLANE = Plane(np.array([0.0, 0.0, 1.0]), 0.0, 1000, True)
YELLOW, PINK = (0.51, 0.46, 0.24), (0.64, 0.48, 0.46)
MUG = ObjectDescriptor("white_yellow_mug_1", shape="cylinder", colour_rgb=YELLOW, size_m=(0.1122, 0.1032, 0.1157),
                       size_range_m=((0.1027, 0.0984, 0.1156), (0.1206, 0.1079, 0.1158)))


def _part(xy, radius, bottom, top, colour):
    rgb = np.asarray(colour, float)
    return Detection(np.array([xy[0], xy[1], 0.5 * (bottom + top)]), 0.0, np.array([radius, radius, 0.5 * (top - bottom)]),
                     "cylinder", rgb, srgb_to_lab(np.array([rgb]))[0], 800, 2, 0.002, math.pi, 1.0, bottom,
                     low_m=bottom)


def test_a_mug_standing_in_a_plates_well_is_as_tall_as_its_look_though_cut_at_the_rim():
    cfg = PerceptionConfig.default()
    mug = _part((0.01, 0.30), 0.055, 0.0, 0.125, YELLOW)  # fitted before the cut: rests at the cut after it
    plate = _part((0.012, 0.302), 0.060, 0.0, 0.030, PINK)
    upper, lower = _rested([mug, plate], [True, False], 0.030, PLANE)
    assert not lower.covered and upper.bottom_m == pytest.approx(0.030)
    assert upper.foot_hidden_m == pytest.approx(0.030)
    hidden = cost_matrix([upper], [MUG], cfg)[0, 0]
    seen_only = cost_matrix([replace(upper, foot_hidden_m=0.0)], [MUG], cfg)[0, 0]
    # 9.5 cm as seen, 12.5 at most: the look's 11.56 within; as seen alone, 2.1 cm short
    assert seen_only - hidden == pytest.approx((0.1156 - 0.095) / 3.0 / cfg.association.size_scale_m, abs=1e-6)


def test_only_a_part_within_what_shows_all_round_it_may_hide_its_foot():
    cfg = PerceptionConfig.default()
    mug = _part((0.01, 0.30), 0.055, 0.0, 0.125, YELLOW)
    # a narrower part under it is covered by it (a ramekin under a bowl): nothing hides the foot
    upper, lower = _rested([mug, _part((0.01, 0.30), 0.045, 0.0, 0.023, PINK)], [True, False], 0.023, PLANE)
    assert lower.covered and upper.foot_hidden_m == 0.0
    # a wider part beside it, the upper part's centre off its footprint: nothing hides the foot
    upper, _ = _rested([mug, _part((0.10, 0.30), 0.060, 0.0, 0.030, PINK)], [True, False], 0.030, PLANE)
    assert upper.foot_hidden_m == 0.0
    # a thing's own rim cut from its body: the body is deeper than what shows above it
    rim = _part((0.01, 0.30), 0.045, 0.0, 0.148, YELLOW)
    upper, lower = _rested([rim, _part((0.01, 0.30), 0.057, 0.0, 0.134, PINK)], [True, False], 0.134, PLANE)
    assert not lower.covered and upper.foot_hidden_m == 0.0
    # a look taller than what shows and the whole stack together costs its height's excess
    tall = ObjectDescriptor("bottle_1", shape="cylinder", colour_rgb=YELLOW, size_m=(0.11, 0.11, 0.20))
    upper, _ = _rested([mug, _part((0.012, 0.302), 0.060, 0.0, 0.030, PINK)], [True, False], 0.030, PLANE)
    excess = (0.20 - 0.125) / 3.0 / cfg.association.size_scale_m
    assert cost_matrix([upper], [tall], cfg)[0, 0] >= excess - 1e-6
