"""Shutting a door on a vertical hinge by pushing it along its sweep (LIBERO's microwave).

The door is the one a perceived fixture reports (:mod:`phyagentos.perception.door`: its hinge,
slab, handle and joint, in ``attributes`` of the fixture entity). No grasp: the closed fingers,
pointing down, meet the slab's outer face under its top edge, where the hand's palm passes
over the door and its handle, and follow the circle a point of the face describes about the
hinge to where the door is shut, a little into it, so the door's own stop holds them there.
Where the stop held the hand is the reading that the door is shut (the drawer's push home is
the same idea: :class:`~phyagentos.primitives.affordance.ArticulateSlide`).

:class:`ComputeDoorPush` writes the push's start and the pose above it to the blackboard;
:class:`PushDoor` sweeps from there.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from py_trees.common import Status

from phyagentos.errors import IKError
from phyagentos.motion.cartesian import cartesian_path
from phyagentos.motion.retime import retime

from .affordance import _entity
from .base import Primitive, PrimitiveFailure
from .execution import _Tracking
from .motion import execution_limits, ik_options, nearer_reachable_hand
from .observation import save_tracks

__all__ = ["ComputeDoorPush", "PushDoor", "PUSH_RADIUS_FRACTION", "HANDLE_CLEAR_M", "BELOW_TOP_M", "START_MARGIN_RAD",
           "START_CLEAR_M", "PRESS_M", "FINGER_HALF_M", "STOP_LAG_M", "STOP_BAND_RAD"]

#: Where along the door (fraction of its width from the hinge) the fingers push, and how far
#: short of its handle at least, m: the palm, 20 cm across the fingers' closing, passes the
#: handle's stand-offs. On LIBERO's microwave (26 cm wide, handle at 23.75 cm): 16 cm.
PUSH_RADIUS_FRACTION, HANDLE_CLEAR_M = 0.62, 0.06
#: How far under the door's top edge the tool point pushes, m: the Panda hand's palm, about 5
#: cm above its tool point, then passes over the door's top edge and its handle's (1.09 m on
#: LIBERO's table against the door's 1.108 m); pushed 3 cm lower, the palm met the handle, and
#: with the hand across the door at the shut end it rode on the door's top edge and pulled
#: the door 0.07-0.15 rad back open when it left (LIBERO-90 task 33, generated scene 500).
BELOW_TOP_M = 0.035
#: The push starts this much further open than the door was read (rad), clear of it by
#: :data:`START_CLEAR_M` m: 10 times the reading's 1-sigma.
START_MARGIN_RAD = 0.3
START_CLEAR_M = 0.01
#: How far into the face (m) the fingers are sent along the sweep, so they stay on it while the
#: door, light and damped, lags them; at the shut end its stop holds them this far back.
PRESS_M = 0.012
#: From the tool point to the outer face of the Panda hand's closed fingertips across them, m
#: (measured: the tool point 9 mm off the microwave door's face it pushed, LIBERO-90 task 33).
FINGER_HALF_M = 0.009
#: The stop held the hand when it ends at least this far short of where it was sent, m (the
#: drawer's push home: :data:`~phyagentos.primitives.affordance.STOP_LAG_M`).
STOP_LAG_M = 0.004
#: A stop met within this of the shut end (rad, the door's joint) is the shut stop: twice the
#: door reading's 1-sigma (:data:`~phyagentos.perception.door.DOOR_SIGMA_RAD`), the perceived
#: hinge's error turned into an angle at the push's radius being about as large.
STOP_BAND_RAD = 0.06


def _door(snapshot: dict, name: str) -> tuple[dict, dict]:
    ent = _entity(snapshot, name)
    attrs = ent.get("attributes") or {}
    door = attrs.get("door")
    if attrs.get("joint_type") != "hinge" or not isinstance(door, dict) or attrs.get("anchor") is None:
        raise PrimitiveFailure("perception.affordance", f"{name!r} reports no door (a fixture whose look declares "
                                                        f"one, perceived: attributes.door and its hinge)")
    return attrs, door


def _door_yaw(door: dict, opening: float) -> float:
    """World yaw (rad) of the door's direction (hinge to free edge) opened ``opening`` rad."""
    return float(door["shut_yaw_rad"]) + float(door["turn"]) * float(opening)


def _contact_xy(hinge: np.ndarray, door: dict, yaw: float, radius: float, offset: float) -> np.ndarray:
    """(2,) world m: ``radius`` along the door pointing along ``yaw`` from ``hinge``, ``offset``
    out along its outer normal."""
    u = np.array([math.cos(yaw), math.sin(yaw)])
    a = yaw + float(door["outer"]) * 0.5 * math.pi
    return hinge + radius * u + offset * np.array([math.cos(a), math.sin(a)])


