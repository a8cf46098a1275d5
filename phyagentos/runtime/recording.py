"""Session recordings: ``evidence/<session>/video.mp4`` and the recorded state per frame.

With ``phyagentos run ... --record`` (or ``bench ... --record failures``) the SessionRunner
gives each session a :class:`SessionRecorder`. From its tick hook the recorder renders
the declared camera (default the target's ``overview`` camera) whenever ``1/fps`` seconds
of *simulated* time have passed since the last frame (targets without a simulation clock
use wall time), and copies the MuJoCo state (``qpos``) of that instant. Frames go through
a bounded queue to a background thread that pipes them to the ffmpeg binary shipped in
the ``imageio-ffmpeg`` wheel (H.264 in MP4; no system ffmpeg), so the runner only pays for
the render and a copy. :meth:`SessionRecorder.close` renders the terminal frame, joins
the encoder and writes ``frames.npz`` (``t`` (N,) simulated time in s, ``qpos`` (N, nq),
``wall`` (N,) seconds since the first frame); the runner lists both files in the bundle
before it is finalised. ``phyagentos view`` re-renders any recorded instant from
``frames.npz`` with a free camera.

Configuration travels from the CLI to the runner processes through the environment
variable ``PHYAGENTOS_RECORD`` (``off``, ``all`` or ``failures``, optionally followed by
``,camera=NAME,fps=F,width=W,height=H``), set before the forkserver starts, so
``phyagentos watch`` can record too. ``failures`` records every session and
:func:`prune_recordings` deletes the recordings of sessions whose verdict was success
once the verdicts are in (the runner cannot know the verdict: that is the verifier's).
"""

from __future__ import annotations

import logging
import os
import queue
import threading
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Mapping

import numpy as np

import yaml

from phyagentos.errors import RecordingError, TargetError
from phyagentos.protocol import dump_yaml
from phyagentos.protocol.atomic import atomic_write_text

__all__ = ["ENV_VAR", "RECORD_MODES", "RecordingConfig", "SessionRecorder", "prune_recordings"]

logger = logging.getLogger(__name__)

#: Environment variable carrying the recording configuration to runner processes.
ENV_VAR = "PHYAGENTOS_RECORD"
#: ``off``: no recording; ``all``: keep every session's; ``failures``: keep those whose verdict is not success.
RECORD_MODES = ("off", "all", "failures")
VIDEO_FILE = "video.mp4"
FRAMES_FILE = "frames.npz"


@dataclass(frozen=True)
class RecordingConfig:
    """What to record and how.

    Attributes:
        mode: one of :data:`RECORD_MODES`.
        camera: the target camera to render (MuJoCo camera name).
        fps: frames per second of simulated time (also the video's playback rate,
            so the video plays at real-time speed of the simulation).
        width, height: frame size in pixels (multiples of 16 for H.264).
    """

    mode: str = "off"
    camera: str = "overview"
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
        return f"{self.mode},camera={self.camera},fps={self.fps:g},width={self.width},height={self.height}"

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


class _Encoder(threading.Thread):
    """Pipes RGB frames to ffmpeg (imageio-ffmpeg's bundled binary) off the caller's thread."""

    def __init__(self, path: Path, cfg: RecordingConfig) -> None:
        super().__init__(name=f"recorder-{path.parent.name}", daemon=True)
        self.path = path
        self.cfg = cfg
        self.frames: queue.Queue = queue.Queue(maxsize=64)
        self.error: BaseException | None = None
        self.written = 0

    def run(self) -> None:
        import imageio_ffmpeg  # noqa: PLC0415 - only when recording

        writer = None
        try:
            writer = imageio_ffmpeg.write_frames(
                str(self.path), (self.cfg.width, self.cfg.height), fps=self.cfg.fps, codec="libx264",
                pix_fmt_out="yuv420p", macro_block_size=16, ffmpeg_log_level="error",
                output_params=["-movflags", "+faststart"])
            writer.send(None)
            while True:
                frame = self.frames.get()
                if frame is None:
                    break
                writer.send(frame.tobytes())
                self.written += 1
        except BaseException as exc:  # noqa: BLE001 - reported by close(); a video never fails a session
            self.error = exc
            while self.frames.get() is not None:  # drain so the producer never blocks
                pass
        finally:
            if writer is not None:
                try:
                    writer.close()
                except Exception as exc:  # noqa: BLE001
                    self.error = self.error or exc


