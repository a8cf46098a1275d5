"""Appearance descriptors of LIBERO's object categories, measured from generated scenes.

A LIBERO task declares its objects by name and category only (``alphabet_soup_1 -
alphabet_soup``). The perceiver associates what it segments from RGB-D with declared objects
by colour, size and shape (:mod:`phyagentos.perception.association`), so each category needs
those as a user would declare them. The object models are known (their meshes and textures
ship in LIBERO's asset wheels), so the descriptors are measured on *generated* scenes, never
on an evaluation init state:

for each object of a built LIBERO world, LIBERO's own placement sampler generates a scene
(``env.reset()`` seeded, no fixed init state), every other object is moved out of the cameras'
view, the object is moved to a spot (:data:`SPOTS_XY`) keeping the orientation LIBERO's
sampler gave it (how LIBERO stands that model up), physics settles it for 1 s, both cameras are captured and the project's own perceiver
(no declared objects) reports the one thing it sees: its shape, median top-face colour and
size. The category's descriptor (``{shape, colour, size_m}``, size the full extents, m, long
side first) is the median over the spots (the most frequent shape).

The world is left disturbed: call :meth:`~phyagentos.targets.libero.target.LiberoTarget.reset`
afterwards (:func:`measure_descriptors` does).
"""

from __future__ import annotations

import logging
from typing import Any

import mujoco
import numpy as np

from phyagentos.errors import TargetError

__all__ = ["SPOTS_XY", "measure_descriptors"]

log = logging.getLogger(__name__)

#: Where each object is set down to be measured, world xy in m: four spots spread over the
#: part of LIBERO's scenes both cameras see (the look is the median over them).
SPOTS_XY: tuple[tuple[float, float], ...] = ((0.05, -0.15), (-0.15, -0.2), (-0.15, 0.12), (0.1, 0.12))
_AWAY = 20.0  # m: where the other objects wait (far outside every camera's view)
#: How close to the spot a detection's centre must be to be the object measured, m.
_AT_SPOT_M = 0.04
#: Seed of LIBERO's own placement sampler for the generated scenes (not an init state).
_GENERATOR_SEED = 12345


def _free_adr(m: mujoco.MjModel, body: int) -> tuple[int, int] | None:
    j = int(m.body_jntadr[body])
    if j < 0 or m.jnt_type[j] != mujoco.mjtJoint.mjJNT_FREE:
        return None
    return int(m.jnt_qposadr[j]), int(m.jnt_dofadr[j])


def measure_descriptors(target, *, settle_s: float = 1.0) -> dict[str, dict[str, Any]]:
    """``{category: {"shape", "colour" (3,) sRGB 0..1, "size_m" (3,) m}}`` for every object
    category of ``target``'s task, measured alone on a generated scene (module docstring);
    ``target`` is reset afterwards. Categories the perceiver does not see alone (too flat,
    out of view) are left out.

    Raises:
        TargetError: the target is closed or cannot render.
    """
    m = target.model
    names = list(target._obj_names)
    cats = target._problem.objects
    adr = {n: _free_adr(m, target._obj_body[n]) for n in names}
    out: dict[str, dict[str, Any]] = {}
    try:
        for name in names:
            cat = cats[name]
            if cat in out or adr[name] is None:
                continue
            looks = [look for xy in SPOTS_XY if (look := _look_alone(target, name, names, adr, xy, settle_s)) is not None]
            if len(looks) < 2:
                log.warning("LIBERO descriptor of %s: seen alone at %d of %d spots; left out", cat, len(looks), len(SPOTS_XY))
                continue
            shapes = [lk["shape"] for lk in looks]
            out[cat] = {"shape": max(set(shapes), key=shapes.count),
                        "colour": [round(float(c), 3) for c in np.median([lk["colour"] for lk in looks], axis=0)],
                        "size_m": [round(float(c), 4) for c in np.median([lk["size_m"] for lk in looks], axis=0)]}
    except TargetError:
        raise
    finally:
        target.reset(seed=target.init_index)
    return out


def _look_alone(target, name, names, adr, xy, settle_s) -> dict[str, Any] | None:
    """Shape, colour and size of object ``name`` set down alone at ``xy``: the detection whose
    centre is within :data:`_AT_SPOT_M` of the spot; ``None`` when there is none."""
    from phyagentos.perception import Perceiver  # noqa: PLC0415

    m, d = target.model, target.data
    target.generate_scene(seed=_GENERATOR_SEED)
    for k, other in enumerate(names):
        if other != name and adr[other] is not None:
            qa, da = adr[other]
            d.qpos[qa:qa + 3] = (_AWAY + 2.0 * k, _AWAY, 1.0)
            d.qvel[da:da + 6] = 0.0
    qa, da = adr[name]
    d.qpos[qa:qa + 3] = (xy[0], xy[1], float(d.qpos[qa + 2]) + 0.02)  # orientation: as LIBERO's sampler set it
    d.qvel[da:da + 6] = 0.0
    mujoco.mj_forward(m, d)
    target.hold(duration_s=settle_s)
    frames = [target.capture(s) for s in target.camera_names()]
    snap = Perceiver().observe(frames, target.proprioception())
    seen = sorted((float(np.linalg.norm(np.subtract(e["position"][:2], xy))), i) for i, e in
                  enumerate(snap["entities"]) if e.get("kind") == "unknown")
    log.debug("look of %s at %s: true %s, seen %s", name, xy, d.qpos[qa:qa + 3].round(3).tolist(),
              [(e["name"], e["position"]) for e in snap["entities"]])
    # the thing whose centre is at the spot (a container's walls may also be seen apart)
    if not seen or seen[0][0] > _AT_SPOT_M:
        return None
    e = snap["entities"][seen[0][1]]
    half = sorted((float(e["size"][0]), float(e["size"][1])), reverse=True) + [float(e["size"][2])]
    return {"shape": e["attributes"].get("shape", "box"), "colour": e["attributes"]["colour_rgb"],
            "size_m": [2.0 * h for h in half]}
