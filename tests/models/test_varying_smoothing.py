"""The varying model's wind smoothing: the prior kept unless the cross-validated dA/dt error demands another."""

from __future__ import annotations

import numpy as np
import pytest

from vivbench.models import VaryingCoefficientSINDy
from vivbench.models.varying_fit import (SMOOTHING_MIN_FOLDS, smoothing_candidates, smoothing_choice,
                                         smoothing_evidence)


def test_smoothing_choice_keeps_the_prior_on_noisy_evidence():
    prior = np.array([1.0, 1.2, 0.9, 1.1, 1.0])
    # Lower in sum, but by less than one standard error of the paired fold differences.
    noisy = prior + np.array([-0.5, 0.4, -0.3, 0.35, -0.05])
    assert noisy.sum() < prior.sum()
    cv = np.array([noisy.sum(), prior.sum()])
    assert smoothing_choice(cv, [noisy, prior], prior=1) == 1


def test_smoothing_choice_takes_the_lowest_candidate_beyond_one_standard_error():
    prior = np.array([1.0, 1.2, 0.9, 1.1, 1.0])
    better = prior - np.array([0.10, 0.12, 0.09, 0.11, 0.10])  # lower in every fold
    best = prior - np.array([0.20, 0.25, 0.18, 0.22, 0.21])
    folds = [better, prior, best]
    cv = np.array([f.sum() for f in folds])
    assert smoothing_choice(cv, folds, prior=1) == 2
    # Candidates not scored yet (None, NaN) are skipped; with fewer folds than SMOOTHING_MIN_FOLDS the prior stays.
    assert smoothing_choice(np.array([better.sum(), prior.sum(), np.nan]), [better, prior, None], prior=1) == 0
    few = SMOOTHING_MIN_FOLDS - 1
    assert smoothing_choice(np.array([best[:few].sum(), prior[:few].sum()]), [best[:few], prior[:few]], prior=1) == 1


def test_smoothing_candidates_put_the_prior_first_when_the_grid_lacks_it():
    assert smoothing_candidates(VaryingCoefficientSINDy()) == [30.0]
    assert smoothing_candidates(VaryingCoefficientSINDy(wind_smoothing_grid=(10, 30, 60))) == [10.0, 30.0, 60.0]
    assert smoothing_candidates(VaryingCoefficientSINDy(wind_smoothing_s=45.0, wind_smoothing_grid=(10, 30))) == [
        45.0, 10.0, 30.0]


@pytest.mark.parametrize("kind", ["exact", "noisy"])
def test_fit_records_the_prior_or_the_evidence(kind):
    from tests.models.test_varying import _measured, _records

    records = _records(8) if kind == "exact" else _measured(_records(8))
    model = VaryingCoefficientSINDy(n_basis=(11,), n_bootstrap=0, wind_smoothing_s=30.0,
                                    wind_smoothing_grid=(0.0, 30.0)).fit(records)
    assert model.wind_smoothing_cv_.shape == (2,)
    ev = smoothing_evidence(model)
    assert ev["candidates_s"] == [0.0, 30.0] and ev["prior_s"] == 30.0 and ev["chosen_s"] == model.wind_smoothing_s_
    if kind == "exact":
        # The deck's own wind: smoothing only blurs it, on every fold.
        assert model.wind_smoothing_s_ == 0.0
    else:
        # A point anemometer's 20 s turbulence the deck does not feel: the prior stays.
        assert model.wind_smoothing_s_ == 30.0


def test_the_evidence_says_which_smoothing_and_why():
    from vivbench.analysis.selection_text import _smoothing_lines

    assert smoothing_evidence(object()) is None
    prior = {"chosen_s": 30.0, "prior_s": 30.0, "candidates_s": [10.0, 30.0, 60.0], "cv_error": [0.52, 0.5, 0.51]}
    (line,) = _smoothing_lines(prior)
    assert "wind smoothing 30 s" in line and "10 s 0.52" in line and "the prior, not beaten" in line
    (line,) = _smoothing_lines({**prior, "chosen_s": 10.0, "cv_error": [0.4, 0.5, 0.51]})
    assert "wind smoothing 10 s" in line and "below the 30 s prior's" in line
    assert _smoothing_lines({**prior, "candidates_s": [30.0], "cv_error": [0.5]}) == [
        "  wind smoothing 30 s (given or the prior; not chosen here)"]
    assert _smoothing_lines(None) == []
