"""Scene objects shaped by a mesh file in the workspace (OBJ or STL).

A scene object written ``shape: mesh`` with ``mesh: meshes/hex.obj`` (and an optional
uniform ``scale``) is read by :func:`load_mesh` before anything is built or moves:

- the path is relative to the **workspace root** (the directory holding TARGETS.md):
  the Runtime plane builds targets from the workspace, not from wherever the user's
  goal-graph file happened to be; an absolute path, a path leaving the workspace
  (``../``) or a symlink resolving outside it is refused;
- the format is one MuJoCo decodes natively: ``.obj`` or ``.stl`` (:data:`MESH_FORMATS`);
- the file is at most :data:`MAX_MESH_BYTES` bytes (checked before it is read), and holds
  at most :data:`MAX_MESH_VERTICES` vertices and :data:`MAX_MESH_FACES` faces (counted on
  the bytes, before MuJoCo decodes anything): MuJoCo's mesh processing (hull, inertia)
  grows faster than linearly with the vertex count -- measured on the 2-core reference
  machine 0.2 s at 5,000 vertices, 1.3 s at 20,000, 7 s at 50,000 and 99 s for an 8 MB
  dense OBJ -- while a graspable tabletop object needs a few thousand faces;
- MuJoCo must decode it and build its convex hull (collision uses the hull, as MuJoCo
  does for every mesh geom), and the result must have a volume: a flat or empty mesh is
  refused (:data:`MIN_EXTENT_M`, :data:`MIN_VOLUME_M3`).

The bytes that were checked are the bytes compiled: :class:`MeshData` carries them and
:func:`phyagentos.targets.scene.add_tabletop_world` hands them to MuJoCo through the
spec's in-memory assets, so a file changed after the check cannot slip into the model.

The object's size (:attr:`MeshData.half_extents`) is the axis-aligned bounding box of
the mesh's vertices **after scale**, in the mesh file's axes; the object frame is the
box's centre, so the grasp planner, the graph checker and perception treat a mesh object
as the box that bounds it.
"""

from __future__ import annotations

import hashlib
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np

from phyagentos.errors import TargetError, format_choices

__all__ = ["MeshData", "load_mesh", "mesh_counts", "MESH_FORMATS", "MAX_MESH_BYTES", "MAX_MESH_VERTICES",
           "MAX_MESH_FACES", "MIN_EXTENT_M", "MIN_VOLUME_M3"]

#: File suffixes MuJoCo decodes natively (case-insensitive).
MESH_FORMATS: tuple[str, ...] = (".obj", ".stl")
#: Largest mesh file read (bytes): a graspable tabletop object needs far fewer faces.
MAX_MESH_BYTES = 8 * 1024 * 1024
#: Most vertices of a mesh file (OBJ ``v`` lines; STL: three per triangle, before MuJoCo merges
#: shared ones): about 1.3 s of MuJoCo processing at the limit on the reference machine.
MAX_MESH_VERTICES = 20_000
#: Most faces of a mesh file (OBJ ``f`` lines, STL triangles).
MAX_MESH_FACES = 40_000
#: Smallest full extent (m) of the bounding box along any axis: thinner is degenerate.
MIN_EXTENT_M = 1e-3
#: Smallest volume (m^3) of the convex hull: 1 mm^3.
MIN_VOLUME_M3 = 1e-9
_PROBE_DENSITY = 1000.0  # kg/m^3, MuJoCo's default: body mass / density = hull volume


@dataclass(frozen=True)
class MeshData:
    """A checked mesh file.

    Attributes:
        path: the path as written in the scene (relative to the workspace).
        file: the resolved absolute path that was read.
        scale: uniform scale applied to the vertices.
        sha256: hex digest of :attr:`data`.
        center: (3,) centre of the scaled bounding box in the mesh file's frame, m.
        half_extents: (3,) half sizes of the scaled bounding box, m.
        volume_m3: volume of the scaled convex hull, m^3.
        data: the file's bytes, as checked (compiled from memory, never re-read).
    """

    path: str
    file: str
    scale: float
    sha256: str
    center: tuple[float, float, float]
    half_extents: tuple[float, float, float]
    volume_m3: float
    data: bytes = field(repr=False, compare=False)

    @property
    def asset_name(self) -> str:
        """Name of the in-memory asset the model compiles (content-addressed)."""
        return f"mesh_{self.sha256[:16]}{Path(self.file).suffix.lower()}"


