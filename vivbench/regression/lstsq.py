"""Batched least-squares kernels of the STLSQ path: nested QR and Cholesky factors, truncated refits.

See :mod:`vivbench.regression.stlsq` for the numerics (why QR, when Cholesky, the
nesting of active sets along a threshold path, LAPACK's truncated SVD refit).
"""

from __future__ import annotations

import functools

import numpy as np
from scipy.linalg.lapack import dgeqrf as _dgeqrf
from scipy.linalg.lapack import dgelsd as _dgelsd
from scipy.linalg.lapack import dgelsd_lwork as _dgelsd_lwork
from scipy.linalg.lapack import dtrcon as _dtrcon
from scipy.linalg.lapack import dtrtrs as _dtrtrs
from vivbench.regression.settings import StlsqSettings

__all__ = ["NestedFactors", "as_batches", "empty_path"]

# Granularity of the QR sizes of chains (fewer, larger batches).
_BUCKET = 8
# Largest condition-number bound of a ridge matrix solved by normal equations
# (relative error about this times eps, ~1e-8).
_RIDGE_COND_MAX = 1e8


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


class NestedFactors:
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

