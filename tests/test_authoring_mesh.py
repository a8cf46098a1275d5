"""Scene objects shaped by a mesh file in the workspace (issue 11, item 5), through the CLI.

A hexagonal prism written as an OBJ file into the workspace is picked and placed in
MuJoCo; every bad mesh (missing, unsupported format, unreadable, too large, outside
the workspace or through a symlink out of it, flat, sized by hand) is refused by
``validate``, ``submit`` and ``run`` with exit 2 and the graph's file:line, the
workspace byte for byte unchanged and no target state recorded (nothing moved).
"""

from __future__ import annotations

import json
import math
import struct
from pathlib import Path

import numpy as np
import pytest
from test_authoring_validation import assert_refused_everywhere

from phyagentos.cli import main
from phyagentos.protocol import Workspace
from phyagentos.targets.mesh import MAX_MESH_BYTES, load_mesh
from phyagentos.targets.scene import SceneSpec, build_scene

RADIUS_M, HEIGHT_M = 0.022, 0.045

GRAPH = """\
version: 1
name: mesh_pick
defaults: {{target: franka_tabletop}}
scene:
  objects:
    - {{name: nut, shape: mesh, {mesh}position: [0.45, -0.2]}}
  regions:
    - {{name: bin, center: [0.5, 0.22], half_extents: [0.07, 0.07]}}
nodes:
  - id: pick_nut
    skill: pick
    params: {{object: nut}}
    accept: {{holding: nut}}
  - id: place_nut
    skill: place
    params: {{object: nut, region: bin}}
    accept: {{inside: {{object: nut, region: bin}}}}
    depends_on: [pick_nut]
"""
MESH_LINE = 6  # the line of the object (and its mesh key) in GRAPH


