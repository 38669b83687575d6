"""Gauss-Newton (Levenberg-Marquardt) solution of the grey-box multiple-shooting problem, and its covariance.

Decision variables x = [theta (P spline coefficients), s (one node state per
shooting interval)]. The objective is

    Phi(x) = sum r^2 + sum d^2 + theta^T R theta

with the data residuals r (simulated minus measured section amplitudes, each
event divided by its amplitude scale), the continuity defects d (end of an
interval minus the next node, heavily weighted: a quadratic penalty that
leaves defects orders of magnitude below the data misfit; the largest is
reported) and the roughness penalty R. Each iteration builds the exact
residual Jacobian J from the CasADi step Jacobians
(:mod:`vivbench.models.greybox_shooting`) and solves the Gauss-Newton
system (J^T J + R + mu diag) dx = -(J^T r + R theta) densely (a few thousand
unknowns); a step is kept only when Phi falls (Levenberg-Marquardt control of
mu, :mod:`vivbench.models.gauss_newton`, shared with the library refit). Lower bounds (non-negative limiting terms and locked force) are kept by
projection, with the variables pinned at a bound that the step would push
out frozen for that step.

Covariances (both returned, the model picks one for its bands):

- sandwich: H^-1 M H^-1 with H = J^T J + R at the solution and M = sum_b g_b
  g_b^T the outer products of the scores of contiguous blocks of intervals
  (``block_s`` seconds of one event): residuals are correlated inside a block
  (envelope noise is band-limited, model error is slow) and taken as
  independent between blocks. It holds the estimator's variance only, not
  the smoothing bias of the penalty.
- posterior (Bayesian, Wahba 1983; Nychka 1988): the penalty read as a
  Gaussian prior on the spline coefficients gives the posterior covariance
  sigma^2 kappa (J^T J + R)^-1 (the theta block of the inverse over theta and
  the node states, so the node states are integrated out), with sigma^2 =
  RSS / (n - edf) the residual variance (edf = trace of the influence matrix,
  less one per continuity constraint) and kappa >= 1 the variance inflation
  of correlated residuals: the batch-means ratio kappa = sum_b S_b^2 / sum e^2
  of the block sums S_b of the residuals projected on the modal amplitude
  (e = sum_k |phi_k| r_k / |phi|), blocks as for the sandwich, i.e. n / kappa
  is the effective sample size. Its bands hold the smoothing bias on average
  across the function, so their across-the-function coverage is near nominal
  where the sandwich's falls short.
- sandwich plus bias: the sandwich (the estimator's variance, robust to the
  residuals' correlation) plus the prior-averaged squared smoothing bias
  sigma^2 kappa (J^T J + R)^-1 R (J^T J + R)^-1 (the bias of the penalised
  estimator is -(J^T J + R)^-1 R theta, and the prior of the posterior above
  gives E[theta theta^T] = sigma^2 kappa R^-1); with independent residuals
  (sandwich = sigma^2 H^-1 J^T J H^-1) it is the posterior covariance.

Penalty choice: :func:`gcv_score` scores fits at different penalties by
generalised cross-validation, GCV = n_eff RSS / (n_eff - edf)^2 with each
fit's RSS and edf (the influence matrix of its Gauss-Newton linearisation)
and n_eff = n / kappa the effective sample size (with correlated residuals
the plain GCV, n_eff = n, undersmooths). The fits themselves are needed: a
Gauss-Newton step predicts the RSS at another penalty badly here, because the
heavily weighted continuity defects are far from linear over a whole step
(measured: the predicted RSS 0.04, the cost after the step 1e6).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import numpy as np
import scipy.linalg as sla

from vivbench.models.gauss_newton import continuation_weights, levenberg_marquardt
from vivbench.models.greybox_shooting import ShootingGrid, StepFunctions, propagate

__all__ = ["ShootingProblem", "GaussNewtonResult", "solve_gauss_newton", "block_ids", "gcv_score",
           "batch_means_kappa"]


@dataclass
class ShootingProblem:
    """What the solver needs to evaluate residuals and their Jacobian.

    Attributes
    ----------
    grid : ShootingGrid
    amp : ndarray, shape (S,)
        |phi_k|: A_k = amp_k Q.
    scale : ndarray, shape (I,)
        Amplitude scale of each interval's event, m.
    g_of : callable
        ``g_of(theta)`` -> (g (I, 2n+1, 4), dg_dtheta(p, w) -> (I, P)).
    penalty : ndarray, shape (P, P)
        R.
    lower : ndarray, shape (P,)
        Lower bounds of theta (-inf where free).
    continuity_weight : float
        Weight of a defect relative to one sample's residual (squared scale).
    """

    grid: ShootingGrid
    amp: np.ndarray
    scale: np.ndarray
    g_of: Callable
    penalty: np.ndarray
    lower: np.ndarray
    continuity_weight: float = 1e4

    def __post_init__(self):
        self.funcs = StepFunctions(self.grid.n_intervals, self.grid.n_steps, self.grid.h)
        self.interval_weight = np.ones(self.grid.n_intervals)
        self.sw = self.grid.weight / self.scale[:, None]  # (I, n+1)
        self.set_continuity_weight(self.continuity_weight)
        self.has_next = self.grid.next >= 0
        self.P = self.penalty.shape[0]

    def set_continuity_weight(self, weight: float) -> None:
        """Weight of a continuity defect relative to one grid sample (all sections)."""
        self.continuity_weight = float(weight)
        self.cw = (np.sqrt(self.continuity_weight * float(np.sum(self.amp**2))) / self.scale
                   * np.sqrt(self.interval_weight))

    def set_interval_weights(self, weight: np.ndarray) -> None:
        """Multiplicity of every interval's squared residuals and defect (1: the data as they are).

        An event bootstrap (:mod:`vivbench.models.greybox_bootstrap`) gives
        every interval of an event the number of times the event was drawn;
        an interval of weight 0 drops out (its node state is then free and
        decoupled from theta).
        """
        weight = np.asarray(weight, dtype=float)
        if weight.shape != (self.grid.n_intervals,) or np.any(~(weight >= 0)):
            raise ValueError("interval weights must be one non-negative number per shooting interval")
        self.interval_weight = weight
        self.sw = self.grid.weight / self.scale[:, None] * np.sqrt(weight)[:, None]
        self.set_continuity_weight(self.continuity_weight)

    def residuals(self, Q: np.ndarray, s: np.ndarray):
        """Data residuals (I, n+1, S) and continuity defects (I,) (0 where no next interval)."""
        r = self.sw[..., None] * (self.amp * Q[..., None] - self.grid.A)
        nxt = np.where(self.has_next, self.grid.next, 0)
        d = np.where(self.has_next, self.cw * (Q[:, -1] - s[nxt]), 0.0)
        return r, d

    def cost(self, theta: np.ndarray, s: np.ndarray) -> float:
        g, _ = self.g_of(theta)
        Q, _ = propagate(self.funcs, s, g, self.grid.h)
        with np.errstate(over="ignore", invalid="ignore"):  # a trial step that blows up costs inf: rejected
            r, d = self.residuals(Q, s)
            val = float(np.sum(r**2) + np.sum(d**2) + theta @ self.penalty @ theta)
        return val if np.isfinite(val) else np.inf

    def linearise(self, theta: np.ndarray, s: np.ndarray):
        """Cost, Gauss-Newton matrix H = J^T J (no penalty), J^T r, and per-interval scores.

        Returns
        -------
        cost : float
        H : ndarray, shape (P + I, P + I)
        grad : ndarray, shape (P + I,)
        local : (ndarray (I, 1 + P), ndarray (I, 1 + P), ndarray (I,))
            Per interval: J^T r of its data residuals on (s_i, theta); the
            continuity row a_i on (s_i, theta) and its value d_i (the row also
            holds -cw_i on s_next).
        """
        P, I = self.P, self.grid.n_intervals
        g, dg = self.g_of(theta)
        Q, sens = propagate(self.funcs, s, g, self.grid.h, dg)
        r, d = self.residuals(Q, s)
        cost = float(np.sum(r**2) + np.sum(d**2) + theta @ self.penalty @ theta)
        c = self.sw**2 * float(np.sum(self.amp**2))  # (I, n+1)
        X = sens * np.sqrt(c)[..., None]
        G = np.matmul(X.transpose(0, 2, 1), X)  # (I, 1+P, 1+P)
        u = self.sw * np.einsum("ijk,k->ij", r, self.amp)
        gloc = np.einsum("ij,ija->ia", u, sens)
        arow = np.where(self.has_next[:, None], self.cw[:, None] * sens[:, -1], 0.0)  # (I, 1+P)
        bval = np.where(self.has_next, -self.cw, 0.0)
        nxt = np.where(self.has_next, self.grid.next, 0)
        n = P + I
        H = np.zeros((n, n))
        grad = np.zeros(n)
        si = P + np.arange(I)
        sn = P + nxt
        H[:P, :P] = G[:, 1:, 1:].sum(axis=0) + arow[:, 1:].T @ arow[:, 1:]
        H[si, si] += G[:, 0, 0] + arow[:, 0] ** 2
        H[:P, si] += G[:, 1:, 0].T + (arow[:, 1:] * arow[:, :1]).T
        np.add.at(H, (slice(0, P), sn), (arow[:, 1:] * bval[:, None]).T)
        np.add.at(H, (si, sn), arow[:, 0] * bval)
        np.add.at(H, (sn, sn), bval**2)
        # the blocks above were filled in the upper triangle (theta before s, s_i before s_next)
        H = np.triu(H) + np.triu(H, 1).T
        grad[:P] = gloc[:, 1:].sum(axis=0) + arow[:, 1:].T @ d
        grad[P:] += gloc[:, 0] + arow[:, 0] * d
        np.add.at(grad, sn, bval * d)
        return cost, H, grad, (gloc, arow, d), Q


@dataclass
class GaussNewtonResult:
    """Solution, covariances and diagnostics of :func:`solve_gauss_newton`.

    ``cov`` is the block sandwich; ``covariances`` holds "sandwich",
    "posterior" and "sandwich_bias" (module docstring); ``band_info`` holds
    sigma2, kappa, edf, n_data, n_constraints and rss (for :func:`gcv_score`).
    """

    theta: np.ndarray
    s: np.ndarray
    cov: np.ndarray
    cost: float
    iterations: int
    converged: bool
    message: str
    max_defect: float
    seconds: float
    history: list
    Q: np.ndarray
    covariances: dict | None = None
    band_info: dict | None = None


def block_ids(grid: ShootingGrid, block_s: float) -> np.ndarray:
    """Block of every interval: contiguous ``block_s`` seconds of one event (compact ids)."""
    t0 = grid.t[:, 0]
    first = {}
    for e, t in zip(grid.event, t0):  # one entry per interval (a few thousand)
        first.setdefault(int(e), float(t))
    rel = t0 - np.array([first[int(e)] for e in grid.event])
    key = grid.event.astype(np.int64) * 1_000_000 + np.floor(rel / block_s).astype(np.int64)
    return np.unique(key, return_inverse=True)[1]


def solve_gauss_newton(problem: ShootingProblem, theta0: np.ndarray, s0: np.ndarray, *, max_iter: int = 40,
                       tol: float = 1e-7, block_s: float = 300.0, callback=None,
                       first_weight: float = 1e2, covariance: bool = True) -> GaussNewtonResult:
    """Levenberg-Marquardt iterations on the Gauss-Newton model, then the sandwich covariance.

    Parameters
    ----------
    problem : ShootingProblem
    theta0 : ndarray, shape (P,)
    s0 : ndarray, shape (I,)
    max_iter : int
        Jacobian evaluations at most in each continuation stage (the stages
        together may take up to their number times as many).
    tol : float
        Stop when an accepted step lowers the cost by less than ``tol`` times the cost.
    block_s : float, s
        Length of the blocks of the covariance's score sum.
    callback : callable or None
        ``callback(iteration, cost, mu)`` after every accepted step (progress).
    first_weight : float
        Continuation: the continuity weight starts here and grows 100-fold
        after each converged stage up to the problem's own weight (started
        at full weight, the defects of node states taken from the noisy
        measurement dominate and the iterations crawl: measured on
        noise-free envelopes, cost 57 after 15 iterations against 0.3 after 4
        with the weight at 1e3).
    covariance : bool
        False: skip the covariances (``cov`` is empty), e.g. when screening
        the starts of a multi-start.

    Returns
    -------
    GaussNewtonResult
    """
    t_start = time.perf_counter()
    weights = continuation_weights(problem.continuity_weight, first_weight)
    theta = np.maximum(np.asarray(theta0, dtype=float), problem.lower)
    s = np.asarray(s0, dtype=float).copy()
    history = []
    total = 0
    for weight in weights:
        problem.set_continuity_weight(weight)
        theta, s, lin, it, converged, message = _levenberg_marquardt(problem, theta, s, max_iter, tol, history,
                                                                     callback, total)
        total += it
    it = total
    cost, H, grad, (gloc, arow, d), Q = lin
    history.append(cost)
    cov, covs, band_info = np.zeros((0, 0)), None, None
    if covariance:
        blocks = block_ids(problem.grid, block_s)
        Hinv_rows = _theta_rows_of_inverse(problem, H)
        cov = _sandwich(problem, Hinv_rows, gloc, arow, d, blocks)
        cov_post, bias, band_info = _posterior(problem, Hinv_rows, theta, s, Q, blocks)
        covs = {"sandwich": cov, "posterior": cov_post, "sandwich_bias": cov + bias}
    nxt = np.where(problem.has_next, problem.grid.next, 0)
    defect = np.where(problem.has_next, np.abs(Q[:, -1] - s[nxt]) / problem.scale, 0.0)
    return GaussNewtonResult(theta=theta, s=s, cov=cov, cost=cost, iterations=it, converged=converged,
                             message=message, max_defect=float(defect.max(initial=0.0)),
                             seconds=time.perf_counter() - t_start, history=history, Q=Q,
                             covariances=covs, band_info=band_info)


def _levenberg_marquardt(problem, theta, s, max_iter, tol, history, callback, offset):
    """Levenberg-Marquardt iterations at the problem's current continuity weight."""
    P = problem.P
    R = problem.penalty

    def linearise(x):
        lin = problem.linearise(x[:P], x[P:])
        Hp = lin[1].copy()
        Hp[:P, :P] += R
        gp = lin[2].copy()
        gp[:P] += R @ x[:P]
        return lin[0], Hp, gp, lin

    x0 = np.concatenate([theta, s])
    lower = np.concatenate([problem.lower, np.full(s.size, -np.inf)])
    x, lin, it, converged, message = levenberg_marquardt(
        linearise, lambda z: problem.cost(z[:P], z[P:]), x0, lower, max_iter=max_iter, tol=tol, history=history,
        callback=callback, offset=offset,
        start_error="the grey-box start gives a non-finite cost (a simulation blows up inside an interval)")
    return x[:P], x[P:], lin[3], it, converged, message


