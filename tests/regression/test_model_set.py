"""The confidence set of models from per-event held-out losses, and its margin."""

from __future__ import annotations

import numpy as np
import pytest

from vivbench.regression.model_set import MODEL_SET_TESTS, confidence_set


def _losses(seed=0, n_events=40):
    """Per-event losses of three models: the best, one 0.3 % worse on every event, one 5 % worse."""
    rng = np.random.default_rng(seed)
    best = rng.lognormal(0.0, 1.0, n_events)
    return np.vstack([best, best * 1.003 * (1 + 1e-4 * rng.random(n_events)), best * 1.05])


@pytest.mark.parametrize("test", MODEL_SET_TESTS)
def test_a_consistent_negligible_excess_is_significant_but_within_the_margin(test):
    loss = _losses()
    assert confidence_set(loss, 0.95, test).tolist() == [True, False, False]
    assert confidence_set(loss, 0.95, test, margin=0.005).tolist() == [True, True, False]
    assert confidence_set(loss, 0.95, test, margin=0.1).all()


@pytest.mark.parametrize("test", MODEL_SET_TESTS)
def test_the_margin_only_adds_models(test):
    rng = np.random.default_rng(1)
    for _ in range(20):
        loss = rng.lognormal(0.0, 1.0, (5, 12)) * rng.uniform(1.0, 1.2, (5, 1))
        plain = confidence_set(loss, 0.9, test)
        for margin in (0.001, 0.01, 0.1):
            wide = confidence_set(loss, 0.9, test, margin=margin)
            assert np.all(wide >= plain) and wide[np.argmin(loss.sum(axis=1))]


@pytest.mark.parametrize("margin", [-0.01, float("nan"), float("inf")])
def test_a_bad_margin_is_refused(margin):
    with pytest.raises(ValueError, match="margin must be a finite number >= 0"):
        confidence_set(_losses(), 0.95, margin=margin)
