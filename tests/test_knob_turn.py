"""Turning a knob (issue 28, "turn on the stove"): the knob's look, its reading, the verifier's
band, the turn primitive's arguments and the Goal Planner's clause.

The reading of a real LIBERO cloud and the turn itself are pinned on generated scenes in
``tests/test_perception_knob.py`` and ``tests/test_libero_knob.py``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from phyagentos.agent.criteria import evaluate, parse_criteria
from phyagentos.agent.llm.meaning import read_request
from phyagentos.bench.libero import planner_world
from phyagentos.perception import PerceptionError
from phyagentos.perception.fixtures import KNOB_SIGMA_RAD, FixtureLook, KnobLook, knob_reading
from phyagentos.primitives.affordance import ArticulateHinge

KNOB = {"offset_m": [-0.1, 0.0], "top_m": 0.06, "rest_yaw_rad": 0.0, "range_rad": [-0.005, 2.1]}


def _bar(axis_xy, yaw: float, *, length=0.1, width=0.024, top=0.06, n=600, seed=0):
    """Points (N, 3) and heights (N,) of a bar standing on the support (z = 0.9) at ``axis_xy``."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(-length / 2, length / 2, n)
    v = rng.uniform(-width / 2, width / 2, n)
    h = rng.uniform(0.0, top, n)
    c, s = math.cos(yaw), math.sin(yaw)
    xy = np.asarray(axis_xy) + np.column_stack([c * u - s * v, s * u + c * v])
    return np.column_stack([xy, 0.9 + h]), h


def test_a_bar_reads_as_the_joint_position_it_was_turned_to_within_the_travel():
    knob = KnobLook.from_dict(KNOB, "stove")
    centre = np.array([0.0, 0.2])
    for q in (0.0, 0.6, 1.2, 2.0):
        pts, h = _bar(centre + knob.offset_m, knob.bar_yaw(q))
        yaw, n = knob_reading(pts, h, knob, centre)
        assert n >= 30 and abs(knob.joint_position(yaw) - q) < 0.03
    # a bar reads the same turned by pi: the reading is taken in the window centred on the travel
    assert knob.joint_position(-0.02) == pytest.approx(-0.02)
    assert knob.joint_position(-0.02 + math.pi) == pytest.approx(-0.02)
    assert knob.joint_position(2.0 - math.pi) == pytest.approx(2.0)


def test_a_round_blob_or_a_thing_too_wide_where_the_knob_should_be_gives_no_reading():
    knob = KnobLook.from_dict(KNOB, "stove")
    centre = np.array([0.0, 0.2])
    axis = centre + knob.offset_m
    blob, h = _bar(axis, 0.0, length=0.05, width=0.05)  # round: no orientation
    assert knob_reading(blob, h, knob, centre) is None
    handle, h = _bar(axis, 0.3, length=0.12, width=0.05)  # elongated, but 5 cm across: a pan's handle, not a bar
    assert knob_reading(handle, h, knob, centre) is None
    few, h = _bar(axis, 0.3, n=20)
    assert knob_reading(few, h, knob, centre) is None
    low, h = _bar(axis, 0.3, top=0.02)  # below the knob's band: the burner beside it
    assert knob_reading(low, h, knob, centre) is None


def test_a_malformed_knob_look_is_refused_with_the_valid_keys():
    with pytest.raises(PerceptionError, match="knob must be a mapping with keys"):
        FixtureLook.from_dict({"name": "stove", "size_m": [0.3, 0.2, 0.03], "knob": {"offset_m": [0, 0]}})
    with pytest.raises(PerceptionError, match="spanning less than pi"):
        KnobLook.from_dict({**KNOB, "range_rad": [0.0, 3.5]}, "stove")
    look = FixtureLook.from_dict({"name": "stove", "class": "flat_stove", "size_m": [0.3, 0.2, 0.03], "knob": KNOB})
    assert look is not None and look.knob == KnobLook.from_dict(KNOB, "stove")


def _snap(q, std=KNOB_SIGMA_RAD, travel=(-0.005, 2.1)):
    attrs = {"joint_type": "hinge", "range_rad": list(travel)}
    if q is not None:
        attrs.update(joint_position=q, joint_position_std_rad=std)
    return {"entities": [{"name": "stove", "kind": "fixture", "position": [0, 0, 0.9], "size": [0.1, 0.1, 0.02],
                          "attributes": attrs}]}


def test_turned_on_is_judged_on_the_perceived_knob_with_its_two_sigma_band():
    crit = parse_criteria({"articulated": {"object": "stove", "min_fraction": 1 / 3}})[0]
    bound = -0.005 + (2.1 + 0.005) / 3  # a third of the travel: 0.697 rad

    def status(q, **kw):
        return evaluate(crit, _snap(0.0), _snap(q, **kw)).status

    assert status(1.05) == "satisfied"
    assert status(bound + 0.05) == "unknown"  # within 2 sigma of the bound: look again
    assert status(0.3) == "unsatisfied"
    assert status(None) == "unknown"  # the bar was not read (the arm hid it)
    assert status(bound + 0.05, std=0.0) == "satisfied"  # a reported (exact) joint has no band
    no_travel = {"entities": [{"name": "stove", "attributes": {"joint_position": 1.0}}]}
    assert evaluate(crit, no_travel, no_travel).status == "unknown"


def test_the_turn_takes_exactly_one_of_an_angle_and_a_fraction_of_the_travel():
    ArticulateHinge("t", object="stove", to_fraction=0.5)
    ArticulateHinge("t", object="door", delta_rad=-0.8)
    with pytest.raises(ValueError, match="exactly one of delta_rad and to_fraction"):
        ArticulateHinge("t", object="stove", delta_rad=0.5, to_fraction=0.5)
    with pytest.raises(ValueError, match="exactly one of delta_rad and to_fraction"):
        ArticulateHinge("t", object="stove")
    with pytest.raises(ValueError, match=r"to_fraction must be a number in \[0, 1\]"):
        ArticulateHinge("t", object="stove", to_fraction=1.5)


def test_turn_on_and_off_are_read_as_knob_turns_of_the_thing_named():
    world = planner_world({"moka_pot_1": "moka_pot"}, {"flat_stove_1": "flat_stove", "kitchen_table": "kitchen_table"})
    cases = {
        "turn on the stove": [("turn_on", ("flat_stove_1",))],
        "switch the stove on": [("turn_on", ("flat_stove_1",))],
        "turn off the stove": [("turn_off", ("flat_stove_1",))],
        "turn on the stove and put the moka pot on it": [("turn_on", ("flat_stove_1",)),
                                                         ("stack", ("moka_pot_1",))],
        "put the moka pot on the stove and then turn on the stove": [("move", ("moka_pot_1",)),
                                                                    ("turn_on", ("flat_stove_1",))],
    }
    for text, want in cases.items():
        meaning = read_request(text, world, relations=True)
        assert not meaning.problems, (text, meaning.problems)
        assert [(i.verb, i.objects) for i in meaning.intents] == want, text
    meaning = read_request("turn on the sink", world)
    assert meaning.problems and meaning.problems[0][0] == "unknown_object"
