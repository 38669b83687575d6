"""The error of a section's mean wind taken from an anemometer some distance along the span.

When a monitoring system has fewer anemometers than acceleration sections, the
wind of a section is that of an anemometer elsewhere on the span (field import's
rule, ``wind_distance_m_<section>`` in the event). The deck there feels its own
wind, which differs from the anemometer's by the turbulence that is not coherent
over the distance. For a wind record low-passed and smoothed in time the rms of
that difference is

    sigma_e^2(U, d) = 2 int_0^inf S_u(f) |H(f)|^2 (1 - exp(-C_u f d / U)) df        (m^2/s^2)

with

- S_u(f) = (I_u U)^2 (4 L_u / U) / (1 + 6 f L_u / U)^(5/3), the one-sided Kaimal
  (:func:`vivbench.core.wind_spectra.kaimal_psd`)
  spectrum of the along-wind turbulence (m^2/s^2 per Hz; its integral is
  (I_u U)^2), I_u the turbulence intensity, L_u its integral length (m);
- exp(-C_u f d / U), the Davenport coherence of two points d metres apart
  (:func:`vivbench.core.wind_spectra.davenport_coherence`)
  (C_u its decay constant), so that 2 S_u (1 - coherence) is the spectrum of
  the difference of the two points' winds;
- H(f) = exp(-2 pi^2 f^2 s^2) / (1 + (f / f_c)^(2 N)), the Gaussian smoothing of
  standard deviation s seconds times the identification's zero-phase
  Butterworth low-pass (order N, cutoff f_c Hz, applied forwards and
  backwards, so its gain is the Butterworth's squared);
- U (m/s) the mean wind speed and d (m) the distance to the anemometer.

sigma_e = 0 at d = 0. The priors (:data:`UNMEASURED_WIND_PRIORS`) are stated
values for a deck over open water (turbulence intensity 0.10, the upper middle
of the 0.05-0.12 seen over sea; Kaimal length 8.1 x 42 m, IEC 61400-1 above
60 m height; Davenport decay 10 for the along-wind component along a
horizontal line): one anemometer cannot measure the spanwise coherence of its
own wind. The integral is evaluated on a logarithmic frequency grid; many wind
speeds are evaluated on a grid of speeds and interpolated.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from vivbench.core.errors import InputError
from vivbench.core.record import Record
from vivbench.core.wind_spectra import kaimal_psd

__all__ = ["UNMEASURED_WIND_PRIORS", "unmeasured_wind_error", "unmeasured_wind_rms", "shifted_unmeasured_wind"]

#: Stated priors of :func:`unmeasured_wind_error`: turbulence intensity I_u (-), Kaimal integral length
#: L_u (m) and Davenport decay constant C_u (-) of the along-wind turbulence.
UNMEASURED_WIND_PRIORS = {"intensity": 0.10, "kaimal_length_m": 8.1 * 42.0, "coherence_decay": 10.0}

# Frequency grid of the integral, Hz: far below any event's duration to far above the smoothing.
_F = np.logspace(-6.0, 1.0, 1401)
# Wind speeds tabulated when more than this many are asked for.
_TABLE_AT = 64


def _variance(U: np.ndarray, d: float, smoothing_s: float, cutoff_hz: float, order: int, priors: dict) -> np.ndarray:
    """sigma_e^2 (module docstring) at each speed of ``U`` (1-D, > 0), m^2/s^2."""
    f = _F[None, :]
    Uc = U[:, None]
    S = kaimal_psd(f, Uc, priors["intensity"] * Uc, priors["kaimal_length_m"])
    gain = np.exp(-2.0 * math.pi**2 * f**2 * smoothing_s**2) / (1.0 + (f / cutoff_hz) ** (2 * order))
    # 1 - davenport_coherence(f, d, U, C), as expm1 for its accuracy at low f d / U
    integrand = 2.0 * S * gain**2 * -np.expm1(-priors["coherence_decay"] * f * d / Uc)
    # d f = f d(ln f): the trapezoidal rule on the logarithmic grid
    return np.trapezoid(integrand * f, np.log(_F), axis=1)


def unmeasured_wind_error(U, distance_m: float, smoothing_s: float = 0.0, *, cutoff_hz: float = 1.0 / 60.0,
                          filter_order: int = 4, priors: dict | None = None) -> np.ndarray:
    """The rms error of a section's smoothed mean wind taken from an anemometer ``distance_m`` away.

    Parameters
    ----------
    U : array_like, m/s
        Mean wind speeds (any shape; NaN and values <= 0 give NaN).
    distance_m : float, m
        Distance from the section to the anemometer, >= 0 (0: measured there, error 0).
    smoothing_s : float, s
        Standard deviation of the Gaussian smoothing in time of the wind (0: none).
    cutoff_hz : float, Hz
        Cutoff of the identification's mean-wind low-pass (its default 1/60 Hz).
    filter_order : int
        Order of that Butterworth low-pass (default 4).
    priors : dict or None
        Overrides of :data:`UNMEASURED_WIND_PRIORS` (``intensity``, ``kaimal_length_m``, ``coherence_decay``).

    Returns
    -------
    ndarray, shape of ``U``, m/s
        sigma_e of the module docstring at each speed.
    """
    d = float(distance_m)
    if not (math.isfinite(d) and d >= 0):
        raise InputError(f"the distance to the anemometer must be a finite number of metres >= 0; got {distance_m!r}")
    if not (math.isfinite(smoothing_s) and smoothing_s >= 0):
        raise InputError(f"the wind smoothing must be a number of seconds >= 0; got {smoothing_s!r}")
    if not (math.isfinite(cutoff_hz) and cutoff_hz > 0):
        raise InputError(f"cutoff_hz must be a positive frequency (Hz); got {cutoff_hz!r}")
    unknown = set(priors or {}) - set(UNMEASURED_WIND_PRIORS)
    if unknown:
        raise InputError(f"unknown priors {sorted(unknown)}; allowed: {', '.join(UNMEASURED_WIND_PRIORS)}")
    p = {**UNMEASURED_WIND_PRIORS, **(priors or {})}
    if not all(math.isfinite(v) and v >= 0 for v in p.values()) or p["kaimal_length_m"] <= 0:
        raise InputError(f"the priors must be finite numbers >= 0 (a positive length); got {p}")
    U = np.asarray(U, dtype=float)
    out = np.full(U.shape, np.nan)
    ok = np.isfinite(U) & (U > 0)
    if d == 0.0:
        out[ok] = 0.0
        return out
    u = U[ok]
    if u.size > _TABLE_AT:
        grid = np.linspace(u.min(), u.max(), _TABLE_AT) if u.max() > u.min() else u[:1]
        var = np.interp(u, grid, _variance(grid, d, smoothing_s, cutoff_hz, filter_order, p))
    else:
        var = _variance(u, d, smoothing_s, cutoff_hz, filter_order, p)
    out[ok] = np.sqrt(np.maximum(var, 0.0))
    return out


def unmeasured_wind_rms(record: Record, smoothing_s: float) -> np.ndarray | None:
    """The rms over the record of :func:`unmeasured_wind_error` of each section, shape (S,), m/s.

    None when the record has no distance > 0; 0 for sections measured there (or without finite wind).
    """
    if record.wind_distance is None or not np.any(record.wind_distance > 0):
        return None
    e = _record_errors(record, smoothing_s)
    ok = np.isfinite(e)
    return np.sqrt((np.where(ok, e, 0.0) ** 2).sum(axis=0) / np.maximum(ok.sum(axis=0), 1))


def shifted_unmeasured_wind(record: Record, smoothing_s: float, z: float) -> Record | None:
    """``record`` with each section's U shifted by ``z`` times its :func:`unmeasured_wind_error`, m/s.

    Every section whose wind was taken from an anemometer elsewhere (``Record.wind_distance`` > 0)
    moves at once, by z sigma_e at its own wind (``smoothing_s`` the smoothing the wind is used at);
    the others stay. None when the record has no distance > 0.
    """
    if record.wind_distance is None or not np.any(record.wind_distance > 0):
        return None
    e = _record_errors(record, smoothing_s)
    return dataclasses.replace(record, U=record.U + float(z) * np.nan_to_num(e))


def _record_errors(record: Record, smoothing_s: float) -> np.ndarray:
    """(n, S) errors of one record's sections (0 at distance 0 or none; NaN where U is not finite)."""
    e = np.zeros(record.U.shape)
    if record.wind_distance is not None:
        for k, d in enumerate(record.wind_distance):
            if d > 0:
                e[:, k] = unmeasured_wind_error(record.U[:, k], float(d), smoothing_s)
    return e
