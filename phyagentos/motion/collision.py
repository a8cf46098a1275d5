"""Configuration validity for the arm: joint limits and MuJoCo contacts.

:class:`CollisionChecker` owns a copy of the model (with every geom margin set to the
requested safety margin) and its own ``MjData``, so it never disturbs a running
simulation. A configuration is checked by writing the 7 arm angles into that data,
running ``mj_kinematics`` and ``mj_collision``, and classifying the contacts:

- robot vs environment (table, obstacles, any static geom): collision;
- robot vs a free object: collision, except the attached object against the gripper
  (the bodies below the last arm joint, i.e. the fingers);
- robot vs robot: collision unless the body pair is in ``allowed_pairs`` (adjacent links
  are already excluded by the model);
- attached object vs environment or other objects: collision;
- free object vs environment / other objects: ignored (that is the world's business).

A contact counts when its signed distance is below ``margin_m`` (penetration for 0).

Checkers of one model at other margins can share that copy (``share_model_of``): a copy
carries the whole model, textures included (a LIBERO world: about 250 MB, 147 MB of it
textures), and a checker differs from another only in the geom margins and collision bits
it writes into the copy, so each writes its own into the shared copy before each query
when the last query was another's.
"""

from __future__ import annotations

import copy
import logging
import math
from typing import Iterable, Sequence

import mujoco
import numpy as np
from numpy.typing import ArrayLike

from phyagentos.errors import PlanningError, format_choices

__all__ = ["CollisionChecker", "DEFAULT_ARM_JOINT_NAMES"]

log = logging.getLogger(__name__)

DEFAULT_ARM_JOINT_NAMES: tuple[str, ...] = tuple(f"robot:panda0_joint{i}" for i in range(1, 8))

_ENV, _ROBOT, _OBJECT = 0, 1, 2


class _SharedCopy:
    """A model copy's bookkeeping: the checker whose margins and collision bits it holds
    now (``None``: none for sure)."""

    __slots__ = ("owner",)

    def __init__(self) -> None:
        self.owner: CollisionChecker | None = None


