"""Appearance descriptors of LIBERO's object categories, measured from generated scenes.

A LIBERO task declares its objects by name and category only (``alphabet_soup_1 -
alphabet_soup``). The perceiver associates what it segments from RGB-D with declared objects
by colour, size and shape (:mod:`phyagentos.perception.association`), so each category needs
those as a user would declare them. The object models are known (their meshes and textures
ship in LIBERO's asset wheels), so the descriptors are measured on *generated* scenes, never
on an evaluation init state:

for each object of a built LIBERO world, every other object is moved out of the cameras' view,
the object is set upright at a fixed spot (:data:`SPOT_XY`, yaw 0) on the support surface,
physics settles it for 1 s, both cameras are captured and the project's own perceiver
(no declared objects) reports the one thing it sees: its shape, median top-face colour
and size. That is the category's descriptor (``{shape, colour, size_m}``, size the full
extents, m, long side first).

The world is left disturbed: call :meth:`~phyagentos.targets.libero.target.LiberoTarget.reset`
afterwards (:func:`measure_descriptors` does).
"""

from __future__ import annotations

import logging
from typing import Any

import mujoco
import numpy as np

from phyagentos.errors import TargetError

__all__ = ["SPOT_XY", "measure_descriptors"]

log = logging.getLogger(__name__)

#: Where each object is set down to be measured, world xy in m (in front of the robot, in
#: both cameras' view in LIBERO's scenes).
SPOT_XY = (0.05, -0.15)
_AWAY = 20.0  # m: where the other objects wait (far outside every camera's view)


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
    from phyagentos.perception import Perceiver  # noqa: PLC0415

    m, d = target.model, target.data
    names = list(target._obj_names)
    cats = target._problem.objects
    adr = {n: _free_adr(m, target._obj_body[n]) for n in names}
    out: dict[str, dict[str, Any]] = {}
    try:
        for name in names:
            cat = cats[name]
            if cat in out or adr[name] is None:
                continue
            target.reset(seed=target.init_index)
            for k, other in enumerate(names):
                if other != name and adr[other] is not None:
                    qa, da = adr[other]
                    d.qpos[qa:qa + 3] = (_AWAY + 2.0 * k, _AWAY, 1.0)
                    d.qvel[da:da + 6] = 0.0
            qa, da = adr[name]
            d.qpos[qa:qa + 3] = (SPOT_XY[0], SPOT_XY[1], float(d.qpos[qa + 2]) + 0.02)
            d.qpos[qa + 3:qa + 7] = (1.0, 0.0, 0.0, 0.0)
            d.qvel[da:da + 6] = 0.0
            mujoco.mj_forward(m, d)
            target.hold(duration_s=settle_s)
            for other in names:  # keep the waiting objects from falling forever
                if other != name and adr[other] is not None:
                    d.qvel[adr[other][1]:adr[other][1] + 6] = 0.0
            frames = [target.capture(s) for s in target.camera_names()]
            snap = Perceiver().observe(frames, target.proprioception())
            seen = [e for e in snap["entities"] if e.get("kind") == "unknown"
                    and np.linalg.norm(np.subtract(e["position"][:2], SPOT_XY)) < 0.12]
            log.debug("descriptor %s: true %s, seen %s", cat, d.qpos[qa:qa + 3].round(3).tolist(),
                      [(e["name"], e["position"]) for e in snap["entities"]])
            if len(seen) != 1:
                log.warning("LIBERO descriptor of %s: %d things seen alone at the spot; left out", cat, len(seen))
                continue
            e = seen[0]
            half = sorted((float(e["size"][0]), float(e["size"][1])), reverse=True) + [float(e["size"][2])]
            out[cat] = {"shape": e["attributes"].get("shape", "box"),
                        "colour": [round(float(c), 3) for c in e["attributes"]["colour_rgb"]],
                        "size_m": [round(2.0 * h, 4) for h in half]}
    except TargetError:
        raise
    finally:
        target.reset(seed=target.init_index)
    return out
