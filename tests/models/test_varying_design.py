"""The fast numerics of the varying-coefficient model equal the straightforward ones.

The B-spline local form against scipy's ``BSpline.design_matrix`` (the reference), the grouped block
statistics against dense X_b^T X_b per block, each wind input's contribution against the dense design
times the coefficients, and the per-window Gram matrices against sums over each window's samples.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import BSpline

from tests.helpers import assert_close, bell_records
from vivbench.core import Record
from vivbench.models import VaryingCoefficientSINDy
from vivbench.models.varying import DEGREE, bspline_basis, bspline_local, uniform_knots
from vivbench.regimes import window_grams


def _scipy_basis(U, knots):
    """The reference: scipy's design matrix at U clipped to the base interval, NaN rows NaN."""
    U = np.asarray(U, dtype=float)
    ok = np.isfinite(U)
    x = np.clip(np.where(ok, U, knots[DEGREE]), knots[DEGREE], knots[-DEGREE - 1])
    B = BSpline.design_matrix(x, knots, DEGREE).toarray()
    B[~ok] = np.nan
    return B


@pytest.mark.parametrize("M", [4, 6, 10, 15])
def test_bspline_local_matches_scipy(M):
    rng = np.random.default_rng(M)
    lo, hi = 3.7, 12.9
    knots = uniform_knots(lo, hi, M)
    # random winds, both ends, every interior knot (interval edges), beyond the range (clipped), NaN
    U = np.concatenate([rng.uniform(lo, hi, 2000), [lo, hi], knots[DEGREE:-DEGREE], rng.uniform(-5.0, 30.0, 200),
                        [np.nan, -np.inf, np.inf]])
    ref = _scipy_basis(U, knots)
    B = bspline_basis(U, knots)
    # same recursion, same operation order: equal to rounding (in practice to the bit)
    assert_close(B[np.isfinite(U)], ref[np.isfinite(U)], atol=1e-15, rtol=0.0,
                 reason="absolute: the basis values are in [0, 1] and exact zeros outside the support")
    assert np.array_equal(np.isnan(B), np.isnan(ref))
    first, vals = bspline_local(U, knots)
    rows = np.arange(U.size)[:, None]
    picked = ref[rows, first[:, None] + np.arange(DEGREE + 1)]
    ok = np.isfinite(U)
    assert np.all((first >= 0) & (first <= M - DEGREE - 1))
    assert_close(vals[ok], picked[ok], atol=1e-15, rtol=0.0, reason="absolute: values in [0, 1]")
    # local support: the picked functions carry the whole row
    assert_close(vals[ok].sum(axis=1), np.nansum(ref[ok], axis=1), atol=1e-14, rtol=0.0, reason="sums of 4 values")
    assert np.all(np.isnan(vals[~ok]))


def _design_inputs(n=6000, n_in=3, seed=0):
    rng = np.random.default_rng(seed)
    knots = uniform_knots(4.0, 12.0, 8)
    U = np.clip(8.0 + np.cumsum(rng.normal(0.0, 0.08, (n, n_in)), axis=0), 3.0, 13.0)
    U[rng.random(n) < 0.02, 0] = 12.0  # the right end: the last interval
    A = rng.uniform(0.0, 0.3, n)
    z = rng.uniform(0.0, 2.0, (n, n_in))
    y = rng.normal(size=n)
    block = np.sort(rng.integers(0, 9, n))
    return knots, U, A, z, y, block


@pytest.mark.parametrize("n_in,J,weighted", [(3, 1, False), (3, 1, True), (1, 0, False), (2, 2, True)])
def test_block_stats_equal_dense(n_in, J, weighted):
    from vivbench.models import varying_design as vd

    knots, U, A, z, y, block = _design_inputs(n_in=n_in)
    if n_in == 1:
        U, z = U[:, 0], z[:, 0]
    w = np.random.default_rng(1).uniform(0.5, 2.0, y.size) if weighted else None
    n_blocks = 10  # block 9 holds no sample: zero statistics
    G, b, yy, cnt = vd.block_stats(U, A, y, block, n_blocks, knots, 0.1, z if J else None, J, w, chunk=700)
    X = vd.spline_design(U, A, knots, 0.1, z if J else None, J)
    yw = y.copy()
    if weighted:
        X, yw = X * np.sqrt(w)[:, None], y * np.sqrt(w)
    for j in range(n_blocks):
        r = block == j
        scale = max(np.abs(X[r].T @ X[r]).max(), 1e-300)
        assert_close(G[j] / scale, X[r].T @ X[r] / scale, atol=1e-13, rtol=0.0,
                     reason="sums of a few thousand products in another order")
        assert_close(b[j], X[r].T @ yw[r], atol=1e-11 * max(np.abs(X[r].T @ yw[r]).max(), 1.0), rtol=0.0,
                     reason="sums of a few thousand products in another order")
        assert_close(yy[j], np.sum(yw[r] ** 2), rtol=1e-12, reason="running sums")
        assert cnt[j] == r.sum()


