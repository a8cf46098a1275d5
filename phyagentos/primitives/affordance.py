"""Leaves for what a target declares about its objects: grasp affordances and hinges.

A target's snapshot may give an entity ``attributes.grasp`` — the graspable part as a
box (``position`` (3,) m, ``quat_wxyz``, ``size`` half extents (3,) m, world frame) and,
when it is not grasped from above, ``approach`` (world unit vector from the gripper into
the part), ``closing`` (world unit vector the fingers close along), ``entry`` (the
direction the hand moves in to reach the grasp; default ``approach``) and ``free_axis``
(a round part's axis: the grasp leaves rotation about it free). An articulated
entity (kind ``articulation``) gives its joint: ``joint_type`` ``hinge``,
``joint_position`` (rad), hinge ``anchor`` (3,) m and ``axis`` (3,) unit, world frame; or
``joint_type`` ``slide`` (a drawer), ``joint_position`` (m), ``axis`` (3,) world unit direction
the joint grows along and ``range_m`` [lo, hi] m.
Skills built from these leaves therefore carry no knowledge of a particular
environment: a kettle handle, a microwave door bar or a cabinet handle are all
"a part to grasp", "a hinge to turn" and "a slide to pull".
"""

from __future__ import annotations

import math

import numpy as np
from py_trees.common import Status

from phyagentos.errors import IKError
from phyagentos.geometry import rotation_about
from phyagentos.motion.cartesian import cartesian_path
from phyagentos.motion.grasp import top_down_grasp_candidates
from phyagentos.motion.ik import solve_ik
from phyagentos.motion.retime import retime
from phyagentos.perception.fixtures import DRAWER_HANDLE_PLAY_M
from phyagentos.targets.contract import capabilities_of

from . import planning_world
from .base import Primitive, PrimitiveFailure
from .execution import _Tracking
from .grasp_sense import closed_on_something
from .motion import execution_limits, ik_options
from .observation import save_tracks
from .perception import entity_pose

__all__ = ["ComputeAffordanceGrasp", "ArticulateHinge", "ArticulateSlide", "ComputePlaceAsHeld", "ToolMove"]


def _turn_to(attrs: dict, fraction: float, travel_key: str = "range_rad") -> float | None:
    """The motion (the joint's unit and sign: rad for a hinge, m for a slide) that takes a
    joint whose entity ``attrs`` report its ``joint_position`` and travel ``attrs[travel_key]``
    [lo, hi] (``range_rad``, ``range_m``) to ``lo + fraction (hi - lo)``; None when either is
    not reported (a perceived joint not seen)."""
    q0, travel = attrs.get("joint_position"), attrs.get(travel_key)
    if q0 is None or travel is None:
        return None
    lo, hi = (float(v) for v in travel)
    return lo + fraction * (hi - lo) - float(q0)


def _about_hinge(T: np.ndarray, anchor: np.ndarray, axis: np.ndarray, angle: float, *, follow: float = 1.0) -> np.ndarray:
    """The (4, 4) world pose ``T`` carried ``angle`` rad about the hinge through ``anchor`` (3,)
    m along unit ``axis`` (3,): its position on the circle about the axis, its orientation turned
    by ``follow`` times the angle (0: kept, a bar turning inside the fingers)."""
    out = np.eye(4)
    out[:3, :3] = rotation_about(axis, follow * angle) @ T[:3, :3]
    out[:3, 3] = anchor + rotation_about(axis, angle) @ (T[:3, 3] - anchor)
    return out


def _entity(snapshot: dict, name: str) -> dict:
    for e in snapshot.get("entities", []):
        if e["name"] == name:
            return e
    raise PrimitiveFailure("perception.not_found", f"{name!r} is not in the observation; seen: "
                                                   f"{sorted(e['name'] for e in snapshot.get('entities', []))}")


