"""Starts of the grey-box refit's multi-start: the campaign model's curves, equation-error fits, perturbed copies.

Every start is a vector theta of the grey-box's spline coefficients (Y1, e1,
e2, C_L, each ``n_basis`` long; then the yaw coefficient). The equation-error
starts are penalised linear least squares (:func:`vivbench.regression.penalised_solve`)
on finite differences of the modal amplitude Q on the shooting grid.

Starts (multi-start against wrong local minima). The candidates are the
campaign model's curves (``warm_start``), an equation-error fit with e1 and
e2 constant (picked from a grid; Y1 and C_L splines by linear least squares
on finite differences of Q), an equation-error fit of the same model in
product form (Y1, Y1 e1, Y1 e2, C_L as splines) and copies of the first
with every function scaled by a seeded log-normal factor and a random yaw
coefficient. The roughness penalty is scaled once, at the first start,
before any start is iterated, so all starts minimise one objective; each
start runs ``screen_iter`` Gauss-Newton iterations at the loosest continuity
weight, and the one with the lowest penalised cost there is iterated to
convergence. The draws come from ``seed``: the same data and seed give the
same fit.
"""

from __future__ import annotations

import numpy as np

from vivbench.core.errors import InputError
from vivbench.library.splines import difference_penalty
from vivbench.models.greybox_physics import curves_to_functions, section_factors
from vivbench.regression.penalised import penalised_solve

__all__ = ["penalised_spline_fit", "greybox_starts", "constant_e_start", "equation_error_curves"]


def penalised_spline_fit(B: np.ndarray, v: np.ndarray, K: np.ndarray, lam: float = 1e-3) -> np.ndarray:
    """Spline coefficients of values v (n,) on basis B (n, M) with a small roughness penalty."""
    ok = np.isfinite(v)
    G = B[ok].T @ B[ok]
    return penalised_solve(G, B[ok].T @ v[ok], K, lam * np.trace(G) / np.trace(K), ridge=1e-12, relative_ridge=False)


def greybox_starts(model, grid, B, a, zw, Qm, phi, beta, P, s2) -> list[tuple[str, np.ndarray]]:
    """The named starts of the multi-start.

    The starts, in order: the warm start (if given), the equation-error
    start with constant e1, e2, the product-form equation-error start,
    then perturbed copies of the first (seeded), ``n_starts`` in all;
    their yaw coefficient is 0 except in the perturbed ones.
    """
    M = model.n_basis
    K = difference_penalty(M)
    wind = np.linspace(*model.wind_range_, 200)
    Bw = model.basis_values(wind)

    def from_p(p):
        F = curves_to_functions(wind, p, model.bridge, phi, beta)
        return np.concatenate([penalised_spline_fit(Bw, F[f], K) for f in range(4)] + [np.zeros(P - 4 * M)])

    eq = from_p(equation_error_curves(model, grid, B, a, zw, Qm, wind, phi, beta))
    starts = []
    if model.warm_start is not None:
        ws = model.warm_start
        try:
            cur = np.asarray(ws["curves"].values, dtype=float)
            w = np.asarray(ws["wind"].values, dtype=float)
        except (KeyError, TypeError) as exc:
            raise InputError(f"warm_start must be a curves dataset of docs/concepts.md (coefficient curves) ({exc})") from None
        if cur.shape[0] != phi.size or cur.shape[1] != 4:
            raise InputError(f"warm_start curves must have shape ({phi.size}, 4, n_wind); got {cur.shape}")
        ref = int(np.argmax(np.abs(phi)))
        p = cur[ref] * phi[ref] ** (np.arange(4) - 1)[:, None]  # a_ki = phi_k^(1-i) p_i
        starts.append(("warm start from curves", from_p(np.stack([np.interp(wind, w, pi) for pi in p]))))
    ce, (e1c, e2c) = constant_e_start(model.n_basis, grid, B, a, zw, Qm, P)
    # the constant-e start before the product form: without a warm start it sets the penalty's scale and is
    # the one perturbed (the product form's division by Y1 near its zeros can blow e1, e2 up by orders of
    # magnitude: e2 ~ 2e6 on campaign A)
    starts.append((f"equation error with constant e1 = {e1c:g}, e2 = {e2c:g} (grid)", ce))
    starts.append(("equation error (product form)", eq))
    base = starts[0][1]
    rng = np.random.default_rng(model.seed)
    # the yaw coefficient of a perturbed start: up to a factor 1/2 at the largest measured yaw
    c_hi = 0.5 / max(float(np.max(s2)), 1e-6) if s2 is not None else 0.0
    for j in range(model.n_starts - len(starts)):
        # each function scaled by a log-normal factor, which keeps the signs and the bounds
        factor = np.exp(model.start_spread * rng.standard_normal(4))
        c = np.atleast_1d(rng.uniform(0.0, c_hi))[:P - 4 * M]
        theta = np.concatenate([(base[:4 * M].reshape(4, M) * factor[:, None]).ravel(), c])
        starts.append((f"perturbed start {j + 1} (seed {model.seed}; function factors "
                       f"{', '.join(f'{x:.2f}' for x in factor)}"
                       + (f", yaw coefficient {c[0]:.3g})" if c.size else ")"), theta))
    return starts[:model.n_starts]