def _resolve(path: str, root: Path, where: str) -> Path:
    if not isinstance(path, str) or not path.strip():
        raise TargetError(f"{where}: mesh must be a file path relative to the workspace, got {path!r}")
    rel = Path(path)
    if rel.is_absolute():
        raise TargetError(f"{where}: mesh {path!r} must be relative to the workspace ({root})")
    suffix = rel.suffix.lower()
    if suffix not in MESH_FORMATS:
        raise TargetError(f"{where}: mesh {path!r} is not a supported format; valid formats: "
                          f"{format_choices(MESH_FORMATS)}")
    root = root.resolve()
    candidate = root / rel
    if ".." in rel.parts and root not in Path(os.path.normpath(candidate)).parents:
        raise TargetError(f"{where}: mesh {path!r} resolves outside the workspace ({root}); "
                          "copy the file into the workspace")
    try:
        resolved = candidate.resolve(strict=True)
    except FileNotFoundError:
        raise TargetError(f"{where}: mesh file {path!r} does not exist in the workspace ({root})") from None
    except (OSError, RuntimeError) as exc:  # a symlink loop, a permission problem
        raise TargetError(f"{where}: mesh file {path!r} cannot be resolved: {exc}") from None
    if resolved != root and root not in resolved.parents:
        via = " through a symlink" if resolved != Path(os.path.normpath(candidate)) else ""
        raise TargetError(f"{where}: mesh {path!r} resolves{via} outside the workspace ({root}); "
                          "copy the file into the workspace")
    if not resolved.is_file():
        raise TargetError(f"{where}: mesh {path!r} is not a regular file")
    return resolved


_OBJ_VERTEX = re.compile(rb"(?m)^[ \t]*v[ \t]")
_OBJ_FACE = re.compile(rb"(?m)^[ \t]*f[ \t]")
_STL_ASCII_VERTEX = re.compile(rb"(?i)\bvertex\b")
_STL_ASCII_FACET = re.compile(rb"(?i)\bfacet\b")


def mesh_counts(data: bytes, suffix: str) -> tuple[int, int]:
    """``(vertices, faces)`` declared by mesh file bytes, counted without decoding them
    (linear scans in C): OBJ ``v``/``f`` lines; binary STL its triangle count (three
    vertices each), or the declared count when the size does not match it; ASCII STL
    its ``vertex``/``facet`` keywords."""
    if suffix == ".obj":
        return len(_OBJ_VERTEX.findall(data)), len(_OBJ_FACE.findall(data))
    if suffix == ".stl":
        if data[:5].lower() == b"solid" and b"facet" in data[:4096].lower():
            return len(_STL_ASCII_VERTEX.findall(data)), len(_STL_ASCII_FACET.findall(data))
        if len(data) >= 84:
            declared = int.from_bytes(data[80:84], "little")
            actual = (len(data) - 84) // 50
            n = max(declared, actual)
            return 3 * n, n
    return 0, 0


