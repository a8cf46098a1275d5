"""RGB images of the scene for the evidence bundle, rendered headless by the target.

The SessionRunner saves ``initial.png`` before the skill runs and ``terminal.png``
after, next to the snapshots. Rendering is the target's (MuJoCo offscreen, OSMesa on a
machine without a display); shadows are off because under OSMesa they cost ~5x the
render time (0.19 s vs 0.035 s for 320x240 measured here). Which images survive is the
Agent's retention policy (failures keep theirs; successes only if configured).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from phyagentos.errors import TargetError

__all__ = ["EVIDENCE_IMAGE_SIZE", "save_scene_image"]

logger = logging.getLogger(__name__)

#: (width, height) of evidence images in pixels.
EVIDENCE_IMAGE_SIZE = (320, 240)


def save_scene_image(target: Any, path: str | Path, *, events: list | None = None) -> str | None:
    """Render ``target``'s overview camera to the PNG ``path``; return its file name.

    Returns ``None`` (and appends a ``target.render_unavailable`` event to ``events``)
    when the target cannot render, e.g. no OpenGL backend or a target without a camera,
    and ``None`` alone for a target that draws no pictures (not
    :class:`~phyagentos.targets.contract.RendersImages`): missing images never fail a session.
    """
    from phyagentos.targets.contract import RendersImages  # noqa: PLC0415 - the package imports MuJoCo

    if not isinstance(target, RendersImages):
        return None
    path = Path(path)
    try:
        from PIL import Image  # noqa: PLC0415 - only needed when images are written

        width, height = EVIDENCE_IMAGE_SIZE
        pixels = target.render(width=width, height=height, shadows=False)
        Image.fromarray(pixels).save(path, format="PNG")
    except (TargetError, OSError, TypeError, ValueError) as exc:
        logger.warning("evidence image %s not written: %s", path.name, exc)
        if events is not None:
            events.append({"code": "target.render_unavailable", "message": f"{path.name}: {exc}"})
        return None
    return path.name
