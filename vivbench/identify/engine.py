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

import functools
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg.lapack import dgeqrf as _dgeqrf
from scipy.linalg.lapack import dgelsd as _dgelsd
from scipy.linalg.lapack import dgelsd_lwork as _dgelsd_lwork
from scipy.linalg.lapack import dtrcon as _dtrcon
from scipy.linalg.lapack import dtrtrs as _dtrtrs

from vivbench.identify.library import SCALINGS, library_cond, window_library
from vivbench.terms import feature_names

__all__ = [
    "DEFAULT_THRESHOLDS",
    "SOLVERS",
    "StlsqSettings",
    "StlsqPath",
    "aicc",
    "stlsq_path",
    "window_bounds",
    "WindowedSINDy",
]

DEFAULT_THRESHOLDS = (0.0,) + tuple(float(x) for x in np.logspace(-3, 2, 21))
SOLVERS = ("auto", "qr", "gram")

# pysindy drops coefficients at or below this magnitude before the refit.
_ZERO_COEF = 1e-14
# Granularity of the QR sizes of chains (fewer, larger batches).
_BUCKET = 8
# Largest condition-number bound of a ridge matrix solved by normal equations
# (relative error about this times eps, ~1e-8).
_RIDGE_COND_MAX = 1e8


@dataclass(frozen=True, kw_only=True)
class StlsqSettings:
    """Settings of the threshold path and of AICc selection.

    Parameters
    ----------
    thresholds : sequence of float
        Strictly increasing, non-negative thresholds on the coefficients of
        the design the path is run on (for :class:`WindowedSINDy` with
        scaling, standardised coefficients: unit-RMS columns and targets).
    alpha : float
        Ridge parameter added to the diagonal of X^T X (pysindy's ``alpha``
        and its default).
    max_iter : int
        Maximum number of ridge solves per fit, iteration 0 included.
    unbias : bool
        Refit the final support by unregularised least squares (pysindy's
        ``unbias``).
    allow_empty : bool
        Whether the empty model (k = 0) competes in the AICc selection.
    residual_floor : float
        Relative RMS residual below which a fit counts as exact (see module
        docstring); 0 disables the floor.
    refit_rcond : float or None
        The unbiased refit discards singular values of X_S below
        ``refit_rcond`` times the largest (minimum-norm solution), as
        pysindy's refit does: scikit-learn's ``LinearRegression`` (>= 1.7)
        calls ``scipy.linalg.lstsq`` with ``cond=tol = 1e-6``. None: plain
        least squares (older scikit-learn behaves so up to eps).
    solver : {"auto", "qr", "gram"}
        How STLSQ iterations are solved (final refits always use QR):
        ``"auto"`` by Cholesky where the ridge guarantees accuracy (see the
        module docstring), else QR; ``"qr"`` always QR; ``"gram"`` always
        Cholesky of the normal equations, pysindy's default arithmetic, which
        loses all accuracy once cond(X_S)^2 exceeds 1/eps.
    """

    thresholds: tuple[float, ...] = DEFAULT_THRESHOLDS
    alpha: float = 0.05
    max_iter: int = 20
    unbias: bool = True
    allow_empty: bool = False
    residual_floor: float = 1e-8
    refit_rcond: float | None = 1e-6
    solver: str = "auto"

    def __post_init__(self) -> None:
        th = np.asarray(self.thresholds, dtype=float).ravel()
        if th.size == 0 or not np.all(np.isfinite(th)) or np.any(th < 0):
            raise ValueError(f"thresholds must be a non-empty sequence of finite values >= 0; got {self.thresholds!r}")
        if np.any(np.diff(th) <= 0):
            raise ValueError("thresholds must be strictly increasing")
        object.__setattr__(self, "thresholds", tuple(float(x) for x in th))
        if not (np.isfinite(self.alpha) and self.alpha >= 0):
            raise ValueError(f"alpha must be finite and >= 0; got {self.alpha}")
        if isinstance(self.max_iter, bool) or not isinstance(self.max_iter, (int, np.integer)) or self.max_iter < 1:
            raise ValueError(f"max_iter must be an integer >= 1; got {self.max_iter!r}")
        if not (np.isfinite(self.residual_floor) and 0 <= self.residual_floor < 1):
            raise ValueError(f"residual_floor must lie in [0, 1); got {self.residual_floor}")
        if self.refit_rcond is not None and not (np.isfinite(self.refit_rcond) and 0 <= self.refit_rcond < 1):
            raise ValueError(f"refit_rcond must be None or lie in [0, 1); got {self.refit_rcond}")
        if self.solver not in SOLVERS:
            raise ValueError(f"solver must be one of {SOLVERS}; got {self.solver!r}")


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