class ComputeAffordanceGrasp(Primitive):
    """Grasp and pre-grasp tcp poses for the part an entity declares graspable.

    Without ``attributes.grasp`` the entity's own box is used. With an ``approach``
    vector the tcp z axis points along it and its y axis along ``closing``; the tcp goes to the part's
    centre and the pre-grasp backs off ``approach_height_m`` along the entry direction
    (default the approach); of the
    two hands 180 deg apart the one whose IK keeps the joints farthest from their
    limits is taken.
    Without one the part is grasped from above (:func:`top_down_grasp_candidates`).

    Args:
        object: entity name.
        approach_height_m: pre-grasp distance, m.
        affordance: which declared part to use: ``grasp`` (close the fingers on it) or
            ``hook`` (slide closed fingers under it and carry it on their top face).
        turn_to_fraction: the joint the part moves with will next be moved to this
            fraction of its travel from its ``joint_position`` (a hinge's ``range_rad``:
            :class:`ArticulateHinge`; a slide's ``range_m``: :class:`ArticulateSlide`): a hand is
            taken only when the arm also reaches the grasp moved that far, and its joint margin
            is the lesser of the two (a knob turned by 1 rad takes a wrist that has 1 rad to
            spare; a drawer pulled 16 cm, an arm that reaches 16 cm further).
        snapshot, grasp, pregrasp: blackboard keys (observation in; (4, 4) world tcp poses out).
    """

    IK_SEEDS = 8

    AFFORDANCES = ("grasp", "hook")

    def __init__(self, name: str, *, object: str, approach_height_m: float = 0.10, affordance: str = "grasp",
                 turn_to_fraction: float | None = None, snapshot: str = "snapshot", grasp: str = "grasp_pose",
                 pregrasp: str = "pregrasp_pose"):
        super().__init__(name)
        if approach_height_m <= 0:
            raise ValueError(f"approach_height_m must be > 0, got {approach_height_m}")
        if turn_to_fraction is not None and not 0.0 <= float(turn_to_fraction) <= 1.0:
            raise ValueError(f"turn_to_fraction must be in [0, 1], got {turn_to_fraction!r}")
        self.turn_to_fraction = None if turn_to_fraction is None else float(turn_to_fraction)
        if affordance not in self.AFFORDANCES:
            raise ValueError(f"unknown affordance {affordance!r}; valid: {', '.join(self.AFFORDANCES)}")
        self.object, self.approach_height_m, self.affordance = object, float(approach_height_m), affordance
        self.snapshot_key, self.grasp_key, self.pregrasp_key = snapshot, grasp, pregrasp
        self.reads(snapshot)
        self.writes(grasp, pregrasp)

    def step(self):
        snapshot = self.get(self.snapshot_key)
        ent = _entity(snapshot, self.object)
        part = (ent.get("attributes") or {}).get(self.affordance)
        if part is None and self.affordance != "grasp":
            raise PrimitiveFailure("perception.affordance", f"{self.object!r} declares no {self.affordance!r} affordance")
        if part is None:
            T, half = entity_pose(snapshot, self.object)
        else:
            T, half = entity_pose({"entities": [{"name": "part", **part}]}, "part")
        approach = part.get("approach") if part else None
        if approach is None:
            plan = top_down_grasp_candidates(T, half, approach_height_m=self.approach_height_m)[0]
            G, P = np.array(plan.grasp), np.array(plan.pregrasp)
        else:
            z = np.asarray(approach, dtype=float)
            z /= np.linalg.norm(z)
            y = np.asarray(part.get("closing", T[:3, 0]), dtype=float)
            y = y - z * float(y @ z)
            if np.linalg.norm(y) < 1e-6:
                raise PrimitiveFailure("perception.affordance", f"{self.object}: closing axis parallel to the approach")
            y /= np.linalg.norm(y)
            # Two hands close along +-closing (180 deg apart about the approach). Take one
            # the arm reaches from its current or ready configuration, and of those the one
            # whose IK solution keeps the joints farthest from their limits: the wrist keeps
            # room to turn with whatever the part does next (a door swinging, a knob).
            target = self.ctx.target
            names = tuple(target.arm_joint_names)
            jids = [target.model.joint(n).id for n in names]
            lo, hi = target.model.jnt_range[jids, 0], target.model.jnt_range[jids, 1]
            # IK from the current and the ready configuration, then from a few seeded random ones (a far
            # reorientation can trap a local solver; the Cartesian moves that follow
            # interpolate and do not need this seed).
            rng = np.random.default_rng(self.ctx.seed)
            try:
                ready = [np.asarray(target.home_qpos, dtype=float)]
            except KeyError:  # a model without a ``home`` keyframe (FrankaKitchen's): no ready seed
                ready = [target.arm_qpos()]
            seeds = [target.arm_qpos(), *ready, *rng.uniform(lo, hi, size=(self.IK_SEEDS, len(names)))]
            entry = np.asarray(part.get("entry", z), dtype=float)
            entry /= np.linalg.norm(entry)
            frame = target.tcp_site
            best = None
            for sign in (1.0, -1.0):
                Gs = np.eye(4)
                Gs[:3, :3] = np.column_stack([np.cross(sign * y, z), sign * y, z])
                Gs[:3, 3] = T[:3, 3]
                Ps = Gs.copy()
                Ps[:3, 3] -= entry * self.approach_height_m
                for k, seed in enumerate(seeds):
                    try:
                        with self.ctx.profiler.section("ik"):
                            qp = np.array(solve_ik(target.model, q_seed=seed, target=Ps, arm_joint_names=names,
                                                   frame=frame).q)
                            q = np.array(cartesian_path(target.model, q_start=qp, T_goal=Gs, arm_joint_names=names,
                                                        frame=frame)[-1])
                    except IKError:
                        continue
                    margin = float(np.min(np.minimum(q - lo, hi - q)))
                    turned = self._turned(ent, Gs)
                    if turned is not None:
                        try:
                            with self.ctx.profiler.section("ik"):
                                qt = np.array(cartesian_path(target.model, q_start=q, T_goal=turned,
                                                             arm_joint_names=names, frame=frame)[-1])
                        except IKError:
                            continue  # this hand cannot turn that far: another seed or the other hand
                        margin = min(margin, float(np.min(np.minimum(qt - lo, hi - qt))))
                    # a hand reached from the current or the ready configuration first (the
                    # motion to the pre-grasp solves its IK from those), then by joint margin
                    rank = (k >= 2, -margin)
                    if best is None or rank < best[0]:
                        best = (rank, Gs, Ps)
                    break
            if best is None:
                raise PrimitiveFailure("ik.unreachable", f"{self.object}: neither hand orientation reaches the grasp at "
                                                         f"{np.round(T[:3, 3], 3).tolist()}")
            _, G, P = best
        self.set(self.grasp_key, G)
        self.set(self.pregrasp_key, P)
        self.ctx.trace.record("grasp_pose", leaf=self.name, object=self.object, affordance=part is not None,
                              grasp=G[:3, 3].round(4).tolist(), approach=G[:3, 2].round(4).tolist())

    def _turned(self, ent: dict, G: np.ndarray) -> np.ndarray | None:
        """The (4, 4) tcp pose ``G`` turned about ``ent``'s hinge (or pulled along its slide) as
        far as ``turn_to_fraction`` asks from its reported position; None when no motion is
        asked or the entity does not report its joint, position and travel."""
        attrs = ent.get("attributes") or {}
        if self.turn_to_fraction is None or attrs.get("joint_type") not in ("hinge", "slide"):
            return None
        if attrs["joint_type"] == "slide":
            delta = _turn_to(attrs, self.turn_to_fraction, "range_m")
            if delta is None:
                return None
            out = G.copy()
            out[:3, 3] += delta * _unit(attrs["axis"])
            return out
        delta = _turn_to(attrs, self.turn_to_fraction)
        if delta is None:
            return None
        return _about_hinge(G, np.asarray(attrs["anchor"], dtype=float), np.asarray(attrs["axis"], dtype=float), delta)


