"""YAML behaviour trees: the shipped trees build, and bad trees fail with file:line and choices."""

from __future__ import annotations

import py_trees
import pytest

from phyagentos.errors import SkillError
from phyagentos.primitives import PRIMITIVES
from phyagentos.resources import skills_dir, trees_dir
from phyagentos.runtime.preflight import tree_tools
from phyagentos.runtime.skills import SkillRegistry
from phyagentos.runtime.trees import TreeLibrary, render_ascii


@pytest.fixture
def library() -> TreeLibrary:
    return TreeLibrary(trees_dir(), PRIMITIVES)


def write(tmp_path, name, text):
    (tmp_path / f"{name}.yaml").write_text(text, encoding="utf-8")
    return TreeLibrary(tmp_path, PRIMITIVES)


def test_every_shipped_skill_builds_its_tree(library):
    skills = SkillRegistry(skills_dir())
    assert {"pick", "place", "pick_and_place", "hold"} <= set(skills.names())
    for name in skills.names():
        manifest = skills.get(name)
        if manifest.runtime != "builtin":
            continue  # policy skills have no tree (tests/test_policy_*.py)
        # the required parameters, and the optional ones the manifest gives an example of (a push
        # says where to by one of two pairs: its manifest's examples are direction and distance_m)
        params = {k: d.get("example", "x") for k, d in manifest.params.items() if d.get("required") or "example" in d}
        root = library.build(manifest.tree, params)
        assert isinstance(root, py_trees.behaviour.Behaviour)


def test_pick_tree_uses_ik_planning_timing_execution_and_gripper(library):
    root = library.build("pick", {"object": "cube"})
    kinds = {type(n).__name__ for n in root.iterate()}
    assert {"Observe", "SolveIK", "PlanPath", "RetimePath", "ExecuteTrajectory", "Gripper", "CartesianMove", "Retry"} <= kinds
    assert {"snapshot", "move_joints", "set_gripper"} <= tree_tools(root)
    art = render_ascii(root)
    assert "Pick" in art and "MoveToPregrasp" in art


def test_parameter_references_are_substituted_with_their_types(library):
    root = library.build("pick", {"object": "cube", "lift_m": 0.2})
    lift = next(n for n in root.iterate() if n.name == "Lift")
    assert lift.offset.tolist() == [0.0, 0.0, 0.2]


def test_missing_required_parameter_names_it(library):
    with pytest.raises(SkillError, match="needs parameter 'object'"):
        library.build("pick", {})


def test_unknown_primitive_lists_valid_primitives_with_line(tmp_path):
    lib = write(tmp_path, "t", "version: 1\nname: t\nroot:\n  sequence:\n    children:\n      - primitive: teleport\n")
    with pytest.raises(SkillError) as info:
        lib.build("t")
    assert "t.yaml:6" in str(info.value) and "'observe'" in str(info.value) and "teleport" in str(info.value)


def test_unknown_node_kind_lists_valid_kinds(tmp_path):
    lib = write(tmp_path, "t", "version: 1\nname: t\nroot:\n  loop:\n    children: []\n")
    with pytest.raises(SkillError, match="valid kinds: .*'sequence'"):
        lib.build("t")


def test_bad_primitive_parameter_lists_accepted_ones(tmp_path):
    lib = write(tmp_path, "t", "version: 1\nname: t\nroot:\n  primitive: gripper\n  params: {comand: open}\n")
    with pytest.raises(SkillError, match="accepted: .*'command'"):
        lib.build("t")


def test_invalid_primitive_value_is_reported_at_its_line(tmp_path):
    lib = write(tmp_path, "t", "version: 1\nname: t\nroot:\n  primitive: gripper\n  params: {command: squeeze}\n")
    with pytest.raises(SkillError) as info:
        lib.build("t")
    assert "t.yaml:4" in str(info.value) and "squeeze" in str(info.value)


def test_unresolved_reference_lists_available_parameters(tmp_path):
    lib = write(tmp_path, "t", "version: 1\nname: t\nparams: {object: {required: true}}\n"
                               "root:\n  primitive: compute_grasp\n  params: {object: '${obj}'}\n")
    with pytest.raises(SkillError, match=r"\$\{obj\}.*available parameters: 'object'"):
        lib.build("t", {"object": "cube"})