class SessionRecorder:
    """Records one session of ``target`` into ``directory``.

    Args:
        target: the session's target; needs ``render(camera, width, height, shadows=)``
            and, for re-rendering in the view, a MuJoCo ``data`` attribute.
        directory: the session's evidence directory.
        config: the recording configuration (``mode`` must not be ``off``).

    Raises:
        RecordingError: the target cannot render (no ``render``).
        TargetError: the target lacks the camera or has no OpenGL backend.
    """

    def __init__(self, target: Any, directory: str | Path, config: RecordingConfig) -> None:
        if getattr(target, "render", None) is None:
            raise RecordingError(f"target {getattr(target, 'name', target)!r} cannot render; nothing to record")
        self.target = target
        self.directory = Path(directory)
        self.config = config
        self.period = 1.0 / config.fps
        self._next: float | None = None
        self._t: list[float] = []
        self._wall: list[float] = []
        self._qpos: list[np.ndarray] = []
        self._t0 = time.perf_counter()
        self.render_s = 0.0
        self.ticks = 0
        self._encoder = _Encoder(self.directory / VIDEO_FILE, config)
        self._encoder.start()
        self._closed = False
        self.capture()  # the first frame: the initial state, and it fails fast on a bad camera

    def _clock(self) -> float:
        t = getattr(self.target, "sim_time", None)
        return float(t) if t is not None else time.perf_counter() - self._t0

    def capture(self) -> None:
        """Render one frame now (and record its state), regardless of the rate."""
        started = time.perf_counter()
        c = self.config
        frame = self.target.render(c.camera, width=c.width, height=c.height, shadows=False)
        data = getattr(self.target, "data", None)
        self._qpos.append(np.array(data.qpos, dtype=np.float64) if data is not None else np.zeros(0))
        now = self._clock()
        # A tick may advance several frame periods of simulated time: the video repeats the
        # frame for each period it covers, so it plays at the simulation's real-time speed.
        slots = 1 if not self._t else max(1, round((now - self._t[-1]) * self.config.fps))
        self._t.append(now)
        self._wall.append(started - self._t0)
        self._next = now + self.period
        if self._encoder.is_alive():
            pixels = np.ascontiguousarray(frame, dtype=np.uint8)
            for _ in range(slots):
                self._encoder.frames.put(pixels)
        self.render_s += time.perf_counter() - started

    def tick(self) -> None:
        """Called after every tick: renders a frame when one is due (cheap otherwise)."""
        self.ticks += 1
        if self._closed or self._clock() < self._next:
            return
        try:
            self.capture()
        except (TargetError, OSError, ValueError) as exc:
            logger.warning("recording %s stopped: %s", self.directory.name, exc)
            self._closed = True

    def close(self) -> dict[str, str]:
        """Capture the terminal frame, finish the video and write ``frames.npz``.

        Returns the files written, for the bundle's ``files``: ``{"video": "video.mp4",
        "frames": "frames.npz"}`` (``video`` missing if encoding failed, which is logged).
        """
        if not self._closed and (not self._t or self._clock() > self._t[-1]):  # the terminal instant, if new
            try:
                self.capture()
            except (TargetError, OSError, ValueError) as exc:
                logger.warning("recording %s: no terminal frame: %s", self.directory.name, exc)
        self._closed = True
        self._encoder.frames.put(None)
        self._encoder.join()
        files: dict[str, str] = {}
        qpos = np.stack(self._qpos) if self._qpos and all(q.shape == self._qpos[0].shape for q in self._qpos) else np.zeros((0, 0))
        np.savez_compressed(self.directory / FRAMES_FILE, t=np.asarray(self._t), wall=np.asarray(self._wall), qpos=qpos,
                            camera=np.asarray(self.config.camera), fps=np.asarray(self.config.fps))
        files["frames"] = FRAMES_FILE
        if self._encoder.error is None and self._encoder.written:
            files["video"] = VIDEO_FILE
        else:
            logger.warning("recording %s: video not written: %s", self.directory.name, self._encoder.error)
        logger.info("recording %s: %d frames, render %.3f s over %d ticks", self.directory.name, len(self._t),
                    self.render_s, self.ticks)
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
                bundle = yaml.safe_load(bundle_path.read_text(encoding="utf-8")) or {}
                files = bundle.get("files", {})
                dropped = [files.pop(k) for k in ("video", "frames") if k in files]
                if dropped:
                    atomic_write_text(bundle_path, dump_yaml(bundle))
            removed += 1
    return removed
