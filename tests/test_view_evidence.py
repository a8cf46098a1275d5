"""The view's shared evidence readers (``phyagentos/view/evidence.py``) and its module graph."""

from __future__ import annotations

import ast
import json
from pathlib import Path

import numpy as np

from phyagentos.view import evidence
from phyagentos.view.evidence import frames_of, read_trace

VIEW = Path(__file__).resolve().parents[1] / "phyagentos" / "view"


def _imports_within_view(path: Path) -> set[str]:
    """Modules of ``phyagentos.view`` that ``path`` imports anywhere (also inside functions)."""
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom):
            if node.level == 1:
                base = node.module
                out |= {base.split(".")[0]} if base else {a.name for a in node.names}
            elif (node.module or "").startswith("phyagentos.view."):
                out.add(node.module.split(".")[2])
        elif isinstance(node, ast.Import):
            out |= {a.name.split(".")[2] for a in node.names if a.name.startswith("phyagentos.view.")}
    return out


def test_the_view_modules_import_each_other_without_a_cycle():
    graph = {p.stem: _imports_within_view(p) - {p.stem} for p in VIEW.glob("*.py") if p.stem != "__init__"}
    assert "signals" not in graph["scene3d"] and "scene3d" not in graph["signals"], graph
    assert {"evidence"} <= graph["scene3d"] & graph["signals"]
    # depth-first search for any cycle among the package's modules
    state: dict[str, int] = {}

    def visit(name: str, stack: list[str]) -> None:
        state[name] = 1
        for dep in sorted(graph.get(name, ())):
            assert state.get(dep) != 1, f"import cycle: {' -> '.join([*stack, name, dep])}"
            if dep in graph and dep not in state:
                visit(dep, [*stack, name])
        state[name] = 2

    for name in sorted(graph):
        if name not in state:
            visit(name, [])


def test_read_trace_keeps_json_objects_skips_other_lines_and_says_when_cut(tmp_path, monkeypatch):
    assert read_trace(tmp_path / "missing.jsonl") == ([], False)
    path = tmp_path / "trace.jsonl"
    lines = [json.dumps({"kind": "proprio", "stamp_s": 0.1}), "not json", "[1, 2]", json.dumps({"kind": "slip"})]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    assert read_trace(path) == ([{"kind": "proprio", "stamp_s": 0.1}, {"kind": "slip"}], False)
    monkeypatch.setattr(evidence, "MAX_TRACE_BYTES", len(lines[0]) + 5)  # the limit falls inside line 2
    assert read_trace(path) == ([{"kind": "proprio", "stamp_s": 0.1}], True)


def test_frames_of_reads_time_and_qpos_per_frame(tmp_path):
    assert frames_of(tmp_path) is None
    np.savez(tmp_path / "frames.npz", t=np.array([0.0, 0.1]), qpos=np.zeros((2, 9)), camera="overview",
             fps=np.float64(10.0), wall=np.array([0.0, 0.2]))
    f = frames_of(tmp_path)
    assert f["t"].tolist() == [0.0, 0.1] and f["qpos"].shape == (2, 9) and f["camera"] == "overview"
    assert f["fps"] == 10.0 and f["wall"].tolist() == [0.0, 0.2]
