"""Sampling rates of field records: plausibility, declared rates, and resampling to the event grid.

Monitoring systems record wind at 1-50 Hz and acceleration at 20-1000 Hz; the
event format's grid is 32 Hz for wind and 50 Hz for acceleration
(:data:`vivbench.io.NOMINAL_RATES`). A record whose rate differs from the
nominal one is resampled with an anti-aliasing polyphase filter
(:func:`scipy.signal.resample_poly`, the ratio approximated by a fraction
up/down) and then interpolated linearly onto the grid's exact instants.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
from scipy.signal import resample_poly

from vivbench.core.errors import InputError

__all__ = ["PLAUSIBLE_RATES", "FIELD_RATE_TOLERANCE", "measured_rate", "regular_grid", "resample_to_grid"]

#: Sampling rates (Hz) field systems record at, per sensor group; others are refused.
PLAUSIBLE_RATES = {"wind": (1.0, 50.0), "accel": (20.0, 1000.0)}
#: Relative tolerance of a rate against a declared rate, of the plausible range's ends, and under
#: which a record counts as already on the nominal grid (kept as it is, not resampled).
FIELD_RATE_TOLERANCE = 0.01
# Largest denominator of the fraction up/down: polyphase filters stay short (at most 64 phases)
# and the remaining mismatch of rates (below 1/64^2 relative) is taken up by the interpolation.
_MAX_DENOMINATOR = 64
# Time stamps may stray from a regular clock by up to this fraction of a step (jitter).
_MAX_JITTER = 0.25


def measured_rate(t: np.ndarray, name: str, group: str, declared: float | None = None) -> float:
    """Sampling rate of a record from its time stamps' median step, checked.

    Parameters
    ----------
    t : numpy.ndarray, shape (n,)
        Time stamps, s, increasing.
    name : str
        The source file, named in errors.
    group : {"wind", "accel"}
    declared : float, optional
        The rate (Hz) the mapping declares for the record.

    Returns
    -------
    float
        The rate, Hz (``1 / median step``).

    Raises
    ------
    InputError
        One line naming the file: fewer than 2 stamps, a declared rate that the
        median step contradicts by more than 1 %, or a rate outside the
        plausible range of the group (:data:`PLAUSIBLE_RATES`, 1 % tolerance).
    """
    if t.size < 2:
        raise InputError(f"{name}: {t.size} distinct time(s); at least 2 needed")
    step = float(np.median(np.diff(t)))
    rate = 1.0 / step
    if declared is not None and abs(rate / declared - 1.0) > FIELD_RATE_TOLERANCE:
        raise InputError(
            f"{name}: the mapping declares rate = {declared:g} Hz but the time stamps step every {step:.6g} s "
            f"(median), i.e. {rate:.6g} Hz; fix the rate or the time column"
        )
    lo, hi = PLAUSIBLE_RATES[group]
    if not lo * (1.0 - FIELD_RATE_TOLERANCE) <= rate <= hi * (1.0 + FIELD_RATE_TOLERANCE):
        raise InputError(
            f"{name}: sampling rate {rate:.4g} Hz (median step) is outside the {lo:g}-{hi:g} Hz of {group} "
            f"records; check the time column and its format"
        )
    return rate


def regular_grid(first: float, last: float, rate: float) -> np.ndarray:
    """Instants ``first + k / rate`` from ``first`` up to ``last`` (inclusive to 1e-9 of a step), s."""
    n = int(np.floor((last - first) * rate + 1e-9)) + 1
    return first + np.arange(n) / rate


def resample_to_grid(t: np.ndarray, values: np.ndarray, rate: float, grid: np.ndarray, name: str) -> np.ndarray:
    """Resample one channel recorded at ``rate`` onto the regular instants ``grid``, with anti-aliasing.

    The samples are placed on their own regular clock (the number of steps
    between stamps rounded, so the clock does not drift over a long record),
    gaps filled linearly for the filter, resampled by
    :func:`scipy.signal.resample_poly` (its Kaiser-window low-pass cuts at the
    lower of the two Nyquist frequencies) and interpolated linearly onto
    ``grid``. A grid instant within half a grid step of a missing source
    sample, or outside the record, is NaN.

    Parameters
    ----------
    t : numpy.ndarray, shape (n,)
        Time stamps, s, strictly increasing.
    values : numpy.ndarray, shape (n,)
        The channel (NaN where missing).
    rate : float
        The record's sampling rate, Hz.
    grid : numpy.ndarray, shape (m,)
        Target instants, s, regular.
    name : str
        The source file, named in errors.

    Returns
    -------
    numpy.ndarray, shape (m,)

    Raises
    ------
    InputError
        When the stamps stray from a regular clock by more than a quarter step.
    """
    slots = np.concatenate(([0], np.cumsum(np.rint(np.diff(t) * rate).astype(np.int64))))
    span = float(t[-1] - t[0])
    clock = slots[-1] / span if span > 0 else rate
    stray = np.abs(t - (t[0] + slots / clock)) * clock
    if stray.max() > _MAX_JITTER:
        i = int(np.argmax(stray))
        raise InputError(
            f"{name}: the time stamp {float(t[i]):.6g} s after start is {stray[i]:.2f} steps away from a regular {rate:.4g} Hz clock "
            f"(at most {_MAX_JITTER:g} allowed); the file needs one regular sample clock"
        )
    x = np.full(slots[-1] + 1, np.nan)
    x[slots] = values
    missing = ~np.isfinite(x)
    src_t = t[0] + np.arange(x.size) / clock
    out = np.full(grid.size, np.nan)
    if missing.sum() > x.size - 2:
        return out
    if missing.any():
        x[missing] = np.interp(src_t[missing], src_t[~missing], x[~missing])
    target = 1.0 / float(grid[1] - grid[0]) if grid.size > 1 else clock
    ratio = Fraction(target / clock).limit_denominator(_MAX_DENOMINATOR)
    y = resample_poly(x, ratio.numerator, ratio.denominator, padtype="line")
    y_t = t[0] + np.arange(y.size) * ratio.denominator / (ratio.numerator * clock)
    inside = (grid >= t[0] - 1e-9) & (grid <= t[-1] + 1e-9)
    out[inside] = np.interp(grid[inside], y_t, y)
    if missing.any():
        # Missing source samples within half a grid step of each grid instant.
        counts = np.concatenate(([0], np.cumsum(missing)))
        half = 0.5 / target
        lo = np.searchsorted(src_t, grid - half, side="left")
        hi = np.searchsorted(src_t, grid + half, side="right")
        out[counts[hi] - counts[lo] > 0] = np.nan
    return out
