"""Gain of the frequency-domain integration's vibration band (shared by the displacement and the noise floor)."""

from __future__ import annotations


import numpy as np


__all__ = ["band_gain"]


def band_gain(f: np.ndarray, f_mode: float, half_width: float, taper: float) -> np.ndarray:
    """Gain 1 within (1 - taper) * half_width of f_mode, raised cosine to 0 at half_width."""
    d = np.abs(f - f_mode)
    flat = (1.0 - taper) * half_width
    x = np.clip((d - flat) / (taper * half_width), 0.0, 1.0)
    return 0.5 * (1.0 + np.cos(np.pi * x))

