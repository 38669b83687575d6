"""Recovery of the truth by the identification, window by window.

The truth of a synthetic event (``/truth``) is compared with the windows of an
identification result (``<event_id>.identify.nc``): the true regime of each
window and equation by the same rule as the models (DESIGN 2.5), and the true
right-hand side dA/dt evaluated at the measured amplitudes and winds.
"""

from __future__ import annotations

import numpy as np
import xarray as xr

from vivbench.regime import classify_regime
from vivbench.terms import evaluate_library

__all__ = ["truth_window_regimes", "rhs_relative_error", "regime_scores"]


def truth_window_regimes(truth: xr.Dataset, window_start: np.ndarray, window_end: np.ndarray, tau: float = 0.2) -> np.ndarray:
    """True regime of each window and section.

    Parameters
    ----------
    truth : the ``/truth`` group of an event (time, A, r)
    window_start, window_end : ndarray, shape (W,), s

    Returns
    -------
    regime : ndarray of int8, shape (W, n_sections); 0 where the window holds no truth sample
    """
    t = truth["time"].values
    A = truth["A"].values
    r = truth["r"].values
    out = np.zeros((len(window_start), A.shape[1]), dtype=np.int8)
    # Windows are few (about 100 per event): one vectorised rule call per window.
    for w, (t0, t1) in enumerate(zip(window_start, window_end)):
        m = (t >= t0) & (t <= t1)
        if m.any():
            out[w] = classify_regime(r[m], A[m], tau=tau, axis=0)
    return out


def rhs_relative_error(coef_identified: np.ndarray, coef_true: np.ndarray, A: np.ndarray, U: np.ndarray) -> np.ndarray:
    """Relative RMS error of an identified right-hand side over one window.

    Both models are evaluated on the same measured data (the identified
    model's own inputs), so the error is that of the dynamics, not of the
    trajectory.

    Parameters
    ----------
    coef_identified : ndarray, shape (n_eq, n_features)
    coef_true : ndarray, shape (n_eq, n_features)
    A, U : ndarray, shape (n_samples, n_sections), m and m/s

    Returns
    -------
    ndarray, shape (n_eq,): rms(f_id - f_true) / rms(f_true)
    """
    theta = evaluate_library(A, U)
    f_id = theta @ np.nan_to_num(coef_identified).T
    f_true = theta @ coef_true.T
    return np.sqrt(np.mean((f_id - f_true) ** 2, axis=0)) / np.sqrt(np.mean(f_true**2, axis=0))


def regime_scores(identified: np.ndarray, truth: np.ndarray, identifiable: np.ndarray) -> dict:
    """Regime accuracy on identifiable windows, beside coverage and the rest.

    Parameters
    ----------
    identified, truth : ndarray of int, same shape; 0 in ``truth`` means no truth
    identifiable : ndarray of bool, same shape

    Returns
    -------
    dict with ``n``, ``coverage`` (share flagged identifiable), ``accuracy_identifiable``,
    ``accuracy_not_identifiable``, ``accuracy_all`` (NaN where there is nothing to score).
    """
    identified = np.asarray(identified).ravel()
    truth = np.asarray(truth).ravel()
    ok = np.asarray(identifiable, dtype=bool).ravel()
    scored = (truth > 0) & (identified > 0)
    hit = identified == truth

    def acc(mask):
        m = scored & mask
        return float(hit[m].mean()) if m.any() else float("nan")

    return {
        "n": int(scored.sum()),
        "coverage": float(ok[scored].mean()) if scored.any() else float("nan"),
        "accuracy_identifiable": acc(ok),
        "accuracy_not_identifiable": acc(~ok),
        "accuracy_all": acc(np.ones_like(ok)),
    }
