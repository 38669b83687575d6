"""The shared numerics: the spline basis, the penalised least-squares solve and the RK4 integrator."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp
from scipy.interpolate import BSpline

from tests.helpers import assert_close
from vivbench.library.splines import (DEGREE, bspline_basis, bspline_local, difference_penalty, first_index,
                                      uniform_knots)
from vivbench.models.integrate import ABOVE, BELOW, NON_FINITE, NOT_STOPPED, StopRule, rk4
from vivbench.regression.bootstrap import block_counts
from vivbench.regression.penalised import (held_out_errors, penalised_rss, penalised_solve, penalty_scale,
                                           quadratic_error, spd_solve)


# -- splines ------------------------------------------------------------------------------------------

@settings(max_examples=30, deadline=None)
@given(lo=st.floats(0.0, 20.0), width=st.floats(0.5, 20.0), n_basis=st.integers(4, 25), seed=st.integers(0, 99))
def test_basis_equals_scipy_design_matrix(lo, width, n_basis, seed):
    knots = uniform_knots(lo, lo + width, n_basis)
    assert knots.size == n_basis + DEGREE + 1
    U = np.random.default_rng(seed).uniform(lo, lo + width, 200)
    U[:2] = knots[DEGREE], knots[-DEGREE - 1]  # both ends of the base interval (lo, hi up to rounding)
    B = bspline_basis(U, knots)
    ref = BSpline.design_matrix(U, knots, DEGREE).toarray()
    assert_close(B, ref, atol=1e-15, reason="the same recursion; bit-equal in practice, 1e-15 of a value <= 1")
    assert_close(B.sum(axis=1), np.ones(U.size), atol=1e-14, reason="partition of unity, rounding of 4 terms")


def test_basis_clips_outside_and_keeps_nan_rows():
    knots = uniform_knots(5.0, 10.0, 8)
    B = bspline_basis(np.array([1.0, 5.0, 12.0, 10.0, np.nan]), knots)
    assert np.array_equal(B[0], B[1]) and np.array_equal(B[2], B[3])  # held constant outside the range
    assert np.isnan(B[4]).all()
    first, vals = bspline_local(np.array([5.0, 10.0]), knots)
    assert list(first) == [0, 8 - DEGREE - 1]
    assert list(first_index(np.array([np.nan, 7.5]), knots)) == [0, 2]
    assert vals.shape == (2, DEGREE + 1)


def test_difference_penalty_leaves_lines_free():
    P = difference_penalty(9)
    assert_close(P @ np.ones(9), np.zeros(9), atol=1e-12, reason="integer sums")
    assert_close(P @ np.arange(9.0), np.zeros(9), atol=1e-12, reason="integer sums")
    assert np.linalg.matrix_rank(P) == 7


# -- penalised least squares ----------------------------------------------------------------------------

def _problem(seed=0, n=200, p=12, batch=()):
    rng = np.random.default_rng(seed)
    X = rng.normal(size=batch + (n, p))
    y = rng.normal(size=batch + (n,))
    D = np.diff(np.eye(p), n=2, axis=0)
    return X, y, D


@pytest.mark.parametrize("lam", [0.0, 0.3, 30.0])
def test_penalised_solve_equals_lstsq_on_the_stacked_system(lam):
    X, y, D = _problem()
    P = D.T @ D
    c = penalised_solve(X.T @ X, X.T @ y, P, lam, ridge=0.0)
    stacked = np.vstack([X, np.sqrt(lam) * D])
    ref = np.linalg.lstsq(stacked, np.concatenate([y, np.zeros(D.shape[0])]), rcond=None)[0]
    assert_close(c, ref, rtol=1e-10, atol=1e-12, reason="normal equations against QR: cond(X) ~ 10")
    rss = quadratic_error(c, X.T @ X, X.T @ y, y @ y)
    assert_close(rss, np.sum((y - X @ c) ** 2), rtol=1e-10, reason="c'Gc - 2c'b + y'y cancels about one digit")


def test_penalised_solve_drops_columns_and_batches():
    X, y, D = _problem(batch=(3,))
    P = D.T @ D
    G, b = np.einsum("enp,enq->epq", X, X), np.einsum("enp,en->ep", X, y)
    keep = np.ones(12, dtype=bool)
    keep[[0, 5]] = False
    lams = np.array([0.1, 1.0])
    c = penalised_solve(G[:, None], b[:, None], P, lams, keep, ridge=0.0)
    assert c.shape == (3, 2, 12) and np.all(c[..., ~keep] == 0)
    for e in range(3):
        for j, lam in enumerate(lams):
            Dk = D[:, keep]
            stacked = np.vstack([X[e][:, keep], np.sqrt(lam) * Dk])
            ref = np.linalg.lstsq(stacked, np.concatenate([y[e], np.zeros(D.shape[0])]), rcond=None)[0]
            assert_close(c[e, j, keep], ref, rtol=1e-10, atol=1e-12, reason="normal equations against QR")


def test_penalised_rss_uses_the_relative_penalty():
    X, y, D = _problem(seed=3)
    P = D.T @ D
    G, b = X.T @ X, X.T @ y
    keep = np.ones(12, dtype=bool)
    lam = 0.5 * penalty_scale(G, P)
    assert_close(lam, 0.5 * np.trace(G) / np.trace(P))
    c = penalised_solve(G, b, P, lam, keep)
    assert_close(penalised_rss(G, b, y @ y, P, 0.5, keep), np.sum((y - X @ c) ** 2), rtol=1e-10,
                 reason="c'Gc - 2c'b + y'y cancels about one digit")


def test_held_out_errors_refit_without_each_group():
    X, y, D = _problem(seed=4, batch=(4,), n=50)
    P = D.T @ D
    G, b, yy = np.einsum("enp,enq->epq", X, X), np.einsum("enp,en->ep", X, y), (y**2).sum(axis=1)
    err = held_out_errors(G.sum(0), b.sum(0), G, b, yy, P, np.array([2.0]))
    for e in range(4):
        rest = [j for j in range(4) if j != e]
        Xr, yr = X[rest].reshape(-1, 12), y[rest].ravel()
        c = np.linalg.lstsq(np.vstack([Xr, np.sqrt(2.0) * D]), np.concatenate([yr, np.zeros(10)]), rcond=None)[0]
        assert_close(err[e, 0], np.sum((y[e] - X[e] @ c) ** 2), rtol=1e-9, reason="normal equations against QR")


def test_spd_solve_matches_solve_and_falls_back():
    rng = np.random.default_rng(5)
    A = rng.normal(size=(3, 6, 6))
    H = A @ A.transpose(0, 2, 1) + 6 * np.eye(6)
    H[2] = -H[2]  # not positive definite: LU
    b = rng.normal(size=(3, 6))
    assert_close(spd_solve(H, b), np.linalg.solve(H, b[..., None])[..., 0], rtol=1e-10,
                 reason="Cholesky against LU, well conditioned")


# -- RK4 --------------------------------------------------------------------------------------------------

def test_rk4_matches_solve_ivp_on_a_linear_ode():
    """dx/dt = M x + u(t), two trajectories at once; the error against solve_ivp falls as h^4."""
    M = np.array([[-0.05, 1.0], [-1.0, -0.05]])

    def u(tau):
        return np.stack([np.sin(0.3 * tau), np.cos(0.2 * tau)], axis=-1)

    x0 = np.array([[1.0, 0.0], [-0.5, 2.0]])
    errors = []
    for n_times in (101, 201):
        t = np.linspace(0.0, 13.5, n_times)
        stages = (u(t[:-1]), u(0.5 * (t[1:] + t[:-1])), u(t[1:]))
        run = rk4(lambda x, n, stage: x @ M.T + stages[stage][n], x0, t)
        assert run.x.shape == (t.size, 2, 2) and np.all(run.stop == -1) and np.all(run.reason == NOT_STOPPED)
        ref = np.stack([solve_ivp(lambda tau, x: M @ x + u(tau), (t[0], t[-1]), x0[j], t_eval=t, rtol=1e-12,
                                  atol=1e-13).y.T for j in range(2)], axis=1)
        errors.append(np.abs(run.x - ref).max())
    assert errors[1] < 1e-5  # RK4 at h = 0.07 s over 13.5 s, states of size 2
    assert errors[0] / errors[1] > 12.0  # fourth order: 16 when h halves


def test_rk4_stop_rule_freezes_each_trajectory():
    t = np.linspace(0.0, 5.0, 51)
    rates = np.array([[1.0], [-1.0], [0.0]])  # growth, decay, constant

    def rhs(x, n, stage):
        return rates * x

    run = rk4(rhs, np.array([[1.0], [1.0], [1.0]]), t, stop=StopRule(upper=2.0, lower=0.5))
    assert list(run.reason) == [ABOVE, BELOW, NOT_STOPPED]
    assert run.stop[0] == int(np.argmax(np.exp(t) > 2.0)) and run.stop[1] == int(np.argmax(np.exp(-t) < 0.5))
    assert np.isnan(run.x[run.stop[0]:, 0]).all() and np.isfinite(run.x[:run.stop[0], 0]).all()
    assert_close(run.x[:, 2, 0], np.ones(t.size))
    with np.errstate(over="ignore", invalid="ignore"):  # dx/dt = x^2 blows up at t = 1 s: the stop it is about
        blow = rk4(lambda x, n, s: x**2, np.array([1.0]), np.linspace(0.0, 3.0, 31))
    assert blow.reason == NON_FINITE
    scaled = rk4(lambda x, n, s: x, np.array([1.0]), t, stop=StopRule(upper=4.0, scale=2.0))
    assert scaled.reason == ABOVE and scaled.stop == int(np.argmax(2.0 * np.exp(t) > 4.0))


def test_rk4_n_steps_and_bad_rules():
    run = rk4(lambda x, n, s: -x, np.array([1.0]), np.linspace(0.0, 1.0, 11), n_steps=4)
    assert np.isfinite(run.x[:5]).all() and np.isnan(run.x[5:]).all() and run.stop == -1
    with pytest.raises(ValueError, match="lower <= upper"):
        StopRule(upper=0.0, lower=1.0)
    with pytest.raises(ValueError, match="scale"):
        StopRule(scale=0.0)


# -- block bootstrap --------------------------------------------------------------------------------------

@pytest.mark.parametrize("draw", ["multinomial", "indices"])
def test_block_counts_resample_every_block_with_replacement(draw):
    counts = block_counts(7, 4000, np.random.default_rng(3), draw=draw)
    assert counts.shape == (4000, 7) and np.all(counts.sum(axis=1) == 7) and counts.min() >= 0
    # each block's count is Binomial(7, 1/7): mean 1, variance 6/7
    assert_close(counts.mean(axis=0), np.ones(7), atol=0.05, reason="4000 replicates: standard error 0.015")
    assert_close(counts.var(axis=0), np.full(7, 6 / 7), atol=0.08, reason="4000 replicates: standard error ~0.02")
    again = block_counts(7, 4000, np.random.default_rng(3), draw=draw)
    assert np.array_equal(counts, again)
    with pytest.raises(ValueError, match="draw must be one of"):
        block_counts(7, 1, np.random.default_rng(0), draw="poisson")
