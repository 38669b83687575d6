"""Penalised least squares from sufficient statistics: (G + lambda P + r I) c = b, batched.

Every quadratic-penalty fit of the models and the analyses (P-spline coefficient
curves, the change scan's refits before and after a split, the grey-box's
equation-error starts) solves the normal equations of

    ||y - X c||^2 + lambda c^T P c

from the statistics G = X^T X, b = X^T y, y^T y, on a subset of the columns
(``keep``), with a small ridge r I that keeps a rank-deficient G solvable
(by default r = 1e-10 trace(G_kk) / q, relative to G's mean diagonal). The
solves are batched over any leading axes (folds, events, bootstrap replicates,
penalties); nothing loops over samples.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg.lapack import dposv

__all__ = ["penalty_scale", "penalised_solve", "quadratic_error", "penalised_rss", "held_out_errors", "spd_solve",
           "DEFAULT_RIDGE"]

#: Default ridge, relative to the mean diagonal of the kept block of G.
DEFAULT_RIDGE = 1e-10


def penalty_scale(G: np.ndarray, P: np.ndarray) -> np.ndarray:
    """trace(G) / trace(P), shape G.shape[:-2]: turns a relative penalty into lambda independent of the data's size.

    Parameters
    ----------
    G : ndarray, shape (..., p, p)
    P : ndarray, shape (p, p)
    """
    return np.trace(G, axis1=-2, axis2=-1) / max(float(np.trace(P)), 1e-300)


def penalised_solve(G: np.ndarray, b: np.ndarray, P: np.ndarray, lam, keep: np.ndarray | None = None, *,
                    ridge: float = DEFAULT_RIDGE, relative_ridge: bool = True) -> np.ndarray:
    """The penalised least-squares coefficients on the kept columns: (G_kk + lam P_kk + r I) c_k = b_k.

    Parameters
    ----------
    G : ndarray, shape (..., p, p)
        X^T X of each problem.
    b : ndarray, shape (..., p)
        X^T y.
    P : ndarray, shape (p, p)
        The penalty matrix (e.g. D^T D of a difference penalty).
    lam : float or ndarray broadcastable to G.shape[:-2]
        Absolute penalty weights (see :func:`penalty_scale` for relative ones).
    keep : ndarray of bool, shape (p,), optional
        The columns fitted (default all); the others' coefficients are zero.
    ridge : float
        r, or r relative to trace(G_kk) / q with ``relative_ridge`` (q kept columns).
    relative_ridge : bool

    Returns
    -------
    ndarray, shape broadcast(G.shape[:-2], lam.shape) + (p,)
    """
    G, b, P = np.asarray(G, dtype=float), np.asarray(b, dtype=float), np.asarray(P, dtype=float)
    lam = np.asarray(lam, dtype=float)
    if keep is None:
        Gk, bk, Pk, q = G, b, P, P.shape[0]
    else:
        idx = np.flatnonzero(keep)
        Gk, bk, Pk, q = G[..., idx[:, None], idx], b[..., idx], P[idx[:, None], idx], idx.size
    if relative_ridge:
        r = ridge * (np.trace(Gk, axis1=-2, axis2=-1) / max(q, 1))
    else:
        r = np.asarray(ridge, dtype=float)
    H = Gk + lam[..., None, None] * Pk + r[..., None, None] * np.eye(q)
    ck = np.linalg.solve(H, np.broadcast_to(bk[..., None], H.shape[:-1] + (1,)))[..., 0]
    if keep is None:
        return ck
    out = np.zeros(ck.shape[:-1] + (G.shape[-1],))
    out[..., idx] = ck
    return out


def quadratic_error(c: np.ndarray, G: np.ndarray, b: np.ndarray, yy) -> np.ndarray:
    """||y - X c||^2 from the statistics: c^T G c - 2 c^T b + y^T y, batched over the leading axes.

    Parameters
    ----------
    c : ndarray, shape (..., p); G : ndarray, shape (..., p, p); b : ndarray, shape (..., p); yy : array_like, (...)
    """
    return (np.einsum("...p,...pq,...q->...", c, G, c) - 2.0 * np.einsum("...p,...p->...", c, b)
            + np.asarray(yy, dtype=float))


def penalised_rss(G: np.ndarray, b: np.ndarray, yy: np.ndarray, P: np.ndarray, penalty: float,
                  keep: np.ndarray) -> np.ndarray:
    """Residual sum of squares of the penalised fit to pooled statistics, batched.

    Parameters
    ----------
    G : ndarray, shape (..., p, p); b : ndarray, shape (..., p); yy : ndarray, shape (...)
        Summed statistics of the samples fitted together (e.g. the events on one side of a split).
    P : ndarray, shape (p, p); penalty : float, relative (times trace(G) / trace(P) of each fit)
    keep : ndarray of bool, shape (p,)

    Returns
    -------
    ndarray, shape (...): ||y - X c||^2 at the penalised solution c (standardised units).
    """
    G, b, yy = np.asarray(G, dtype=float), np.asarray(b, dtype=float), np.asarray(yy, dtype=float)
    idx = np.flatnonzero(keep)
    c = penalised_solve(G, b, P, penalty * penalty_scale(G, P), keep)[..., idx]
    return quadratic_error(c, G[..., idx[:, None], idx], b[..., idx], yy)


def held_out_errors(G_total: np.ndarray, b_total: np.ndarray, G: np.ndarray, b: np.ndarray, yy: np.ndarray,
                    P: np.ndarray, lam, keep: np.ndarray | None = None) -> np.ndarray:
    """Each group's squared error under the penalised fit to every other group (e.g. leave one event out).

    Parameters
    ----------
    G_total, b_total : ndarray, shapes (p, p), (p,)
        The statistics summed over the groups fitted (which hold the groups left out).
    G, b, yy : ndarray, shapes (E, p, p), (E, p), (E,)
        Each group's statistics.
    P : ndarray, shape (p, p)
    lam : ndarray, shape (L,)
        Absolute penalties.
    keep : ndarray of bool, shape (p,), optional

    Returns
    -------
    ndarray, shape (E, L)
    """
    lam = np.asarray(lam, dtype=float).reshape(-1)
    G, b, yy = np.asarray(G, dtype=float), np.asarray(b, dtype=float), np.asarray(yy, dtype=float)
    G_total, b_total = np.asarray(G_total, dtype=float), np.asarray(b_total, dtype=float)
    if keep is not None:  # the kept columns only: the others' coefficients are zero
        idx = np.flatnonzero(keep)
        G_total, b_total, P = G_total[idx[:, None], idx], b_total[idx], np.asarray(P)[idx[:, None], idx]
        G, b = G[:, idx[:, None], idx], b[:, idx]
    G_fit, b_fit = G_total[None] - G, b_total[None] - b  # (E, q, q), (E, q): each group's fit without it
    out = np.empty((G.shape[0], lam.size))
    for j, lam_j in enumerate(lam):  # the penalties (a few): each a batch of E solves of q x q
        out[:, j] = quadratic_error(penalised_solve(G_fit, b_fit, P, lam_j), G, b, yy)
    return out


def spd_solve(H: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Solutions of the symmetric positive definite systems H x = b, H (N, q, q), b (N, q); returns (N, q).

    Cholesky (LAPACK posv, one call per system: about 1.5 times faster than the LU of
    ``np.linalg.solve`` at q ~ 100); a system that is not numerically positive definite is solved by LU.
    """
    x = np.empty_like(b)
    for i in range(H.shape[0]):  # one LAPACK call per system (systems, not samples)
        # H[i] is symmetric: its transpose is the same matrix in the Fortran order LAPACK takes.
        _, x[i], info = dposv(H[i].T, b[i], lower=1)
        if info != 0:
            x[i] = np.linalg.solve(H[i], b[i])
    return x