def _theta_rows_of_inverse(problem: ShootingProblem, H: np.ndarray) -> np.ndarray:
    """Rows of (H + R)^-1 that belong to theta, shape (P, P + I)."""
    P, I = problem.P, problem.grid.n_intervals
    Hp = H.copy()
    Hp[:P, :P] += problem.penalty
    # Jacobi scaling first: spline coefficients (e2 ~ 1e2, C_L ~ 1e-2) and node states (~1e-2 m)
    # differ by orders of magnitude, which alone would make H look singular
    dsc = 1.0 / np.sqrt(np.maximum(np.diag(Hp), 1e-300))
    Hs = Hp * dsc[:, None] * dsc[None, :]
    rhs = np.zeros((P + I, P))
    rhs[np.arange(P), np.arange(P)] = dsc[:P]
    return (sla.solve(Hs, rhs, assume_a="pos", check_finite=False) * dsc[:, None]).T


def _sandwich(problem: ShootingProblem, Hinv_rows, gloc, arow, d, block: np.ndarray) -> np.ndarray:
    """Block sandwich covariance of theta, shape (P, P)."""
    P, I = problem.P, problem.grid.n_intervals
    n_blocks = int(block.max()) + 1
    # score of every interval on (theta, s_i, s_next): data part plus its continuity row
    sc_theta = gloc[:, 1:] + arow[:, 1:] * d[:, None]
    sc_s = gloc[:, 0] + arow[:, 0] * d
    sc_next = np.where(problem.has_next, -problem.cw * d, 0.0)
    Gb = np.zeros((n_blocks, P + I))
    np.add.at(Gb, (block, slice(0, P)), sc_theta)
    np.add.at(Gb, (block, P + np.arange(I)), sc_s)
    nxt = np.where(problem.has_next, problem.grid.next, 0)
    np.add.at(Gb, (block, P + nxt), sc_next)
    KG = Hinv_rows @ Gb.T
    factor = n_blocks / max(n_blocks - 1, 1)
    return factor * (KG @ KG.T)


