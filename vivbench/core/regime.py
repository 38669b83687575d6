"""The regime rule of docs/concepts.md (regimes), one function for the truth and for models.

Regimes (the paper's Table 1): 1, no self-excited effect (damped, forced);
2, slight self-excitation (net negative linear damping); 3, medium (the A^2
order matters); 4, strong (the A^3 order matters).
"""

from __future__ import annotations

import warnings

import numpy as np
from vivbench.core.errors import InputError

__all__ = ["DEFAULT_TAU", "classify_regime", "order_rms", "regime_rule"]

DEFAULT_TAU = 0.2


def order_rms(r: np.ndarray, axis: int = 0) -> np.ndarray:
    """RMS of each order contribution over a window.

    Parameters
    ----------
    r : ndarray, shape (..., 4) with the window along ``axis``, m/s
        Order contributions r_0..r_3 to dA/dt.
    """
    r = np.asarray(r, dtype=float)
    return np.sqrt(np.mean(r**2, axis=axis))


def classify_regime(r: np.ndarray, A: np.ndarray, tau: float = DEFAULT_TAU, axis: int = 0) -> np.ndarray:
    """Regime 1..4 of a window by the rule of docs/concepts.md (regimes).

    Parameters
    ----------
    r : ndarray, shape (..., 4), window along ``axis``, m/s
        Order contributions r_i over the window (last axis is the order).
    A : ndarray, same shape as ``r`` without the order axis, m
        Amplitudes over the window; the net linear coefficient is the window
        mean of r_1 / A.
    tau : float
        Relative level at which an order counts (0 < tau < 1).
    axis : int
        The window (time) axis of ``A``; in ``r`` the same axis.

    Returns
    -------
    regime : ndarray of int8
        Shape of ``A`` with ``axis`` removed.

    Notes
    -----
    A window of one sample gives the regime at a moment (``r`` of shape
    (1, 4)); that is how the truth is labelled on its time grid.
    """
    if not 0.0 < tau < 1.0:
        raise InputError(f"tau must lie strictly between 0 and 1; got {tau}")
    r = np.asarray(r, dtype=float)
    A = np.asarray(A, dtype=float)
    if r.shape[:-1] != A.shape or r.shape[-1] != 4:
        raise ValueError(f"r must have shape A.shape + (4,); got r {r.shape}, A {A.shape}")
    # A negative axis counts from A's end; r has the extra order axis last.
    axis = axis % A.ndim if A.ndim else 0
    R = order_rms(r, axis=axis)
    with np.errstate(divide="ignore", invalid="ignore"), warnings.catch_warnings():
        # a window without a positive amplitude has no linear coefficient (NaN: not > 0)
        warnings.simplefilter("ignore", RuntimeWarning)
        c1 = np.nanmean(np.where(A > 0, r[..., 1] / A, np.nan), axis=axis)
    return regime_rule(R, c1, tau)


def regime_rule(R: np.ndarray, c1: np.ndarray, tau: float = DEFAULT_TAU) -> np.ndarray:
    """The rule of docs/concepts.md (regimes) from a window's statistics.

    Parameters
    ----------
    R : ndarray, shape (..., 4), m/s
        RMS over the window of each order contribution r_0..r_3.
    c1 : ndarray, shape (...), 1/s
        Window mean of r_1 / A (NaN where undefined: counts as not positive).
    tau : float

    Returns
    -------
    regime : ndarray of int8, shape (...)
    """
    if not 0.0 < tau < 1.0:
        raise InputError(f"tau must lie strictly between 0 and 1; got {tau}")
    R = np.asarray(R, dtype=float)
    M = R.max(axis=-1)
    with np.errstate(invalid="ignore"):
        regime = np.where(c1 > 0, 2, 1).astype(np.int8)
        regime = np.where(R[..., 2] >= tau * M, 3, regime)
        regime = np.where(R[..., 3] >= tau * M, 4, regime)
        # A window with no dynamics at all (M == 0) is damped and unforced.
        return np.where(M > 0, regime, 1).astype(np.int8)
