"""Action bridges: declared conversions, type-checked, malformed input rejected (never repaired)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from phyagentos.errors import ActionBridgeError
from phyagentos.runtime.bridges import ActionChunk, ActionSpec, BridgeChain, ReferenceState, make_bridge
from phyagentos.runtime.target_adapters import MuJoCoFrankaAdapter

JOINTS = tuple(f"robot:panda0_joint{i}" for i in range(1, 8))
TARGET = MuJoCoFrankaAdapter.native_spec(500.0)


def pi0_like(**kw) -> ActionSpec:
    """A VLA-style action: shuffled joints in degrees, normalised gripper, 32-wide padding, 15 Hz."""
    d = dict(space="joint_position", joint_names=JOINTS[::-1], units="deg", gripper="normalized_closed",
             rate_hz=15.0, padding=24)
    d.update(kw)
    return ActionSpec(**d)


FULL_CHAIN = [
    {"bridge": "project", "dims": 8},
    {"bridge": "units", "from": "deg", "to": "rad"},
    {"bridge": "reorder_joints", "order": list(JOINTS)},
    {"bridge": "gripper_remap", "from": "normalized_closed", "to": "opening_m", "max_opening_m": 0.04},
    {"bridge": "resample", "to_hz": 500, "method": "cubic"},
]


def test_a_declared_chain_type_checks_from_policy_to_target():
    assert BridgeChain.from_declarations(FULL_CHAIN).check(pi0_like(), TARGET) == []


def test_a_missing_bridge_is_reported_per_field_with_a_fix():
    problems = BridgeChain.from_declarations(FULL_CHAIN[:1]).check(pi0_like(), TARGET)
    fields = {p.field for p in problems}
    assert fields == {"action.units", "action.joint_names", "action.gripper", "action.rate_hz"}
    assert all(p.fix for p in problems)


@pytest.mark.parametrize("decl, field", [
    ({"bridge": "project", "dims": 7}, "action.dim"),  # would drop the gripper, not padding
    ({"bridge": "units", "from": "rad", "to": "deg"}, "action.units"),
    ({"bridge": "gripper_remap", "from": "normalized_open", "to": "opening_m", "max_opening_m": 0.04}, "action.gripper"),
    ({"bridge": "resample", "to_hz": 500}, "action.padding"),
    ({"bridge": "frame", "from": "camera", "to": "world", "transform": {"position": [0, 0, 0], "quat_wxyz": [1, 0, 0, 0]}},
     "action.space"),
])
def test_a_bridge_that_cannot_accept_its_input_spec_fails_the_type_check(decl, field):
    problems = BridgeChain.from_declarations([decl]).check(pi0_like(), TARGET)
    assert problems and problems[0].field.endswith(field), problems


def test_reordering_needs_a_bijection():
    problems = BridgeChain.from_declarations([{"bridge": "reorder_joints", "order": list(JOINTS[:6]) + ["elbow"]}]).check(
        pi0_like(padding=0, units="rad"), TARGET)
    assert "missing" in problems[0].fix and "elbow" in problems[0].fix


def test_unknown_bridges_and_parameters_are_refused_with_the_valid_choices():
    with pytest.raises(ValueError, match="valid: 'frame', 'gripper_remap'"):
        make_bridge({"bridge": "teleport"})
    with pytest.raises(ValueError, match="unknown parameter"):
        make_bridge({"bridge": "resample", "to_hz": 500, "smooth": True})


def test_the_chain_converts_values_to_the_target_language():
    chain = BridgeChain.from_declarations(FULL_CHAIN[:4])
    chain.check(pi0_like(), TARGET)
    v = np.zeros((3, 32))
    v[:, :7] = np.degrees(np.arange(7)[::-1] * 0.1)  # reversed joint order, degrees
    v[:, 7] = [0.0, 0.5, 1.0]
    v[:, 8:] = 99.0  # padding
    out = chain.apply(ActionChunk(v, 15.0), None).values
    assert out.shape == (3, 8)
    assert np.allclose(out[0, :7], np.arange(7) * 0.1)
    assert np.allclose(out[:, 7], [0.04, 0.02, 0.0])


def test_resampling_continues_from_the_reference_at_the_control_rate():
    chain = BridgeChain.from_declarations([FULL_CHAIN[-1]])
    spec = ActionSpec("joint_position", JOINTS, gripper="opening_m", rate_hz=20.0, max_opening_m=0.04)
    assert chain.check(spec, TARGET) == []
    knots = np.zeros((4, 8))
    knots[:, 0] = [0.02, 0.04, 0.06, 0.08]  # 0.4 rad/s on joint 1
    knots[:, 7] = [0.04, 0.04, 0.0, 0.0]
    ref = ReferenceState(q=np.zeros(7), qd=np.array([0.4, 0, 0, 0, 0, 0, 0]))
    out = chain.apply(ActionChunk(knots, 20.0), ref)
    assert out.rate_hz == 500.0 and out.values.shape == (100, 8)  # 4 steps at 20 Hz = 0.2 s
    v0 = (out.values[0, 0] - 0.0) / 0.002
    assert v0 == pytest.approx(0.4, rel=1e-3)  # C1 at the chunk boundary
    assert out.values[24, 0] == pytest.approx(0.02) and out.values[-1, 0] == pytest.approx(0.08)
    assert np.all(out.values[:50, 7] == 0.04) and np.all(out.values[50:, 7] == 0.0)  # gripper held per knot


@pytest.mark.parametrize("values, code", [
    (np.zeros((5, 31)), "safety.shape"),
    (np.zeros((5,)), "safety.shape"),
    (np.zeros((5, 32), dtype=np.int64), "safety.dtype"),
])
def test_a_malformed_chunk_is_rejected_not_reshaped(values, code):
    chain = BridgeChain.from_declarations(FULL_CHAIN)
    chain.check(pi0_like(), TARGET)
    with pytest.raises(ActionBridgeError) as exc:
        chain.apply(ActionChunk(values, 15.0), ReferenceState(np.zeros(7), np.zeros(7)))
    assert exc.value.code == code and exc.value.bridge == "project"


def test_a_gripper_command_beyond_the_tolerance_is_rejected_within_it_projected():
    chain = BridgeChain.from_declarations([FULL_CHAIN[3]])
    spec = ActionSpec("joint_position", JOINTS, gripper="normalized_closed", rate_hz=500.0)
    chain.check(spec, TARGET)
    ok = np.zeros((2, 8))
    ok[:, 7] = [1.03, -0.02]
    assert np.allclose(chain.apply(ActionChunk(ok, 500.0)).values[:, 7], [0.0, 0.04])
    bad = ok.copy()
    bad[1, 7] = 1.5
    with pytest.raises(ActionBridgeError) as exc:
        chain.apply(ActionChunk(bad, 500.0))
    assert exc.value.code == "safety.joint_limit"


def test_a_frame_bridge_moves_cartesian_actions_into_the_target_frame():
    half = math.sqrt(0.5)
    decl = {"bridge": "frame", "from": "camera", "to": "world",
            "transform": {"position": [0.5, 0.0, 0.2], "quat_wxyz": [half, 0.0, 0.0, half]}}  # 90 deg about z
    spec = ActionSpec("ee_pose", ("x", "y", "z", "rx", "ry", "rz"), frame="camera", rate_hz=10.0)
    chain = BridgeChain.from_declarations([decl])
    out_spec = chain.bridges[0].bind(spec)
    assert out_spec.frame == "world"
    v = np.array([[0.1, 0.0, 0.0, 0.0, 0.0, 0.3]])
    out = chain.apply(ActionChunk(v, 10.0)).values
    assert np.allclose(out[0, :3], [0.5, 0.1, 0.2])
    assert np.allclose(out[0, 3:], [0.0, 0.0, 0.3 + math.pi / 2])