def _data_residuals(problem: ShootingProblem, Q: np.ndarray, s: np.ndarray):
    """Data residuals projected on the modal amplitude, (I, n+1), their count, and the defects (I,)."""
    r, d = problem.residuals(Q, s)
    e = np.einsum("ijk,k->ij", r, problem.amp) / np.sqrt(float(np.sum(problem.amp**2)))
    n_data = int(np.count_nonzero(problem.grid.weight > 0)) * problem.amp.size
    return r, e, n_data, d


def batch_means_kappa(e: np.ndarray, block: np.ndarray) -> float:
    """Variance inflation of correlated residuals by batch means: sum_b S_b^2 / sum e^2, at least 1.

    For residuals independent between blocks, E[S_b^2] is the block's sum of
    covariances, so the ratio is the long-run variance over the variance (1
    for white residuals, the block length for a constant within a block).

    Parameters
    ----------
    e : ndarray, shape (I, n)
        Residuals of every interval's samples (0 where none).
    block : ndarray of int, shape (I,)
        Block of every interval.

    Returns
    -------
    float
    """
    S = np.zeros(int(block.max()) + 1)
    np.add.at(S, block, e.sum(axis=1))
    return max(1.0, float(np.sum(S**2) / max(np.sum(e**2), 1e-300)))


