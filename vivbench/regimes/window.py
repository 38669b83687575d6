"""Regimes of window models and whether the data can tell them apart (docs/concepts.md (regimes)).

Inside a 50 s window U is nearly constant and, on a plateau, so is A: the
library's orders (A^0 ... A^3 times powers of U) then mimic one another, and
many sparse models fit the window equally well while splitting the dynamics
between the orders differently. The regime of the selected model is then an
accident of the selection, not a property of the data.

The flag used here is a model-selection uncertainty test (Burnham and
Anderson's rule that models within 2 of the best AICc have substantial support;
Mangan et al. 2017 use the same rule for SINDy): a window's regime counts as
identifiable when every competing sparse model with AICc <= best + margin
gives the same regime. The competitors are

- the models along the STLSQ threshold path, and
- for each order of A present in the selected model, the best model on the
  library without that order (re-run over the same threshold path): if the
  data can be explained as well without, say, the A^3 terms, the A^3 share of
  the dynamics is not identifiable.

Not a proof: the competitors are the models the method itself finds, so an
equally good model that no threshold reaches is not seen. The flag is
checked on windows whose truth is known to be unidentifiable (plateaus) and on
windows that are (strong growth), see ``tests/analysis/test_identify.py``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from vivbench.models.window import EventWindowSINDy, WindowProblem
from vivbench.regression.settings import StlsqSettings
from vivbench.regression.stlsq import stlsq_path
from vivbench.core.regime import classify_regime
from vivbench.library.basis import basis_orders, order_contributions_basis

__all__ = ["label_windows", "window_regimes"]


def _dense_rss(theta: np.ndarray, y: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Least-squares RSS of every target on all columns of its window, shape (W, S).

    A lower bound of the RSS of any model on a subset of these columns (for a
    rank-deficient design, of its least-squares fit too: the Householder Q
    spans at least the columns' range).
    """
    X = np.where(valid[..., None], np.nan_to_num(theta), 0.0)
    Y = np.where(valid[..., None], np.nan_to_num(y), 0.0)
    Q = np.linalg.qr(X)[0]  # (W, n, c): the same rows as the regression, invalid ones zeroed
    proj = np.matmul(np.swapaxes(Q, 1, 2), Y)
    return np.sum(Y**2, axis=1) - np.sum(proj**2, axis=1)


def _regimes(r: np.ndarray, A: np.ndarray, valid: np.ndarray, tau: float) -> np.ndarray:
    """Regime per model: r (W, S, M, n, 4), A (W, n, S), valid (W, n) -> (W, S, M)."""
    Aw = np.where(valid[..., None], A, np.nan)  # invalid rows drop out of the c1 mean
    Aw = np.moveaxis(Aw, 2, 1)[:, :, None, :]  # (W, S, 1, n)
    Aw = np.broadcast_to(Aw, r.shape[:-1])
    # Invalid rows contribute zeros to every order's RMS alike; ratios are unchanged.
    r = np.where(valid[:, None, None, :, None], r, 0.0)
    return classify_regime(r, Aw, tau=tau, axis=-1)


