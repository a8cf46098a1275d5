"""The Target contract: what every simulator, game or real robot implements.

A *target* is where a session's actions happen. The runtime talks to it only through
:class:`Target` (one small ABC) and reads what it offers from its
:class:`TargetCapabilities` (a frozen value object, a class attribute, so preflight
can read it without constructing the target). Nothing in the runtime probes a target
for optional attributes: an optional hook below has a documented default on
:class:`Target`, and a capability says whether the runtime may use a feature.

Units and frames: metres, radians, seconds, newtons; poses are (4, 4) homogeneous
transforms in the world frame (z up); joint vectors are ``(n,)`` float arrays in the
order of the target's ``arm_joint_names``.

What a driver implements (abstract; :class:`TypeError` at construction otherwise):

=========================  ====================================================================
``observe()``              current observation, a dict (arrays allowed; keys are the driver's)
``reset(*, seed)``         initial state for ``seed``; returns :meth:`Target.observe`
``step(ctrl)``             apply one low-level command for one control period
``execute_trajectory``     stream a timed joint trajectory (``t`` (T,) s, ``q`` (T, n) rad,
                           ``qd`` (T, n) rad/s) and return an :class:`ExecutionResult`;
                           a target without joint actions raises :class:`TargetError`
``query_state()``          JSON-ready summary (plain lists, floats, strings)
``tools()``                the names :meth:`Target.invoke_tool` accepts (``_tool_<name>``)
``save_state(path)``       write the world state to ``path`` (``.npz``), return the path
``load_state(path)``       restore what :meth:`Target.save_state` wrote
=========================  ====================================================================

The constructor signature is ``Driver(name: str, scene, *, seed: int | None)``; a driver
whose scene is not the tabletop :class:`~phyagentos.targets.scene.SceneSpec` overrides
``scene_from_dict(raw, *, root)`` (a classmethod or staticmethod returning its scene
type, which has ``to_dict()``).

Optional hooks (the defaults on :class:`Target`, used when a driver does not override):

=================================  ==========================================================
``from_target_spec(...)``          ``cls(spec.name, scene, seed=seed)`` (a classmethod; the
                                   target pool builds every target through it)
``halt()``                         does nothing (targets that move on their own override)
``set_perturbations(active)``      ignores them (no perturbation support)
``configure_sensors(sensors)``     ignores the workspace's ``sensors.yaml`` entry
``prepare_cameras()``              opens nothing, returns 0
``world_digest()``                 ``None``: the world cannot be proven unchanged (no
                                   perceived view is reused between sessions)
``ground_truth()``                 ``None``: no simulator truth (a real robot); requires
                                   ``capabilities.simulated_ground_truth`` to return a dict
``scene_record()``                 ``None``: no physical scene record
``benchmark_signals()``            ``{}``: no benchmark success signals
``estop``                          ``None``; the safety guard sets its e-stop latch (an
                                   object with ``is_set()``) here, and a target that
                                   streams motion checks it every step
``datasheet_limits``               ``None``: the safety guard's default, the Franka's 7
                                   joints (else ``(velocity (n,) rad/s, acceleration
                                   (n,) rad/s^2)``; every other arm declares its own)
``scene_from_dict(raw, *, root)``  the tabletop :class:`~phyagentos.targets.scene.SceneSpec`
                                   (``SceneSpec.default()`` for an empty ``raw``)
``ROBOT``                          ``"robot"``: the robot's entity name in perceived scenes
``runtime_notes``                  ``{}`` (set by ``Target.__init__``): the runtime's own
                                   plain-data notes about the robot (grasp belief, perceived
                                   tracks); a driver that checkpoints saves them with the state
``sim_time``                       ``None``: no simulated clock (callers use wall time);
                                   else simulated seconds (or game steps) since the reset
``perception_config()``            ``None``: the perceiver's defaults suit this world
``held_objects()``                 ``()``: the target cannot tell what the gripper holds
``KEEP_WHEN_IDLE``                 ``True``: a runner may keep the target built while it
                                   serves another workspace (runtime/worker.py keeps two
                                   workspaces' targets); ``False`` for a world too big to
                                   hold twice (a LIBERO world)
=================================  ==========================================================

Optional capabilities (mix-in ABCs, checked with ``isinstance``; a driver declares one by
deriving from it and implementing its abstract members):

=============================== ==========================================================
:class:`MuJoCoBacked`           ``model``, ``data``, ``scene``, ``arm_joint_names``,
                                ``tcp_site``: the recorder replays its states, the evidence
                                writer renders them in the background, contact primitives
                                read its forces, the view rebuilds it
:class:`RendersImages`          ``render(camera, width, height, *, shadows)``: evidence images
                                and recordings of a target without a MuJoCo model
:class:`OscControlled`          ``osc_step``, ``osc_proprio``, ``osc_limits``: an
                                operational-space controller (the ``osc_pose_delta_chunk``
                                action form)
:class:`PlansInPerceivedWorld`  ``planning_bodies()``: motion planning checks collisions in a
                                world built from what the robot perceived, not the
                                simulator's state (:mod:`phyagentos.primitives.planning_world`)
=============================== ==========================================================

Registering a driver: see :mod:`phyagentos.targets.registry` and ``docs/targets.md``.
"""