def _unit(v) -> np.ndarray:
    a = np.asarray(v, dtype=float)
    return a / np.linalg.norm(a)


class _Articulate(_Tracking):
    """What :class:`ArticulateHinge` and :class:`ArticulateSlide` share: the motion asked
    (``delta`` in the joint's unit, or ``to_fraction`` of the travel the entity reports), the
    entity's joint read from the observation, the IK waypoints timed with toppra and streamed.
    Subclasses set :attr:`JOINT` (the ``joint_type`` they move), :attr:`TRAVEL_KEY`,
    :attr:`UNIT` and :attr:`MAX_DELTA`, and build the tcp waypoints in :meth:`poses`.
    """

    JOINT = ""
    TRAVEL_KEY = ""
    UNIT = ""
    MAX_DELTA = math.inf

    def __init__(self, name: str, *, object: str, delta: float | None, to_fraction: float | None, step: float,
                 max_step: float, velocity_scale: float, snapshot: str):
        super().__init__(name)
        d = f"delta_{self.UNIT}"
        if (delta is None) == (to_fraction is None):
            raise ValueError(f"give exactly one of {d} and to_fraction")
        if to_fraction is not None and (not isinstance(to_fraction, (int, float)) or not 0.0 <= to_fraction <= 1.0):
            raise ValueError(f"to_fraction must be a number in [0, 1], got {to_fraction!r}")
        if delta is not None and (not isinstance(delta, (int, float)) or not math.isfinite(delta) or delta == 0
                                  or abs(delta) > self.MAX_DELTA):
            unit = {"rad": "radians", "m": "metres"}[self.UNIT]
            within = f" within {self.MAX_DELTA:g} {self.UNIT}" if math.isfinite(self.MAX_DELTA) else ""
            raise ValueError(f"{d} must be a non-zero number of {unit}{within}, got {delta!r}")
        if not 0 < step <= max_step:
            raise ValueError(f"step_{self.UNIT} must be in (0, {max_step:g}], got {step}")
        if not 0 < velocity_scale <= 1:
            raise ValueError(f"velocity_scale must be in (0, 1], got {velocity_scale}")
        self.object, self.step_size = object, float(step)
        self.delta = float(delta) if delta is not None else None
        self.to_fraction = float(to_fraction) if to_fraction is not None else None
        self.velocity_scale, self.snapshot_key = float(velocity_scale), snapshot
        self.reads(snapshot)

    def poses(self, T0: np.ndarray, attrs: dict, delta: float) -> list[np.ndarray]:
        """(4, 4) world tcp poses from the grasp ``T0`` along the joint moved by ``delta``, at
        most :attr:`step_size` apart, the last one the motion's end (not ``T0``)."""
        raise NotImplementedError

    def _hand_motion(self, delta: float) -> float:
        """The hand's motion (the joint's unit and sign) that moves the joint by ``delta`` to
        ``to_fraction``: ``delta`` itself for a held handle."""
        return delta

    def on_enter(self):
        ctx = self.ctx
        target = ctx.target
        self._done = False
        ent = _entity(self.get(self.snapshot_key), self.object)
        attrs = ent.get("attributes") or {}
        if attrs.get("joint_type") != self.JOINT:
            raise PrimitiveFailure("perception.affordance", f"{self.object!r} is not a {self.JOINT} articulation "
                                                            f"(kind {ent.get('kind')!r}, joint {attrs.get('joint_type')!r})")
        delta = self.delta
        key = f"delta_{self.UNIT}"
        if self.to_fraction is not None:
            delta = _turn_to(attrs, self.to_fraction, self.TRAVEL_KEY)
            if delta is None:
                raise PrimitiveFailure("perception.affordance", f"{self.object!r}: its joint position or travel is not "
                                                                "known (the joint was not seen), so a motion to a "
                                                                "fraction of the travel cannot be planned")
            delta = self._hand_motion(delta)
            if abs(delta) < 1e-3:
                ctx.trace.record("articulate", leaf=self.name, object=self.object, **{key: 0.0},
                                 joint_position=attrs.get("joint_position"), waypoints=0)
                self._done = True
                return
        assert delta is not None
        q = target.arm_qpos()
        path = [q]
        with ctx.profiler.section("ik"):
            for Tk in self.poses(target.tcp_pose(), attrs, delta):
                segment = cartesian_path(target.model, q_start=q, T_goal=Tk, **ik_options(target))
                path.extend(segment[1:])
                q = segment[-1]
        vel, acc = execution_limits(ctx, self.velocity_scale, self.velocity_scale)
        with ctx.profiler.section("timing"):
            traj = retime(np.array(path), vel_limits=vel, acc_limits=acc, dt=target.model.opt.timestep)
        ctx.trace.record("articulate", leaf=self.name, object=self.object, **{key: round(delta, 4)},
                         joint_position=attrs.get("joint_position"), waypoints=len(path))
        self._start(traj)

    def step(self):
        return Status.SUCCESS if self._done else self._advance()