def test_input_contributions_sum_to_the_design():
    from vivbench.models import varying_design as vd

    knots, U, A, z, _y, _b = _design_inputs(n=3000)
    c = np.random.default_rng(2).normal(size=4 * 2 * 3 * 8)
    parts = vd.input_contributions(U, A, knots, 0.1, z, 1, c)
    full = vd.spline_design(U, A, knots, 0.1, z, 1) @ c
    assert parts.shape == (3, U.shape[0])
    assert_close(parts.sum(axis=0), full, atol=1e-12 * np.abs(full).max(), rtol=0.0, reason="sums in another order")
    # each input's share: the design with only that input's columns
    X = vd.spline_design(U, A, knots, 0.1, z, 1).reshape(U.shape[0], 4, 2, 3, 8)
    for s in range(3):
        own = X[:, :, :, s, :].reshape(U.shape[0], -1) @ c.reshape(4, 2, 3, 8)[:, :, s, :].ravel()
        assert_close(parts[s], own, atol=1e-12 * np.abs(own).max(), rtol=0.0, reason="sums in another order")


def _records(n_events=4, S=2, seed=5):
    """Noisy records with a bell at 9 m/s, each section's wind wandering off the deck's, and a yaw the truth ignores."""
    return bell_records(n_events, seed=seed, duration_s=600.0, dt_s=0.5, mode_shape=np.linspace(1, 0.7, S),
                        wind_spread_m_s=5.0, wind_period_s=(400.0, 50.0), wind_walk_m_s=0.3,
                        amplitude_period_s=200.0, yaw_deg=15.0, yaw_period_s=500.0, yaw_in_truth=False,
                        bell_centre_m_s=9.0, a3=-2.0, noise_m_s=1e-4)


def test_window_grams_equal_window_sums():
    recs = _records()
    model = VaryingCoefficientSINDy(n_basis=(7,), penalties=(1e-3,), n_bootstrap=3, wind_input="additive",
                                    wind_smoothing_s=0.0, block_s=150.0).fit(recs)
    rec = recs[1]
    A = rec.A.copy()
    A[100:130, 0] = np.nan  # an invalid stretch
    A[400:420, 1] = 0.0  # not positive: valid, but out of the mean of r_1 / A
    rec = Record(event_id=rec.event_id, t=rec.t, A=A, U=rec.U, dA=rec.dA, yaw=rec.yaw)
    start = np.arange(0.0, 560.0, 20.0)
    end = start + 45.0  # overlapping windows
    end[-1] = 1e4  # one reaching past the record
    stats = window_grams(model, rec, start, end)
    cols, vals = model.basis_rows(rec)
    n, S, _ = vals.shape
    P = stats["gram"].shape[-1]
    for k in range(S):
        phi = np.zeros((n, P))
        phi[np.arange(n)[:, None], cols[:, k]] = vals[:, k]
        ok = np.isfinite(vals[:, k]).all(axis=1) & np.isfinite(A[:, k])
        for w, (a, b) in enumerate(zip(start, end)):
            r = ok & (rec.t >= a) & (rec.t < b)
            assert stats["n_valid"][w, k] == r.sum()
            for i in range(4):
                ref = (phi[r] * A[r, k, None] ** (2 * i)).T @ phi[r]
                scale = max(np.abs(ref).max(), 1e-300)
                assert_close(stats["gram"][w, k, i] / scale, ref / scale, atol=1e-13, rtol=0.0,
                             reason="sums of a few hundred products in another order")
            pos = r & (A[:, k] > 0)
            assert stats["n_positive"][w, k] == pos.sum()
            assert_close(stats["mean1"][w, k], phi[pos].sum(axis=0), atol=1e-12, rtol=0.0, reason="sums of values <= 1")


def test_split_gains_of_permuted_orderings_equal_direct_fits():
    from vivbench.analysis import changes
    from vivbench.models.varying import difference_penalty, penalised_rss

    rng = np.random.default_rng(7)
    E, p, M = 9, 16, 4
    X = rng.normal(size=(E, 40, p))
    G = np.einsum("enp,enq->epq", X, X)
    b = np.einsum("enp,en->ep", X, rng.normal(size=(E, 40)))
    yy = 40.0 + rng.random(E) * 10.0
    P = np.kron(np.eye(p // M), difference_penalty(M))
    keep = np.ones(p, dtype=bool)
    keep[:M] = False  # a dropped order
    stats = [{"G": G, "b": b, "yy": yy, "P": P, "penalty": 0.3, "keep": keep}]
    order = np.stack([rng.permutation(E) for _ in range(5)])
    splits = np.arange(2, E - 1)
    gain = changes._split_gain(changes._reduced_sums(stats), order, splits)
    args = (P, 0.3, keep)
    full = penalised_rss(G.sum(0), b.sum(0), yy.sum(), *args)
    for r in range(order.shape[0]):
        for j, k in enumerate(splits):
            pre, post = order[r, :k], order[r, k:]
            rss = (penalised_rss(G[pre].sum(0), b[pre].sum(0), yy[pre].sum(), *args)
                   + penalised_rss(G[post].sum(0), b[post].sum(0), yy[post].sum(), *args))
            assert_close(gain[r, j], (full - rss) / full, atol=1e-12, rtol=0.0,
                         reason="relative RSS drops of order 1 from sums in another order")