def test_recursive_subtree_is_rejected(tmp_path):
    lib = write(tmp_path, "a", "version: 1\nname: a\nroot:\n  subtree: a\n")
    with pytest.raises(SkillError, match="deeper than"):
        lib.build("a")


def test_decorators_and_parallel_build(tmp_path):
    lib = write(tmp_path, "t", """version: 1
name: t
root:
  parallel:
    policy: success_on_one
    children:
      - timeout:
          duration_s: 2.5
          child: {primitive: hold, params: {duration_s: 0.1}}
      - retry:
          num_failures: 2
          child: {primitive: observe}
""")
    root = lib.build("t")
    assert isinstance(root, py_trees.composites.Parallel)
    kinds = [type(n).__name__ for n in root.iterate()]
    assert "Timeout" in kinds and "Retry" in kinds


def test_unknown_tree_lists_valid_trees(library):
    with pytest.raises(SkillError, match="valid trees: .*'pick'"):
        library.build("juggle")


def test_the_place_retreat_rises_as_high_as_the_arm_reaches_at_least_min_retreat_m(library):
    for tree in ("place", "place_at"):
        params = {"object": "cube", "region": "goal"}
        retreat = next(n for n in library.build(tree, params).iterate() if n.name == "Retreat")
        assert retreat.at_least_m == 0.04 and retreat.offset.tolist() == [0.0, 0.0, 0.10]
        lower = next(n for n in library.build(tree, {**params, "min_retreat_m": 0.06}).iterate() if n.name == "Retreat")
        assert lower.at_least_m == 0.06


def test_give_way_ends_a_clean_up_so_the_selector_moves_on_with_the_failure_that_called_for_it(tmp_path):
    """``give_way`` fails at once and records nothing: the clean-up sequence it ends fails, the
    selector's next child runs, and the failure recorded before the clean-up stays the last."""
    from phyagentos.primitives import SkillContext

    lib = write(tmp_path, "t", "version: 1\nname: t\nroot:\n  selector:\n    children:\n"
                               "      - sequence:\n          name: CleanUp\n          children:\n"
                               "            - primitive: noop\n              name: Undo\n"
                               "            - primitive: give_way\n              name: GiveWay\n"
                               "      - primitive: noop\n        name: Next\n")
    root = lib.build("t")
    ctx = SkillContext(target=None)
    ctx.fail("execution.tracking", "LowerToTheDrawer", "tracking error 0.050 rad exceeded 0.05 rad")
    for node in root.iterate():
        if hasattr(node, "ctx"):  # the primitives
            node.setup(context=ctx)
    root.tick_once()
    while root.status == py_trees.common.Status.RUNNING:
        root.tick_once()
    nodes = {n.name: n for n in root.iterate()}
    assert root.status == py_trees.common.Status.SUCCESS
    assert nodes["CleanUp"].status == py_trees.common.Status.FAILURE
    assert nodes["Undo"].status == py_trees.common.Status.SUCCESS and nodes["Next"].status == py_trees.common.Status.SUCCESS
    assert ctx.failure["primitive"] == "LowerToTheDrawer"
    assert [r["kind"] for r in ctx.trace.records if r["kind"] == "give_way"] == ["give_way"]


def test_a_hook_whose_fingers_stop_on_the_way_down_is_raised_back_before_the_handle_is_tried(library):
    """LIBERO-10 task 3 init 5: the hook's fingers stopped on the drawer's front and the handle's
    branch planned from there, in contact (``start_in_collision``, no rung left): a failed
    lowering is followed by a straight raise back to the pose above the hook, then the branch."""
    root = library.build("hook_drawer", {"object": "white_cabinet_1_bottom_drawer"})
    nodes = {n.name: n for n in root.iterate()}
    lower = nodes["LowerOrRaiseBack"]
    assert isinstance(lower, py_trees.composites.Selector)
    assert [c.name for c in lower.children] == ["LowerToTheDrawer", "RaiseBackAndGiveWay"]
    raise_back, give_way = nodes["RaiseBackAndGiveWay"].children
    assert type(raise_back).__name__ == "CartesianMove" and raise_back.to == "pregrasp_pose"
    assert type(give_way).__name__ == "GiveWay"
    assert [c.name for c in root.children] == ["HookDrawer", "PullByTheHandle"]