from __future__ import annotations

import abc
import inspect
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar, Literal, Mapping, Sequence

from phyagentos.errors import TargetError, format_choices

if TYPE_CHECKING:
    import mujoco
    import numpy as np

    from phyagentos.motion.dynamics import ArmDynamics
    from phyagentos.perception import PerceptionConfig

__all__ = [
    "ACTION_FORMS",
    "SENSOR_KINDS",
    "TARGET_KINDS",
    "ExecutionResult",
    "MuJoCoBacked",
    "OscControlled",
    "PlanningBodies",
    "PlansInPerceivedWorld",
    "RendersImages",
    "Target",
    "TargetCapabilities",
    "TargetKind",
    "arm_dynamics_of",
    "capabilities_of",
]

TargetKind = Literal["simulation", "real_robot", "game"]
TARGET_KINDS: tuple[str, ...] = ("simulation", "real_robot", "game")

#: The action forms a target may accept (the vocabulary of ``TargetCapabilities.action_forms``
#: and of a skill runtime's ``action_forms``):
#: ``joint_trajectory``: timed joint trajectories (``execute_trajectory``), rad;
#: ``joint_position_chunk``: chunks of joint position targets from a policy, rad;
#: ``cartesian_pose``: tcp pose targets, (4, 4) world transforms, m;
#: ``gripper_command``: a gripper opening, m (``set_gripper(opening_m=...)``);
#: ``game_action``: one of a finite set of named discrete actions (``tools()``);
#: ``osc_pose_delta_chunk``: chunks of normalised end-effector deltas + gripper for an
#: operational-space controller, one per control step (LIBERO's OSC_POSE, ``osc_step``).
ACTION_FORMS: tuple[str, ...] = ("joint_trajectory", "joint_position_chunk", "cartesian_pose",
                                 "gripper_command", "game_action", "osc_pose_delta_chunk")

#: The sensors a target may offer (``TargetCapabilities.sensors``):
#: ``proprioception``: joint positions/velocities/efforts (``proprioception()``);
#: ``rgb``: named cameras (``camera_names()``, ``capture(sensor)`` -> a camera frame); a
#: target without them may still ``render`` pictures for evidence images (:class:`RendersImages`);
#: ``depth``: depth images (``render_depth(camera=, width=, height=)``, m);
#: ``wrist_force``: a wrist force/torque sensor (``wrist_external_force_n()``, N);
#: ``contacts``: unexpected contacts reported by ``execute_trajectory``;
#: ``perception``: a built-in perceiver (``perceive()``);
#: ``symbolic_view``: a game's symbolic local view (in ``observe()``).
SENSOR_KINDS: tuple[str, ...] = ("proprioception", "rgb", "depth", "wrist_force", "contacts",
                                 "perception", "symbolic_view")


