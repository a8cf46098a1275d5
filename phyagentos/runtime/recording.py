"""Session recordings: ``evidence/<session>/video.mp4`` and the recorded state per frame.

With ``phyagentos run ... --record`` (or ``bench ... --record failures``) the SessionRunner
gives each session a :class:`SessionRecorder`. From its tick hook the recorder captures
an instant whenever ``1/fps`` seconds of *simulated* time have passed since the last one
(targets without a simulation clock use wall time; a frame can only be captured between
ticks, so a skill whose ticks advance 0.1 s gets at most 10 distinct frames per second).
For a MuJoCo target the hook only copies the state (``qpos`` and mocap poses); a
background thread renders the declared camera (default the target's own view) from that state
with its own ``MjData`` and renderer and pipes the frames to the ffmpeg binary shipped in
the ``imageio-ffmpeg`` wheel (H.264 in MP4; no system ffmpeg). Rendering is therefore never
in the control loop; the session's end waits for the backlog. When one tick advances
several frame periods, the video repeats the frame for each, so it plays at the
simulation's real-time speed. :meth:`SessionRecorder.close` captures the terminal
instant, joins the encoder and writes ``frames.npz`` (``t`` (N,) simulated time in s,
``qpos`` (N, nq), ``wall`` (N,) s since the first frame); the runner lists both files in
the bundle before it is finalised. ``phyagentos view`` re-renders any recorded instant
from ``frames.npz`` with a free camera.

Configuration travels from the CLI to the runner processes through the environment
variable ``PHYAGENTOS_RECORD`` (``off``, ``all`` or ``failures``, optionally followed by
``,camera=NAME,fps=F,width=W,height=H``), set before the forkserver starts, so
``phyagentos watch`` can record too. ``failures`` records every session and
:func:`prune_recordings` deletes the recordings of sessions whose verdict was success
once the verdicts are in (the runner cannot know the verdict: that is the verifier's).
"""

from __future__ import annotations

import contextlib
import inspect
import logging
import os
import queue
import threading
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from phyagentos.errors import RecordingError, TargetError
from phyagentos.protocol import dump_yaml
from phyagentos.protocol.atomic import atomic_write_text
from phyagentos.yamlsource import read_yaml

__all__ = ["ENV_VAR", "RECORD_MODES", "RecordingConfig", "SessionRecorder", "default_camera", "prune_recordings"]

logger = logging.getLogger(__name__)

#: Environment variable carrying the recording configuration to runner processes.
ENV_VAR = "PHYAGENTOS_RECORD"
#: ``off``: no recording; ``all``: keep every session's; ``failures``: keep those whose verdict is not success.
RECORD_MODES = ("off", "all", "failures")
#: Nice increment of the render process (and its ffmpeg): the control loop goes first.
RENDER_NICE = 10
VIDEO_FILE = "video.mp4"
FRAMES_FILE = "frames.npz"


def default_camera(target: Any) -> str:
    """The camera ``target`` renders when none is named: the default of its
    ``render(camera=...)`` (``overview`` where it has none)."""
    try:
        default = inspect.signature(target.render).parameters["camera"].default
    except (AttributeError, KeyError, TypeError, ValueError):
        return "overview"
    return default if isinstance(default, str) and default else "overview"


