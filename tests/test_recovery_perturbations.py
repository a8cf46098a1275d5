"""Seeded perturbations of the MuJoCo tabletop (phyagentos.targets.perturbations)."""

from __future__ import annotations

import numpy as np
import pytest

from phyagentos.errors import TargetError
from phyagentos.targets import MuJoCoTarget, SceneSpec
from phyagentos.targets.perturbations import KINDS, ActivePerturbations, parse_perturbations

pytestmark = pytest.mark.sim


@pytest.fixture(scope="module")
def target():
    t = MuJoCoTarget("perturbed", SceneSpec.default(), seed=0)
    yield t
    t.close()


def active(raw, seed=0):
    return ActivePerturbations(parse_perturbations(raw, objects=("cube",)), session_seed=seed)


def cube_xy(snapshot):
    return np.array(next(e["position"][:2] for e in snapshot["entities"] if e["name"] == "cube"))


@pytest.mark.parametrize("raw,message", [
    ([{"kind": "rain"}], "unknown kind 'rain'; valid kinds: " + ", ".join(repr(k) for k in sorted(KINDS))),
    ([{"kind": "low_friction"}], "needs 'object'"),
    ([{"kind": "low_friction", "object": "ball"}], "unknown object 'ball'; objects: 'cube'"),
    ([{"kind": "displaced", "object": "cube", "speed": 3}], "unknown key\\(s\\) 'speed'"),
    ([{"kind": "heavy_object", "object": "cube", "mass_kg": [2, 1]}], "lo <= hi"),
    ({"kind": "perception_noise"}, "must be a list"),
])
def test_malformed_perturbations_name_the_problem_and_valid_choices(raw, message):
    with pytest.raises(TargetError, match=message):
        parse_perturbations(raw, objects=("cube",))


def test_episode_draws_depend_on_the_perturbation_seed_only():
    raw = [{"kind": "low_friction", "object": "cube", "seed": 4}]
    a, b = active(raw, seed=1).record()[0], active(raw, seed=9).record()[0]
    assert a["drawn"] == b["drawn"] and 0.02 <= a["drawn"]["friction"] <= 0.04
    other = active([{"kind": "low_friction", "object": "cube", "seed": 5}]).record()[0]
    assert other["drawn"] != a["drawn"]


def test_perception_noise_is_seeded_per_session_and_averaging_frames_shrinks_it(target):
    target.reset(seed=0)
    truth = cube_xy(target.snapshot())
    raw = [{"kind": "perception_noise", "sigma_m": 0.03, "seed": 2}]
    target.set_perturbations(active(raw, seed=5))
    single = np.array([cube_xy(target.perceive()) - truth for _ in range(200)])
    target.set_perturbations(active(raw, seed=5))
    assert np.allclose(cube_xy(target.perceive()) - truth, single[0])  # same seeds, same frames
    averaged = np.array([cube_xy(target.perceive(samples=16)) - truth for _ in range(200)])
    assert np.std(single) == pytest.approx(0.03, rel=0.15)
    assert np.std(averaged) == pytest.approx(0.03 / 4, rel=0.2)
    assert np.allclose(cube_xy(target.snapshot()), truth)  # ground truth untouched
    target.set_perturbations(None)
    assert np.allclose(cube_xy(target.perceive()), truth)


def test_low_friction_and_heavy_change_the_model_and_are_restored(target):
    m = target.model
    g, b = m.geom("cube").id, m.body("cube").id
    nominal = (m.geom_friction[g, 0], m.geom_priority[g], m.body_mass[b], m.body_inertia[b].copy())
    target.set_perturbations(active([{"kind": "heavy_object", "object": "cube", "mass_kg": 1.5, "friction": 0.5}]))
    assert m.body_mass[b] == pytest.approx(1.5)
    assert np.allclose(m.body_inertia[b], nominal[3] * 1.5 / nominal[2])
    assert m.geom_friction[g, 0] == pytest.approx(0.5) and m.geom_priority[g] > nominal[1]
    target.set_perturbations(active([{"kind": "low_friction", "object": "cube", "friction": 0.03}]))
    assert m.body_mass[b] == pytest.approx(nominal[2]) and m.geom_friction[g, 0] == pytest.approx(0.03)
    target.set_perturbations(None)
    assert (m.geom_friction[g, 0], m.geom_priority[g], m.body_mass[b]) == nominal[:3]


def test_displacement_fires_once_after_the_first_perception_and_stays_near_the_scene_position(target):
    target.reset(seed=0)
    origin = np.array(target.scene.object("cube").position)
    target.set_perturbations(active([{"kind": "displaced", "object": "cube", "distance_m": 0.05, "seed": 1}], seed=3))
    seen = cube_xy(target.perceive())
    assert np.allclose(seen, origin, atol=1e-3)  # the observation was right ...
    moved = cube_xy(target.snapshot())
    assert np.linalg.norm(moved - origin) == pytest.approx(0.05, abs=1e-3)  # ... and immediately stale
    target.step_for(0.3)
    assert np.allclose(cube_xy(target.perceive()), cube_xy(target.snapshot()), atol=1e-3)  # once per session
    (rec,) = target.perturbations.record()
    assert rec["events"][0]["code"] == "perturbation.displaced"
    # a second session of the episode, starting where the first left the cube, stays within reach of the origin
    target.set_perturbations(active([{"kind": "displaced", "object": "cube", "distance_m": 0.05, "seed": 1}], seed=3))
    target.perceive()
    assert np.linalg.norm(cube_xy(target.snapshot()) - origin) <= 0.05 + 1e-3
    target.set_perturbations(None)


def test_grip_force_is_commanded_past_the_closed_position(target):
    target.reset(seed=0)
    kp = target.model.actuator_gainprm[target._finger_act[0], 0]
    target.set_gripper(opening_m=0.0, force_n=40.0, settle_s=0.2)
    assert target.data.ctrl[target._finger_act] == pytest.approx(-40.0 / kp)
    with pytest.raises(TargetError, match="force_n must be in"):
        target.set_gripper(opening_m=0.0, force_n=500.0)
    target.set_gripper(opening_m=0.04, settle_s=0.2)


def test_a_session_without_perturbations_after_perturbed_ones_gets_the_constants_of_a_fresh_target():
    # Sessions without perturbations skip the restore once the model is nominal; every
    # derived constant must still be what a target never perturbed has.
    fresh = MuJoCoTarget("fresh", SceneSpec.default(), seed=0)
    used = MuJoCoTarget("used", SceneSpec.default(), seed=0)
    try:
        fresh.set_perturbations(None)
        heavy = active([{"kind": "heavy_object", "object": "cube", "mass_kg": 1.5, "friction": 0.5}])
        for installed in (None, heavy, None, active([]), heavy, active([]), None):
            used.set_perturbations(installed)
            if installed:
                assert not np.array_equal(used.model.body_invweight0, fresh.model.body_invweight0)
            else:
                for field in ("body_mass", "body_inertia", "geom_friction", "geom_priority", "body_invweight0",
                              "dof_invweight0", "tendon_invweight0", "actuator_acc0"):
                    assert np.array_equal(getattr(used.model, field), getattr(fresh.model, field)), field
                assert used.perturbations is None
    finally:
        fresh.close()
        used.close()
