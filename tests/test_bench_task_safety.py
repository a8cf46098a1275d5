"""A task's own ``safety`` overrides the suite's in that task's episodes only (tasks that
stand in different cells: LIBERO-10 mixes kitchen, living-room and study scenes), and
LIBERO's scene classes each get the template's workspace box moved to their cell."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from phyagentos.bench.compiler import compile_episodes, episode_template_dir, plan_episodes
from phyagentos.bench.suite import load_suite
from phyagentos.errors import BenchError
from phyagentos.protocol import Workspace
from phyagentos.resources import templates_dir

SUITE_BOX = {"min": [-1.0, -1.0, -0.01], "max": [1.0, 1.0, 1.5]}
TASK_BOX = {"min": [-0.5, -0.5, 0.5], "max": [0.5, 0.5, 2.0]}


def _suite(tmp_path: Path) -> Path:
    doc = {"version": 1, "name": "cells", "episodes": 1, "safety": {"workspace_box": SUITE_BOX,
                                                                     "max_command_duration_s": 20},
           "tasks": [{"id": "low", "goal_graph": "pick_and_place.yaml"},
                     {"id": "high", "goal_graph": "pick_and_place.yaml", "safety": {"workspace_box": TASK_BOX}}]}
    path = tmp_path / "cells.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")
    return path


def test_a_tasks_safety_overrides_the_suites_in_its_own_episodes_only(tmp_path):
    suite = load_suite(_suite(tmp_path))
    assert dict(suite.task("high").safety) == {"workspace_box": TASK_BOX} and not suite.task("low").safety
    ws = Workspace.create(tmp_path / "ws")
    run_dir = tmp_path / "run"
    plan = plan_episodes(suite, bench_id="b", seeds=(0,), split="train", memory="off", protocol="standard")
    template = episode_template_dir(ws.root, run_dir, {}, safety=dict(suite.safety))
    task_templates = {t.id: episode_template_dir(ws.root, run_dir, {}, safety={**suite.safety, **t.safety},
                                                 name=f"template_{t.id}") for t in suite.tasks if t.safety}
    dirs = compile_episodes(plan, run_dir=run_dir, template=template, task_templates=task_templates)
    safety = {d.name.split("-")[0]: yaml.safe_load((d / "safety.yaml").read_text()) for d in dirs}
    by_task = {ep.task: safety[ep.episode_id.split("-")[0]] for ep in plan}
    assert by_task["low"]["workspace_box"] == SUITE_BOX and by_task["high"]["workspace_box"] == TASK_BOX
    # the task's keys are laid over the suite's, not instead of them
    assert by_task["low"]["max_command_duration_s"] == by_task["high"]["max_command_duration_s"] == 20


def test_each_libero_scene_class_gets_the_template_box_moved_to_its_robot_base_and_work_surface():
    from phyagentos.bench.libero import LIBERO_CELLS, workspace_box

    template = yaml.safe_load((templates_dir() / "safety.yaml").read_text())["workspace_box"]
    for scene, (x, y, z) in LIBERO_CELLS.items():
        box = workspace_box(scene)
        assert box["min"] == pytest.approx([template["min"][0] + x, template["min"][1] + y, template["min"][2] + z])
        assert box["max"] == pytest.approx([template["max"][0] + x, template["max"][1] + y, template["max"][2] + z])
    # the table scene's box is the one libero_spatial was measured with (docs/libero.md)
    assert workspace_box("LIBERO_Tabletop_Manipulation") == {"min": [-0.86, -0.8, 0.89], "max": [0.34, 0.8, 2.1]}
    with pytest.raises(BenchError, match="LIBERO_Coffee_Table_Manipulation.*known: .*LIBERO_Floor_Manipulation"):
        workspace_box("LIBERO_Coffee_Table_Manipulation")


def test_every_task_of_libero_and_libero_90_stands_in_a_cell_with_a_workspace_box():
    from phyagentos.bench.libero import LIBERO_CELLS
    from phyagentos.targets.libero.catalog import parse_bddl, suite_tasks

    scenes = {}
    for suite in ("libero_spatial", "libero_object", "libero_goal", "libero_10", "libero_90"):
        for task in suite_tasks(suite):
            scenes.setdefault(parse_bddl(task.bddl_path).scene, []).append(f"{suite}/{task.index}")
    assert set(scenes) <= set(LIBERO_CELLS), {s: v[:3] for s, v in scenes.items() if s not in LIBERO_CELLS}
    assert len(scenes["LIBERO_Study_Tabletop_Manipulation"]) == 1 + 17  # libero_10 task 5 and 17 of libero_90


@pytest.mark.sim
@pytest.mark.parametrize("suite,task", [("libero_10", 0), ("libero_10", 5)])  # living room, study
def test_the_start_pose_lies_in_the_box_and_the_box_floor_just_under_the_work_surface(suite, task):
    import mujoco
    import numpy as np

    from phyagentos.bench.libero import workspace_box
    from phyagentos.targets.libero.catalog import parse_bddl, suite_tasks
    from phyagentos.targets.libero.target import LiberoScene, LiberoTarget

    box = workspace_box(parse_bddl(suite_tasks(suite)[task].bddl_path).scene)
    target = LiberoTarget("libero", LiberoScene(suite=suite, task=task, init=0))
    try:
        target.reset()
        m, d = target._model, target._data
        tcp = target.tcp_pose()[:3, 3]
        assert np.all(np.asarray(box["min"]) < tcp) and np.all(tcp < np.asarray(box["max"])), (tcp, box)
        base = d.xpos[m.body("robot0_base").id]
        start = np.array([base[0] + 0.55, base[1] + 0.1, base[2] + 0.12])  # under the arm, over the table
        geom = np.array([-1], dtype=np.int32)
        dist = mujoco.mj_ray(m, d, start, np.array([0.0, 0.0, -1.0]), None, 1, m.body("robot0_base").id, geom)
        surface = start[2] - dist
        assert 0.0 < surface - box["min"][2] < 0.03, (surface, box)
    finally:
        target.close()
