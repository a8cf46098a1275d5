"""Target drivers and the world state that outlives a session.

A run of a goal graph is one episode: a ``place`` session must find the cube where
the ``pick`` session left it. Real robots keep their state by existing; simulated
targets keep it as a file (``targets/<name>/state.npz`` plus ``state.yaml`` naming
the run and scene it belongs to), so any runner process can continue the episode.
The first session of a new run (or a changed scene) resets the target with the
session's seed.
"""

from __future__ import annotations

import copy
import hashlib
import json
import logging
from pathlib import Path
from typing import Any, Mapping

from phyagentos.errors import TargetError
from phyagentos.protocol import SessionRecord, TargetSpec
from phyagentos.protocol.atomic import atomic_write_text
from phyagentos.protocol.codec import dump_yaml
from phyagentos.protocol.sensors import read_sensors
from phyagentos.targets import SceneSpec
from phyagentos.targets.perturbations import ActivePerturbations, PerturbationSpec, parse_perturbations, split_scene
from phyagentos.targets.registry import DRIVERS, get_target_class
from phyagentos.yamlsource import load_yaml

__all__ = ["DRIVERS", "TargetPool", "scene_for", "perturbations_for"]

logger = logging.getLogger(__name__)

# DRIVERS (re-exported): the read-only view of phyagentos.targets.registry (driver name -> class).


def scene_for(session: SessionRecord, spec: TargetSpec, *, root: str | Path | None = None) -> SceneSpec:
    """The scene of a session: its own ``scene``, else the target's, else the default
    (without its ``perturbations``, see :func:`perturbations_for`). ``root`` is the
    workspace root that mesh objects' files are read from."""
    return _scene_of(spec, session.scene, root=root)


def _scene_of(spec: TargetSpec, scene: Mapping[str, Any] | None, *, root: str | Path | None) -> SceneSpec:
    raw, _ = split_scene(scene or spec.scene or None)
    # Target.scene_from_dict: the tabletop SceneSpec, unless the driver has its own scene
    # type (e.g. FrankaKitchen's task list).
    return get_target_class(spec.driver).scene_from_dict(raw, root=root)


def perturbations_for(session: SessionRecord, spec: TargetSpec, *,
                      root: str | Path | None = None) -> tuple[PerturbationSpec, ...]:
    """The validated ``perturbations`` of the session's scene (:mod:`phyagentos.targets.perturbations`).

    Raises:
        TargetError: a malformed perturbation (the message lists valid kinds and keys).
    """
    _, raw = split_scene(session.scene or spec.scene or None)
    return parse_perturbations(raw, objects=getattr(scene_for(session, spec, root=root), "object_names", ()))


def _scene_hash(scene: SceneSpec) -> str:
    data = scene.to_dict()
    meshes = [o.mesh_data.sha256 for o in getattr(scene, "objects", ()) if getattr(o, "mesh_data", None)]
    if meshes:  # a mesh file edited between sessions is another world
        data = {**data, "mesh_sha256": meshes}
    return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()[:16]


def _close_target(target) -> None:
    """Close ``target`` and drop what the runtime's caches keep of its MuJoCo model (the IK
    contexts, the safety guard's kinematic chains: each holds the model, so a closed
    world's model would stay alive, a LIBERO world's about 250 MB, until newer models
    push it out of those caches)."""
    model = getattr(target, "model", None) if _mujoco_backed(target) else None
    target.close()
    if model is not None:
        from phyagentos.motion.ik import forget_model  # noqa: PLC0415 - imports mink
        from phyagentos.runtime.safety_guard import ChainFK  # noqa: PLC0415

        forget_model(model)
        ChainFK.forget(model)


def _mujoco_backed(target) -> bool:
    from phyagentos.targets.contract import MuJoCoBacked  # noqa: PLC0415

    return isinstance(target, MuJoCoBacked)