class ArticulateHinge(_Articulate):
    """Turn a held handle about its entity's hinge by ``delta_rad``, or to ``to_fraction``
    of the joint's travel.

    The tcp follows the circle the grasp point describes about the hinge axis: ``n``
    poses with positions ``anchor + Rot(axis, delta k/n) (p0 - anchor)``, turning with
    the door unless the grasped part declares a ``free_axis`` parallel to the hinge (a
    round bar turns inside the closed fingers), joined by Cartesian IK segments, timed with toppra at
    ``velocity_scale`` of the joint limits and streamed with the tracking check. A
    door that resists (not held, blocked) shows up as a tracking failure or, after
    success, as a joint angle the verifier finds unchanged.

    Args:
        object: the articulated entity (kind ``articulation``, or any entity whose attributes
            declare ``joint_type: hinge``: a perceived fixture's knob).
        delta_rad: signed rotation about the hinge axis, rad (the joint's own sign).
        to_fraction: instead of ``delta_rad``: turn to ``lo + to_fraction (hi - lo)`` of the
            entity's ``range_rad`` [lo, hi] from the ``joint_position`` it reports (perceived:
            the observation before the grasp); a failure ``perception.affordance`` when it
            reports either not.
        step_rad: largest rotation between consecutive poses, rad.
        velocity_scale: fraction (0, 1] of the joint velocity limits.
        snapshot: blackboard key of the observation holding the hinge.

    Raises:
        ValueError: not exactly one of ``delta_rad`` and ``to_fraction``, or a value out of range.
    """

    JOINT, TRAVEL_KEY, UNIT = "hinge", "range_rad", "rad"

    def __init__(self, name: str, *, object: str, delta_rad: float | None = None, to_fraction: float | None = None,
                 step_rad: float = 0.05, velocity_scale: float = 0.5, snapshot: str = "snapshot"):
        super().__init__(name, object=object, delta=delta_rad, to_fraction=to_fraction, step=step_rad, max_step=0.5,
                         velocity_scale=velocity_scale, snapshot=snapshot)

    def poses(self, T0: np.ndarray, attrs: dict, delta: float) -> list[np.ndarray]:
        anchor = np.asarray(attrs["anchor"], dtype=float)
        axis = np.asarray(attrs["axis"], dtype=float)
        # A handle that is a bar parallel to the hinge turns inside the closed fingers (its
        # declared free axis), so the hand need not turn with the door: keeping its
        # orientation spares the wrist the whole door angle.
        free = (attrs.get("grasp") or {}).get("free_axis")
        follow = 0.0 if free is not None and abs(float(np.dot(free, axis))) > 0.99 else 1.0
        n = max(1, int(math.ceil(abs(delta) / self.step_size)))
        return [_about_hinge(T0, anchor, axis, delta * k / n, follow=follow) for k in range(1, n + 1)]