def constant_e_start(n_basis: int, grid, B, a, zw, Qm, P):
    """Start from an equation-error fit with e1, e2 constant, picked from a grid, and Y1, C_L splines.

    With e1 and e2 fixed the amplitude equation is linear in the splines
    of C_L and Y1: dQ/dt + zeta w Q = sum_k a_0k C_L + sum_k Y1 (a_1k Q +
    a_2k e1 Q^2 + a_3k e2 Q^3). Every pair (e1, e2) of a small logarithmic
    grid is solved by penalised linear least squares on finite
    differences of Q (each event's rows divided by its amplitude scale),
    and the pair with the least residual kept; C_L is clipped at 0. The
    constant, non-negative limiting terms keep the start's simulation
    bounded where the product form's e = (Y1 e) / Y1 explodes near a zero of Y1.

    Returns
    -------
    theta : ndarray, shape (P,)
    (e1, e2) : the chosen constants
    """
    M = n_basis
    Bg, ag = B[:, 0::2], a[:, 0::2]
    dQ = np.gradient(Qm, grid.h, axis=1)
    powers = Qm[..., None] ** np.arange(4)
    X = np.einsum("ijsm,ijsf,ijf->ijfm", Bg, ag, powers)  # (I, n+1, 4, M) by order
    ok = grid.weight > 0
    ev, inv = np.unique(grid.event, return_inverse=True)
    num, den = np.zeros(ev.size), np.zeros(ev.size)
    np.add.at(num, inv, np.sum(np.where(ok, Qm, 0.0) ** 2, axis=1))
    np.add.at(den, inv, ok.sum(axis=1))
    w = np.broadcast_to((1.0 / np.sqrt(np.maximum(num / np.maximum(den, 1), 1e-300)))[inv][:, None],
                        ok.shape)[ok]
    Xf = X[ok].reshape(-1, 4 * M) * w[:, None]
    y = (dQ[ok] + zw * Qm[ok]) * w
    G, b, yy = Xf.T @ Xf, Xf.T @ y, float(y @ y)
    K = difference_penalty(M)
    e1_grid = np.array([0.0, 3.0, 10.0, 30.0, 100.0])
    e2_grid = np.logspace(1.0, 4.0, 13)
    best = (np.inf, None, None)
    for e1 in e1_grid:
        for e2 in e2_grid:
            T = np.zeros((4 * M, 2 * M))
            T[:M, :M] = np.eye(M)  # C_L
            T[M:2 * M, M:] = np.eye(M)  # Y1 a_1
            T[2 * M:3 * M, M:] = e1 * np.eye(M)
            T[3 * M:, M:] = e2 * np.eye(M)
            Gt, bt = T.T @ G @ T, T.T @ b
            sc = np.sqrt(np.maximum(np.diag(Gt), 1e-300))
            Gs = Gt / np.outer(sc, sc)
            pen = np.kron(np.eye(2), K)
            c = penalised_solve(Gs, bt / sc, pen, 1e-3 * np.trace(Gs) / np.trace(pen), relative_ridge=False) / sc
            rss = yy - 2.0 * c @ bt + c @ Gt @ c
            if rss < best[0]:
                best = (rss, (float(e1), float(e2)), c)
    _, (e1, e2), c = best
    theta = np.concatenate([c[M:], np.full(M, e1), np.full(M, e2), np.clip(c[:M], 0.0, None),
                            np.zeros(P - 4 * M)])
    return theta, (e1, e2)

def equation_error_curves(model, grid, B, a, zw, Qm, wind, phi, beta) -> np.ndarray:
    """p_i(U) on ``wind`` from linear least squares of dQ/dt in the product form."""
    M = model.n_basis
    Bg, ag = B[:, 0::2], a[:, 0::2]  # grid points
    dQ = np.gradient(Qm, grid.h, axis=1)
    powers = Qm[..., None] ** np.arange(4)  # (I, n+1, 4)
    X = np.einsum("ijsm,ijsf,ijf->ijfm", Bg, ag, powers)  # columns (CL*, Y, H2, H3) by order
    ok = grid.weight > 0
    Xf = X[ok].reshape(-1, 4 * M)
    y = dQ[ok] + zw * Qm[ok]
    sc = np.sqrt(np.mean(Xf**2, axis=0)) + 1e-300
    K = difference_penalty(M)
    Pen = np.kron(np.eye(4), K)
    G = (Xf / sc).T @ (Xf / sc)
    c = penalised_solve(G, (Xf / sc).T @ y, Pen, 1e-3 * np.trace(G) / np.trace(Pen), relative_ridge=False) / sc
    c = c.reshape(4, M)  # order-major: C_L, Y1, Y1 e1, Y1 e2
    Uw = np.repeat(wind[:, None], phi.size, axis=1)
    k = section_factors(Uw, model.bridge, phi, beta).sum(axis=1)
    vals = model.basis_values(wind) @ c.T  # (n, 4)
    p = (k * vals).T
    p[1] -= zw
    return p
