"""The mean wind's yaw: its angle to the span's normal, from the anemometers' horizontal components.

The realistic aerodynamics (docs/concepts.md (aeroelastic force), 2.8) fall off as the wind turns away
from the span's normal; U = V |sin theta| carries only the perpendicular speed,
not that angle. The components along and across the span are low-passed with
the mean-wind filter (so the angle is that of the slowly varying mean wind,
not of the turbulence), then psi = atan(along / |across|).
"""

from __future__ import annotations

import math

import numpy as np

from vivbench.core.errors import InputError
from vivbench.preprocess.config import PreprocessConfig
from vivbench.preprocess.runs import as_2d, check_time
from vivbench.preprocess.wind import mean_wind_runs

__all__ = ["event_yaw", "mean_yaw"]


def mean_yaw(t, u, v, span_azimuth_deg: float, config: PreprocessConfig | None = None) -> np.ndarray:
    """Yaw of the low-passed mean wind, degrees in [-90, 90] (0: perpendicular to the span).

    Parameters
    ----------
    t : array_like, shape (n,), s, strictly increasing
    u, v : array_like, shape (n,) or (n, S), m/s
        Eastward and northward components; NaN marks missing data.
    span_azimuth_deg : float
        Direction of the span axis, degrees from north.
    config : PreprocessConfig, optional
        The mean-wind filter (``wind_cutoff_hz``, ``wind_filter_order``, ``max_gap_s``).

    Returns
    -------
    ndarray, shape (n, S), degrees
        Signed angle between the mean wind and the span's normal (NaN in gaps).
    """
    config = PreprocessConfig() if config is None else config
    t = check_time(t, "t")
    u, v = as_2d(np.asarray(u, dtype=float)), as_2d(np.asarray(v, dtype=float))
    if u.shape != v.shape or u.shape[0] != t.size:
        raise ValueError(f"u and v must have the same shape (n, S) with n = len(t) = {t.size}; got {u.shape}, {v.shape}")
    if not math.isfinite(float(span_azimuth_deg)):
        raise InputError(f"span_azimuth_deg must be finite; got {span_azimuth_deg!r}")
    a = math.radians(float(span_azimuth_deg))
    along = u * math.sin(a) + v * math.cos(a)   # component along the span axis
    across = u * math.cos(a) - v * math.sin(a)  # perpendicular to it (horizontal)
    both, _ = mean_wind_runs(t, np.concatenate([along, across], axis=1), config)
    S = u.shape[1]
    return np.degrees(np.arctan2(both[:, :S], np.abs(both[:, S:])))


def event_yaw(t_wind, u, v, span_azimuth_deg: float, t_out, config: PreprocessConfig | None = None) -> np.ndarray:
    """The low-passed mean wind's yaw (:func:`mean_yaw`) at times ``t_out``.

    Parameters
    ----------
    t_wind : ndarray, shape (n,), s; u, v : ndarray, shape (n, S), m/s (east, north)
    span_azimuth_deg : float, degrees from north
    t_out : ndarray, shape (m,), s (e.g. the identification's preprocessing grid)
    config : PreprocessConfig, optional (the mean-wind filter)

    Returns
    -------
    ndarray, shape (m, S), degrees (NaN outside the wind record or in its gaps)
    """
    yaw = mean_yaw(t_wind, u, v, span_azimuth_deg, config)
    t_out = np.asarray(t_out, dtype=float)
    return np.stack([np.interp(t_out, np.asarray(t_wind, dtype=float), yaw[:, k], left=np.nan, right=np.nan)
                     for k in range(yaw.shape[1])], axis=1)