class CollisionChecker:
    """Joint-space validity checker for the arm.

    Args:
        model: compiled scene model (not modified; a copy is used).
        arm_joint_names: the 7 arm joints, in order.
        margin_m: safety distance in metres (>= 0): contacts closer than this count.
        tcp_site: site used as the tool frame for :meth:`attach`.
        allowed_pairs: extra robot body-name pairs allowed to touch.
        gripper_bodies: bodies (with their descendants) an attached object may touch;
            default: the bodies below the last arm joint's body (the Franka's fingers).
            A gripper whose fixed jaw is the last arm body (the SO-101's) names it here.
        share_model_of: a checker built from the same ``model`` whose private copy this
            one uses too, instead of copying ``model`` again (results are the same: each
            checker's margins and collision bits are written into the copy before its
            queries). Checkers sharing a copy must be used from one thread.

    Raises:
        PlanningError: unknown joint/site names, a negative margin, or ``share_model_of``
            built from another model.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        *,
        arm_joint_names: Sequence[str] = DEFAULT_ARM_JOINT_NAMES,
        margin_m: float = 0.0,
        tcp_site: str = "tcp",
        allowed_pairs: Iterable[tuple[str, str]] = (),
        gripper_bodies: Iterable[str] | None = None,
        share_model_of: "CollisionChecker | None" = None,
    ):
        if not margin_m >= 0.0 or not math.isfinite(margin_m):
            raise PlanningError(f"margin_m must be a finite number >= 0, got {margin_m}")
        self.margin_m = float(margin_m)
        self._source = model
        if share_model_of is None:
            self.model = copy.copy(model)
            self._shared = _SharedCopy()
            self._orig_contype = self.model.geom_contype.copy()
            self._orig_conaffinity = self.model.geom_conaffinity.copy()
        else:
            if share_model_of.model_source is not model:
                raise PlanningError("share_model_of: that checker was built from another model")
            self.model = share_model_of.model
            self._shared = share_model_of._shared
            # the source's collision bits (the shared copy holds the other checker's)
            self._orig_contype = share_model_of._orig_contype.copy()
            self._orig_conaffinity = share_model_of._orig_conaffinity.copy()
        self._shared.owner = self
        self.model.geom_margin[:] = self.margin_m
        self.model.geom_gap[:] = 0.0
        self.data = mujoco.MjData(self.model)
        m = self.model
        self.arm_joint_names = tuple(arm_joint_names)
        jnames = [m.joint(i).name for i in range(m.njnt)]
        jids = []
        for name in self.arm_joint_names:
            jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)
            if jid < 0:
                raise PlanningError(f"unknown arm joint {name!r}; joints: {format_choices(jnames)}")
            jids.append(jid)
        self._jids = np.array(jids)
        self.qadr = m.jnt_qposadr[self._jids].copy()
        self.lower = m.jnt_range[self._jids, 0].copy()
        self.upper = m.jnt_range[self._jids, 1].copy()
        # contiguous arm joints (the usual case) are written through a slice
        a0 = int(self.qadr[0])
        contiguous = np.array_equal(self.qadr, np.arange(a0, a0 + len(self.qadr)))
        self._qidx = slice(a0, a0 + len(self.qadr)) if contiguous else self.qadr
        self._lower_tol = self.lower - 1e-9
        self._upper_tol = self.upper + 1e-9
        self.tcp_site_id = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, tcp_site)
        if self.tcp_site_id < 0:
            sites = [m.site(i).name for i in range(m.nsite)]
            raise PlanningError(f"unknown tcp site {tcp_site!r}; sites: {format_choices(sites)}")

        # -- body classes
        first_body = int(m.jnt_bodyid[self._jids[0]])
        last_body = int(m.jnt_bodyid[self._jids[-1]])
        robot_root = int(m.body_rootid[first_body])
        self.robot_bodies = frozenset(b for b in range(m.nbody) if m.body_rootid[b] == robot_root and b != 0)
        if gripper_bodies is None:
            self.gripper_bodies = frozenset(b for b in self.robot_bodies
                                            if b != last_body and self._is_descendant(b, last_body))
        else:
            ids = []
            for name in gripper_bodies:
                bid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name)
                if bid < 0 or bid not in self.robot_bodies:
                    raise PlanningError(f"gripper body {name!r} is not a body of the robot")
                ids.append(bid)
            self.gripper_bodies = frozenset(b for b in self.robot_bodies if any(self._is_descendant(b, g) for g in ids))
        body_class = np.full(m.nbody, _ENV, dtype=np.int8)
        self.objects: dict[str, int] = {}
        self._object_qadr: dict[int, int] = {}
        for j in range(m.njnt):
            if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
                b = int(m.jnt_bodyid[j])
                if b not in self.robot_bodies:
                    self.objects[m.body(b).name] = b
                    self._object_qadr[b] = int(m.jnt_qposadr[j])
        for b in range(m.nbody):
            if b in self.robot_bodies:
                body_class[b] = _ROBOT
            elif m.body_weldid[b] != 0:
                # any moving non-robot body (free objects and their children)
                body_class[b] = _OBJECT
        self._body_class = body_class
        self._geom_body = m.geom_bodyid.copy()
        self._geom_class = body_class[self._geom_body]
        # Object bodies that move together (children of a free body) map to the free body.
        self._geom_root = np.array([int(m.body_rootid[b]) for b in self._geom_body])
        # Re-assign collision bits in the private model so MuJoCo only generates the
        # contacts that matter (a contact needs ct1 & ca2 or ct2 & ca1):
        #   robot link      ct 1, ca 1|2|4   (1 only if it collided with the robot before)
        #   gripper geom    ct 1, ca 1|2     (no bit 4: the attached object may touch it)
        #   env / object    ct 2, ca 0       (never among themselves)
        #   attached object ct 4, ca 2       (links, environment, other objects)
        # Geoms that could not collide at all (visual meshes, regions) stay disabled.
        self._collidable = (self._orig_contype != 0) | (self._orig_conaffinity != 0)
        # this checker's collision bits: written into the (possibly shared) copy before its queries
        self._contype = self._orig_contype.copy()
        self._conaffinity = self._orig_conaffinity.copy()
        for g in range(m.ngeom):
            if not self._collidable[g]:
                continue
            if self._geom_class[g] == _ROBOT:
                self_bit = 1 if self._orig_conaffinity[g] else 0
                gripper = int(self._geom_body[g]) in self.gripper_bodies
                self._contype[g] = 1
                self._conaffinity[g] = self_bit | 2 | (0 if gripper else 4)
            else:
                self._contype[g] = 2
                self._conaffinity[g] = 0
        m.geom_contype[:] = self._contype
        m.geom_conaffinity[:] = self._conaffinity
        self._allowed = set()
        for name_a, name_b in allowed_pairs:
            ia = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name_a)
            ib = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name_b)
            if ia < 0 or ib < 0:
                raise PlanningError(f"allowed pair ({name_a!r}, {name_b!r}) names an unknown body")
            self._allowed.add((min(ia, ib), max(ia, ib)))
        self._attached: int | None = None
        self._attached_name: str | None = None
        self._T_tcp_obj: np.ndarray | None = None
        self._buf_q_tcp = np.empty(4)
        self._buf_q_obj = np.empty(4)
        self._buf_p_obj = np.empty(3)
        # the gripper's slide joints (a parallel gripper's fingers): (qpos address, +1 or -1),
        # the sign of the side of zero their range lies on
        self._finger_qadr = tuple((int(m.jnt_qposadr[j]), 1.0 if m.jnt_range[j, 1] > 0.0 else -1.0)
                                  for j in range(m.njnt)
                                  if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_SLIDE
                                  and int(m.jnt_bodyid[j]) in self.gripper_bodies)
        travel = [float(np.max(np.abs(m.jnt_range[j]))) for j in range(m.njnt)
                  if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_SLIDE and int(m.jnt_bodyid[j]) in self.gripper_bodies]
        self._full_opening = min(travel) if travel else None
        self.n_checks = 0
        mujoco.mj_kinematics(m, self.data)

    def _is_descendant(self, b: int, ancestor: int) -> bool:
        while b > 0:
            if b == ancestor:
                return True
            b = int(self.model.body_parentid[b])
        return False

    @property
    def model_source(self) -> mujoco.MjModel:
        """The model this checker was built from (its private copy is :attr:`model`)."""
        return self._source

    # -- world state ----------------------------------------------------------------
    @property
    def nq(self) -> int:
        return self.model.nq

    @property
    def joint_limits(self) -> tuple[np.ndarray, np.ndarray]:
        """``(lower, upper)`` arm joint limits, each ``(7,)`` rad."""
        return self.lower.copy(), self.upper.copy()

    def set_world_state(self, qpos_full: ArrayLike) -> None:
        """Copy a full ``(nq,)`` configuration (objects, fingers, arm) from the simulation."""
        q = np.asarray(qpos_full, dtype=float)
        if q.shape != (self.model.nq,):
            raise PlanningError(f"qpos_full must have shape ({self.model.nq},), got {q.shape}")
        self.data.qpos[:] = q

    @property
    def full_opening_m(self) -> float | None:
        """How far the gripper's fingers open at most, m per finger (the least travel from
        closed of its slide joints, by their ranges in the model: the Franka Hand's 0.04), or
        ``None`` for a gripper without slide joints (the SO-101's revolute jaw)."""
        return self._full_opening

    def set_gripper_opening(self, opening_m: float) -> bool:
        """Stand the gripper's fingers ``opening_m`` (m per finger, >= 0) open in the checked
        world, as a hand pre-shaped before an approach will be (the world state's own opening
        until the next :meth:`set_world_state`).

        The fingers are the gripper's slide joints (a parallel gripper: the Franka Hand's two,
        robosuite's Panda gripper's two); one whose range lies at or above zero stands at
        ``+opening_m``, one below zero at ``-opening_m`` (each joint's value is its finger's
        travel from closed, as both models define them). Returns ``False``, changing nothing,
        for a gripper without slide joints (the SO-101's revolute jaw): the check then keeps
        the world's opening.

        Raises:
            PlanningError: a negative or non-finite opening.
        """
        o = float(opening_m)
        if not (math.isfinite(o) and o >= 0.0):
            raise PlanningError(f"opening_m must be a finite number >= 0 m, got {opening_m!r}")
        if not self._finger_qadr:
            return False
        for adr, sign in self._finger_qadr:
            self.data.qpos[adr] = sign * o
        return True

    def attach(self, object_name: str, T_tcp_object: np.ndarray) -> None:
        """Carry ``object_name`` rigidly at ``T_tcp_object`` (4, 4) in the tcp frame.

        While attached, the object may touch the gripper but nothing else.
        Raises :class:`PlanningError` for an unknown object.
        """
        if object_name not in self.objects:
            raise PlanningError(f"cannot attach unknown object {object_name!r}; objects: {format_choices(self.objects)}")
        T = np.asarray(T_tcp_object, dtype=float)
        if T.shape != (4, 4):
            raise PlanningError(f"T_tcp_object must be (4, 4), got {T.shape}")
        self.detach()
        self._attached = self.objects[object_name]
        self._attached_name = object_name
        self._T_tcp_obj = T.copy()
        self._attached_qadr = self._object_qadr[self._attached]
        self._p_tcp_obj = T[:3, 3].copy()
        self._q_tcp_obj = np.empty(4)
        mujoco.mju_mat2Quat(self._q_tcp_obj, np.ascontiguousarray(T[:3, :3]).reshape(-1))
        for g in np.nonzero(self._geom_root == self._attached)[0]:
            if self._collidable[g]:
                self._contype[g] = 4
                self._conaffinity[g] = 2
        self._shared.owner = None  # written into the copy at the next query

    def detach(self) -> None:
        """Stop carrying the attached object (it stays where the world state puts it)."""
        if self._attached is not None:
            for g in np.nonzero(self._geom_root == self._attached)[0]:
                if self._collidable[g]:
                    self._contype[g] = 2
                    self._conaffinity[g] = 0
            self._shared.owner = None  # written into the copy at the next query
        self._attached = None
        self._attached_name = None
        self._T_tcp_obj = None

    @property
    def attached(self) -> str | None:
        """Name of the attached object or ``None``."""
        return self._attached_name

    # -- checks -----------------------------------------------------------------------
    def within_limits(self, q: ArrayLike) -> bool:
        """Whether ``q`` (7,) rad lies inside the joint limits."""
        q = np.asarray(q, dtype=float)
        return bool(np.all(q >= self.lower - 1e-9) and np.all(q <= self.upper + 1e-9))

    def _set(self, q) -> None:
        m, d = self.model, self.data
        d.qpos[self._qidx] = q
        mujoco.mj_kinematics(m, d)
        if self._attached is not None:
            # object pose = tcp pose * T_tcp_obj, written into its free joint
            sm = d.site_xmat[self.tcp_site_id]
            mujoco.mju_mat2Quat(self._buf_q_tcp, sm)
            mujoco.mju_mulQuat(self._buf_q_obj, self._buf_q_tcp, self._q_tcp_obj)
            mujoco.mju_mulMatVec(self._buf_p_obj, sm.reshape(3, 3), self._p_tcp_obj)
            adr = self._attached_qadr
            d.qpos[adr : adr + 3] = d.site_xpos[self.tcp_site_id] + self._buf_p_obj
            d.qpos[adr + 3 : adr + 7] = self._buf_q_obj
            mujoco.mj_kinematics(m, d)
        if self._shared.owner is not self:
            self._own_copy()
        mujoco.mj_collision(m, d)

    def _own_copy(self) -> None:
        """Write this checker's geom margins and collision bits into the model copy (shared
        with checkers at other margins, or changed by an attach or detach)."""
        m = self.model
        m.geom_margin[:] = self.margin_m
        m.geom_contype[:] = self._contype
        m.geom_conaffinity[:] = self._conaffinity
        self._shared.owner = self

    def _bad_contacts(self) -> list[int]:
        """Indices of forbidden contacts in ``self.data`` (the collision bits already
        keep out everything except robot/attached-object contacts)."""
        d = self.data
        n = d.ncon
        if n == 0:
            return []
        close = d.contact.dist < self.margin_m
        if not self._allowed:
            return np.nonzero(close)[0].tolist()
        keep = []
        geoms = d.contact.geom
        for i in np.nonzero(close)[0]:
            b0, b1 = int(self._geom_body[geoms[i, 0]]), int(self._geom_body[geoms[i, 1]])
            if (min(b0, b1), max(b0, b1)) not in self._allowed:
                keep.append(int(i))
        return keep

    def is_valid(self, q: ArrayLike) -> bool:
        """Whether ``q`` (7,) rad is inside the limits and free of forbidden contacts."""
        q = np.asarray(q, dtype=float)
        if ((q < self._lower_tol) | (q > self._upper_tol)).any():
            self.n_checks += 1
            return False
        return self.is_valid_within_limits(q)

    def is_valid_within_limits(self, q: np.ndarray) -> bool:
        """:meth:`is_valid` for a float ``(7,)`` array already known to be within the
        joint limits (e.g. states sampled by the planner inside the bounds)."""
        self.n_checks += 1
        self._set(q)
        if self.data.ncon == 0:
            return True
        return not self._bad_contacts()

    def colliding_pairs(self, q: ArrayLike) -> tuple[tuple[str, str], ...]:
        """Sorted, de-duplicated name pairs in forbidden contact at ``q`` (7,) rad.

        Robot links and objects are named by body, static geoms by geom name (``table``,
        ``obstacle:<name>``). A configuration outside the joint limits yields pairs
        ``('joint_limit', <joint name>)``.
        """
        q = np.asarray(q, dtype=float)
        out: set[tuple[str, str]] = set()
        for i, name in enumerate(self.arm_joint_names):
            if q[i] < self.lower[i] - 1e-9 or q[i] > self.upper[i] + 1e-9:
                out.add(("joint_limit", name))
        self._set(np.clip(q, self.lower, self.upper))
        for i in self._bad_contacts():
            g0, g1 = (int(g) for g in self.data.contact.geom[i])
            out.add(tuple(sorted((self._name(g0), self._name(g1)))))  # type: ignore[arg-type]
        return tuple(sorted(out))

    def _name(self, geom: int) -> str:
        m = self.model
        body = int(self._geom_body[geom])
        if self._geom_class[geom] == _ENV:
            return m.geom(geom).name or m.body(body).name or f"geom{geom}"
        return m.body(body).name or f"body{body}"

    def check_path(self, path: np.ndarray, *, resolution_rad: float = 0.02) -> bool:
        """Whether every state of the piecewise-linear ``path`` (N, 7) is valid.

        Segments are sampled so consecutive checked states differ by at most
        ``resolution_rad`` in every joint.
        """
        return self.first_invalid(path, resolution_rad=resolution_rad) is None

    def first_invalid(self, path: np.ndarray, *, resolution_rad: float = 0.02) -> np.ndarray | None:
        """The first invalid interpolated state of ``path`` (N, 7), or ``None``."""
        P = np.asarray(path, dtype=float)
        if P.ndim != 2 or P.shape[1] != len(self.arm_joint_names) or len(P) == 0:
            raise PlanningError(f"path must have shape (N, {len(self.arm_joint_names)}), got {P.shape}")
        if resolution_rad <= 0:
            raise PlanningError(f"resolution_rad must be > 0, got {resolution_rad}")
        if not self.is_valid(P[0]):
            return P[0].copy()
        for a, b in zip(P[:-1], P[1:]):
            n = int(math.ceil(float(np.max(np.abs(b - a))) / resolution_rad))
            for k in range(1, n + 1):
                q = a + (b - a) * (k / n)
                if not self.is_valid(q):
                    return q
        return None

    def tcp_pose(self, q: ArrayLike) -> np.ndarray:
        """World (4, 4) pose of the tcp site at arm configuration ``q`` (7,) rad."""
        d = self.data
        d.qpos[self.qadr] = np.asarray(q, dtype=float)
        mujoco.mj_kinematics(self.model, d)
        T = np.eye(4)
        T[:3, 3] = d.site_xpos[self.tcp_site_id]
        T[:3, :3] = d.site_xmat[self.tcp_site_id].reshape(3, 3)
        return T
