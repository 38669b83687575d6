"""The permutation p-value counts a permuted statistic equal to the observed one, whatever the rounding."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from vivbench.regression.permutation import permutation_p_value


def test_exact_counts_and_ties_within_rounding():
    assert permutation_p_value(np.array([0.1, 0.2, 0.3]), 0.5) == 0.25  # none reaches it: 1 / (1 + 3)
    assert permutation_p_value(np.array([0.6, 0.2, 0.3]), 0.5) == 0.5
    x = 0.7
    # the observed value summed in another order: one ulp above and below count alike
    assert permutation_p_value(np.array([np.nextafter(x, 0.0), np.nextafter(x, 1.0), 0.1]), x) == 0.75


@settings(max_examples=50, deadline=None)
@given(seed=st.integers(0, 2**16), n=st.integers(3, 40))
def test_a_sum_in_any_order_is_a_tie(seed, n):
    """The statistic of an ordering that keeps the partition is the same sum in another order: always a tie."""
    rng = np.random.default_rng(seed)
    v = np.abs(rng.normal(size=n)) * 10.0 ** rng.uniform(-3, 3, n)  # gains: sums of terms >= 0
    observed = float(np.sum(v))
    null = np.array([float(np.sum(v[rng.permutation(n)])) for _ in range(9)] + [0.5 * observed])
    assert permutation_p_value(null, observed) == 10 / 11