def _posterior(problem: ShootingProblem, Hinv_rows, theta, s, Q, block):
    """Posterior covariance sigma^2 kappa (J^T J + R)^-1 of theta, the prior-averaged squared bias, the ingredients."""
    P = problem.P
    r, e, n_data, _ = _data_residuals(problem, Q, s)
    rss = float(np.sum(r**2))
    Vt = Hinv_rows[:, :P]
    n_con = int(np.count_nonzero(problem.has_next))
    # edf = trace of the influence matrix (H + R)^-1 H = (P + I) - tr((H + R)^-1 R), R only on theta (the
    # variables at a bound counted as free: a slight overcount of edf, so a slightly larger sigma^2)
    edf = float(Vt.shape[0] + problem.grid.n_intervals - np.sum(Vt * problem.penalty.T)) - n_con
    sigma2 = rss / max(n_data - edf, 1.0)
    kappa = batch_means_kappa(e, block)
    cov = sigma2 * kappa * 0.5 * (Vt + Vt.T)
    bias = sigma2 * kappa * (Vt @ problem.penalty @ Vt.T)
    info = {"sigma2": sigma2, "kappa": kappa, "edf": edf, "n_data": n_data, "n_constraints": n_con, "rss": rss}
    return cov, 0.5 * (bias + bias.T), info


def gcv_score(band_info: dict, kappa: float) -> dict:
    """GCV of a fit with the effective sample size: n_eff RSS / (n_eff - edf)^2, n_eff = n / kappa.

    Parameters
    ----------
    band_info : dict
        ``rss``, ``edf`` and ``n_data`` of a fit (:attr:`GaussNewtonResult.band_info`).
    kappa : float
        Variance inflation of the residuals (>= 1), the same for all fits compared.

    Returns
    -------
    dict
        ``gcv`` (inf when edf >= n_eff), ``rss``, ``edf``, ``n_eff``.
    """
    n_eff = band_info["n_data"] / max(float(kappa), 1.0)
    edf, rss = float(band_info["edf"]), float(band_info["rss"])
    gcv = n_eff * rss / (n_eff - edf) ** 2 if edf < n_eff else float("inf")
    return {"gcv": gcv, "rss": rss, "edf": edf, "n_eff": n_eff}