@dataclass(frozen=True)
class RecordingConfig:
    """What to record and how.

    Attributes:
        mode: one of :data:`RECORD_MODES`.
        camera: the target camera to render (MuJoCo camera name); ``""``: the one the
            target renders by default (the default of its ``render(camera=)``: ``overview``
            on the built tabletops, ``agentview`` on LIBERO).
        fps: frames per second of simulated time (also the video's playback rate,
            so the video plays at real-time speed of the simulation).
        width, height: frame size in pixels (multiples of 16 for H.264).
    """

    mode: str = "off"
    camera: str = ""
    fps: float = 10.0
    width: int = 320
    height: int = 240

    def __post_init__(self) -> None:
        if self.mode not in RECORD_MODES:
            raise RecordingError(f"unknown recording mode {self.mode!r}; valid: {', '.join(RECORD_MODES)}")
        if not 0 < self.fps <= 60:
            raise RecordingError(f"recording fps must be in (0, 60], got {self.fps}")
        for name in ("width", "height"):
            v = getattr(self, name)
            if v < 16 or v > 1920 or v % 16:
                raise RecordingError(f"recording {name} must be a multiple of 16 in [16, 1920], got {v}")

    @property
    def enabled(self) -> bool:
        return self.mode != "off"

    def to_env(self) -> str:
        """The ``PHYAGENTOS_RECORD`` value that :meth:`from_env` parses back."""
        camera = f",camera={self.camera}" if self.camera else ""
        return f"{self.mode}{camera},fps={self.fps:g},width={self.width},height={self.height}"

    @classmethod
    def parse(cls, text: str) -> "RecordingConfig":
        """Parse ``MODE[,camera=NAME][,fps=F][,width=W][,height=H]``.

        Raises:
            RecordingError: unknown mode or key, or a value out of range.
        """
        parts = [p.strip() for p in text.split(",") if p.strip()]
        if not parts:
            return cls()
        cfg = cls(mode=parts[0])
        kinds = {"camera": str, "fps": float, "width": int, "height": int}
        for part in parts[1:]:
            key, _, value = part.partition("=")
            if key not in kinds or not value:
                raise RecordingError(f"bad recording option {part!r}; valid keys: {', '.join(kinds)} (key=value)")
            try:
                cfg = replace(cfg, **{key: kinds[key](value)})
            except ValueError:
                raise RecordingError(f"bad recording option {part!r}: {value!r} is not a {kinds[key].__name__}") from None
        return cfg

    @classmethod
    def from_env(cls, environ: Mapping[str, str] | None = None) -> "RecordingConfig":
        """The configuration in ``PHYAGENTOS_RECORD`` (``off`` when unset)."""
        text = (os.environ if environ is None else environ).get(ENV_VAR, "")
        return cls.parse(text) if text else cls()


def _write_frames(path: Path, cfg: RecordingConfig):
    """An imageio-ffmpeg writer generator, primed (H.264, yuv420p, fast start)."""
    import imageio_ffmpeg  # noqa: PLC0415 - only when recording

    writer = imageio_ffmpeg.write_frames(
        str(path), (cfg.width, cfg.height), fps=cfg.fps, codec="libx264", pix_fmt_out="yuv420p",
        macro_block_size=16, ffmpeg_log_level="error", output_params=["-movflags", "+faststart"])
    writer.send(None)
    return writer


def _model_recipe(target: Any, seed: int | None) -> dict[str, Any] | None:
    """How a render process rebuilds ``target``'s MuJoCo model (class, name, scene, seed), or None."""
    import mujoco  # noqa: PLC0415

    from phyagentos.targets.contract import MuJoCoBacked  # noqa: PLC0415 - the package imports MuJoCo

    if not isinstance(target, MuJoCoBacked):
        return None
    scene = target.scene
    if not isinstance(target.model, mujoco.MjModel) or not hasattr(scene, "to_dict"):
        return None
    cls = type(target)
    # a scene with mesh objects travels as the checked spec itself (it carries the mesh
    # bytes; its plain-data form names workspace files the render process cannot vouch for)
    meshes = any(getattr(o, "mesh_data", None) is not None for o in getattr(scene, "objects", ()))
    return {"module": cls.__module__, "cls": cls.__qualname__, "name": target.name,
            "scene": scene if meshes else scene.to_dict(), "seed": seed, "nq": int(target.model.nq)}


