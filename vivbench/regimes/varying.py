"""Identifiability of the varying-coefficient model's regime in each window (DESIGN 2.5).

A window's regime is the rule of DESIGN 2.5 applied to the model's order
contributions over the window's data. It counts as identifiable when

1. at least ``model.agreement`` of the block-bootstrap replicates of the spline
   coefficients (penalty and basis fixed) give the window the same regime: the
   replicates' curves are the model's confidence band, evaluated on the
   window's own (A, U) rather than on a wind grid; and
2. every plausible model of the confidence set of order subsets
   (``model.subset_plausible_``: models without some of the orders 0, 2, 3
   whose leave-one-event-out prediction error is not significantly above the
   best subset's) gives it the same regime. The bootstrap measures variance
   only; a systematic misfit (a forced-only bridge whose forced plateaus the
   model bends with A^2 and A^3 terms) passes it, but then the model without
   those orders predicts the held-out events about as well and disagrees.
"""

from __future__ import annotations

import numpy as np

from vivbench.core.record import Record
from vivbench.core.regime import regime_rule
from vivbench.models.varying import VaryingCoefficientSINDy

__all__ = ["varying_window_verdicts", "window_order_stats"]


def window_order_stats(r: np.ndarray, A: np.ndarray, t: np.ndarray, window_start, window_end):
    """Window RMS of the order contributions and window mean of r_1 / A.

    Parameters
    ----------
    r : ndarray, shape (..., n, S, 4), m/s
    A : ndarray, shape (n, S), m
    t : ndarray, shape (n,), s
    window_start, window_end : ndarray, shape (W,), s (a window holds start <= t < end)

    Returns
    -------
    R : ndarray, shape (..., W, S, 4), m/s; c1 : ndarray, shape (..., W, S), 1/s;
    n_valid : ndarray, shape (..., W, S)
    """
    lo = np.searchsorted(t, np.asarray(window_start, dtype=float), side="left")
    hi = np.searchsorted(t, np.asarray(window_end, dtype=float), side="left")
    ok = np.isfinite(r).all(axis=-1) & np.isfinite(A)
    okA = ok & (A > 0)
    ax = r.ndim - 3  # the time axis

    def wsum(x):
        c = np.cumsum(x, axis=ax)
        c = np.concatenate([np.zeros_like(np.take(c, [0], axis=ax)), c], axis=ax)
        return np.take(c, hi, axis=ax) - np.take(c, lo, axis=ax)

    rz = np.where(ok[..., None], r, 0.0)
    inv = np.where(okA, 1.0 / np.where(okA, A, 1.0), 0.0)
    nv = wsum(ok.astype(float))
    with np.errstate(invalid="ignore", divide="ignore"):
        R = np.sqrt(wsum(rz**2) / nv[..., None])
        c1 = wsum(rz[..., 1] * inv) / wsum(okA.astype(float))
    return R, c1, nv


def varying_window_verdicts(model: VaryingCoefficientSINDy, record: Record, window_start, window_end,
                            chunk: int = 25) -> dict:
    """Regimes of a fitted :class:`VaryingCoefficientSINDy` over a record's windows, and their identifiability.

    Parameters
    ----------
    model : VaryingCoefficientSINDy (fitted, ``n_bootstrap`` > 0 for any window to be identifiable)
    record : Record
    window_start, window_end : array_like, shape (W,), s
    chunk : int
        Replicates evaluated together (memory: chunk x n_samples x S x 4 floats).

    Returns
    -------
    dict
        ``regime`` (W, S) int8 (0: no valid sample), ``identifiable`` (W, S) bool,
        ``agreement`` (W, S) share of replicates with the same regime (NaN
        without replicates), ``order_rms`` (W, S, 4) m/s.
    """
    t, A = record.t, record.A
    R, c1, nv = window_order_stats(model.order_contributions(record), A, t, window_start, window_end)
    point = np.where(nv > 0, regime_rule(np.nan_to_num(R), c1, model.tau), 0).astype(np.int8)
    B = model.coef_bootstrap_.shape[0]
    if B == 0:
        return {"regime": point, "identifiable": np.zeros(point.shape, dtype=bool),
                "agreement": np.full(point.shape, np.nan), "order_rms": R}
    same = np.zeros(point.shape)
    for c0 in range(0, B, chunk):
        r = model.replicate_order_contributions(record, c0, c0 + chunk)
        Rb, c1b, _ = window_order_stats(r, A, t, window_start, window_end)
        same += (regime_rule(np.nan_to_num(Rb), c1b, model.tau) == point[None]).sum(axis=0)
    agree = same / B
    # Every plausible model of the confidence set of order subsets must give the same regime.
    Rs, c1s, _ = window_order_stats(model.subset_order_contributions(record), A, t, window_start, window_end)
    sub = regime_rule(np.nan_to_num(Rs), c1s, model.tau)  # (n_subsets, W, S)
    plaus = model.subset_plausible_[:, None, :]
    set_agree = np.all((sub == point[None]) | ~plaus, axis=0)
    return {"regime": point, "identifiable": (agree >= model.agreement) & (point > 0) & set_agree,
            "agreement": agree, "order_rms": R, "model_set_agree": set_agree}
