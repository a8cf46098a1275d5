"""Action bridges: declared, composable, type-checked conversions of action chunks.

A policy speaks its own action language (joint order, units, gripper convention,
padding, control rate); the target speaks another. An :class:`ActionSpec` describes
one side; an :class:`ActionBridge` converts one spec into another. A skill declares
its bridges in order (``skills/<name>.yaml``, ``policy.bridges``)::

    bridges:
      - {bridge: project, dims: 8}                         # drop the model's padding
      - {bridge: units, from: deg, to: rad}
      - {bridge: reorder_joints, order: [j1, j2, ...]}
      - {bridge: gripper_remap, from: normalized_closed, to: opening_m, max_opening_m: 0.04}
      - {bridge: resample, to_hz: 500, method: cubic}      # model rate -> control rate

Preflight runs :meth:`BridgeChain.check`: every bridge's input spec must match the
previous output (:meth:`ActionBridge.output_spec` raises otherwise), and the last
output must equal the target's native spec; each mismatch becomes a rejection item.
At run time :meth:`BridgeChain.apply` converts chunks; a chunk whose shape does not
match the declared spec is rejected (:class:`~phyagentos.errors.ActionBridgeError`
with a ``safety.*`` code), never reshaped or padded to fit. Values are converted,
not judged: admissibility (limits, NaN, speed) is the SafetyGuard's job, which runs
after the last bridge.

Column layout of a chunk ``(H, dim)``: the joint (or Cartesian) columns named in
``ActionSpec.joint_names``, then the gripper column if ``gripper`` is set, then
``padding`` columns that carry no meaning.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Mapping, Sequence

import mujoco
import numpy as np
from scipy.interpolate import CubicSpline

from phyagentos.errors import ActionBridgeError, format_choices

__all__ = [
    "ActionSpec",
    "ActionChunk",
    "BridgeMismatch",
    "ActionBridge",
    "ProjectBridge",
    "ReorderJointsBridge",
    "UnitsBridge",
    "FrameBridge",
    "GripperRemapBridge",
    "ResampleBridge",
    "BridgeChain",
    "BRIDGES",
    "SPACES",
    "GRIPPER_CONVENTIONS",
    "make_bridge",
]

#: Action spaces: joint positions; a tcp pose as position (m) + rotation vector (rad);
#: ``osc_pose_delta``: the normalised end-effector deltas of an operational-space controller
#: (LIBERO's / robosuite's OSC_POSE: each of ``dx dy dz drx dry drz`` in [-1, 1], scaled by
#: the controller's ``output_max``, 0.05 m / 0.5 rad per control step; no angle unit).
SPACES = ("joint_position", "ee_pose", "osc_pose_delta")
#: Gripper conventions: opening per finger in metres; 0 open .. 1 closed; 0 closed .. 1 open;
#: ``signed_closed``: -1 open .. +1 closed (robosuite's gripper action, LIBERO's 7th column).
GRIPPER_CONVENTIONS = ("opening_m", "normalized_closed", "normalized_open", "signed_closed")
_ANGLE_UNITS = {"rad": 1.0, "deg": math.pi / 180.0}
_EE_COLUMNS = ("x", "y", "z", "rx", "ry", "rz")
_OSC_COLUMNS = ("dx", "dy", "dz", "drx", "dry", "drz")


@dataclass(frozen=True)
class ActionSpec:
    """What the columns of an action chunk mean.

    Attributes:
        space: one of :data:`SPACES`.
        joint_names: names of the leading columns (joint names, or ``x y z rx ry rz``
            for ``ee_pose``).
        units: angle unit of joint / rotation columns, ``rad`` or ``deg``.
        frame: ``joint`` for joint spaces; the reference frame name for ``ee_pose``.
        gripper: gripper convention (:data:`GRIPPER_CONVENTIONS`) or ``None``.
        rate_hz: sample rate of the chunk, Hz.
        padding: trailing columns without meaning (e.g. pi0 pads actions to 32).
        max_opening_m: full opening per finger for the ``opening_m`` convention.
    """

    space: str
    joint_names: tuple[str, ...]
    units: str = "rad"
    frame: str = "joint"
    gripper: str | None = None
    rate_hz: float = 0.0
    padding: int = 0
    max_opening_m: float | None = None

    @property
    def dim(self) -> int:
        """Number of columns."""
        return len(self.joint_names) + (1 if self.gripper else 0) + self.padding

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], *, where: str) -> "ActionSpec":
        """Parse a declaration (skill manifest or server metadata).

        Keys: ``space``, ``joint_names``, ``units``, ``frame``, ``gripper``, ``rate_hz``,
        ``padding``, ``max_opening_m``. Raises ValueError naming ``where`` and the bad key.
        """
        known = {"space", "joint_names", "units", "frame", "gripper", "rate_hz", "padding", "max_opening_m", "dim"}
        unknown = set(d) - known
        if unknown:
            raise ValueError(f"{where}: unknown action key(s) {format_choices(unknown)}; valid: {format_choices(known)}")
        space = d.get("space")
        if space not in SPACES:
            raise ValueError(f"{where}: action space {space!r} is not one of {format_choices(SPACES)}")
        names = d.get("joint_names", {"ee_pose": _EE_COLUMNS, "osc_pose_delta": _OSC_COLUMNS}.get(space))
        if not names or not all(isinstance(n, str) for n in names):
            raise ValueError(f"{where}: joint_names must be a non-empty list of names (the action columns)")
        units = d.get("units", "rad")
        if units not in _ANGLE_UNITS:
            raise ValueError(f"{where}: units {units!r} is not one of {format_choices(_ANGLE_UNITS)}")
        gripper = d.get("gripper")
        if gripper is not None and gripper not in GRIPPER_CONVENTIONS:
            raise ValueError(f"{where}: gripper {gripper!r} is not one of {format_choices(GRIPPER_CONVENTIONS)}")
        rate = d.get("rate_hz")
        if not isinstance(rate, (int, float)) or not rate > 0:
            raise ValueError(f"{where}: rate_hz must be a number > 0, got {rate!r}")
        spec = cls(space=space, joint_names=tuple(names), units=units, frame=str(d.get("frame", "joint")),
                   gripper=gripper, rate_hz=float(rate), padding=int(d.get("padding", 0)),
                   max_opening_m=(float(d["max_opening_m"]) if d.get("max_opening_m") is not None else None))
        if "dim" in d and int(d["dim"]) != spec.dim:
            raise ValueError(f"{where}: dim {d['dim']} does not match {len(spec.joint_names)} named columns "
                             f"+ {'1 gripper + ' if gripper else ''}{spec.padding} padding = {spec.dim}")
        return spec

    def to_dict(self) -> dict[str, Any]:
        return {"space": self.space, "joint_names": list(self.joint_names), "units": self.units, "frame": self.frame,
                "gripper": self.gripper, "rate_hz": self.rate_hz, "padding": self.padding,
                "max_opening_m": self.max_opening_m, "dim": self.dim}


@dataclass(frozen=True)
class ActionChunk:
    """A chunk of ``H`` actions sampled at ``rate_hz``; ``values[k]`` applies at
    ``(k + 1) / rate_hz`` seconds after the chunk starts."""

    values: np.ndarray
    rate_hz: float

    @property
    def dt(self) -> float:
        return 1.0 / self.rate_hz

    @property
    def horizon(self) -> int:
        return int(self.values.shape[0])


@dataclass(eq=False)
class BridgeMismatch(Exception):
    """A bridge cannot accept a spec: ``field``, ``expected``, ``found`` and a ``fix``."""

    field: str
    expected: str
    found: str
    fix: str

    def __str__(self) -> str:
        return f"{self.field}: expected {self.expected}, found {self.found} ({self.fix})"


@dataclass(frozen=True)
class ReferenceState:
    """The last commanded target-space state a chunk continues from (for resampling)."""

    q: np.ndarray
    qd: np.ndarray
    gripper: float | None = None


class ActionBridge:
    """One declared conversion. Subclasses set :attr:`name` and :attr:`PARAMS`
    (parameter -> description) and implement :meth:`output_spec` and :meth:`_apply`."""

    name = ""
    PARAMS: Mapping[str, str] = {}
    REQUIRED: tuple[str, ...] = ()

    def __init__(self, **params: Any):
        unknown = set(params) - set(self.PARAMS)
        if unknown:
            raise ValueError(f"bridge {self.name!r}: unknown parameter(s) {format_choices(unknown)}; "
                             f"valid: {format_choices(self.PARAMS)}")
        missing = [p for p in self.REQUIRED if p not in params]
        if missing:
            raise ValueError(f"bridge {self.name!r}: missing parameter(s) {', '.join(missing)}")
        self.params = dict(params)
        self.in_spec: ActionSpec | None = None

    def describe(self) -> dict[str, Any]:
        """The declaration this bridge was built from (recorded in the AdapterPlan)."""
        return {"bridge": self.name, **self.params}

    def output_spec(self, spec: ActionSpec) -> ActionSpec:
        """The spec this bridge produces from ``spec``; raises :class:`BridgeMismatch`."""
        raise NotImplementedError

    def bind(self, spec: ActionSpec) -> ActionSpec:
        """Type-check against ``spec`` and remember it as the runtime input spec."""
        out = self.output_spec(spec)
        self.in_spec = spec
        return out

    def apply(self, chunk: ActionChunk, ref: ReferenceState | None = None) -> ActionChunk:
        """Convert ``chunk``; rejects a chunk that does not match the bound input spec."""
        spec = self.in_spec
        if spec is None:
            raise RuntimeError(f"bridge {self.name!r} used before bind()")
        v = chunk.values
        if not isinstance(v, np.ndarray) or v.dtype.kind != "f":
            raise ActionBridgeError(f"expected a floating-point chunk, got {getattr(v, 'dtype', type(v).__name__)}",
                                    code="safety.dtype", bridge=self.name)
        if v.ndim != 2 or v.shape[0] < 1 or v.shape[1] != spec.dim:
            raise ActionBridgeError(f"expected a chunk of shape (H, {spec.dim}) ({spec.space}, "
                                    f"{len(spec.joint_names)} columns{' + gripper' if spec.gripper else ''}"
                                    f"{f' + {spec.padding} padding' if spec.padding else ''}), got {v.shape}",
                                    code="safety.shape", bridge=self.name)
        if abs(chunk.rate_hz - spec.rate_hz) > 1e-9 * spec.rate_hz:
            raise ActionBridgeError(f"expected a chunk at {spec.rate_hz} Hz, got {chunk.rate_hz} Hz",
                                    code="safety.rate", bridge=self.name)
        return self._apply(chunk, spec, ref)

    def _apply(self, chunk: ActionChunk, spec: ActionSpec, ref: ReferenceState | None) -> ActionChunk:
        raise NotImplementedError


def _gripper_col(spec: ActionSpec) -> int | None:
    return len(spec.joint_names) if spec.gripper else None


class ProjectBridge(ActionBridge):
    """Dimensional projection: drop padding columns (e.g. pi0's 32-wide actions to 8).

    Only declared padding may be dropped; projecting away a named joint or the
    gripper is a type error (that would change what the command means).
    """

    name = "project"
    PARAMS = {"dims": "number of leading columns to keep"}
    REQUIRED = ("dims",)

    def output_spec(self, spec: ActionSpec) -> ActionSpec:
        dims = int(self.params["dims"])
        meaningful = spec.dim - spec.padding
        if dims != meaningful:
            raise BridgeMismatch("action.dim", f"{meaningful} (the named columns and gripper of the input)", str(dims),
                                 f"project to dims: {meaningful}; only padding columns may be dropped")
        return replace(spec, padding=0)

    def _apply(self, chunk, spec, ref):
        return ActionChunk(chunk.values[:, : spec.dim - spec.padding].copy(), chunk.rate_hz)


class ReorderJointsBridge(ActionBridge):
    """Joint reordering: permute the named columns into ``order`` (a bijection)."""

    name = "reorder_joints"
    PARAMS = {"order": "joint names in the output order"}
    REQUIRED = ("order",)

    def output_spec(self, spec: ActionSpec) -> ActionSpec:
        order = tuple(self.params["order"])
        if sorted(order) != sorted(spec.joint_names) or len(set(order)) != len(order):
            missing = sorted(set(spec.joint_names) - set(order))
            extra = sorted(set(order) - set(spec.joint_names))
            raise BridgeMismatch("action.joint_names", f"a permutation of {list(spec.joint_names)}", str(list(order)),
                                 f"missing {missing}, unknown {extra}: list every input joint exactly once")
        self._perm = np.array([spec.joint_names.index(n) for n in order])
        return replace(spec, joint_names=order)

    def _apply(self, chunk, spec, ref):
        v = chunk.values.copy()
        n = len(spec.joint_names)
        v[:, :n] = chunk.values[:, self._perm]
        return ActionChunk(v, chunk.rate_hz)


class UnitsBridge(ActionBridge):
    """Angle unit conversion of the joint (or rotation) columns: ``deg`` <-> ``rad``."""

    name = "units"
    PARAMS = {"from": "input angle unit (rad or deg)", "to": "output angle unit (rad or deg)"}
    REQUIRED = ("from", "to")

    def output_spec(self, spec: ActionSpec) -> ActionSpec:
        src, dst = self.params["from"], self.params["to"]
        for u in (src, dst):
            if u not in _ANGLE_UNITS:
                raise BridgeMismatch("bridge.units", f"one of {format_choices(_ANGLE_UNITS)}", str(u), "fix the unit name")
        if spec.units != src:
            raise BridgeMismatch("action.units", src, spec.units, f"declare from: {spec.units}")
        return replace(spec, units=dst)

    def _apply(self, chunk, spec, ref):
        factor = _ANGLE_UNITS[self.params["from"]] / _ANGLE_UNITS[self.params["to"]]
        v = chunk.values.copy()
        cols = slice(0, len(spec.joint_names)) if spec.space == "joint_position" else slice(3, 6)
        v[:, cols] *= factor
        return ActionChunk(v, chunk.rate_hz)


class FrameBridge(ActionBridge):
    """Frame conversion of ``ee_pose`` actions by a declared rigid transform.

    ``transform`` is the pose of the input frame in the output frame:
    ``{position: [x, y, z] m, quat_wxyz: [w, x, y, z]}``. Positions become
    ``R p + t``; rotation vectors ``r`` become ``log(R exp(r))``.
    """

    name = "frame"
    PARAMS = {"from": "input frame name", "to": "output frame name", "transform": "pose of 'from' in 'to'"}
    REQUIRED = ("from", "to", "transform")

    def output_spec(self, spec: ActionSpec) -> ActionSpec:
        if spec.space != "ee_pose":
            raise BridgeMismatch("action.space", "ee_pose (frames apply to Cartesian actions)", spec.space,
                                 "remove the frame bridge: joint-space actions have no frame")
        if spec.frame != self.params["from"]:
            raise BridgeMismatch("action.frame", str(self.params["from"]), spec.frame, f"declare from: {spec.frame}")
        tf = self.params["transform"]
        try:
            t = np.asarray(tf["position"], dtype=float).reshape(3)
            q = np.asarray(tf["quat_wxyz"], dtype=float).reshape(4)
        except (KeyError, TypeError, ValueError):
            raise BridgeMismatch("bridge.transform", "{position: [x, y, z], quat_wxyz: [w, x, y, z]}", repr(tf),
                                 "declare the transform of the input frame in the output frame") from None
        if not np.all(np.isfinite(t)) or not np.all(np.isfinite(q)) or abs(np.linalg.norm(q) - 1.0) > 1e-6:
            raise BridgeMismatch("bridge.transform.quat_wxyz", "a finite unit quaternion", str(q.tolist()),
                                 "normalise the quaternion")
        R = np.empty(9)
        mujoco.mju_quat2Mat(R, q)
        self._R, self._t = R.reshape(3, 3), t
        return replace(spec, frame=str(self.params["to"]))

    def _apply(self, chunk, spec, ref):
        v = chunk.values.copy()
        v[:, :3] = chunk.values[:, :3] @ self._R.T + self._t
        scale = _ANGLE_UNITS[spec.units]
        for k in range(len(v)):
            r = v[k, 3:6] * scale
            quat = np.empty(4)
            mujoco.mju_axisAngle2Quat(quat, r / (np.linalg.norm(r) or 1.0), float(np.linalg.norm(r)))
            Rk = np.empty(9)
            mujoco.mju_quat2Mat(Rk, quat)
            Ro = self._R @ Rk.reshape(3, 3)
            qo = np.empty(4)
            mujoco.mju_mat2Quat(qo, Ro.reshape(-1))
            rv = np.empty(3)
            mujoco.mju_quat2Vel(rv, qo, 1.0)
            v[k, 3:6] = rv / scale
        return ActionChunk(v, chunk.rate_hz)


class GripperRemapBridge(ActionBridge):
    """Gripper remapping between conventions (:data:`GRIPPER_CONVENTIONS`).

    ``normalized_closed`` g (0 open .. 1 closed) -> ``opening_m`` = (1 - g) x
    ``max_opening_m``; the other directions analogously. Inputs up to ``tolerance``
    outside the normalised range [0, 1] are projected onto it (a bounded projection
    that keeps the meaning: "fully closed"); anything further is rejected with
    ``safety.joint_limit``.
    """

    name = "gripper_remap"
    PARAMS = {"from": "input convention", "to": "output convention",
              "max_opening_m": "full opening per finger, m (opening_m side)",
              "tolerance": "projected overshoot of the normalised range (default 0.05)"}
    REQUIRED = ("from", "to")

    def output_spec(self, spec: ActionSpec) -> ActionSpec:
        src, dst = self.params["from"], self.params["to"]
        for c in (src, dst):
            if c not in GRIPPER_CONVENTIONS:
                raise BridgeMismatch("bridge.gripper", f"one of {format_choices(GRIPPER_CONVENTIONS)}", str(c),
                                     "fix the gripper convention name")
        if spec.gripper is None:
            raise BridgeMismatch("action.gripper", src, "no gripper column", "remove the gripper_remap bridge")
        if spec.gripper != src:
            raise BridgeMismatch("action.gripper", src, spec.gripper, f"declare from: {spec.gripper}")
        max_open = self.params.get("max_opening_m", spec.max_opening_m)
        if "opening_m" in (src, dst) and not (isinstance(max_open, (int, float)) and max_open > 0):
            raise BridgeMismatch("bridge.max_opening_m", "a full opening per finger > 0 m", repr(max_open),
                                 "declare max_opening_m (the Franka Hand opens 0.04 m per finger)")
        self._max = float(max_open) if max_open is not None else None
        return replace(spec, gripper=dst, max_opening_m=self._max if dst == "opening_m" else None)

    def _normalized_closed(self, g: np.ndarray, conv: str) -> np.ndarray:
        if conv == "normalized_closed":
            return g
        if conv == "normalized_open":
            return 1.0 - g
        if conv == "signed_closed":
            return 0.5 * (g + 1.0)
        return 1.0 - g / self._max

    def _apply(self, chunk, spec, ref):
        src, dst = self.params["from"], self.params["to"]
        tol = float(self.params.get("tolerance", 0.05))
        col = _gripper_col(spec)
        g = self._normalized_closed(chunk.values[:, col], src)
        finite = np.isfinite(g)
        far = finite & ((g < -tol) | (g > 1.0 + tol))
        if far.any():
            k = int(np.argmax(far))
            raise ActionBridgeError(f"gripper command {chunk.values[k, col]!r} ({src}) at sample {k} is outside its range "
                                    f"by more than the tolerance {tol}", code="safety.joint_limit", bridge=self.name)
        g = np.where(finite, np.clip(g, 0.0, 1.0), g)  # NaN passes on: the SafetyGuard rejects it
        if dst == "normalized_closed":
            out = g
        elif dst == "normalized_open":
            out = 1.0 - g
        elif dst == "signed_closed":
            out = 2.0 * g - 1.0
        else:
            out = (1.0 - g) * self._max
        v = chunk.values.copy()
        v[:, col] = out
        return ActionChunk(v, chunk.rate_hz)


class ResampleBridge(ActionBridge):
    """Action-chunk resampling to the target's control rate.

    The chunk's knots ``values[k]`` at ``(k + 1) / rate`` are joined to the reference
    state (last commanded position at ``t = 0``) by a cubic spline whose start
    velocity is the reference velocity (C1 across chunk boundaries; ``method: cubic``,
    scipy ``CubicSpline`` with a clamped start and natural end) or by straight
    segments (``linear``), and sampled at ``to_hz`` for the chunk's duration. The
    gripper column is held (zero-order) at each knot's value over its interval.
    """

    name = "resample"
    PARAMS = {"to_hz": "output rate, Hz (the target's control rate)", "method": "cubic (default) or linear"}
    REQUIRED = ("to_hz",)

    def output_spec(self, spec: ActionSpec) -> ActionSpec:
        to = self.params["to_hz"]
        if not isinstance(to, (int, float)) or not to > 0:
            raise BridgeMismatch("bridge.to_hz", "a rate > 0 Hz", repr(to), "set to_hz to the target's control rate")
        method = self.params.get("method", "cubic")
        if method not in ("cubic", "linear"):
            raise BridgeMismatch("bridge.method", "cubic or linear", repr(method), "choose an interpolation method")
        if spec.padding:
            raise BridgeMismatch("action.padding", "0 (project padding away first)", str(spec.padding),
                                 "put a project bridge before resample")
        return replace(spec, rate_hz=float(to))

    def _apply(self, chunk, spec, ref):
        if ref is None:
            raise ActionBridgeError("resampling needs the reference state the chunk continues from",
                                    code="safety.shape", bridge=self.name)
        to = float(self.params["to_hz"])
        H = chunk.horizon
        n_out = max(1, int(round(H * to / chunk.rate_hz)))
        t_knots = np.concatenate([[0.0], np.arange(1, H + 1) / chunk.rate_hz])
        t_out = np.arange(1, n_out + 1) / to
        n = len(spec.joint_names)
        Q = np.vstack([ref.q[None, :n], chunk.values[:, :n]])
        if self.params.get("method", "cubic") == "cubic" and H >= 2 and np.all(np.isfinite(Q)):
            spline = CubicSpline(t_knots, Q, axis=0, bc_type=((1, ref.qd[:n]), (2, np.zeros(n))))
            joints = spline(t_out)
        else:
            joints = np.column_stack([np.interp(t_out, t_knots, Q[:, j]) for j in range(n)])
        out = np.empty((n_out, spec.dim))
        out[:, :n] = joints
        col = _gripper_col(spec)
        if col is not None:
            k = np.minimum(np.ceil(t_out * chunk.rate_hz - 1e-9).astype(int) - 1, H - 1)
            out[:, col] = chunk.values[np.maximum(k, 0), col]
        return ActionChunk(out, to)


#: Bridge name (as declared in skill manifests) -> class.
BRIDGES: dict[str, type[ActionBridge]] = {
    b.name: b for b in (ProjectBridge, ReorderJointsBridge, UnitsBridge, FrameBridge, GripperRemapBridge, ResampleBridge)
}


def make_bridge(decl: Mapping[str, Any]) -> ActionBridge:
    """Build a bridge from ``{bridge: name, **params}``.

    Raises:
        ValueError: not a mapping, unknown bridge (valid ones listed) or bad parameters.
    """
    if not isinstance(decl, Mapping) or "bridge" not in decl:
        raise ValueError(f"a bridge declaration must be a mapping with a 'bridge' key, got {decl!r}")
    params = dict(decl)
    name = params.pop("bridge")
    cls = BRIDGES.get(name)
    if cls is None:
        raise ValueError(f"unknown action bridge {name!r}; valid: {format_choices(BRIDGES)}")
    return cls(**params)


_COMPARED = ("space", "joint_names", "units", "frame", "gripper", "rate_hz", "padding")
_FIXES = {
    "space": "use a policy whose action space matches the target",
    "joint_names": "add a reorder_joints bridge with the target's joint order",
    "units": "add a units bridge",
    "frame": "add a frame bridge",
    "gripper": "add a gripper_remap bridge",
    "rate_hz": "add a resample bridge to the target's control rate",
    "padding": "add a project bridge that drops the padding",
}


@dataclass
class BridgeChain:
    """An ordered list of bridges from a policy's action spec to a target's."""

    bridges: list[ActionBridge] = field(default_factory=list)

    @classmethod
    def from_declarations(cls, decls: Sequence[Mapping[str, Any]]) -> "BridgeChain":
        return cls([make_bridge(d) for d in decls])

    def check(self, source: ActionSpec, target: ActionSpec) -> list[BridgeMismatch]:
        """Type-check the chain from ``source`` to ``target``; every problem is returned.

        A bridge that rejects its input stops the walk (later bridges would be judged
        against a spec that does not exist); the final spec is compared field by field.
        """
        problems: list[BridgeMismatch] = []
        spec = source
        for i, bridge in enumerate(self.bridges):
            try:
                spec = bridge.bind(spec)
            except BridgeMismatch as exc:
                problems.append(BridgeMismatch(f"bridges[{i}].{bridge.name}: {exc.field}", exc.expected, exc.found, exc.fix))
                return problems
        for name in _COMPARED:
            have, want = getattr(spec, name), getattr(target, name)
            same = abs(have - want) <= 1e-9 * max(abs(want), 1.0) if name == "rate_hz" else have == want
            if not same:
                problems.append(BridgeMismatch(f"action.{name}", f"{want!r} (target)",
                                               f"{have!r} (policy after {len(self.bridges)} bridge(s))", _FIXES[name]))
        if spec.gripper == "opening_m" and target.gripper == "opening_m" and spec.max_opening_m is not None \
                and target.max_opening_m is not None and abs(spec.max_opening_m - target.max_opening_m) > 1e-9:
            problems.append(BridgeMismatch("action.max_opening_m", str(target.max_opening_m), str(spec.max_opening_m),
                                           "use the target gripper's full opening in gripper_remap"))
        return problems

    def apply(self, chunk: ActionChunk, ref: ReferenceState | None = None) -> ActionChunk:
        """Run ``chunk`` through every bridge (after :meth:`check` bound them)."""
        for bridge in self.bridges:
            chunk = bridge.apply(chunk, ref)
        return chunk

    def describe(self) -> list[dict[str, Any]]:
        return [b.describe() for b in self.bridges]