class _RenderProcess:
    """A child process (``python -m phyagentos.runtime.recording``) that rebuilds the target's
    model, renders each state it receives and encodes the video: MuJoCo's OpenGL render holds
    the GIL, so in a thread it would stall the control loop; in a process it only competes
    for a core, at a lower priority (nice +10).

    Messages on its stdin are length-prefixed pickles: the recipe and config first, then
    ``(state, slots)`` per frame, then ``None``; it answers one JSON line on stdout.
    """

    def __init__(self, path: Path, cfg: RecordingConfig, recipe: dict[str, Any]) -> None:
        import subprocess  # noqa: PLC0415
        import sys  # noqa: PLC0415

        self.proc = subprocess.Popen([sys.executable, "-m", "phyagentos.runtime.recording"], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE)
        with contextlib.suppress(OSError):  # lower priority: under contention the control loop goes first
            os.setpriority(os.PRIO_PROCESS, self.proc.pid, os.getpriority(os.PRIO_PROCESS, 0) + RENDER_NICE)
        self.result: dict[str, Any] = {}
        self._send({"path": str(path), "config": cfg.to_env(), "recipe": recipe})

    def _send(self, obj: Any) -> None:
        import pickle  # noqa: PLC0415
        import struct  # noqa: PLC0415

        data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
        try:
            self.proc.stdin.write(struct.pack("<I", len(data)) + data)
            self.proc.stdin.flush()
        except (BrokenPipeError, OSError) as exc:
            self.result.setdefault("error", f"render process gone: {exc}")

    def put(self, state: dict, slots: int) -> None:
        self._send((state, slots))

    def close(self, beat: Callable[[], None] | None = None) -> dict[str, Any]:
        import json  # noqa: PLC0415
        import subprocess  # noqa: PLC0415

        self._send(None)
        with contextlib.suppress(OSError):
            self.proc.stdin.close()
        while True:  # the backlog may take seconds: keep the runner's heartbeat fresh meanwhile
            try:
                self.proc.wait(timeout=0.5)
                break
            except subprocess.TimeoutExpired:
                if beat is not None:
                    beat()
        out = self.proc.stdout.read().decode(errors="replace").strip().splitlines()
        try:
            self.result = {**json.loads(out[-1]), **self.result} if out else {"error": "render process said nothing", **self.result}
        except ValueError:
            self.result = {"error": f"render process answered {out[-1]!r}", **self.result}
        return self.result


class _InlineEncoder(threading.Thread):
    """For targets the render process cannot rebuild: images rendered by the caller, encoded here."""

    def __init__(self, path: Path, cfg: RecordingConfig) -> None:
        super().__init__(name=f"recorder-{path.parent.name}", daemon=True)
        self.path, self.cfg = path, cfg
        self.items: queue.Queue = queue.Queue()
        self.result: dict[str, Any] = {"written": 0, "error": None, "render_s": 0.0}

    def put(self, pixels: np.ndarray, slots: int) -> None:
        self.items.put((pixels, slots))

    def run(self) -> None:
        writer = None
        try:
            writer = _write_frames(self.path, self.cfg)
            while (item := self.items.get()) is not None:
                frame = np.ascontiguousarray(item[0], dtype=np.uint8).tobytes()
                for _ in range(item[1]):
                    writer.send(frame)
                    self.result["written"] += 1
        except Exception as exc:  # noqa: BLE001 - reported by close(); a video never fails a session
            self.result["error"] = f"{type(exc).__name__}: {exc}"
            while self.items.get() is not None:
                pass
        finally:
            if writer is not None:
                with contextlib.suppress(Exception):
                    writer.close()

    def close(self, beat: Callable[[], None] | None = None) -> dict[str, Any]:
        self.items.put(None)
        while self.is_alive():
            self.join(timeout=0.5)
            if beat is not None and self.is_alive():
                beat()
        return self.result


def _render_main() -> int:
    """The render process (see :class:`_RenderProcess`)."""
    import importlib  # noqa: PLC0415
    import json  # noqa: PLC0415
    import pickle  # noqa: PLC0415
    import struct  # noqa: PLC0415
    import sys  # noqa: PLC0415

    import phyagentos  # noqa: F401,PLC0415 - selects the headless GL backend before mujoco loads

    stdin = sys.stdin.buffer

    def receive():
        head = stdin.read(4)
        if len(head) < 4:
            return None
        return pickle.loads(stdin.read(struct.unpack("<I", head)[0]))

    result = {"written": 0, "error": None, "render_s": 0.0}
    writer = renderer = target = None
    try:
        import mujoco  # noqa: PLC0415

        from phyagentos.renderer import Renderer  # noqa: PLC0415

        setup = receive()
        cfg = RecordingConfig.parse(setup["config"])
        recipe = setup["recipe"]
        cls = getattr(importlib.import_module(recipe["module"]), recipe["cls"])
        scene = recipe["scene"]
        target = cls(recipe["name"], cls.scene_from_dict(scene) if isinstance(scene, dict) else scene,
                     seed=recipe["seed"])
        model = target.model
        if model.nq != recipe["nq"]:
            raise RecordingError(f"rebuilt model has nq={model.nq}, the session's has {recipe['nq']}")
        data = mujoco.MjData(model)
        renderer = Renderer(model, height=cfg.height, width=cfg.width)
        writer = _write_frames(Path(setup["path"]), cfg)
        while (item := receive()) is not None:
            state, slots = item
            started = time.perf_counter()
            data.qpos[:] = state["qpos"]
            if model.nmocap:
                data.mocap_pos[:] = state["mocap_pos"]
                data.mocap_quat[:] = state["mocap_quat"]
            mujoco.mj_forward(model, data)
            renderer.update_scene(data, camera=cfg.camera)
            renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = False
            frame = renderer.render().tobytes()
            result["render_s"] += time.perf_counter() - started
            for _ in range(slots):
                writer.send(frame)
                result["written"] += 1
    except Exception as exc:  # noqa: BLE001 - reported to the parent, which logs it
        result["error"] = f"{type(exc).__name__}: {exc}"
        while receive() is not None:  # drain, so the parent never blocks on a full pipe
            pass
    finally:
        for closing in (writer, renderer, target):
            if closing is not None:
                with contextlib.suppress(Exception):
                    closing.close()
    sys.stdout.write(json.dumps(result) + "\n")
    sys.stdout.flush()
    return 0