def window_regimes(
    theta: np.ndarray,
    y: np.ndarray,
    y_scale: np.ndarray,
    A: np.ndarray,
    valid: np.ndarray,
    path,
    settings: StlsqSettings,
    *,
    tau: float = 0.2,
    margin: float | None = 2.0,
    order_deletion: bool = True,
    fit_tolerance: float = 0.1,
) -> dict:
    """Regime of each selected window model and its identifiability flag.

    Parameters
    ----------
    theta : ndarray, shape (W, n, p)
        Window libraries in the regression basis (powers of A as in the physical library).
    y : ndarray, shape (W, n, S)
        Standardised targets the path was fitted to.
    y_scale : ndarray, shape (W, S), m/s
        Factors back to dA/dt.
    A : ndarray, shape (W, n, S), m
    valid : ndarray of bool, shape (W, n)
    path : StlsqPath of ``theta`` against ``y``
    settings : the path's settings (reused for the order-deletion refits)
    tau : regime threshold of docs/concepts.md (regimes)
    margin : AICc margin of "equally good"; None skips the test (all flagged identifiable)
    order_deletion : also try the best model without each present order

    Returns
    -------
    dict of ndarray
        ``regime`` (W, S) int8 (0 where no model); ``identifiable`` (W, S) bool;
        ``regimes_seen`` (W, S) int8 bit mask (bit k-1 set if regime k occurs
        among the equally good models found); ``n_equivalent`` (W, S) int,
        equally good competitors found (the order-restricted search stops for a
        window and equation once a competitor with another regime is found); ``order_rms`` (W, S, 4)
        m/s, RMS over the window of each order's contribution to dA/dt.
    """
    W, n, p = theta.shape
    S = y.shape[-1]
    orders = basis_orders(p // 23)
    best = path.best_coef  # (W, S, p)
    has_model = path.selected >= 0
    r_best = order_contributions_basis(theta, best, orders) * y_scale[:, :, None, None]  # (W, S, n, 4)
    reg_best = _regimes(r_best[:, :, None], A, valid, tau)[:, :, 0]
    nv = np.maximum(valid.sum(axis=1), 1)
    order_rms = np.sqrt((np.where(valid[:, None, :, None], r_best, 0.0) ** 2).sum(axis=2) / nv[:, None, None])
    regime = np.where(has_model, reg_best, 0).astype(np.int8)
    seen = np.where(has_model, 1 << (regime.astype(int) - 1), 0)
    n_equiv = np.zeros((W, S), dtype=int)
    if margin is None:
        return {"regime": regime, "identifiable": has_model.copy(), "regimes_seen": seen.astype(np.int8),
                "n_equivalent": n_equiv, "order_rms": order_rms}

    best_aicc = np.where(has_model, path.best_aicc, np.inf)
    # 1) competitors along the threshold path (distinct supports only)
    T = path.aicc.shape[2]
    near = np.isfinite(path.aicc) & (path.aicc <= best_aicc[:, :, None] + margin)
    near &= np.arange(T)[None, None, :] != np.maximum(path.selected, 0)[:, :, None]
    same_support = (path.support == path.best_support[:, :, None, :]).all(axis=-1)
    near &= ~same_support
    if near.any():
        # Only the competitors' contributions are needed: gather them, padded to the
        # largest count per window (most thresholds are not competitors).
        k = near.reshape(W, -1).sum(axis=1)
        K = int(k.max())
        flat = np.argsort(~near.reshape(W, -1), axis=1, kind="stable")[:, :K]  # competitors first
        has = np.arange(K)[None, :] < k[:, None]
        coef_near = np.take_along_axis(path.coef.reshape(W, S * T, p), flat[:, :, None], axis=1)
        r_near = order_contributions_basis(theta, np.where(has[..., None], coef_near, 0.0), orders)  # (W, K, n, 4)
        s_of = flat // T
        A_of = np.take_along_axis(np.moveaxis(A, 2, 1), s_of[:, :, None], axis=1)  # (W, K, n): each competitor's section
        reg_near = _regimes(r_near[:, :, None], np.moveaxis(A_of, 1, 2), valid, tau)[:, :, 0]  # (W, K)
        w_idx, k_idx = np.nonzero(has)
        np.bitwise_or.at(seen, (w_idx, s_of[w_idx, k_idx]), 1 << (reg_near[w_idx, k_idx].astype(int) - 1))
        n_equiv += near.sum(axis=2)
    # 2) competitors restricted to a subset of the orders of A. A competitor
    #    counts when its residual RMS is within (1 + fit_tolerance) of the
    #    selected model's: that residual is the data's own noise level, and
    #    derivative errors are smooth and correlated, so AICc's
    #    independent-residual arithmetic would call competitors significantly
    #    worse that the data cannot reject.
    if order_deletion:
        present = np.stack([(best[..., orders == i] != 0).any(axis=-1) for i in range(4)], axis=-1)  # (W,S,4)
        # Every proper, non-empty subset of the orders 0..3, single orders first:
        # in practice they are the ones that settle the verdict soonest.
        masks = sorted(range(1, 15), key=lambda mk: (bin(mk).count("1"), mk))
        rss_best = np.where(has_model, path.best_rss, np.nan)
        rss_equal = (1.0 + fit_tolerance) ** 2 * rss_best
        # Competitors need not reproduce pysindy's truncated refit to the last digit.
        alt_settings = dataclasses.replace(settings, refit_rcond=None)
        own = np.where(has_model, 1 << (regime.astype(int) - 1), 0)
        for mk in masks:
            allowed = np.array([(mk >> i) & 1 for i in range(4)], dtype=bool)
            keep = allowed[orders]
            # A restriction only matters where the selected model uses a removed
            # order, and only windows whose verdict is still open are refitted.
            applies = present[..., ~allowed].any(axis=-1) & (seen == own) & has_model
            rows = np.flatnonzero(applies.any(axis=1))
            if rows.size == 0:
                continue
            # No model on these columns fits better than all of them together: where even
            # that least-squares fit misses the tolerance, the restricted path cannot
            # find a competitor and is not run (the flags are the same).
            with np.errstate(invalid="ignore"):
                applies[rows] &= _dense_rss(theta[rows][..., keep], y[rows], valid[rows]) <= rss_equal[rows] * (1 + 1e-9)
            rows = rows[applies[rows].any(axis=1)]
            if rows.size == 0:
                continue
            alt = stlsq_path(theta[rows][..., keep], y[rows], alt_settings)
            with np.errstate(invalid="ignore"):
                ok = applies[rows] & (alt.selected >= 0) & (alt.best_rss <= rss_equal[rows])
            if not ok.any():
                continue
            coef_alt = np.zeros((rows.size, S, p))
            coef_alt[..., keep] = np.nan_to_num(alt.best_coef)
            r_alt = order_contributions_basis(theta[rows], coef_alt, orders)
            reg_alt = _regimes(r_alt[:, :, None], A[rows], valid[rows], tau)[:, :, 0]
            seen[rows] |= np.where(ok, 1 << (reg_alt.astype(int) - 1), 0)
            n_equiv[rows] += ok
    identifiable = has_model & (seen == np.where(has_model, 1 << (regime.astype(int) - 1), 0))
    return {"regime": regime, "identifiable": identifiable, "regimes_seen": seen.astype(np.int8),
            "n_equivalent": n_equiv, "order_rms": order_rms}


def label_windows(model: EventWindowSINDy, t, A, U, dA, *, tau: float = 0.2, margin: float | None = 2.0,
                  order_deletion: bool = True, fit_tolerance: float = 0.1) -> dict:
    """Fit window SINDy and give every selected model its regime and identifiability verdict.

    Parameters
    ----------
    model : EventWindowSINDy
        Fitted here (``model.fit(t, A, U, dA)``); its fitted attributes are set as usual.
    t : ndarray, shape (n,), s
    A, U, dA : ndarray, shape (n, S); m, m/s and m/s
    tau : regime threshold of docs/concepts.md (regimes)
    margin, order_deletion, fit_tolerance : see :func:`window_regimes`

    Returns
    -------
    dict of ndarray, shape (W, S)
        ``regime`` int8 (0: no model), ``identifiable`` bool, ``regimes_seen`` int8
        bit mask, ``n_equivalent`` int (see :func:`window_regimes`).
    """
    parts: list[tuple[slice, dict]] = []

    def verdict(problem: WindowProblem) -> None:
        parts.append((problem.windows, window_regimes(
            problem.theta, problem.y, problem.y_scale, problem.A, problem.valid, problem.path, problem.settings,
            tau=tau, margin=margin, order_deletion=order_deletion, fit_tolerance=fit_tolerance)))

    model.fit(t, A, U, dA, on_chunk=verdict)
    W, S = model.coef_.shape[:2]
    out = {"regime": np.zeros((W, S), dtype=np.int8), "identifiable": np.zeros((W, S), dtype=bool),
           "regimes_seen": np.zeros((W, S), dtype=np.int8), "n_equivalent": np.zeros((W, S), dtype=int)}
    for windows, reg in parts:
        for key, values in out.items():
            values[windows] = reg[key]
    return out
