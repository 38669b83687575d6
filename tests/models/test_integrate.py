"""The RK4 integrator's stop rule (vivbench.models.integrate.StopRule)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from vivbench.models.integrate import ABOVE, BELOW, NON_FINITE, NOT_STOPPED, StopRule


def _codes(rule: StopRule, x: np.ndarray) -> np.ndarray:
    """The rule's definition, trajectory by trajectory: non-finite, then above, then below."""
    out = np.full(x.shape[:-1], NOT_STOPPED)
    for i in np.ndindex(x.shape[:-1]):
        y = rule.scale * x[i]
        if not np.isfinite(x[i]).all():
            out[i] = NON_FINITE
        elif (y > rule.upper).any():
            out[i] = ABOVE
        elif (y < rule.lower).any():
            out[i] = BELOW
    return out


_values = st.sampled_from([0.0, 0.5, -0.2, 2.0, 1e308, -3.0, np.nan, np.inf, -np.inf])


@settings(max_examples=200, deadline=None)
@given(st.lists(_values, min_size=6, max_size=6), st.sampled_from([(1.0, -0.1), (np.inf, -np.inf), (3.0, -np.inf)]),
       st.sampled_from([1.0, 10.0]), st.sampled_from([(3, 2), (6,), (1, 6)]))
def test_stop_codes_follow_the_rules_definition(values, bounds, scale, shape):
    rule = StopRule(upper=bounds[0], lower=bounds[1], scale=scale)
    x = np.array(values).reshape(shape)
    with np.errstate(over="ignore", invalid="ignore"):
        got = rule.check(x)
        expected = _codes(rule, x)
    assert got.shape == x.shape[:-1] and np.array_equal(got, expected)
