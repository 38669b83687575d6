"""Identifiability of the campaign model's regime in each window (docs/concepts.md (regimes)).

A window's regime is the rule of docs/concepts.md (regimes) applied to the campaign model's order
contributions over that window's data. It counts as identifiable when

1. no model in the coefficients' joint confidence region gives it another regime
   (chi-square in p dimensions, residual variance inflated by the residuals'
   integrated correlation time; checked per window and order by a small
   eigenvalue problem, orders bounded one at a time), and
2. at least ``model.agreement`` of the block-bootstrap replicate models give it
   the same regime, and the campaign has at least ``model.min_blocks`` blocks.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.stats import chi2

from vivbench.core.errors import InputError
from vivbench.core.regime import regime_rule
from vivbench.core.terms import evaluate_library, section_exponents

__all__ = ["WindowRecord", "campaign_window_verdicts", "pooled_window_stats", "window_record", "window_stats",
           "window_sums"]


def campaign_window_verdicts(model: PooledSINDy, t: np.ndarray, A: np.ndarray, U: np.ndarray,
                         window_start: np.ndarray, window_end: np.ndarray) -> dict:
    """Regimes of the campaign model over the windows of one record, and their identifiability.

    Parameters
    ----------
    t : ndarray, shape (n,), s
    A, U : ndarray, shape (n, S), m and m/s
    window_start, window_end : ndarray, shape (W,), s; a window holds t0 <= t < t1

    Returns
    -------
    dict
        ``regime`` (W, S) int8 (0: no valid sample), ``identifiable`` (W, S)
        bool, ``agreement`` (W, S) share of bootstrap replicates with the same
        regime (NaN without replicates), ``order_rms`` (W, S, 4) m/s.
    """
    if not hasattr(model, "gram_inv_"):
        raise InputError("this campaign model was rebuilt from a campaign regimes file, which holds no regression basis; "
                         "re-run vivbench pool (it writes campaign.model.nc) for window verdicts")
    models = np.concatenate([model.coef_[None], model.coef_bootstrap_], axis=0)
    rec = window_record(t, A, U, window_start, window_end)  # evaluated once for the statistics and the margins
    R, c1, nv = window_stats(models, rec)
    reg = regime_rule(R, c1, model.tau)  # (B+1, W, S)
    reg = np.where(nv[None, :, None] > 0, reg, 0).astype(np.int8)
    point = reg[0]
    dR, dc1 = _margins(model, rec)
    robust = _regime_is_determined(R[0], dR, c1[0], dc1, model.tau) & (point > 0)
    if models.shape[0] > 1 and model.enough_data_:
        agree = (reg[1:] == point[None]).mean(axis=0)
        identifiable = robust & (agree >= model.agreement)
    else:
        agree = np.full(point.shape, np.nan)
        identifiable = np.zeros(point.shape, dtype=bool)
    return {"regime": point, "identifiable": identifiable, "agreement": agree, "robust": robust,
            "order_rms": R[0], "order_rms_margin": dR}

def _margins(model: PooledSINDy, rec: WindowRecord):
    """How far models that fit equally well can move each window's order RMS and c1.

    Over all models xi + delta with ||X delta||^2 <= b (X the pooled scaled
    library, b = chi2_p(confidence) sigma^2 n_corr, sigma^2 = RSS / N and
    n_corr the residuals' integrated correlation time in samples), the
    largest change of the window RMS of order i's contribution is
    sqrt(b lambda_max(C_i^T X_wi^T X_wi C_i) / n_w), with C_i C_i^T
    the order-i block of (X^T X + alpha I)^-1; the largest change of the
    window mean of r_1/A is the same bound on a linear functional. Both
    are in m/s and 1/s after scaling by the target's RMS.
    """
    A, ok, lo, hi = rec.A, rec.ok, rec.lo, rec.hi
    S = A.shape[1]
    X = rec.theta @ model.to_physical_
    orders = np.tile(section_exponents()[:, 0], S)

    def wsum(x):
        return window_sums(x, lo, hi)

    nv = np.maximum(wsum(ok.astype(float)), 1.0)
    n_max = int(max((hi - lo).max(initial=0), 1))
    idx = lo[:, None] + np.arange(n_max)[None, :]
    inwin = idx < hi[:, None]
    idx = np.minimum(idx, A.shape[0] - 1)
    # Models the data cannot reject: a chi-square region in p dimensions with the
    # residual variance inflated by the residuals' integrated correlation time.
    p = X.shape[1]
    budget = chi2.ppf(model.confidence, p) * model.rss_scaled_ / model.n_samples_ * model.correlation_samples_
    dR = np.empty((lo.size, S, 4))
    dc1 = None
    okA = ok[:, None] & (A > 0)
    invA = np.where(okA, 1.0 / np.where(okA, A, 1.0), 0.0)
    for i in range(4):
        cols = orders == i
        C = np.linalg.cholesky(model.gram_inv_[np.ix_(cols, cols)])
        Z = X[:, cols] @ C
        Zw = Z[idx] * inwin[..., None]  # (W, n_max, k); rows outside a window are zero
        gw = np.matmul(np.swapaxes(Zw, 1, 2), Zw)
        lam = np.linalg.eigvalsh(gw)[:, -1]
        dR[:, :, i] = np.sqrt(np.maximum(lam, 0.0)[:, None] / nv[:, None] * budget[None, :])
        if i == 1:
            v = wsum(Z[:, None, :] * invA[:, :, None]) / np.maximum(wsum(okA.astype(float)), 1.0)[:, :, None]
            dc1 = np.sqrt(budget)[None, :] * np.linalg.norm(v, axis=-1)
    ys = model.y_scale_[None, :]
    return dR * ys[..., None], dc1 * ys


def _regime_is_determined(R, dR, c1, dc1, tau):
    """Whether every order RMS in [R - dR, R + dR] and c1 in [c1 - dc1, c1 + dc1] give one regime.

    Orders are bounded one at a time (conservative: a joint move is smaller).
    """
    lo = np.maximum(R - dR, 0.0)
    hi = R + dR
    m_lo = lo.max(axis=-1)
    m_hi = hi.max(axis=-1)
    can4 = hi[..., 3] >= tau * m_lo
    not4 = lo[..., 3] < tau * m_hi
    can3 = not4 & (hi[..., 2] >= tau * m_lo)
    below = not4 & (lo[..., 2] < tau * m_hi)
    with np.errstate(invalid="ignore"):
        can2 = below & ~(c1 + dc1 <= 0)
        can1 = below & ~(c1 - dc1 > 0)
    return (can4.astype(int) + can3 + can2 + can1) == 1


class WindowRecord(NamedTuple):
    """One record's library (zero on samples with a non-finite term) and its windows' sample ranges."""

    A: np.ndarray
    theta: np.ndarray
    ok: np.ndarray
    lo: np.ndarray
    hi: np.ndarray


def window_record(t, A, U, window_start, window_end) -> WindowRecord:
    """A record's physical library (zero where a term is not finite) and its windows' sample ranges."""
    t = np.asarray(t, dtype=float)
    A = np.asarray(A, dtype=float)
    theta = evaluate_library(A, np.asarray(U, dtype=float))
    ok = np.isfinite(theta).all(axis=1)
    return WindowRecord(A=A, theta=np.where(ok[:, None], theta, 0.0), ok=ok,
                   lo=np.searchsorted(t, window_start, side="left"), hi=np.searchsorted(t, window_end, side="left"))


def window_sums(x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Sums of x over samples lo[w] <= i < hi[w] along axis 0, by one cumulative sum."""
    c = np.concatenate([np.zeros((1,) + x.shape[1:]), np.cumsum(x, axis=0)], axis=0)
    return c[hi] - c[lo]


def pooled_window_stats(models: np.ndarray, t, A, U, window_start, window_end):
    """Order RMS and net linear coefficient of several models over every window.

    Parameters
    ----------
    models : ndarray, shape (M, S, 23 S)
        Physical coefficients.
    t : ndarray, shape (n,), s; A, U : ndarray, shape (n, S)
    window_start, window_end : ndarray, shape (W,), s

    Returns
    -------
    R : ndarray, shape (M, W, S, 4), m/s; c1 : ndarray, shape (M, W, S), 1/s;
    n_valid : ndarray, shape (W,)
    """
    return window_stats(models, window_record(t, A, U, window_start, window_end))


def window_stats(models: np.ndarray, rec: WindowRecord):
    A, theta, ok, lo, hi = rec
    S = A.shape[1]
    orders = np.tile(section_exponents()[:, 0], S)
    models = np.nan_to_num(np.asarray(models, dtype=float))
    M = models.shape[0]
    okA = ok[:, None] & (A > 0)
    invA = np.where(okA, 1.0 / np.where(okA, A, 1.0), 0.0)

    def wsum(x):
        return window_sums(x, lo, hi)

    nv = wsum(ok.astype(float))
    sq = np.empty((lo.size, M, S, 4))
    c1 = None
    for i in range(4):
        # (n, M*S) by one matrix product per order
        r = theta[:, orders == i] @ models[..., orders == i].reshape(M * S, -1).T
        r = r.reshape(-1, M, S)
        sq[..., i] = wsum(r**2)
        if i == 1:
            c1 = wsum(r * invA[:, None, :])
    with np.errstate(invalid="ignore", divide="ignore"):
        R = np.sqrt(sq / nv[:, None, None, None])
        c1 = c1 / wsum(okA.astype(float))[:, None, :]
    return np.moveaxis(R, 1, 0), np.moveaxis(c1, 1, 0), nv