class SessionRecorder:
    """Records one session of ``target`` into ``directory``.

    For a MuJoCo target (:class:`~phyagentos.targets.contract.MuJoCoBacked`, ``model`` a
    ``mujoco.MjModel``), the tick hook only copies the state (``qpos``, mocap poses:
    microseconds); a render process renders it with its own ``MjData`` and renderer and
    encodes it, so rendering never runs in the control loop. Other targets
    (:class:`~phyagentos.targets.contract.RendersImages`) render through ``target.render``
    in the hook.

    Args:
        target: the session's target.
        directory: the session's evidence directory.
        config: the recording configuration (``mode`` must not be ``off``).

    Raises:
        RecordingError: the target can neither be replayed nor render (neither
            ``MuJoCoBacked`` with a model nor ``RendersImages``).
        TargetError: the camera is not one of the target's (the message lists them).
    """

    def __init__(self, target: Any, directory: str | Path, config: RecordingConfig, *, seed: int | None = None) -> None:
        import mujoco  # noqa: PLC0415

        from phyagentos.targets.contract import MuJoCoBacked, RendersImages  # noqa: PLC0415

        if not config.camera:
            config = replace(config, camera=default_camera(target))
        recipe = _model_recipe(target, seed)
        if recipe is None and not isinstance(target, RendersImages):
            raise RecordingError(f"target {target.name!r} cannot render; nothing to record")
        if recipe is not None and mujoco.mj_name2id(target.model, mujoco.mjtObj.mjOBJ_CAMERA, config.camera) < 0:
            model = target.model
            cams = [model.camera(i).name for i in range(model.ncam)]
            raise TargetError(f"unknown camera {config.camera!r} to record; cameras: {', '.join(cams) or 'none'}")
        self._replay = recipe is not None
        self._mujoco = isinstance(target, MuJoCoBacked)  # its qpos is recorded
        self.target = target
        self.directory = Path(directory)
        self.config = config
        self.period = 1.0 / config.fps
        self._next: float | None = None
        self._t: list[float] = []
        self._wall: list[float] = []
        self._qpos: list[np.ndarray] = []
        self._t0 = time.perf_counter()
        self.hook_s = 0.0
        self.ticks = 0
        self.result: dict[str, Any] = {}
        video = self.directory / VIDEO_FILE
        if self._replay:
            self._encoder: Any = _RenderProcess(video, config, recipe)
        else:
            self._encoder = _InlineEncoder(video, config)
            self._encoder.start()
        self._closed = False
        self.capture()  # the first frame: the initial state

    @property
    def frames(self) -> int:
        """Instants captured so far."""
        return len(self._t)

    @property
    def render_s(self) -> float:
        """Wall time spent rendering in the render process (known after :meth:`close`), s."""
        return float(self.result.get("render_s", 0.0))

    def _clock(self) -> float:
        t = self.target.sim_time
        return float(t) if t is not None else time.perf_counter() - self._t0

    def capture(self) -> None:
        """Capture one frame now (and record its state), regardless of the rate."""
        started = time.perf_counter()
        data = self.target.data if self._mujoco else None
        qpos = np.array(data.qpos, dtype=np.float64) if data is not None else np.zeros(0)
        if self._replay:
            payload: Any = {"qpos": qpos, "mocap_pos": np.array(data.mocap_pos), "mocap_quat": np.array(data.mocap_quat)}
        else:
            c = self.config
            payload = self.target.render(c.camera, width=c.width, height=c.height, shadows=False)
        now = self._clock()
        # A tick may advance several frame periods of simulated time: the video repeats the
        # frame for each period it covers, so it plays at the simulation's real-time speed.
        slots = 1 if not self._t else max(1, round((now - self._t[-1]) * self.config.fps))
        self._qpos.append(qpos)
        self._t.append(now)
        self._wall.append(started - self._t0)
        self._next = now + self.period
        self._encoder.put(payload, slots)
        self.hook_s += time.perf_counter() - started

    def tick(self) -> None:
        """Called after every tick: captures a frame when one is due (cheap otherwise)."""
        started = time.perf_counter()
        self.ticks += 1
        if not self._closed and self._clock() >= self._next:
            try:
                self.capture()
                return
            except (TargetError, OSError, ValueError) as exc:
                logger.warning("recording %s stopped: %s", self.directory.name, exc)
                self._closed = True
        self.hook_s += time.perf_counter() - started

    def close(self, *, heartbeat: Callable[[], None] | None = None) -> dict[str, str]:
        """Capture the terminal frame, wait for the video to be encoded, write ``frames.npz``.

        ``heartbeat`` is called every 0.5 s while waiting (the supervisor must not take a
        runner that waits for its video for a dead one).

        Returns the files written, for the bundle's ``files``: ``{"video": "video.mp4",
        "frames": "frames.npz"}`` (``video`` missing if encoding failed, which is logged).
        """
        if not self._closed and (not self._t or self._clock() > self._t[-1]):  # the terminal instant, if new
            try:
                self.capture()
            except (TargetError, OSError, ValueError) as exc:
                logger.warning("recording %s: no terminal frame: %s", self.directory.name, exc)
        self._closed = True
        self.result = self._encoder.close(heartbeat)
        files: dict[str, str] = {}
        same = self._qpos and all(q.shape == self._qpos[0].shape for q in self._qpos)
        qpos = np.stack(self._qpos) if same else np.zeros((0, 0))
        np.savez_compressed(self.directory / FRAMES_FILE, t=np.asarray(self._t), wall=np.asarray(self._wall), qpos=qpos,
                            camera=np.asarray(self.config.camera), fps=np.asarray(self.config.fps))
        files["frames"] = FRAMES_FILE
        if not self.result.get("error") and self.result.get("written"):
            files["video"] = VIDEO_FILE
        else:
            logger.warning("recording %s: video not written: %s", self.directory.name, self.result.get("error"))
        logger.info("recording %s: %d instants, %d video frames; hook %.4f s over %d ticks, render %.3f s",
                    self.directory.name, len(self._t), self.result.get("written", 0), self.hook_s, self.ticks, self.render_s)
        return files


