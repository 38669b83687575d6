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
from vivbench.core.errors import InputError


__all__ = ["DEFAULT_THRESHOLDS", "SOLVERS", "StlsqSettings", "StlsqPath", "aicc", "stlsq_path"]

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
            raise InputError(f"thresholds must be a non-empty sequence of finite values >= 0; got {self.thresholds!r}")
        if np.any(np.diff(th) <= 0):
            raise InputError("thresholds must be strictly increasing")
        object.__setattr__(self, "thresholds", tuple(float(x) for x in th))
        if not (np.isfinite(self.alpha) and self.alpha >= 0):
            raise InputError(f"alpha must be finite and >= 0; got {self.alpha}")
        if isinstance(self.max_iter, bool) or not isinstance(self.max_iter, (int, np.integer)) or self.max_iter < 1:
            raise InputError(f"max_iter must be an integer >= 1; got {self.max_iter!r}")
        if not (np.isfinite(self.residual_floor) and 0 <= self.residual_floor < 1):
            raise InputError(f"residual_floor must lie in [0, 1); got {self.residual_floor}")
        if self.refit_rcond is not None and not (np.isfinite(self.refit_rcond) and 0 <= self.refit_rcond < 1):
            raise InputError(f"refit_rcond must be None or lie in [0, 1); got {self.refit_rcond}")
        if self.solver not in SOLVERS:
            raise InputError(f"solver must be one of {SOLVERS}; got {self.solver!r}")


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


def empty_path(W: int, q: int, T: int, p: int) -> dict:
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


def as_batches(theta, y) -> tuple[np.ndarray, np.ndarray]:
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


