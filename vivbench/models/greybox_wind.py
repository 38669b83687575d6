"""The wind's errors-in-variables in the grey-box fit: draws of the anemometers' error and the refits they move.

The grey-box fit (:mod:`vivbench.models.greybox`) evaluates Y1, e1, e2 and
C_L at each section's measured (smoothed) wind, but the deck feels the wind
averaged over its tributary strip, not the anemometer's point value. The
difference is an error in the fit's input (errors-in-variables), whose effect
on the curves no band from the residuals' variance holds: it moves the
optimum itself.

Its size from the data alone: the sections' anemometers differ from their
mean by d_k = U_k - mean_l U_l. If each anemometer's slow turbulence is
independent of the others' with standard deviation sigma, Var(d_k) =
sigma^2 (1 - 1/S); so sqrt(S / (S - 1)) d_k has the error's size and,
being a record of the same instruments, its time correlation. (The felt
winds of the sections differ too, so this overstates sigma; a constant
``scale`` <= 1 can take that back.)

Draws (:func:`wind_error_draws`): an event's wind gets the relative
deviation d / mean_l U_l of another event (drawn, a donor: its turbulence is
independent of this event's), started at a random interval of the donor and
continued cyclically, with the sections permuted and the sign flipped at
random, times this event's mean wind.

Refits (:func:`wind_refits`): a few Levenberg-Marquardt iterations from the
fit's optimum with the wind perturbed by a draw (the problem's wind-dependent
coefficients rebuilt by a caller's function), like the event bootstrap of
:mod:`vivbench.models.greybox_bootstrap`. The measured wind is the felt one
plus one draw of the error; a refit with one more draw moves the optimum
as the error moved it from the truth's, to first order in the spread and
(SIMEX, Cook and Stefanski 1994, linear in the added error variance) with
the opposite mean shift. The band component is therefore the second moment
of the refits about the same refit with the wind unperturbed (:func:`wind_second_moment`): their spread (the
error's variance) plus their mean shift squared (the SIMEX estimate of the
error's bias, |extrapolated to no error - fit|). A single linearised step
per draw (theta - (J'J + R)^-1 [grad under the perturbed wind - grad])
does not do: at the fit's continuity weight the defects the perturbed wind
opens are far from linear, and the step came out 400 times the curves' RMS
on bridge B.

A section whose wind was taken from an anemometer elsewhere on the span
(``Record.wind_distance`` > 0; one anemometer copied to every section shows
no spread at all) adds draws of that error (:func:`unmeasured_wind_draws`):
per event and section a standard normal multiple of its rms error over the
distance (:func:`vivbench.preprocess.unmeasured_wind_error`, Kaimal turbulence
with Davenport coherence, at the identification's low-pass and no further
smoothing, which overstates it), added to the spread's draws.

Everything is drawn from ``numpy.random.default_rng(seed)`` before any
refit, and the refits run in order: the same data and seed give the same bytes.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from vivbench.models.greybox_solve import ShootingProblem, solve_gauss_newton
from vivbench.preprocess.unmeasured_wind import unmeasured_wind_error

__all__ = [
    "WindRefits",
    "relative_spread",
    "simex_extrapolate",
    "unmeasured_wind_draws",
    "wind_error_draws",
    "wind_refits",
    "wind_second_moment",
]


def relative_spread(U: np.ndarray) -> np.ndarray:
    """Each section's deviation from the sections' mean wind, relative to it, scaled to one anemometer's error.

    Parameters
    ----------
    U : ndarray, shape (..., S), m/s

    Returns
    -------
    ndarray, shape (..., S)
        sqrt(S / (S - 1)) (U_k - mean_l U_l) / mean_l U_l; zeros with one section (not estimable).
    """
    U = np.asarray(U, dtype=float)
    S = U.shape[-1]
    if S < 2:
        return np.zeros_like(U)
    mean = U.mean(axis=-1, keepdims=True)
    return np.sqrt(S / (S - 1.0)) * (U - mean) / np.where(mean > 0, mean, np.inf)


def wind_error_draws(U: np.ndarray, event: np.ndarray, *, n_draws: int, seed: int,
                     scale: float = 1.0) -> np.ndarray:
    """Draws of the wind's error on the shooting grid, from other events' anemometer spread.

    Parameters
    ----------
    U : ndarray, shape (I, m, S), m/s
        Section winds at the stage points of every interval (``ShootingGrid.U``).
    event : ndarray of int, shape (I,)
        Event of every interval (intervals of an event in time order).
    n_draws : int
        Number of draws (independent of one another).
    seed : int
    scale : float
        Factor on the error's size (0: no error).

    Returns
    -------
    ndarray, shape (n_draws, I, m, S), m/s
    """
    if not (isinstance(n_draws, (int, np.integer)) and n_draws >= 1):
        raise ValueError(f"n_draws must be a positive integer; got {n_draws!r}")
    U = np.asarray(U, dtype=float)
    I, m, S = U.shape
    rel = relative_spread(U)
    mean = U.mean(axis=-1, keepdims=True)  # (I, m, 1)
    events = np.unique(event)
    members = [np.flatnonzero(event == e) for e in events]
    rng = np.random.default_rng(seed)
    out = np.zeros((n_draws, I, m, S))
    for b in range(n_draws):
        for i, idx in enumerate(members):  # one pass per event and draw: a few hundred at most
            others = [j for j in range(len(members)) if j != i] or [i]
            donor = members[others[int(rng.integers(len(others)))]]
            start = int(rng.integers(donor.size))
            src = donor[(start + np.arange(idx.size)) % donor.size]
            perm = rng.permutation(S)
            sign = 1.0 if rng.random() < 0.5 else -1.0
            out[b, idx] = sign * scale * rel[src][..., perm] * mean[idx]
    return out


def unmeasured_wind_draws(U: np.ndarray, event: np.ndarray, distances: np.ndarray, *, n_draws: int,
                          seed) -> np.ndarray | None:
    """Draws of the error of section winds taken from an anemometer elsewhere on the span.

    Parameters
    ----------
    U : ndarray, shape (I, m, S), m/s
        Section winds at the stage points of every interval (``ShootingGrid.U``).
    event : ndarray of int, shape (I,)
        Record of every interval.
    distances : ndarray, shape (n_records, S), m
        Each record's distance from each section to the anemometer its wind came from (0: measured there).
    n_draws : int
    seed : int or sequence of int, of ``numpy.random.default_rng``

    Returns
    -------
    ndarray, shape (n_draws, I, m, S), m/s, or None when no distance is > 0
        z sigma_e(U): per draw, record and section one standard normal z times the section's rms error at
        each point (:func:`vivbench.preprocess.unmeasured_wind_error`); 0 where measured there.
    """
    distances = np.asarray(distances, dtype=float)
    if not np.any(distances > 0):
        return None
    U = np.asarray(U, dtype=float)
    event = np.asarray(event)
    err = np.zeros_like(U)
    for r, k in zip(*np.nonzero(distances > 0)):  # records x sections with a distance: a few hundred at most
        rows = event == r
        err[rows, :, k] = np.nan_to_num(unmeasured_wind_error(U[rows, :, k], float(distances[r, k])))
    z = np.random.default_rng(seed).standard_normal((int(n_draws), distances.shape[0], U.shape[-1]))
    return z[:, event, None, :] * err[None]


@dataclass
class WindRefits:
    """Refits of the grey-box problem with perturbed winds.

    Attributes
    ----------
    theta : ndarray, shape (L, B, P)
        Coefficients of every refit at every level.
    levels : ndarray, shape (L,)
        Added error variance in units of the error's (lambda).
    iterations : ndarray of int, shape (L, B)
    seconds : float
    reference : ndarray, shape (P,)
        The same refit with the measured wind unperturbed: the iterations
        alone move the fit a little (they run to a tighter tolerance and
        through a relaxed continuity weight), and that move is no wind
        error; the draws are compared with this reference.
    """

    theta: np.ndarray
    levels: np.ndarray
    iterations: np.ndarray
    seconds: float
    reference: np.ndarray


def wind_refits(problem: ShootingProblem, g_builder: Callable, U: np.ndarray, theta: np.ndarray, s: np.ndarray,
                draws: np.ndarray, *, levels=(1.0,), n_iter: int = 3, first_weight: float = 1e4,
                tol: float = 1e-6) -> WindRefits:
    """Refit from the optimum (theta, s) with the wind U + sqrt(lambda) delta for every draw and level.

    Also once with the wind unperturbed (``reference``), by the same iterations.

    Parameters
    ----------
    problem : ShootingProblem
        At its final penalty and continuity weight; its ``g_of`` is restored on return.
    g_builder : callable
        ``g_builder(U)`` -> a ``g_of`` for the problem with section winds U (I, m, S).
    U : ndarray, shape (I, m, S), m/s
        The measured winds of the fit.
    theta, s : ndarray
        The fit's optimum.
    draws : ndarray, shape (B, I, m, S), m/s
        Errors of the size sigma (:func:`wind_error_draws`).
    levels : sequence of float
        lambda of every level.
    n_iter : int
        Levenberg-Marquardt iterations per continuation stage.
    first_weight : float
        Continuity weight of the first stage.

    Returns
    -------
    WindRefits
    """
    t0 = time.perf_counter()
    levels = np.asarray(levels, dtype=float)
    g_of, full_weight = problem.g_of, problem.continuity_weight
    out = np.empty((levels.size, draws.shape[0], theta.size))
    iters = np.zeros((levels.size, draws.shape[0]), dtype=int)

    def refit(delta):
        # a perturbed wind below zero would flip the aerodynamic terms' signs: floored
        problem.g_of = g_builder(np.maximum(U + delta, 1e-3))
        problem.set_continuity_weight(full_weight)
        return solve_gauss_newton(problem, theta, s, max_iter=n_iter, tol=tol,
                                  first_weight=min(first_weight, full_weight), covariance=False)

    try:
        reference = refit(np.zeros_like(U)).theta
        for a, lam in enumerate(levels):
            for b in range(draws.shape[0]):
                res = refit(np.sqrt(lam) * draws[b])
                out[a, b] = res.theta
                iters[a, b] = res.iterations
    finally:
        problem.g_of = g_of
        problem.set_continuity_weight(full_weight)
    return WindRefits(theta=out, levels=levels, iterations=iters, seconds=time.perf_counter() - t0,
                      reference=reference)


def wind_second_moment(theta: np.ndarray, refits: np.ndarray) -> np.ndarray:
    """Mean of (theta_b - theta)(theta_b - theta)^T over the refits: their spread plus their mean shift squared.

    Parameters
    ----------
    theta : ndarray, shape (P,)
        The refit with the unperturbed wind (``WindRefits.reference``).
    refits : ndarray, shape (B, P)
        Refits with the wind perturbed by draws of its error at its own size.

    Returns
    -------
    ndarray, shape (P, P)
    """
    d = np.asarray(refits, dtype=float) - np.asarray(theta, dtype=float)[None]
    return d.T @ d / d.shape[0]


def simex_extrapolate(theta0: np.ndarray, means: np.ndarray, levels, *, order: int = 1) -> np.ndarray:
    """SIMEX: the mean refit as a polynomial in lambda through lambda = 0 (the fit), evaluated at -1.

    Parameters
    ----------
    theta0 : ndarray, shape (P,)
        The fit (lambda = 0).
    means : ndarray, shape (L, P)
        Mean refit at every level.
    levels : sequence of float, (L,)
    order : int
        Degree of the polynomial (1 linear, 2 quadratic; at most L).

    Returns
    -------
    ndarray, shape (P,)
    """
    lam = np.concatenate([[0.0], np.asarray(levels, dtype=float)])
    if not 1 <= order <= lam.size - 1:
        raise ValueError(f"order must lie in 1..{lam.size - 1} (the levels given); got {order!r}")
    Y = np.vstack([theta0[None], np.asarray(means, dtype=float)])
    V = np.vander(lam, order + 1, increasing=True)
    coef = np.linalg.lstsq(V, Y, rcond=None)[0]  # (order+1, P)
    return (np.vander(np.array([-1.0]), order + 1, increasing=True) @ coef)[0]