def hex_prism_obj(radius: float = RADIUS_M, height: float = HEIGHT_M, z0: float = 0.0) -> str:
    """A closed hexagonal prism (OBJ text): axis along z from ``z0``, corners on x."""
    verts = [(radius * math.cos(k * math.pi / 3), radius * math.sin(k * math.pi / 3), z)
             for z in (z0, z0 + height) for k in range(6)]
    text = "# hexagonal prism\n" + "".join(f"v {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in verts)
    for k in range(6):
        n = (k + 1) % 6
        text += f"f {k + 1} {n + 1} {n + 7} {k + 7}\n"
    return text + "f 6 5 4 3 2 1\nf 7 8 9 10 11 12\n"


@pytest.fixture()
def ws(tmp_path) -> Path:
    root = tmp_path / "ws"
    Workspace.create(root)
    (root / "meshes").mkdir()
    (root / "meshes" / "hex.obj").write_text(hex_prism_obj(), encoding="utf-8")
    return root


def graph_file(tmp_path: Path, mesh: str) -> Path:
    path = tmp_path / "graph.yaml"
    path.write_text(GRAPH.format(mesh=mesh), encoding="utf-8")
    return path


def test_a_mesh_object_is_sized_by_its_bounding_box_after_scale(ws):
    md = load_mesh("meshes/hex.obj", root=ws, scale=2.0)
    assert md.half_extents == pytest.approx([2 * RADIUS_M, 2 * RADIUS_M * math.sin(math.pi / 3), HEIGHT_M], abs=1e-6)
    assert md.center == pytest.approx([0.0, 0.0, HEIGHT_M], abs=1e-6)  # the file's prism stands on z = 0
    area = 1.5 * math.sqrt(3) * (2 * RADIUS_M) ** 2
    assert md.volume_m3 == pytest.approx(area * 2 * HEIGHT_M, rel=1e-3)
    scene = SceneSpec.from_dict({"objects": [{"name": "nut", "shape": "mesh", "mesh": "meshes/hex.obj",
                                              "position": [0.45, -0.2]}]}, root=ws)
    nut = scene.object("nut")
    assert nut.rest_z == pytest.approx(HEIGHT_M / 2)
    model = build_scene(scene)
    import mujoco

    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    g = model.geom("nut").id
    mesh = model.geom_dataid[g]
    verts = model.mesh_vert[model.mesh_vertadr[mesh]:model.mesh_vertadr[mesh] + model.mesh_vertnum[mesh]]
    world = verts @ data.geom_xmat[g].reshape(3, 3).T + data.geom_xpos[g]
    assert world[:, 2].min() == pytest.approx(0.0, abs=1e-6)  # resting on the table top
    assert world[:, :2].mean(axis=0) == pytest.approx([0.45, -0.2], abs=1e-6)
    with pytest.raises(Exception, match="no workspace was given"):
        SceneSpec.from_dict({"objects": [{"name": "nut", "shape": "mesh", "mesh": "meshes/hex.obj"}]})


def test_a_thin_mesh_is_refused_after_a_good_mesh_of_the_same_size_was_read_in_the_process(ws):
    """MuJoCo caches decoded assets process-wide: the check must measure each file, not
    a cached one of the same name and size (the 0.2 mm prism's file is as long as the
    good one's)."""
    good, thin = hex_prism_obj(), hex_prism_obj(height=0.0002)
    assert len(good) == len(thin)
    (ws / "meshes" / "thin.obj").write_text(thin, encoding="utf-8")
    (ws / "meshes" / "tall.obj").write_text(hex_prism_obj(height=0.0451), encoding="utf-8")
    for _ in range(2):
        assert load_mesh("meshes/hex.obj", root=ws).half_extents[2] == pytest.approx(HEIGHT_M / 2, abs=1e-6)
        with pytest.raises(Exception, match="degenerate"):
            load_mesh("meshes/thin.obj", root=ws)
        assert load_mesh("meshes/tall.obj", root=ws).half_extents[2] == pytest.approx(0.0451 / 2, abs=1e-6)


def test_a_mesh_object_is_picked_and_placed_in_mujoco_through_the_cli(tmp_path, ws, capsys):
    graph = graph_file(tmp_path, "mesh: meshes/hex.obj, ")
    assert main(["validate", str(graph), "--workspace", str(ws)]) == 0
    capsys.readouterr()
    assert main(["run", str(graph), "--workspace", str(ws), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert {s["node"]: s["status"] for s in report["sessions"]} == {"pick_nut": "succeeded",
                                                                   "place_nut": "succeeded"}
    qpos = np.load(ws / "targets" / "franka_tabletop" / "state.npz")["qpos"]
    assert qpos.shape == (16,)  # 7 arm + 2 finger joints + the nut's free joint
    x, y, z = qpos[9:12]  # the nut's centre, world frame, m: inside the bin, on the table
    assert abs(x - 0.5) <= 0.07 and abs(y - 0.22) <= 0.07
    assert z == pytest.approx(HEIGHT_M / 2, abs=0.005)


def _stl_header_only() -> bytes:
    return b"\0" * 80 + struct.pack("<I", 0)


BAD = {
    "missing": ("mesh: meshes/nope.obj, ", None, r"does not exist in the workspace"),
    "format": ("mesh: meshes/hex.ply, ", ("meshes/hex.ply", hex_prism_obj().encode()),
               r"not a supported format; valid formats: '\.obj', '\.stl'"),
    "unparseable_obj": ("mesh: meshes/junk.obj, ", ("meshes/junk.obj", b"this is not a mesh\n\x00\x01\x02"),
                        r"unreadable"),
    "unparseable_stl": ("mesh: meshes/junk.stl, ", ("meshes/junk.stl", _stl_header_only()), r"unreadable"),
    "too_large": ("mesh: meshes/big.obj, ", ("meshes/big.obj", b"# padding\n" * (MAX_MESH_BYTES // 10 + 1)),
                  rf"more than the limit of {MAX_MESH_BYTES}"),
    "parent": ("mesh: ../outside.obj, ", None, r"outside the workspace"),
    "absolute": ("mesh: /etc/passwd.obj, ", None, r"must be relative to the workspace"),
    "symlink_out": ("mesh: meshes/link.obj, ", "symlink", r"resolves through a symlink outside the workspace"),
    "flat": ("mesh: meshes/flat.obj, ", ("meshes/flat.obj", b"v 0 0 0\nv 0.05 0 0\nv 0 0.05 0\nv 0.05 0.05 0\n"
                                         b"f 1 2 3\nf 2 4 3\n"), r"degenerate"),
    "thin": ("mesh: meshes/thin.obj, ", ("meshes/thin.obj", hex_prism_obj(height=0.0002).encode()), r"degenerate"),
    "sized_by_hand": ("mesh: meshes/hex.obj, half_extents: [0.02, 0.02, 0.02], ", None,
                      r"size is its file's bounding box; remove half_extents"),
    "bad_scale": ("mesh: meshes/hex.obj, scale: -1, ", None, r"scale must be a positive number"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_a_bad_mesh_is_refused_before_anything_moves(case, tmp_path, ws, capsys):
    mesh, extra, expect = BAD[case]
    (tmp_path / "outside.obj").write_text(hex_prism_obj(), encoding="utf-8")
    if extra == "symlink":
        (ws / "meshes" / "link.obj").symlink_to(tmp_path / "outside.obj")
    elif extra is not None:
        (ws / extra[0]).write_bytes(extra[1])
    graph = graph_file(tmp_path, mesh)
    assert_refused_everywhere(graph, ws, capsys, expect=expect, line=MESH_LINE)