@dataclass(frozen=True)
class TargetCapabilities:
    """What a target offers, declared once per driver class (``Driver.CAPABILITIES``).

    Attributes:
        action_forms: accepted action forms, in the driver's order of preference (a subset of
            :data:`ACTION_FORMS`).
        sensors: offered sensors (a subset of :data:`SENSOR_KINDS`).
        simulated_ground_truth: ``ground_truth()`` returns the simulator's truth (never read
            by the Agent plane; a real robot has none).
        articulated_fixtures: the world has articulated fixtures (doors, drawers, knobs).
        resettable: ``reset(seed=)`` restores a seeded initial world without a person.
        real_hardware: actions move physical hardware (the safety guard's hardware checks apply).

    Raises:
        TargetError: an unknown action form or sensor (the message lists the valid ones).
    """

    action_forms: tuple[str, ...] = ()
    sensors: tuple[str, ...] = ()
    simulated_ground_truth: bool = False
    articulated_fixtures: bool = False
    resettable: bool = True
    real_hardware: bool = False

    def __post_init__(self) -> None:
        for attr, valid in (("action_forms", ACTION_FORMS), ("sensors", SENSOR_KINDS)):
            values = tuple(getattr(self, attr))
            object.__setattr__(self, attr, values)
            bad = [v for v in values if v not in valid]
            if bad:
                raise TargetError(f"TargetCapabilities.{attr}: unknown {bad[0]!r}; valid: {format_choices(valid)}")

    def accepts(self, form: str) -> bool:
        """Whether ``form`` is one of :attr:`action_forms`."""
        return form in self.action_forms

    def has_sensor(self, sensor: str) -> bool:
        """Whether ``sensor`` is one of :attr:`sensors`."""
        return sensor in self.sensors

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"action_forms": list(self.action_forms), "sensors": list(self.sensors),
                "simulated_ground_truth": self.simulated_ground_truth,
                "articulated_fixtures": self.articulated_fixtures, "resettable": self.resettable,
                "real_hardware": self.real_hardware}


def capabilities_of(target_or_cls: Any) -> TargetCapabilities:
    """The :class:`TargetCapabilities` of a target or driver class; an object outside the
    contract (not a :class:`Target`) offers nothing (``TargetCapabilities()``)."""
    cls = target_or_cls if isinstance(target_or_cls, type) else type(target_or_cls)
    return cls.CAPABILITIES if issubclass(cls, Target) else TargetCapabilities()



def arm_dynamics_of(target: Any) -> ArmDynamics | None:
    """The arm's :class:`~phyagentos.motion.dynamics.ArmDynamics` a target declares for timing
    its motions within its actuators' torques (its ``arm_dynamics()``, a
    :class:`~phyagentos.targets.mujoco_arm.MuJoCoArmTarget` hook), or None where it declares
    none: speed and acceleration limits alone then time its motions."""
    get = getattr(target, "arm_dynamics", None)
    return get() if callable(get) else None

@dataclass(frozen=True)
class ExecutionResult:
    """Outcome of :meth:`Target.execute_trajectory`.

    Attributes:
        completed: the whole trajectory was streamed and the arm settled at its end.
        max_tracking_error_rad: largest ``|q - q_ref|`` over joints and time steps, rad.
        sim_time_s: target time spent executing (simulated seconds for simulations).
        steps: control steps taken.
        contacts: the robot's parts that met something unexpected during execution
            (sorted robot body names, e.g. ``('panda0_link7',)``, or ``'held object'`` where
            what the hand holds met an obstacle); empty when none. What they met is never
            named: a real arm senses where a collision is on itself, not what it hit.
        reason: empty when completed, otherwise why execution stopped.
        code: empty unless the target itself stopped the motion for a reason it can name:
            then an error code (``<family>.<detail>``, ``protocol/errorcodes``), e.g.
            ``bus.load`` when a real arm's bus guard stopped a stalled joint. The executing
            primitive fails with this code instead of ``execution.tracking``.
    """

    completed: bool
    max_tracking_error_rad: float
    sim_time_s: float
    steps: int
    contacts: tuple[str, ...] = ()
    reason: str = ""
    code: str = ""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "completed": self.completed,
            "max_tracking_error_rad": self.max_tracking_error_rad,
            "sim_time_s": self.sim_time_s,
            "steps": self.steps,
            "contacts": list(self.contacts),
            "reason": self.reason,
            "code": self.code,
        }


