"""SafetyGuard: the last check between the action bridges and the target, for both flows.

Every command (a behaviour tree's timed trajectory, a policy's action chunk, a single
action through the TargetSessionHandle) passes :meth:`SafetyGuard.check` before it is
streamed. The guard answers whether the command is admissible and what to do otherwise:

==================  ============================================================
check               violation code (outcome when not clamped: ``safety.yaml``)
==================  ============================================================
e-stop latch        ``safety.estop`` (always halt)
dtype               ``safety.dtype``: not a floating-point ndarray
shape               ``safety.shape``: not ``(N, 7)`` or ``(N, 8)`` (arm + gripper)
NaN / infinity      ``safety.nan``
command rate        ``safety.rate``: sample rate ``1/dt`` above ``max_command_rate_hz``
command duration    ``safety.duration``: ``N * dt`` above ``max_command_duration_s``
joint positions     ``safety.joint_limit``: outside the model's range shrunk by the margin
                    (gripper: outside its opening range)
joint velocity      ``safety.velocity``: above datasheet x ``max_joint_velocity_scale``
joint acceleration  ``safety.acceleration``: above min(datasheet, safety.yaml bound)
workspace           ``safety.workspace``: tcp (forward kinematics) outside the box
==================  ============================================================

OSC_POSE delta chunks (the policy flow on LIBERO, :meth:`SafetyGuard.check_osc_deltas`) get
the e-stop, dtype, shape ``(N, 7)``, NaN, rate and duration checks above, then: every pose
delta within the controller's input range [-1, 1] (``safety.velocity``: a delta per control
period is a speed command), the gripper column within [-1, 1] (``safety.joint_limit``), and
the end-effector path the deltas command (measured position plus the running sum of
``delta x output_max``) inside the workspace box (``safety.workspace``).

Outcomes: ``reject`` (the command is dropped; the arm keeps its last admitted command),
``halt`` (dropped and the caller stops the arm) or ``clamp`` (bounded: clipped into
the joint range, rate-limited, or truncated) only for codes listed in ``clamp_allowed``.
Every intervention becomes an event ``{code, check, outcome, layer, flow, message, ...}``
in the session's evidence (``events.yaml``), which the SessionVerifier reads as a
safety stop.

Limits come from the robot model (MuJoCo joint ranges; Franka datasheet velocity and
acceleration limits, :data:`phyagentos.motion.retime.FRANKA_VELOCITY_LIMITS`) and from
``safety.yaml`` (:class:`~phyagentos.protocol.SafetyConfig`, a frozen model). The guard
copies them into read-only arrays when it is built; nothing on the memory or
self-evolution path (LESSONS.md, KNOWLEDGE.md) can reach them.

Velocities and accelerations are finite differences of the commanded positions,
continued from the last admitted command (:meth:`SafetyGuard.sync` sets it from the
measured state), unless the caller passes the trajectory's own ``qd`` / ``qdd``.
Forward kinematics of the tcp is vectorised over the chunk (Rodrigues per joint, one
batched matrix product per link); single actions use MuJoCo's ``mj_kinematics``.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import mujoco
import numpy as np

from phyagentos.geometry import quat_to_matrix
from phyagentos.motion.retime import FRANKA_ACCELERATION_LIMITS, FRANKA_VELOCITY_LIMITS
from phyagentos.protocol.schemas import CLAMPABLE_VIOLATIONS, SAFETY_VIOLATIONS, SafetyConfig

__all__ = [
    "SAFETY_VIOLATIONS",
    "CLAMPABLE_VIOLATIONS",
    "EStopLatch",
    "PROCESS_ESTOP",
    "ChainFK",
    "RobotLimits",
    "Violation",
    "GuardDecision",
    "SafetyGuard",
]

logger = logging.getLogger(__name__)

_SEVERITY = {"pass": 0, "clamp": 1, "reject": 2, "halt": 3}


class EStopLatch:
    """An emergency-stop latch: once engaged it stays engaged until cleared.

    Thread-safe; :meth:`is_set` is a single attribute read so the streaming loops can
    check it every control period. ``engaged_at`` is ``time.perf_counter()`` at the
    engage call (used to measure e-stop latency). Listeners (:meth:`add_listener`) are
    called with the reason in the engaging thread, so a driver can put the stop on its
    bus at once, whether or not its control loop is being scheduled.
    """

    def __init__(self) -> None:
        self._event = threading.Event()
        self._lock = threading.Lock()
        self._listeners: list[Callable[[str], None]] = []
        self.reason = ""
        self.source = ""
        self.engaged_at: float | None = None

    def add_listener(self, fn: Callable[[str], None]) -> None:
        """Call ``fn(reason)`` in the engaging thread each time the latch is engaged (not on
        an engage while it already is). A listener that raises is logged; the e-stop stays
        engaged and the other listeners are still called."""
        with self._lock:
            if fn not in self._listeners:
                self._listeners.append(fn)

    def remove_listener(self, fn: Callable[[str], None]) -> None:
        """Stop calling ``fn`` (no error when it was not added)."""
        with self._lock:
            if fn in self._listeners:
                self._listeners.remove(fn)

    def engage(self, reason: str = "", *, source: str = "operator") -> None:
        """Engage the e-stop (idempotent: the first reason is kept), then call the
        listeners (first engage only)."""
        with self._lock:
            if self._event.is_set():
                return
            logger.warning("e-stop engaged by %s: %s", source, reason)  # before: setting is the signal
            self.reason, self.source = reason, source
            self.engaged_at = time.perf_counter()
            self._event.set()
            listeners = list(self._listeners)
        for fn in listeners:
            try:
                fn(reason)
            except Exception:  # noqa: BLE001 - the latch is engaged whatever a listener does
                logger.exception("e-stop listener %r failed", fn)

    def clear(self) -> None:
        """Release the latch (an operator decision; never done by the runtime itself)."""
        with self._lock:
            self._event.clear()
            self.reason, self.source, self.engaged_at = "", "", None

    def is_set(self) -> bool:
        return self._event.is_set()


#: The process-wide e-stop: an e-stop halts every target of the process. The
#: supervisor engages it on an ``estop`` signal in RUNTIME_SIGNAL.md.
PROCESS_ESTOP = EStopLatch()


class ChainFK:
    """Vectorised forward kinematics of a serial chain of hinge joints to one site.

    Built from a MuJoCo model: for each joint ``i`` the body offset ``(pos_i, R_i)``
    relative to its parent, the hinge axis ``a_i`` and anchor ``c_i`` in the body frame;
    the chain's base pose is read once from ``mj_kinematics`` (the base must not move).
    Then ``p_b = p_parent + R_parent pos_i + R_pre (c_i - Rj c_i)``, ``R_b = R_pre Rj``
    with ``R_pre = R_parent R_i`` and ``Rj = I + sin(q) K + (1 - cos(q)) K^2``
    (Rodrigues; ``K`` the skew matrix of ``a_i``).

    Args:
        model: MuJoCo model holding the joints and the site.
        joint_names: the chain's hinge joints, base to tip.
        site: site whose world position is returned.

    Raises:
        ValueError: unknown joint or site, a non-hinge joint, or joints that do not form
            a chain ending at the site's body.
    """

    _SMALL = 4  # below this many configurations mj_kinematics is faster than numpy

    def __init__(self, model: mujoco.MjModel, joint_names: Sequence[str], site: str = "tcp"):
        jids = []
        for name in joint_names:
            jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
            if jid < 0:
                raise ValueError(f"unknown joint {name!r} in the robot model")
            if model.jnt_type[jid] != mujoco.mjtJoint.mjJNT_HINGE:
                raise ValueError(f"joint {name!r} is not a hinge; ChainFK handles hinge chains only")
            jids.append(jid)
        sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, site)
        if sid < 0:
            raise ValueError(f"unknown site {site!r} in the robot model")
        bodies = [int(model.jnt_bodyid[j]) for j in jids]
        for parent, child in zip(bodies, bodies[1:]):
            if int(model.body_parentid[child]) != parent:
                raise ValueError(f"joints {list(joint_names)} do not form a serial chain")
        if int(model.site_bodyid[sid]) != bodies[-1]:
            raise ValueError(f"site {site!r} is not on the last body of the chain")
        self.n = len(jids)
        self._model = model
        self._data = mujoco.MjData(model)
        self._qadr = model.jnt_qposadr[jids].copy()
        contiguous = bool(np.all(np.diff(self._qadr) == 1))
        self._qslice = slice(int(self._qadr[0]), int(self._qadr[0]) + len(jids)) if contiguous else self._qadr
        self._sid = sid
        mujoco.mj_kinematics(model, self._data)
        base = int(model.body_parentid[bodies[0]])
        self._R0 = self._data.xmat[base].reshape(3, 3).copy()
        self._p0 = self._data.xpos[base].copy()
        self._R = np.array([quat_to_matrix(model.body_quat[b]) for b in bodies])
        self._pos = np.array([model.body_pos[b] for b in bodies], dtype=float)
        ax = np.array([model.jnt_axis[j] for j in jids], dtype=float)
        ax /= np.linalg.norm(ax, axis=1, keepdims=True)
        K = np.zeros((self.n, 3, 3))
        K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -ax[:, 2], ax[:, 1], -ax[:, 0]
        K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = ax[:, 2], -ax[:, 1], ax[:, 0]
        self._K, self._K2 = K, K @ K
        self._c = np.array([model.jnt_pos[j] for j in jids], dtype=float)
        self._anchored = bool(np.any(self._c != 0.0))
        self._site = model.site_pos[sid].astype(float).copy()

    @classmethod
    def of(cls, model: mujoco.MjModel, joint_names: Sequence[str], site: str = "tcp") -> "ChainFK":
        """The chain of ``model`` (this model object, not an equal one), built on the first
        call and shared by later ones: a target, and its model, outlives its sessions, and
        building a chain (a scratch ``MjData`` and ``mj_kinematics``) cost about 0.7 ms of
        every session's preparation. Everything a chain reads from the model is kinematic
        (body offsets, joint axes and anchors, the base pose at ``qpos0``), which nothing
        changes after a model is compiled; :meth:`positions` uses its scratch data only.

        Raises:
            ValueError: as the constructor.
        """
        key = (id(model), tuple(joint_names), site)
        with _CHAINS_LOCK:
            hit = _CHAINS.get(key)
            if hit is not None and hit[0] is model:
                return hit[1]
        chain = cls(model, joint_names, site)
        with _CHAINS_LOCK:
            if len(_CHAINS) >= _CHAINS_MAX:
                _CHAINS.clear()
            _CHAINS[key] = (model, chain)  # the model is held, so its id is not reused meanwhile
        return chain

    @staticmethod
    def forget(model: mujoco.MjModel) -> int:
        """Drop the cached chains of ``model`` (its target is closed): each entry holds the
        model, so the cache would keep a closed world's model alive (a LIBERO world's: about
        250 MB) until it fills up. Returns how many chains were dropped."""
        with _CHAINS_LOCK:
            stale = [key for key, (m, _) in _CHAINS.items() if m is model]
            for key in stale:
                del _CHAINS[key]
        return len(stale)

    def positions(self, Q: np.ndarray) -> np.ndarray:
        """World positions ``(N, 3)`` m of the site for joint configurations ``Q`` ``(N, n)`` rad."""
        Q = np.asarray(Q, dtype=float)
        if len(Q) < self._SMALL:
            out = np.empty((len(Q), 3))
            d, qpos, xpos = self._data, self._data.qpos, self._data.site_xpos
            for k in range(len(Q)):
                qpos[self._qslice] = Q[k]
                mujoco.mj_kinematics(self._model, d)
                out[k] = xpos[self._sid]
            return out
        s = np.sin(Q)[:, :, None, None]
        c = (1.0 - np.cos(Q))[:, :, None, None]
        Rj = np.eye(3) + s * self._K + c * self._K2
        R = np.broadcast_to(self._R0, (len(Q), 3, 3))
        p = np.broadcast_to(self._p0, (len(Q), 3))
        for i in range(self.n):
            p = p + R @ self._pos[i]
            R = R @ self._R[i]
            if self._anchored:
                p = p + R @ self._c[i] - (R @ Rj[:, i]) @ self._c[i]
            R = R @ Rj[:, i]
        return p + R @ self._site


#: (id(model), joint names, site) -> (model, its ChainFK), at most _CHAINS_MAX models' chains.
_CHAINS: dict[tuple[int, tuple[str, ...], str], tuple[mujoco.MjModel, ChainFK]] = {}
_CHAINS_LOCK = threading.Lock()
_CHAINS_MAX = 8


@dataclass(frozen=True)
class RobotLimits:
    """The robot model's side of the limits, already combined with ``safety.yaml``.

    Attributes:
        joint_names: arm joints, in command order.
        q_min, q_max: ``(n,)`` rad, the model's joint range shrunk by the margin.
        v_max: ``(n,)`` rad/s, datasheet velocity x ``max_joint_velocity_scale``.
        a_max: ``(n,)`` rad/s^2, min(datasheet, ``max_joint_acceleration_rad_s2``).
        gripper_range: ``(lo, hi)`` opening per finger in m (an ``(N, n + 1)`` command's
            last column).
        box_min, box_max: ``(3,)`` m, workspace box of the tcp, world frame.
        fk: forward kinematics of the tcp.
    """

    joint_names: tuple[str, ...]
    q_min: np.ndarray
    q_max: np.ndarray
    v_max: np.ndarray
    a_max: np.ndarray
    gripper_range: tuple[float, float]
    box_min: np.ndarray
    box_max: np.ndarray
    fk: ChainFK = field(repr=False)

    @classmethod
    def from_model(
        cls,
        model: mujoco.MjModel,
        config: SafetyConfig,
        *,
        joint_names: Sequence[str],
        site: str = "tcp",
        gripper_joint: str | None = None,
        velocity_datasheet: Sequence[float] = FRANKA_VELOCITY_LIMITS,
        acceleration_datasheet: Sequence[float] = FRANKA_ACCELERATION_LIMITS,
    ) -> "RobotLimits":
        """Combine the model's joint ranges and the datasheet with ``config``.

        Raises:
            ValueError: unknown joints, a margin that empties a joint range, or
                datasheet arrays of the wrong length.
        """
        names = tuple(joint_names)
        jids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n) for n in names]
        if min(jids) < 0:
            raise ValueError(f"unknown joint(s) {[n for n, j in zip(names, jids) if j < 0]} in the robot model")
        margin = config.joint_position_margin_rad
        lo = model.jnt_range[jids, 0] + margin
        hi = model.jnt_range[jids, 1] - margin
        if np.any(lo >= hi):
            raise ValueError(f"joint_position_margin_rad {margin} leaves an empty range for some joint")
        v = np.asarray(velocity_datasheet, dtype=float) * config.max_joint_velocity_scale
        a = np.minimum(np.asarray(acceleration_datasheet, dtype=float), config.max_joint_acceleration_rad_s2)
        if v.shape != (len(names),) or a.shape != (len(names),):
            raise ValueError(f"datasheet limits must have {len(names)} entries")
        grip = (0.0, 0.0)
        if gripper_joint is not None:
            gid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, gripper_joint)
            if gid < 0:
                raise ValueError(f"unknown gripper joint {gripper_joint!r}")
            grip = (float(model.jnt_range[gid, 0]), float(model.jnt_range[gid, 1]))
        arrays = [lo, hi, v, a, np.array(config.workspace_box.min, float), np.array(config.workspace_box.max, float)]
        for arr in arrays:
            arr.setflags(write=False)
        return cls(names, arrays[0], arrays[1], arrays[2], arrays[3], grip, arrays[4], arrays[5],
                   ChainFK.of(model, names, site))


@dataclass(frozen=True)
class Violation:
    """One failed check.

    Attributes:
        code: violation code (``safety.<check>``).
        outcome: ``clamp``, ``reject`` or ``halt``.
        message: what was wrong, where, and the limit.
        index: first offending sample of the command, if any.
        joint: offending joint (or ``gripper``), if any.
        value, limit: the offending value and the limit it broke (SI units).
    """

    code: str
    outcome: str
    message: str
    index: int | None = None
    joint: str | None = None
    value: float | None = None
    limit: float | None = None


@dataclass(frozen=True)
class GuardDecision:
    """The guard's answer for one command.

    Attributes:
        outcome: ``pass``, ``clamp``, ``reject`` or ``halt`` (the most severe violation).
        actions: what may be sent (the input, or its clamped version); ``None`` when
            the outcome is ``reject`` or ``halt``.
        violations: every failed check, clamped ones included.
    """

    outcome: str
    actions: np.ndarray | None
    violations: tuple[Violation, ...] = ()

    @property
    def admitted(self) -> bool:
        return self.outcome in ("pass", "clamp")

    @property
    def code(self) -> str | None:
        """Code of the most severe violation (``None`` when the command passed)."""
        if not self.violations:
            return None
        return max(self.violations, key=lambda v: _SEVERITY[v.outcome]).code

    @property
    def message(self) -> str:
        return "; ".join(f"[{v.code}] {v.message}" for v in self.violations)


class SafetyGuard:
    """Checks commands against the robot's and ``safety.yaml``'s limits.

    Args:
        limits: the combined limits (:meth:`RobotLimits.from_model`).
        config: the session's ``safety.yaml``.
        events: the session's event list (evidence); interventions are appended.
        estop: e-stop latch (default :data:`PROCESS_ESTOP`).
        flow: ``builtin``, ``policy`` or ``agent`` (recorded in events).
        clock: returns the target time in s for event stamps (e.g. ``lambda: target.sim_time``).

    The guard keeps the *reference* command (last admitted position and velocity) so
    that the first sample of the next command is checked for a jump; call :meth:`sync`
    with the measured state when a session starts or after a halt.
    """

    def __init__(
        self,
        limits: RobotLimits,
        config: SafetyConfig,
        *,
        events: list | None = None,
        estop: EStopLatch | None = None,
        flow: str = "builtin",
        clock: Callable[[], float] | None = None,
    ):
        self.limits = limits
        self.events = events if events is not None else []
        self.estop = estop if estop is not None else PROCESS_ESTOP
        self.flow = flow
        self.clock = clock
        self._clamp = frozenset(config.clamp_allowed)
        self._outcome = dict(config.violation_outcomes)
        self._max_rate = float(config.max_command_rate_hz)
        self._max_duration = float(config.max_command_duration_s)
        self._n = len(limits.joint_names)
        self._q_mid = 0.5 * (limits.q_min + limits.q_max)
        self._q_half = 0.5 * (limits.q_max - limits.q_min) + 1e-9
        self._v_tol = limits.v_max + 1e-9
        self._a_tol = limits.a_max + 1e-9
        self._box_mid = 0.5 * (limits.box_min + limits.box_max)
        self._box_half = 0.5 * (limits.box_max - limits.box_min)
        g_lo, g_hi = limits.gripper_range
        self._mid8 = np.append(self._q_mid, 0.5 * (g_lo + g_hi))
        half8 = np.append(self._q_half, 0.5 * (g_hi - g_lo) + 1e-9)
        # Tolerance rows of the fast-path buffer for (N, n) and (N, n + 1) commands.
        self._tol = {D: np.concatenate([half8[:D], self._v_tol, self._a_tol, self._box_half])
                     for D in (self._n, self._n + 1)}
        self._ref_q = np.zeros(self._n)
        self._ref_qd = np.zeros(self._n)
        self._synced = False
        self.stats = {"checks": 0, "actions": 0, "interventions": 0}

    @classmethod
    def for_target(cls, target: Any, config: SafetyConfig, **kwargs: Any) -> "SafetyGuard":
        """A guard for a MuJoCo-backed target (``model``, ``arm_joint_names``,
        ``arm_qpos()``, optionally ``datasheet_limits`` = (velocity, acceleration) per
        joint, default the Franka's; gripper range from the first finger joint when the
        model has one), synced to the target's current arm state. The target's ``estop``
        (:attr:`phyagentos.targets.contract.Target.estop`) gets the guard's latch, so its
        streaming halts within one step."""
        from phyagentos.targets.scene import FINGER_JOINT_NAMES  # noqa: PLC0415

        model = target.model
        finger = FINGER_JOINT_NAMES[0] if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, FINGER_JOINT_NAMES[0]) >= 0 else None
        # A robot other than the Franka declares its own datasheet (velocity, acceleration) limits.
        datasheet = target.datasheet_limits
        extra = {} if datasheet is None else {"velocity_datasheet": datasheet[0], "acceleration_datasheet": datasheet[1]}
        limits = RobotLimits.from_model(model, config, joint_names=target.arm_joint_names, gripper_joint=finger, **extra)
        kwargs.setdefault("clock", lambda: float(target.sim_time))
        guard = cls(limits, config, **kwargs)
        guard.sync(target.arm_qpos())
        target.estop = guard.estop  # arm the target-local hook (Target.estop, checked every physics step)
        return guard

    # -- reference ---------------------------------------------------------------------
    def sync(self, q: Sequence[float], qd: Sequence[float] | None = None) -> None:
        """Set the reference command to the measured state ``q`` (n,) rad, ``qd`` (n,) rad/s."""
        self._ref_q = np.array(q, dtype=float).reshape(self._n)
        self._ref_qd = np.zeros(self._n) if qd is None else np.array(qd, dtype=float).reshape(self._n)
        self._synced = True

    @property
    def reference(self) -> tuple[np.ndarray, np.ndarray]:
        """``(q, qd)`` of the last admitted command (copies)."""
        return self._ref_q.copy(), self._ref_qd.copy()

    def commit(self, actions: np.ndarray, *, dt: float, qd_end: np.ndarray | None = None) -> None:
        """Record that ``actions`` (as admitted) were sent: the reference moves to their end."""
        q = actions[:, : self._n]
        if qd_end is not None:
            self._ref_qd = np.array(qd_end, dtype=float)
        elif len(q) >= 2:
            self._ref_qd = (q[-1] - q[-2]) / dt
        else:
            self._ref_qd = (q[-1] - self._ref_q) / dt
        self._ref_q = np.array(q[-1], dtype=float)

    # -- checks ------------------------------------------------------------------------
    def estop_engaged(self) -> bool:
        """True when the e-stop latch is engaged (records a ``safety.estop`` event once per call)."""
        if not self.estop.is_set():
            return False
        self._record((Violation("safety.estop", "halt", f"e-stop engaged by {self.estop.source}: {self.estop.reason}"),), 0)
        return True

    def check(
        self,
        actions: Any,
        *,
        dt: float,
        qd: np.ndarray | None = None,
        qdd: np.ndarray | None = None,
        source: str = "",
    ) -> GuardDecision:
        """Check a command of ``N`` samples spaced ``dt`` seconds apart.

        Args:
            actions: ``(N, n)`` joint positions in rad, or ``(N, n + 1)`` with the
                gripper opening per finger (m) last; float dtype.
            dt: sample period in s (keyword-only, like every safety-relevant argument).
            qd, qdd: optional ``(N, n)`` velocities (rad/s) and accelerations (rad/s^2)
                of a timed trajectory; finite differences of ``actions`` otherwise.
            source: who produced the command (recorded in events), e.g. the leaf name.

        Returns:
            :class:`GuardDecision`; interventions are appended to :attr:`events`.
        """
        refused = self._refuse_outright(actions, source)
        if refused is not None:
            return refused
        n = self._n
        if actions.ndim != 2 or actions.shape[0] < 1 or actions.shape[1] not in (n, n + 1):
            return self._decide((self._v("safety.shape", f"command must have shape (N, {n}) or (N, {n + 1}) with N >= 1, "
                                                         f"got {actions.shape}"),), None, source, 0)
        N = actions.shape[0]
        self.stats["actions"] += N
        if self._admissible(actions, N, dt, qd, qdd):
            return GuardDecision("pass", actions)
        return self._diagnose(actions, N, dt, qd, qdd, source)

    def _refuse_outright(self, actions: Any, source: str) -> GuardDecision | None:
        """Count a check; the decision for a command refused before its values are read (the
        e-stop engaged, or not a floating-point ndarray), else ``None``."""
        self.stats["checks"] += 1
        if self.estop.is_set():
            return self._decide((Violation("safety.estop", "halt",
                                           f"e-stop engaged by {self.estop.source}: {self.estop.reason}"),), None, source, 0)
        if not isinstance(actions, np.ndarray) or actions.dtype.kind != "f":
            kind = actions.dtype if isinstance(actions, np.ndarray) else type(actions).__name__
            return self._decide((self._v("safety.dtype", f"command must be a floating-point ndarray, got {kind}"),),
                                None, source, 0)
        return None

    def check_osc_deltas(self, actions: Any, *, dt: float, eef_position: Sequence[float],
                         output_max_m: float, source: str = "") -> GuardDecision:
        """Check a chunk of OSC_POSE delta actions (LIBERO's controller) before it is stepped.

        Args:
            actions: ``(N, 7)`` float: ``dx dy dz drx dry drz`` in [-1, 1], gripper -1 .. 1.
            dt: control period, s.
            eef_position: ``(3,)`` m, the measured end-effector position (world) the deltas
                start from.
            output_max_m: metres of motion per step at input 1 (robosuite's ``output_max``).
            source: who produced the command (recorded in events).

        Returns:
            :class:`GuardDecision`; a clamp (when ``safety.velocity`` / ``safety.joint_limit``
            are in ``clamp_allowed``) clips into [-1, 1], as the controller would.
        """
        refused = self._refuse_outright(actions, source)
        if refused is not None:
            return refused
        if actions.ndim != 2 or actions.shape[0] < 1 or actions.shape[1] != 7:
            return self._decide((self._v("safety.shape", f"an OSC_POSE chunk must have shape (N, 7) with N >= 1, "
                                                         f"got {actions.shape}"),), None, source, 0)
        N = actions.shape[0]
        self.stats["actions"] += N
        if not np.isfinite(actions).all() or not math.isfinite(dt):
            bad = np.argwhere(~np.isfinite(actions))
            idx = int(bad[0, 0]) if len(bad) else None
            return self._decide((self._v("safety.nan", f"command contains NaN or infinity (first at sample {idx})",
                                         index=idx),), None, source, N)
        if dt <= 0 or 1.0 / dt > self._max_rate * (1 + 1e-9):
            return self._decide((self._v("safety.rate", f"sample period {dt} s is a rate above {self._max_rate} Hz",
                                         value=(1.0 / dt if dt > 0 else math.inf), limit=self._max_rate),), None, source, N)
        violations: list[Violation] = []
        if N * dt > self._max_duration + 1e-9:
            violations.append(self._v("safety.duration", f"command lasts {N * dt:.3f} s, longer than "
                                                         f"{self._max_duration} s", value=N * dt, limit=self._max_duration))
        over = np.abs(actions[:, :6]) > 1.0 + 1e-9
        if over.any():
            k, j = np.argwhere(over)[0]
            axis = ("dx", "dy", "dz", "drx", "dry", "drz")[j]
            violations.append(self._v("safety.velocity", f"OSC delta {axis} = {actions[k, j]:.4f} at sample {k} is outside "
                                                         "the controller's input range [-1, 1]",
                                      index=int(k), joint=axis, value=float(actions[k, j]), limit=1.0))
        badg = np.abs(actions[:, 6]) > 1.0 + 1e-9
        if badg.any():
            k = int(np.argmax(badg))
            violations.append(self._v("safety.joint_limit", f"gripper command {actions[k, 6]:.4f} at sample {k} is outside "
                                                            "[-1 open, +1 closed]", index=k, joint="gripper",
                                      value=float(actions[k, 6]), limit=1.0))
        clipped = np.clip(actions, -1.0, 1.0)
        path = np.asarray(eef_position, dtype=float).reshape(3) + float(output_max_m) * np.cumsum(clipped[:, :3], axis=0)
        out_of = np.abs(path - self._box_mid) > self._box_half
        if out_of.any():
            k, axis = np.argwhere(out_of)[0]
            lim = self.limits
            bound = lim.box_min[axis] if path[k, axis] < lim.box_min[axis] else lim.box_max[axis]
            violations.append(self._v("safety.workspace", f"the commanded end-effector path reaches "
                                                          f"{np.round(path[k], 4).tolist()} m, outside the workspace box "
                                                          f"{lim.box_min.tolist()}..{lim.box_max.tolist()} m on {'xyz'[axis]} "
                                                          f"(sample {k})",
                                      index=int(k), value=float(path[k, axis]), limit=float(bound)))
        if not violations:
            return GuardDecision("pass", actions)
        if all(v.outcome == "clamp" for v in violations):
            out = clipped
            if any(v.code == "safety.duration" for v in violations):
                out = out[: max(1, int(math.floor(self._max_duration / dt + 1e-9)))]
            return self._decide(tuple(violations), out, source, N)
        return self._decide(tuple(violations), None, source, N)

    def _admissible(self, actions: np.ndarray, N: int, dt: float, qd, qdd) -> bool:
        """Fast path: every check at once on one ``(N, W)`` buffer of excesses.

        Columns: |action - range centre| (joints and gripper), |velocity|, |acceleration|,
        |tcp - box centre|, compared with the half widths / limits in one pass. NaN
        compares false, so a non-finite command falls through to :meth:`_diagnose`.
        """
        if not (0.0 < dt and N * dt <= self._max_duration + 1e-9 and 1.0 / dt <= self._max_rate * (1 + 1e-9)):
            return False
        n, D = self._n, actions.shape[1]
        if N == 1:  # a single action: the same checks with fewer array operations
            q = actions[0, :n]
            vel = (q - self._ref_q) * (1.0 / dt) if qd is None else qd[0]
            acc = (vel - self._ref_qd) * (1.0 / dt) if qdd is None else qdd[0]
            p = self.limits.fk.positions(actions[:, :n])[0]
            x = np.concatenate((actions[0] - self._mid8[:D], vel, acc, p - self._box_mid))
            return bool((np.abs(x, out=x) <= self._tol[D]).all())
        B = np.empty((N, D + 2 * n + 3))
        np.subtract(actions, self._mid8[:D], out=B[:, :D])
        q = actions[:, :n]
        vel, acc = B[:, D:D + n], B[:, D + n:D + 2 * n]
        if qd is None:
            np.subtract(q[0], self._ref_q, out=vel[0])
            np.subtract(q[1:], q[:-1], out=vel[1:])
            vel *= 1.0 / dt
        else:
            vel[:] = qd
        if qdd is None:
            np.subtract(vel[0], self._ref_qd, out=acc[0])
            np.subtract(vel[1:], vel[:-1], out=acc[1:])
            acc *= 1.0 / dt
        else:
            acc[:] = qdd
        np.subtract(self.limits.fk.positions(q), self._box_mid, out=B[:, D + 2 * n:])
        np.abs(B, out=B)
        return bool((B <= self._tol[D]).all())

    def _diagnose(self, actions: np.ndarray, N: int, dt: float, qd, qdd, source: str) -> GuardDecision:
        """Slow path: find every violation, decide the outcome, record the events."""
        n = self._n
        finite = np.isfinite(actions).all()
        if finite and qd is not None:
            finite = np.isfinite(qd).all() and (qdd is None or np.isfinite(qdd).all())
        if not finite or not math.isfinite(dt):
            bad = np.argwhere(~np.isfinite(actions))
            idx = int(bad[0, 0]) if len(bad) else None
            return self._decide((self._v("safety.nan", f"command contains NaN or infinity (first at sample {idx})",
                                         index=idx),), None, source, N)
        violations: list[Violation] = []
        if dt <= 0 or 1.0 / dt > self._max_rate * (1 + 1e-9):
            violations.append(self._v("safety.rate", f"sample period {dt} s is a rate above {self._max_rate} Hz",
                                      value=(1.0 / dt if dt > 0 else math.inf), limit=self._max_rate))
            return self._decide(tuple(violations), None, source, N)
        if N * dt > self._max_duration + 1e-9:
            violations.append(self._v("safety.duration", f"command lasts {N * dt:.3f} s, longer than "
                                                         f"{self._max_duration} s", value=N * dt, limit=self._max_duration))
        lim = self.limits
        q = actions[:, :n]
        violations += self._joint_limits(q, actions)
        if qd is not None:
            vel = qd
        else:
            vel = np.empty_like(q)
            np.subtract(q[0], self._ref_q, out=vel[0])
            np.subtract(q[1:], q[:-1], out=vel[1:])
            vel *= 1.0 / dt
        over_v = np.abs(vel) > self._v_tol
        if over_v.any():
            k, j = np.argwhere(over_v)[0]
            violations.append(self._v("safety.velocity", f"joint {lim.joint_names[j]} at {vel[k, j]:.3f} rad/s exceeds "
                                                         f"{lim.v_max[j]:.3f} rad/s (sample {k})",
                                      index=int(k), joint=lim.joint_names[j], value=float(vel[k, j]), limit=float(lim.v_max[j])))
        if qdd is not None:
            acc = qdd
        else:
            acc = np.empty_like(vel)
            np.subtract(vel[0], self._ref_qd, out=acc[0])
            np.subtract(vel[1:], vel[:-1], out=acc[1:])
            acc *= 1.0 / dt
        over_a = np.abs(acc) > self._a_tol
        if over_a.any():
            k, j = np.argwhere(over_a)[0]
            violations.append(self._v("safety.acceleration", f"joint {lim.joint_names[j]} at {acc[k, j]:.2f} rad/s^2 exceeds "
                                                             f"{lim.a_max[j]:.2f} rad/s^2 (sample {k})",
                                      index=int(k), joint=lim.joint_names[j], value=float(acc[k, j]), limit=float(lim.a_max[j])))
        violations += self._workspace(q)
        if not violations:
            return GuardDecision("pass", actions)
        if all(v.outcome == "clamp" for v in violations):
            clamped = self._apply_clamps(actions, dt, {v.code for v in violations})
            # A clamp must produce an admissible command: re-check what cannot be clamped.
            after = self._joint_limits(clamped[:, :n], clamped) + self._workspace(clamped[:, :n])
            after = [v for v in after if v.outcome != "clamp"]
            if after:
                return self._decide(tuple(violations) + tuple(after), None, source, N)
            return self._decide(tuple(violations), clamped, source, N)
        return self._decide(tuple(violations), None, source, N)

    # -- pieces ------------------------------------------------------------------------
    def _v(self, code: str, message: str, **kw: Any) -> Violation:
        outcome = "clamp" if code in self._clamp else self._outcome.get(code, "halt")
        return Violation(code, outcome, message, **kw)

    def _joint_limits(self, q: np.ndarray, actions: np.ndarray) -> list[Violation]:
        lim = self.limits
        out = []
        # |q - centre| > half width: one pass instead of two comparisons.
        bad = np.abs(q - self._q_mid) > self._q_half
        if bad.any():
            k, j = np.argwhere(bad)[0]
            bound = lim.q_min[j] if q[k, j] < lim.q_min[j] else lim.q_max[j]
            out.append(self._v("safety.joint_limit", f"joint {lim.joint_names[j]} at {q[k, j]:.4f} rad is outside "
                                                     f"[{lim.q_min[j]:.4f}, {lim.q_max[j]:.4f}] rad (sample {k})",
                               index=int(k), joint=lim.joint_names[j], value=float(q[k, j]), limit=float(bound)))
        if actions.shape[1] == self._n + 1:
            g = actions[:, -1]
            lo, hi = lim.gripper_range
            badg = (g < lo - 1e-9) | (g > hi + 1e-9)
            if badg.any():
                k = int(np.argmax(badg))
                out.append(self._v("safety.joint_limit", f"gripper opening {g[k]:.4f} m is outside [{lo}, {hi}] m (sample {k})",
                                   index=k, joint="gripper", value=float(g[k]), limit=float(lo if g[k] < lo else hi)))
        return out

    def _workspace(self, q: np.ndarray) -> list[Violation]:
        lim = self.limits
        p = lim.fk.positions(q)
        out_of = np.abs(p - self._box_mid) > self._box_half
        if not out_of.any():
            return []
        k, axis = np.argwhere(out_of)[0]
        bound = lim.box_min[axis] if p[k, axis] < lim.box_min[axis] else lim.box_max[axis]
        return [self._v("safety.workspace", f"tcp at {np.round(p[k], 4).tolist()} m leaves the workspace box "
                                            f"{lim.box_min.tolist()}..{lim.box_max.tolist()} m on {'xyz'[axis]} (sample {k})",
                        index=int(k), joint=None, value=float(p[k, axis]), limit=float(bound))]

    def _apply_clamps(self, actions: np.ndarray, dt: float, codes: set[str]) -> np.ndarray:
        lim = self.limits
        out = np.array(actions, dtype=float)
        if "safety.duration" in codes:
            out = out[: max(1, int(math.floor(self._max_duration / dt + 1e-9)))]
        n = self._n
        if "safety.joint_limit" in codes:
            np.clip(out[:, :n], lim.q_min, lim.q_max, out=out[:, :n])
            if out.shape[1] == n + 1:
                np.clip(out[:, n], *lim.gripper_range, out=out[:, n])
        if codes & {"safety.velocity", "safety.acceleration"}:
            # Rate limiter: follow the command as closely as the bounds allow.
            q_prev, v_prev = self._ref_q.copy(), self._ref_qd.copy()
            clamp_a = "safety.acceleration" in codes
            for k in range(len(out)):
                v = (out[k, :n] - q_prev) / dt
                if clamp_a:
                    v = np.clip(v, v_prev - lim.a_max * dt, v_prev + lim.a_max * dt)
                v = np.clip(v, -lim.v_max, lim.v_max)
                q_prev = q_prev + v * dt
                v_prev = v
                out[k, :n] = q_prev
        return out

    def _decide(self, violations: tuple[Violation, ...], actions: np.ndarray | None, source: str, n: int) -> GuardDecision:
        worst = max((v.outcome for v in violations), key=_SEVERITY.__getitem__)
        self._record(violations, n, source)
        return GuardDecision(worst, actions if worst == "clamp" else None, violations)

    def _record(self, violations: Sequence[Violation], n: int, source: str = "") -> None:
        at = self.clock() if self.clock is not None else None
        for v in violations:
            self.stats["interventions"] += 1
            event = {"code": v.code, "check": v.code.split(".", 1)[1], "outcome": v.outcome, "layer": "safety_guard",
                     "flow": self.flow, "message": v.message, "n_actions": int(n)}
            if source:
                event["source"] = source
            if at is not None:
                event["target_time_s"] = round(float(at), 6)
            for key in ("index", "joint", "value", "limit"):
                val = getattr(v, key)
                if val is not None:
                    event[key] = val if not isinstance(val, float) else round(val, 6)
            self.events.append(event)
            logger.warning("SafetyGuard %s (%s): %s", v.code, v.outcome, v.message)
