"""Sensors of a MuJoCo arm: the cameras of ``sensors.yaml`` (RGB-D frames with intrinsics from
``fovy`` and seeded noise), rendering, the wrist force-torque sensor and proprioception
(mixed into :class:`~phyagentos.targets.mujoco_arm.MuJoCoArmTarget`)."""

from __future__ import annotations

import logging
import warnings
import zlib
from typing import Any, Sequence

import mujoco
import numpy as np

from phyagentos.errors import TargetError, format_choices
from phyagentos.geometry import pose_matrix
from phyagentos.perception.frames import CameraFrame, CameraIntrinsics, Proprioception
from phyagentos.renderer import Renderer

from ..camera_noise import CameraNoise

log = logging.getLogger(__name__)


#: Camera frame (MuJoCo: x right, y up, looking along -z) -> optical frame (OpenCV:
#: x right, y down, z forward).
_CAM_TO_OPTICAL = np.diag([1.0, -1.0, -1.0])


class SharedContextRenderer(mujoco.Renderer):
    """A :class:`mujoco.Renderer` of another image size that draws with ``base``'s GL
    context and MuJoCo render context instead of opening its own.

    Every ``mujoco.Renderer`` opens a GL context and a ``MjrContext``, which uploads the
    model's textures and meshes (under OSMesa into the process's own memory: about 0.5 GB
    for a LIBERO world with 147 MB of textures). Both draw into the model's offscreen
    framebuffer (``offwidth`` x ``offheight``) and read back only the image's rectangle,
    so one context serves every image size up to the framebuffer's; this renderer has its
    own scene, option and ``width`` x ``height`` rectangle, and renders exactly what a
    renderer of its own would (the same ``mjr_render`` / ``mjr_readPixels`` code path, a
    test compares the pixels). :meth:`close` drops its references without freeing the
    contexts: they are ``base``'s, closed with it.

    Args:
        base: the renderer whose contexts are shared (it must outlive this one).
        width, height: image size in pixels, at most the model's offscreen framebuffer.

    Raises:
        ValueError: an image larger than the offscreen framebuffer (as ``mujoco.Renderer``).
    """

    def __init__(self, base: mujoco.Renderer, *, width: int, height: int) -> None:
        # mujoco.Renderer.__init__ is not called: it would open another GL context and
        # upload the model again. These are the attributes its methods use (mujoco 3.10-3.11).
        self._gl_context = None
        self._mjr_context = None
        model = base.model
        if width > model.vis.global_.offwidth or height > model.vis.global_.offheight:
            raise ValueError(f"image {width}x{height} larger than the offscreen framebuffer "
                             f"({model.vis.global_.offwidth}x{model.vis.global_.offheight})")
        self._width, self._height, self._model = int(width), int(height), model
        self._scene = mujoco.MjvScene(model=model, maxgeom=base.scene.maxgeom)
        self._scene_option = mujoco.MjvOption()
        self._rect = mujoco.MjrRect(0, 0, self._width, self._height)
        self._depth_rendering = False
        self._segmentation_rendering = False
        self._gl_context = base._gl_context
        self._mjr_context = base._mjr_context
        self._base = base

    def render(self, *, out: np.ndarray | None = None) -> np.ndarray:
        """As :meth:`mujoco.Renderer.render`, drawn with ``base``'s contexts.

        Raises:
            RuntimeError: this renderer or ``base`` is closed.
        """
        if self._base._mjr_context is None:
            raise RuntimeError("render cannot be called after the shared context is closed")
        return super().render(out=out)

    def close(self) -> None:
        """Forget the shared contexts (``base`` frees them)."""
        self._gl_context = None
        self._mjr_context = None



