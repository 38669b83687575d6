"""Levenberg-Marquardt iterations on a Gauss-Newton model, shared by the CasADi output-error refits.

Both the grey-box refit (:mod:`vivbench.models.greybox_solve`) and the
library-coefficient refit (:mod:`vivbench.models.refit_shooting`) minimise a
sum of squares Phi(x) = |r(x)|^2 (+ a quadratic penalty) over multiple-shooting
variables. Each supplies the exact Gauss-Newton matrix H = J^T J (penalty
included) and gradient J^T r from CasADi step Jacobians; this module holds
the step control they share: a damped step (H + mu diag(H)) dx = -g, kept
only when Phi falls, mu lowered after a success and raised after a failure.
Lower bounds are kept by a small active set (variables a step carries below
their bound are fixed at it and the rest solved again).
"""

from __future__ import annotations

from typing import Callable

import numpy as np
import scipy.linalg as sla

__all__ = ["continuation_weights", "levenberg_marquardt"]


def continuation_weights(final: float, first: float) -> list[float]:
    """Continuity weights of a continuation, ascending: ``final`` / 100^k down to ``first``, then back up.

    Started at full weight, the defects of node states taken from a noisy
    measurement dominate and the iterations crawl, so the weight grows
    100-fold per stage up to ``final``.

    Parameters
    ----------
    final : float
        The last stage's weight.
    first : float
        No stage's weight lies below it (``final`` alone when ``final / 100 < first``).

    Returns
    -------
    list of float
    """
    weights = [float(final)]
    while weights[-1] / 100.0 >= first:
        weights.append(weights[-1] / 100.0)
    return weights[::-1]


def levenberg_marquardt(linearise: Callable, cost: Callable, x: np.ndarray, lower: np.ndarray, *, max_iter: int,
                        tol: float, history: list | None = None, callback: Callable | None = None, offset: int = 0,
                        start_error: str = "the start gives a non-finite cost"):
    """Levenberg-Marquardt iterations from ``x``.

    Parameters
    ----------
    linearise : callable
        ``linearise(x) -> (cost, H, grad, extra)``: Phi(x), the Gauss-Newton
        matrix (n, n) and the gradient (n,) of Phi / 2 with every penalty
        included; ``extra`` is passed back untouched.
    cost : callable
        ``cost(x) -> float``: Phi(x), ``inf`` when not finite.
    x : ndarray, shape (n,)
        Start (at or above ``lower``).
    lower : ndarray, shape (n,)
        Lower bounds (-inf where free).
    max_iter : int
        Linearisations (Jacobian evaluations) at most.
    tol : float
        Stop when an accepted step lowers Phi by less than ``tol`` times Phi.
    history : list or None
        Phi at the start of every iteration is appended here.
    callback : callable or None
        ``callback(iteration, cost, mu)`` after every accepted step.
    offset : int
        Added to the iteration number given to ``callback`` (continuation stages).
    start_error : str
        Message of the ValueError raised when Phi is not finite at the start.

    Returns
    -------
    x : ndarray, shape (n,)
    lin : tuple
        ``linearise`` at the returned ``x``.
    iterations : int
    converged : bool
    message : str
    """
    history = [] if history is None else history
    mu = 1e-3
    converged, message = False, "iteration limit"
    it = 0
    x = np.asarray(x, dtype=float).copy()
    lin = linearise(x)
    if not np.isfinite(lin[0]):
        raise ValueError(start_error)
    for it in range(1, max_iter + 1):
        phi, Hp, gp = lin[0], lin[1], lin[2]
        history.append(phi)
        pinned = (x <= lower) & (gp > 0)  # at the bound and pushed outwards
        diag_all = np.diag(Hp)
        floor = 1e-12 * max(float(diag_all.max()), 1e-300)
        accepted = False
        for _ in range(25):
            dx = _bounded_step(Hp, gp, x, lower, pinned, mu * diag_all + floor)
            if dx is None:
                mu *= 10.0
                continue
            xn = np.maximum(x + dx, lower)
            new_phi = cost(xn)
            if new_phi < phi:
                accepted = True
                x = xn
                mu = max(mu / 3.0, 1e-9)
                break
            mu *= 4.0
        if not accepted:
            converged, message = True, "no step lowers the cost (local minimum within rounding)"
            break
        if callback is not None:
            callback(offset + it, new_phi, mu)
        lin = linearise(x)
        if phi - new_phi < tol * phi:
            converged, message = True, f"relative decrease below {tol:g}"
            break
    return x, lin, it, converged, message


def _bounded_step(H, g, x, lower, pinned, damping, max_rounds: int = 6):
    """Damped Gauss-Newton step that stops at the lower bounds (a few rounds of an active set).

    Variables that the step carries below their bound are moved to it and
    fixed, and the rest is solved again with that move, so the projected step
    stays a minimiser of the quadratic model on the remaining variables.
    None when the damped matrix is not positive definite.
    """
    fixed = pinned.copy()
    dx = np.zeros_like(x)
    for _ in range(max_rounds):  # usually one or two rounds
        free = ~fixed
        dx_fixed = np.where(fixed, np.where(pinned, 0.0, lower - x), 0.0)
        dx_fixed = np.where(np.isfinite(dx_fixed), dx_fixed, 0.0)
        rhs = -g[free] - H[np.ix_(free, fixed)] @ dx_fixed[fixed]
        A = H[np.ix_(free, free)] + np.diag(damping[free])
        try:
            sol = sla.cho_solve(sla.cho_factor(A, lower=False, check_finite=False), rhs, check_finite=False)
        except (np.linalg.LinAlgError, ValueError):
            return None
        dx = dx_fixed.copy()
        dx[free] = sol
        out = free & (x + dx < lower)
        if not out.any():
            break
        fixed |= out
    return dx
