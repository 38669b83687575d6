"""The design of the varying-coefficient model: columns B_m(U_s) (A / a_ref)^i z_s^j and their block statistics.

Equation k of :class:`vivbench.models.VaryingCoefficientSINDy` regresses dA_k/dt
on the columns B_m(U_s) (A_k / a_ref)^i z_s^j, i = 0..3 (the powers of the
amplitude), j = 0..J (the powers of the scaled yaw covariate), s over the wind
inputs (one, or every section's with ``wind_input="additive"``), m over the
cubic B-splines (:mod:`vivbench.library.splines`), ordered (i, j, s, m). A row
has only DEGREE + 1 non-zero B-splines per wind input; everything here works
from that local form, and :func:`block_stats` sums the per-block sufficient
statistics (X_b^T X_b, X_b^T y_b, y_b^T y_b) without building the dense rows.

With ``wind_input="sum"`` every wind input shares one curve per order and yaw
power, weighted by its section's weight w_s: the columns are sum_s w_s B_m(U_s)
(A / a_ref)^i z_s^j, i.e. X T with the tying matrix T of :func:`untie`, which maps the
tied coefficients to the untied layout (their statistics: :func:`vivbench.models.varying_stats.tied_statistics`).
"""

from __future__ import annotations

import numpy as np

from vivbench.library.splines import DEGREE, bspline_local, bspline_local_t, first_index

__all__ = ["design_local_t", "local_columns", "spline_design", "input_contributions", "block_stats", "design_rows",
           "held_yaw", "untie", "key_groups", "group_chunks"]


def key_groups(key: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The samples ordered by ``key`` (stable) and its runs of equal values.

    Returns
    -------
    order : ndarray of intp, shape (n,); keys : ndarray, shape (n,), ``key[order]``;
    starts, ends : ndarray of intp, shape (n_groups,), each run's first and past-the-end position in ``order``
    """
    order = np.argsort(key, kind="stable")
    keys = key[order]
    starts = np.flatnonzero(np.r_[True, keys[1:] != keys[:-1]])
    return order, keys, starts, np.r_[starts[1:], key.size]


def group_chunks(starts: np.ndarray, chunk: int):
    """Ranges (g0, g1) of whole groups of :func:`key_groups`, each about ``chunk`` samples (at least one group)."""
    g0 = 0
    while g0 < starts.size:
        g1 = max(int(np.searchsorted(starts, starts[g0] + chunk, side="right")), g0 + 1)
        yield g0, g1
        g0 = g1


def held_yaw(z: np.ndarray | None, yaw_min, yaw_max, shared_inputs: bool) -> np.ndarray | None:
    """The yaw covariate held at the fitted range's ends outside it, as the curves are in the wind.

    Parameters
    ----------
    z : ndarray, shape (n, S), sin^2 psi of each equation's (or, with ``shared_inputs``, each section's) yaw;
        None passes through
    yaw_min, yaw_max : array_like, shape (S,) or None
        The fitted samples' least and largest sin^2 psi per equation (NaN or None: unknown, not held)
    shared_inputs : bool
        Every equation takes every section's yaw (``wind_input`` ``"additive"`` or ``"sum"``): the columns of ``z``
        are sections, and the range over every equation holds them.

    Returns
    -------
    ndarray, shape (n, S), or None
        A polynomial in sin^2 psi says nothing beyond its data: without the hold, a held-out event, a forecast
        or a truth at a larger yaw than the fitted ones would extrapolate it.
    """
    if z is None or yaw_min is None or yaw_max is None:
        return z
    lo, hi = np.asarray(yaw_min, dtype=float), np.asarray(yaw_max, dtype=float)
    if shared_inputs:
        lo, hi = np.full(z.shape[1], np.min(lo)), np.full(z.shape[1], np.max(hi))
    lo, hi = np.where(np.isfinite(lo), lo, -np.inf), np.where(np.isfinite(hi), hi, np.inf)
    return np.clip(z, lo, hi)  # NaN (no yaw) stays NaN


def design_local_t(U: np.ndarray, A: np.ndarray, knots: np.ndarray, a_ref: float, z: np.ndarray | None = None,
                    n_yaw: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The non-zero entries of the rows of :func:`spline_design`, transposed (samples last).

    Each row has DEGREE + 1 non-zero B-splines per wind input, so Q = 4 (J + 1)
    n_in (DEGREE + 1) of its p = 4 (J + 1) n_in M entries are non-zero.

    Returns
    -------
    first : ndarray of intp, shape (n, n_in)
        Each wind input's first non-zero B-spline (:func:`local_columns` gives the columns).
    vals : ndarray, shape (4, J + 1, n_in, DEGREE + 1, n)
        The products of :func:`spline_design` in the same order, ((A / a_ref)^i z_s^j) B_{first_s + a}(U_s).
    """
    U2 = np.asarray(U, dtype=float).reshape(np.shape(U)[0], -1)
    n, n_in = U2.shape
    first = np.empty((n, n_in), dtype=np.intp)
    B = np.empty((n_in, DEGREE + 1, n))
    for s_ in range(n_in):  # a few wind inputs
        first[:, s_], B[s_] = bspline_local_t(U2[:, s_], knots)
    Apow = (A / a_ref)[None, :] ** np.arange(4)[:, None]  # (4, n)
    Z2 = np.ones_like(U2) if z is None else np.asarray(z, dtype=float).reshape(n, -1)
    Zpow = Z2.T[None, :, :] ** np.arange(n_yaw + 1)[:, None, None]  # (J + 1, n_in, n)
    return first, Apow[:, None, None, None, :] * Zpow[None, :, :, None, :] * B[None, None, :, :, :]