class ArmSensors:
    """Cameras, rendering, wrist force-torque and proprioception.

    Mixed into :class:`~phyagentos.targets.mujoco_arm.MuJoCoArmTarget`.
    """

    # -- sensors ------------------------------------------------------------------------
    def configure_sensors(self, sensors: Sequence[Any]) -> None:
        """Install the target's sensor list (:class:`phyagentos.protocol.sensors.SensorSpec`
        items from ``sensors.yaml``). Cameras must name a model camera (``mount.camera``,
        default the sensor name) whose parent body is ``mount.body`` when given; a
        ``fovy_deg`` overrides the model camera's field of view.

        Raises:
            TargetError: a camera the model does not have, a mount body mismatch, or a
                camera larger than the model's offscreen framebuffer (``sensors.yaml`` named).
        """
        m = self._model
        specs = {}
        for s in sensors:
            if s.kind in ("rgbd_camera", "rgb_camera"):
                cam = s.camera_name
                cid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_CAMERA, cam)
                if cid < 0:
                    cams = [m.camera(i).name for i in range(m.ncam)]
                    raise TargetError(f"sensor {s.name!r}: target {self.name!r} has no camera {cam!r}; "
                                      f"cameras: {format_choices(cams)}")
                body = m.body(int(m.cam_bodyid[cid])).name
                if s.mount.body and s.mount.body != body:
                    raise TargetError(f"sensor {s.name!r}: camera {cam!r} is mounted on body {body!r}, "
                                      f"sensors.yaml says {s.mount.body!r}")
                fb_w, fb_h = int(m.vis.global_.offwidth), int(m.vis.global_.offheight)
                if int(s.width) > fb_w or int(s.height) > fb_h:
                    raise TargetError(f"sensors.yaml: camera {s.name!r} of target {self.name!r} is {s.width}x{s.height} "
                                      f"pixels, larger than the model's offscreen framebuffer ({fb_w}x{fb_h}); "
                                      f"use at most {fb_w}x{fb_h}")
                if s.fovy_deg is not None:
                    m.cam_fovy[cid] = float(s.fovy_deg)
            elif s.kind == "force_torque" and self._ft_adr is None:
                raise TargetError(f"sensor {s.name!r}: target {self.name!r} has no wrist force/torque sensor")
            specs[s.name] = s
        self._sensor_specs = specs
        self._camera_noise = {}

    @property
    def sensors(self) -> dict[str, Any]:
        """Installed sensor specs by name (empty until :meth:`configure_sensors`)."""
        return dict(self._sensor_specs)

    def camera_names(self) -> tuple[str, ...]:
        """Names of the configured camera sensors, in sensors.yaml order."""
        return tuple(n for n, s in self._sensor_specs.items() if s.kind in ("rgbd_camera", "rgb_camera"))

    def prepare_cameras(self) -> int:
        """Open the renderers (OpenGL contexts) of the configured cameras now, so the first
        :meth:`capture` does not pay for them (about 0.1-0.3 s each on OSMesa); renders
        nothing and draws no camera noise. Returns how many renderers are open.

        Raises:
            TargetError: no OpenGL backend.
        """
        self._check_open()
        for name in self.camera_names():
            spec = self._sensor_specs[name]
            try:
                self._renderer(int(spec.width), int(spec.height))
            except TargetError:
                raise
            except Exception as exc:
                raise TargetError(f"rendering is not available (no OpenGL backend?): {exc}") from exc
        return len(self._renderers)

    def _renderer(self, width: int, height: int):
        """The renderer of ``width`` x ``height`` pixel images. The first one opens the
        target's only GL context and MuJoCo render context (which uploads the model's
        textures and meshes: for a LIBERO world about 0.5 GB under OSMesa); a renderer of
        another size draws with those same contexts (:class:`SharedContextRenderer`)."""
        key = (int(width), int(height))
        r = self._renderers.get(key)
        vis = self._model.vis.global_
        if r is None and (key[0] > int(vis.offwidth) or key[1] > int(vis.offheight)):
            raise TargetError(f"a {key[0]}x{key[1]} image exceeds the model's offscreen framebuffer "
                              f"({int(vis.offwidth)}x{int(vis.offheight)}, <visual><global offwidth/offheight> in its "
                              f"XML); ask for at most that")
        if r is None:
            base = next(iter(self._renderers.values()), None)
            if base is not None:
                r = self._renderers[key] = SharedContextRenderer(base, width=key[0], height=key[1])
            else:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")  # glfw warns before failing without a display
                    r = self._renderers[key] = Renderer(self._model, height=key[1], width=key[0])
        return r

    def _drop_renderers(self) -> None:
        """Close every renderer (after a rendering failure: the next call opens a fresh
        context; the views of another size share the failed one's)."""
        renderers, self._renderers = self._renderers, {}
        for r in renderers.values():
            try:
                r.close()
            except Exception:  # noqa: BLE001 - pragma: no cover - GL teardown
                pass

    def render(self, camera: str = "overview", width: int = 640, height: int = 480, *,
               shadows: bool = True) -> np.ndarray:
        """``(height, width, 3)`` uint8 image from model camera ``camera``; ``shadows=False``
        renders about 5x faster under OSMesa. Raises TargetError if no OpenGL backend is
        available, the camera is unknown or the image is larger than the model's offscreen
        framebuffer (the message gives its size)."""
        self._check_open()
        m = self._model
        cams = [m.camera(i).name for i in range(m.ncam)]
        if camera not in cams:
            raise TargetError(f"unknown camera {camera!r}; cameras: {format_choices(cams)}")
        try:
            r = self._renderer(width, height)
            r.disable_depth_rendering()
            r.update_scene(self._data, camera=camera, scene_option=self._render_scene_option())
            r.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = bool(shadows)
            return r.render().copy()
        except TargetError:
            raise
        except Exception as exc:
            self._drop_renderers()
            raise TargetError(f"rendering is not available (no OpenGL backend?): {exc}") from exc

    def _render_scene_option(self) -> mujoco.MjvOption | None:
        """The ``MjvOption`` :meth:`render` draws with (None: MuJoCo's defaults); a target
        whose model carries geoms a camera would not see (collision hulls) overrides it."""
        return None

    def _noise_for(self, spec) -> CameraNoise:
        n = self._camera_noise.get(spec.name)
        if n is None:
            # seeded by the episode and the sensor name: two sensors never share a stream
            seed = [zlib.crc32(spec.name.encode())]
            if self._episode_seed is not None:
                seed.append(abs(int(self._episode_seed)))
            n = self._camera_noise[spec.name] = CameraNoise(spec.noise, np.random.default_rng(seed))
        return n

    @property
    def _capture_option(self) -> mujoco.MjvOption:
        """What a real camera sees: geoms only (no sites, joints or other markers)."""
        opt = getattr(self, "_cap_opt", None)
        if opt is None:
            opt = self._cap_opt = mujoco.MjvOption()
            opt.sitegroup[:] = 0
        return opt

    def capture(self, sensor: str) -> CameraFrame:
        """Render camera sensor ``sensor`` (RGB, and depth for ``rgbd_camera``).

        Returns a :class:`CameraFrame`: intrinsics from the camera's ``fovy``
        (:meth:`CameraIntrinsics.from_fovy`), ``T_world_camera`` the (4, 4) optical frame
        (x right, y down, z forward) in the world, depth in metres along the optical axis
        (MuJoCo's linearised depth buffer; 0 beyond the far plane), with the sensor's seeded
        noise (:class:`~phyagentos.targets.camera_noise.CameraNoise`) applied.

        Raises:
            TargetError: an unknown sensor, a non-camera sensor, or no OpenGL backend.
        """
        self._check_open()
        spec = self._sensor_specs.get(sensor)
        cams = self.camera_names()
        if spec is None or spec.kind not in ("rgbd_camera", "rgb_camera"):
            raise TargetError(f"target {self.name!r} has no camera sensor {sensor!r}; cameras: {format_choices(cams)}")
        m, d = self._model, self._data
        cid = m.camera(spec.camera_name).id
        w, h = int(spec.width), int(spec.height)
        opt = self._capture_option
        try:
            r = self._renderer(w, h)
            r.disable_depth_rendering()
            r.update_scene(d, camera=cid, scene_option=opt)
            r.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = False
            rgb = r.render().copy()
            depth = None
            if spec.kind == "rgbd_camera":
                r.enable_depth_rendering()
                r.update_scene(d, camera=cid, scene_option=opt)
                depth = r.render().astype(np.float32)
                r.disable_depth_rendering()
                far = float(m.vis.map.zfar * m.stat.extent)
                depth[depth >= 0.999 * far] = 0.0
        except TargetError:
            raise
        except Exception as exc:
            self._drop_renderers()
            raise TargetError(f"rendering is not available (no OpenGL backend?): {exc}") from exc
        noise = self._noise_for(spec)
        rgb, depth = noise.apply(rgb, depth)
        T = pose_matrix(d.cam_xpos[cid], d.cam_xmat[cid])
        T[:3, :3] = T[:3, :3] @ _CAM_TO_OPTICAL
        self._frame_count += 1
        return CameraFrame(sensor=spec.name, frame_id=spec.frame_id, stamp_s=self.sim_time,
                           intrinsics=CameraIntrinsics.from_fovy(w, h, float(m.cam_fovy[cid])),
                           T_world_camera=T, rgb=rgb, depth_m=depth)

    def _finger_offsets_m(self) -> tuple[float, float] | None:
        """Each finger's distance from the tcp along its y axis, m (+y finger first), for
        :attr:`Proprioception.finger_offsets_m <phyagentos.perception.frames.Proprioception.finger_offsets_m>`;
        ``None`` here: the base reports the opening only (a target whose fingers move apart
        overrides it)."""
        return None

    def _gripper_effort_n(self) -> float:
        """Finger actuator force, N (squeeze; 0 when free). Subclasses with fingers override."""
        return 0.0

    def wrist_wrench(self) -> tuple[np.ndarray, np.ndarray] | None:
        """``((3,) N, (3,) N m)`` of the wrist force/torque sensor in its site frame, or None."""
        if self._ft_adr is None:
            return None
        f, t = self._ft_adr
        sd = self._data.sensordata
        return sd[f:f + 3].copy(), sd[t:t + 3].copy()

    def _hand_bodies(self) -> list[int]:
        hb = getattr(self, "_hand_body_ids", None)
        if hb is None:
            m = self._model
            root = int(m.site_bodyid[m.site(self.FT_SITE).id])
            hb = self._hand_body_ids = [b for b in range(m.nbody) if self._is_under(b, root)]
        return hb

    def wrist_external_force_n(self) -> np.ndarray | None:
        """``(3,)`` N, world frame: the wrist sensor's force minus what the hand itself
        causes (its weight and inertial forces, predicted from the robot model's inertias
        and the joint accelerations, as payload identification does); i.e. the load of
        whatever the hand carries or pushes. ``None`` without a force sensor.

        Prediction: sum over the bodies distal to the sensor of ``m_i a_i`` (MuJoCo's
        ``mj_objectAcceleration`` at each body's centre of mass, gravity included)."""
        if self._ft_adr is None:
            return None
        m, d = self._model, self._data
        mujoco.mj_rnePostConstraint(m, d)
        mujoco.mj_sensorAcc(m, d)
        site = m.site(self.FT_SITE).id
        f_meas = d.site_xmat[site].reshape(3, 3) @ d.sensordata[self._ft_adr[0]:self._ft_adr[0] + 3]
        pred = np.zeros(3)
        acc = np.zeros(6)
        for b in self._hand_bodies():
            mujoco.mj_objectAcceleration(m, d, mujoco.mjtObj.mjOBJ_BODY, b, acc, 0)
            pred += m.body_mass[b] * acc[3:]
        return f_meas - pred

    def unloaded_wrist_force_n(self) -> float | None:
        """|f| (N) the wrist sensor reads when the hand holds nothing and is still: the
        weight of everything distal to the sensor site, from the robot model (what a real
        robot's end-effector load configuration states). ``None`` without a sensor."""
        if self._ft_adr is None:
            return None
        m = self._model
        body = int(m.site_bodyid[m.site(self.FT_SITE).id])
        return float(m.body_subtreemass[body]) * float(np.linalg.norm(m.opt.gravity))

    def proprioception(self) -> Proprioception:
        """Joint state, actuator forces, gripper opening and effort, wrist wrench, tcp pose
        (forward kinematics) at the current simulated time."""
        self._check_open()
        d = self._data
        mujoco.mj_rnePostConstraint(self._model, d)  # cfrc_int for the force/torque sensors
        mujoco.mj_sensorAcc(self._model, d)
        ww = self.wrist_wrench()
        return Proprioception(
            stamp_s=self.sim_time, joint_names=self._arm_names, joint_positions=self.arm_qpos(),
            joint_velocities=self.arm_qvel(), joint_efforts=d.actuator_force[self._arm_act].copy(),
            gripper_opening_m=float(self.gripper_opening()), gripper_effort_n=float(self._gripper_effort_n()),
            wrist_force_n=None if ww is None else ww[0], wrist_torque_nm=None if ww is None else ww[1],
            tcp_pose=self.tcp_pose(), finger_offsets_m=self._finger_offsets_m(),
        )

