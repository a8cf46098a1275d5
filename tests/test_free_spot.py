"""A free spot in a container for one more object (phyagentos.motion.free_spot): LIBERO-10's
"put both the alphabet soup and the tomato sauce in the basket" set the second can on the first."""

from __future__ import annotations

import math

import numpy as np
import pytest

from phyagentos.motion.free_spot import FREE_CLEARANCE_M, free_spot

BASKET = dict(centre_xy=(0.0, 0.26), yaw_rad=0.0, inner_half_xy=(0.072, 0.063))  # 14.4 x 12.6 cm inside
CAN = (0.034, 0.034)


def test_an_empty_container_takes_the_object_in_its_middle():
    spot, clear = free_spot(**BASKET, object_half_xy=CAN, occupants=[])
    assert np.allclose(spot, (0.0, 0.26)) and clear == math.inf


def test_two_cans_share_a_basket_when_the_first_takes_its_cell():
    # the first can set in its cell (the left half of the longer side), the second beside it
    first_spot, _ = free_spot(**BASKET, object_half_xy=CAN, occupants=[], prefer_xy=(-0.036, 0.26))
    assert first_spot[0] + CAN[0] <= 0.0 + 1e-9  # wholly in the left half
    first = ((first_spot[0] + 0.004, first_spot[1] - 0.003), CAN)  # where it came to rest, a few mm off
    spot, clear = free_spot(**BASKET, object_half_xy=CAN, occupants=[first], prefer_xy=(0.036, 0.26))
    assert clear > -0.005  # beside it: at most the few millimetres the first one drifted
    assert abs(spot[0]) + CAN[0] <= 0.072 + 1e-9 and abs(spot[1] - 0.26) + CAN[1] <= 0.063 + 1e-9
    # the first can let go in the middle leaves no room for a second: the least overlap, reported
    _, crowded = free_spot(**BASKET, object_half_xy=CAN, occupants=[((-0.003, 0.244), CAN)])
    assert crowded < 0.0


def test_once_clear_enough_the_spot_nearest_the_middle_wins():
    far = ((0.065, 0.26), (0.005, 0.005))  # a small thing against one wall
    spot, clear = free_spot(**BASKET, object_half_xy=(0.02, 0.02), occupants=[far])
    assert clear >= FREE_CLEARANCE_M and np.hypot(spot[0], spot[1] - 0.26) < 0.01


def test_a_turned_container_keeps_the_object_inside_its_own_axes():
    turned = dict(BASKET, yaw_rad=math.pi / 2)  # its long side along world y now
    spot, _ = free_spot(**turned, object_half_xy=CAN, occupants=[((0.0, 0.26), CAN)])
    assert abs(spot[0]) + CAN[0] <= 0.063 + 1e-9 and abs(spot[1] - 0.26) + CAN[1] <= 0.072 + 1e-9


def test_an_object_wider_than_the_inside_has_no_spot():
    assert free_spot(**BASKET, object_half_xy=(0.08, 0.02), occupants=[((0.0, 0.26), CAN)]) is None


@pytest.mark.parametrize("seed", range(5))
def test_the_spot_is_never_worse_than_the_middle(seed):
    rng = np.random.default_rng(seed)
    occ = [(rng.uniform((-0.06, 0.2), (0.06, 0.32)), rng.uniform(0.01, 0.03, 2)) for _ in range(2)]
    spot, clear = free_spot(**BASKET, object_half_xy=(0.025, 0.02), occupants=occ)
    middle = min(float(np.max(np.abs(np.array((0.0, 0.26)) - q) - ((0.025, 0.02) + h))) for q, h in occ)
    assert clear >= min(middle, FREE_CLEARANCE_M) - 1e-9
