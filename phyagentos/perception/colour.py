"""Colour: sRGB to CIELAB (D65) and perceptual distances.

Conversion by OpenCV (``cv2.cvtColor`` with ``COLOR_RGB2Lab`` on float32 input in [0, 1],
which applies the sRGB transfer curve and returns L* in [0, 100], a*, b* in about
[-127, 127]; CIE 15:2004).
"""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["srgb_to_lab", "lab_distance"]


def srgb_to_lab(rgb: np.ndarray) -> np.ndarray:
    """(N, 3) CIELAB of (N, 3) sRGB colours (uint8 0..255, or floats in 0..1)."""
    a = np.asarray(rgb)
    f = a.astype(np.float32) / 255.0 if a.dtype == np.uint8 else a.astype(np.float32)
    if f.shape[0] == 0:
        return np.zeros((0, 3), np.float32)
    return cv2.cvtColor(f.reshape(-1, 1, 3), cv2.COLOR_RGB2Lab).reshape(-1, 3)


def lab_distance(lab1: np.ndarray, lab2: np.ndarray, *, lightness_weight: float = 1.0) -> np.ndarray:
    """Delta E*ab (CIE 1976) between broadcastable (..., 3) Lab arrays, with Delta L* scaled
    by ``lightness_weight`` (< 1 discounts shading, which changes mostly L*)."""
    d = np.asarray(lab1, float) - np.asarray(lab2, float)
    return np.sqrt((lightness_weight * d[..., 0]) ** 2 + d[..., 1] ** 2 + d[..., 2] ** 2)
