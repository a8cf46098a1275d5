"""Expensive meshes are bounded by size and work before MuJoCo decodes them (issue 33): a
dense 8 MB OBJ (99 s in ``validate`` before) is refused in well under a second by ``validate``,
``submit`` and ``run``, with the graph's file:line; the counts are read without decoding."""

from __future__ import annotations

import struct
import time

import numpy as np
import pytest
from hostile_tally import counted
from hypothesis import given, settings
from hypothesis import strategies as st
from test_authoring_mesh import MESH_LINE, graph_file, ws  # noqa: F401 - ws is a fixture
from test_authoring_validation import assert_refused_everywhere

from phyagentos.targets.mesh import MAX_MESH_BYTES, MAX_MESH_FACES, MAX_MESH_VERTICES, mesh_counts


def dense_obj(target_bytes: int) -> bytes:
    """A closed-looking point cloud OBJ of about ``target_bytes`` (vertices on a 3 cm sphere)."""
    rng = np.random.default_rng(0)
    n = target_bytes // 60
    v = rng.normal(size=(n, 3))
    v = 0.03 * v / np.linalg.norm(v, axis=1, keepdims=True)
    f = rng.integers(1, n + 1, size=(n, 3))
    lines = [f"v {a:.6f} {b:.6f} {c:.6f}" for a, b, c in v] + [f"f {a} {b} {c}" for a, b, c in f]
    return ("\n".join(lines) + "\n").encode()[:MAX_MESH_BYTES]


@counted("meshes: validate/submit/run")
def test_a_dense_8mb_obj_is_refused_before_mujoco_decodes_it(tmp_path, ws, capsys):  # noqa: F811
    data = dense_obj(MAX_MESH_BYTES - 1024)
    assert len(data) <= MAX_MESH_BYTES
    (ws / "meshes" / "dense.obj").write_bytes(data)
    graph = graph_file(tmp_path, "mesh: meshes/dense.obj, ")
    started = time.perf_counter()
    assert_refused_everywhere(graph, ws, capsys, expect=rf"more than the limit of {MAX_MESH_VERTICES} vertices",
                              line=MESH_LINE)
    assert time.perf_counter() - started < 30  # three commands; was 99 s for validate alone


@counted("meshes: validate/submit/run")
def test_a_binary_stl_declaring_too_many_triangles_is_refused(tmp_path, ws, capsys):  # noqa: F811
    n = MAX_MESH_FACES + 1
    (ws / "meshes" / "huge.stl").write_bytes(b"\0" * 80 + struct.pack("<I", n) + b"\0" * 50 * 10)
    graph = graph_file(tmp_path, "mesh: meshes/huge.stl, ")
    assert_refused_everywhere(graph, ws, capsys, expect=r"faces, more than the limit", line=MESH_LINE)


@settings(max_examples=50, deadline=None)
@given(nv=st.integers(0, 3 * MAX_MESH_VERTICES), nf=st.integers(0, 3 * MAX_MESH_FACES),
       indent=st.sampled_from(["", " ", "\t"]))
@counted("meshes: counted before decoding")
def test_obj_counts_are_read_from_the_bytes_in_linear_time(nv, nf, indent):
    data = (f"{indent}v 0 0 0\n" * nv + "vn 0 0 1\nvt 0 0\n# v comment\n" + f"{indent}f 1 2 3\n" * nf).encode()
    started = time.perf_counter()
    assert mesh_counts(data, ".obj") == (nv, nf)
    assert time.perf_counter() - started < 1.0


@counted("meshes: counted before decoding")
def test_stl_counts():
    assert mesh_counts(b"\0" * 80 + struct.pack("<I", 2) + b"\0" * 100, ".stl") == (6, 2)
    ascii_stl = b"solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\n" \
                b"endfacet\nendsolid x\n"
    assert mesh_counts(ascii_stl, ".stl") == (3, 1)
    assert mesh_counts(b"", ".stl") == (0, 0)


@pytest.mark.parametrize("n", [1000, MAX_MESH_VERTICES])
@counted("meshes: within bounds still read")
def test_meshes_within_the_bounds_are_still_read(tmp_path, n):
    from phyagentos.targets.mesh import load_mesh  # noqa: PLC0415

    rng = np.random.default_rng(1)
    v = rng.normal(size=(n, 3))
    v = 0.03 * v / np.linalg.norm(v, axis=1, keepdims=True)
    f = rng.integers(1, n + 1, size=(n, 3))
    text = "".join(f"v {a:.6f} {b:.6f} {c:.6f}\n" for a, b, c in v) + "".join(f"f {a} {b} {c}\n" for a, b, c in f)
    (tmp_path / "m.obj").write_text(text)
    started = time.perf_counter()
    mesh = load_mesh("m.obj", root=tmp_path)
    assert mesh.half_extents[0] == pytest.approx(0.03, abs=0.005)
    assert time.perf_counter() - started < 20
