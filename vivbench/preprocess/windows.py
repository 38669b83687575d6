"""Sliding windows over a time grid."""

from __future__ import annotations


import numpy as np
from vivbench.core.errors import InputError


__all__ = ["window_bounds"]


def window_bounds(t: np.ndarray, window: float, step: float):
    """Sliding windows [start, start + window) over a time grid.

    Windows start at t[0], t[0] + step, ... and are kept while complete: the
    last sample a window should hold (its end minus the median sample
    interval) lies within the record.

    Parameters
    ----------
    t : ndarray, shape (n,), s
        Strictly increasing sample times.
    window, step : float, s

    Returns
    -------
    start, end : ndarray, shape (n_windows,), s
    first, stop : ndarray of int, shape (n_windows,)
        Window k holds samples ``first[k]:stop[k]``.
    """
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or t.size < 2 or not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
        raise ValueError("t must be a 1-D, finite, strictly increasing array of at least two times")
    if not (np.isfinite(window) and window > 0 and np.isfinite(step) and step > 0):
        raise InputError(f"window and step must be finite and > 0 s; got window={window}, step={step}")
    dt = float(np.median(np.diff(t)))
    # Boundaries are compared with a tolerance far below the sample interval,
    # so that rounding of shifted time axes cannot move a sample across.
    tol = 1e-6 * dt
    span = t[-1] - t[0]
    n_windows = int(np.floor((span - (window - dt) + tol) / step)) + 1
    if n_windows < 1:
        return np.empty(0), np.empty(0), np.empty(0, dtype=int), np.empty(0, dtype=int)
    start = t[0] + step * np.arange(n_windows)
    end = start + window
    first = np.searchsorted(t, start - tol, side="left")
    stop = np.searchsorted(t, end - tol, side="left")
    return start, end, first, stop