def prune_recordings(workspace: Any) -> int:
    """Delete the recordings of sessions whose last verdict is ``success`` (``--record failures``).

    Reads the session records (never writes one); drops ``video.mp4`` and ``frames.npz``
    and their entries from the evidence bundle's ``files``. Returns how many sessions'
    recordings were deleted.
    """
    removed = 0
    for rec in workspace.list_sessions():
        verdict = rec.attempts[-1].verdict if rec.attempts else None
        if verdict is None or verdict.verdict != "success":
            continue
        for attempt in rec.attempts:
            if not attempt.evidence:
                continue
            directory = workspace.root / attempt.evidence
            video = directory / VIDEO_FILE
            if not video.exists() and not (directory / FRAMES_FILE).exists():
                continue
            video.unlink(missing_ok=True)
            (directory / FRAMES_FILE).unlink(missing_ok=True)
            bundle_path = directory / "bundle.yaml"
            if bundle_path.is_file():
                try:
                    bundle = read_yaml(bundle_path, error=RecordingError) or {}
                except (OSError, RecordingError) as exc:
                    logger.warning("video dropped, bundle left as it is: %s", exc)
                    removed += 1
                    continue
                files = bundle.get("files", {})
                dropped = [files.pop(k) for k in ("video", "frames") if k in files]
                if dropped:
                    atomic_write_text(bundle_path, dump_yaml(bundle))
            removed += 1
    return removed


if __name__ == "__main__":
    raise SystemExit(_render_main())