#: A push to the shut stop met it when the hand ends at least this far short of where it was
#: sent, m: the servo's lag in free motion after settling is under a millimetre (its tracking
#: tolerance bounds it in motion), so 4 mm short is something holding the hand back.
STOP_LAG_M = 0.004
#: Smallest band, m, about where a slide was read shut in which a stop met is taken for the shut
#: stop (a reported joint is exact: the band is then the hand's own play on the handle).
STOP_BAND_MIN_M = 0.005
#: How far the hand may move along a drawer's axis before the handle it holds moves with it, m:
#: the bar slides between the closed fingers toward the palm. Pushed again from shut, LIBERO's
#: wooden cabinet's top drawer held the hand after 9.9 and 10.2 mm (LIBERO-90 task 0, inits 0
#: and 1, the training set: the drawer already at its stop). The hand's travel may exceed the
#: drawer's by this much, so a stop met up to this much beyond the reading's band is still the
#: shut stop; it never widens the side a jam (a drawer held out, short of shut) falls on.
HANDLE_PLAY_M = DRAWER_HANDLE_PLAY_M


class ArticulateSlide(_Articulate):
    """Pull (or push) a held handle along its entity's slide by ``delta_m``, or to
    ``to_fraction`` of the joint's travel: a drawer.

    The tcp moves in a straight line along the slide's ``axis`` (orientation kept), Cartesian
    IK every ``step_m``, timed with toppra at ``velocity_scale`` of the joint limits and
    streamed with the tracking check. A drawer that resists (not held, at its stop, blocked)
    shows up as a tracking failure or, after success, as an opening the verifier finds
    unchanged.

    **Pushed home** (``push_to_stop_m`` > 0, with ``to_fraction`` 0): the hand goes on
    ``push_to_stop_m`` past the shut end it was sent to, so it meets the drawer's shut stop
    wherever within the reading's band the drawer really is, and the motion ends where the
    stop holds it (a tracking failure there, or a settle that ends :data:`STOP_LAG_M` or more
    short, is the stop, not a fault). The hand's travel from the grasp to the stop (joint
    encoders, forward kinematics: millimetres) is compared with the travel the reading asked
    (``joint_position`` less the shut end, 0): within the reading's 2 sigma (at least
    :data:`STOP_BAND_MIN_M`; beyond it by up to :data:`HANDLE_PLAY_M`, the bar's play in the
    closed fingers) the stop is the shut stop, and the session's perceiver is told
    (:meth:`~phyagentos.perception.Perceiver.note_drawer_stop`: the drawer is read shut from
    then on, to the contact's 1-sigma, while its handle stays where a shut one is read);
    stopped shorter, it is blocked (``execution.blocked``: a bowl standing out of the drawer);
    never held back, or held back past the band, the perceiver is told nothing and the
    verifier judges the handle alone, which cannot confirm "shut". Traced as ``slide_stop``.

    **Pulled open**: a pull that ends with the fingers still closed on the handle (the hand's
    encoders) tells the session's perceiver where the hand let the drawer stand, the reading it
    began from plus the hand's travel along the axis
    (:meth:`~phyagentos.perception.Perceiver.note_drawer_opened`: a lower bound while the handle
    stays hidden). Traced as ``slide_felt``.

    Args:
        object: the articulated entity (any entity whose attributes declare ``joint_type:
            slide`` with ``axis`` (3,) world unit, ``joint_position`` m and ``range_m`` [lo, hi]
            m: a perceived drawer).
        delta_m: signed motion along the slide's axis, m (the joint's own sign).
        to_fraction: instead of ``delta_m``: move to ``lo + to_fraction (hi - lo)`` of the
            entity's ``range_m`` from the ``joint_position`` it reports (perceived: the
            observation before the grasp); a failure ``perception.affordance`` when it reports
            either not.
        step_m: largest motion between consecutive IK waypoints, m.
        velocity_scale: fraction (0, 1] of the joint velocity limits.
        snapshot: blackboard key of the observation holding the slide.
        push_to_stop_m: keyword-only; how far past the shut end the hand is sent, m, in [0,
            0.1]; 0: no push (the motion ends where it was sent). Needs ``to_fraction`` 0.
        lead_m: keyword-only; how far the hand travels before what it moves moves with it, m, in
            [0, 0.05]: the hand goes this much further (closed fingers hooked behind a drawer's
            front, :mod:`.drawer_hook`, with this gap to it and on a little against the open
            stop). 0: the hand holds the handle.

    Raises:
        ValueError: not exactly one of ``delta_m`` and ``to_fraction``, a value out of range, or
            ``push_to_stop_m`` without ``to_fraction`` 0.
    """

    JOINT, TRAVEL_KEY, UNIT, MAX_DELTA = "slide", "range_m", "m", 1.0

    def __init__(self, name: str, *, object: str, delta_m: float | None = None, to_fraction: float | None = None,
                 step_m: float = 0.02, velocity_scale: float = 0.3, snapshot: str = "snapshot",
                 push_to_stop_m: float = 0.0, lead_m: float = 0.0):
        super().__init__(name, object=object, delta=delta_m, to_fraction=to_fraction, step=step_m, max_step=0.1,
                         velocity_scale=velocity_scale, snapshot=snapshot)
        if isinstance(lead_m, bool) or not isinstance(lead_m, (int, float)) or not 0.0 <= lead_m <= 0.05:
            raise ValueError(f"lead_m must be a number of metres in [0, 0.05], got {lead_m!r}")
        self.lead_m = float(lead_m)
        if isinstance(push_to_stop_m, bool) or not isinstance(push_to_stop_m, (int, float)) \
                or not 0.0 <= push_to_stop_m <= 0.1:
            raise ValueError(f"push_to_stop_m must be a number of metres in [0, 0.1], got {push_to_stop_m!r}")
        if push_to_stop_m > 0 and self.to_fraction != 0.0:
            raise ValueError("push_to_stop_m pushes a drawer home: it needs to_fraction 0 (the shut end), got "
                             f"to_fraction {self.to_fraction!r}")
        self.push_to_stop_m = float(push_to_stop_m)
        self._push: dict | None = None

    def poses(self, T0: np.ndarray, attrs: dict, delta: float) -> list[np.ndarray]:
        axis = _unit(attrs["axis"])
        if self._push is not None:  # on past the shut end, into the stop
            delta -= self.push_to_stop_m
        n = max(1, int(math.ceil(abs(delta) / self.step_size)))
        out = []
        for k in range(1, n + 1):
            Tk = T0.copy()
            Tk[:3, 3] += axis * (delta * k / n)
            out.append(Tk)
        return out

    def _hand_motion(self, delta: float) -> float:
        """With ``lead_m`` (closed fingers against one face of the drawer): the hand goes the lead
        further; sent to an end of the travel (``to_fraction`` 0 or 1) it moves only towards
        that end, however far past it the drawer was read (a reading 5 mm beyond the open stop
        would otherwise send fingers hooked behind the front the wrong way)."""
        if self.lead_m == 0.0:
            return delta
        if self.to_fraction in (0.0, 1.0):
            end = 1.0 if self.to_fraction == 1.0 else -1.0
            return end * (max(end * delta, 0.0) + self.lead_m)
        return delta + math.copysign(self.lead_m, delta)

    def on_enter(self):
        self._push = None
        attrs = _entity(self.get(self.snapshot_key), self.object).get("attributes") or {}
        q, axis = attrs.get("joint_position"), attrs.get("axis")
        # where the drawer was read and where the hand starts: the planning world follows the drawer
        self._moved_from = ((float(q), _unit(axis), self.ctx.target.tcp_pose()[:3, 3].copy())
                            if q is not None and axis is not None else None)
        perceiver = getattr(self.ctx, "perceiver", None)
        if perceiver is not None and hasattr(perceiver, "forget_drawer_stop"):
            perceiver.forget_drawer_stop(self.object)  # it is moved now: what was known of its stop no longer holds
        if self.push_to_stop_m > 0:
            attrs = _entity(self.get(self.snapshot_key), self.object).get("attributes") or {}
            q, travel = attrs.get("joint_position"), attrs.get("range_m")
            if q is not None and travel is not None and attrs.get("axis") is not None:
                sigma = float(attrs.get("joint_position_std_m") or 0.0)
                self._push = {"expected_m": float(q), "band_m": max(2.0 * sigma, STOP_BAND_MIN_M),
                              "axis": _unit(attrs["axis"]), "start": self.ctx.target.tcp_pose()[:3, 3].copy(),
                              "commanded_m": float(q) - float(travel[0]) + self.push_to_stop_m}
        super().on_enter()

    def step(self):
        try:
            status = self._slide()
        except PrimitiveFailure:
            self._note_moved()
            raise
        if status != Status.RUNNING:
            opening = self._note_moved()
            if status == Status.SUCCESS and self._push is None and opening is not None:
                self._note_opened(opening)
        return status

    def _note_opened(self, opening: float) -> None:
        """A pull that opened the drawer, ended with the fingers still closed on its handle (the
        hand's own encoders: opening and effort, :mod:`.grasp_sense`): tell the session's
        perceiver where the hand let the drawer stand
        (:meth:`~phyagentos.perception.Perceiver.note_drawer_opened`), for a look that cannot
        read the handle. A pull that lost the handle, or a push, tells it nothing; a pull by the
        closed fingers hooked behind the drawer's front (``lead_m``) tells it where it was read
        plus the hand's travel less the lead, even where that is no further out (a drawer read at
        its stop: the fingers stay behind the front, so it stands at least where they ended)."""
        assert self._moved_from is not None
        target, perceiver = self.ctx.target, getattr(self.ctx, "perceiver", None)
        if (opening <= self._moved_from[0] and not self.lead_m) or perceiver is None \
                or not hasattr(perceiver, "note_drawer_opened") \
                or not capabilities_of(target).has_sensor("proprioception"):
            return
        p = target.proprioception()
        held = closed_on_something(p) or self.lead_m > 0  # hooked behind the front: it moved at least so far
        self.ctx.trace.record("slide_felt", leaf=self.name, object=self.object, opening_m=round(opening, 4),
                              from_m=round(self._moved_from[0], 4), held=bool(held))
        if held:
            perceiver.note_drawer_opened(self.object, opening_m=opening, stamp_s=float(target.sim_time or 0.0))
            save_tracks(target, perceiver)

    def _slide(self) -> Status:
        """One tick of the motion; a push home ends where the stop holds the hand (:meth:`_at_stop`)."""
        if self._push is None or self._done:
            return super().step()
        try:
            status = super().step()
        except PrimitiveFailure as exc:
            if exc.code != "execution.tracking":
                raise
            return self._at_stop(str(exc))
        return self._at_stop("") if status == Status.SUCCESS else status

    def _note_moved(self) -> float | None:
        """Tell the planning world where the drawer is now: read where the motion began, moved
        as far as the hand holding its handle moved along its axis (the joint encoders).
        Returns that opening, m (``None``: the drawer was not read where the motion began)."""
        if self._moved_from is None:
            return None
        q0, axis, start = self._moved_from
        moved = float(np.dot(self.ctx.target.tcp_pose()[:3, 3] - start, axis))
        moved = math.copysign(max(abs(moved) - self.lead_m, 0.0), moved)  # the hand's lead moved no drawer
        planning_world.note_slide(self.ctx.target, self.object, q0 + moved)
        return q0 + moved

    def _at_stop(self, tracking: str) -> Status:
        """End a push home (class docstring): where the hand stands against what held it back."""
        push, target = self._push, self.ctx.target
        assert push is not None
        moved = float(np.dot(push["start"] - target.tcp_pose()[:3, 3], push["axis"])) - self.lead_m  # toward shut, m
        short = push["commanded_m"] - moved
        stopped = short >= STOP_LAG_M
        at_shut = stopped and -push["band_m"] <= moved - push["expected_m"] <= push["band_m"] + HANDLE_PLAY_M
        if stopped:
            target.settle(target.arm_qpos(), settle_s=0.2)  # stop pushing: the drawer stays at its stop
        self.ctx.trace.record("slide_stop", leaf=self.name, object=self.object, moved_m=round(moved, 4),
                              commanded_m=round(push["commanded_m"], 4), read_m=round(push["expected_m"], 4),
                              band_m=round(push["band_m"], 4), stopped=stopped, at_shut=at_shut,
                              tracking=tracking or None)
        if stopped and moved < push["expected_m"] - push["band_m"]:
            raise PrimitiveFailure("execution.blocked",
                                   f"{self.object!r} stopped {push['expected_m'] - moved:.3f} m short of where it was "
                                   f"read shut (band {push['band_m']:.3f} m): something holds it out")
        perceiver = getattr(self.ctx, "perceiver", None)
        if at_shut and perceiver is not None and hasattr(perceiver, "note_drawer_stop"):
            perceiver.note_drawer_stop(self.object, stamp_s=float(target.sim_time or 0.0))
        return Status.SUCCESS