class Target(abc.ABC):
    """The target contract (see the module docstring for the table of required methods
    and optional hooks).

    Subclasses set the class attributes :attr:`KIND`, :attr:`TOOLS` and
    :attr:`CAPABILITIES`, call ``super().__init__(name, kind)`` and implement the abstract
    methods. :meth:`invoke_tool` dispatches to ``_tool_<name>`` methods for the names in
    :meth:`tools`; anything else raises :class:`TargetError` listing the valid tools.

    Args:
        name: target name as written in TARGETS.md (non-empty).
        kind: one of :data:`TARGET_KINDS`.

    Raises:
        TargetError: an empty name or an unknown kind.
    """

    #: ``'simulation'``, ``'real_robot'`` or ``'game'`` (read without constructing a target).
    KIND: ClassVar[str] = "simulation"
    #: Tool names the driver offers (read by preflight without constructing a target).
    TOOLS: ClassVar[tuple[str, ...]] = ()
    #: What the driver offers (read by preflight and the runtime instead of probing).
    CAPABILITIES: ClassVar[TargetCapabilities] = TargetCapabilities()
    #: The safety guard's e-stop latch (``is_set()``), installed by the guard; a target that
    #: streams motion checks it every step and halts when set. ``None``: no guard.
    estop: Any = None
    #: Same as ``CAPABILITIES.action_forms`` (kept in step by :meth:`__init_subclass__`).
    ACTION_FORMS: ClassVar[tuple[str, ...]] = ()
    #: The robot's entity name in perceived scenes and world records.
    ROBOT: ClassVar[str] = "robot"
    #: Whether a runner may keep this target built, idle, while it serves another
    #: workspace (a runner keeps the targets of at most two workspaces, so that one it
    #: comes back to needs no rebuild): ``False`` for worlds too big to hold twice, whose
    #: workspace's targets are closed as soon as the runner moves on.
    KEEP_WHEN_IDLE: ClassVar[bool] = True
    #: The widest object the gripper takes in a top-down grasp, m; ``None``: no gripper
    #: (a game, a mobile base). Grasp planning and the graph preflight refuse wider objects
    #: before anything moves. Arms set their own (the Franka Hand: 0.08).
    max_grasp_width_m: ClassVar[float | None] = None
    #: Where the gripper's fingers reach along the tool frame's z (out of the hand), m:
    #: ``(lowest point of the fingers below the tcp, bottom of the finger pads below it, how far
    #: above it an object's top may rise before the finger base)``. Top-down grasps set the tcp
    #: so the fingertips clear the support and the pads close on the object's side; ``None``:
    #: the Franka Hand's with the tcp of the tabletop Franka
    #: (:data:`~phyagentos.motion.grasp.FRANKA_FINGERS`).
    finger_geometry_m: ClassVar[tuple[float, float, float] | None] = None
    #: Sliding friction coefficient of the fingertips, the part of the closed fingers that
    #: meets a surface below them (the robot's own; MuJoCo's ``geom_friction[0]``); ``None``: not
    #: declared. A push presses a low object from above and drags it only with fingertips that
    #: grip (:data:`~phyagentos.primitives.contact.PRESS_MIN_TIP_FRICTION`).
    fingertip_friction: ClassVar[float | None] = None
    #: The runtime's own notes about this robot (plain data: the grasp it believes it holds,
    #: the objects it has perceived; :mod:`phyagentos.primitives.grasp_sense`). ``{}`` after
    #: ``__init__``; a driver that checkpoints its state saves them with it.
    runtime_notes: dict[str, Any]

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if "CAPABILITIES" in cls.__dict__:
            cls.ACTION_FORMS = cls.CAPABILITIES.action_forms

    def __init__(self, name: str, kind: TargetKind):
        if not isinstance(name, str) or not name:
            raise TargetError(f"target name must be a non-empty string, got {name!r}")
        if kind not in TARGET_KINDS:
            raise TargetError(f"unknown target kind {kind!r}; valid kinds: {format_choices(TARGET_KINDS)}")
        self._name = name
        self._kind = kind
        self._closed = False
        self.runtime_notes = {}

    @property
    def name(self) -> str:
        """Target name as written in TARGETS.md."""
        return self._name

    @property
    def kind(self) -> str:
        """``'simulation'``, ``'real_robot'`` or ``'game'``."""
        return self._kind

    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def capabilities(self) -> TargetCapabilities:
        """This driver's :attr:`CAPABILITIES`."""
        return type(self).CAPABILITIES

    # -- required ---------------------------------------------------------------------
    @abc.abstractmethod
    def observe(self) -> dict:
        """Current observation (arrays allowed; see the subclass for keys)."""

    @abc.abstractmethod
    def reset(self, *, seed: int | None = None) -> dict:
        """Put the target in its initial state and return :meth:`observe`."""

    @abc.abstractmethod
    def step(self, ctrl) -> None:
        """Apply one low-level control command for one control period."""

    @abc.abstractmethod
    def execute_trajectory(self, traj, *, tracking_tol_rad: float) -> ExecutionResult:
        """Stream a timed joint trajectory (``t`` (T,) s, ``q`` (T, n) rad, ``qd`` (T, n)
        rad/s) to the arm; ``tracking_tol_rad`` bounds ``|q - q_ref|``, rad."""

    @abc.abstractmethod
    def query_state(self) -> dict:
        """JSON-ready summary of the target state (plain lists, floats, strings)."""

    @abc.abstractmethod
    def tools(self) -> tuple[str, ...]:
        """Names accepted by :meth:`invoke_tool`."""

    # save_state / load_state are required by the target pool (a world that outlives a
    # session); they are not abstract here so that a driver written against the older
    # contract still constructs, and the conformance test checks them.
    def save_state(self, path) -> Any:  # pragma: no cover - every driver overrides
        """Write the world state to ``path`` (``.npz``) and return the path written."""
        raise TargetError(f"target {self.name!r} ({type(self).__name__}) cannot save its state")

    def load_state(self, path) -> None:  # pragma: no cover - every driver overrides
        """Restore the world state written by :meth:`save_state`."""
        raise TargetError(f"target {self.name!r} ({type(self).__name__}) cannot load a state")

    def invoke_tool(self, name: str, **kwargs) -> Any:
        """Run tool ``name`` with keyword arguments.

        Raises :class:`TargetError` for an unknown tool (listing :meth:`tools`), for
        bad arguments, or when the target is closed.
        """
        valid = self.tools()
        if name not in valid:
            raise TargetError(f"target {self.name!r} has no tool {name!r}; valid tools: {format_choices(valid)}")
        if self._closed:
            raise TargetError(f"target {self.name!r} is closed")
        fn = getattr(self, f"_tool_{name}", None)
        if fn is None:  # pragma: no cover - subclass bug
            raise TargetError(f"target {self.name!r} lists tool {name!r} but does not implement it")
        sig = inspect.signature(fn)
        try:
            sig.bind(**kwargs)
        except TypeError as exc:
            params = ", ".join(str(p) for p in sig.parameters.values())
            raise TargetError(
                f"bad arguments for tool {name!r} of target {self.name!r}: {exc}; expected ({params})"
            ) from exc
        return fn(**kwargs)

    # -- optional hooks (documented defaults) -----------------------------------------
    @classmethod
    def scene_from_dict(cls, raw: Mapping[str, Any] | None, *, root: Any = None) -> Any:
        """Parse the scene of a TARGETS.md entry or session (``raw``: plain data, without its
        ``perturbations``); ``root`` is the workspace root that mesh files are read from.
        Default: the tabletop :class:`~phyagentos.targets.scene.SceneSpec`
        (``SceneSpec.default()`` for an empty ``raw``); a driver with its own scene type
        overrides this.

        Raises:
            TargetError: a malformed scene (the message names the key).
        """
        from .scene import SceneSpec  # noqa: PLC0415 - MuJoCo-backed; only the tabletop needs it

        return SceneSpec.from_dict(raw, root=root) if raw else SceneSpec.default()

    @classmethod
    def from_target_spec(cls, spec: Any, scene: Any, *, seed: int | None = None) -> "Target":
        """Build the target of a TARGETS.md entry (``spec``: a
        :class:`~phyagentos.protocol.TargetSpec`) on ``scene``. Default:
        ``cls(spec.name, scene, seed=seed)``; a driver that needs more of its entry (an
        endpoint, limits) overrides this."""
        return cls(spec.name, scene, seed=seed)

    def halt(self) -> None:
        """Stop any motion and hold still (called on cancellation or errors).
        The default does nothing; targets that move on their own override it."""

    def set_perturbations(self, active: Any) -> None:
        """Install the session's active perturbations
        (:class:`~phyagentos.targets.perturbations.ActivePerturbations`). Default: ignored."""

    def configure_sensors(self, sensors: Any) -> None:
        """Install the workspace's ``sensors.yaml`` entry for this target. Default: ignored."""

    def prepare_cameras(self) -> int:
        """Open the cameras' renderers ahead of the first session; returns how many were
        opened. Default: none (0)."""
        return 0

    def world_digest(self) -> str | None:
        """A digest of the world state equal for equal worlds, or ``None`` (the default)
        when the target cannot prove its world unchanged (e.g. a real robot)."""
        return None

    def ground_truth(self) -> dict[str, Any] | None:
        """The simulator's truth (Runtime plane only), or ``None`` (the default) for a target
        without a ground-truth channel."""
        return None

    def scene_record(self) -> dict[str, Any] | None:
        """The physical scene the target was built from, or ``None`` (the default)."""
        return None

    def benchmark_signals(self) -> dict[str, Any]:
        """The target's own success signals (e.g. a benchmark's task completions);
        default: none (``{}``)."""
        return {}

    @property
    def sim_time(self) -> float | None:
        """Target time since the last reset (or loaded state): simulated seconds, or game
        steps for a game; ``None`` (the default) for a target without a simulated clock
        (callers then use wall time)."""
        return None

    def perception_config(self) -> PerceptionConfig | None:
        """The :class:`~phyagentos.perception.PerceptionConfig` that suits this world when the
        workspace has no ``perception.yaml``, or ``None`` (the default): the perceiver's
        defaults."""
        return None

    def held_objects(self) -> tuple[str, ...]:
        """Names of the objects the gripper holds now (simulator contacts: ground truth),
        or ``()`` (the default) when the target cannot tell."""
        return ()

    @property
    def datasheet_limits(self) -> tuple[tuple[float, ...], tuple[float, ...]] | None:
        """``(velocity (n,) rad/s, acceleration (n,) rad/s^2)`` datasheet limits for the
        safety guard, or ``None`` (the default) for the guard's default (the Franka's seven
        joints: every other arm declares its own)."""
        return None

    def close(self) -> None:
        """Release resources; further calls are no-ops."""
        self._closed = True

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r}, kind={self.kind!r})"