class TargetPool:
    """Builds targets on demand and carries their state between sessions.

    Args:
        state_dir: the workspace's ``targets/`` directory.
    """

    def __init__(self, state_dir: str | Path):
        self.state_dir = Path(state_dir)
        self._live: dict[str, tuple[str, Any]] = {}  # name -> (scene hash, target)
        self._views: dict[str, tuple] = {}  # name -> the last session's terminal view (keep_view)

    def acquire(self, session: SessionRecord, spec: TargetSpec):
        """Return the target for ``session``, in the state the episode left it.

        Raises:
            TargetError: unknown driver (valid drivers listed) or a scene that does not build.
        """
        cls = get_target_class(spec.driver)  # TargetError: unknown driver (the registered ones listed)
        scene = scene_for(session, spec, root=self.state_dir.parent)  # state_dir is <workspace>/targets
        key = _scene_hash(scene)
        target = self._built(cls, spec, scene, key, seed=session.seed)
        meta_path = self.state_dir / spec.name / "state.yaml"
        try:  # bounded like every YAML the project reads; an unreadable record means: reset
            meta = load_yaml(meta_path.read_text(encoding="utf-8"), path=meta_path, error=TargetError) \
                if meta_path.is_file() else None
        except (TargetError, UnicodeDecodeError) as exc:
            logger.warning("target %s: state record unreadable (%s); resetting the world", spec.name, exc)
            meta = None
        if isinstance(meta, dict) and meta.get("run_id") == session.run_id and meta.get("scene") == key:
            target.load_state(self.state_dir / spec.name / "state.npz")
            logger.debug("target %s: continuing episode of run %s", spec.name, session.run_id)
        else:
            target.reset(seed=session.seed)
            logger.debug("target %s: reset for run %s (seed %s)", spec.name, session.run_id, session.seed)
        active = perturbations_for(session, spec, root=self.state_dir.parent)
        target.set_perturbations(ActivePerturbations(active, session_seed=session.seed))
        return target

    def _built(self, cls, spec: TargetSpec, scene, key: str, *, seed: int | None):
        """The live target of ``spec`` for ``scene`` (hash ``key``; built, with its sensors,
        if the pool holds none or one of another scene). Neither reset nor restored here."""
        cached = self._live.get(spec.name)
        if cached is None or cached[0] != key:
            if cached is not None:
                del self._live[spec.name]  # not held while the next world builds
                _close_target(cached[1])
                cached = None  # nor referenced from here
            self._views.pop(spec.name, None)
            target = cls.from_target_spec(spec, scene, seed=seed)
            # the workspace's sensors.yaml entry for this target (read-only deploy config);
            # installed before the target is kept: a refused entry (e.g. a camera larger than
            # the framebuffer) must fail every acquire, not only the first (a warm-up's)
            try:
                sensors = read_sensors(self.state_dir.parent).for_target(spec.name)
                if sensors:
                    target.configure_sensors(sensors)
            except BaseException:
                _close_target(target)
                raise
            self._live[spec.name] = (key, target)
        return self._live[spec.name][1]

    def warm(self, spec: TargetSpec, scene: Mapping[str, Any] | None) -> bool:
        """Build ``spec``'s target for ``scene`` (a goal graph's raw ``scene``; None: the
        target's own) ahead of its first session, and open its cameras' renderers, so
        that :meth:`acquire` finds it built. Moves nothing and writes nothing: the
        session still resets or restores the world (:meth:`acquire`), and a session of
        another scene rebuilds. Returns True if a target was built now.

        Raises:
            TargetError: unknown driver, or a scene that does not build.
        """
        cls = get_target_class(spec.driver)  # TargetError: unknown driver (the registered ones listed)
        before = self._live.get(spec.name)
        built = _scene_of(spec, scene, root=self.state_dir.parent)
        target = self._built(cls, spec, built, _scene_hash(built), seed=None)
        target.prepare_cameras()
        return self._live.get(spec.name) is not before

    def keep_view(self, session: SessionRecord, spec: TargetSpec, target, snapshot: dict, *, key: Any = None) -> None:
        """Remember ``snapshot``, the perceived view of ``target`` at the end of ``session``,
        with the digest of the world it saw (``target.world_digest()``; targets without
        one, e.g. real robots, keep nothing) and ``key`` (whatever else the view depends
        on, e.g. the perception configuration's identity)."""
        digest = target.world_digest()
        self._views.pop(spec.name, None)
        if digest is None:
            return
        perturbed = bool(split_scene(session.scene or spec.scene or None)[1])
        self._views[spec.name] = (session.run_id, id(target), digest, perturbed, key, copy.deepcopy(snapshot))

    def take_view(self, session: SessionRecord, spec: TargetSpec, target, *, key: Any = None) -> dict | None:
        """The view kept by :meth:`keep_view` if ``target`` (just acquired for ``session``) is
        provably in the world that view saw: same run, same live target, equal world
        digest, the same ``key``, and neither session perturbed; else None. A view is
        handed out at most once and forgotten at the first look, so any session that
        moved the target in between (or a failed one) makes the next perceive afresh."""
        view = self._views.pop(spec.name, None)
        if view is None:
            return None
        run_id, target_id, digest, perturbed, view_key, snapshot = view
        if (run_id != session.run_id or target_id != id(target) or perturbed or view_key != key
                or split_scene(session.scene or spec.scene or None)[1]):
            return None
        return snapshot if target.world_digest() == digest else None

    def release(self, session: SessionRecord, target) -> None:
        """Persist the target's world state for the next session of the same run."""
        self.checkpoint(session, target)

    def checkpoint(self, session: SessionRecord, target) -> None:
        """Persist the target's world state now (atomically); the SessionRunner calls this
        periodically while a session runs, so a supervisor recovering a crashed runner
        restores the world as it was at most one checkpoint interval earlier."""
        directory = self.state_dir / target.name
        directory.mkdir(parents=True, exist_ok=True)
        target.save_state(directory / "state.npz")
        key = self._live[target.name][0]
        atomic_write_text(directory / "state.yaml",
                          dump_yaml({"run_id": session.run_id, "session_id": session.session_id, "scene": key}))

    @property
    def keep_when_idle(self) -> bool:
        """Whether a runner may keep this pool's targets while it serves another workspace:
        every live target's class allows it (:attr:`Target.KEEP_WHEN_IDLE`)."""
        return all(type(target).KEEP_WHEN_IDLE for _, target in self._live.values())

    def close(self) -> None:
        self._views.clear()
        live, self._live = self._live, {}
        for _, target in live.values():
            _close_target(target)
