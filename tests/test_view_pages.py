"""What the view's pages write: poses, bounded structured text, the CLI's hint on a new directory."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from phyagentos.view.pages import pose_text, struct_text

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("rpy_deg", [(10.0, -20.0, 30.0), (0.0, 0.0, 179.0), (-170.0, 45.0, -5.0), (0.0, 89.0, 0.0)])
def test_a_4x4_pose_reads_as_position_rpy_and_quaternion(rpy_deg):
    rot = Rotation.from_euler("xyz", rpy_deg, degrees=True)
    m = np.eye(4)
    m[:3, :3] = rot.as_matrix()
    m[:3, 3] = (0.5, -0.2, 0.125)
    text = struct_text({"grasp_pose": m.tolist()})
    assert text.startswith("grasp_pose: p = (0.500, -0.200, 0.125) m")
    rpy = [float(x) for x in text.split("rpy = (")[1].split(")")[0].split(",")]
    q = [float(x) for x in text.split("q(wxyz) = (")[1].split(")")[0].split(",")]
    back = Rotation.from_euler("xyz", rpy, degrees=True)
    assert np.allclose(back.as_matrix(), rot.as_matrix(), atol=2e-3)
    xyzw = rot.as_quat()
    expect = np.array([xyzw[3], *xyzw[:3]]) * (1 if xyzw[3] >= 0 else -1)
    assert np.allclose(q, expect, atol=2e-3)
    assert pose_text(m.tolist()) in text


def test_long_structures_are_cut_at_item_boundaries_with_a_count():
    value = {f"key{i}": {"limit_n": 12.345678, "names": ["alpha", "beta", "gamma"]} for i in range(40)}
    text = struct_text(value, limit=160)
    assert len(text) < 260
    assert text.rstrip().endswith("more")
    # every item shown is whole: balanced braces and brackets, numbers not cut
    shown = text.rsplit("; …", 1)[0]
    assert shown.count("{") == shown.count("}") and shown.count("[") == shown.count("]")
    assert "12.35" in shown
    long = struct_text("word " * 200, limit=50)
    assert long.endswith("more characters)") and "wor …" not in long


def test_view_on_a_new_directory_prints_a_cli_hint(tmp_path):
    for path in (tmp_path / "new", tmp_path):
        proc = subprocess.run([sys.executable, "-m", "phyagentos.cli", "view", str(path), "--port", "0"], cwd=ROOT,
                              capture_output=True, text=True, timeout=60)
        assert proc.returncode == 2
        text = proc.stdout + proc.stderr
        assert "phyagentos run " in text and f"--workspace {path}" in text and f"phyagentos view {path}" in text
        assert "Workspace.create" not in text and "Traceback" not in text


def test_the_tree_graph_marks_the_running_leaf_and_fits_wide_trees():
    import re

    from phyagentos.view.tree_svg import tree_svg

    def node(i, parent, name, kind, status):
        return {"id": i, "parent": parent, "name": name, "type": "X", "kind": kind, "status": status, "message": ""}

    small = [node(0, None, "Root", "composite", "running"), node(1, 0, "Done", "leaf", "success"),
             node(2, 0, "Moving", "leaf", "running"), node(3, 0, "Next", "leaf", "invalid")]
    svg = tree_svg(small)
    assert re.findall(r'class="btn ([^"]+)" data-i="(\d)"', svg) == [
        ("bt-running", "0"), ("bt-success", "1"), ("bt-running active-leaf", "2"), ("bt-invalid", "3")]
    w, h = (int(v) for v in re.search(r'width="(\d+)" height="(\d+)"', svg).groups())
    assert w > h  # three leaves: top-down
    wide = [node(0, None, "Root", "composite", "running")] + [
        node(i, 0, f"Leaf{i}", "leaf", "success") for i in range(1, 20)]
    w, h = (int(v) for v in re.search(r'width="(\d+)" height="(\d+)"', tree_svg(wide)).groups())
    assert w < 400 < h  # nineteen leaves: left to right, narrow enough for the panel
    assert tree_svg(wide * 30) == ""  # beyond MAX_SVG_NODES: the table only
