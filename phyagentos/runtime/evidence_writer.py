"""Evidence images rendered off the session's critical path.

Rendering the two RGB images of an evidence bundle (``initial.png``, ``terminal.png``)
under OSMesa costs tens of milliseconds each, more than everything else a short
session does, and the Agent's retention policy deletes them again for every success
(unless ``--keep-success-images``). So the SessionRunner only *captures* the scene
(MuJoCo's integration state of the target, ``mj_getState`` with ``mjSTATE_INTEGRATION``:
a vector of a few hundred numbers, microseconds) and an :class:`EvidenceImageWriter`
thread of the runner process renders it later, with its own renderer and its own
``MjData``, in which it restores that state and recomputes the positions
(``mj_setState``, ``mj_forward``). A copy of the whole ``MjData`` would also do, but it
copies the data's arena and buffer (about 40 MB for franka_tabletop: 0.8 ms on an idle
core, 3.6-7 ms traced in a runner preparing a session), and the initial scene is taken
on the path from a verdict to the next session's first tick. The image shows the scene
at exactly the joint values the snapshot of that moment records (a live ``MjData``'s
poses lag its ``qpos`` by one physics step after ``mj_step``):

- While a session's images are owed, its evidence directory holds ``.images-pending``
  (markers: :mod:`phyagentos.protocol.evidence_markers`); the writer removes it once every image is written or skipped.
- The Agent plane answers through the evidence directory, never through the runtime:
  ``.images-pruned`` (:data:`PRUNED_MARKER`, a success whose images are not kept) makes
  the writer skip them and delete any it already wrote; ``.images-wanted``
  (:data:`WANTED_MARKER`, any other verdict, or images kept) makes it render at once.
  Without an answer it renders after ``decide_s`` (e.g. no agent running).
- The verifier does not wait for images unless it needs them (a verdict other than
  success, or kept images): then it waits for ``.images-pending`` to disappear
  (``wait_for_images``).

Race-free retention: the writer renames an image into place and only then looks for
``.images-pruned``; the Agent creates ``.images-pruned`` and only then deletes the
images. Whichever comes second removes the file.

Targets without ``model``/``data`` MuJoCo handles (or an ``overview`` camera) are
rendered synchronously as before (:func:`save_scene_image`).
"""

from __future__ import annotations

import logging
import os
import queue
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from phyagentos.protocol.evidence_markers import PENDING_MARKER, PRUNED_MARKER, WANTED_MARKER

from .evidence_images import EVIDENCE_IMAGE_SIZE, save_scene_image

__all__ = ["EvidenceImageWriter"]

logger = logging.getLogger(__name__)

_CAMERA = "overview"