# -- optional capabilities (mix-ins, checked with isinstance) -----------------------------
class MuJoCoBacked(abc.ABC):
    """A target whose world is a MuJoCo model (an optional capability: check with
    ``isinstance(target, MuJoCoBacked)``). The session recorder replays its states in a
    render process, the evidence writer renders them in the background, the contact
    primitives read forces from it, the view rebuilds it.
    :class:`~phyagentos.targets.mujoco_arm.MuJoCoArmTarget` implements it."""

    @property
    @abc.abstractmethod
    def model(self) -> mujoco.MjModel:
        """The compiled model (treat as read-only)."""

    @property
    @abc.abstractmethod
    def data(self) -> mujoco.MjData:
        """The live data (``qpos``, ``mocap_pos``, contacts, ``time`` s)."""

    @property
    @abc.abstractmethod
    def scene(self) -> Any:
        """The scene this target was built from (has ``to_dict()``): ``cls(name, scene,
        seed=seed)`` rebuilds the same model in another process."""

    @property
    @abc.abstractmethod
    def arm_joint_names(self) -> tuple[str, ...]:
        """The model's arm joints, in the order of the target's joint vectors ``(n,)``."""

    @property
    @abc.abstractmethod
    def tcp_site(self) -> str:
        """Name of the model site at the tool point (the tcp)."""

    def hand_capsules(self) -> list[tuple[tuple[float, ...], tuple[float, ...], float]]:
        """Capsules ``(p0 (3,), p1 (3,), radius)`` in m, world frame, over hand parts the
        perceiver's gripper box does not cover (the SO-101's moving jaw); their points are
        masked out of the clouds like the arm's links. Default: none."""
        return []