def load_mesh(path: str, *, root: str | Path, scale: float = 1.0, where: str = "mesh") -> MeshData:
    """Check and read the mesh file ``path`` (relative to the workspace ``root``).

    Args:
        path: relative path as written in the scene.
        root: the workspace root directory.
        scale: uniform scale (> 0) applied to the vertices.
        where: prefix of error messages (e.g. ``"object 'nut'"``).

    Returns:
        The :class:`MeshData` (bounding box after scale, hull volume, the bytes read).

    Raises:
        TargetError: a missing file, an unsupported format, a path resolving outside the
            workspace (``..``, absolute, or a symlink out), a file larger than
            :data:`MAX_MESH_BYTES` or with more than :data:`MAX_MESH_VERTICES` vertices
            or :data:`MAX_MESH_FACES` faces, a file MuJoCo cannot decode, or a degenerate mesh
            (no volume, an extent below :data:`MIN_EXTENT_M`).
    """
    if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not math.isfinite(scale) or scale <= 0:
        raise TargetError(f"{where}: scale must be a positive number, got {scale!r}")
    file = _resolve(path, Path(root), where)
    size = file.stat().st_size
    if size > MAX_MESH_BYTES:
        raise TargetError(f"{where}: mesh {path!r} is {size} bytes, more than the limit of {MAX_MESH_BYTES}")
    with open(file, "rb") as fh:
        data = fh.read(MAX_MESH_BYTES + 1)
    if len(data) > MAX_MESH_BYTES:  # grew after the stat
        raise TargetError(f"{where}: mesh {path!r} is more than {MAX_MESH_BYTES} bytes")
    vertices, faces = mesh_counts(data, file.suffix.lower())
    if vertices > MAX_MESH_VERTICES or faces > MAX_MESH_FACES:
        raise TargetError(f"{where}: mesh {path!r} has {vertices} vertices and {faces} faces, more than the limit of "
                          f"{MAX_MESH_VERTICES} vertices and {MAX_MESH_FACES} faces; simplify it (a graspable "
                          "object needs a few thousand faces)")
    sha = hashlib.sha256(data).hexdigest()
    # Content-addressed, as in the scene (MeshData.asset_name): MuJoCo keeps decoded
    # assets in a process-wide cache that a fixed name like "probe.obj" would hit with
    # another file of the same size, and the probe would measure that file instead.
    asset = f"probe_{sha[:32]}{file.suffix.lower()}"
    spec = mujoco.MjSpec()
    spec.assets = {asset: data}
    spec.add_mesh(name="probe", file=asset, scale=[float(scale)] * 3)
    body = spec.worldbody.add_body(name="probe")
    body.add_freejoint()
    body.add_geom(type=mujoco.mjtGeom.mjGEOM_MESH, meshname="probe", density=_PROBE_DENSITY)
    try:
        model = spec.compile()
    except Exception as exc:  # noqa: BLE001 - mujoco raises ValueError with the decoder's message
        detail = " ".join(str(exc).replace(asset, path).split())[:300]
        kind = "degenerate (it has no volume)" if "coplanar" in detail or "volume" in detail else "unreadable"
        raise TargetError(f"{where}: mesh {path!r} is {kind}: {detail}") from None
    n, adr = int(model.mesh_vertnum[0]), int(model.mesh_vertadr[0])
    R = np.empty(9)
    mujoco.mju_quat2Mat(R, model.geom_quat[0])
    # MuJoCo recentres a mesh on its hull's centroid (geom_pos/quat carry the offset):
    # undo it to get the vertices in the file's frame, scaled.
    verts = model.mesh_vert[adr:adr + n] @ R.reshape(3, 3).T + model.geom_pos[0]
    lo, hi = verts.min(axis=0), verts.max(axis=0)
    extent = hi - lo
    volume = float(model.body_mass[1]) / _PROBE_DENSITY
    if float(extent.min()) < MIN_EXTENT_M or volume < MIN_VOLUME_M3:
        raise TargetError(f"{where}: mesh {path!r} is degenerate: bounding box {np.round(extent, 5).tolist()} m, "
                          f"hull volume {volume:.3g} m^3 (need every extent >= {MIN_EXTENT_M} m and a volume "
                          f">= {MIN_VOLUME_M3} m^3)")
    center = 0.5 * (lo + hi)
    return MeshData(path=path, file=str(file), scale=float(scale), sha256=sha,
                    center=tuple(float(c) for c in center), half_extents=tuple(float(e) / 2.0 for e in extent),
                    volume_m3=volume, data=data)
