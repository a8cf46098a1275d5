"""Checkpoints of a MuJoCo arm: atomic ``.npz`` state files with a model fingerprint, restore
with a check that the file belongs to this model, and the world digest that tells two equal
worlds apart (mixed into :class:`~phyagentos.targets.mujoco_arm.MuJoCoArmTarget`)."""

from __future__ import annotations

import hashlib
import io
import json
import logging
import os
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from phyagentos.errors import TargetError
from phyagentos.protocol.atomic import atomic_write_bytes

from ..state_file import read_state_npz

log = logging.getLogger(__name__)


_STATE_FORMAT = 2




class ArmCheckpoints:
    """Atomic npz checkpoints with a model fingerprint, and the world digest.

    Mixed into :class:`~phyagentos.targets.mujoco_arm.MuJoCoArmTarget`.
    """

    # -- checkpoints --------------------------------------------------------------------
    def _fingerprint_extra(self) -> dict[str, Any]:
        return {}

    def _fingerprint(self) -> str:
        m = self._model
        scene = self._scene.to_dict() if hasattr(self._scene, "to_dict") else None
        return json.dumps({"robot": self.ROBOT, "nq": m.nq, "nv": m.nv, "nu": m.nu, "na": m.na, "scene": scene,
                           **self._fingerprint_extra()}, sort_keys=True)

    def _state_meta(self) -> dict[str, Any]:
        """Extra JSON-ready state a subclass keeps beside the physics (default none)."""
        return {}

    def _restore_meta(self, meta: dict[str, Any]) -> None:
        """Restore what :meth:`_state_meta` wrote."""

    def _holds_state_of(self, path: Path) -> bool:
        """Whether the live world is exactly the one in the state file at ``path``: this
        target wrote or read that file with the same bytes (SHA-256 of the file) and its
        :meth:`world_digest` has not changed since. Saving to it again or loading it
        would then change nothing."""
        known = self._state_file
        if known is None or known[0] != str(path.absolute()):
            return False
        try:
            content = path.read_bytes()
        except OSError:
            return False
        return known == (str(path.absolute()), hashlib.sha256(content).hexdigest(), self.world_digest())

    def _remember_state_file(self, path: Path, content: bytes) -> None:
        """Record that the live world is the one in ``content``, the bytes of ``path``."""
        self._state_file = (str(path.absolute()), hashlib.sha256(content).hexdigest(), self.world_digest())

    def save_state(self, path: str | os.PathLike) -> Path:
        """Write the simulated state to ``path``: npz with MuJoCo's full integration state,
        ``qpos``/``qvel``/``ctrl``/``act``/``time``, the subclass's metadata and a model
        fingerprint. The write is atomic (temporary file, fsync, rename). Returns the path.

        Writes nothing if the file at ``path`` already holds this world: this target wrote
        or read that file with the same bytes (SHA-256) and its :meth:`world_digest` is
        unchanged since (e.g. the checkpoint before a session's first tick, right after
        the previous session's last one). The file is as durable as that earlier write
        made it (fsynced, or inside a batch that fsyncs it before the batch ends)."""
        self._check_open()
        p = Path(path)
        if self._holds_state_of(p):
            return p
        m, d = self._model, self._data
        spec = mujoco.mjtState.mjSTATE_INTEGRATION
        full = np.empty(mujoco.mj_stateSize(m, spec))
        mujoco.mj_getState(m, d, full, spec)
        p.parent.mkdir(parents=True, exist_ok=True)
        buf = io.BytesIO()
        np.savez(buf, format=np.array(_STATE_FORMAT), qpos=d.qpos.copy(), qvel=d.qvel.copy(), ctrl=d.ctrl.copy(),
                 act=d.act.copy(), time=np.array(d.time), full_state=full,
                 meta=np.array(json.dumps({**self._state_meta(), "runtime_notes": self.runtime_notes})),
                 fingerprint=np.array(self._fingerprint()))
        content = buf.getvalue()
        atomic_write_bytes(p, content)
        self._remember_state_file(p, content)
        return p

    def world_digest(self) -> str:
        """A digest of everything :meth:`save_state` keeps (MuJoCo's full integration state,
        the subclass's metadata, ``runtime_notes`` and the model fingerprint): two equal
        digests mean the same simulated world, e.g. before :meth:`save_state` and after
        :meth:`load_state` of that file. Hex string (SHA-256)."""
        self._check_open()
        m, d = self._model, self._data
        spec = mujoco.mjtState.mjSTATE_INTEGRATION
        full = np.empty(mujoco.mj_stateSize(m, spec))
        mujoco.mj_getState(m, d, full, spec)
        h = hashlib.sha256(full.tobytes())
        meta = {**self._state_meta(), "runtime_notes": self.runtime_notes}
        h.update(json.dumps(meta, sort_keys=True, default=str).encode())
        h.update(self._fingerprint().encode())
        return h.hexdigest()

    def load_state(self, path: str | os.PathLike) -> None:
        """Restore a state written by :meth:`save_state` for the same scene and robot.
        Raises TargetError if the file is missing, malformed or from another scene.

        If the live world already is the file's (this target wrote or read these very bytes
        and its :meth:`world_digest` is unchanged since; see :meth:`save_state`), nothing
        is parsed or restored: only the derived quantities are recomputed (``mj_forward``), as a
        restore does, so either way the target ends in the same state."""
        self._check_open()
        m, d = self._model, self._data
        p = Path(path)
        if self._holds_state_of(p):
            mujoco.mj_forward(m, d)
            return
        try:
            content = p.read_bytes()
        except OSError:
            content = None  # read_state_npz reports it
        data = read_state_npz(p, content=content)
        if "fingerprint" not in data or str(data["fingerprint"]) != self._fingerprint():
            raise TargetError(f"state file {p} was saved from a different scene or model")
        spec = mujoco.mjtState.mjSTATE_INTEGRATION
        full = data.get("full_state")
        if full is not None and full.shape == (mujoco.mj_stateSize(m, spec),):
            mujoco.mj_setState(m, d, full, spec)
        else:
            missing = [k for k in ("qpos", "qvel", "ctrl", "act", "time") if k not in data]
            if missing:
                raise TargetError(f"state file {p} lacks {', '.join(missing)}")
            for k, n in (("qpos", m.nq), ("qvel", m.nv), ("ctrl", m.nu), ("act", m.na)):
                if data[k].shape != (n,):
                    raise TargetError(f"state file {p}: {k} has shape {data[k].shape}, expected ({n},)")
            d.qpos[:], d.qvel[:], d.ctrl[:], d.act[:] = data["qpos"], data["qvel"], data["ctrl"], data["act"]
            d.time = float(data["time"])
        mujoco.mj_forward(m, d)
        self.runtime_notes = {}
        if "meta" in data:
            meta = json.loads(str(data["meta"]))
            self.runtime_notes = dict(meta.pop("runtime_notes", None) or {})
            self._restore_meta(meta)
        self._remember_state_file(p, content)