class RendersImages(abc.ABC):
    """A target that draws pictures of its world (an optional capability: check with
    ``isinstance(target, RendersImages)``): evidence images, and the recordings of a
    target that is not :class:`MuJoCoBacked`."""

    @abc.abstractmethod
    def render(self, camera: str = "", width: int = 640, height: int = 480, *,
               shadows: bool = True) -> np.ndarray:
        """``(height, width, 3)`` uint8 RGB picture from ``camera`` (the driver's default
        camera when omitted); ``shadows=False`` may be cheaper.

        Raises:
            TargetError: an unknown camera, or no rendering backend (e.g. no OpenGL).
        """


@dataclass(frozen=True)
class PlanningBodies:
    """Where the things a perceiver reports go in a target's MuJoCo model, for motion planning
    in a world built from perception (:mod:`phyagentos.primitives.planning_world`). Names only:
    the model's geometry is the robot's knowledge of its objects and fixtures (their meshes ship
    with the assets), never where the simulator has put them.

    Attributes:
        robot_joints: the robot's joints (arm and hand): their positions are its encoders'.
        objects: ``{entity name: root body name}`` of the movable objects (a free joint each).
        fixtures: ``{entity name: root body name}`` of the fixtures (bodies fixed in the
            model), set where the perceiver reports their model frame
            (``attributes.body.root``).
        slides: ``{articulation entity name: (joint name, sign)}``: a drawer's slide, set to
            ``sign`` times the perceived opening (``attributes.joint_position``, m), or a
            fixture's door's hinge (the fixture's name), set the same way (its opening, rad).
        unseen_slots: mocap bodies with one box geom each, which the planner sizes and places
            on the segments perception saw but could not name (``kind: unknown``); empty: such
            segments are not in the planner's world.
        perceived_shapes: the objects' models are stand-ins whose one primitive geom (box,
            cylinder or sphere) takes the perceived shape and size (a randomised world draws
            them: the model's are the simulator's); ``False``: the model's geometry is the
            robot's own knowledge of the object (LIBERO's assets).
    """

    robot_joints: tuple[str, ...]
    objects: Mapping[str, str]
    fixtures: Mapping[str, str]
    slides: Mapping[str, tuple[str, float]]
    unseen_slots: tuple[str, ...] = ()
    perceived_shapes: bool = False


