"""Whether the hand can take a thing at all from its declared look (``motion.takeable``):
across it within the Franka Hand's stroke, or by the rim of an open container."""

from __future__ import annotations

import pytest

from phyagentos.motion.takeable import across_width, takeable


def test_a_flat_plate_wider_than_the_stroke_is_not_takeable():
    # LIBERO's plate as the bench measures it: 13.9 cm across, 1.9 cm tall
    assert not takeable("plate", "cylinder", [0.1386, 0.1384, 0.0186])
    # the same width declared as a box, or with no shape: no side fits between the fingers
    assert not takeable("plate", "box", [0.1386, 0.1384, 0.0186])
    assert not takeable(None, None, [0.1386, 0.1384, 0.0186])


def test_a_bowl_too_wide_to_take_across_is_taken_by_its_rim():
    assert takeable("akita_black_bowl", "cylinder", [0.113, 0.113, 0.0506])
    # the same size as a category with no wall to hold: not takeable
    assert not takeable("cookie_box", "cylinder", [0.113, 0.113, 0.0506])


def test_the_narrow_side_decides_and_the_clearance_is_kept():
    # a cream cheese box: 4.5 cm across its narrow side
    assert takeable("cream_cheese", "box", [0.0846, 0.0452, 0.0198])
    # the stroke less 4 mm clearance is the widest taken across
    assert takeable("box", "box", [0.20, 0.076, 0.05])
    assert not takeable("box", "box", [0.20, 0.077, 0.05])
    assert takeable("box", "box", [0.20, 0.10, 0.05], max_width_m=0.11)
    assert across_width("sphere", [0.1, 0.1, 0.06]) == pytest.approx(0.06)
    assert across_width("box", [0.1, 0.05, 0.02]) == pytest.approx(0.05)


@pytest.mark.parametrize("size", [[0.1, 0.1], [0.1, -0.1, 0.1], [0.1, float("nan"), 0.1], "abc", None])
def test_a_size_that_is_not_three_positive_extents_is_refused(size):
    with pytest.raises(ValueError, match="size_m must be"):
        takeable("plate", "cylinder", size)


def test_an_unknown_shape_or_stroke_is_refused_with_the_valid_choices():
    with pytest.raises(ValueError, match="box, cylinder, sphere, unknown"):
        takeable("plate", "disc", [0.1, 0.1, 0.02])
    with pytest.raises(ValueError, match="max_width_m"):
        takeable("plate", "box", [0.1, 0.1, 0.02], max_width_m=0.0)
