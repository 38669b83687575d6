"""The varying model's ``penalty_choice``: the least penalty the held-out events cannot tell from the best."""

from __future__ import annotations

import dataclasses
import json
import shutil

import numpy as np
import pytest
import xarray as xr

from tests.helpers import assert_close, bell, bell_records
from vivbench.core.errors import InputError
from vivbench.models import VaryingCoefficientSINDy


def _noisy_wind_records(n_events: int = 10, seed: int = 2, error_m_s: float = 0.5):
    """dA/dt = bell(U) A - 2 A^3 on the deck's wind; the records carry that wind plus a slow classical error.

    The error (a 60 s moving average of white noise, rescaled to ``error_m_s`` RMS, one per event and section)
    is what a point anemometer adds to the wind the deck feels; both sections get the same one, so the mean
    wind carries it whole.
    """
    recs = bell_records(n_events, seed=seed, duration_s=1800.0, dt_s=1.0, mode_shape=np.array([1.0, 0.7]),
                        wind_period_s=(500.0, 80.0), amplitude_period_s=250.0, a3=-2.0, noise_m_s=1e-4)
    rng = np.random.default_rng(seed + 100)
    out = []
    for r in recs:
        e = np.convolve(rng.standard_normal(r.t.size + 59), np.ones(60) / 60.0, mode="valid")
        e *= error_m_s / e.std()
        out.append(dataclasses.replace(r, U=r.U + e[:, None]))
    return out


SETTINGS = dict(n_basis=(11,), wind_smoothing_s=0.0, eiv_weights=False, n_bootstrap=0, block_s=300.0,
                wind_weights="equal")


@pytest.fixture(scope="module")
def fits():
    recs = _noisy_wind_records()
    return {choice: VaryingCoefficientSINDy(penalty_choice=choice, **SETTINGS).fit(recs)
            for choice in ("cv", "least", "loeo")}


def test_loeo_penalty_is_the_best_of_the_set(fits):
    loeo, cv = fits["loeo"], fits["cv"]
    pen = np.asarray(loeo.penalties)
    np.testing.assert_array_equal(loeo.penalty_cv_, cv.penalty_)  # the 5-fold choice, recorded
    for k in range(2):
        chosen = np.flatnonzero(pen == loeo.penalty_[k])[0]
        assert loeo.penalty_plausible_[chosen, k]  # the confidence set's best is always in it
        assert_close(loeo.penalty_coef_[chosen, k], loeo.coef_[k], atol=1e-12, reason="rounding near zero")


def test_least_penalty_is_the_smallest_plausible(fits):
    cv, least = fits["cv"], fits["least"]
    pen = np.asarray(least.penalties)
    for k in range(2):
        # both record the cross-validated minimum; "least" fits the smallest penalty of the confidence set
        assert least.penalty_cv_[k] == cv.penalty_[k] == cv.penalty_cv_[k]
        assert least.penalty_[k] == pen[least.penalty_plausible_[:, k]].min()
        assert least.penalty_[k] <= least.penalty_cv_[k]
        chosen = np.flatnonzero(pen == least.penalty_[k])[0]
        assert_close(least.penalty_coef_[chosen, k], least.coef_[k], atol=1e-12, reason="rounding near zero")


def _a1_errors(models: dict) -> dict:
    """RMS error of each model's a_1 curve against the bell over its peak, 1/s."""
    wind = np.linspace(8.5, 11.5, 31)
    return {name: float(np.sqrt(np.mean((m.curves(wind)["curves"].values[:, 1] - bell(wind)) ** 2)))
            for name, m in models.items()}


def test_least_penalty_takes_the_smallest_candidate_when_none_is_rejected(fits):
    # Here the wind's error is large (0.5 m/s) and the same at every section (the sections' spread does not
    # show it), and ten events reject no small penalty, so "least" takes the smallest candidate.
    least = fits["least"]
    assert least.penalty_plausible_[0].all()  # the smallest candidate is plausible for every equation
    np.testing.assert_array_equal(least.penalty_, min(least.penalties))


@pytest.mark.xfail(strict=True, reason="known failure: an error in the wind that every section shares biases "
                   "every held-out event alike, so neither the penalties' confidence set nor the held-out choice "
                   "between cv and least sees that the least penalty's curve overshoots the bell's peak")