class ComputeDoorPush(Primitive):
    """The start of a push that shuts ``object``'s door, and the pose above it.

    From the fixture entity's door (its hinge ``anchor``, ``attributes.door``, the opening read
    ``joint_position``, rad; without a reading the far end of its travel ``range_rad``): the tool point pointing
    down at :data:`BELOW_TOP_M` under the door's top, :data:`PUSH_RADIUS_FRACTION` along it
    (:data:`HANDLE_CLEAR_M` short of its handle), :data:`START_CLEAR_M` off its outer face, the
    door taken :data:`START_MARGIN_RAD` further open than read; the hand's closing axis along the
    shut door (the palm across the sweep at the start, along the door at the end), of the two
    such hands the one that the arm reaches at both ends of the sweep, nearer the current
    wrist. Writes ``grasp_pose`` (the start, (4, 4) world) and ``pregrasp_pose``
    (``approach_height_m`` above it), and ``door_push`` (the sweep, for :class:`PushDoor`).

    Args:
        object: the fixture with the door.
        approach_height_m: the pose above the start, m.

    Raises:
        ValueError: ``approach_height_m`` not positive.
    """

    def __init__(self, name: str, *, object: str, approach_height_m: float = 0.08, snapshot: str = "snapshot"):
        super().__init__(name)
        if not approach_height_m > 0:
            raise ValueError(f"approach_height_m must be > 0, got {approach_height_m!r}")
        self.object, self.approach_height_m, self.snapshot_key = object, float(approach_height_m), snapshot
        self.reads(snapshot)
        self.writes("grasp_pose", "pregrasp_pose", "door_push")

    def step(self):
        attrs, door = _door(self.get(self.snapshot_key), self.object)
        hinge = np.asarray(attrs["anchor"], dtype=float)[:2]
        travel = float(attrs["range_rad"][1])
        read = attrs.get("joint_position")
        o0 = travel if read is None else min(float(read) + START_MARGIN_RAD, travel)
        width = float(door["width_m"])
        radius = PUSH_RADIUS_FRACTION * width
        if door.get("handle_r_m") is not None:
            radius = min(radius, float(door["handle_r_m"]) - HANDLE_CLEAR_M)
        face = float(door["mid_m"]) + 0.5 * float(door["thickness_m"])
        z = float(door["z_m"][1]) - BELOW_TOP_M
        shut_yaw = float(door["shut_yaw_rad"])
        start = _contact_xy(hinge, door, _door_yaw(door, o0), radius, face + FINGER_HALF_M + START_CLEAR_M)
        end = _contact_xy(hinge, door, shut_yaw, radius, face + FINGER_HALF_M - PRESS_M)
        closing = np.array([math.cos(shut_yaw), math.sin(shut_yaw), 0.0])
        ends = [np.array([start[0], start[1], z]), np.array([end[0], end[1], z])]
        best = nearer_reachable_hand(self.ctx, closing, np.array([0.0, 0.0, -1.0]), ends)
        if best is None:
            raise PrimitiveFailure("ik.unreachable", f"{self.object!r}: the arm reaches neither hand along the push "
                                                     f"that shuts its door (from {np.round(start, 3).tolist()} to "
                                                     f"{np.round(end, 3).tolist()} m at z {z:.3f} m)")
        S = np.eye(4)
        S[:3, :3], S[:3, 3] = best[1], ends[0]
        P = S.copy()
        P[2, 3] += self.approach_height_m
        self.set("grasp_pose", S)
        self.set("pregrasp_pose", P)
        sweep: dict[str, Any] = {"object": self.object, "hinge": hinge.tolist(), "radius_m": radius, "z_m": z,
                                 "R": S[:3, :3].tolist(), "opening_start": o0, "face_m": face, "door": dict(door),
                                 "read_rad": read}
        self.set("door_push", sweep)
        self.ctx.trace.record("door_push", leaf=self.name, object=self.object, read_rad=read, start_rad=round(o0, 4),
                              radius_m=round(radius, 4), start=np.round(S[:3, 3], 4).tolist(),
                              end=[round(float(end[0]), 4), round(float(end[1]), 4), round(z, 4)])
        return Status.SUCCESS


