"""Window libraries in a well-conditioned basis that spans exactly the physical library.

The physical library of one section (:mod:`vivbench.core.terms`) is the 23 monomials
A^i U^j, i = 0..3, j = 0..5, (i, j) != (0, 0). Inside a 50 s window U is
nearly constant, so U, U^2, ..., U^5 are nearly parallel and the raw window
library has condition numbers up to 1e17. This module evaluates, per window,
a different basis of the *same* 23-dimensional function space per section,
regresses in it, and maps coefficients back to the physical library exactly
(an invertible block-diagonal linear map, one 23 x 23 block per section).

Bases (``scaling``)
-------------------
``"raw"``
    The physical library itself; the map is the identity.
``"normalized"``
    (A/a)^i (U/u_ref)^j with constants a = RMS(A), u_ref = RMS(U), then every
    column divided by its RMS. A diagonal rescaling: it spans the physical
    space exactly but does nothing for the collinearity of U^j on a window
    where U is nearly constant (a diagonal scaling cannot make nearly parallel
    columns less parallel), so its condition number stays huge.
``"scaled"`` (default)
    U is centred: with U~ = (U - c)/s (c, s the window mean and standard
    deviation of U) and A~ = A/a,

    - for i >= 1: A~^i U~^j, j = 0..5;
    - for i = 0:  (U/u_ref) U~^(j-1), j = 1..5;

    then every column divided by its RMS. Centring U alone would be wrong:
    the i = 0 block U~^j = ((U - c)/s)^j contains the constant (-c/s)^j, and
    {U~^j, j = 1..5} spans the polynomials of degree <= 5 vanishing at U = c,
    whereas the physical {U^j, j = 1..5} spans those vanishing at U = 0 - a
    different space (the physical library has no constant column). The factor
    U in the i = 0 block keeps the span {U q(U): deg q <= 4} = {U, ..., U^5}
    exactly, and since U/u_ref is close to 1 on a window the block is as well
    conditioned as the centred monomials. For i >= 1 the factor A^i already
    vanishes at A = 0, so centring U there changes the basis but not the span.
    A is scaled but not centred, so a scaled term's power of A equals the
    physical one: the regime signature (the order of A, docs/concepts.md (regimes)) of every
    scaled term is that of the physical terms it maps to. Consequently the
    near-collinearity of A, A^2, A^3 on a plateau (A nearly constant) remains
    (it is the non-identifiability of docs/concepts.md (regimes), not an artefact of the
    basis) and shows in the condition number.

Scaling by constants (a, s, u_ref) never changes the condition number after
column normalisation; they only keep the numbers in range. Only the centring
of U does real work, and it does not suffice for three sections: scaled, one
section's 23 terms are orders of magnitude better conditioned than raw or
normalized ones, but all 69 terms of three sections stay ill-conditioned.
That floor is not an artefact of the basis: within a window each section's
U q(U) (deg q <= 4) approximates a constant to about (s/c)^5, so the three
sections' constant-like terms are nearly interchangeable in any basis of the
physical space. The regression engine copes with it
(:mod:`vivbench.regression.stlsq`).

All three bases span exactly the physical space, so a model fitted in any of
them is a physical model: ``to_physical @ coef`` is exact in exact arithmetic.
In floating point, evaluating the physical model suffers cancellation of order
eps * (c/s)^5 (the physical coefficients are large and of alternating sign);
evaluate with the window basis where that matters.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import comb

import numpy as np

from vivbench.core.terms import section_exponents
from vivbench.core.errors import InputError

__all__ = [
    "SCALINGS",
    "WindowLibrary",
    "window_library",
    "library_cond",
    "condition_number",
    "basis_orders",
    "order_contributions_basis",
]

SCALINGS = ("raw", "normalized", "scaled")

_EXPONENTS = section_exponents()
_N_TERMS = _EXPONENTS.shape[0]


@dataclass(frozen=True, kw_only=True)
class WindowLibrary:
    """A window library in the chosen basis and its exact map to physical coefficients.

    Leading dimensions ``...`` are batch dimensions (for example windows);
    ``n`` samples, ``S`` sections, ``p = 23 S`` terms.

    Attributes
    ----------
    theta : ndarray, shape (..., n, p)
        Library in the chosen basis, columns of unit RMS over the valid
        samples (``"raw"``: physical units, not normalised). Rows of invalid
        samples are NaN.
    to_physical : ndarray, shape (..., p, p)
        Block-diagonal map: coefficients ``xi`` on ``theta`` are the physical
        coefficients ``to_physical @ xi`` on :func:`vivbench.core.terms.evaluate_library`,
        i.e. ``theta == evaluate_library(A, U) @ to_physical`` on valid rows.
    valid : ndarray of bool, shape (..., n)
        Samples used (finite A and U, and the caller's mask).
    n_valid : ndarray of int, shape (...)
    col_scale : ndarray, shape (..., p)
        RMS of each basis column before normalisation (1 for ``"raw"``).
    a_scale, u_center, u_scale, u_ref : ndarray, shape (..., S)
        Constants of the basis: a (m), c (m/s), s (m/s), u_ref (m/s).
    scaling : str
    """

    theta: np.ndarray
    to_physical: np.ndarray
    valid: np.ndarray
    n_valid: np.ndarray
    col_scale: np.ndarray
    a_scale: np.ndarray
    u_center: np.ndarray
    u_scale: np.ndarray
    u_ref: np.ndarray
    scaling: str

    def physical_coef(self, coef: np.ndarray) -> np.ndarray:
        """Map coefficients on ``theta`` to the physical library.

        Parameters
        ----------
        coef : ndarray, shape (..., q, p)
            One row per equation (target); batch dimensions as ``theta``'s.

        Returns
        -------
        ndarray, shape (..., q, p)
            Coefficients on ``evaluate_library(A, U)``.
        """
        return np.matmul(coef, np.swapaxes(self.to_physical, -1, -2))


def _masked_rms(x: np.ndarray, valid: np.ndarray, n_valid: np.ndarray) -> np.ndarray:
    """RMS over the sample axis (-2) of ``x`` (..., n, m) restricted to ``valid`` (..., n)."""
    sq = np.where(valid[..., None], x * x, 0.0).sum(axis=-2)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.sqrt(sq / n_valid[..., None])


def _positive_or_one(x: np.ndarray) -> np.ndarray:
    # A zero or undefined scale (all-zero or empty data) leaves the variable
    # unscaled instead of dividing by zero.
    return np.where(np.isfinite(x) & (x > 0), x, 1.0)


def _basis_plan(scaling: str):
    """Per term m: (power of A, U factor flag delta, power e of the U variable)."""
    i = _EXPONENTS[:, 0]
    j = _EXPONENTS[:, 1]
    delta = ((i == 0) & (scaling == "scaled")).astype(int)
    return i, delta, j - delta


def window_library(
    A: np.ndarray,
    U: np.ndarray,
    *,
    scaling: str = "scaled",
    valid: np.ndarray | None = None,
) -> WindowLibrary:
    """Evaluate the library of each window in a well-conditioned basis.

    Parameters
    ----------
    A : ndarray, shape (..., n, S), m
        Amplitudes of the S sections over each window.
    U : ndarray, shape (..., n, S), m/s
        Mean wind speeds over each window.
    scaling : {"scaled", "normalized", "raw"}
        Basis, see the module docstring.
    valid : ndarray of bool, shape (..., n), optional
        Samples to use; combined with finiteness of A and U. Scales are
        computed over valid samples only.

    Returns
    -------
    WindowLibrary
    """
    if scaling not in SCALINGS:
        raise InputError(f"scaling must be one of {SCALINGS}; got {scaling!r}")
    A = np.asarray(A, dtype=float)
    U = np.asarray(U, dtype=float)
    if A.shape != U.shape or A.ndim < 2:
        raise ValueError(f"A and U must have the same shape (..., n_samples, n_sections); got {A.shape} and {U.shape}")
    ok = np.isfinite(A).all(axis=-1) & np.isfinite(U).all(axis=-1)
    if valid is not None:
        valid = np.asarray(valid, dtype=bool)
        if valid.shape != A.shape[:-1]:
            raise ValueError(f"valid must have shape {A.shape[:-1]} (A without its section axis); got {valid.shape}")
        ok &= valid
    n_valid = ok.sum(axis=-1)
    n_sections = A.shape[-1]
    batch = A.shape[:-2]
    Af = np.where(ok[..., None], A, 0.0)
    Uf = np.where(ok[..., None], U, 0.0)

    ones = np.ones(batch + (n_sections,))
    if scaling == "raw":
        a, c, s, u_ref = ones, np.zeros_like(ones), ones, ones
    else:
        a = _positive_or_one(_masked_rms(Af, ok, n_valid))
        u_ref = _positive_or_one(_masked_rms(Uf, ok, n_valid))
        if scaling == "normalized":
            c, s = np.zeros_like(ones), u_ref
        else:
            with np.errstate(invalid="ignore", divide="ignore"):
                c = Uf.sum(axis=-2) / n_valid[..., None]
            c = np.where(np.isfinite(c), c, 0.0)
            s = _positive_or_one(_masked_rms(Uf - c[..., None, :], ok, n_valid))

    i_pow, delta, e_pow = _basis_plan(scaling)
    At = Af / a[..., None, :]
    Vt = (Uf - c[..., None, :]) / s[..., None, :]
    # Left factor per A power: A~^i for i >= 1; for i = 0 either 1 or U/u_ref.
    left = [Uf / u_ref[..., None, :] if scaling == "scaled" else np.ones_like(At), At, At * At, At * At * At]
    vpow = [np.ones_like(Vt)]
    for _ in range(5):
        vpow.append(vpow[-1] * Vt)
    L = np.stack(left, axis=-1)  # (..., n, S, 4)
    V = np.stack(vpow, axis=-1)  # (..., n, S, 6)
    cols = L[..., i_pow] * V[..., e_pow]  # (..., n, S, 23)
    cols = cols.reshape(cols.shape[:-2] + (n_sections * _N_TERMS,))

    p = n_sections * _N_TERMS
    if scaling == "raw":
        r = np.ones(batch + (p,))
    else:
        r = _positive_or_one(_masked_rms(cols, ok, n_valid))
    theta = np.where(ok[..., None], cols / r[..., None, :], np.nan)

    to_phys = _to_physical(a, c, s, u_ref, r.reshape(batch + (n_sections, _N_TERMS)), scaling)
    return WindowLibrary(
        theta=theta,
        to_physical=to_phys,
        valid=ok,
        n_valid=n_valid,
        col_scale=r,
        a_scale=a,
        u_center=c,
        u_scale=s,
        u_ref=u_ref,
        scaling=scaling,
    )


def _to_physical(a, c, s, u_ref, r, scaling):
    """Block-diagonal map (..., p, p) from basis coefficients to physical ones.

    Basis term m = (i, delta, e) with scaling constants is
        a^-i A^i (U/u_ref)^delta ((U - c)/s)^e / r_m
      = sum_k a^-i u_ref^-delta s^-e C(e, k) (-c)^(e-k) / r_m * A^i U^(k + delta),
    so the physical coefficient of A^i U^(k+delta) collects that factor.
    """
    i_pow, delta, e_pow = _basis_plan(scaling)
    index = {(int(i), int(j)): n for n, (i, j) in enumerate(_EXPONENTS)}
    rows, cols, binom, k_pow = [], [], [], []
    centred = scaling == "scaled"
    for m in range(_N_TERMS):
        # Without centring (c = 0) only the k = e term of the expansion survives.
        for k in range(0 if centred else e_pow[m], e_pow[m] + 1):
            rows.append(m)
            cols.append(index[(int(i_pow[m]), int(k + delta[m]))])
            binom.append(comb(int(e_pow[m]), k))
            k_pow.append(k)
    rows = np.array(rows)
    cols = np.array(cols)
    binom = np.array(binom, dtype=float)
    k_pow = np.array(k_pow)
    e = e_pow[rows]
    # (..., S, n_entries): the factors for each (basis term, physical term) pair.
    values = (
        a[..., None] ** (-i_pow[rows]).astype(float)
        * u_ref[..., None] ** (-delta[rows]).astype(float)
        * (-c[..., None]) ** (e - k_pow).astype(float)
        / s[..., None] ** e.astype(float)
        * binom
        / r[..., rows]
    )
    n_sections = a.shape[-1]
    blocks = np.zeros(a.shape + (_N_TERMS, _N_TERMS))
    # Block T has basis terms as rows; the physical map is its transpose.
    blocks[..., cols, rows] = values
    p = n_sections * _N_TERMS
    out = np.zeros(a.shape[:-1] + (p, p))
    for sec in range(n_sections):
        sl = slice(sec * _N_TERMS, (sec + 1) * _N_TERMS)
        out[..., sl, sl] = blocks[..., sec, :, :]
    return out


def condition_number(theta: np.ndarray) -> np.ndarray:
    """2-norm condition number of each design matrix, ignoring non-finite rows.

    Parameters
    ----------
    theta : ndarray, shape (..., n, p)

    Returns
    -------
    ndarray, shape (...)
        sigma_max / sigma_min (inf if rank deficient or empty).
    """
    theta = np.asarray(theta, dtype=float)
    rows_ok = np.isfinite(theta).all(axis=-1, keepdims=True)
    # Zero rows leave the singular values unchanged.
    sv = np.linalg.svd(np.where(rows_ok, theta, 0.0), compute_uv=False)
    with np.errstate(divide="ignore", invalid="ignore"):
        cond = sv[..., 0] / sv[..., -1]
    return np.where(np.isfinite(cond), cond, np.inf)


def library_cond(
    A: np.ndarray,
    U: np.ndarray,
    *,
    scaling: str = "scaled",
    valid: np.ndarray | None = None,
) -> np.ndarray:
    """Condition number of each window's library in the given basis.

    ``scaling="raw"`` gives the condition number of the physical library
    (up to about 1e17 on 50 s windows); ``"scaled"`` that of the basis the
    regression uses.

    Parameters
    ----------
    A, U : ndarray, shape (..., n, S)
        Amplitudes (m) and wind speeds (m/s) per window.
    scaling : {"scaled", "normalized", "raw"}
    valid : ndarray of bool, shape (..., n), optional

    Returns
    -------
    ndarray, shape (...)
    """
    return condition_number(window_library(A, U, scaling=scaling, valid=valid).theta)


def basis_orders(n_sections: int = 3) -> np.ndarray:
    """Power of A of every library column (the same in the scaled basis), shape (23 n_sections,)."""
    return np.tile(section_exponents()[:, 0], n_sections)


def order_contributions_basis(theta: np.ndarray, coef: np.ndarray, orders: np.ndarray) -> np.ndarray:
    """Contributions of the orders of A to the prediction ``theta @ coef``.

    Parameters
    ----------
    theta : ndarray, shape (W, n, p)
    coef : ndarray, shape (W, ..., p); any models per window
    orders : ndarray of int, shape (p,)

    Returns
    -------
    r : ndarray, shape (W, ..., n, 4), in the units of ``theta @ coef``
    """
    theta = np.nan_to_num(theta)
    coef = np.nan_to_num(coef)
    W, n, p = theta.shape
    mid = coef.shape[1:-1]
    c2 = coef.reshape(W, -1, p)
    out = np.empty((W, c2.shape[1], n, 4))
    for i in range(4):  # four orders, each a batched matrix product
        cols = orders == i
        out[..., i] = np.einsum("wnc,wmc->wmn", theta[..., cols], c2[..., cols], optimize=True)
    return out.reshape((W,) + mid + (n, 4))
