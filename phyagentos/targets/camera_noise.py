"""Seeded noise of a simulated camera (a property of the camera, not of perception).

Per episode one brightness gain ``g ~ 1 + N(0, lighting_jitter)`` (clipped to [0.6, 1.4])
models lighting variation; per frame, RGB gets ``N(0, rgb_sigma)`` counts per pixel and
channel, and depth ``z`` (metres, 0 = no return) gets ``N(0, (k z^2)^2)`` with
``k = depth_sigma_per_m2`` (the axial error of structured-light and stereo depth grows with
z^2: Khoshelham & Elberink 2012, Sensors 12(2)). The generator comes from the episode seed.
"""

from __future__ import annotations

import numpy as np

__all__ = ["CameraNoise"]


class CameraNoise:
    """Applies one camera's noise; ``spec`` has ``rgb_sigma``, ``depth_sigma_per_m2`` and
    ``lighting_jitter`` (:class:`phyagentos.protocol.sensors.CameraNoiseSpec`)."""

    def __init__(self, spec, rng: np.random.Generator):
        self._spec = spec
        self._rng = rng
        self.gain = float(np.clip(1.0 + spec.lighting_jitter * rng.standard_normal(), 0.6, 1.4))

    def apply(self, rgb: np.ndarray, depth: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
        """``rgb`` (H, W, 3) uint8 and ``depth`` (H, W) float32 m -> noisy copies (same types)."""
        s = self._spec
        if s.rgb_sigma > 0 or self.gain != 1.0:
            x = rgb.astype(np.float32) * self.gain
            if s.rgb_sigma > 0:
                x += self._rng.normal(0.0, s.rgb_sigma, size=x.shape).astype(np.float32)
            rgb = np.clip(x, 0.0, 255.0).astype(np.uint8)
        if depth is not None and s.depth_sigma_per_m2 > 0:
            valid = depth > 0
            noise = self._rng.standard_normal(size=depth.shape).astype(np.float32)
            depth = np.where(valid, np.maximum(depth + noise * (s.depth_sigma_per_m2 * depth * depth), 1e-3), 0.0)
            depth = depth.astype(np.float32)
        return rgb, depth
