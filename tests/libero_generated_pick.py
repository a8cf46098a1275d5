"""One pick through ``phyagentos run`` on a generated LIBERO scene (LIBERO's placement sampler,
``generated: true``, never an evaluation init state), for the sim tests of issue 28."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any, Mapping, Sequence

import yaml

ROOT = Path(__file__).resolve().parent.parent

#: KITCHEN_SCENE6's microwave (LIBERO-90 task 33, LIBERO-10 task 9) as ``measure_fixture_looks``
#: measures it in that world: its body with the door shut, the door and the room behind it
MICROWAVE = {"name": "microwave_1", "class": "microwave", "size_m": [0.3469, 0.1497, 0.2078],
             "root": {"offset_m": [-0.0007, 0.0378, 0.02], "yaw_rad": 0.0, "body_yaw_rad": -0.0041},
             "model_box": {"lo": [-0.1723, -0.1124], "hi": [0.1723, 0.1104]},
             "door": {"hinge_m": [-0.1725, -0.088], "shut_yaw_rad": 0.0, "sign": 1.0, "range_rad": [-2.094, 0.0],
                      "shut_rad": 0.0, "width_m": 0.259, "thickness_m": 0.024, "mid_m": 0.013, "outer": -1.0,
                      "z_m": [0.0035, 0.1885], "handle_r_m": 0.2375, "handle_out_m": 0.054,
                      "handle_z_m": [0.021, 0.171]},
             "inside": {"lo_m": [-0.1435, -0.089], "hi_m": [0.0635, 0.0805], "floor_m": 0.024, "roof_m": 0.168,
                        "mouth": [0.0, -1.0]}}


def run_generated_pick(tmp_path: Path, *, name: str, description: str, suite: str, task: int,
                       looks: Mapping[str, Mapping[str, Any]], fixture: Mapping[str, str], obj: str,
                       workspace_box: Mapping[str, list] | None = None, seed: int = 108,
                       fixtures: Sequence[Mapping[str, Any]] = (), place_on: str | None = None) -> dict:
    """Run a one-node pick graph of ``obj`` (declared with every category of ``looks``, one
    object each, named ``<category>_1``; the fixture ``fixture`` and ``fixtures``) in a fresh
    workspace ``tmp_path/ws`` whose TARGETS.md has the LIBERO target and whose safety box is
    ``workspace_box`` (the template's if None); with ``place_on``, a place node on it follows
    (accepted when ``obj`` rests on it and is let go). Returns ``phyagentos run --json``'s
    report."""
    nodes: list[dict] = [{"id": "pick", "skill": "pick", "params": {"object": obj},
                          "accept": [{"holding": obj}, {"lifted": {"object": obj, "min_height": 0.05}}]}]
    if place_on is not None:
        nodes.append({"id": "place", "skill": "place", "params": {"object": obj, "region": place_on},
                      "accept": [{"on": {"object": obj, "support": place_on}}, {"released": obj}],
                      "depends_on": ["pick"]})
    objects = [{"name": f"{c}_1", "class": c, **look} for c, look in looks.items()]
    return run_generated_graph(tmp_path, name=name, description=description, suite=suite, task=task,
                               objects=objects, fixtures=[fixture, *fixtures], nodes=nodes,
                               workspace_box=workspace_box, seed=seed)


def run_generated_graph(tmp_path: Path, *, name: str, description: str, suite: str, task: int,
                        objects: Sequence[Mapping[str, Any]], fixtures: Sequence[Mapping[str, Any]],
                        nodes: Sequence[dict], workspace_box: Mapping[str, list] | None = None,
                        seed: int = 108) -> dict:
    """Run goal graph ``nodes`` (each given a 600 s execution and 180 s heartbeat limit) on
    generated scene ``seed`` of LIBERO ``suite`` task ``task`` with the declared ``objects`` and
    ``fixtures``, in a fresh workspace ``tmp_path/ws`` as :func:`run_generated_pick` makes it.
    Returns ``phyagentos run --json``'s report."""
    from phyagentos.bench.libero import target_entry
    from phyagentos.protocol import Workspace
    from phyagentos.protocol.schemas import TargetSpec

    ws = Workspace.create(tmp_path / "ws")
    ws.update("TARGETS", lambda doc: doc.targets.append(TargetSpec.model_validate(target_entry())))
    if workspace_box is not None:
        safety = tmp_path / "ws" / "safety.yaml"
        doc = yaml.safe_load(safety.read_text())
        doc["workspace_box"] = dict(workspace_box)
        safety.write_text(yaml.safe_dump(doc, sort_keys=False))
    limited = [{**n, "limits": {"execution_timeout_s": 600, "heartbeat_timeout_s": 180, **n.get("limits", {})}}
               for n in nodes]
    graph = {"version": 1, "name": name, "description": description, "defaults": {"target": "libero"},
             "scene": {"suite": suite, "task": task, "generated": True, "objects": [dict(o) for o in objects],
                       "fixtures": [dict(f) for f in fixtures]},
             "nodes": limited}
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(graph, sort_keys=False))
    out = subprocess.run([sys.executable, "-m", "phyagentos.cli", "run", str(path), "--workspace", str(tmp_path / "ws"),
                          "--seed", str(seed), "--json", "--memory", "off"], capture_output=True, text=True, timeout=600,
                         cwd=tmp_path, env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    assert out.stdout.strip(), out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])