def _qr_r(At: np.ndarray) -> np.ndarray:
    """R factors of the matrices At[i].T: shape (n, min(m, c), c) for At (n, c, m).

    Matrices are passed transposed because LAPACK wants column-major storage:
    At[i].T is then factored in place without a copy. LAPACK's geqrf called
    per matrix is 2-4x faster than numpy's batched QR at these sizes.
    """
    n, c, m = At.shape
    r = min(m, c)
    out = np.empty((n, r, c))
    for i in range(n):
        out[i] = _dgeqrf(At[i].T, overwrite_a=True)[0][:r]
    # Below the diagonal LAPACK leaves the Householder vectors.
    lower = np.tril_indices(r, -1, c)
    out[:, lower[0], lower[1]] = 0.0
    return out


@functools.lru_cache(maxsize=None)
def _gelsd_work(shape: tuple[int, int]) -> tuple[int, int]:
    lwork, iwork, info = _dgelsd_lwork(shape[0], shape[1], 1, -1.0)
    if info:
        raise RuntimeError(f"LAPACK dgelsd workspace query failed (info={info})")
    return int(lwork), int(iwork)


class _Factors:
    """Per-window reductions shared by all thresholds, iterations and targets."""

    def __init__(self, X: np.ndarray, Y: np.ndarray, settings: StlsqSettings):
        W, N, p = X.shape
        q = Y.shape[2]
        Mt = np.concatenate([np.swapaxes(X, 1, 2), np.swapaxes(Y, 1, 2)], axis=1)
        if N < p + q:
            # Zero rows change no least-squares problem; they only give the
            # QR enough rows to return a square factor.
            Mt = np.concatenate([Mt, np.zeros((W, p + q, p + q - N))], axis=2)
        Rf = _qr_r(np.ascontiguousarray(Mt))
        self.R = np.ascontiguousarray(Rf[:, :p, :p])
        self.Z = np.ascontiguousarray(Rf[:, :p, p:])
        # Energy of each target orthogonal to every column of the window.
        self.yperp2 = np.sum(Rf[:, p:, p:] ** 2, axis=1)
        self.RT = np.ascontiguousarray(np.swapaxes(self.R, 1, 2))
        self.ZT = np.ascontiguousarray(np.swapaxes(self.Z, 1, 2))
        self.G = np.matmul(self.RT, self.R)
        self.b = np.matmul(self.RT, self.Z)
        self.p, self.q = p, q
        sv = np.linalg.svd(self.R, compute_uv=False)
        with np.errstate(divide="ignore", invalid="ignore"):
            self.cond = np.where(sv[:, -1] > 0, sv[:, 0] / sv[:, -1], np.inf)
        alpha = settings.alpha
        if settings.solver == "qr":
            self.cholesky_ok = np.zeros(W, dtype=bool)
        elif settings.solver == "gram":
            self.cholesky_ok = np.ones(W, dtype=bool)
        else:
            # With ridge, every active set's X_S^T X_S + alpha I has condition
            # number <= (sigma_max^2 + alpha) / alpha (eigenvalue interlacing),
            # so its normal equations are accurate when that bound is moderate.
            self.cholesky_ok = np.full(W, alpha > 0) & (sv[:, 0] ** 2 + alpha <= _RIDGE_COND_MAX * alpha)
        self.counts = {"qr": 0, "cholesky": 0, "svd": 0, "lstsq": 0}

    def solve(self, w, e, masks, *, alpha, iterate, screen=None):
        """Ridge (alpha > 0) or least-squares solutions of problems (w, e, S = mask).

        Problems must be ordered by window, then target, then threshold, so
        that nested active sets are neighbours. ``iterate`` marks STLSQ
        iterations, which may use normal equations (``cholesky_ok``); final
        refits always use QR. Returns coefficients (P, p), zero off the masks,
        and flags (P,) of active sets whose X_S may have singular values below
        ``screen`` times the largest (all False without ``screen``).
        """
        coef = np.zeros(masks.shape)
        ill = np.zeros(w.size, dtype=bool)
        chol = self.cholesky_ok[w] if iterate else np.zeros(w.size, dtype=bool)
        for sel, method in ((chol, "cholesky"), (~chol, "qr")):
            idx = np.flatnonzero(sel & masks.any(axis=1))
            if idx.size:
                coef[idx], ill[idx] = self._solve_chains(
                    w[idx], e[idx], masks[idx], alpha=alpha, method=method, screen=screen
                )
        return coef, ill

    def _solve_chains(self, w, e, masks, *, alpha, method, screen=None):
        """Solves shared along chains of nested active sets.

        Consecutive problems of one window whose sets shrink form a chain
        S_0 ⊇ S_1 ⊇ ... With the columns ordered so that every S_r is a
        prefix, one factorisation serves every member: the leading k_r x k_r
        block of the Householder QR of [R_perm | Z] (with sqrt(alpha) I rows
        for ridge), or of the Cholesky factor of the permuted X^T X + alpha I,
        is the factor of the member's own problem.
        """
        P, p = masks.shape
        k = masks.sum(axis=1)
        start = np.ones(P, dtype=bool)
        start[1:] = (w[1:] != w[:-1]) | np.any(masks[1:] & ~masks[:-1], axis=1)
        chain = np.cumsum(start) - 1
        heads = np.flatnonzero(start)
        depth = np.add.reduceat(masks.astype(np.int32), heads, axis=0)
        order = np.argsort(-depth, axis=1, kind="stable")
        K = k[heads]
        # Chains are batched by head size rounded up; the extra columns are
        # factored too, but no member uses them (prefix property).
        Kb = np.minimum(-(-K // _BUCKET) * _BUCKET, p)
        slot = np.arange(P) - heads[chain]
        local_of_chain = np.zeros(heads.size, dtype=int)
        coef = np.zeros((P, p))
        ill = np.zeros(P, dtype=bool)
        for KK in np.unique(Kb):
            csel = np.flatnonzero(Kb == KK)
            local_of_chain[csel] = np.arange(csel.size)
            msel = np.flatnonzero(Kb[chain] == KK)
            local = local_of_chain[chain[msel]]
            cw = w[heads[csel]]
            cols = order[csel, :KK]
            km = k[msel]
            x = None
            if method == "cholesky":
                x = self._cholesky_bucket(cw, cols, K[csel], local, slot[msel], e[msel], km, alpha)
            if x is None:
                x, ill[msel] = self._qr_bucket(cw, cols, K[csel], local, slot[msel], e[msel], km, alpha, screen)
            bad = ~np.all(np.isfinite(x), axis=1)
            if bad.any():
                x[bad] = self._lstsq(w[msel][bad], e[msel][bad], cols[local][bad], km[bad], alpha)
            keep = np.arange(KK) < km[:, None]
            rows = np.zeros((msel.size, p))
            np.put_along_axis(rows, cols[local], np.where(keep, x, 0.0), axis=1)
            coef[msel] = rows
        return coef, ill

    def _qr_bucket(self, cw, cols, K, local, slot, e, km, alpha, screen=None):
        """Members' solutions (M, KK) from one QR per chain (NaN if singular),
        and the ``screen`` flags of their leading blocks."""
        n, KK = cols.shape
        p, q = self.p, self.q
        # Built transposed (rows of R^T are columns of R) for column-major QR.
        At = np.zeros((n, KK + q, p + (KK if alpha else 0)))
        At[:, :KK, :p] = self.RT[cw[:, None], cols]
        At[:, KK:, :p] = self.ZT[cw]
        if alpha:
            At[:, np.arange(KK), p + np.arange(KK)] = np.sqrt(alpha)
        T = _qr_r(At)
        self.counts["qr"] += n
        rows = np.arange(KK)
        rhs = T[local[:, None], rows[None, :], (KK + e)[:, None]]
        x = self._triangular(T[:, :KK, :KK], K, local, slot, rhs, km)
        ill = self._screen(T, local, km, screen) if screen else np.zeros(km.size, dtype=bool)
        return x, ill

    @staticmethod
    def _screen(T, local, km, rcond):
        """Flag members whose leading block T_k may have sigma_min < rcond sigma_max.

        cond(T_k) >= max|T_ii| / min|T_ii| flags most at once; where that
        bound is inconclusive, LAPACK's estimate of the 1-norm condition
        number (a lower bound, usually within a few; cond_2 <= k cond_1)
        decides, with a margin of 10.
        """
        KK = km.max()
        d = np.abs(np.diagonal(T, axis1=1, axis2=2))[local, :KK]
        inside = np.arange(KK)[None, :] < km[:, None]
        dmax = np.where(inside, d, 0.0).max(axis=1)
        dmin = np.where(inside, d, np.inf).min(axis=1)
        ill = dmin <= rcond * dmax
        for i in np.flatnonzero(~ill):
            k = km[i]
            rc = _dtrcon(T[local[i], :k, :k].T, norm="1", uplo="L")[0]
            ill[i] = rc < 10 * k * rcond
        return ill

    def truncated_lstsq(self, w, e, masks, rcond):
        """Minimum-norm least squares discarding singular values of X_S below
        ``rcond`` times the largest, as ``scipy.linalg.lstsq(X_S, y,
        cond=rcond)`` (LAPACK gelsd on R_S, which has the singular values of
        X_S). One problem at a time: only used for the few refits that can
        change the AICc selection."""
        out = np.zeros(masks.shape)
        for i in range(w.size):
            cols = np.flatnonzero(masks[i])
            A = np.asfortranarray(self.R[w[i]][:, cols])
            b = self.Z[w[i], :, e[i]].reshape(-1, 1)
            lwork, iwork = _gelsd_work(A.shape)
            x, _, _, info = _dgelsd(A, b, lwork, iwork, rcond)
            out[i, cols] = x[: cols.size, 0] if info == 0 else np.nan
            self.counts["svd"] += 1
        return out

    def _cholesky_bucket(self, cw, cols, K, local, slot, e, km, alpha):
        """As ``_qr_bucket`` from the Cholesky factor of X^T X + alpha I.

        Returns None if a factorisation fails (then QR is used).
        """
        n, KK = cols.shape
        p, q = self.p, self.q
        # Flat gathers are several times faster than 3-D fancy indexing.
        idx = (cw[:, None, None] * (p * p) + cols[:, :, None] * p + cols[:, None, :]).reshape(n, -1)
        Gs = self.G.ravel().take(idx).reshape(n, KK, KK)
        if alpha:
            Gs[:, np.arange(KK), np.arange(KK)] += alpha
        try:
            L = np.linalg.cholesky(Gs)
        except np.linalg.LinAlgError:
            return None
        self.counts["cholesky"] += n
        bi = cw[local][:, None] * (p * q) + cols[local] * q + e[:, None]
        rhs = self.b.ravel().take(bi)
        # Forward substitution with the lower factor; entries beyond a
        # member's prefix are not part of its problem and are cut before the
        # back substitution with the upper factor L^T.
        y = self._triangular(L, K, local, slot, rhs, km, lower=True)
        return self._triangular(np.swapaxes(L, 1, 2), K, local, slot, y, km, lower=False)

    @staticmethod
    def _triangular(U, K, local, slot, rhs, km, *, lower=False):
        """Solve each member's leading block of the triangular factor of its chain.

        A member's right-hand side is cut to its size k; for an upper factor
        the solve of the chain's K x K system then returns the k x k
        leading-block solution followed by zeros, so all members of a chain
        share one solve (for a lower factor the first k entries are the
        leading-block solution and the rest is cut). NaN rows flag members of
        a chain whose factor is exactly singular.
        """
        n, KK, _ = U.shape
        keep = np.arange(KK)[None, :] < km[:, None]
        B = np.zeros((n, KK, slot.max() + 1))
        B[local, :, slot] = np.where(keep, rhs, 0.0)
        X = np.empty_like(B)
        for i in range(n):
            k = K[i]
            # U[i][:k, :k].T is column-major, so LAPACK reads it without a
            # copy as the transpose of the lower/upper factor we need.
            x, info = _dtrtrs(U[i, :k, :k].T, B[i, :k], lower=int(not lower), trans=1)
            X[i, :k] = x if info == 0 else np.nan
            X[i, k:] = 0.0
        return np.where(keep, X[local, :, slot], 0.0)

    def _lstsq(self, w, e, cols, km, alpha):
        """Minimum-norm solutions for members whose factor is singular.

        Exactly dependent columns: pysindy's ridge falls back to an SVD
        solve, which gives the minimum-norm solution, as here.
        """
        out = np.zeros(cols.shape)
        for i in range(w.size):
            c = cols[i, : km[i]]
            A = self.R[w[i]][:, c]
            b = self.Z[w[i], :, e[i]]
            if alpha:
                A = np.vstack([A, np.sqrt(alpha) * np.eye(c.size)])
                b = np.concatenate([b, np.zeros(c.size)])
            out[i, : c.size] = np.linalg.lstsq(A, b, rcond=None)[0]
            self.counts["lstsq"] += 1
        return out


def _empty_path(W: int, q: int, T: int, p: int) -> dict:
    """Path arrays of W windows, q targets, T thresholds and p terms before any fit (no model anywhere)."""
    return dict(
        coef=np.full((W, q, T, p), np.nan),
        support=np.zeros((W, q, T, p), dtype=bool),
        rss=np.full((W, q, T), np.nan),
        n_terms=np.zeros((W, q, T), dtype=int),
        aicc=np.full((W, q, T), np.inf),
        n_iter=np.zeros((W, q, T), dtype=int),
        converged=np.zeros((W, q, T), dtype=bool),
        lower_bound=np.zeros((W, q, T), dtype=bool),
    )


def _as_batches(theta, y) -> tuple[np.ndarray, np.ndarray]:
    """Designs (W, n, p) and targets (W, n, q) as float arrays, a single 2-D window given a batch axis."""
    theta = np.asarray(theta, dtype=float)
    y = np.asarray(y, dtype=float)
    if theta.ndim == 2:
        theta = theta[None]
    if y.ndim == 2:
        y = y[None]
    if theta.ndim != 3 or y.ndim != 3 or theta.shape[:2] != y.shape[:2]:
        raise ValueError(f"theta (W, n, p) and y (W, n, q) must agree on W and n; got {theta.shape} and {y.shape}")
    return theta, y


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
    theta, y = _as_batches(theta, y)
    W, N, p = theta.shape
    q = y.shape[2]
    th = np.asarray(settings.thresholds)
    T = th.size
    valid = np.isfinite(theta).all(axis=2) & np.isfinite(y).all(axis=2)
    n_valid = valid.sum(axis=1)
    X = np.where(valid[..., None], theta, 0.0)
    Y = np.where(valid[..., None], y, 0.0)

    out = _empty_path(W, q, T, p)
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
    fac = _Factors(X, Y, settings)
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
        raise ValueError(f"window and step must be finite and > 0 s; got window={window}, step={step}")
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


class WindowedSINDy:
    """Time-varying SINDy: STLSQ with AICc selection on sliding windows (DESIGN 3.2).

    Each window's library (:func:`vivbench.identify.library.window_library`,
    69 terms for three sections) is regressed against each section's dA/dt
    in a well-conditioned basis; the targets are divided by their window RMS
    (unless ``scaling="raw"``), so thresholds act on standardised
    coefficients: a coefficient of 0.1 means the term, at unit RMS, carries a
    tenth of the target's RMS. Coefficients are reported in physical units.

    Parameters
    ----------
    window, step : float, s
        Window width and step (the paper: 50 s and 25 s).
    thresholds : sequence of float, optional
        STLSQ threshold path; default :data:`DEFAULT_THRESHOLDS` (0 and 21
        log-spaced values from 1e-3 to 1e2).
    alpha : float
        Ridge parameter on X^T X (pysindy's ``alpha``; its default 0.05).
        The basis columns have unit RMS, so diag(X^T X) equals the number of
        samples (200 for 50 s at 4 Hz). Some ridge is needed: three sections'
        constant-like terms are nearly interchangeable in a window (condition
        numbers ~1e15), and without it the least-squares coefficients at
        iteration 0 are so large that no threshold removes anything (on the
        test campaigns even 0.1 % derivative noise gives 69-term models). The
        price: a ridge resolves those non-identifiable directions by minimum
        norm, not sparsity, so even noise-free sparse models are not
        recovered exactly; alpha = 0 recovers them (single section) when the
        data are exact.
    max_iter : int
        STLSQ iterations, iteration 0 included (pysindy's ``max_iter``).
    scaling : {"scaled", "normalized", "raw"}
        Library basis, see :mod:`vivbench.identify.library`.
    unbias, allow_empty, residual_floor, refit_rcond, solver
        See :class:`StlsqSettings`.
    chunk_size : int
        Windows processed together (memory grows linearly with it).
    keep_path : bool
        Keep the per-threshold results (``path_*_`` attributes).
    raw_cond : bool
        Also compute the condition number of the physical library (one more
        SVD per window).
    tau : float
        Regime threshold of DESIGN 2.5.
    identifiability_margin : float or None
        AICc margin within which competing models count as equally good
        (None: no identifiability test, every fitted window flagged identifiable).
    order_deletion : bool
        Also compete with the best model without each order of A present.
    fit_tolerance : float
        Relative RMS residual within which an order-restricted model fits equally well.
    optimizer : {"stlsq", "sr3", "ensemble"}
        Sparse regression per window: this engine's STLSQ path (default), or
        pysindy's SR3 path or bagged STLSQ on the same scaled problem, see
        :mod:`vivbench.identify.optimizers`.
    optimizer_options : OptimizerOptions, optional
        Settings of ``"sr3"`` and ``"ensemble"`` (None: their defaults).
    random_state : int
        Seed of the bootstrap samples of ``"ensemble"`` (one child seed per window).

    Attributes
    ----------
    thresholds_ : ndarray, shape (T,)
    window_start_, window_end_ : ndarray, shape (W,), s
    n_samples_ : ndarray of int, shape (W,)
        Valid samples per window (finite A, U and dA).
    coef_ : ndarray, shape (W, S, 23 S)
        Selected model per window and equation on the physical library
        :func:`vivbench.terms.evaluate_library` (A in m, U in m/s, dA/dt in
        m/s); NaN where no model could be fitted.
    coef_scaled_ : ndarray, shape (W, S, 23 S)
        The same model on the regression basis (standardised coefficients).
    support_ : ndarray of bool, shape (W, S, 23 S)
        Non-zero terms of the basis model (its physical image has at least
        these orders of A; centring U fills in lower powers of U).
    threshold_, aicc_, rss_ : ndarray, shape (W, S)
        Chosen threshold, its AICc and residual sum of squares (m^2/s^2;
        AICc from the physical RSS).
    n_terms_, selected_ : ndarray of int, shape (W, S)
        Number of basis terms; index into ``thresholds_`` (-1: none).
    cond_ : ndarray, shape (W,)
        Condition number of each window's basis library.
    cond_raw_ : ndarray, shape (W,) or None
        Condition number of the physical library (if ``raw_cond``).
    a_scale_, u_center_, u_scale_, u_ref_ : ndarray, shape (W, S)
        Basis constants (m, m/s), see :class:`WindowLibrary`.
    col_scale_ : ndarray, shape (W, 23 S)
    y_scale_ : ndarray, shape (W, S), m/s
        RMS of dA/dt per window and equation (1 for ``"raw"``).
    path_support_ : ndarray of bool, shape (W, S, T, 23 S)
    path_aicc_, path_rss_ : ndarray, shape (W, S, T)
    path_n_terms_, n_iter_ : ndarray of int, shape (W, S, T)
    converged_, path_lower_bound_ : ndarray of bool, shape (W, S, T)
        See :class:`StlsqPath` (``converged``, ``lower_bound``).
    regime_ : ndarray of int8, shape (W, S)
        Regime (DESIGN 2.5) of each selected model over its window; 0 where none.
    identifiable_ : ndarray of bool, shape (W, S)
        Whether every equally good competing model has the same regime
        (:mod:`vivbench.identify.identifiability`).
    regimes_seen_ : ndarray of int8, shape (W, S)
        Bit mask of the regimes among the equally good models (bit k-1: regime k).
    n_equivalent_ : ndarray of int, shape (W, S)
        Number of equally good competitors found.
    inclusion_ : ndarray, shape (W, S, 23 S)
        ``optimizer="ensemble"`` only: inclusion probability in [0, 1] of each
        basis term over the bootstrap models (NaN where no model was fitted).
        For ``"ensemble"`` the path attributes have T + 1 entries, the last
        the ensemble model, and ``threshold_`` is the bootstrap fits' threshold.
    order_rms_ : ndarray, shape (W, S, 4), m/s
        RMS over the window of each order's contribution to dA/dt.
    feature_names_ : list of str
    n_sections_ : int
    solves_ : dict
        Work done, summed over chunks (see :class:`StlsqPath`).
    """

    def __init__(
        self,
        *,
        window: float = 50.0,
        step: float = 25.0,
        thresholds=None,
        alpha: float = 0.05,
        max_iter: int = 20,
        scaling: str = "scaled",
        unbias: bool = True,
        allow_empty: bool = False,
        residual_floor: float = 1e-8,
        refit_rcond: float | None = 1e-6,
        solver: str = "auto",
        chunk_size: int = 128,
        keep_path: bool = True,
        raw_cond: bool = False,
        tau: float = 0.2,
        identifiability_margin: float | None = 2.0,
        order_deletion: bool = True,
        fit_tolerance: float = 0.1,
        optimizer: str = "stlsq",
        optimizer_options=None,
        random_state: int = 0,
    ):
        self.window = window
        self.step = step
        self.thresholds = thresholds
        self.alpha = alpha
        self.max_iter = max_iter
        self.scaling = scaling
        self.unbias = unbias
        self.allow_empty = allow_empty
        self.residual_floor = residual_floor
        self.refit_rcond = refit_rcond
        self.solver = solver
        self.chunk_size = chunk_size
        self.keep_path = keep_path
        self.raw_cond = raw_cond
        self.tau = tau
        self.identifiability_margin = identifiability_margin
        self.order_deletion = order_deletion
        self.fit_tolerance = fit_tolerance
        self.optimizer = optimizer
        self.optimizer_options = optimizer_options
        self.random_state = random_state

    _PARAMS = (
        "window",
        "step",
        "thresholds",
        "alpha",
        "max_iter",
        "scaling",
        "unbias",
        "allow_empty",
        "residual_floor",
        "refit_rcond",
        "solver",
        "chunk_size",
        "keep_path",
        "raw_cond",
        "tau",
        "identifiability_margin",
        "order_deletion",
        "fit_tolerance",
        "optimizer",
        "optimizer_options",
        "random_state",
    )

    def get_params(self, deep: bool = True) -> dict:
        """Constructor parameters (scikit-learn convention)."""
        return {name: getattr(self, name) for name in self._PARAMS}

    def set_params(self, **params) -> "WindowedSINDy":
        """Set constructor parameters (scikit-learn convention)."""
        for name, value in params.items():
            if name not in self._PARAMS:
                raise ValueError(f"unknown parameter {name!r}; allowed: {', '.join(self._PARAMS)}")
            setattr(self, name, value)
        return self

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={getattr(self, k)!r}" for k in self._PARAMS)
        return f"WindowedSINDy({args})"

    def settings(self) -> StlsqSettings:
        """The :class:`StlsqSettings` these parameters define (validated)."""
        return StlsqSettings(
            thresholds=DEFAULT_THRESHOLDS if self.thresholds is None else tuple(np.ravel(self.thresholds)),
            alpha=self.alpha,
            max_iter=self.max_iter,
            unbias=self.unbias,
            allow_empty=self.allow_empty,
            residual_floor=self.residual_floor,
            refit_rcond=self.refit_rcond,
            solver=self.solver,
        )

    def fit(self, t, A, U, dA) -> "WindowedSINDy":
        """Identify one model per window and equation.

        Parameters
        ----------
        t : ndarray, shape (n,), s
            Strictly increasing sample times (one grid for A, U and dA).
        A : ndarray, shape (n, S), m
            Amplitudes of the S sections.
        U : ndarray, shape (n, S), m/s
            Mean wind speeds.
        dA : ndarray, shape (n, S), m/s
            Time derivatives of A: one equation per section.
            Samples with a non-finite A, U or dA are ignored.

        Returns
        -------
        self
        """
        from vivbench.identify.identifiability import window_regimes  # it builds on stlsq_path
        from vivbench.identify.optimizers import OPTIMIZERS, run_optimizer

        settings = self.settings()
        if self.optimizer not in OPTIMIZERS:
            raise ValueError(f"optimizer must be one of {OPTIMIZERS}; got {self.optimizer!r}")
        if self.scaling not in SCALINGS:
            raise ValueError(f"scaling must be one of {SCALINGS}; got {self.scaling!r}")
        chunk = self.chunk_size
        if isinstance(chunk, bool) or not isinstance(chunk, (int, np.integer)) or chunk < 1:
            raise ValueError(f"chunk_size must be an integer >= 1; got {self.chunk_size!r}")
        t = np.asarray(t, dtype=float)
        A = np.asarray(A, dtype=float)
        U = np.asarray(U, dtype=float)
        dA = np.asarray(dA, dtype=float)
        if A.ndim != 2 or A.shape != U.shape or A.shape != dA.shape or t.shape != (A.shape[0],):
            raise ValueError(
                f"t must have shape (n,) and A, U, dA shape (n, n_sections); got t {t.shape}, "
                f"A {A.shape}, U {U.shape}, dA {dA.shape}"
            )
        start, end, first, stop = window_bounds(t, self.window, self.step)
        if start.size == 0:
            raise ValueError(f"the record ({t[-1] - t[0]:.6g} s) is shorter than one window ({self.window} s)")
        n, S = A.shape
        p = 23 * S
        W = start.size
        # The ensemble's path ends with the ensemble model itself.
        T = len(settings.thresholds) + (self.optimizer == "ensemble")
        n_max = int((stop - first).max())

        res = {
            "coef_": np.full((W, S, p), np.nan),
            "coef_scaled_": np.full((W, S, p), np.nan),
            "support_": np.zeros((W, S, p), dtype=bool),
            "threshold_": np.full((W, S), np.nan),
            "aicc_": np.full((W, S), np.nan),
            "rss_": np.full((W, S), np.nan),
            "n_terms_": np.zeros((W, S), dtype=int),
            "selected_": np.full((W, S), -1),
            "n_samples_": np.zeros(W, dtype=int),
            "cond_": np.full(W, np.nan),
            "a_scale_": np.ones((W, S)),
            "u_center_": np.zeros((W, S)),
            "u_scale_": np.ones((W, S)),
            "u_ref_": np.ones((W, S)),
            "col_scale_": np.ones((W, p)),
            "y_scale_": np.ones((W, S)),
            "regime_": np.zeros((W, S), dtype=np.int8),
            "identifiable_": np.zeros((W, S), dtype=bool),
            "regimes_seen_": np.zeros((W, S), dtype=np.int8),
            "n_equivalent_": np.zeros((W, S), dtype=int),
            "order_rms_": np.full((W, S, 4), np.nan),
        }
        if self.keep_path:
            res.update(
                path_support_=np.zeros((W, S, T, p), dtype=bool),
                path_aicc_=np.full((W, S, T), np.inf),
                path_rss_=np.full((W, S, T), np.nan),
                path_n_terms_=np.zeros((W, S, T), dtype=int),
                n_iter_=np.zeros((W, S, T), dtype=int),
                converged_=np.zeros((W, S, T), dtype=bool),
                path_lower_bound_=np.zeros((W, S, T), dtype=bool),
            )
        if self.optimizer == "ensemble":
            res["inclusion_"] = np.full((W, S, p), np.nan)
        seeds = np.random.SeedSequence(self.random_state).spawn(W)
        cond_raw = np.full(W, np.nan) if self.raw_cond else None
        solves = {"qr": 0, "cholesky": 0, "svd": 0, "lstsq": 0}

        for c0 in range(0, W, self.chunk_size):
            ch = slice(c0, min(W, c0 + self.chunk_size))
            offs = np.arange(n_max)
            inwin = offs[None, :] < (stop[ch] - first[ch])[:, None]
            idx = np.minimum(first[ch][:, None] + offs[None, :], n - 1)
            Aw, Uw, dAw = A[idx], U[idx], dA[idx]
            valid = inwin & np.isfinite(Aw).all(-1) & np.isfinite(Uw).all(-1) & np.isfinite(dAw).all(-1)
            lib = window_library(Aw, Uw, scaling=self.scaling, valid=valid)
            if self.scaling == "raw":
                ys = np.ones((idx.shape[0], S))
            else:
                sq = np.where(valid[..., None], dAw**2, 0.0).sum(axis=1)
                with np.errstate(invalid="ignore", divide="ignore"):
                    ys = np.sqrt(sq / lib.n_valid[:, None])
                ys = np.where(np.isfinite(ys) & (ys > 0), ys, 1.0)
            y = np.where(valid[..., None], dAw / ys[:, None, :], np.nan)
            path, extra = run_optimizer(self.optimizer, lib.theta, y, settings, self.optimizer_options,
                                        seed=seeds[ch])
            for key in solves:
                solves[key] += path.solves.get(key, 0)

            N = path.n_samples
            with np.errstate(divide="ignore", invalid="ignore"):
                shift = N[:, None] * np.log(ys**2)  # AICc offset from scaled to physical RSS
            best = path.best_coef
            res["coef_scaled_"][ch] = best
            res["coef_"][ch] = lib.physical_coef(np.where(np.isfinite(best), best, 0.0)) * ys[:, :, None]
            res["coef_"][ch] = np.where(np.isfinite(best).all(axis=2, keepdims=True), res["coef_"][ch], np.nan)
            res["support_"][ch] = path.best_support
            res["threshold_"][ch] = extra.get("threshold", path.best_threshold)
            if "inclusion" in extra:
                res["inclusion_"][ch] = extra["inclusion"]
            res["aicc_"][ch] = path.best_aicc + shift
            res["rss_"][ch] = path.best_rss * ys**2
            res["n_terms_"][ch] = path.best_n_terms
            res["selected_"][ch] = path.selected
            res["n_samples_"][ch] = N
            res["cond_"][ch] = path.cond
            res["a_scale_"][ch] = lib.a_scale
            res["u_center_"][ch] = lib.u_center
            res["u_scale_"][ch] = lib.u_scale
            res["u_ref_"][ch] = lib.u_ref
            res["col_scale_"][ch] = lib.col_scale
            res["y_scale_"][ch] = ys
            if self.keep_path:
                res["path_support_"][ch] = path.support
                res["path_aicc_"][ch] = path.aicc + shift[:, :, None]
                res["path_rss_"][ch] = path.rss * (ys**2)[:, :, None]
                res["path_n_terms_"][ch] = path.n_terms
                res["n_iter_"][ch] = path.n_iter
                res["converged_"][ch] = path.converged
                res["path_lower_bound_"][ch] = path.lower_bound
            if self.raw_cond:
                cond_raw[ch] = library_cond(Aw, Uw, scaling="raw", valid=valid)
            reg = window_regimes(lib.theta, y, ys, Aw, valid, path, settings, tau=self.tau,
                                 margin=self.identifiability_margin, order_deletion=self.order_deletion,
                                 fit_tolerance=self.fit_tolerance)
            for key in ("regime", "identifiable", "regimes_seen", "n_equivalent", "order_rms"):
                res[f"{key}_"][ch] = reg[key]

        if "inclusion_" not in res and hasattr(self, "inclusion_"):
            delattr(self, "inclusion_")
        path_names = ("path_support_", "path_aicc_", "path_rss_", "path_n_terms_", "n_iter_", "converged_")
        for name in path_names + ("path_lower_bound_",):
            # No stale path from an earlier fit with keep_path=True.
            if name not in res and hasattr(self, name):
                delattr(self, name)
        for name, value in res.items():
            setattr(self, name, value)
        self.thresholds_ = np.asarray(settings.thresholds)
        self.window_start_ = start
        self.window_end_ = end
        self.cond_raw_ = cond_raw
        self.n_sections_ = S
        self.feature_names_ = feature_names(S)
        self.solves_ = solves
        return self