class ComputePlaceAsHeld(Primitive):
    """Place and pre-place tcp poses that set the carried ``object`` down centred in
    ``region`` *keeping the hand's current orientation* (a hooked or side-held object
    cannot be turned top-down on the way): the object's lowest point ends
    ``clearance_m`` above the region's surface (its z), the pre-place
    ``approach_height_m`` above that.

    Args:
        object, region: entity names.
        approach_height_m: pre-place height above the place pose, m.
        clearance_m: gap left under the object, m.
        snapshot, place, preplace: blackboard keys (observation in; (4, 4) world tcp poses out).
    """

    def __init__(self, name: str, *, object: str, region: str, approach_height_m: float = 0.10,
                 clearance_m: float = 0.005, snapshot: str = "snapshot", place: str = "place_pose",
                 preplace: str = "preplace_pose"):
        super().__init__(name)
        self.object, self.region = object, region
        self.approach_height_m, self.clearance_m = float(approach_height_m), float(clearance_m)
        self.snapshot_key, self.place_key, self.preplace_key = snapshot, place, preplace
        self.reads(snapshot)
        self.writes(place, preplace)

    def step(self):
        snapshot = self.get(self.snapshot_key)
        T_region, _ = entity_pose(snapshot, self.region)
        T_obj, half = entity_pose(snapshot, self.object)
        T_tcp = self.ctx.target.tcp_pose()
        T_tcp_obj = np.linalg.inv(T_tcp) @ T_obj
        R_obj = T_tcp[:3, :3] @ T_tcp_obj[:3, :3]
        ext_z = float(np.abs(R_obj[2, :]) @ half)
        p_obj = np.array([T_region[0, 3], T_region[1, 3], T_region[2, 3] + ext_z + self.clearance_m])
        T_place = T_tcp.copy()
        T_place[:3, 3] = p_obj - T_tcp[:3, :3] @ T_tcp_obj[:3, 3]
        T_pre = T_place.copy()
        T_pre[2, 3] += self.approach_height_m
        self.set(self.place_key, T_place)
        self.set(self.preplace_key, T_pre)
        self.ctx.trace.record("place_pose", leaf=self.name, object=self.object, region=self.region,
                              place=T_place[:3, 3].round(4).tolist())


