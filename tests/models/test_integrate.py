"""The RK4 integrator's stop rule (vivbench.models.integrate.StopRule)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vivbench.models.integrate import ABOVE, BELOW, NON_FINITE, NOT_STOPPED, StopRule, rk4


def _codes(rule: StopRule, x: np.ndarray) -> np.ndarray:
    """The rule's definition, trajectory by trajectory: non-finite, then above, then below."""
    out = np.full(x.shape[:-1], NOT_STOPPED)
    upper = np.broadcast_to(rule.upper, x.shape[:-1])
    lower = np.broadcast_to(rule.lower, x.shape[:-1])
    for i in np.ndindex(x.shape[:-1]):
        y = rule.scale * x[i]
        if not np.isfinite(x[i]).all():
            out[i] = NON_FINITE
        elif (y > upper[i]).any():
            out[i] = ABOVE
        elif (y < lower[i]).any():
            out[i] = BELOW
    return out


_values = st.sampled_from([0.0, 0.5, -0.2, 2.0, 1e308, -3.0, np.nan, np.inf, -np.inf])


@settings(max_examples=200, deadline=None)
@given(st.lists(_values, min_size=6, max_size=6), st.sampled_from([(1.0, -0.1), (np.inf, -np.inf), (3.0, -np.inf)]),
       st.sampled_from([1.0, 10.0]), st.sampled_from([(3, 2), (6,), (1, 6)]))
@pytest.mark.parametrize("per_trajectory", [False, True])
def test_stop_codes_follow_the_rules_definition(per_trajectory, values, bounds, scale, shape):
    upper, lower = bounds
    if per_trajectory:  # each trajectory its own bounds: the given ones scaled by 1, 2, ...
        factor = np.arange(1.0, 1.0 + np.prod(shape[:-1])).reshape(shape[:-1])
        upper, lower = upper * factor, lower * factor
    rule = StopRule(upper=upper, lower=lower, scale=scale)
    x = np.array(values).reshape(shape)
    with np.errstate(over="ignore", invalid="ignore"):
        got = rule.check(x)
        expected = _codes(rule, x)
    assert got.shape == x.shape[:-1] and np.array_equal(got, expected)


def test_runs_on_their_own_grids_are_the_runs_integrated_alone():
    """A batch of trajectories, each on its own time grid and bounds (NaN after its end), gives each one's own run."""
    def rhs(x, n, stage):
        return 0.3 * x - x**3

    grids = [np.linspace(0.0, 20.0, 41), np.linspace(5.0, 12.0, 23)]
    x0 = np.array([[0.1, 0.2], [1.5, 0.05]])
    tops = np.array([2.0, 1.0])
    grid = np.full((41, 2), np.nan)
    grid[:41, 0], grid[:23, 1] = grids
    batch = rk4(rhs, x0, grid, stop=StopRule(upper=tops, lower=-tops))
    for b in range(2):
        alone = rk4(rhs, x0[b], grids[b], stop=StopRule(upper=tops[b], lower=-tops[b]))
        n = grids[b].size
        assert np.array_equal(batch.x[:n, b], alone.x, equal_nan=True)
        assert batch.stop[b] == alone.stop or (alone.stop < 0 and batch.stop[b] >= n)
    assert batch.stop[1] == 1  # 1.5 is above its bound of 1 at the first step
