"""Block statistics held once and summed over any weighting of the blocks: equal to the dense design's sums."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.helpers import assert_close
from tests.models.test_varying_design import _design_inputs
from vivbench.library.splines import bspline_local_t, first_index, uniform_cubic_local_t, uniform_knots
from vivbench.models.varying_design import spline_design
from vivbench.models.varying_stats import block_statistics, one_hot


def _inputs(n_in):
    """The inputs of the dense design's test, one column per wind input (one: 1-D)."""
    knots, U, A, z, y, block = _design_inputs(n=5000, n_in=n_in)
    return (knots, U, A, z, y, block) if n_in > 1 else (knots, U[:, 0], A, z[:, 0], y, block)


@pytest.mark.parametrize("n_in,J,weighted", [(1, 0, False), (1, 1, True), (1, 2, False), (1, 2, True), (3, 1, True)])
def test_weighted_sums_of_blocks_equal_the_dense_design(n_in, J, weighted):
    knots, U, A, z, y, block = _inputs(n_in)
    w = np.random.default_rng(1).uniform(0.5, 2.0, y.size) if weighted else None
    n_blocks = 10  # block 9 holds no sample: zero statistics
    stats = block_statistics(U, A, y, block, n_blocks, knots, 0.1, z if J else None, J, w, chunk=700)
    X = spline_design(U, A, knots, 0.1, z if J else None, J)
    yw = y.copy()
    if w is not None:
        X, yw = X * np.sqrt(w)[:, None], y * np.sqrt(w)
    # every block alone, two groupings of blocks and bootstrap-like multiplicities
    weights = np.vstack([np.eye(n_blocks), one_hot(np.arange(n_blocks) % 3, 3),
                         np.random.default_rng(2).integers(0, 3, (4, n_blocks))]).astype(float)
    G, b, yy = stats.sums(weights)
    for r, wr in enumerate(weights):
        ws = wr[block]
        Xr = X * np.sqrt(ws)[:, None]
        Gd, bd = Xr.T @ Xr, X.T @ (ws * yw)
        scale = max(np.abs(Gd).max(), 1e-300)
        assert_close(G[r] / scale, Gd / scale, atol=1e-13, rtol=0.0,
                     reason="sums of a few thousand products in another order, from the moments' powers")
        assert_close(b[r], bd, atol=1e-11 * max(np.abs(bd).max(), 1.0), rtol=0.0,
                     reason="sums of a few thousand products in another order")
        assert_close(yy[r], np.sum(ws * yw**2), rtol=1e-12, reason="sums in another order")
    assert np.array_equal(stats.count, np.bincount(block, minlength=n_blocks))
    Gt, bt, yt = stats.total()
    assert_close(Gt, G[:n_blocks].sum(axis=0), rtol=1e-12, atol=1e-12 * np.abs(Gt).max(),
                 reason="sums in another order")


@settings(max_examples=40, deadline=None)
@given(lo=st.floats(-5.0, 20.0), width=st.floats(0.5, 30.0), M=st.integers(4, 25), seed=st.integers(0, 2**16))
def test_the_closed_form_uniform_cubic_equals_the_recursion(lo, width, M, seed):
    knots = uniform_knots(lo, lo + width, M)
    U = np.r_[np.random.default_rng(seed).uniform(lo - 1.0, lo + width + 1.0, 500), knots[3:M + 1]]
    f1, v1 = bspline_local_t(U, knots)
    f2, v2 = uniform_cubic_local_t(U, knots)
    assert np.array_equal(f1, f2)
    assert_close(v2, v1, atol=1e-13, rtol=0.0, reason="another sequence of roundings of values in [0, 1]")
    f3, v3 = uniform_cubic_local_t(U, knots, first_index(U, knots))  # the caller's own first index
    assert np.array_equal(f3, f2) and np.array_equal(v3, v2)
