"""Cubic B-splines on uniform knots (P-splines): knots, the basis and its local form, the roughness penalty.

The basis of every spline curve of the wind in the models (the varying-coefficient
model's coefficient curves, the grey-box's aerodynamic functions): M B-splines
of degree ``DEGREE`` on M - degree uniform intervals, the boundary knots
repeated at the same spacing (the P-spline convention of Eilers & Marx 1996),
evaluated by the Cox-de Boor recursion vectorised over the samples, and the
squared difference penalty D^T D of the coefficients.
"""

from __future__ import annotations

import numpy as np

from vivbench.core.errors import InputError

__all__ = ["DEGREE", "uniform_knots", "bspline_local", "bspline_local_t", "uniform_cubic_local_t", "first_index",
           "bspline_basis", "difference_penalty"]

#: Spline degree (cubic).
DEGREE = 3


def uniform_knots(lo: float, hi: float, n_basis: int, degree: int = DEGREE) -> np.ndarray:
    """Knot vector of ``n_basis`` B-splines of ``degree`` on uniform intervals over [lo, hi].

    Returns
    -------
    ndarray, shape (n_basis + degree + 1,), m/s
        The boundary knots are repeated ``degree`` times beyond [lo, hi] at the
        same spacing (P-spline convention), so every interval is alike.
    """
    n_int = n_basis - degree
    if n_int < 1:
        raise InputError(f"n_basis must exceed the degree {degree}; got {n_basis}")
    if not hi > lo:
        hi = lo + 1.0  # a campaign at one wind speed: any unit interval
    h = (hi - lo) / n_int
    return lo + h * np.arange(-degree, n_int + degree + 1)


def bspline_local(U: np.ndarray, knots: np.ndarray, degree: int = DEGREE) -> tuple[np.ndarray, np.ndarray]:
    """The non-zero B-splines at each U (local form of :func:`bspline_basis`), U clipped to the base interval.

    The Cox-de Boor recursion, vectorised over the samples, with the same
    operations in the same order as scipy's ``BSpline.design_matrix`` (so the
    values are the same to the bit)
    but without building a sparse matrix per call.

    Parameters
    ----------
    U : ndarray, shape (n,), m/s (NaN allowed: that row's values are NaN, its first index 0)
    knots : ndarray, shape (M + degree + 1,), non-decreasing with distinct base-interval knots

    Returns
    -------
    first : ndarray of intp, shape (n,)
        Index of the first non-zero B-spline (0..M - degree - 1).
    vals : ndarray, shape (n, degree + 1)
        B_{first + a}(U), a = 0..degree.
    """
    first, h = bspline_local_t(U, knots, degree)
    return first, h.T


def bspline_local_t(U: np.ndarray, knots: np.ndarray, degree: int = DEGREE) -> tuple[np.ndarray, np.ndarray]:
    """:func:`bspline_local` with the values transposed, shape (degree + 1, n): every operation runs along the samples.

    Returns
    -------
    first : ndarray of intp, shape (n,)
    vals : ndarray, shape (degree + 1, n)
    """
    U = np.asarray(U, dtype=float).ravel()
    knots = np.asarray(knots, dtype=float)
    n_b = knots.size - degree - 1
    lo, hi = knots[degree], knots[n_b]
    ok = np.isfinite(U)
    x = np.clip(np.where(ok, U, lo), lo, hi)
    ell = first_index(x, knots, degree) + degree
    h = np.zeros((degree + 1, x.size))
    h[0] = 1.0
    for j in range(1, degree + 1):  # the recursion's degrees, not samples
        hh = h[:j].copy()
        h[0] = 0.0
        for m in range(1, j + 1):
            xb, xa = knots[ell + m], knots[ell + m - j]
            w = hh[m - 1] / (xb - xa)
            h[m - 1] += w * (xb - x)
            h[m] = w * (x - xa)
    if not ok.all():
        h[:, ~ok] = np.nan
        return np.where(ok, ell - degree, 0), h
    return ell - degree, h


def uniform_cubic_local_t(U: np.ndarray, knots: np.ndarray,
                          first: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`bspline_local_t` of cubic B-splines on uniform knots (:func:`uniform_knots`), in closed form.

    With t = (x - t_l) / (t_(l+1) - t_l) in the knot interval of x, the four non-zero uniform cubic
    B-splines are (1 - t)^3 / 6, (3 t^3 - 6 t^2 + 4) / 6, (-3 t^3 + 3 t^2 + 3 t + 1) / 6 and t^3 / 6:
    the recursion's values to rounding, in a few operations per sample. Only for finite U.
    ``first``, :func:`first_index` of U when the caller has it already, is not computed again.

    Returns
    -------
    first : ndarray of intp, shape (n,)
    vals : ndarray, shape (4, n)
    """
    U = np.asarray(U, dtype=float).ravel()
    knots = np.asarray(knots, dtype=float)
    n_b = knots.size - DEGREE - 1
    x = np.clip(U, knots[DEGREE], knots[n_b])
    first = first_index(x, knots) if first is None else np.asarray(first)
    left = knots[first + DEGREE]
    t = (x - left) / (knots[first + DEGREE + 1] - left)
    t2 = t * t
    t3 = t2 * t
    s = 1.0 - t
    vals = np.empty((DEGREE + 1, U.size))
    vals[0] = s * s * s / 6.0
    vals[1] = (3.0 * t3 - 6.0 * t2 + 4.0) / 6.0
    vals[2] = (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0
    vals[3] = t3 / 6.0
    return first, vals


def first_index(U: np.ndarray, knots: np.ndarray, degree: int = DEGREE) -> np.ndarray:
    """Index of the first non-zero B-spline at each U (clipped; NaN: 0), shape (n,) intp.

    The knot interval t[ell] <= x < t[ell + 1], the last one at the right end (as scipy's
    ``find_interval``), minus ``degree``.
    """
    n_b = knots.size - degree - 1
    x = np.clip(np.nan_to_num(np.asarray(U, dtype=float), nan=knots[degree]), knots[degree], knots[n_b])
    return np.clip(np.searchsorted(knots, x, side="right") - 1, degree, n_b - 1) - degree


def bspline_basis(U: np.ndarray, knots: np.ndarray, degree: int = DEGREE) -> np.ndarray:
    """Dense B-spline design matrix, U clipped to the knots' base interval.

    Parameters
    ----------
    U : ndarray, shape (n,), m/s (NaN allowed: that row is NaN)
    knots : ndarray, shape (M + degree + 1,)

    Returns
    -------
    ndarray, shape (n, M)
        The same values as scipy's ``BSpline.design_matrix`` (:func:`bspline_local`).
    """
    first, vals = bspline_local(U, knots, degree)
    n = first.size
    B = np.zeros((n, knots.size - degree - 1))
    B[np.arange(n)[:, None], first[:, None] + np.arange(degree + 1)] = vals
    B[np.isnan(vals[:, 0])] = np.nan
    return B


def difference_penalty(n_basis: int, order: int = 2) -> np.ndarray:
    """D^T D for the ``order``-th difference matrix D of ``n_basis`` coefficients, shape (M, M)."""
    D = np.diff(np.eye(n_basis), n=order, axis=0)
    return D.T @ D