def local_columns(first: np.ndarray, M: int, n_yaw: int) -> np.ndarray:
    """Columns of the local entries of :func:`design_local_t`, shape (n, Q), ordered as its values.

    Column of (i, j, s, first_s + a): ((i (J + 1) + j) n_in + s) M + first_s + a.
    """
    n, n_in = first.shape
    base = ((np.arange(4)[:, None, None] * (n_yaw + 1) + np.arange(n_yaw + 1)[None, :, None]) * n_in
            + np.arange(n_in)[None, None, :]) * M  # (4, J + 1, n_in)
    return (base[None, :, :, :, None] + first[:, None, None, :, None] + np.arange(DEGREE + 1)).reshape(n, -1)


def spline_design(U: np.ndarray, A: np.ndarray, knots: np.ndarray, a_ref: float, z: np.ndarray | None = None,
            n_yaw: int = 0) -> np.ndarray:
    """Columns B_m(U_s) (A / a_ref)^i z_s^j, ordered (i, j, s, m); shape (n, 4 (n_yaw + 1) n_in M).

    ``U`` is shape (n,) (one wind, n_in = 1) or (n, n_in) (one column per
    section whose wind enters additively, ``wind_input="additive"``); ``z``,
    the scaled yaw covariate (sin^2 psi over its reference) of the same shape,
    is used for j = 1..n_yaw. Built from the local form (:func:`design_local_t`);
    a wind input that is not finite makes its columns NaN.
    """
    first, vals = design_local_t(U, A, knots, a_ref, z, n_yaw)
    U2 = np.asarray(U, dtype=float).reshape(np.shape(U)[0], -1)
    n, n_in = U2.shape
    M = knots.size - DEGREE - 1
    X = np.zeros((n, 4 * (n_yaw + 1) * n_in * M))
    np.put_along_axis(X, local_columns(first, M, n_yaw), vals.reshape(-1, n).T, axis=1)
    # As the dense product: a non-finite factor makes every column it multiplies NaN, not only the local ones.
    Z2 = np.ones_like(U2) if z is None else np.asarray(z, dtype=float).reshape(n, -1)
    factor = ((A / a_ref)[:, None, None, None] ** np.arange(4)[:, None, None]
              * Z2[:, None, None, :] ** np.arange(n_yaw + 1)[:, None] * np.where(np.isfinite(U2), 1.0, np.nan)[:, None, None, :])
    bad = ~np.isfinite(factor)  # (n, 4, J + 1, n_in)
    if bad.any():
        X.reshape(n, 4, n_yaw + 1, n_in, M)[bad] = np.nan
    return X


