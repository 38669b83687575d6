"""Event bootstrap of the grey-box fit: refits on events drawn with replacement, warm-started at the optimum.

The block sandwich of :mod:`vivbench.models.greybox_solve` is the linearised
version of this: it treats the events (one block each by default) as the
independent units and propagates their scores through the Gauss-Newton
matrix at the optimum. The bootstrap does the same without the linearisation
of the estimator: every replicate draws the campaign's events with
replacement (multinomial counts, seeded), gives every interval of an event
its count as the multiplicity of its squared residuals and continuity defect
(:meth:`ShootingProblem.set_interval_weights`; an event drawn 0 times drops
out) and refits the spline coefficients with the same roughness penalty,
starting from the full fit's optimum: ``n_iter`` Levenberg-Marquardt
iterations on the exact Jacobian (one linearisation each) with the
continuity weight relaxed to ``first_weight``, then ``n_iter`` more at the
problem's own weight (a continuation as in the fit itself: at the full
weight 1e6 the defects are so far from linear that the steps stay short;
measured on bridge C, one replicate: 30 iterations at 1e6 reached the cost
467.1, 5 + 5 from 1e4 reached 464.5). The replicates stay in the full fit's
basin: the same replicate continued from the weight 1e2 (88 iterations, a
minute) reached 427 with a_k1 moved by 0.10 of its RMS, where 10 + 10 from
1e4 moved it by 0.03; this is a bootstrap of the local minimum, and the
cheaper for it (the full restart would cost the fit's time per replicate).
The covariance
of the replicates' coefficients is the bootstrap covariance; it holds the
estimator's variance over events (including the curvature of the model in
theta that the sandwich linearises away), not the smoothing bias of the
penalty, which every replicate shares.

Cost: up to ``n_boot * 2 (n_iter + 1)`` linearisations plus the trial costs
of the step control. The counts
are drawn once for all replicates from ``numpy.random.default_rng(seed)``
before any refit, and the replicates run in order in one process: the same
data and seed give the same bytes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vivbench.models.greybox_solve import ShootingProblem, solve_gauss_newton
from vivbench.regression.bootstrap import block_counts

__all__ = ["BootstrapResult", "event_bootstrap", "event_counts"]


@dataclass
class BootstrapResult:
    """Replicates of an event bootstrap.

    Attributes
    ----------
    theta : ndarray, shape (B, P)
        Coefficients of every replicate.
    counts : ndarray of int, shape (B, E)
        How often each event was drawn in each replicate.
    cov : ndarray, shape (P, P)
        Covariance of the replicates' coefficients (ddof 1).
    iterations : ndarray of int, shape (B,)
        Levenberg-Marquardt iterations each replicate ran.
    last_step : ndarray, shape (B,)
        Relative decrease of the replicate's cost in its last iteration (how
        far from converged it stopped; 0 for a replicate that converged).
    seconds : float
    """

    theta: np.ndarray
    counts: np.ndarray
    cov: np.ndarray
    iterations: np.ndarray
    last_step: np.ndarray
    seconds: float


def event_counts(n_events: int, n_boot: int, seed: int) -> np.ndarray:
    """Multinomial counts of ``n_events`` events drawn with replacement, shape (n_boot, n_events)."""
    if n_events < 2:
        raise ValueError("an event bootstrap needs at least two events")
    return block_counts(n_events, n_boot, np.random.default_rng(seed))


def event_bootstrap(problem: ShootingProblem, theta: np.ndarray, s: np.ndarray, *, n_boot: int, n_iter: int,
                    seed: int, tol: float = 1e-6, first_weight: float = 1e4, callback=None) -> BootstrapResult:
    """Refit ``problem`` on ``n_boot`` event resamples from the optimum (theta, s).

    Parameters
    ----------
    problem : ShootingProblem
        At its final continuity weight and penalty; its interval weights are
        restored to 1 on return.
    theta : ndarray, shape (P,)
        The full fit's coefficients (the warm start of every replicate).
    s : ndarray, shape (I,)
        The full fit's node states.
    n_boot : int
        Replicates.
    n_iter : int
        Levenberg-Marquardt iterations per replicate and continuation stage at most.
    seed : int
        Seed of the event draws.
    tol : float
        A replicate stops earlier when a step lowers its cost by less than
        ``tol`` times the cost.
    first_weight : float
        Continuity weight of the first stage (the problem's own weight is the last).
    callback : callable or None
        ``callback(replicate, n_boot)`` after every replicate (progress).

    Returns
    -------
    BootstrapResult
    """
    import time

    t0 = time.perf_counter()
    events, ev_of_interval = np.unique(problem.grid.event, return_inverse=True)
    counts = event_counts(events.size, n_boot, seed)
    P = problem.P
    full_weight = problem.continuity_weight
    out = np.empty((n_boot, P))
    iters = np.zeros(n_boot, dtype=int)
    last = np.zeros(n_boot)
    try:
        for b in range(n_boot):
            problem.set_interval_weights(counts[b][ev_of_interval].astype(float))
            problem.set_continuity_weight(full_weight)
            res = solve_gauss_newton(problem, theta, s, max_iter=n_iter, tol=tol,
                                     first_weight=min(first_weight, full_weight), covariance=False)
            out[b] = res.theta
            iters[b] = res.iterations
            h = res.history
            last[b] = 0.0 if res.converged or len(h) < 2 else max(h[-2] - h[-1], 0.0) / max(h[-2], 1e-300)
            if callback is not None:
                callback(b + 1, n_boot)
    finally:
        problem.set_continuity_weight(full_weight)
        problem.set_interval_weights(np.ones(problem.grid.n_intervals))
    cov = np.cov(out, rowvar=False, ddof=1) if n_boot > 1 else np.zeros((P, P))
    return BootstrapResult(theta=out, counts=counts, cov=np.atleast_2d(cov), iterations=iters, last_step=last,
                           seconds=time.perf_counter() - t0)