class PushDoor(_Tracking):
    """Sweep the closed fingers along the door's circle from the push's start to its shut end
    (``door_push`` from :class:`ComputeDoorPush`), :data:`PRESS_M` into its face, and read where
    its stop held the hand.

    Poses every ``step_rad`` of the door's opening, joined by Cartesian IK, timed with toppra at
    ``velocity_scale`` of the joint limits and streamed with the tracking check; the hand keeps
    its orientation (the fingers, pointing down, meet the face alike either way). The motion
    ends where the door's stop holds the hand: a tracking failure there, or a settle that ends
    :data:`STOP_LAG_M` or more short of where it was sent, is the stop, not a fault. The door's
    opening at the contact is then read from the hand (joint encoders, forward kinematics) and
    the perceived hinge: within :data:`STOP_BAND_RAD` of shut it is the shut stop, and the
    session's perceiver is told (:meth:`~phyagentos.perception.Perceiver.note_door_stop`: the
    door is reported shut from then on, to the stop's 1-sigma); held further open, the door is
    blocked (``execution.blocked``: something in its way); never held, the perceiver is told
    nothing (the verifier then has only the door's look, which cannot confirm "shut"). Traced as
    ``door_stop``.

    Args:
        step_rad: the door's opening between consecutive poses, rad.
        velocity_scale: fraction (0, 1] of the joint velocity limits.

    Raises:
        ValueError: a value out of range.
    """

    def __init__(self, name: str, *, step_rad: float = 0.05, velocity_scale: float = 0.5):
        super().__init__(name)
        if not 0 < step_rad <= 0.5:
            raise ValueError(f"step_rad must be in (0, 0.5], got {step_rad!r}")
        if not 0 < velocity_scale <= 1:
            raise ValueError(f"velocity_scale must be in (0, 1], got {velocity_scale!r}")
        self.step_rad, self.velocity_scale = float(step_rad), float(velocity_scale)
        self.reads("door_push")

    def on_enter(self):
        ctx, target = self.ctx, self.ctx.target
        sweep = self._sweep = self.get("door_push")
        door = sweep["door"]
        o0 = float(sweep["opening_start"])
        hinge, radius, z = np.asarray(sweep["hinge"], float), float(sweep["radius_m"]), float(sweep["z_m"])
        offset = float(sweep["face_m"]) + FINGER_HALF_M - PRESS_M
        R = np.asarray(sweep["R"], float)
        n = max(1, int(math.ceil(o0 / self.step_rad)))
        q = target.arm_qpos()
        path = [q]
        perceiver = getattr(ctx, "perceiver", None)
        if perceiver is not None and hasattr(perceiver, "forget_door_stop"):
            perceiver.forget_door_stop(self.object_name)  # it is moved now: what was known of its stop no longer holds
        T = target.tcp_pose()
        with ctx.profiler.section("ik"):
            for k in range(1, n + 1):
                ok = o0 * (1.0 - k / n)
                xy = _contact_xy(hinge, door, _door_yaw(door, ok), radius, offset)
                T = np.eye(4)
                T[:3, :3], T[:3, 3] = R, [xy[0], xy[1], z]
                try:
                    segment = cartesian_path(target.model, q_start=q, T_goal=T, **ik_options(target))
                except IKError as exc:
                    raise PrimitiveFailure("ik.unreachable", f"{self.object_name!r}: the push along its door's sweep "
                                                             f"leaves the arm's reach opened {ok:.3f} rad: {exc}"
                                           ) from exc
                path.extend(segment[1:])
                q = segment[-1]
        self._end = T[:3, 3].copy()
        vel, acc = execution_limits(ctx, self.velocity_scale, self.velocity_scale)
        with ctx.profiler.section("timing"):
            traj = retime(np.array(path), vel_limits=vel, acc_limits=acc, dt=target.model.opt.timestep)
        ctx.trace.record("door_sweep", leaf=self.name, object=self.object_name, from_rad=round(o0, 4), to_rad=0.0,
                         waypoints=len(path))
        self._start(traj)

    @property
    def object_name(self) -> str:
        return str(self._sweep["object"])

    def step(self):
        try:
            status = self._advance()
        except PrimitiveFailure as exc:
            if exc.code != "execution.tracking":
                raise
            return self._at_stop(str(exc))
        return self._at_stop("") if status == Status.SUCCESS else status

    def _at_stop(self, tracking: str) -> Status:
        """End the sweep (class docstring): where the hand stands against what held it back."""
        ctx, target, sweep = self.ctx, self.ctx.target, self._sweep
        door = sweep["door"]
        tcp = target.tcp_pose()[:3, 3]
        short = float(np.linalg.norm(tcp[:2] - self._end[:2]))
        stopped = short >= STOP_LAG_M
        if stopped:
            target.settle(target.arm_qpos(), settle_s=0.2)  # stop pushing: the door stays at its stop
        v = tcp[:2] - np.asarray(sweep["hinge"], float)
        off = float(sweep["face_m"]) + FINGER_HALF_M
        along = math.sqrt(max(float(v @ v) - off * off, 1e-12))
        yaw = math.atan2(float(v[1]), float(v[0])) - math.atan2(float(door["outer"]) * off, along)
        opening = float(door["turn"]) * ((yaw - float(door["shut_yaw_rad"]) + math.pi) % (2.0 * math.pi) - math.pi)
        at_shut = stopped and abs(opening) <= STOP_BAND_RAD
        ctx.trace.record("door_stop", leaf=self.name, object=self.object_name, short_m=round(short, 4),
                         stopped=stopped, opening_rad=round(opening, 4), at_shut=at_shut, tracking=tracking or None)
        if stopped and opening > STOP_BAND_RAD:
            raise PrimitiveFailure("execution.blocked",
                                   f"{self.object_name!r}: its door stopped {opening:.3f} rad short of shut (band "
                                   f"{STOP_BAND_RAD} rad): something holds it open")
        perceiver = getattr(ctx, "perceiver", None)
        if at_shut and perceiver is not None and hasattr(perceiver, "note_door_stop"):
            perceiver.note_door_stop(self.object_name, stamp_s=float(target.sim_time or 0.0))
            save_tracks(target, perceiver)
        return Status.SUCCESS