def test_the_chosen_penalty_does_not_overshoot_a_bell_under_a_shared_wind_error(fits):
    from vivbench.analysis.selection import varying_selection

    chosen = varying_selection(criterion="derivative", options={"penalty_choice": ("cv", "least")},
                               n_perturbations=0, **SETTINGS).fit(_noisy_wind_records())
    err = _a1_errors({"cv": fits["cv"], "chosen": chosen})
    assert err["chosen"] <= 1.5 * err["cv"]


def test_choice_is_validated_saved_and_defaults_for_older_files(fits, tmp_path):
    with pytest.raises(InputError, match="penalty_choice must be one of 'cv', 'least', 'loeo'"):
        VaryingCoefficientSINDy(penalty_choice="smallest").fit(_noisy_wind_records(2))
    with pytest.raises(InputError, match="wind_weights must be 'modal', 'equal'"):
        VaryingCoefficientSINDy(wind_weights="auto").fit(_noisy_wind_records(2))
    assert (VaryingCoefficientSINDy().penalty_choice, VaryingCoefficientSINDy().wind_weights) == ("cv", "modal")
    path = fits["least"].save(tmp_path / "m.nc")
    loaded = VaryingCoefficientSINDy.load(path)
    assert loaded.penalty_choice == loaded.penalty_choice_ == "least"
    assert loaded.wind_weights_choice_ == "equal"
    np.testing.assert_array_equal(loaded.penalty_cv_, fits["least"].penalty_cv_)
    with xr.open_dataset(path) as ds:
        old = ds.load()
    params = json.loads(old.attrs["params_json"])
    del params["penalty_choice"], params["wind_weights"]
    old.attrs["params_json"] = json.dumps(params)
    for key in ("penalty_cv", "penalty_choice_fitted", "wind_weights_choice"):
        del old.attrs[key]
    old.to_netcdf(tmp_path / "old.nc")
    older = VaryingCoefficientSINDy.load(tmp_path / "old.nc")
    assert older.penalty_choice == older.penalty_choice_ == "cv" and older.wind_weights_choice_ == "equal"
    np.testing.assert_array_equal(older.penalty_cv_, older.penalty_)


def test_files_of_the_former_size_rule_load_with_the_choice_they_made(fits, tmp_path):
    # Files written while wind_weights and penalty_choice defaulted to "auto" (chosen by the campaign's size)
    # load with the weights and penalty choice the fit made.
    path = fits["least"].save(tmp_path / "m.nc")
    with xr.open_dataset(path) as ds:
        old = ds.load()
    params = json.loads(old.attrs["params_json"])
    params["penalty_choice"] = params["wind_weights"] = "auto"
    old.attrs["params_json"] = json.dumps(params)
    old.to_netcdf(tmp_path / "auto.nc")
    loaded = VaryingCoefficientSINDy.load(tmp_path / "auto.nc")
    assert (loaded.penalty_choice, loaded.wind_weights) == ("least", fits["least"].wind_weights_choice_)
    np.testing.assert_array_equal(loaded.coef_, fits["least"].coef_)


def test_pool_passes_the_choice_to_the_model(small_results, tmp_path):
    from vivbench.analysis import load_campaign_model
    from vivbench.cli import main

    _camp, res_dir, _ = small_results
    res = tmp_path / "res"
    shutil.copytree(res_dir, res)
    assert main(["pool", str(res), "--model", "varying", "--bootstrap", "4", "--block", "20",
                 "--wind-weights", "modal", "--penalty-choice", "least", "--wind-smoothing-grid", "10,30"]) == 0
    model = load_campaign_model(res)
    assert model.penalty_choice == "least" and model.wind_weights == "modal"
    # The grid's choice is recorded beside the prior, and the model holds the chosen smoothing.
    from vivbench.io.campaign_model import read_campaign_regimes, regimes_file

    chosen = json.loads(read_campaign_regimes(regimes_file(res)).attrs["selection_json"])["wind_smoothing"]
    assert (chosen["candidates_s"], chosen["prior_s"]) == ([10.0, 30.0], 30.0)
    assert model.fitted_wind_smoothing() == chosen["chosen_s"]
    assert np.all(model.penalty_ <= model.penalty_cv_)
    pen = np.asarray(model.penalties)
    for k in range(model.n_sections_):
        assert model.penalty_[k] == pen[model.penalty_plausible_[:, k]].min()
