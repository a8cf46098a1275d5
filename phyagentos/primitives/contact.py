"""Contact leaves: motions that expect to touch something.

``push`` and ``compute_push`` push an object along the table with the closed hand: the
push expects contact (``contact.missing`` otherwise), tolerates the lag contact causes
(its own ``tracking_tol_rad``) and bounds the effort (``contact.excessive_force``).

``guarded_move`` moves the tcp along a straight line, slowly, and stops as soon as the
robot presses on something with at least ``max_contact_force_n`` (checked after every
physics step: the stop comes within one step of the limit being reached); a motion that should
have touched and did not fails with ``contact.missing``. Its tracking tolerance is a
parameter: a compliant push lets the arm lag behind its reference while in contact,
where a free-space motion would call that lag a collision.

Contact force: the sum over the active MuJoCo contacts between a robot geom (a geom
of a jointed, non-free body) and anything else of the normal force
(:func:`mujoco.mj_contactForce`, N). A held object's contacts with the hand do not
count (they are the grip's own forces, which a wrist sensor does not see either). Targets
without a MuJoCo model fail with ``contact.unsupported``.

What is touched is named by the robot's side only (its own links: a fingertip, the hand, a
link of the arm), never by what it met: a real arm's force sensing says how hard and where on
itself, not on what. A press checks that it landed on the object it meant from where the
fingertips stopped (their height from the joint encoders) against the object's perceived
top, not from the simulator's contact pairs.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import mujoco
import numpy as np
from py_trees.common import Status

from phyagentos.errors import IKError
from phyagentos.geometry import VIEWER_SIDES
from phyagentos.motion.cartesian import cartesian_path
from phyagentos.motion.grasp import FINGERTIP_BELOW_TCP_M, FRANKA_FINGERS, top_down_rotation
from phyagentos.motion.retime import Trajectory, retime
from phyagentos.targets.contract import MuJoCoBacked

from .base import Primitive, PrimitiveFailure
from .execution import _Tracking
from .motion import clear_ik, execution_limits, ik_options
from .perception import (
    BESIDE_GAP_M,
    LOWER_APPROACH_M,
    Blocked,
    _object_body,
    beside_point,
    entity_pose,
    landmark_box,
    reach_blocked,
    viewer_side,
)

__all__ = ["GuardedMove", "Push", "ComputePush", "contact_force_n", "MIN_PUSH_M", "FINGER_HALF_THICKNESS_M",
           "CLOSED_FINGERS_DEPTH_M", "PUSH_LEANS_RAD", "TIGHT_CLEARANCE_M", "PUSH_BESIDE_GAP_M", "PUSH_MAX_SHIFT",
           "FREE_MARGIN_M", "free_shift", "PUSH_STRATEGIES", "PRESS_MAX_HEIGHT_M", "PRESS_START_ABOVE_M",
           "PRESS_CONTACT_N", "PRESS_DEPTH_M", "PRESS_LANDED_ABOVE_TOP_M", "PRESS_MIN_TIP_FRICTION", "PRESS_TURNS"]

#: The least push (m) :class:`ComputePush` makes towards a landmark's side: an object already
#: there is pushed this much more, so the push still touches it.
MIN_PUSH_M = 0.01
#: Half the thickness (m) of the closed fingers' pushing face along the push: the tcp stands this
#: far behind the fingertips' front (the value the push had used since it was written).
FINGER_HALF_THICKNESS_M = 0.01
#: How far (rad) the hand may lean over the object it pushes, tried in this order: upright first;
#: leaning, the hand's body stands over the object and away from what stands behind it (a plate
#: 3 cm from a cabinet's side: the upright hand's body would be in the cabinet). Leaning, the
#: fingers' face presses the object down as well as along (at 0.6 rad: 0.56 N down per N along,
#: which a table's friction below 1.5 lets slide).
PUSH_LEANS_RAD = (0.0, 0.3, 0.6)
#: How far (m) the closed fingertips reach from the tcp along the fingers' closing axis: the
#: pushing face when the hand is turned edge-on (its closing axis along the push). robosuite's
#: Panda hand: each closed finger's pad and tip stand 1.3-1.8 cm out from the centre plane
#: (measured on the collision meshes in the tcp frame, LIBERO's model).
CLOSED_FINGERS_DEPTH_M = 0.018
#: The gap (m) between the fingers and the object's face at the start when the skill's
#: clearance leaves no start clear: 8 mm still lets the hand come down without touching it
#: (LIBERO's plates stand 3-4.5 cm from the cabinet's side in libero_goal task 5).
TIGHT_CLEARANCE_M = 0.008
#: How far (m) a pushed object's near face is aimed beyond a landmark's edge ("to the front of
#: the stove"): the middle of what the verifier's ``beside`` accepts (0 to its 8 cm reach less 2
#: sigma, :data:`phyagentos.agent.criteria.BESIDE_REACH_M`), since a push lands less surely than a
#: place (:data:`~.perception.BESIDE_GAP_M`, 1.5 cm): the object slides on or stops short by a few cm.
PUSH_BESIDE_GAP_M = 0.03
#: The farthest a pushed object's aim point moves across the side, from level with the
#: landmark's centre, to a spot clear of what stands there: this fraction of the landmark's half
#: extent across (the verifier's ``beside`` accepts half of it less its 2 sigma:
#: :data:`phyagentos.agent.criteria.BESIDE_CENTRED`).
PUSH_MAX_SHIFT = 0.25
#: Clearance (m) between a pushed object's footprint at its aim point and any other perceived
#: object's (both as discs: a footprint's circumscribed circle).
FREE_MARGIN_M = 0.01
#: How :class:`ComputePush` may move the object: ``auto`` (pressed from above when it is low
#: (:data:`PRESS_MAX_HEIGHT_M`) and the fingertips grip (:data:`PRESS_MIN_TIP_FRICTION`), from
#: behind otherwise or where no press start is clear), ``behind`` (only from behind), ``above``
#: (only pressed from above).
PUSH_STRATEGIES = ("auto", "behind", "above")
#: The highest object (m, its perceived height) ``auto`` presses from above: the closed fingers
#: then stand in it or on it by at most this much, well under the Panda's 4.5 cm from knuckle to
#: fingertip, and a press at its centre cannot tip it (LIBERO's plate: 1.9 cm; its cream cheese
#: box: 1.8 cm; a bowl, 5.1 cm, is pushed from behind).
PRESS_MAX_HEIGHT_M = 0.03
#: The least friction of the fingertips (the target's ``fingertip_friction``) with which ``auto``
#: presses from above. Dragged by fingertips pressing with F, an object of weight mg slides along
#: when mu_tip F > mu_support (mg + F) (Coulomb's law at both contacts): the tips must grip it
#: better than its support holds it, and the press makes up the weight. The support's friction
#: is not known to the robot; a dish on a table's is mostly below 1 (LIBERO's plate on its table:
#: 0.95), so fingertips of 1.0 (robosuite's Panda's finger meshes) carry LIBERO's 11.5 g plate with
#: a press above 2.1 N. A target that declares no friction is never pressed in ``auto``; a drag
#: that slips leaves the object short, which the look after the push reports.
PRESS_MIN_TIP_FRICTION = 1.0
#: The hand's turns (rad about the vertical, from the closing axis across the way) tried for a press
#: from above, in order, with whether the closing axis then lies along the way (``edge_on``): along
#: it either way round (the hand's narrow side across the way; the wrist reaches one of the two),
#: then half way (its long side 7.4 cm out each way instead of 10.4: a plate between a cabinet's
#: side and a bowl, where along meets the cabinet above and across sweeps the bowl), then across.
PRESS_TURNS = ((np.pi / 2, True), (-np.pi / 2, True), (np.pi / 4, False), (-np.pi / 4, False),
               (3 * np.pi / 4, False), (-3 * np.pi / 4, False), (0.0, False), (np.pi, False))
#: Fingertips (m) above the object's perceived top where a press from above starts its descent.
PRESS_START_ABOVE_M = 0.01
#: Contact force (N) at which the descent of a press from above stops: it has landed on the object.
PRESS_CONTACT_N = 2.0
#: How far (m) below where it landed the hand is held while it drags the object. The drag's
#: margin grows with the press (the fingertips' friction over the support's, times the force):
#: on LIBERO's Panda (its joint servos) 4 mm pressed LIBERO's plate with about 20 N and it stalled
#: against the cream cheese it shoves along in 4 of 16 development scenes of libero_goal task 5
#: (seeds 500-515), where 6 mm (21-29 N) carried it in 16 of 16. On seeds 500-531 the plate made
#: less than 0.8 of the hand's way in 5 of 32 drags at 6 mm (0.54-0.79; LIBERO's checker counting
#: 29) and in 2 at 8 mm (0.60, 0.77; 25-39 N; LIBERO counting 31; one drag met the push's 40 N
#: limit, at 46 N, shoving the cheese).
PRESS_DEPTH_M = 0.008
#: How far above the pressed object's perceived top (m) the fingertips may stop and the press
#: still count as landed on it: higher, they met something else first (a bowl's rim beside a
#: plate stands 3 cm above the plate's). The perceived top is within a few mm of the true one
#: (``bench/libero_planning_world.py``: centres median 2 mm, p90 8 mm), the fingertips' height
#: from the encoders within a millimetre.
PRESS_LANDED_ABOVE_TOP_M = 0.01


def contact_force_n(model: mujoco.MjModel, data: mujoco.MjData, *, ignore_bodies: frozenset[int] = frozenset()
                    ) -> tuple[float, tuple[str, ...]]:
    """Total normal force (N) the robot exerts on anything now, and the robot's parts that
    touch something (sorted names of its own bodies, e.g. ``("gripper0_finger1",)``; what
    they touch is not named).

    Robot geoms are those of bodies with a hinge or slide joint (not world, not a free
    object); contacts with bodies in ``ignore_bodies`` (a held object: the grip's own
    forces) are skipped.
    """
    total, touched = 0.0, []
    f6 = np.zeros(6)
    for i in range(data.ncon):
        c = data.contact[i]
        b1, b2 = int(model.geom_bodyid[c.geom1]), int(model.geom_bodyid[c.geom2])
        robot = [_is_robot(model, b) for b in (b1, b2)]
        if robot[0] == robot[1] or {b1, b2} & ignore_bodies:
            continue
        mujoco.mj_contactForce(model, data, i, f6)
        total += abs(float(f6[0]))
        part = b1 if robot[0] else b2
        touched.append(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, part) or f"body{part}")
    return total, tuple(sorted(set(touched)))


def _is_robot(model: mujoco.MjModel, body: int) -> bool:
    if body == 0 or model.body_jntnum[body] == 0:
        # a geom on a link without its own joint (e.g. a hand) belongs to the robot when its
        # ancestor is jointed and not a free object
        parent = int(model.body_parentid[body])
        return body != 0 and parent != 0 and _is_robot(model, parent)
    return model.jnt_type[model.body_jntadr[body]] != mujoco.mjtJoint.mjJNT_FREE


def _offset_arg(offset) -> np.ndarray:
    offset = np.asarray(offset, dtype=float)
    if offset.shape != (3,) or not np.all(np.isfinite(offset)):
        raise ValueError(f"offset must be 3 finite numbers in m, got {offset!r}")
    return offset


@dataclass(frozen=True)
class _Slice:
    """What one control period of a contact motion ended with: the tracking result of the
    last physics step, the contact force (N) and the robot's parts touching after it, and whether the
    force limit stopped it."""

    completed: bool
    max_tracking_error_rad: float
    force_n: float
    touched: tuple[str, ...]
    stopped: bool


class _ContactMotion(_Tracking):
    """A straight tcp motion that expects contact (shared by :class:`GuardedMove` and
    :class:`Push`): argument checks, planning, and a stream that checks the contact
    force after **every physics step** (the target is asked for one step at a time), so
    a force limit stops the motion within one step (``timestep`` s) of being reached."""

    def _motion_args(self, *, to: str | None, offset, velocity_scale: float, tracking_tol_rad: float,
                     force_limit_n: float, force_name: str, expect_contact: bool, allow_to: bool) -> None:
        if allow_to and (to is None) == (offset is None):
            raise ValueError("give exactly one of 'to' (blackboard pose key) or 'offset' ([dx, dy, dz] in m)")
        if offset is not None or not allow_to:
            offset = _offset_arg(offset)
        if not 0 < velocity_scale <= 1:
            raise ValueError(f"velocity_scale must be in (0, 1], got {velocity_scale}")
        if not tracking_tol_rad > 0:
            raise ValueError(f"tracking_tol_rad must be > 0 rad, got {tracking_tol_rad}")
        if not force_limit_n > 0:
            raise ValueError(f"{force_name} must be > 0 N, got {force_limit_n}")
        self.to, self.offset, self.velocity_scale = to, offset, float(velocity_scale)
        self.tracking_tol_rad, self.expect_contact = float(tracking_tol_rad), bool(expect_contact)
        if to is not None:
            self.reads(to)
        self.writes("contact")

    def _plan(self, T_goal: np.ndarray | None = None) -> None:
        """Plan the straight line to ``to`` / by ``offset`` (or to the (4, 4) world tcp pose
        ``T_goal`` when given) and start streaming it; held objects' contacts are ignored when
        measuring the force.

        Raises:
            PrimitiveFailure: ``contact.unsupported`` on a target without a MuJoCo model
                (not :class:`~phyagentos.targets.contract.MuJoCoBacked`).
        """
        ctx = self.ctx
        target = ctx.target
        if not isinstance(target, MuJoCoBacked):
            raise PrimitiveFailure("contact.unsupported", f"target {target.name!r} reports no contact forces")
        T_start = target.tcp_pose()
        if T_goal is not None:
            T_goal = np.asarray(T_goal, dtype=float)
        elif self.to is not None:
            T_goal = np.asarray(self.get(self.to), dtype=float)
        else:
            T_goal = T_start.copy()
            T_goal[:3, 3] += self.offset
        self._start_xyz = T_start[:3, 3].copy()
        self._length = float(np.linalg.norm(T_goal[:3, 3] - T_start[:3, 3]))
        with ctx.profiler.section("ik"):
            path = cartesian_path(target.model, q_start=target.arm_qpos(), T_goal=T_goal, **ik_options(target))
        vel, acc = execution_limits(ctx, self.velocity_scale, self.velocity_scale)
        with ctx.profiler.section("timing"):
            traj = retime(path, vel_limits=vel, acc_limits=acc, dt=target.model.opt.timestep)
        # The simulated force reading leaves out the grip's own forces (the fingers squeezing what
        # they hold), as a wrist sensor would: the simulator's bookkeeping picks them out; no
        # name leaves this sum.
        held = target.held_objects()
        self._ignore = frozenset(int(target.model.body(_body_name(target, n)).id) for n in held)
        self._start(traj)

    def _stream(self, over_limit: Callable[[float], bool]) -> _Slice:
        """Stream up to one control period, one physics step per ``track`` call, measuring
        the contact force after each step; return at the first step where
        ``over_limit(force)`` holds or tracking fails (the arm's command then stays where
        the target left it: :meth:`halt` is the caller's).

        Raises:
            PrimitiveFailure: ``safety.estop`` when the SafetyGuard's e-stop is engaged;
                the target's own code (``ExecutionResult.code``) when it stopped itself.
        """
        ctx = self.ctx
        target = ctx.target
        if ctx.guard is not None and ctx.guard.estop_engaged():
            target.halt()
            raise PrimitiveFailure("safety.estop", f"e-stop engaged: {ctx.guard.estop.reason}")
        t_end = min(self._t + ctx.motion.control_period_s, self._traj.duration)
        dt = float(target.model.opt.timestep)
        force, touched, max_err = 0.0, (), 0.0
        while self._t < t_end - 1e-12:
            t_next = min(self._t + dt, t_end)
            window, t0 = self._window(self._t, t_next)
            with ctx.profiler.section("simulation"):
                result = target.track(window, t_start=self._t - t0, t_end=t_next - t0,
                                      tracking_tol_rad=self.tracking_tol_rad)
            self._t = t_next
            if not result.completed and result.code:  # the target stopped itself (a real arm's bus guard)
                raise PrimitiveFailure(result.code, f"target stopped at t={t_next:.2f} s: {result.reason}")
            max_err = max(max_err, result.max_tracking_error_rad)
            force, touched = contact_force_n(target.model, target.data, ignore_bodies=self._ignore)
            self._sample(force, touched)
            stopped = over_limit(force)
            if stopped or not result.completed:
                return _Slice(result.completed, max_err, force, touched, stopped)
        return _Slice(True, max_err, force, touched, False)

    def _window(self, t_start: float, t_end: float) -> tuple[Trajectory, float]:
        """The samples of the trajectory around ``(t_start, t_end]`` (s), re-based to start
        at 0, and the time of the first on the trajectory's clock: ``track`` interpolates
        the same reference from them, at a cost that does not grow with the trajectory's
        length (the primitive calls it once per physics step)."""
        traj = self._traj
        t = np.asarray(traj.t, dtype=float)
        if t_start <= 0.0:  # the first step: the whole start check of track applies
            i0 = 0
        else:  # a sample strictly before t_start, so the slice never restarts the clock
            i0 = max(0, int(np.searchsorted(t, t_start, side="left")) - 1)
        i1 = min(len(t) - 1, int(np.searchsorted(t, t_end, side="left")) + 1)
        i1 = max(i1, min(i0 + 1, len(t) - 1))
        sl = slice(i0, i1 + 1)
        qdd = getattr(traj, "qdd", None)
        window = Trajectory(t=t[sl] - t[i0], q=np.asarray(traj.q)[sl], qd=np.asarray(traj.qd)[sl],
                            qdd=np.asarray(qdd)[sl] if qdd is not None else np.zeros_like(np.asarray(traj.q)[sl]))
        return window, float(t[i0])

    def _sample(self, force: float, touched: tuple[str, ...]) -> None:
        """Called after every physics step with the contact force (N) and the robot's parts touching."""

    def _touched_down(self, s: _Slice, what: str) -> bool:
        """Whether slice ``s`` of a motion that stops on contact ended on it (its force limit
        reached, or blocked while touching something).

        Raises:
            PrimitiveFailure: ``execution.tracking`` when ``what`` was blocked touching nothing.
        """
        if s.stopped or (not s.completed and s.touched):
            return True
        if not s.completed:
            raise PrimitiveFailure("execution.tracking",
                                   f"{what} blocked without contact: tracking error {s.max_tracking_error_rad:.3f} "
                                   f"rad exceeded {self.tracking_tol_rad} rad")
        return False


class GuardedMove(_ContactMotion):
    """Straight-line tcp motion by a world ``offset`` that stops on contact.

    Args:
        offset: (3,) world-frame tcp displacement in m (orientation kept): the farthest
            the motion goes.
        velocity_scale: fraction (0, 1] of the joint velocity limits (slow: contact).
        tracking_tol_rad: joint tracking error tolerated before the motion counts as
            blocked, rad (a blocked motion with contact is the contact it expected).
        max_contact_force_n: stop as soon as the robot presses with this much, N;
            checked after every physics step, so the stop comes within one step.
        expect_contact: fail with ``contact.missing`` when the whole offset is travelled
            without touching anything.

    Blackboard: writes ``contact`` with ``{force_n, touched, travelled_m}`` (``touched``: the
    robot's parts in contact, :func:`contact_force_n`).
    """

    def __init__(self, name: str, *, offset, velocity_scale: float = 0.05, tracking_tol_rad: float = 0.05,
                 max_contact_force_n: float = 10.0, expect_contact: bool = True):
        super().__init__(name)
        self._motion_args(to=None, offset=offset, velocity_scale=velocity_scale, tracking_tol_rad=tracking_tol_rad,
                          force_limit_n=max_contact_force_n, force_name="max_contact_force_n",
                          expect_contact=expect_contact, allow_to=False)
        self.max_contact_force_n = float(max_contact_force_n)

    def on_enter(self):
        self._plan()

    def _contact(self, force: float, touched: tuple[str, ...]) -> Status:
        target = self.ctx.target
        target.halt()
        travelled = float(np.linalg.norm(target.tcp_pose()[:3, 3] - self._start_xyz))
        info = {"force_n": round(force, 3), "touched": list(touched), "travelled_m": round(travelled, 4),
                "sim_time_s": round(float(target.data.time), 6)}
        self.set("contact", info)
        self.ctx.trace.record("contact", leaf=self.name, **info)
        return Status.SUCCESS

    def step(self):
        target = self.ctx.target
        s = self._stream(lambda force: force >= self.max_contact_force_n)
        if self._touched_down(s, "the move"):
            return self._contact(s.force_n, s.touched)
        if self._t < self._traj.duration - 1e-9:
            return Status.RUNNING
        if s.touched:
            return self._contact(s.force_n, s.touched)
        if self.expect_contact:
            target.halt()
            raise PrimitiveFailure("contact.missing",
                                   f"moved {np.linalg.norm(self.offset):.3f} m and touched nothing "
                                   f"(expected contact of at least {self.max_contact_force_n} N)")
        self.set("contact", {"force_n": 0.0, "touched": [], "travelled_m": float(np.linalg.norm(self.offset))})
        return Status.SUCCESS


def free_shift(point_xy, across_xy, radius_m: float, obstacles, *, max_shift_m: float,
               step_m: float = 0.005, margin_m: float = FREE_MARGIN_M) -> float:
    """The shift (m, along the (2,) unit ``across_xy``) nearest 0 that puts a disc of
    ``radius_m`` centred at ``point_xy + shift * across_xy`` at least ``margin_m`` clear of every
    obstacle disc (``obstacles``: ``((2,) centre, radius m)`` pairs, world frame), within
    ``|shift| <= max_shift_m``, tried in ``step_m`` steps (the positive side first at each
    size). When no shift clears them, the one whose nearest obstacle is farthest (the nearest
    to 0 of equals): the pushed object then meets less of what stands there."""
    p, a = np.asarray(point_xy, dtype=float)[:2], np.asarray(across_xy, dtype=float)[:2]
    obstacles = [(np.asarray(c, dtype=float)[:2], float(r)) for c, r in obstacles]
    n = int(np.floor(max(0.0, max_shift_m) / step_m + 1e-9))
    best, best_room = 0.0, -np.inf
    for k in range(n + 1):
        for shift in ((0.0,) if k == 0 else (k * step_m, -k * step_m)):
            q = p + shift * a
            room = min((float(np.linalg.norm(q - c)) - radius_m - r for c, r in obstacles), default=np.inf)
            if room >= margin_m - 1e-9:
                return float(shift)
            if room > best_room + 1e-12:
                best, best_room = float(shift), room
    return best


def _body_name(target, obj: str) -> str:
    """The model body of object ``obj``: the target's ``object_body`` (LIBERO's object
    ``plate_1`` is body ``plate_1_main``), else the object's own name."""
    return target.object_body(obj) if hasattr(target, "object_body") else obj


def _disc_radius(half, round_: bool) -> float:
    """Radius (m) of the circle round a perceived footprint: a round one's radius, else its
    box's horizontal half diagonal (``half`` (3,) half extents in the object's frame; the
    circle is the same whatever the box's yaw)."""
    return float(max(half[0], half[1])) if round_ else float(np.hypot(half[0], half[1]))


def _obstacles(snapshot: dict, *, skip) -> list[tuple[np.ndarray, float]]:
    """``((2,) centre, radius m)`` of every perceived object and unknown thing on the table
    but those named in ``skip``, as discs round their footprints (:func:`_disc_radius`; the
    world frame)."""
    out = []
    for e in snapshot.get("entities", []):
        if e.get("name") in skip or e.get("kind") not in ("object", "unknown"):
            continue
        size = np.asarray(e.get("size") or (0.0, 0.0, 0.0), dtype=float)
        radius = _disc_radius(size, (e.get("attributes") or {}).get("shape") == "cylinder")
        out.append((np.asarray(e["position"], dtype=float)[:2], radius))
    return out


def _push_rotation(yaw: float, direction: np.ndarray, *, edge_on: bool, lean_rad: float) -> np.ndarray:
    """(3, 3) world rotation of the tcp pushing along the (3,) horizontal unit ``direction``:
    top-down at ``yaw`` (rad, the fingers' closing axis, tcp y, across the push) or turned a
    quarter turn (``edge_on``: that axis along the push), then leant by ``lean_rad`` about the
    horizontal tcp axis across the push, the hand's body forward over the object and the
    fingertips behind it."""
    R = top_down_rotation(yaw + (np.pi / 2 if edge_on else 0.0))
    if lean_rad == 0.0:
        return R
    c, s = np.cos(lean_rad), np.sin(lean_rad)
    for sign in (1.0, -1.0):
        if edge_on:  # about tcp x
            L = np.array([[1.0, 0.0, 0.0], [0.0, c, -sign * s], [0.0, sign * s, c]])
        else:  # about tcp y
            L = np.array([[c, 0.0, -sign * s], [0.0, 1.0, 0.0], [sign * s, 0.0, c]])
        out = R @ L
        if float(out[:, 2] @ direction) < 0.0:  # the hand's axis (to the fingertips) points back
            return out
    raise AssertionError("unreachable: one of the two leans points the hand's axis back")


class ComputePush(Primitive):
    """Start and pre-start tcp poses to push ``object`` along the table with the closed hand.

    Either along ``direction`` by ``distance_m``, or to the viewer's ``side`` of ``landmark``
    (``push the plate to the front of the stove``): to where :func:`~.perception.beside_point`
    sets an object down there, its footprint :data:`PUSH_BESIDE_GAP_M` clear of the landmark's
    (the middle of the verifier's reach: a push lands less surely than a place), level with the
    landmark's centre across, or moved across by :func:`free_shift` to the nearest spot clear of
    every other perceived object (at most :data:`PUSH_MAX_SHIFT` of the landmark's half width);
    the direction and distance are then those from the object's perceived centre to that point.

    The tcp starts ``clearance_m`` behind the object's face (its extent along the direction from
    the perceived centre: its box's, or its radius when perceived round), the fingers across the
    direction, low enough that the closed fingertips meet the object but stay
    ``tip_clearance_m`` above the surface it stands on (its box's bottom); the push ends where
    the face has moved the distance. The start poses are tried in order (:meth:`_candidates`)
    until one's start and pre-start the arm reaches clear of collisions
    (:func:`~.perception.reach_blocked`): the hand top-down, then leaning over the object by
    each of :data:`PUSH_LEANS_RAD`; then the same turned edge-on, its closing axis along the
    push (the hand's body is then 6.2 cm across the push instead of 20.8, robosuite's Panda,
    and the closed fingers' outer face pushes: :data:`CLOSED_FINGERS_DEPTH_M`); then all of
    those :data:`TIGHT_CLEARANCE_M` behind the face. None of them clear: upright, fingers
    across, and the planner reports the collision.

    **Pressed from above** (``strategy``, :data:`PUSH_STRATEGIES`): a low object (a plate, a flat
    box; :data:`PRESS_MAX_HEIGHT_M`) is moved with the closed fingertips pressed on it at its
    perceived centre, the hand's closing axis along the way (its narrow side across it), so no
    room is needed behind it (a plate against a cabinet's side). The start stands
    :data:`PRESS_START_ABOVE_M` above the object's top; :class:`Push` lowers from there until
    it lands (:data:`PRESS_CONTACT_N`) and drags the object to the goal,
    :data:`PRESS_DEPTH_M` below where it landed. Its pre-start is straight above the start
    (``approach_height_m``, then lower: :data:`~.perception.LOWER_APPROACH_M`, where the hand
    turned along the way meets a fixture above); the drag's way (a third, two thirds, the end)
    and straight above its end must be reachable clear of everything but the object too.
    ``press`` is then written with ``{contact_n, depth_m, descent_m, object, top_m, tip_m}``
    (``top_m`` the object's perceived top, world z in m; ``tip_m`` the fingertips' depth below
    the tcp, m), else ``None``. In
    ``auto`` the presses are tried first, then the starts behind.

    Args:
        object: the object to push.
        direction: ``[dx, dy]`` world-frame push direction (normalised here); with ``distance_m``.
        distance_m: how far the object should move, m.
        landmark: the thing to push the object beside (an object or a fixture); with ``side``.
        side: ``left`` / ``right`` / ``front`` (towards the viewer) / ``back``
            (:data:`~phyagentos.geometry.VIEWER_SIDES`).
        strategy: one of :data:`PUSH_STRATEGIES`.
        press_carry: the fraction (0, 1] of the hand's way a pressed object makes (it creeps
            under the fingertips); the hand drags it ``1 / press_carry`` times the distance.
        clearance_m: gap between the fingertips and the object at the start, m.
        approach_height_m: how far the pre-start stands back from the start along the hand's
            axis (straight above it when upright; over the object when leaning), m.
        tip_clearance_m: fingertips above the surface the object stands on, m.
        snapshot: blackboard key of the observation.
        start, prestart, goal: blackboard keys written with (4, 4) world tcp poses (goal:
            where the hand ends the push).
        press: blackboard key written with the press from above (a dict) or ``None``.

    Raises:
        ValueError: neither or both of (``direction``, ``distance_m``) and (``landmark``,
            ``side``), a direction that is not 2 finite numbers, a distance not > 0, a side not
            one of :data:`~phyagentos.geometry.VIEWER_SIDES`, a strategy not one of
            :data:`PUSH_STRATEGIES`.
        PrimitiveFailure: (at the step) ``perception.not_found`` / ``perception.no_viewer`` as
            :func:`~.perception.beside_point`.
    """

    def __init__(self, name: str, *, object: str, direction=None, distance_m: float | None = None,
                 landmark: str | None = None, side: str | None = None, strategy: str = "auto",
                 press_carry: float = 1.0, clearance_m: float = 0.02, approach_height_m: float = 0.10,
                 tip_clearance_m: float = 0.005, snapshot: str = "snapshot", start: str = "push_start_pose",
                 prestart: str = "push_prestart_pose", goal: str = "push_goal_pose", press: str = "push_press"):
        super().__init__(name)
        if strategy not in PUSH_STRATEGIES:
            raise ValueError(f"{name}: strategy must be one of {', '.join(PUSH_STRATEGIES)}, got {strategy!r}")
        if not (isinstance(press_carry, (int, float)) and 0.0 < press_carry <= 1.0):
            raise ValueError(f"{name}: press_carry must be in (0, 1], got {press_carry!r}")
        self.strategy, self.press_carry = strategy, float(press_carry)
        pairs = ((direction, distance_m), (landmark, side))
        given = [all(v is not None for v in pair) for pair in pairs]
        partial = any(any(v is not None for v in pair) and not full for pair, full in zip(pairs, given))
        if sum(given) != 1 or partial:
            raise ValueError(f"{name}: give either direction and distance_m, or landmark and side; got "
                             f"direction={direction!r}, distance_m={distance_m!r}, landmark={landmark!r}, "
                             f"side={side!r}")
        self.landmark, self.side = landmark, side
        self.direction, self.distance_m = None, None
        if landmark is None:
            d = np.asarray(direction, dtype=float)
            if d.shape != (2,) or not np.all(np.isfinite(d)) or np.linalg.norm(d) < 1e-9:
                raise ValueError(f"direction must be 2 finite numbers, not both 0, got {direction!r}")
            if not (isinstance(distance_m, (int, float)) and distance_m > 0):
                raise ValueError(f"distance_m must be > 0 m, got {distance_m!r}")
            self.direction, self.distance_m = d / np.linalg.norm(d), float(distance_m)
        elif side not in VIEWER_SIDES:
            raise ValueError(f"side must be one of {', '.join(VIEWER_SIDES)}, got {side!r}")
        self.object = object
        self.clearance_m, self.approach_height_m = float(clearance_m), float(approach_height_m)
        self.tip_clearance_m = float(tip_clearance_m)
        self.snapshot_key, self.start_key, self.prestart_key, self.goal_key = snapshot, start, prestart, goal
        self.press_key = press
        self.reads(snapshot)
        self.writes(start, prestart, goal, press)

    def step(self):
        snapshot = self.get(self.snapshot_key)
        T_obj, half = entity_pose(snapshot, self.object)
        half = np.asarray(half, dtype=float)
        attrs = next(e for e in snapshot["entities"] if e["name"] == self.object).get("attributes") or {}
        round_ = attrs.get("shape") == "cylinder"

        def extent(d: np.ndarray) -> float:  # half extent along the horizontal unit vector d (a round one's radius)
            if round_:
                return float(max(half[0], half[1]))
            return float(np.abs(T_obj[:3, :3].T @ np.array([d[0], d[1], 0.0])) @ half)

        shift = 0.0
        if self.landmark is not None:
            side_xy = viewer_side(snapshot, self.side, who=self.name, of=self.landmark)
            goal, _ = beside_point(snapshot, self.landmark, self.side,
                                   extent(side_xy) + PUSH_BESIDE_GAP_M - BESIDE_GAP_M, who=self.name)
            T_lm, lm_half = landmark_box(snapshot, self.landmark)
            across = np.array([-side_xy[1], side_xy[0]])
            width = float(np.abs(T_lm[:3, :3].T @ np.array([across[0], across[1], 0.0])) @ lm_half)
            shift = free_shift(goal[:2], across, _disc_radius(half, round_),
                               _obstacles(snapshot, skip=(self.object, self.landmark)),
                               max_shift_m=PUSH_MAX_SHIFT * width)
            goal = goal.copy()
            goal[:2] += shift * across
            move = goal[:2] - T_obj[:2, 3]
            distance = float(np.linalg.norm(move))
            # already there (within a centimetre): a centimetre more towards that side, so the push still
            # touches what it was asked to push
            direction = move / distance if distance >= MIN_PUSH_M else side_xy
            distance = max(distance, MIN_PUSH_M)
        else:
            direction, distance = self.direction, self.distance_m
        height = 2.0 * float(np.abs(T_obj[2, :3]) @ half)
        bottom = float(T_obj[2, 3]) - height / 2.0
        target = getattr(self.ctx, "target", None)
        tip_m = float((getattr(target, "finger_geometry_m", None) or FRANKA_FINGERS)[0])  # tcp above the fingertips
        tips = getattr(target, "fingertip_friction", None)
        press_first = self.strategy == "above" or (
            self.strategy == "auto" and height <= PRESS_MAX_HEIGHT_M and tips is not None
            and tips >= PRESS_MIN_TIP_FRICTION)
        poses = []
        if press_first:
            poses += self._press_poses(T_obj[:3, 3], bottom + height, direction, distance, tip_m)
        if self.strategy != "above":
            poses += self._behind_poses(T_obj, bottom, extent(direction), direction)
        (info, T, P, G, press), rejected = self._choose(poses, bottom + tip_m + PRESS_DEPTH_M)
        if press is None:  # the hand travels the gap, then the object's distance
            G[:2, 3] += (info["clearance_m"] + distance) * direction
        else:
            press = {**press, "descent_m": round(float(T[2, 3] - tip_m - bottom), 4), "object": self.object,
                     "top_m": round(bottom + height, 4), "tip_m": round(tip_m, 4)}
        self.set(self.start_key, T)
        self.set(self.prestart_key, P)
        self.set(self.goal_key, G)
        self.set(self.press_key, press)
        self.ctx.trace.record("push_pose", object=self.object, start=T[:3, 3].round(4).tolist(),
                              direction=np.round(direction, 4).tolist(), distance_m=round(distance, 4),
                              **info, rejected=rejected,
                              **({"landmark": self.landmark, "side": self.side, "shift_m": round(shift, 4)}
                                 if self.landmark else {}))

    def _choose(self, poses: list, land_z: float) -> tuple[tuple, list[dict]]:
        """The first of ``poses`` (:meth:`_press_poses`, :meth:`_behind_poses`) the arm reaches
        clear, and why each before it was refused; none clear: the first, and the planner says
        why. A press's lower pre-start is tried only where the one above was what blocked; a
        press lands with the tcp at ``land_z`` (m, world) at the lowest."""
        rejected: list[dict] = []
        chosen = None
        for info, T, P, G, press in poses:
            if press is not None and info["approach_m"] != self.approach_height_m and not (
                    rejected and str(rejected[-1]["why"]).startswith("push prestart")):
                continue
            why = self._blocked(P, T)
            if why is None and press is not None:
                G_up, T_land = G.copy(), T.copy()
                G_up[2, 3] += self.approach_height_m
                T_land[2, 3] = land_z
                why = self._way_blocked(T_land, T, G, G_up)
            if why is None:
                return (info, T, P, G, press), rejected
            rejected.append({**info, "why": str(why)})
            chosen = chosen or (info, T, P, G, press)
        return chosen, rejected

    def _press_poses(self, centre, top: float, direction: np.ndarray, distance: float, tip_m: float) -> list:
        """``(info, start, prestart, goal, press)`` of the presses from above, in the order tried
        (:data:`PRESS_TURNS`), each with its pre-start ``approach_height_m`` and then
        :data:`~.perception.LOWER_APPROACH_M` straight above the start; the start over ``centre``
        ((3,) world, m) with the fingertips (``tip_m`` m below the tcp: the target's
        ``finger_geometry_m``) :data:`PRESS_START_ABOVE_M` above ``top`` (m), the goal
        ``distance / press_carry`` m along the (2,) unit ``direction`` (the object moves with the
        hand, less its creep)."""
        yaw = float(np.arctan2(direction[1], direction[0]))
        heights = [self.approach_height_m, *(h for h in LOWER_APPROACH_M if h < self.approach_height_m)]
        out = []
        for turn, edge_on in PRESS_TURNS:
            for height in heights:
                T = np.eye(4)
                T[:3, :3] = top_down_rotation(yaw + turn)
                T[:3, 3] = [centre[0], centre[1], top + PRESS_START_ABOVE_M + tip_m]
                P, G = T.copy(), T.copy()
                P[2, 3] += height
                G[:2, 3] += distance / self.press_carry * direction
                info = {"press": True, "edge_on": edge_on, "turn_rad": round(turn, 4), "approach_m": height,
                        "clearance_m": 0.0, "lean_rad": 0.0}
                out.append((info, T, P, G, {"contact_n": PRESS_CONTACT_N, "depth_m": PRESS_DEPTH_M}))
        return out

    def _behind_poses(self, T_obj: np.ndarray, bottom: float, reach: float, direction: np.ndarray) -> list:
        """``(info, start, prestart, goal, None)`` of the starts behind the object
        (:meth:`_candidates`), ``reach`` m its extent along the (2,) unit ``direction`` from its
        centre; the goal is the start (the caller moves it by the gap and the distance)."""
        z = max(float(T_obj[2, 3]), bottom + FINGERTIP_BELOW_TCP_M + self.tip_clearance_m)
        # fingers close along the tcp y axis: across the push direction, or along it when turned edge-on
        yaw = float(np.arctan2(direction[1], direction[0]))
        d3 = np.array([direction[0], direction[1], 0.0])
        out = []
        for clearance, edge_on, lean in self._candidates():
            face = CLOSED_FINGERS_DEPTH_M if edge_on else FINGER_HALF_THICKNESS_M
            xy = T_obj[:2, 3] - (reach + clearance + face) * direction
            T = np.eye(4)
            T[:3, :3] = _push_rotation(yaw, d3, edge_on=edge_on, lean_rad=lean)
            T[:3, 3] = [xy[0], xy[1], z]
            P = T.copy()  # back along the hand's own axis: straight above, or over the object when leaning
            P[:3, 3] -= self.approach_height_m * T[:3, 2]
            info = {"press": False, "clearance_m": clearance, "edge_on": edge_on, "lean_rad": lean}
            out.append((info, T, P, T.copy(), None))
        return out

    def _candidates(self) -> list[tuple[float, bool, float]]:
        """``(clearance m, edge_on, lean rad)`` of the start poses, in the order tried: the
        skill's clearance first, the hand across then edge-on, each upright then leaning
        (:data:`PUSH_LEANS_RAD`); then the same with :data:`TIGHT_CLEARANCE_M` where that is less
        (a plate 3 cm from a cabinet's side leaves the fingers no 2 cm gap)."""
        clearances = [self.clearance_m] + ([TIGHT_CLEARANCE_M] if TIGHT_CLEARANCE_M < self.clearance_m else [])
        return [(c, e, lean) for c in clearances for e in (False, True) for lean in PUSH_LEANS_RAD]

    def _blocked(self, T_pre: np.ndarray, T_start: np.ndarray):
        """Why the arm cannot stand at ``T_pre`` and then ``T_start`` ((4, 4) world tcp poses:
        :func:`~.perception.reach_blocked`); ``None`` when it can."""
        return reach_blocked(self.ctx, self.object, ("push prestart", T_pre), ("push start", T_start))

    def _way_blocked(self, T_land: np.ndarray, T_start: np.ndarray, T_end: np.ndarray, T_above: np.ndarray):
        """Why the arm cannot press and drag: land at ``T_land`` (as low as a press lands, the
        fingertips :data:`PRESS_DEPTH_M` above the object's bottom, on a plate's floor: a neighbour
        as high as the hand's body beside it counts), then drag from ``T_start`` to ``T_end`` (at
        the start's height, the fingertips over the object's top: what stands lower in its way is
        the object's to push, not the hand's to meet) and lift straight up to ``T_above`` ((4, 4)
        world tcp poses). The landing, the poses a third and two thirds of the way and its end are
        each reached (IK seeded from the one before) clear of everything but the object, then the
        pose above the end; ``None`` when it can."""
        q = None
        poses = [("press landing", T_land)]
        for label, f in (("press way 1/3", 1.0 / 3.0), ("press way 2/3", 2.0 / 3.0), ("press end", 1.0)):
            T = T_start.copy()
            T[:3, 3] += f * (T_end[:3, 3] - T_start[:3, 3])
            poses.append((label, T))
        for label, T in poses:
            why, q = self._reach(label, T, q)
            if why is not None:
                return why
        return reach_blocked(self.ctx, self.object, ("press end above", T_above), ("press end", T_end))

    def _reach(self, label: str, T: np.ndarray, q_seed):
        """``(why blocked or None, the solution's joints)`` of one pose of the drag's way."""
        try:
            sol, pairs, _ = clear_ik(self.ctx, T, q_seed=q_seed, allow=_object_body(self.ctx, self.object),
                                     margin_m=0.0)
        except IKError as exc:
            return Blocked(f"{label}: {str(exc)[:100]}", stage=label, collides=False), None
        if pairs:
            return Blocked(f"{label} collides: {', '.join('-'.join(pr) for pr in pairs[:3])}", stage=label,
                           collides=True), None
        return None, sol.q


class Push(_ContactMotion):
    """Push: a straight tcp motion (to a blackboard pose or by an ``offset``) that must touch something.

    With a press from above on the blackboard (``press``, written by :class:`ComputePush`:
    ``{contact_n, depth_m, descent_m, object, top_m, tip_m}``), the push first lowers the hand
    straight down, at most ``descent_m`` m, until it presses with ``contact_n`` N
    (``contact.missing`` when it lands on nothing, ``execution.collision`` when the fingertips
    stop more than :data:`PRESS_LANDED_ABOVE_TOP_M` above ``object``'s perceived top ``top_m``,
    where the press gives it: they met something else first), then drags the
    object: the same straight motion, its height ``depth_m`` m below where the hand landed.

    Args:
        to: blackboard key of the (4, 4) world tcp pose where the push ends; or
        offset: (3,) world-frame tcp displacement, m (the whole push, from the start pose).
        velocity_scale: fraction (0, 1] of the joint velocity limits.
        tracking_tol_rad: joint tracking error tolerated while pushing, rad (contact
            makes the arm lag; a free-space motion would call that a collision).
        max_force_n: effort limit: the push stops and fails with
            ``contact.excessive_force`` when the robot presses harder, N (checked after
            every physics step).
        expect_contact: fail with ``contact.missing`` if nothing was touched.
        press: blackboard key of the press from above (``None`` or a missing key: no press).

    Blackboard: writes ``contact`` with ``{max_force_n, touched}`` (``touched``: the robot's parts
    that touched anything during the push, the table's contacts included).
    """

    def __init__(self, name: str, *, to: str | None = None, offset=None, velocity_scale: float = 0.05,
                 tracking_tol_rad: float = 0.15, max_force_n: float = 40.0, expect_contact: bool = True,
                 press: str | None = None):
        super().__init__(name)
        self._motion_args(to=to, offset=offset, velocity_scale=velocity_scale, tracking_tol_rad=tracking_tol_rad,
                          force_limit_n=max_force_n, force_name="max_force_n", expect_contact=expect_contact,
                          allow_to=True)
        self.max_force_n = float(max_force_n)
        self.press_key = press
        if press is not None:
            self.reads(press)

    def on_enter(self):
        self._peak, self._touched = 0.0, set()
        press = self.get(self.press_key) if self.press_key is not None else None
        self._press = dict(press) if press else None
        if self._press is None:
            self._plan_push()
            return
        T = self.ctx.target.tcp_pose()
        T[2, 3] -= float(self._press["descent_m"])
        self._plan_push(T)

    def _plan_push(self, T_goal: np.ndarray | None = None) -> None:
        self._plan(T_goal)
        self._ignore = frozenset()  # a push counts every contact, a held object's too (fingertips pressed on it)

    def _sample(self, force: float, touched: tuple[str, ...]) -> None:
        self._peak = max(self._peak, force)
        self._touched.update(touched)

    def _landed(self) -> Status:
        """The descent of a press from above: drag from where the hand landed, or fail."""
        target = self.ctx.target
        press = self._press
        s = self._stream(lambda force: force >= press["contact_n"])
        if self._touched_down(s, "the press"):
            target.halt()
            T_now = target.tcp_pose()
            tips_z = float(T_now[2, 3]) - float(press.get("tip_m", 0.0))
            if "top_m" in press and tips_z > float(press["top_m"]) + PRESS_LANDED_ABOVE_TOP_M:
                raise PrimitiveFailure("execution.collision",
                                       f"the press landed with the fingertips at z {tips_z:.3f} m, "
                                       f"{tips_z - float(press['top_m']):.3f} m above {press['object']}'s perceived "
                                       f"top (at most {PRESS_LANDED_ABOVE_TOP_M} m): on something else")
            if self.to is not None:
                G = np.asarray(self.get(self.to), dtype=float).copy()
            else:
                G = T_now.copy()
                G[:3, 3] += self.offset
            G[2, 3] = T_now[2, 3] - float(press["depth_m"])
            self.ctx.trace.record("press", leaf=self.name, force_n=round(s.force_n, 3), touched=list(s.touched),
                                  landed_z=round(float(T_now[2, 3]), 4), tips_z=round(tips_z, 4),
                                  top_m=press.get("top_m"))
            self._press = None
            self._plan_push(G)
            return Status.RUNNING
        if self._t < self._traj.duration - 1e-9:
            return Status.RUNNING
        target.halt()
        raise PrimitiveFailure("contact.missing", f"lowered {press['descent_m']:.3f} m to press and touched nothing "
                                                  f"(expected {press['contact_n']} N)")

    def step(self):
        if self._press is not None:
            return self._landed()
        ctx = self.ctx
        target = ctx.target
        s = self._stream(lambda force: force > self.max_force_n)
        if s.stopped:
            target.halt()
            raise PrimitiveFailure("contact.excessive_force",
                                   f"pushing with {s.force_n:.1f} N on {list(s.touched)} exceeds max_force_n "
                                   f"{self.max_force_n} N")
        if not s.completed:
            raise PrimitiveFailure("execution.tracking",
                                   f"push blocked: tracking error {s.max_tracking_error_rad:.3f} rad exceeded "
                                   f"tracking_tol_rad {self.tracking_tol_rad} with {s.force_n:.1f} N on {list(s.touched)}")
        if self._t < self._traj.duration - 1e-9:
            return Status.RUNNING
        target.settle(self._traj.q[-1])
        info = {"max_force_n": round(self._peak, 3), "touched": sorted(self._touched)}
        self.set("contact", info)
        ctx.trace.record("push", leaf=self.name, **info)
        if self.expect_contact and not self._touched:
            raise PrimitiveFailure("contact.missing", f"pushed {self._length:.3f} m and touched nothing")
        return Status.SUCCESS
