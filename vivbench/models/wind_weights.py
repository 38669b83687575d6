"""The weights of the sections' winds in a campaign model's one wind.

Averaging (docs/concepts.md (the truth)) gives the modal amplitude's equation a sum over the
sections' aerodynamic forces, section j's weighted by beta_j phi_j, so its
linear term is -zeta w1 + sum_j w_j c(U_j) / 2 with

    w_j = L_j phi_j^2 / sum_l L_l phi_l^2        (they sum to 1),

L_j the tributary length and phi_j the mode shape at section j. A model that
evaluates its curves at one wind should therefore weight the sections' winds
by w_j, not equally: an antinode's wind drives the mode more than a quarter
point's. Where the tributary lengths are equal (instrumented sections spread
evenly along the span) w_j is the share of section j in the mode's energy,
phi_j^2 / sum_l phi_l^2, which the data give without the mode shape: in one
mode A_j = |phi_j| Q, so the campaign's sum of A_j^2 is proportional to
phi_j^2 (:func:`modal_wind_weights`). The higher orders weight the sections by
L_j phi_j^(i+1) instead; with the in-phase modes of a VIV their weights differ
from w_j by a few per cent of the winds' differences, which one wind cannot
carry anyway.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np

from vivbench.core.errors import InputError

__all__ = ["WIND_WEIGHT_MODES", "modal_wind_weights", "resolve_wind_weights", "weighted_section_mean",
           "weighted_mean_standard_error", "check_wind_weights"]

#: Named choices of the weights: estimated from the amplitudes (``"modal"``) or equal (the plain mean).
WIND_WEIGHT_MODES = ("modal", "equal")


def check_wind_weights(spec) -> None:
    """Raise InputError unless ``spec`` is one of ``WIND_WEIGHT_MODES`` or a sequence of finite numbers >= 0 with a positive sum."""
    if isinstance(spec, str):
        if spec not in WIND_WEIGHT_MODES:
            raise InputError(f"wind_weights must be 'modal', 'equal' or a sequence of one weight per section; "
                             f"got {spec!r}")
        return
    w = np.asarray(spec, dtype=float) if isinstance(spec, Sequence | np.ndarray) else np.array([np.nan])
    if w.ndim != 1 or w.size == 0 or not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
        raise InputError(f"wind_weights as numbers must be one finite weight >= 0 per section with a positive sum; "
                         f"got {spec!r}")


def modal_wind_weights(A: np.ndarray) -> np.ndarray:
    """Each section's share of the mode's energy, from the amplitudes alone.

    Parameters
    ----------
    A : ndarray, shape (n_samples, S), m
        Section amplitudes of a campaign (NaN where missing).

    Returns
    -------
    w : ndarray, shape (S,)
        sum_t A_j(t)^2 / sum_l sum_t A_l(t)^2 over the samples where every
        section is finite (= phi_j^2 / sum_l phi_l^2 in one mode; the large
        amplitudes, where the sensors' noise is least, dominate the sums).
        Equal weights where no sample has every section.
    """
    A = np.asarray(A, dtype=float)
    if A.ndim != 2 or A.shape[1] == 0:
        raise ValueError(f"A must have shape (n_samples, S); got {A.shape}")
    S = A.shape[1]
    ok = np.all(np.isfinite(A), axis=1)
    energy = np.sum(A[ok] ** 2, axis=0)
    if not ok.any() or energy.sum() <= 0:
        return np.full(S, 1.0 / S)
    return energy / energy.sum()


def resolve_wind_weights(spec, A: np.ndarray) -> np.ndarray:
    """The weights of ``wind_weights`` ``"modal"``, ``"equal"`` or numbers for amplitudes ``A`` (n_samples, S), summing to 1."""
    check_wind_weights(spec)
    S = np.shape(A)[1]
    if isinstance(spec, str):
        return modal_wind_weights(A) if spec == "modal" else np.full(S, 1.0 / S)
    w = np.asarray(spec, dtype=float)
    if w.size != S:
        raise InputError(f"wind_weights gives {w.size} weights for {S} sections")
    return w / w.sum()


def _row_weights(X: np.ndarray, w: np.ndarray) -> np.ndarray:
    """The weights of each row's finite entries, renormalised to sum to 1 (NaN rows: 0), shape (n, S)."""
    ww = np.where(np.isfinite(X), np.asarray(w, dtype=float)[None, :], 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return ww / ww.sum(axis=1, keepdims=True)


def weighted_section_mean(X: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Weighted mean over the sections of X (n, S) with weights w (S,), over each row's finite entries.

    Returns shape (n,); NaN where a row has no finite entry with a positive weight.
    """
    X = np.asarray(X, dtype=float)
    rw = _row_weights(X, w)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        out = np.sum(np.where(np.isfinite(X), X, 0.0) * np.nan_to_num(rw), axis=1)
    return np.where(np.isfinite(rw).all(axis=1), out, np.nan)


def weighted_mean_standard_error(U: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Standard error of :func:`weighted_section_mean` of U (n, S), m/s, when each entry's error is independent.

    Each section's error is taken as the spread of the row's entries about
    their mean (sample standard deviation), so the weighted mean's is that
    times sqrt(sum_j w_j^2) over the row's finite entries (1/sqrt(S) for equal
    weights). NaN where a row has fewer than two finite entries.
    """
    U = np.asarray(U, dtype=float)
    rw = np.nan_to_num(_row_weights(U, w))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        sd = np.nanstd(U, axis=1, ddof=1)
    return sd * np.sqrt(np.sum(rw**2, axis=1))
