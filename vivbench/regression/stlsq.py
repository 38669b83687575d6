"""Fast windowed STLSQ over a threshold path with AICc model selection.

For every window, every equation (target) and every threshold of a path, run
sequentially thresholded least squares with the semantics of
``pysindy.optimizers.STLSQ`` and pick, per window and equation, the model with
the smallest AICc (Mangan et al. 2017). Everything is batched over windows;
no regression costs a pysindy fit.

STLSQ semantics (pysindy 2.x, ``sparse_ind=None``, ``normalize_columns=False``)
----------------------------------------------------------------------------
1. Iteration 0 solves the ridge problem on all features:
   (X^T X + alpha I) w = X^T y; features with |w| >= threshold are kept.
2. Each further iteration solves the ridge problem on the kept features only
   and thresholds again (only kept features can stay). The loop stops when
   the kept set no longer changes, becomes empty, or after ``max_iter``
   ridge solves in total (iteration 0 included).
3. Features with |w| <= 1e-14 are dropped; with ``unbias`` the coefficients
   are refitted by unregularised least squares on the remaining features.
pysindy iterates all targets jointly until all have converged; since a
converged target's kept set is a fixed point this equals iterating each
target separately, which is what is done here.

Numerics
--------
Each window's design ``[X | y]`` is reduced once by a Householder QR to the
p x p factor R and the transformed targets Z = Q^T y; every later solve
works on R, whatever the window length. Scaled window libraries of three
sections remain extremely ill-conditioned (cond ~1e14-1e16: within a window
U_k q(U_k), deg q <= 4, approximates a constant to about (s/c)^5, so the
constant-like terms of the three sections are nearly interchangeable; on a
plateau A, A^2, A^3 are nearly collinear too). Normal equations square the
condition number and lose every digit there, so:

- Least-squares solves (alpha = 0 iterations, final refits) use Householder
  QR of [R_S | z], as accurate as a direct least-squares solve.
- Ridge iterations (alpha > 0) use the Cholesky factor of X_S^T X_S + alpha I,
  pysindy's own arithmetic, only when it is provably accurate: by eigenvalue
  interlacing every active set's matrix has condition number at most
  (sigma_max(X)^2 + alpha) / alpha, which must not exceed 1e8 (relative
  error ~1e-8). Otherwise QR of [R_S | z ; sqrt(alpha) I | 0].

Speed comes from nesting. Along a threshold path the active sets of one
window and target shrink as the threshold grows (at iteration 1 exactly, as
all come from thresholding the same iteration-0 solution; later mostly).
Ordering the columns so that each set of such a chain is a prefix, one QR of
[R_perm | Z] (or one Cholesky factor of the permuted X^T X + alpha I) serves
every member: the leading k x k block of the factor is the factor of the
member's own problem, and the first k transformed target entries are its
right-hand side (a reflection or elimination step touches one column at a
time). A window then costs about one factorisation per target and iteration
instead of one per threshold.

The unbiased refit of pysindy goes through scikit-learn's
``LinearRegression``, which (scikit-learn >= 1.7) calls
``scipy.linalg.lstsq(X_S, y, cond=1e-6)``: singular values below 1e-6 of the
largest are discarded. The engine reproduces this (``refit_rcond``): supports
that may be that ill-conditioned are flagged cheaply (diagonal of their QR
factor, LAPACK's condition estimate), and since truncation can only raise the
RSS, the plain least-squares AICc bounds the truncated one from below; the
SVD-based truncated refit (LAPACK gelsd, as scipy) is computed only for
flagged candidates whose bound beats the best exact AICc of their window and
equation, best bound first, until none does. Candidates skipped this way keep
their least-squares values, marked in ``StlsqPath.lower_bound``.

AICc
----
AIC = N ln(RSS/N) + 2k and AICc = AIC + 2k(k+1)/(N-k-1), k the number of
non-zero terms, N the number of valid samples in the window. Models with
N - k - 1 <= 0 are excluded (AICc = +inf), as is the empty model (k = 0)
unless ``allow_empty``. An RSS below ``residual_floor**2 * sum(y**2)`` is
raised to that floor: on noise-free data the residuals of all correct models
are rounding noise, and ln(RSS) of rounding noise would choose among them at
random; with the floor, the correct model with the fewest terms wins.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from vivbench.regression.lstsq import NestedFactors, as_batches, empty_path
from vivbench.regression.settings import StlsqSettings


__all__ = ["StlsqPath", "aicc", "stlsq_path"]


# pysindy drops coefficients at or below this magnitude before the refit.
_ZERO_COEF = 1e-14


def aicc(rss, n_terms, n_samples, *, floor=0.0) -> np.ndarray:
    """Corrected Akaike information criterion (Mangan et al. 2017).

    Parameters
    ----------
    rss : array_like
        Residual sums of squares (units of the target squared).
    n_terms : array_like of int
        Number k of non-zero coefficients.
    n_samples : array_like of int
        Number N of samples.
    floor : array_like
        RSS values below ``floor`` are raised to it.

    Returns
    -------
    ndarray
        N ln(RSS/N) + 2k + 2k(k+1)/(N-k-1); +inf where N - k - 1 <= 0.
    """
    rss = np.maximum(np.asarray(rss, dtype=float), np.asarray(floor, dtype=float))
    k = np.asarray(n_terms, dtype=float)
    n = np.asarray(n_samples, dtype=float)
    dof = n - k - 1
    ok = dof > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        value = n * np.log(rss / n) + 2 * k + 2 * k * (k + 1) / np.where(ok, dof, 1.0)
    return np.where(ok, value, np.inf)


@dataclass(frozen=True, kw_only=True)
class StlsqPath:
    """STLSQ results along the threshold path for a batch of windows.

    ``W`` windows, ``q`` targets, ``T`` thresholds, ``p`` features. Windows
    with fewer than p + 2 valid samples are not fitted: their entries are NaN
    (``selected`` = -1). All quantities are in the units of the design and
    targets the path was run on.

    Attributes
    ----------
    thresholds : ndarray, shape (T,)
    coef : ndarray, shape (W, q, T, p)
        Final coefficients (refitted if ``unbias``) per threshold.
    support : ndarray of bool, shape (W, q, T, p)
    rss : ndarray, shape (W, q, T)
        Residual sum of squares (not floored).
    n_terms : ndarray of int, shape (W, q, T)
    aicc : ndarray, shape (W, q, T)
        +inf for excluded models.
    n_iter : ndarray of int, shape (W, q, T)
        Ridge solves done (iteration 0 included).
    converged : ndarray of bool, shape (W, q, T)
        False if ``max_iter`` stopped the iteration.
    lower_bound : ndarray of bool, shape (W, q, T)
        True where ``coef``, ``rss`` and ``aicc`` are those of the plain
        least-squares refit of a support that the truncated refit
        (``refit_rcond``) may change: its RSS is then a lower bound of the
        truncated refit's, and the truncated refit was skipped because even
        the bound cannot beat the selected model.
    n_samples : ndarray of int, shape (W,)
    cond : ndarray, shape (W,)
        Condition number of each window's design (from the R factor).
    selected : ndarray of int, shape (W, q)
        Index into ``thresholds`` of the smallest AICc (first of ties), -1
        if no admissible model.
    solves : dict
        Work done: QR factorisations ("qr") and Cholesky factorisations
        ("cholesky") of chains, truncated-SVD refits ("svd"), minimum-norm
        fallbacks for exactly singular active sets ("lstsq").
    """

    thresholds: np.ndarray
    coef: np.ndarray
    support: np.ndarray
    rss: np.ndarray
    n_terms: np.ndarray
    aicc: np.ndarray
    n_iter: np.ndarray
    converged: np.ndarray
    lower_bound: np.ndarray
    n_samples: np.ndarray
    cond: np.ndarray
    selected: np.ndarray
    solves: dict = field(default_factory=dict)

    def _pick(self, values: np.ndarray, fill) -> np.ndarray:
        sel = np.maximum(self.selected, 0)
        picked = np.take_along_axis(values, sel.reshape(sel.shape + (1,) * (values.ndim - 2)), axis=2)
        picked = picked[:, :, 0]
        none = (self.selected < 0).reshape(sel.shape + (1,) * (picked.ndim - 2))
        return np.where(none, fill, picked)

    @property
    def best_coef(self) -> np.ndarray:
        """Selected coefficients, shape (W, q, p); NaN where none."""
        return self._pick(self.coef, np.nan)

    @property
    def best_support(self) -> np.ndarray:
        """Selected support, shape (W, q, p); all False where none."""
        return self._pick(self.support, False)

    @property
    def best_threshold(self) -> np.ndarray:
        """Selected threshold, shape (W, q); NaN where none."""
        th = np.broadcast_to(self.thresholds, self.rss.shape)
        return self._pick(th, np.nan)

    @property
    def best_aicc(self) -> np.ndarray:
        return self._pick(self.aicc, np.nan)

    @property
    def best_rss(self) -> np.ndarray:
        return self._pick(self.rss, np.nan)

    @property
    def best_n_terms(self) -> np.ndarray:
        """Selected number of terms, shape (W, q); 0 where none."""
        return self._pick(self.n_terms, 0)


def stlsq_path(theta: np.ndarray, y: np.ndarray, settings: StlsqSettings | None = None) -> StlsqPath:
    """Run STLSQ over a threshold path for a batch of windows and select by AICc.

    Parameters
    ----------
    theta : ndarray, shape (W, n, p) or (n, p)
        Design matrix of each window (for example ``WindowLibrary.theta``).
        Rows with a non-finite entry in ``theta`` or ``y`` are ignored.
    y : ndarray, shape (W, n, q) or (n, q)
        Targets (one column per equation).
    settings : StlsqSettings, optional

    Returns
    -------
    StlsqPath
        With a leading window axis even for a single 2-D window.
    """
    settings = StlsqSettings() if settings is None else settings
    theta, y = as_batches(theta, y)
    W, N, p = theta.shape
    q = y.shape[2]
    th = np.asarray(settings.thresholds)
    T = th.size
    valid = np.isfinite(theta).all(axis=2) & np.isfinite(y).all(axis=2)
    n_valid = valid.sum(axis=1)
    X = np.where(valid[..., None], theta, 0.0)
    Y = np.where(valid[..., None], y, 0.0)

    out = empty_path(W, q, T, p)
    cond = np.full(W, np.nan)
    fit = np.flatnonzero(n_valid >= p + 2)
    solves = {"qr": 0, "cholesky": 0, "svd": 0, "lstsq": 0}
    if fit.size:
        res = _path(X[fit], Y[fit], n_valid[fit], settings)
        for name, value in res.items():
            if name == "cond":
                cond[fit] = value
            elif name == "solves":
                solves = value
            else:
                out[name][fit] = value

    finite = np.isfinite(out["aicc"])
    masked = np.where(finite, out["aicc"], np.inf)
    selected = np.where(finite.any(axis=2), np.argmin(masked, axis=2), -1)
    return StlsqPath(
        thresholds=th.copy(),
        n_samples=n_valid,
        cond=cond,
        selected=selected,
        solves=solves,
        **out,
    )


def _path(X, Y, n_valid, settings: StlsqSettings) -> dict:
    """The path for windows that all have enough samples (see ``stlsq_path``)."""
    W, N, p = X.shape
    q = Y.shape[2]
    th = np.asarray(settings.thresholds)
    T = th.size
    fac = NestedFactors(X, Y, settings)
    alpha = settings.alpha
    # Exactly zero columns get a zero coefficient from pysindy's minimum-norm
    # fallback and are dropped at the end; excluding them at once is the same.
    usable = np.sum(fac.R**2, axis=1) > 0

    # Iteration 0: one ridge solve per window and target, shared by all thresholds.
    w0 = np.repeat(np.arange(W), q)
    e0 = np.tile(np.arange(q), W)
    m0 = usable[w0]
    c0, _ = fac.solve(w0, e0, m0, alpha=alpha, iterate=True)

    P0 = W * q
    src = np.repeat(np.arange(P0), T)
    w = w0[src]
    e = e0[src]
    tt = np.tile(np.arange(T), P0)
    thr = th[tt][:, None]
    mask = (np.abs(c0[src]) >= thr) & m0[src]
    coef = np.where(mask, c0[src], 0.0)
    n_iter = np.ones(src.size, dtype=int)
    active = np.any(mask != m0[src], axis=1) & mask.any(axis=1)
    for _ in range(1, settings.max_iter):
        ai = np.flatnonzero(active)
        if ai.size == 0:
            break
        sol, _ = fac.solve(w[ai], e[ai], mask[ai], alpha=alpha, iterate=True)
        new = (np.abs(sol) >= thr[ai]) & mask[ai]
        changed = np.any(new != mask[ai], axis=1)
        mask[ai] = new
        coef[ai] = np.where(new, sol, 0.0)
        n_iter[ai] += 1
        active[ai] = changed & new.any(axis=1)
    converged = ~active

    final = mask & (np.abs(coef) > _ZERO_COEF)
    coef = np.where(final, coef, 0.0)
    rcond = settings.refit_rcond if settings.unbias else None
    ill = np.zeros(final.shape[0], dtype=bool)
    if settings.unbias:
        # Without ridge, a converged fit's last solve already is the least-
        # squares refit on its support; only the others need one.
        if alpha == 0 and not rcond:
            redo = ~converged | np.any(final != mask, axis=1)
        else:
            redo = np.ones(final.shape[0], dtype=bool)
        ri = np.flatnonzero(redo & final.any(axis=1))
        coef[ri], ill[ri] = fac.solve(w[ri], e[ri], final[ri], alpha=0.0, iterate=False, screen=rcond)
    k = final.sum(axis=1)
    yy = np.sum(Y**2, axis=1)[w, e]
    N_ = n_valid[w]
    floor = np.maximum(settings.residual_floor**2 * yy, np.finfo(float).tiny)

    def score(idx):
        res = fac.Z[w[idx], :, e[idx]] - np.einsum("npk,nk->np", fac.R[w[idx]], coef[idx])
        rss_i = np.sum(res**2, axis=1) + fac.yperp2[w[idx], e[idx]]
        a_i = aicc(rss_i, k[idx], N_[idx], floor=floor[idx])
        # A failed SVD refit (NaN) excludes the model rather than the row.
        admissible = ((k[idx] > 0) | settings.allow_empty) & np.isfinite(a_i)
        return rss_i, np.where(admissible, a_i, np.inf)

    # Residuals from R; problems are ordered (window, target, threshold).
    pred = np.matmul(fac.R, coef.reshape(W, q * T, p).transpose(0, 2, 1))
    res = np.repeat(fac.Z, T, axis=2) - pred
    rss = np.sum(res**2, axis=1).reshape(-1) + fac.yperp2[w, e]
    a = aicc(rss, k, N_, floor=floor)
    if not settings.allow_empty:
        a = np.where(k > 0, a, np.inf)

    # Truncated refits change nothing for well-conditioned supports and only
    # raise the RSS of the others, so the plain least-squares AICc is a lower
    # bound: refit (by SVD, expensive) only candidates whose bound beats the
    # best exact AICc of their window and equation, best bound first.
    lower_bound = ill.copy()
    if rcond and ill.any():
        A2 = a.reshape(W * q, T)
        lb2 = lower_bound.reshape(W * q, T)
        F2 = final.reshape(W * q, T, p)
        while True:
            best = np.where(lb2, np.inf, A2).min(axis=1)
            # Ties are refitted too, so that no bound can be selected.
            cand = lb2 & (A2 <= best[:, None]) & np.isfinite(A2)
            rows = np.flatnonzero(cand.any(axis=1))
            if rows.size == 0:
                break
            pick = np.argmin(np.where(cand[rows], A2[rows], np.inf), axis=1)
            idx = rows * T + pick
            coef[idx] = fac.truncated_lstsq(w[idx], e[idx], final[idx], rcond)
            rss[idx], a[idx] = score(idx)
            # Thresholds of the same row with the same support share the refit.
            same = np.all(F2[rows] == final[idx][:, None, :], axis=2) & lb2[rows]
            r_, t_ = np.nonzero(same)
            dst = rows[r_] * T + t_
            src = idx[r_]
            coef[dst], rss[dst], a[dst] = coef[src], rss[src], a[src]
            lb2[rows[r_], t_] = False

    shape = (W, q, T)
    return dict(
        coef=coef.reshape(shape + (p,)),
        support=final.reshape(shape + (p,)),
        rss=rss.reshape(shape),
        n_terms=k.reshape(shape),
        aicc=a.reshape(shape),
        n_iter=n_iter.reshape(shape),
        converged=converged.reshape(shape),
        lower_bound=lower_bound.reshape(shape),
        cond=fac.cond,
        solves=dict(fac.counts),
    )