def input_contributions(U: np.ndarray, A: np.ndarray, knots: np.ndarray, a_ref: float, z: np.ndarray | None,
                         n_yaw: int, c: np.ndarray) -> np.ndarray:
    """Each wind input's share of the fitted value X c, shape (n_in, n) (their sum is :func:`spline_design` @ c).

    From the non-zero B-splines (:func:`bspline_local`): Q products per sample instead of p.
    """
    U2 = np.asarray(U, dtype=float).reshape(np.shape(U)[0], -1)
    n, n_in = U2.shape
    M = knots.size - DEGREE - 1
    C = np.asarray(c).reshape(4, n_yaw + 1, n_in, M)
    Apow = (A / a_ref)[None, :] ** np.arange(4)[:, None]  # (4, n)
    Z2 = np.ones_like(U2) if z is None else np.asarray(z, dtype=float).reshape(n, -1)
    out = np.empty((n_in, n))
    for s_ in range(n_in):  # a few wind inputs
        first, B = bspline_local_t(U2[:, s_], knots)
        # sum_a B_a C[i, j, s, first + a]: each (order, yaw power) curve of this input at the samples
        curve = sum(C[:, :, s_].take(first + a, axis=-1) * B[a] for a in range(DEGREE + 1))  # (4, J + 1, n)
        w = Apow[:, None, :] * Z2[:, s_][None, None, :] ** np.arange(n_yaw + 1)[None, :, None]
        out[s_] = (w * curve).sum(axis=(0, 1))
    return out


def block_stats(U: np.ndarray, A: np.ndarray, y: np.ndarray, block: np.ndarray, n_blocks: int,
                 knots: np.ndarray, a_ref: float, z: np.ndarray | None = None, n_yaw: int = 0,
                 weight: np.ndarray | None = None, chunk: int = 65_536):
    """Per-block sufficient statistics of the design :func:`spline_design`.

    Returns X_b^T X_b (n_blocks, p, p), X_b^T y_b (n_blocks, p), y_b^T y_b and
    the sample counts (n_blocks,). With ``weight`` (n,) the statistics are those
    of the weighted least squares (rows and target times sqrt(weight)).

    Why not the dense design: a row has only Q = 4 (J + 1) n_in (DEGREE + 1) of its
    p entries non-zero (Q = 96 of p = 240 with three winds and the yaw), and the
    samples of a block whose winds lie in the same knot intervals share those
    columns. The samples are grouped by (block, knot intervals); each group adds
    one dense Q x Q product V_g^T V_g (BLAS) to its block's Gram at its columns:
    about (p / Q)^2 fewer operations than X_b^T X_b, no p-wide rows built, and
    memory of ``chunk`` local rows. The sums equal the dense ones up to rounding.
    """
    U2 = np.asarray(U, dtype=float).reshape(np.shape(U)[0], -1)
    n, n_in = U2.shape
    M = knots.size - DEGREE - 1
    p = 4 * (n_yaw + 1) * n_in * M
    z2 = None if z is None else np.asarray(z, dtype=float).reshape(n, -1)
    sw = None if weight is None else np.sqrt(weight)
    yw = y if sw is None else y * sw
    # y^T y and the counts as before: running sums in block order
    order = np.argsort(block, kind="stable")
    bounds = np.searchsorted(block[order], np.arange(n_blocks + 1))
    cy = np.concatenate([[0.0], np.cumsum(yw[order] ** 2)])
    # group key: the block, then each wind input's knot interval (M - DEGREE of them)
    key = np.asarray(block, dtype=np.int64)
    for s_ in range(n_in):
        key = key * (M - DEGREE) + first_index(U2[:, s_], knots)
    order, _keys, starts, ends = key_groups(key)
    G = np.zeros((n_blocks, p, p))
    b = np.zeros((n_blocks, p))
    for g0, g1 in group_chunks(starts, chunk):  # chunks of whole groups, each a few tens of thousands of samples
        sel = order[starts[g0]:ends[g1 - 1]]
        first, vals = design_local_t(U2[sel], A[sel], knots, a_ref, None if z2 is None else z2[sel], n_yaw)
        vals = vals.reshape(-1, sel.size)  # (Q, samples of the chunk)
        ysel = yw[sel]
        if sw is not None:
            vals *= sw[sel]
        off = starts[g0]
        glo, ghi = starts[g0:g1] - off, ends[g0:g1] - off
        gcols = local_columns(first[glo], M, n_yaw)  # every group's columns at once
        gblock = block[sel[glo]]
        for g in range(g1 - g0):  # one BLAS product per group (a few per block), not per sample
            V, c, j = vals[:, glo[g]:ghi[g]], gcols[g], gblock[g]
            G[j, c[:, None], c] += V @ V.T
            b[j, c] += V @ ysel[glo[g]:ghi[g]]
    return G, b, cy[bounds[1:]] - cy[bounds[:-1]], np.diff(bounds)


