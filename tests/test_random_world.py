"""The randomised tabletop world (issue 9 part 7) and scene shapes (issue 11 item 5)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from phyagentos.app.orchestrator import run_goal_graph
from phyagentos.resources import goal_graphs_dir
from phyagentos.targets import MuJoCoTarget, SceneSpec
from phyagentos.targets.world import FRICTION, MASS_KG, REACH_M, SIZE_M, draw_world

pytestmark = pytest.mark.sim

BASE = {"objects": [{"name": "cube", "rgba": [0.85, 0.12, 0.1, 1], "class": "block"}],
        "regions": [{"name": "goal", "center": [0.5, 0.25], "half_extents": [0.08, 0.08]}],
        "obstacles": [{"name": "wall", "center": [0.5, 0.03, 0.15], "half_extents": [0.2, 0.01, 0.15]}]}


def world(seed: int, **extra):
    return draw_world(SceneSpec.from_dict({**BASE, "randomise": {"seed": seed, **extra}}))


def test_two_seeds_give_different_worlds_and_one_seed_the_same_world():
    (a, ra), (_, rb), (a2, ra2) = world(0), world(1), world(0)
    assert a == a2 and ra == ra2
    ca, cb = ra["objects"]["cube"], rb["objects"]["cube"]
    for key in ("half_extents", "position", "mass_kg", "friction"):
        assert ca[key] != cb[key], key
    # over many seeds every property covers its range and every shape occurs
    shapes, counts, touching = set(), set(), 0
    for seed in range(60):
        sc, rec = world(seed)
        c = rec["objects"]["cube"]
        shapes.add(c["shape"])
        counts.add(len(rec["distractors"]))
        touching += sum(d["touching"] == "cube" for d in rec["distractors"])
        assert SIZE_M[0] / 2 - 1e-9 <= min(c["half_extents"]) and max(c["half_extents"]) <= SIZE_M[1] / 2 + 1e-9
        assert MASS_KG[0] <= c["mass_kg"] <= MASS_KG[1] and FRICTION[0] <= c["friction"] <= FRICTION[1]
        assert REACH_M[0] <= math.hypot(*c["position"]) <= REACH_M[1]
        objs = sc.objects
        for i, o in enumerate(objs):  # bounding circles never overlap
            for p in objs[i + 1:]:
                gap = math.dist(o.position, p.position) - math.hypot(*o.half_extents[:2]) - math.hypot(*p.half_extents[:2])
                assert gap >= -1e-9
    assert shapes == {"box", "cylinder", "sphere"} and counts == {0, 1, 2, 3, 4} and touching > 5


def test_the_draw_goes_to_ground_truth_and_the_declared_scene_keeps_only_what_the_user_wrote():
    with MuJoCoTarget("franka_tabletop", SceneSpec.from_dict({**BASE, "randomise": {"seed": 4}}), seed=4) as t:
        declared = t.describe_declared()["objects"]
        assert declared == [{"name": "cube", "colour_rgb": [0.85, 0.12, 0.1], "class": "block"}]
        record = t.scene_record()
        draw = record["draw"]
        assert record["declared"]["randomise"] == {"seed": 4}
        truth = t.ground_truth()["objects"]
        assert truth["cube"]["mass_kg"] == pytest.approx(draw["objects"]["cube"]["mass_kg"], abs=1e-5)  # recorded to 5 decimals
        assert truth["cube"]["shape"] == draw["objects"]["cube"]["shape"]
        assert set(truth) == {"cube", *(d["name"] for d in draw["distractors"])}
        # the physical world rests on the table as drawn
        t.hold(duration_s=0.5)
        for name, o in truth.items():
            assert t.object_pose(name)[2, 3] == pytest.approx(o["half_extents"][2], abs=0.004)


def test_the_tabletop_suite_draws_worlds_from_the_episode_seed_without_scripted_perturbations():
    from phyagentos.bench.compiler import plan_episodes
    from phyagentos.bench.suite import load_suite

    suite = load_suite("tabletop")
    eps = plan_episodes(suite, bench_id="b", seeds=(0, 1), split="measurement", memory="off", protocol="first",
                        tasks=("pick_and_place",))
    seeds = [e.scene["randomise"]["seed"] for e in eps]
    assert seeds[0] != seeds[1] and all(e.evaluation["perturbation"] is None for e in eps)
    assert "perturbations" not in eps[0].scene and "mass" not in eps[0].scene["objects"][0]


@pytest.mark.parametrize("shape,half", [("cylinder", [0.022, 0.022, 0.03]), ("sphere", [0.024, 0.024, 0.024])])
def test_cylinders_and_spheres_build_and_are_picked(tmp_path, shape, half):
    spec = yaml.safe_load((goal_graphs_dir() / "pick_and_place.yaml").read_text())
    spec["scene"]["objects"][0].update(shape=shape, half_extents=half)
    spec["nodes"] = [n for n in spec["nodes"] if n["id"] == "pick_cube"]
    graph = tmp_path / "g.yaml"
    graph.write_text(yaml.safe_dump(spec))
    report = run_goal_graph(graph, tmp_path / "ws", seed=0)
    assert report.succeeded, report.to_dict()
    sc = SceneSpec.from_dict(spec["scene"])
    with MuJoCoTarget("check", sc) as t:
        assert t.model.geom_type[t.model.geom("cube").id] == {"cylinder": 5, "sphere": 2}[shape]
        t.load_state(tmp_path / "ws" / "targets" / "franka_tabletop" / "state.npz")
        assert t.held_objects() == ("cube",) and t.object_pose("cube")[2, 3] > 0.1
    # the grasp was judged from proprioception: the gripper entry carries no simulator key
    trace = next((tmp_path / "ws" / "evidence").glob("*pick_cube-1/trace.jsonl")).read_text()
    assert '"grasped"' not in trace and '"closed_on_something": true' in trace


def test_grasp_candidates_of_round_objects_close_across_the_diameter_at_any_yaw():
    from phyagentos.motion.grasp import top_down_grasp_candidates

    T = np.eye(4)
    T[:3, 3] = [0.5, 0.0, 0.03]
    for shape, he in (("cylinder", (0.025, 0.025, 0.03)), ("sphere", (0.03, 0.03, 0.03))):
        plans = top_down_grasp_candidates(T, he, shape=shape, current_yaw_rad=0.3)
        assert len(plans) == 4 and plans[0].yaw_rad == pytest.approx(0.3)
        assert all(p.width_m == pytest.approx(2 * he[0]) for p in plans)
