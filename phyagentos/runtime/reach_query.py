"""The Runtime's answer to a :class:`~phyagentos.protocol.reach.ReachQuery`: IK on the target's model.

The same check the graph preflight runs (:func:`~phyagentos.runtime.graph_preflight.check_reachability`:
mink IK of every top-down grasp and pre-grasp of the picked object, and of the place and
pre-place pose over the destination, seeded from the home configuration), on the query's
scene with the objects at their *perceived* positions. An object the query gives no
position for is not checked: the answer is ``unknown`` rather than a guess from the
declared scene. Nothing is stepped and nothing is written.
"""

from __future__ import annotations

import copy
import dataclasses
import logging
from typing import Any

from phyagentos.protocol.reach import ReachAnswer, ReachQuery

from .graph_preflight import PickPose, PlacePose, check_reachability, check_scene

__all__ = ["answer_reach_query"]

logger = logging.getLogger(__name__)


def _perceived_scene(query: ReachQuery) -> dict[str, Any]:
    scene = copy.deepcopy(dict(query.scene))
    for obj in scene.get("objects") or []:
        if isinstance(obj, dict) and obj.get("name") in query.positions:
            xy = query.positions[obj["name"]]
            obj["position"] = [float(xy[0]), float(xy[1]), *list(obj.get("position", []))[2:3]]
    return scene


def _at_perceived_positions(scene: Any, query: ReachQuery) -> Any:
    """A randomised scene (``randomise``) is drawn when its target is built, which would put every
    object at its *drawn* position; the answer must rest on the perceived ones. So the world is
    drawn here and the perceived objects are moved to their perceived (x, y) (shape and size stay
    the drawn ones: the runtime's own model of the object); the draw is not asked again."""
    if not getattr(scene, "randomise", None) or not query.positions:
        return scene
    from phyagentos.targets.world import draw_world  # noqa: PLC0415

    drawn, _ = draw_world(scene)
    objects = tuple(dataclasses.replace(o, position=(float(query.positions[o.name][0]), float(query.positions[o.name][1])))
                    if o.name in query.positions else o for o in drawn.objects)
    return dataclasses.replace(drawn, objects=objects, randomise=None)


def answer_reach_query(query: ReachQuery, *, root: Any = None) -> ReachAnswer:
    """Whether ``query.target`` reaches the query's pick and place poses (see the module docstring).

    Args:
        query: the node's poses, target and scene.
        root: the workspace root that the scene's mesh files (``shape: mesh``) are read
            from; ``None``: a scene with a mesh object is ``unsupported``.
    """
    scene, problems = check_scene(_perceived_scene(query), query.driver, root=root)
    if scene is None:
        return ReachAnswer(status="unsupported", reasons=[p.message for p in problems] or ["scene not modelled"])
    scene = _at_perceived_positions(scene, query)
    objects = {o.get("name") for o in query.scene.get("objects") or [] if isinstance(o, dict)}

    def unseen(*names: str | None) -> list[str]:
        return [n for n in dict.fromkeys(names) if n and n in objects and n not in query.positions]

    # What is known is checked; what is not perceived is not (a place needs the destination's
    # position only: the hold is relative to the object). The arm's start pose is always checked.
    pick_unseen = unseen(query.pick)
    place_unseen = unseen(query.place[1]) if query.place else []
    picks = [PickPose(node="query", obj=query.pick, line=None)] if query.pick and not pick_unseen else []
    places = ([PlacePose(node="query", obj=query.place[0], region=query.place[1], line=None)]
              if query.place and not place_unseen else [])
    try:
        found = check_reachability(query.driver, query.target, scene, picks=picks, places=places)
    except KeyError as exc:  # a name the scene does not have
        return ReachAnswer(status="unsupported", reasons=[f"not in the scene: {exc}"])
    if found:
        return ReachAnswer(status="unreachable", reasons=[p.message for p in found])
    missing = pick_unseen + place_unseen
    if missing:
        checked = "the place pose solves; " if places else ""
        return ReachAnswer(status="unknown", reasons=[f"{checked}{', '.join(missing)} not perceived yet: reach is "
                                                      f"checked once the position is known (the runtime's preflight)"])
    return ReachAnswer(status="reachable", reasons=[f"IK solves every pose on {query.target}'s model"])