def design_rows(U: np.ndarray, z: np.ndarray | None, knots: np.ndarray, n_basis: np.ndarray, n_coef: int, n_yaw: int,
                n_in: int) -> tuple[np.ndarray, np.ndarray]:
    """The non-zero entries of every equation's design row in the layout of the stacked coefficients.

    Parameters
    ----------
    U : ndarray, shape (n, S), m/s
        Each equation's wind input (every section's with ``n_in`` = S).
    z : ndarray, shape (n, S), or None
        The yaw covariate sin^2(psi) (unscaled: the stacked coefficients are those of (sin^2 psi)^j).
    knots : ndarray, shape (S, M_max + DEGREE + 1), m/s (NaN-padded); n_basis : ndarray of int, shape (S,)
    n_coef : int
        Coefficients per curve and yaw power in the stacked layout (n_in M_max).
    n_yaw : int
        Yaw powers J.
    n_in : int
        Wind inputs per equation.

    Returns
    -------
    cols : ndarray of intp, shape (n, S, (DEGREE + 1) (J + 1) n_in)
        Entry j n_coef + s M_k + first + a: the coefficient of B_{first + a}(U_s) (sin^2 psi_s)^j.
    vals : ndarray, shape (n, S, (DEGREE + 1) (J + 1) n_in), NaN where the curves are undefined
    """
    n, S = U.shape[0], knots.shape[0]
    cols = np.empty((n, S, n_yaw + 1, n_in, DEGREE + 1), dtype=np.intp)
    vals = np.empty(cols.shape)
    a = np.arange(DEGREE + 1)
    for k in range(S):  # a few sections
        M = int(n_basis[k])
        kn = knots[k, :M + DEGREE + 1]
        for s_ in range(n_in):  # additive: each section's wind has its own M columns
            u = s_ if n_in > 1 else k
            first, picked = bspline_local(U[:, u], kn)  # the row's only non-zero B-splines
            idx = first[:, None] + a
            zp = np.ones((n, 1)) if z is None else z[:, u, None] ** np.arange(n_yaw + 1)
            cols[:, k, :, s_] = idx[:, None, :] + s_ * M + n_coef * np.arange(n_yaw + 1)[:, None]
            vals[:, k, :, s_] = zp[:, :, None] * picked[:, None, :]
    return cols.reshape(n, S, -1), vals.reshape(n, S, -1)


def untie(c: np.ndarray, weights: np.ndarray, n_yaw: int, M: int) -> np.ndarray:
    """Tied coefficients (..., 4 (n_yaw + 1) M) as those of one wind input per section, T c: shape (..., 4 (n_yaw + 1) S M)."""
    w = np.asarray(weights, dtype=float)
    IJ = 4 * (n_yaw + 1)
    c = np.asarray(c, dtype=float)
    out = c.reshape(c.shape[:-1] + (IJ, 1, M)) * w[:, None]
    return out.reshape(c.shape[:-1] + (IJ * w.size * M,))
