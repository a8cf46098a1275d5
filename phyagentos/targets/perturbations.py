"""Seeded perturbations of the MuJoCo tabletop: documented ways a task genuinely fails.

A session's scene may list them under ``perturbations``::

    scene:
      objects: [{name: cube, ...}]
      perturbations:
        - {kind: perception_noise, sigma_m: 0.03}
        - {kind: low_friction, object: cube, friction: [0.02, 0.04]}
        - {kind: displaced, object: cube, distance_m: [0.04, 0.06]}
        - {kind: heavy_object, object: cube, mass_kg: [1.2, 1.8], friction: 0.5}

A value written ``[lo, hi]`` is drawn uniformly from that range; a plain number is used
as is.

==================  ====================================================================
kind                effect (defaults in brackets)
==================  ====================================================================
perception_noise    every perceived object position (``MuJoCoTarget.perceive``) gets
                    zero-mean Gaussian noise in x and y, standard deviation ``sigma_m``
                    [0.03 m] per axis and per frame; ``perceive(samples=N)`` averages N
                    frames (noise sigma / sqrt(N)). ``object`` limits it to one object.
                    Ground-truth snapshots (evidence, grasp checks) are not affected.
low_friction        ``object``'s surface friction becomes ``friction`` [0.02 .. 0.04]
                    (oily or wet) and governs its contacts, finger pads included: at
                    the default grip (about 10 N per finger) a 0.1 kg box slips out when
                    lifted; a grip of 30 N or more holds it.
displaced           right after the first perception of a session that sees ``object``
                    resting on the table, the object is pushed ``distance_m``
                    [0.04 .. 0.06 m] in a random horizontal direction, i.e. the
                    observation is stale before the robot acts. Directions that would
                    take it farther than ``distance_m`` from its place in the scene, or
                    not clear of obstacles and other objects, are skipped, so repeated
                    sessions of an episode do not walk it across the table.
heavy_object        ``object`` becomes a dense metal block: mass ``mass_kg`` [1.2 .. 1.8 kg]
                    and surface friction ``friction`` [0.5] against the pads: at the
                    default grip it slips out when lifted; 40 N holds it.
==================  ====================================================================

Seeding (reproducible, and the same for a parent session and its replanned child):

- values of the episode (friction, mass, displacement distance) are drawn from the
  perturbation's own ``seed`` [0] and its index in the list, so every session of an
  episode sees the same object;
- per-session randomness (noise frames, displacement direction) is drawn from the
  perturbation's ``seed`` and the session's seed.

The draws are recorded (:meth:`ActivePerturbations.record`) in the evidence bundle's
``perturbations.yaml`` for audit; the Agent's verifier and diagnosis never read it.
Friction and mass act on the model, so :class:`~phyagentos.targets.franka_tabletop.MuJoCoTarget`
restores its nominal values before installing the next session's perturbations.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from phyagentos.errors import TargetError, format_choices

__all__ = [
    "KINDS",
    "PerturbationSpec",
    "ActivePerturbations",
    "parse_perturbations",
    "split_scene",
]

logger = logging.getLogger(__name__)

# kind -> (keys with defaults, whether ``object`` is required)
_SCHEMA: dict[str, tuple[dict[str, Any], bool]] = {
    "perception_noise": ({"sigma_m": 0.03}, False),
    "low_friction": ({"friction": (0.02, 0.04)}, True),
    "displaced": ({"distance_m": (0.04, 0.06)}, True),
    "heavy_object": ({"mass_kg": (1.2, 1.8), "friction": 0.5}, True),
}
KINDS: tuple[str, ...] = tuple(_SCHEMA)
_COMMON_KEYS = ("kind", "object", "seed")
#: Contact priority that makes an object's own friction govern its contacts (the
#: scene gives the finger pads priority 1, see phyagentos.targets.scene).
_SURFACE_PRIORITY = 2
#: Clearance kept between a displaced object and obstacles or other objects, m.
_DISPLACE_CLEARANCE_M = 0.01


@dataclass(frozen=True)
class PerturbationSpec:
    """One declared perturbation (see the module docstring for kinds and keys).

    Attributes:
        kind: one of :data:`KINDS`.
        object: the object it acts on (``None``: every object; perception noise only).
        params: the kind's keys, each a number or a ``(lo, hi)`` range.
        seed: seed of the episode-level draws (default 0).
    """

    kind: str
    object: str | None
    params: Mapping[str, Any]
    seed: int = 0


def _value(raw: Any, where: str) -> float | tuple[float, float]:
    if isinstance(raw, (int, float)) and not isinstance(raw, bool) and math.isfinite(raw):
        return float(raw)
    if isinstance(raw, Sequence) and not isinstance(raw, str) and len(raw) == 2:
        lo, hi = (_value(v, where) for v in raw)
        if not isinstance(lo, float) or not isinstance(hi, float) or lo > hi:
            raise TargetError(f"{where}: a range must be [lo, hi] with lo <= hi, got {raw!r}")
        return (lo, hi)
    raise TargetError(f"{where}: expected a number or a [lo, hi] range, got {raw!r}")


def parse_perturbations(raw: Any, *, objects: Sequence[str]) -> tuple[PerturbationSpec, ...]:
    """Validate a scene's ``perturbations`` list.

    Args:
        raw: the list (``None`` for none).
        objects: names of the scene's objects (an ``object`` must be one of them).

    Raises:
        TargetError: not a list, an unknown kind or key (valid ones listed), a missing
            ``object``, an unknown object, or a value that is not a number or range.
    """
    if raw is None:
        return ()
    if not isinstance(raw, Sequence) or isinstance(raw, (str, bytes)):
        raise TargetError(f"scene perturbations must be a list, got {type(raw).__name__}")
    out = []
    for i, item in enumerate(raw):
        where = f"scene perturbations[{i}]"
        if not isinstance(item, Mapping) or "kind" not in item:
            raise TargetError(f"{where}: expected a mapping with 'kind' (one of {format_choices(KINDS)}), got {item!r}")
        kind = item["kind"]
        if kind not in _SCHEMA:
            raise TargetError(f"{where}: unknown kind {kind!r}; valid kinds: {format_choices(KINDS)}")
        defaults, needs_object = _SCHEMA[kind]
        unknown = set(item) - set(defaults) - set(_COMMON_KEYS)
        if unknown:
            raise TargetError(f"{where} ({kind}): unknown key(s) {format_choices(unknown)}; "
                              f"valid keys: {format_choices((*_COMMON_KEYS, *defaults))}")
        obj = item.get("object")
        if obj is None and needs_object:
            raise TargetError(f"{where} ({kind}): needs 'object' (one of {format_choices(objects)})")
        if obj is not None and obj not in objects:
            raise TargetError(f"{where} ({kind}): unknown object {obj!r}; objects: {format_choices(objects)}")
        seed = item.get("seed", 0)
        if not isinstance(seed, int) or isinstance(seed, bool) or seed < 0:
            raise TargetError(f"{where} ({kind}): seed must be an integer >= 0, got {seed!r}")
        params = {k: _value(item.get(k, d), f"{where}.{k}") for k, d in defaults.items()}
        for key, v in params.items():
            if min(v if isinstance(v, tuple) else (v,)) < 0:
                raise TargetError(f"{where}.{key} must be >= 0, got {v!r}")
        out.append(PerturbationSpec(kind=kind, object=obj, params=params, seed=seed))
    return tuple(out)


def split_scene(raw: Mapping[str, Any] | None) -> tuple[dict[str, Any], Any]:
    """``(scene without 'perturbations', the raw perturbations list or None)``."""
    if not raw:
        return {}, None
    scene = {k: v for k, v in raw.items() if k != "perturbations"}
    return scene, raw.get("perturbations")


def _draw(rng: np.random.Generator, v: float | tuple[float, float]) -> float:
    return float(rng.uniform(v[0], v[1])) if isinstance(v, tuple) else float(v)


@dataclass
class _Active:
    spec: PerturbationSpec
    index: int
    values: dict[str, float]
    session_rng: np.random.Generator
    fired: bool = False
    events: list[dict[str, Any]] = field(default_factory=list)


class ActivePerturbations:
    """The perturbations of one session on one target, with their draws.

    Args:
        specs: parsed specs (:func:`parse_perturbations`).
        session_seed: the session's seed (``None`` counts as 0).
    """

    def __init__(self, specs: Sequence[PerturbationSpec], *, session_seed: int | None):
        self.specs = tuple(specs)
        s = int(session_seed or 0)
        self._items: list[_Active] = []
        for i, spec in enumerate(self.specs):
            episode_rng = np.random.default_rng([spec.seed, i, KINDS.index(spec.kind)])
            values = {k: _draw(episode_rng, v) for k, v in spec.params.items()}
            session_rng = np.random.default_rng([spec.seed, i, s, 1])
            self._items.append(_Active(spec=spec, index=i, values=values, session_rng=session_rng))
        self._perceptions = 0

    def __bool__(self) -> bool:
        return bool(self._items)

    # -- model-level effects --------------------------------------------------------

    def apply_model(self, model, *, object_geoms: Mapping[str, int], object_bodies: Mapping[str, int]) -> None:
        """Write friction and mass changes into ``model`` (a ``mujoco.MjModel``).

        Mass changes scale the body's inertia by the same factor (same shape, denser).
        """
        for item in self._items:
            kind, obj = item.spec.kind, item.spec.object
            if kind in ("low_friction", "heavy_object"):
                g = object_geoms[obj]
                model.geom_friction[g, 0] = item.values["friction"]
                model.geom_priority[g] = _SURFACE_PRIORITY
            if kind == "heavy_object":
                b = object_bodies[obj]
                factor = item.values["mass_kg"] / float(model.body_mass[b])
                model.body_mass[b] *= factor
                model.body_inertia[b] *= factor

    # -- perception ----------------------------------------------------------------

    def perceive(self, snapshot: dict, *, samples: int, target) -> dict:
        """Apply perception noise to ``snapshot`` (in place) and fire displacements.

        Args:
            snapshot: a ground-truth snapshot (``MuJoCoTarget.snapshot``).
            samples: frames averaged (>= 1).
            target: the target (displacements move its objects after this perception).

        Returns:
            ``snapshot`` with noisy object positions.
        """
        held = {r["object"] for r in snapshot.get("relations", []) if r.get("relation") == "holding"}
        for item in self._items:
            if item.spec.kind != "perception_noise":
                continue
            sigma = item.values["sigma_m"]
            for ent in snapshot.get("entities", []):
                if ent.get("kind") != "object" or (item.spec.object and ent["name"] != item.spec.object):
                    continue
                noise = item.session_rng.normal(0.0, sigma, size=(samples, 2)).mean(axis=0)
                ent["position"][0] += float(noise[0])
                ent["position"][1] += float(noise[1])
        self._perceptions += 1
        for item in self._items:
            if item.spec.kind == "displaced" and not item.fired and item.spec.object not in held:
                item.fired = True
                self._displace(item, target)
        return snapshot

    def _displace(self, item: _Active, target) -> None:
        name = item.spec.object
        distance = item.values["distance_m"]
        T = target.object_pose(name)
        start = T[:2, 3].copy()
        origin = np.asarray(target.scene.object(name).position[:2], dtype=float)
        first = float(item.session_rng.uniform(0.0, 2.0 * math.pi))
        for k in range(16):
            angle = first + k * (2.0 * math.pi / 16.0)
            goal = start + distance * np.array([math.cos(angle), math.sin(angle)])
            if np.linalg.norm(goal - origin) > distance * 1.01 + 1e-9:
                continue
            if target.footprint_clear(name, goal, clearance_m=_DISPLACE_CLEARANCE_M):
                target.move_object(name, goal)
                item.events.append({"code": "perturbation.displaced", "object": name,
                                    "from": [round(float(x), 4) for x in start],
                                    "to": [round(float(x), 4) for x in goal], "sim_time_s": round(target.sim_time, 4)})
                logger.info("perturbation: %s displaced by %.3f m", name, distance)
                return
        item.events.append({"code": "perturbation.displace_blocked", "object": name})

    # -- audit ---------------------------------------------------------------------

    def record(self) -> list[dict[str, Any]]:
        """What was declared, what was drawn and what happened (YAML-ready)."""
        return [
            {
                "kind": it.spec.kind,
                "object": it.spec.object,
                "seed": it.spec.seed,
                "drawn": {k: round(v, 6) for k, v in it.values.items()},
                "events": list(it.events),
            }
            for it in self._items
        ]
