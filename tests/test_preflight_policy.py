"""RuntimeCompatibilityPreflight: every missing item reported, before any target access."""

from __future__ import annotations

import copy
import socket

import pytest

from phyagentos.policy.grasp_policy import GraspPolicy
from phyagentos.policy.server import PolicyServer
from phyagentos.primitives import PRIMITIVES
from phyagentos.protocol import SessionRecord, Workspace
from phyagentos.protocol.lifecycle import utc_now
from phyagentos.protocol.schemas import SafetyConfig
from phyagentos.resources import skills_dir, trees_dir
from phyagentos.runtime.preflight import NEVER_EXPOSED, run_preflight
from phyagentos.runtime.skills import SkillRegistry
from phyagentos.targets.registry import DRIVERS
from phyagentos.runtime.trees import TreeLibrary
from phyagentos.targets import MuJoCoTarget


class CountingTarget(MuJoCoTarget):
    """The real target, counting constructions: preflight must never build one."""

    built = 0

    def __init__(self, *args, **kwargs):
        type(self).built += 1
        super().__init__(*args, **kwargs)


@pytest.fixture(scope="module")
def server():
    srv = PolicyServer(GraspPolicy()).start()
    yield srv
    srv.stop()


@pytest.fixture
def ws(tmp_path):
    return Workspace.create(tmp_path / "ws")


def session(skill="policy_pick", runtime="policy", **params) -> SessionRecord:
    now = utc_now()
    return SessionRecord(session_id="s1", run_id="r1", node="n", skill=skill, skill_runtime=runtime,
                         target="franka_tabletop", parameters={"object": "cube", **params}, accept={"holding": "cube"},
                         created_at=now, updated_at=now)


def preflight(ws, rec, *, skills=None, targets=None, safety=None):
    CountingTarget.built = 0
    result = run_preflight(rec, targets=targets or ws.read("TARGETS").data, runtimes=ws.read("SKILLRUNTIME").data,
                           skills=skills or SkillRegistry(skills_dir()), trees=TreeLibrary(trees_dir(), PRIMITIVES),
                           drivers={**DRIVERS, "mujoco_franka": CountingTarget}, safety=safety or ws.read_safety())
    assert CountingTarget.built == 0
    return result


def codes(result) -> set[str]:
    return {i.code for i in result.rejections}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_a_compatible_policy_session_gets_a_plan_and_a_manifest(ws, server):
    result = preflight(ws, session(policy_endpoint=server.uri))
    assert result.ok, result.rejections
    plan = result.plan.to_dict()
    assert plan["policy_adapter"] == "openpi" and plan["target_adapter"] == "mujoco_franka"
    assert plan["action_form"] == "joint_position_chunk"
    assert plan["policy"]["action"]["rate_hz"] == 20.0 and plan["target_action"]["rate_hz"] == 500.0
    assert plan["policy"]["server"]["policy"] == "phyagentos.grasp_policy"
    assert not set(result.manifest.operations) & NEVER_EXPOSED


def test_an_unreachable_endpoint_is_rejected_after_really_trying(ws):
    result = preflight(ws, session(policy_endpoint=f"ws://127.0.0.1:{free_port()}"))
    [item] = [i for i in result.rejections if i.code == "preflight.endpoint_unreachable"]
    assert item.field == "policy_endpoint" and "Connect" in item.found and "phyagentos policy serve" in item.fix


def test_an_incompatible_adapter_configuration_lists_every_missing_item(ws, server):
    skills = SkillRegistry(skills_dir())
    manifest = skills.get("policy_pick")
    decl = copy.deepcopy(dict(manifest.policy))
    decl["action"] = dict(decl["action"], units="deg", rate_hz=15, gripper="normalized_open")
    decl["bridges"] = []
    inputs = dict(decl["inputs"])
    del inputs["observation/joint_velocity"]
    inputs["observation/depth"] = {"source": "depth", "dtype": "float32", "shape": [224, 224]}
    inputs["observation/image"] = {"source": "rgb", "dtype": "float32", "shape": [224, 224, 3]}
    decl["inputs"] = inputs
    skills._skills["policy_pick"] = type(manifest)(**{**manifest.__dict__, "policy": decl})
    result = preflight(ws, session(policy_endpoint=server.uri), skills=skills)
    assert not result.ok
    fields = {(i.code, i.field) for i in result.rejections}
    for name in ("units", "rate_hz", "gripper"):  # the skill and the served policy disagree
        assert ("preflight.policy_action_mismatch", f"skills.policy_pick.policy.action.{name}") in fields
    bridge_fields = {f for c, f in fields if c == "preflight.action_bridge"}
    assert {"skills.policy_pick.policy.action.units", "skills.policy_pick.policy.action.rate_hz",
            "skills.policy_pick.policy.action.gripper"} <= bridge_fields  # no bridge converts them
    assert ("preflight.observation_missing", "targets.franka_tabletop.observations") in fields  # depth
    assert ("preflight.observation_contract", "skills.policy_pick.policy.inputs.observation/joint_velocity") in fields
    assert ("preflight.observation_shape", "skills.policy_pick.policy.inputs.observation/image") in fields
    for item in result.rejections:
        assert item.code and item.field and item.expected and item.found and item.fix


def test_a_policy_without_any_action_declaration_is_ambiguous(ws):
    skills = SkillRegistry(skills_dir())
    manifest = skills.get("policy_pick")
    decl = {k: v for k, v in manifest.policy.items() if k != "action"}
    skills._skills["policy_pick"] = type(manifest)(**{**manifest.__dict__, "policy": decl})
    result = preflight(ws, session(policy_endpoint=f"ws://127.0.0.1:{free_port()}"), skills=skills)
    assert {"preflight.action_underspecified", "preflight.endpoint_unreachable"} <= codes(result)


def test_a_real_robot_without_an_allow_list_may_only_look(ws, server):
    targets = ws.read("TARGETS").data
    robot = targets.targets[0].model_copy(update={"kind": "real_robot"})
    result = preflight(ws, session(policy_endpoint=server.uri), targets=targets.model_copy(update={"targets": [robot]}))
    denied = {i.expected for i in result.rejections if i.code == "preflight.operation_not_permitted"}
    assert denied == {"stream_joint_positions"}  # observing and stopping stay allowed


def test_never_exposed_operations_cannot_be_allowed(ws):
    targets = ws.read("TARGETS").data
    t = targets.targets[0]
    t = t.model_copy(update={"constraints": {"tool_policy": {"allow": ["observe", "disable_safety", "move_joints"]}}})
    result = preflight(ws, session(skill="pick", runtime="builtin"), targets=targets.model_copy(update={"targets": [t]}))
    assert "preflight.tool_policy" in codes(result)
    assert "preflight.operation_not_permitted" in codes(result)  # pick needs set_gripper, snapshot ...


def test_a_target_faster_than_safety_yaml_allows_is_rejected(ws, server):
    result = preflight(ws, session(policy_endpoint=server.uri), safety=SafetyConfig(max_command_rate_hz=200))
    [item] = [i for i in result.rejections if i.code == "preflight.safety_rate"]
    assert item.found == "200 Hz" and "500" in item.expected


def test_builtin_skills_still_get_their_tree_tools(ws):
    rec = session(skill="pick", runtime="builtin")
    rec.parameters = {"object": "cube"}
    result = preflight(ws, rec)
    assert result.ok, result.rejections
    assert "move_joints" in result.manifest.operations and result.plan.action_bridges == ()