class EvidenceImageWriter:
    """Renders captured scenes to PNG in a background thread of the runner process.

    Args:
        decide_s: how long a finished session's images wait for the Agent's answer
            (pruned or wanted) before they are rendered anyway, s.
    """

    def __init__(self, *, decide_s: float = 2.0) -> None:
        self.decide_s = decide_s
        self._jobs: queue.Queue = queue.Queue()
        self._held: dict[str, list[tuple]] = {}
        self._thread: threading.Thread | None = None
        #: (model, mujoco.Renderer, its MjData), writer thread only
        self._renderer: tuple[Any, Any, Any] | None = None
        self._lock = threading.Lock()

    # -- the SessionRunner's side ------------------------------------------------

    def scene(self, target: Any) -> tuple[Any, Any] | None:
        """``target``'s scene as it is now, for a later :meth:`capture`: ``(model, state)``
        with ``state`` the ``(mj_stateSize,)`` float64 vector of its integration state
        (``mjSTATE_INTEGRATION``: time, qpos, qvel, act, warm start, ctrl, applied
        forces, equality activations, mocap poses, user data), or None for a target this
        writer cannot render in the background (not
        :class:`~phyagentos.targets.contract.MuJoCoBacked`, or no ``overview`` camera).
        Writes nothing: the SessionRunner takes the initial scene while it prepares a
        session, before ``go``."""
        from phyagentos.targets.contract import MuJoCoBacked  # noqa: PLC0415 - the package imports MuJoCo

        if not isinstance(target, MuJoCoBacked):
            return None
        try:
            import mujoco  # noqa: PLC0415

            model, data = target.model, target.data
            usable = (isinstance(model, mujoco.MjModel) and isinstance(data, mujoco.MjData)
                      and mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, _CAMERA) >= 0)
            if not usable:
                return None
            spec = mujoco.mjtState.mjSTATE_INTEGRATION  # every input of the physics
            state = np.empty(mujoco.mj_stateSize(model, spec))
            mujoco.mj_getState(model, data, state, spec)
        except Exception:  # noqa: BLE001 - any doubt: the synchronous path decides
            return None
        return model, state

    def capture(self, target: Any, path: str | os.PathLike[str], *, events: list | None = None,
                scene: tuple[Any, Any] | None = None) -> str | None:
        """Capture ``target``'s scene now for ``path`` (rendered later); returns the file
        name the bundle lists. ``scene``: one :meth:`scene` took earlier of the same
        world (nothing moved since), used instead of taking it now. Falls back to
        rendering at once (:func:`save_scene_image`) for a target without MuJoCo handles
        or an ``overview`` camera."""
        path = Path(path)
        if scene is None:
            scene = self.scene(target)
        if scene is None:
            return save_scene_image(target, path, events=events)
        key = str(path.parent)
        with self._lock:
            if key not in self._held:
                self._held[key] = []
                (path.parent / PENDING_MARKER).touch()
            self._held[key].append((*scene, path))
        return path.name

    def release(self, evidence_dir: str | os.PathLike[str]) -> None:
        """The session's bundle is written: its captured images may be rendered now."""
        with self._lock:
            jobs = self._held.pop(str(Path(evidence_dir)), [])
            if not jobs:
                return
            self._jobs.put((Path(evidence_dir), jobs, time.monotonic() + self.decide_s))
            if self._thread is None or not self._thread.is_alive():
                self._thread = threading.Thread(target=self._serve, name="evidence-images", daemon=True)
                self._thread.start()

    def discard(self, evidence_dir: str | os.PathLike[str]) -> None:
        """Forget the images captured for ``evidence_dir`` and not yet released (a
        session prepared but never started): nothing is rendered for it, and its
        ``.images-pending`` marker goes."""
        with self._lock:
            jobs = self._held.pop(str(Path(evidence_dir)), None)
        if jobs is not None:
            (Path(evidence_dir) / PENDING_MARKER).unlink(missing_ok=True)

    def close(self, timeout: float = 10.0) -> None:
        """Render what is owed (without waiting for answers) and stop the thread."""
        with self._lock:
            held, self._held = self._held, {}
        for directory in held:
            self._jobs.put((Path(directory), held[directory], 0.0))
        self._jobs.put(None)
        if self._thread is not None:
            self._thread.join(timeout)

    # -- the writer thread -------------------------------------------------------

    def _serve(self) -> None:
        while True:
            item = self._jobs.get()
            if item is None:
                return
            directory, jobs, decide_at = item
            try:
                self._session(directory, jobs, decide_at)
            except Exception:  # noqa: BLE001 - an image must never take the runner down
                logger.exception("evidence images of %s not written", directory)
            finally:
                (directory / PENDING_MARKER).unlink(missing_ok=True)

    def _session(self, directory: Path, jobs: list[tuple], decide_at: float) -> None:
        pruned, wanted = directory / PRUNED_MARKER, directory / WANTED_MARKER
        while time.monotonic() < decide_at and not pruned.exists() and not wanted.exists() and self._jobs.empty():
            time.sleep(0.01)
        for model, state, path in jobs:
            if pruned.exists():
                return
            self._render(model, state, path)
            if pruned.exists():  # the Agent pruned while we rendered: ours to delete
                path.unlink(missing_ok=True)

    def _render(self, model, state, path: Path) -> None:
        import mujoco  # noqa: PLC0415
        from PIL import Image  # noqa: PLC0415

        from phyagentos.renderer import Renderer  # noqa: PLC0415

        width, height = EVIDENCE_IMAGE_SIZE
        try:
            if self._renderer is None or self._renderer[0] is not model:
                if self._renderer is not None:
                    self._renderer[1].close()
                self._renderer = (model, Renderer(model, height=height, width=width), mujoco.MjData(model))
            _, renderer, data = self._renderer
            mujoco.mj_setState(model, data, state, mujoco.mjtState.mjSTATE_INTEGRATION)
            mujoco.mj_forward(model, data)  # body, geom, camera and light poses of that state
            renderer.update_scene(data, camera=_CAMERA)
            renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = False
            pixels = renderer.render()
        except Exception as exc:  # noqa: BLE001 - no GL backend: the bundle simply has no image
            logger.warning("evidence image %s not rendered: %s", path, exc)
            self._renderer = None
            return
        tmp = path.with_name(f".{path.name}.tmp")
        Image.fromarray(pixels).save(tmp, format="PNG")
        os.replace(tmp, path)
