"""Scene description and the MuJoCo model built from it (real MuJoCo, no mocks)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from phyagentos.errors import TargetError
from phyagentos.targets import (
    ARM_JOINT_NAMES,
    DEFAULT_SCENE,
    FINGER_JOINT_NAMES,
    HOME_QPOS,
    MuJoCoTarget,
    ObjectSpec,
    ObstacleSpec,
    RegionSpec,
    SceneSpec,
    build_scene,
    franka_asset_dir,
)

pytestmark = pytest.mark.sim


@pytest.fixture(scope="module")
def model() -> mujoco.MjModel:
    return build_scene(DEFAULT_SCENE)


def test_franka_assets_are_found_inside_the_gymnasium_robotics_wheel():
    d = franka_asset_dir()
    for f in ("assets.xml", "actuator.xml", "chain.xml"):
        assert (d / f).is_file()
    assert (d / "meshes" / "collision").is_dir()


def test_default_scene_builds_with_robot_objects_regions_and_obstacles(model):
    for j in ARM_JOINT_NAMES + FINGER_JOINT_NAMES:
        assert mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, j) >= 0, j
    assert model.site("tcp").id >= 0
    assert model.camera("overview").id >= 0
    assert model.body("cube").id >= 0
    assert model.jnt_type[model.joint("cube:free").id] == mujoco.mjtJoint.mjJNT_FREE
    region = model.geom("region:goal")
    assert region.contype == 0 and region.conaffinity == 0
    wall = model.geom("obstacle:wall")
    np.testing.assert_allclose(wall.size, [0.2, 0.01, 0.15])
    table = model.geom("table")
    assert table.pos[2] + table.size[2] == pytest.approx(0.0)
    assert model.body("panda0_link0").pos.tolist() == [0.0, 0.0, 0.0]
    assert model.opt.timestep == pytest.approx(0.002)


def test_home_configuration_points_the_tcp_down_above_the_table(model):
    d = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, d, model.key("home").id)
    mujoco.mj_forward(model, d)
    np.testing.assert_allclose(d.qpos[:7], HOME_QPOS)
    z_axis = d.site("tcp").xmat.reshape(3, 3)[:, 2]
    np.testing.assert_allclose(z_axis, [0, 0, -1], atol=1e-2)
    assert 0.2 < d.site("tcp").xpos[2] < 0.5
    assert d.ncon == sum(1 for c in d.contact[: d.ncon] if model.geom(c.geom1).name == "table")


def test_tcp_site_lies_midway_between_the_fingertip_pads(model):
    d = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, d, model.key("home").id)
    mujoco.mj_forward(model, d)
    left = d.body("panda0_leftfinger").xpos
    right = d.body("panda0_rightfinger").xpos
    tcp = d.site("tcp").xpos
    mid = 0.5 * (left + right)
    # centred between the fingers (xy), below the finger bodies along the approach axis
    np.testing.assert_allclose(tcp[:2], mid[:2], atol=2e-3)
    assert 0.07 < mid[2] - tcp[2] < 0.09
    # the tcp y axis is the finger motion direction
    y_axis = d.site("tcp").xmat.reshape(3, 3)[:, 1]
    finger_dir = (left - right) / np.linalg.norm(left - right)
    assert abs(abs(float(y_axis @ finger_dir)) - 1.0) < 1e-3


def test_cube_rests_on_the_table_after_settling():
    with MuJoCoTarget("sim", DEFAULT_SCENE) as t:
        t.step_for(1.0)
        p = t.object_pose("cube")[:3, 3]
        assert p[2] == pytest.approx(0.02, abs=1e-3)
        np.testing.assert_allclose(p[:2], [0.5, -0.2], atol=1e-3)
        assert np.linalg.norm(t.data.qvel[t.model.jnt_dofadr[t.model.joint("cube:free").id]:][:6]) < 1e-3
        assert {"subject": "cube", "relation": "on", "object": "table"} in t.snapshot()["relations"]


def test_both_finger_actuators_are_driven_together():
    with MuJoCoTarget("sim", DEFAULT_SCENE) as t:
        t.step(np.concatenate([t.home_qpos, [0.01]]))
        a1, a2 = (t.model.actuator(n).id for n in ("r_gripper_finger_joint", "l_gripper_finger_joint"))
        assert t.data.ctrl[a1] == t.data.ctrl[a2] == pytest.approx(0.01)
        t.step_for(0.6)
        f1, f2 = (t.data.qpos[t.model.jnt_qposadr[t.model.joint(n).id]] for n in FINGER_JOINT_NAMES)
        assert f1 == pytest.approx(f2, abs=1e-4)
        assert t.gripper_opening() == pytest.approx(0.01, abs=2e-3)


def test_scene_round_trips_through_plain_dicts():
    d = DEFAULT_SCENE.to_dict()
    assert SceneSpec.from_dict(d) == DEFAULT_SCENE
    custom = SceneSpec.from_dict(
        {
            "objects": [{"name": "box", "half_extents": [0.015, 0.03, 0.02], "position": [0.45, -0.25], "yaw": 0.3}],
            "regions": [{"name": "bin", "center": [0.4, 0.3]}],
        }
    )
    assert custom.object("box").rest_z == pytest.approx(0.02)
    m = build_scene(custom)
    assert m.body("box").id >= 0 and m.geom("region:bin").id >= 0


def test_unknown_scene_keys_are_rejected_with_the_valid_keys():
    with pytest.raises(TargetError, match="valid keys: 'objects', 'obstacles', 'randomise', 'regions', 'timestep'"):
        SceneSpec.from_dict({"objects": [], "robots": []})
    with pytest.raises(TargetError, match="'half_extents'"):
        SceneSpec.from_dict({"objects": [{"name": "a", "colour": "red"}]})


@pytest.mark.parametrize(
    "make",
    [
        lambda: ObjectSpec("a", half_extents=(0.02, -0.01, 0.02)),
        lambda: ObjectSpec("a", mass=0.0),
        lambda: ObjectSpec("bad name"),
        lambda: RegionSpec("r", half_extents=(0.1,)),
        lambda: ObstacleSpec("o", rgba=(1, 1, 1, 2)),
        lambda: SceneSpec(objects=(ObjectSpec("x"),), regions=(RegionSpec("x"),)),
        lambda: SceneSpec(objects=(ObjectSpec("table"),)),
        lambda: SceneSpec(timestep=0.5),
    ],
)
def test_invalid_scene_values_raise_target_error(make):
    with pytest.raises(TargetError):
        make()


def test_specs_are_frozen_and_hashable():
    o = ObjectSpec("a")
    with pytest.raises(Exception):
        o.mass = 1.0  # type: ignore[misc]
    assert hash(DEFAULT_SCENE) == hash(SceneSpec.from_dict(DEFAULT_SCENE.to_dict()))
