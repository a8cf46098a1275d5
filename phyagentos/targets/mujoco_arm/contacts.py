"""Contacts of a MuJoCo arm's tabletop scene: which objects the fingers touch, which objects
touch each other, and which contacts are unexpected during a motion (mixed into
:class:`~phyagentos.targets.mujoco_arm.MuJoCoArmTarget`)."""

from __future__ import annotations

import logging

import numpy as np

from .common import K_ENV, K_FINGER, K_NONE, K_OBJECT, K_ROBOT

log = logging.getLogger(__name__)



class ArmContacts:
    """Finger and object contacts of a tabletop scene, classified by geom kind.

    Mixed into :class:`~phyagentos.targets.mujoco_arm.MuJoCoArmTarget`.
    """

    # -- contacts (tabletop scenes) -----------------------------------------------------
    def _finger_contacts(self) -> tuple[set[int], set[int]]:
        """Objects (indices) touching finger side 1 and finger side 2."""
        d = self._data
        a_side: set[int] = set()
        b_side: set[int] = set()
        if d.ncon == 0:
            return a_side, b_side
        geoms = d.contact.geom
        dist = d.contact.dist
        for i in range(d.ncon):
            if dist[i] > 1e-4:
                continue
            g0, g1 = int(geoms[i, 0]), int(geoms[i, 1])
            for a, b in ((g0, g1), (g1, g0)):
                o = int(self._gobj[b])
                if o < 0 or not self._gside[a]:
                    continue
                (a_side if self._gside[a] == 1 else b_side).add(o)
        return a_side, b_side

    def held_objects(self) -> tuple[str, ...]:
        """Objects in contact with both finger pads (simulator contacts: ground truth)."""
        left, right = self._finger_contacts()
        return tuple(self._obj_names[i] for i in sorted(left & right))

    def _object_contacts(self) -> list[list[str]]:
        """Sorted pairs of objects touching each other (simulator contacts)."""
        d = self._data
        pairs: set[tuple[str, str]] = set()
        for i in range(d.ncon):
            if d.contact.dist[i] > 1e-4:
                continue
            a, b = int(self._gobj[d.contact.geom[i, 0]]), int(self._gobj[d.contact.geom[i, 1]])
            if a >= 0 and b >= 0 and a != b:
                pairs.add(tuple(sorted((self._obj_names[a], self._obj_names[b]))))  # type: ignore[arg-type]
        return [list(p) for p in sorted(pairs)]

    def _unexpected_matrix(self, held: set[int]) -> np.ndarray:
        """(ngeom, ngeom) bool: True where a contact between the two geoms is unexpected."""
        k = self._gkind
        o = self._gobj
        robotish = (k == K_ROBOT) | (k == K_FINGER)
        collides = k != K_NONE
        U = np.zeros((len(k), len(k)), dtype=bool)
        U |= robotish[:, None] & collides[None, :]
        U |= U.T
        held_mask = np.array([oi in held for oi in o]) & (k == K_OBJECT)
        fingers = k == K_FINGER
        U[np.ix_(fingers, held_mask)] = False
        U[np.ix_(held_mask, fingers)] = False
        obstacles = (k == K_ENV) & ~np.isin(np.arange(len(k)), list(self._support_geoms))
        U[np.ix_(held_mask, obstacles)] = True
        U[np.ix_(obstacles, held_mask)] = True
        return U

    def _unexpected_for_current_grasp(self) -> np.ndarray:
        left, right = self._finger_contacts()
        key = frozenset(left & right)
        U = self._U_cache.get(key)
        if U is None:
            U = self._U_cache[key] = self._unexpected_matrix(set(key))
        return U

    def _collect_contacts(self, U: np.ndarray, bad_pairs: set) -> None:
        d = self._data
        if d.ncon:
            g = d.contact.geom
            hit = U[g[:, 0], g[:, 1]] & (d.contact.dist < 0.0)
            if hit.any():
                for i in np.nonzero(hit)[0]:
                    bad_pairs.add((int(g[i, 0]), int(g[i, 1])))

    def _robot_part(self, a: int, b: int) -> str:
        """The robot's side of an unexpected contact between geoms ``a`` and ``b``: the robot
        body that met something (its own link's name), or ``"held object"`` where what the
        hand holds met an obstacle. What it met is not named: a real arm's collision sensing
        (joint torques, a wrist force sensor) says where on the robot, never what it hit."""
        m = self._model
        for g in (a, b):
            if self._gkind[g] in (K_ROBOT, K_FINGER):
                return m.body(int(m.geom_bodyid[g])).name
        return "held object"

    def _contact_names(self, bad_pairs: set) -> tuple[str, ...]:
        """Sorted robot parts (:meth:`_robot_part`) of the unexpected contacts in ``bad_pairs``."""
        out = tuple(sorted({self._robot_part(a, b) for a, b in bad_pairs}))
        if out:
            log.info("unexpected contacts during execution, on: %s", out)
        return out

