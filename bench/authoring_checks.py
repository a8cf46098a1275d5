"""Cost of checking a goal graph before anything moves (issue 11).

    .venv/bin/python bench/authoring_checks.py [--repeat 5]

Measures, best of ``--repeat`` (the minimum is the least disturbed by other processes):

- the bounded YAML loader refusing a ~1 KB "billion laughs" alias bomb (9 levels of 9
  aliases: 9**10 nodes if expanded), in ms;
- reading one protocol session document (a real one written by a pick session) with the
  alias bound on and with it off, in ms (the bound walks only texts with an anchor);
- ``check_goal_graph`` of shipped graphs, whole (schema, trees, predicates, scene,
  gripper resources, IK reachability per target), in s, with the share of the
  reachability step.

Writes bench/results/authoring_checks.json.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from _harness import parser as bench_parser
from _harness import write_json

import phyagentos  # noqa: F401  (headless GL before mujoco loads)
from phyagentos.agent.goal_graph import parse_goal_graph
from phyagentos.app.graph_check import check_goal_graph
from phyagentos.errors import GoalGraphError
from phyagentos.protocol import SessionRecord, Workspace, codec
from phyagentos.resources import goal_graphs_dir, skill_dirs, tree_dirs
from phyagentos.runtime.builtin_runtime import BuiltinSkillRuntime

BOMB = "\n".join(["a0: &a0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]"]
                 + [f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 10)])

SESSION = """# Session

```yaml
version: 1
session_id: r1-pick-1
run_id: r1
node: pick
skill: pick
target: franka_tabletop
parameters: {object: cube, approach_height_m: 0.1, grasp_candidate: 0}
created_at: '2026-01-01T00:00:00Z'
updated_at: '2026-01-01T00:00:00Z'
```
"""


def best(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def main() -> None:
    parser = bench_parser(__doc__, "authoring_checks")
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    rows: dict[str, float] = {}

    text = "version: 1\nname: bomb\n" + BOMB + "\nnodes: []\n"

    def bomb() -> None:
        try:
            parse_goal_graph(text, skills=[], targets=[])
        except GoalGraphError:
            return
        raise AssertionError("the alias bomb was accepted")

    rows["alias_bomb_refused_ms"] = 1e3 * best(bomb, args.repeat)

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "r1-pick-1.md"
        path.write_text(SESSION, encoding="utf-8")
        read = lambda: [codec.read_document(path, SessionRecord) for _ in range(100)]  # noqa: E731
        rows["session_read_ms"] = 10 * best(read, args.repeat)
        # an anchor makes the bound walk the node tree (an anchored scalar, no expansion)
        path.write_text(SESSION.replace("{object: cube", "{object: &obj cube"), encoding="utf-8")
        rows["session_read_with_anchor_ms"] = 10 * best(read, args.repeat)

        runtime = BuiltinSkillRuntime.from_dirs(skill_dirs(), tree_dirs())
        ws = Workspace.create(Path(tmp) / "ws")
        for name, target in (("pick_and_place.yaml", None), ("sort_two_cubes.yaml", None),
                             ("pick_and_place_compact.yaml", "so101_tabletop")):
            graph = goal_graphs_dir() / name
            whole = best(lambda: check_goal_graph(graph, ws, runtime, target=target), args.repeat)
            no_reach = best(lambda: check_goal_graph(graph, ws, runtime, target=target, reach=False), args.repeat)
            key = name.removesuffix(".yaml") + (f"@{target}" if target else "")
            rows[f"check_{key}_s"] = whole
            rows[f"check_{key}_without_reach_s"] = no_reach

    write_json(args.out, rows)
    width = max(len(k) for k in rows)
    print(f"{'measure':<{width}}  value (best of {args.repeat}; machine shared, loaded)")
    for k, v in rows.items():
        print(f"{k:<{width}}  {v:.4f}")


if __name__ == "__main__":
    main()
