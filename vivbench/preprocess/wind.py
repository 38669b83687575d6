"""Wind: speed and direction, the component perpendicular to the span, and its slowly varying mean."""

from __future__ import annotations

import math

import numpy as np
from scipy import signal

from vivbench.core.errors import InputError
from vivbench.preprocess.config import PreprocessConfig
from vivbench.preprocess.runs import as_2d, check_time, run_rate, valid_runs

__all__ = ["wind_speed_direction", "perpendicular_speed", "mean_wind", "perpendicular_wind", "mean_wind_runs"]


def wind_speed_direction(u, v) -> tuple[np.ndarray, np.ndarray]:
    """Horizontal wind speed and meteorological direction.

    Parameters
    ----------
    u, v : array_like, same shape
        Eastward and northward wind components, m/s.

    Returns
    -------
    V : ndarray
        Horizontal speed sqrt(u^2 + v^2), m/s.
    theta : ndarray
        Direction the wind blows FROM, degrees clockwise from north, in
        [0, 360). A calm (V = 0) gets 0.
    """
    u = np.asarray(u, dtype=float)
    v = np.asarray(v, dtype=float)
    if u.shape != v.shape:
        raise ValueError(f"u and v must have the same shape; got {u.shape} and {v.shape}")
    V = np.hypot(u, v)
    # The wind comes from the direction opposite to its velocity vector (-u, -v).
    theta = np.mod(np.degrees(np.arctan2(-u, -v)), 360.0)
    # np.mod can round a tiny negative angle up to exactly 360.
    theta = np.where(theta >= 360.0, 0.0, theta)
    return V, theta


def perpendicular_speed(V, theta, span_azimuth_deg: float) -> np.ndarray:
    """Wind speed perpendicular to the span, U~ = V ``|sin(theta - span azimuth)|``.

    Parameters
    ----------
    V : array_like
        Horizontal wind speed, m/s.
    theta : array_like, broadcastable with ``V``
        Meteorological wind direction (from), degrees from north.
    span_azimuth_deg : float
        Direction of the span axis, degrees from north (a and a + 180 are the
        same span).

    Returns
    -------
    ndarray
        U~, m/s; equal to V when the wind blows across the span and 0 when
        it blows along it.
    """
    V = np.asarray(V, dtype=float)
    theta = np.asarray(theta, dtype=float)
    return V * np.abs(np.sin(np.radians(theta - float(span_azimuth_deg))))


def _lowpass(x: np.ndarray, fs: float, config: PreprocessConfig) -> np.ndarray:
    """Zero-phase Butterworth low-pass along axis 0 of a gap-free run."""
    if config.wind_cutoff_hz >= 0.5 * fs:
        raise InputError(
            f"wind_cutoff_hz = {config.wind_cutoff_hz} Hz must lie below the Nyquist frequency {0.5 * fs} Hz"
        )
    sos = signal.butter(config.wind_filter_order, config.wind_cutoff_hz, btype="low", fs=fs, output="sos")
    # Odd extension over one settling time continues the run's level and
    # slope; on synthetic turbulence it gave about half the end error of
    # mirror (even) extension, which forces a zero slope at the ends.
    padlen = min(x.shape[0] - 1, int(round(config.wind_settling_s * fs)))
    return signal.sosfiltfilt(sos, x, axis=0, padtype="odd", padlen=padlen)


def mean_wind(t, u, v, span_azimuth_deg: float, config: PreprocessConfig | None = None) -> np.ndarray:
    """Mean wind speed perpendicular to the span, U = low-pass(U~).

    Parameters
    ----------
    t : array_like, shape (n,)
        Sample times, s, strictly increasing (nominally 32 Hz).
    u, v : array_like, shape (n,) or (n, n_sections)
        Eastward and northward wind components, m/s; NaN marks missing data.
    span_azimuth_deg : float
        Direction of the span axis, degrees from north.
    config : PreprocessConfig, optional
        Uses ``wind_cutoff_hz``, ``wind_filter_order`` and ``max_gap_s``.

    Returns
    -------
    U : ndarray, shape of ``u``
        Low-passed U~, m/s. Each valid run is filtered on its own; times in
        gaps that are not bridged are NaN. Edges are NOT dropped here: the
        first and last ``config.wind_settling_s`` (or more) of each run
        carry filter transients.
    """
    config = PreprocessConfig() if config is None else config
    t = check_time(t, "t")
    U_tilde = perpendicular_wind(t, u, v, span_azimuth_deg)
    U, _ = mean_wind_runs(t, U_tilde, config)
    return U.reshape(np.shape(u))


def perpendicular_wind(t: np.ndarray, u, v, span_azimuth_deg: float) -> np.ndarray:
    u = np.asarray(u, dtype=float)
    v = np.asarray(v, dtype=float)
    if u.shape != v.shape or u.shape[0] != t.shape[0] or u.ndim > 2:
        raise ValueError(
            f"u and v must both have shape (n,) or (n, n_sections) with n = len(t) = {t.shape[0]}; "
            f"got {u.shape} and {v.shape}"
        )
    if not math.isfinite(float(span_azimuth_deg)):
        raise InputError(f"span_azimuth_deg must be finite; got {span_azimuth_deg!r}")
    V, theta = wind_speed_direction(u, v)
    return as_2d(perpendicular_speed(V, theta, span_azimuth_deg))


def mean_wind_runs(t: np.ndarray, U_tilde: np.ndarray, config: PreprocessConfig):
    """Low-pass each valid run of U~ (n, k); returns U (NaN in gaps) and the runs."""
    filled, starts, ends = valid_runs(t, U_tilde, config.max_gap_s)
    U = np.full_like(filled, np.nan)
    for i0, i1 in zip(starts, ends):
        if i1 - i0 < 2:
            continue
        U[i0:i1] = _lowpass(filled[i0:i1], run_rate(t, i0, i1), config)
    return U, (starts, ends)

