"""The Target contract's declared members: the defaults a minimal driver inherits, and the
optional capabilities (mix-ins checked with ``isinstance``) the built-in drivers declare,
so the runtime reads a target's members instead of probing for them."""

from __future__ import annotations

import inspect

import pytest

from phyagentos.targets.contract import MuJoCoBacked, OscControlled, RendersImages, Target
from phyagentos.targets.registry import get_target_class
from phyagentos.targets.scene import SceneSpec


class MinimalGame(Target):
    KIND = "game"
    TOOLS = ()

    def __init__(self, name, scene=None, *, seed=None):
        super().__init__(name, "game")

    def observe(self):
        return {}

    def reset(self, *, seed=None):
        return self.observe()

    def step(self, ctrl):
        pass

    def execute_trajectory(self, traj, *, tracking_tol_rad):
        raise NotImplementedError

    def query_state(self):
        return {}

    def tools(self):
        return self.TOOLS


def test_a_minimal_target_has_the_documented_defaults():
    a, b = MinimalGame("a"), MinimalGame("b")
    assert a.ROBOT == "robot"
    assert a.runtime_notes == {} and a.runtime_notes is not b.runtime_notes  # one dict per target
    assert a.sim_time is None
    assert a.perception_config() is None
    assert a.held_objects() == ()
    assert a.max_grasp_width_m is None  # no gripper declared
    assert not isinstance(a, (MuJoCoBacked, RendersImages, OscControlled))


def test_the_default_scene_parser_is_the_tabletop_scene():
    assert MinimalGame.scene_from_dict(None) == SceneSpec.default()
    assert MinimalGame.scene_from_dict({}) == SceneSpec.default()
    raw = SceneSpec.default().to_dict()
    assert MinimalGame.scene_from_dict(raw, root=None) == SceneSpec.from_dict(raw)


def test_a_capability_mixin_left_unimplemented_keeps_the_driver_abstract():
    class HalfRendered(MinimalGame, RendersImages):
        pass

    assert inspect.isabstract(HalfRendered)
    with pytest.raises(TypeError):
        HalfRendered("x")


@pytest.mark.parametrize(("driver", "mujoco", "renders", "osc"), [
    ("mujoco_franka", True, True, False),
    ("mujoco_so101", True, True, False),
    ("gymnasium_kitchen", True, True, False),
    ("so101_real", True, True, False),
    ("crafter", False, True, False),
    ("libero", True, True, True),
])
def test_the_builtin_drivers_declare_their_optional_capabilities(driver, mujoco, renders, osc):
    cls = get_target_class(driver)
    assert issubclass(cls, MuJoCoBacked) == mujoco
    assert issubclass(cls, RendersImages) == renders
    assert issubclass(cls, OscControlled) == osc
    assert osc == cls.CAPABILITIES.accepts("osc_pose_delta_chunk")


@pytest.mark.parametrize(("driver", "width_m"), [("mujoco_franka", 0.08), ("mujoco_so101", 0.05), ("crafter", None)])
def test_each_driver_declares_its_grippers_widest_grasp(driver, width_m):
    assert get_target_class(driver).max_grasp_width_m == width_m


def test_a_mujoco_backed_target_masks_no_extra_hand_parts_unless_it_declares_them():
    franka, so101 = get_target_class("mujoco_franka"), get_target_class("mujoco_so101")
    assert franka.hand_capsules is MuJoCoBacked.hand_capsules
    assert so101.hand_capsules is not MuJoCoBacked.hand_capsules