class PlansInPerceivedWorld(abc.ABC):
    """A MuJoCo-backed target whose motion planning checks collisions in the world its robot
    perceived (an optional capability: check with ``isinstance(target, PlansInPerceivedWorld)``):
    each perceived object's and fixture's model where it was seen, what was not seen left out.
    Without it the planner's world is the simulator's state (FrankaKitchen's)."""

    @abc.abstractmethod
    def planning_bodies(self) -> PlanningBodies:
        """Where perceived things go in the model (:class:`PlanningBodies`)."""


class OscControlled(abc.ABC):
    """A target driven by an operational-space controller (an optional capability: check
    with ``isinstance(target, OscControlled)``; the ``osc_pose_delta_chunk`` action form)."""

    @abc.abstractmethod
    def osc_step(self, action: Sequence[float]) -> None:
        """One control step of ``action`` (7,): a normalised pose delta in [-1, 1] per axis
        (scaled by ``osc_limits()['output_max']``) and the gripper (-1 open .. +1 closed)."""

    @abc.abstractmethod
    def osc_proprio(self) -> dict[str, np.ndarray]:
        """The controller's proprioception: ``eef_pos`` (3,) m (world), ``eef_quat_xyzw``
        (4,), ``gripper_qpos`` (2,) m."""

    @abc.abstractmethod
    def osc_limits(self) -> dict[str, Any]:
        """The controller as configured: ``type``, ``input_max``, ``output_max`` (6,) (m and
        rad per control step at input 1), ``control_period_s`` s."""