class ToolMove(_Tracking):
    """Straight-line tcp motion by ``offset`` (3,) m expressed in the *tool* frame
    (e.g. ``[0, 0, -0.08]`` backs out along the approach axis), orientation kept.

    Args:
        offset: displacement in the tcp frame, m.
        velocity_scale: fraction (0, 1] of the joint velocity limits.
    """

    def __init__(self, name: str, *, offset, velocity_scale: float = 0.3):
        super().__init__(name)
        off = np.asarray(offset, dtype=float)
        if off.shape != (3,) or not np.all(np.isfinite(off)):
            raise ValueError(f"offset must be 3 finite numbers in m, got {offset!r}")
        if not 0 < velocity_scale <= 1:
            raise ValueError(f"velocity_scale must be in (0, 1], got {velocity_scale}")
        self.offset, self.velocity_scale = off, float(velocity_scale)

    def on_enter(self):
        ctx = self.ctx
        target = ctx.target
        T0 = target.tcp_pose()
        Tg = T0.copy()
        Tg[:3, 3] += T0[:3, :3] @ self.offset
        with ctx.profiler.section("ik"):
            path = cartesian_path(target.model, q_start=target.arm_qpos(), T_goal=Tg, **ik_options(target))
        vel, acc = execution_limits(ctx, self.velocity_scale, self.velocity_scale)
        with ctx.profiler.section("timing"):
            traj = retime(path, vel_limits=vel, acc_limits=acc, dt=target.model.opt.timestep)
        self._start(traj)

    def step(self):
        return self._advance()
