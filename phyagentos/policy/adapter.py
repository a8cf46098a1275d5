"""PolicyAdapter: the observation contract -> a model's inputs, its outputs -> standard actions.

A skill declares what its policy expects (``skills/<name>.yaml``, ``policy.inputs``)::

    inputs:
      observation/joint_position: {source: joint_positions, dtype: float32, shape: [7]}
      observation/gripper_position: {source: gripper_opening, dtype: float32, shape: [1],
                                     convention: normalized_closed}
      observation/image: {source: rgb, dtype: uint8, shape: [224, 224, 3], camera: overview}
      prompt: {source: instruction}

Each key is built from one source of :data:`~phyagentos.policy.observation.SOURCES`,
cast to ``dtype`` and checked against ``shape``. An ``rgb`` input may also name how the
camera frame becomes the model's image, as openpi's LIBERO example prepares it::

      observation/image: {source: rgb, dtype: uint8, shape: [224, 224, 3], camera: agentview,
                          render: [256, 256], orientation: robosuite_rot180, resize: pad}

``render``: the camera's resolution (default ``shape[:2]``); ``orientation``: ``upright``
(row 0 at the top, the default), ``robosuite`` (robosuite's OpenGL order: upside down) or
``robosuite_rot180`` (robosuite's image turned 180 degrees, both axes flipped: openpi's
LIBERO example and its training data); ``resize: pad``: openpi-client's
``image_tools.resize_with_pad`` (aspect kept, PIL bilinear, zero padding, centred). The model's answer must carry
``"actions"``: an ``(H, D)`` array (one row per step; a ``(D,)`` single action is
accepted as ``H = 1``) at the declared action spec's rate. Its width and values are
not judged here: the action bridges check the layout and the SafetyGuard the values.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

import mujoco
import numpy as np

from phyagentos.errors import PolicyError, format_choices

from .observation import SOURCES, Observation

__all__ = ["InputSpec", "PolicyAdapter", "ADAPTERS", "ORIENTATIONS", "resize_with_pad", "orient"]

_DTYPES = ("float32", "float64", "uint8", "int32", "int64")
_GRIPPER = ("opening_m", "normalized_closed", "normalized_open")
#: Image orientations an rgb input may ask for (see the module docstring).
ORIENTATIONS = ("upright", "robosuite", "robosuite_rot180")
_RESIZE = ("pad",)


def orient(img: np.ndarray, orientation: str) -> np.ndarray:
    """An upright image (row 0 at the top) in ``orientation`` (:data:`ORIENTATIONS`).

    robosuite's raw frame is the upright one flipped vertically; turning that by 180
    degrees flips both axes, which leaves the upright frame mirrored left-right.
    """
    if orientation == "upright":
        return img
    if orientation == "robosuite":
        return np.ascontiguousarray(img[::-1])
    if orientation == "robosuite_rot180":
        return np.ascontiguousarray(img[::-1][::-1, ::-1])
    raise ValueError(f"unknown orientation {orientation!r}; valid: {format_choices(ORIENTATIONS)}")


def resize_with_pad(img: np.ndarray, height: int, width: int) -> np.ndarray:
    """openpi-client's ``image_tools.resize_with_pad`` for one ``(H, W, C)`` uint8 image:
    unchanged when already ``height x width``; else scaled by ``1 / max(W / width, H / height)``
    (sizes truncated to integers) with PIL's bilinear filter and pasted at
    ``(int((width - w') / 2), int((height - h') / 2))`` on a zero image."""
    from PIL import Image  # noqa: PLC0415

    h0, w0 = img.shape[:2]
    if (h0, w0) == (height, width):
        return img
    ratio = max(w0 / width, h0 / height)
    h1, w1 = int(h0 / ratio), int(w0 / ratio)
    small = Image.fromarray(img).resize((w1, h1), resample=Image.BILINEAR)
    canvas = Image.new(small.mode, (width, height), 0)
    canvas.paste(small, (max(0, int((width - w1) / 2)), max(0, int((height - h1) / 2))))
    return np.asarray(canvas)


@dataclass(frozen=True)
class InputSpec:
    """One model input: ``key`` built from ``source`` with ``dtype`` and ``shape``.

    ``convention`` applies to ``gripper_opening`` (default ``opening_m``); ``camera``
    to ``rgb`` / ``depth``; ``length`` (history steps) is ``shape[0]`` for
    ``history_joint_positions``.
    """

    key: str
    source: str
    dtype: str | None = None
    shape: tuple[int, ...] | None = None
    convention: str | None = None
    camera: str = "overview"
    render: tuple[int, int] | None = None
    orientation: str = "upright"
    resize: str | None = None

    @classmethod
    def from_dict(cls, key: str, d: Mapping[str, Any]) -> "InputSpec":
        """Raises ValueError naming the key and the valid choices."""
        known = {"source", "dtype", "shape", "convention", "camera", "render", "orientation", "resize"}
        if not isinstance(d, Mapping) or set(d) - known:
            raise ValueError(f"input {key!r}: expected a mapping with keys {format_choices(known)}, got {d!r}")
        source = d.get("source")
        if source not in SOURCES:
            raise ValueError(f"input {key!r}: unknown source {source!r}; valid: {format_choices(SOURCES)}")
        dtype = d.get("dtype")
        if source != "instruction" and dtype not in _DTYPES:
            raise ValueError(f"input {key!r}: dtype {dtype!r} is not one of {format_choices(_DTYPES)}")
        shape = d.get("shape")
        if source != "instruction":
            if not isinstance(shape, (list, tuple)) or not all(isinstance(s, int) and s > 0 for s in shape):
                raise ValueError(f"input {key!r}: shape must be a list of positive integers, got {shape!r}")
            shape = tuple(shape)
        conv = d.get("convention")
        if source == "gripper_opening":
            conv = conv or "opening_m"
            if conv not in _GRIPPER:
                raise ValueError(f"input {key!r}: gripper convention {conv!r} is not one of {format_choices(_GRIPPER)}")
        render = d.get("render")
        if render is not None:
            if not (isinstance(render, (list, tuple)) and len(render) == 2
                    and all(isinstance(v, int) and v > 0 for v in render)):
                raise ValueError(f"input {key!r}: render must be [height, width] in pixels, got {render!r}")
            render = (int(render[0]), int(render[1]))
        orientation = str(d.get("orientation", "upright"))
        if orientation not in ORIENTATIONS:
            raise ValueError(f"input {key!r}: orientation {orientation!r} is not one of {format_choices(ORIENTATIONS)}")
        resize = d.get("resize")
        if resize is not None and resize not in _RESIZE:
            raise ValueError(f"input {key!r}: resize {resize!r} is not one of {format_choices(_RESIZE)}")
        if (render is not None or orientation != "upright" or resize is not None) and source != "rgb":
            raise ValueError(f"input {key!r}: render, orientation and resize apply to source rgb, not {source}")
        return cls(key=key, source=source, dtype=dtype, shape=shape, convention=conv, camera=str(d.get("camera", "overview")),
                   render=render, orientation=orientation, resize=resize)

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"source": self.source}
        if self.dtype:
            d["dtype"] = self.dtype
        if self.shape:
            d["shape"] = list(self.shape)
        if self.convention:
            d["convention"] = self.convention
        if self.source in ("rgb", "depth"):
            d["camera"] = self.camera
        if self.render is not None:
            d["render"] = list(self.render)
        if self.orientation != "upright":
            d["orientation"] = self.orientation
        if self.resize is not None:
            d["resize"] = self.resize
        return d

    @property
    def expected_shape(self) -> tuple[int, ...] | None:
        """The shape the source produces natively (``None``: any, checked at encode time)."""
        return {"joint_positions": (7,), "joint_velocities": (7,), "gripper_opening": (1,), "object_pose": (7,),
                "object_half_extents": (3,), "eef_state": (8,)}.get(self.source)

    @property
    def render_size(self) -> tuple[int, int] | None:
        """``(height, width)`` the camera renders at (images only)."""
        if self.source not in ("rgb", "depth"):
            return None
        return self.render if self.render is not None else (self.shape[0], self.shape[1])


class PolicyAdapter:
    """Builds model inputs from :class:`Observation` and reads the model's actions.

    Args:
        inputs: the declared inputs.
        max_opening_m: full gripper opening per finger (for normalised conventions).
    """

    name = "openpi"

    def __init__(self, inputs: Mapping[str, InputSpec], *, max_opening_m: float = 0.04):
        self.inputs = dict(inputs)
        self.max_opening_m = float(max_opening_m)

    @classmethod
    def from_declaration(cls, decl: Mapping[str, Any], **kw: Any) -> "PolicyAdapter":
        return cls({k: InputSpec.from_dict(k, v) for k, v in decl.items()}, **kw)

    def modalities(self) -> set[str]:
        """Target observation modalities the inputs need."""
        return {m for s in self.inputs.values() if (m := SOURCES[s.source]) is not None}

    def problems(self) -> list[tuple[str, str, str]]:
        """Declaration problems ``(key, expected, found)``: shapes a source cannot produce."""
        out = []
        for s in self.inputs.values():
            want = s.expected_shape
            if want is not None and s.shape != want:
                out.append((s.key, f"shape {list(want)} from source {s.source}", f"shape {list(s.shape or ())}"))
            if s.source == "rgb" and (len(s.shape) != 3 or s.shape[2] != 3 or s.dtype != "uint8"):
                out.append((s.key, "uint8 [H, W, 3] from source rgb", f"{s.dtype} {list(s.shape)}"))
            if s.source == "depth" and (len(s.shape) != 2 or s.dtype not in ("float32", "float64")):
                out.append((s.key, "float32 [H, W] from source depth", f"{s.dtype} {list(s.shape)}"))
            if s.source == "history_joint_positions" and (len(s.shape) != 2 or s.shape[1] != 7):
                out.append((s.key, "[k, 7] from source history_joint_positions", f"{list(s.shape)}"))
            if s.source == "rgb" and s.render is not None and s.render != tuple(s.shape[:2]) and s.resize is None:
                out.append((s.key, f"resize: pad to turn the {list(s.render)} render into {list(s.shape[:2])}",
                            "no resize"))
        seen: dict[tuple[str, str], tuple[int, int]] = {}
        for s in self.inputs.values():
            if s.source in ("rgb", "depth"):
                size = seen.setdefault((s.source, s.camera), s.render_size)
                if size != s.render_size:
                    out.append((s.key, f"one render size per camera ({s.camera}: {list(size)})", f"{list(s.render_size)}"))
        return out

    def cameras(self) -> dict[tuple[str, str], tuple[int, int]]:
        """Images to render: ``(source, camera)`` -> ``(height, width)``."""
        return {(s.source, s.camera): s.render_size for s in self.inputs.values() if s.source in ("rgb", "depth")}

    def needs_eef_state(self) -> bool:
        """Whether an input is built from the end-effector state (``osc_proprio()``)."""
        return any(s.source == "eef_state" for s in self.inputs.values())

    def _gripper(self, opening_m: float, conv: str) -> float:
        closed = 1.0 - opening_m / self.max_opening_m
        return {"opening_m": opening_m, "normalized_closed": closed, "normalized_open": 1.0 - closed}[conv]

    def encode(self, obs: Observation) -> dict[str, Any]:
        """Model inputs for ``obs``.

        Raises:
            PolicyError: ``policy.observation``: a source the observation lacks (no
                focus object, image not rendered) or a shape that does not match.
        """
        out: dict[str, Any] = {}
        for s in self.inputs.values():
            if s.source == "instruction":
                out[s.key] = obs.instruction
                continue
            v = self._source(obs, s)
            arr = np.asarray(v).astype(s.dtype, copy=False)
            if arr.shape != s.shape:
                raise PolicyError(f"input {s.key!r}: source {s.source} gave shape {arr.shape}, declared {s.shape}",
                                  code="policy.observation")
            out[s.key] = arr
        return out

    def _source(self, obs: Observation, s: InputSpec):
        src = s.source
        if src == "joint_positions":
            return obs.joint_positions
        if src == "joint_velocities":
            return obs.joint_velocities
        if src == "gripper_opening":
            return [self._gripper(obs.gripper_opening_m, s.convention or "opening_m")]
        if src in ("object_pose", "object_half_extents"):
            if obs.focus is None or obs.focus not in obs.objects:
                raise PolicyError(f"input {s.key!r} needs the session's object, but the observation has "
                                  f"{obs.focus!r} among {format_choices(obs.objects)}", code="policy.observation")
            o = obs.objects[obs.focus]
            if src == "object_half_extents":
                return o.half_extents
            quat = np.empty(4)
            mujoco.mju_mat2Quat(quat, np.ascontiguousarray(o.pose[:3, :3]).reshape(-1))
            return np.concatenate([o.pose[:3, 3], quat])
        if src in ("rgb", "depth"):
            img = obs.images.get((src, s.camera))
            if img is None:
                img = obs.rgb if src == "rgb" else obs.depth
            if img is None:
                raise PolicyError(f"input {s.key!r} needs a {src} image, none was rendered", code="policy.observation")
            if src == "rgb":
                img = orient(np.asarray(img), s.orientation)
                if s.resize == "pad":
                    img = resize_with_pad(img, s.shape[0], s.shape[1])
            return img
        if src == "eef_state":
            if obs.eef_state is None:
                raise PolicyError(f"input {s.key!r} needs the end-effector state, which this target does not report "
                                  "(no osc_proprio())", code="policy.observation")
            return obs.eef_state
        if src == "history_joint_positions":
            k = s.shape[0]
            past = [h.joint_positions for h in obs.history[-k:]] or [obs.joint_positions]
            return np.array([past[0]] * (k - len(past)) + past)
        raise PolicyError(f"unknown source {src!r}", code="policy.observation")  # pragma: no cover

    def decode(self, response: Mapping[str, Any]) -> np.ndarray:
        """The ``"actions"`` array of a model response as ``(H, D)`` (dtype unchanged).

        Raises:
            PolicyError: ``policy.malformed``: no ``actions`` key, not an array, or not 1-D/2-D.
        """
        if "actions" not in response:
            raise PolicyError(f"policy response has no 'actions' (keys: {format_choices(response)})", code="policy.malformed")
        a = response["actions"]
        if not isinstance(a, np.ndarray):
            raise PolicyError(f"policy 'actions' is a {type(a).__name__}, not an array", code="policy.malformed")
        if a.ndim == 1:
            a = a[None, :]
        if a.ndim != 2 or a.shape[0] < 1:
            raise PolicyError(f"policy 'actions' must be (H, D) or (D,), got {a.shape}", code="policy.malformed")
        return a


#: Policy adapter name (skill manifests, ``policy.adapter``) -> class.
ADAPTERS: dict[str, type[PolicyAdapter]] = {"openpi": PolicyAdapter}
