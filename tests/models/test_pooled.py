"""The pooled campaign model: exact compression, regimes against the truth, the bootstrap verdict."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.helpers import assert_close, assert_not_close
from vivbench.models.campaign import PooledSINDy
from vivbench.models.campaign_verdicts import pooled_window_stats
from vivbench.regimes import campaign_window_verdicts
from vivbench.regression.settings import StlsqSettings
from vivbench.regression.stlsq import stlsq_path
from vivbench.library.basis import window_library
from vivbench.regression.stlsq import aicc
from vivbench.models.campaign import _block_factors, _replicate_fits
from vivbench.core.regime import classify_regime
from vivbench.synth import CampaignConfig
from vivbench.core.terms import evaluate_library, section_exponents
from vivbench.regimes.truth import truth_window_regimes


def _truth(sim):
    """The averaged truth of a simulated event as (t, A, U, dA) and a /truth-like Dataset."""
    import xarray as xr

    phi = np.abs(np.asarray(CampaignConfig().generator.structure.mode_shape))
    A = sim.Q[:, None] * phi
    ds = xr.Dataset({"A": (("time", "section"), A), "r": (("time", "section", "order"), sim.r)},
                    coords={"time": sim.truth_time})
    return (sim.truth_time, A, sim.U, sim.r.sum(-1)), ds


def test_replicates_equal_the_explicitly_resampled_fit():
    """A weighted stack of block factors gives the fit of the data with blocks repeated."""
    rng = np.random.default_rng(3)
    n, S = 600, 3
    t = np.arange(n) * 0.5
    U = 7.0 + 2.0 * np.sin(t / 60.0)[:, None] + 0.1 * np.arange(S)
    A = 0.05 + 0.04 * (1 + np.sin(t / 40.0))[:, None] * np.array([0.7, 1.0, 0.7]) + 1e-3 * rng.standard_normal((n, S))
    dA = 0.01 * A - 0.05 * A**2 + 1e-4 * U * A + 1e-4 * rng.standard_normal((n, S))
    lib = window_library(A[None], U[None])
    y = dA / np.sqrt(np.mean(dA**2, axis=0))
    block = (t // 50.0).astype(int)
    nb = block.max() + 1
    settings = StlsqSettings()
    mult = np.zeros((1, nb))
    mult[0, :] = rng.integers(0, 3, nb)
    mult[0, 0] = 2
    coef, sel, rss, _ = _replicate_fits(_block_factors(lib.theta[0], y, block, nb), mult, settings, chunk_size=4)
    rows = np.concatenate([np.repeat(np.flatnonzero(block == b), int(mult[0, b])) for b in range(nb)])
    direct = stlsq_path(lib.theta[0][rows], y[rows], settings)
    scores = aicc(direct.rss, direct.n_terms, rows.size, floor=settings.residual_floor**2 * (y[rows] ** 2).sum(0)[None, :, None])
    scores = np.where(np.isfinite(direct.aicc), scores, np.inf)
    pick = np.argmin(scores, axis=2)[0]
    assert np.array_equal(sel[0], pick)
    best = direct.coef[0, np.arange(S), pick]
    assert np.array_equal(coef[0] != 0, best != 0)
    # rounding differs between the compressed and the full QR (condition number of the window library)
    assert_close(coef[0], best, rtol=1e-7, atol=1e-9, reason="two QR orders of an ill-conditioned library")
    assert_close(rss[0], direct.rss[0, np.arange(S), pick], rtol=1e-6, reason="RSS as a difference of squares")


def test_window_stats_follow_the_shared_rule():
    """The cumulative-sum window statistics give classify_regime's regimes."""
    rng = np.random.default_rng(0)
    n, S = 400, 3
    t = np.arange(n) * 0.25
    A = 0.1 + 0.05 * rng.random((n, S))
    U = 8.0 + rng.random((n, S))
    models = rng.standard_normal((2, S, 23 * S)) * 1e-3
    start = np.array([0.0, 20.0, 40.0])
    end = start + 50.0
    R, c1, nv = pooled_window_stats(models, t, A, U, start, end)
    from vivbench.core.regime import regime_rule

    theta = evaluate_library(A, U)
    orders = np.tile(section_exponents()[:, 0], S)
    for m in range(2):
        r = np.stack([theta[:, orders == i] @ models[m][:, orders == i].T for i in range(4)], axis=-1)
        for w in range(start.size):
            sel = (t >= start[w]) & (t < end[w])
            assert nv[w] == sel.sum()
            assert np.array_equal(regime_rule(R[m, w], c1[m, w], 0.2), classify_regime(r[sel], A[sel], axis=0))


def test_pooled_model_recovers_the_true_regimes(event1_in_library):
    """Exact averaged dynamics of the paper-like event: every window labelled as the truth, and identifiable."""
    # exact recovery needs the truth inside the library: the in_library mode
    _spec, sim = event1_in_library
    (t, A, U, dA), truth_ds = _truth(sim)
    model = PooledSINDy(n_bootstrap=20, block_s=100.0, seed=1).fit([(t, A, U, dA)])
    start = np.arange(t[0], t[-1] - 50.0, 25.0)
    end = start + 50.0
    out = campaign_window_verdicts(model, t, A, U, start, end)
    truth = truth_window_regimes(truth_ds, start, end)
    assert np.array_equal(out["regime"], truth)
    assert out["identifiable"].mean() > 0.9
    pred = evaluate_library(A, U) @ model.coef_.T
    assert_close(pred, dA, rtol=0, atol=1e-4 * np.abs(dA).max(), reason="sparse refit of exact dynamics")


def test_a_plateau_alone_is_not_identifiable():
    """A forced steady state with noise: the orders cannot be told apart and the bootstrap says so."""
    rng = np.random.default_rng(5)
    n = 4000
    t = np.arange(n) * 0.25
    A = (0.2 + 0.002 * rng.standard_normal(n))[:, None] * np.array([0.707, 1.0, 0.707])
    U = 8.0 + 0.05 * np.sin(t / 100.0)[:, None] + np.array([0.0, 0.02, 0.04])
    dA = 1e-4 * rng.standard_normal((n, 3))
    model = PooledSINDy(n_bootstrap=30, block_s=100.0, seed=0).fit([(t, A, U, dA)])
    start = np.arange(0.0, t[-1] - 50.0, 25.0)
    out = campaign_window_verdicts(model, t, A, U, start, start + 50.0)
    assert out["identifiable"].mean() < 0.5
    # the near-null-space test alone must see it: the bootstrap agrees on a stable but arbitrary split
    assert out["robust"].mean() < 0.5, out["robust"].mean()


def test_same_seed_same_model_and_validation():
    rng = np.random.default_rng(1)
    n = 800
    t = np.arange(n) * 0.25
    A = 0.1 + 0.05 * rng.random((n, 3))
    U = 8.0 + rng.random((n, 3))
    dA = 1e-3 * rng.standard_normal((n, 3))
    a = PooledSINDy(n_bootstrap=5, seed=4).fit([(t, A, U, dA)])
    b = PooledSINDy(n_bootstrap=5, seed=4).fit([(t, A, U, dA)])
    assert np.array_equal(a.coef_bootstrap_, b.coef_bootstrap_, equal_nan=True)
    with pytest.raises(ValueError, match="agreement"):
        PooledSINDy(agreement=1.5).fit([(t, A, U, dA)])
    with pytest.raises(ValueError, match="block_s"):
        PooledSINDy(block_s=0.0).fit([(t, A, U, dA)])


def test_cli_pool_and_validation_of_the_campaign_model(small_results_in_library, tmp_path):
    """`vivbench pool` writes the campaign model; `vivbench validate` scores it beside the windows, as campaign_model_recovery does."""
    import shutil

    from vivbench.cli import main
    from vivbench.io.campaign_model import REGIMES_NAME
    from vivbench.validate import campaign_model_recovery, validate_campaign

    # campaign_model_recovery scores dA/dt against the exact coefficient matrix: the in_library mode
    camp, res_dir, results = small_results_in_library
    res = tmp_path / "res"
    shutil.copytree(res_dir, res)
    assert main(["pool", str(res), "--model", "pooled", "--bootstrap", "10", "--block", "20"]) == 0
    assert (res / REGIMES_NAME).is_file() and not list(res.glob("*.tmp*"))
    v = validate_campaign(camp.files[0].parent, res)
    direct = campaign_model_recovery(camp.files[:2], res / REGIMES_NAME, sorted(res.glob("*.identify.nc")))
    assert v["campaign_model"]["regime"]["n"] == direct["n"]
    assert_close(v["summary"]["campaign_model_regime_accuracy_all"], direct["accuracy_all"])
    assert_close(v["summary"]["campaign_model_regime_coverage"], direct["coverage"])
    assert_close(v["summary"]["campaign_model_median_rhs_rel_error_active"], direct["rhs_median_rel_error_active"])
    # the energy-weighted error on the true (A, U), beside the median, by the same function
    assert_close(v["summary"]["campaign_model_energy_rhs_error_true_AU"], direct["rhs_error_true_AU_energy"])
    # (a 69-term model of two short events: its largest errors at a few truth samples dominate this figure)
    assert 0 < v["summary"]["campaign_model_energy_rhs_error_true_AU"] < math.inf
    assert 0 < v["summary"]["energy_rhs_error_true_AU"] < math.inf
    assert {r["group"] for r in v["regime_confusion"]} >= {"campaign_model_identifiable", "campaign_model_all"}
    # the curves are marked where they extrapolate beyond each section's fitted winds
    from vivbench.io.campaign_model import read_campaign_regimes
    from vivbench.models import data_wind_range
    from vivbench.analysis import records_from_results

    pooled = read_campaign_regimes(res / REGIMES_NAME)
    ext = pooled["curves_extrapolated"].values.astype(bool)
    assert ext.shape == (pooled.sizes["equation"], pooled.sizes["wind"])
    rng = data_wind_range(records_from_results(sorted(res.glob("*.identify.nc")), derivative=None))
    wind = pooled["wind"].values
    np.testing.assert_array_equal(ext, (wind[None] < rng[:, :1]) | (wind[None] > rng[:, 1:]))
    assert ext[:, 0].all() and not ext.all()  # the grid's first point lies below the data, the middle inside
    assert math.isfinite(v["summary"]["campaign_model_curve_error_energy"]) or not v["campaign_model"]["curves"]["scored"]


def test_pool_saves_the_campaign_model_that_forecast_validate_and_the_fallback_use(small_results, tmp_path):
    """campaign.model.nc loads and predicts the pooled coef; forecast and validate use it, or the pooled coef without it."""
    import json
    import shutil

    from vivbench.analysis import campaign_model_file, load_campaign_model, with_campaign_model
    from vivbench.cli import main
    from vivbench.core.errors import InputError
    from vivbench.io.campaign_model import MODEL_NAME, REGIMES_NAME, read_campaign_regimes, regimes_file
    from vivbench.io.result import read_result, result_record
    from vivbench.models.simulate import forecast, simulate_identified
    from vivbench.validate import upgrade_metrics, validate_campaign, write_validation

    camp, res_dir, _results = small_results
    res = tmp_path / "res"
    shutil.copytree(res_dir, res)
    before = {f.name for f in res.iterdir()}
    assert main(["pool", str(res), "--model", "pooled", "--bootstrap", "4", "--block", "20"]) == 0
    assert {f.name for f in res.iterdir()} - before == {REGIMES_NAME, MODEL_NAME}
    pooled = read_campaign_regimes(res / REGIMES_NAME)
    model = PooledSINDy.load(res / MODEL_NAME)
    assert campaign_model_file(res) == res / MODEL_NAME
    assert np.array_equal(model.coef_, pooled["coef"].values)
    result = read_result(sorted(res.glob("*.identify.nc"))[0])
    record = result_record(result)
    assert record.event_id == result.attrs["event_id"] and np.array_equal(record.dA, result["dA"].values, equal_nan=True)
    expected = evaluate_library(record.A, record.U) @ pooled["coef"].values.T
    assert np.array_equal(model.predict(record), expected, equal_nan=True)
    # The protocol's simulation is the old route through result files (coef copied into every window).
    start, end = result["window_start"].values, result["window_end"].values
    cm = with_campaign_model(result, pooled)
    t0 = float(start[start.size // 2])
    assert np.array_equal(model.simulate(record, float(start.min()), float(end.max())).A_sim,
                          simulate_identified(cm).A_sim, equal_nan=True)
    assert np.array_equal(model.simulate(record, t0, t0 + 200.0).A_sim, forecast(cm, t0, 200.0).A_sim, equal_nan=True)

    def run_forecast(out):
        assert main(["forecast", str(sorted(res.glob("*.identify.nc"))[0]),
                     "--out", str(out), "--t0", str(t0), "--horizon", "200", "--d", "0"]) == 0
        return json.loads((out / "summary.json").read_text())

    with_model = run_forecast(tmp_path / "fc_model")
    from vivbench.report.figures import model_forecast_figure

    png = model_forecast_figure(model, record, tmp_path / "fc.png", t0=t0, horizon=200.0, name="campaign model")
    assert png.stat().st_size > 0
    with pytest.raises(InputError, match="lacks dA"):
        result_record(result.drop_vars("dA"))
    v_model = validate_campaign(camp.files[0].parent, res)
    assert v_model["campaign_model"]["model_file"] == str(res / MODEL_NAME)

    # Older outputs (no campaign.model.nc): the model is rebuilt from the regimes file's coef.
    (res / MODEL_NAME).unlink()
    fallback = load_campaign_model(res)
    assert np.array_equal(fallback.predict(record), expected, equal_nan=True)
    assert fallback.equations() == model.equations()
    with pytest.raises(InputError, match=f"{REGIMES_NAME}.*re-run vivbench pool"):
        fallback.curves([8.0, 10.0])
    assert model.curves([8.0, 10.0])["curves"].shape == (3, 4, 2)
    without = run_forecast(tmp_path / "fc_pooled")
    keys = [k for k in with_model if k.startswith("campaign_model_")]
    assert len(keys) == 3 and all(with_model[k] == without[k] for k in keys)
    v_pooled = validate_campaign(camp.files[0].parent, res)
    assert v_pooled["campaign_model"]["model_file"] == str(res / REGIMES_NAME)
    assert json.dumps(v_pooled["summary"], sort_keys=True) == json.dumps(v_model["summary"], sort_keys=True)
    # A directory written by an earlier version (campaign.pooled.nc, format "vivbench-pooled", the settings in
    # pooled_config_json) still loads and scores the same.
    legacy = _as_written_by_earlier_versions(res)
    assert regimes_file(res) == legacy and campaign_model_file(res) == legacy
    assert read_campaign_regimes(legacy).attrs["model_config_json"] == pooled.attrs["model_config_json"]
    assert load_campaign_model(res).equations() == model.equations()
    v_legacy = validate_campaign(camp.files[0].parent, res)
    assert v_legacy["campaign_model"]["model_file"] == str(legacy)
    assert json.dumps(v_legacy["summary"], sort_keys=True) == json.dumps(v_model["summary"], sort_keys=True)
    # ... and so does a metrics.json of vivbench validate written with the earlier names (pooled, pooled_*).
    write_validation(v_model, tmp_path / "val")
    current = json.loads((tmp_path / "val" / "metrics.json").read_text())
    old = json.loads(json.dumps(current).replace('"campaign_model_', '"pooled_').replace('"campaign_model"', '"pooled"'))
    assert "pooled" in old and "pooled_regime_coverage" in old["summary"]
    assert upgrade_metrics(old) == current
    # Neither file: load_campaign_model refuses in one line naming the directory.
    legacy.unlink()
    with pytest.raises(InputError, match="no campaign model"):
        load_campaign_model(res)
    with pytest.raises(InputError, match="not a campaign model"):
        load_campaign_model(sorted(res.glob("*.identify.nc"))[0])


def _as_written_by_earlier_versions(res):
    """Turn res's campaign.regimes.nc into the campaign.pooled.nc an earlier version wrote; its path."""
    import xarray as xr

    from vivbench.io.campaign_model import LEGACY_REGIMES_FORMAT, LEGACY_REGIMES_NAME, REGIMES_NAME

    with xr.open_dataset(res / REGIMES_NAME) as ds:
        old = ds.load()
    old.attrs.update(format=LEGACY_REGIMES_FORMAT, pooled_config_json=old.attrs.pop("model_config_json"))
    old.to_netcdf(res / LEGACY_REGIMES_NAME)
    (res / REGIMES_NAME).unlink()
    return res / LEGACY_REGIMES_NAME


def test_rerunning_pool_on_an_old_directory_leaves_one_regimes_file(small_results, tmp_path):
    import shutil

    from vivbench.cli import main
    from vivbench.io.campaign_model import LEGACY_REGIMES_NAME, REGIMES_NAME

    res = tmp_path / "res"
    shutil.copytree(small_results[1], res)
    assert main(["pool", str(res), "--model", "pooled", "--bootstrap", "4", "--block", "20"]) == 0
    _as_written_by_earlier_versions(res)
    assert main(["pool", str(res), "--model", "pooled", "--bootstrap", "4", "--block", "20"]) == 0
    assert (res / REGIMES_NAME).is_file() and not (res / LEGACY_REGIMES_NAME).exists()


def test_cli_pool_bad_input(tmp_path, capsys):
    from vivbench.cli import main

    assert main(["pool", str(tmp_path / "none")]) == 2
    (tmp_path / "empty").mkdir()
    assert main(["pool", str(tmp_path / "empty")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all(line.startswith("vivbench pool:") for line in err)


def test_too_little_data_gives_no_verdict():
    rng = np.random.default_rng(2)
    n = 2000
    t = np.arange(n) * 0.25
    A = 0.05 + 0.1 * (t / t[-1])[:, None] * np.array([0.7, 1.0, 0.7])
    U = 8.0 + np.sin(t / 80.0)[:, None] + np.array([0.0, 0.1, 0.2])
    dA = 0.01 * A - 0.2 * A**3 + 1e-6 * rng.standard_normal((n, 3))
    model = PooledSINDy(n_bootstrap=10, block_s=300.0, min_blocks=20).fit([(t, A, U, dA)])
    assert not model.enough_data_ and model.n_blocks_ == 2
    out = campaign_window_verdicts(model, t, A, U, np.array([0.0, 100.0]), np.array([50.0, 150.0]))
    assert not out["identifiable"].any()


def test_campaign_model_differentiates_the_results_amplitudes_itself(small_results):
    """The campaign model takes dA/dt from the results' A with its own (unbiased) derivative,
    on exactly the samples where the identification had one; derivative=None keeps the stored dA."""
    import json

    import xarray as xr

    from vivbench.analysis.pool import pool_results
    from vivbench.analysis.pool import CAMPAIGN_DERIVATIVE, _campaign_derivative
    from vivbench.io.netcdf import NETCDF_ENGINE

    _camp, _out, results = small_results
    with xr.open_dataset(results[0], engine=NETCDF_ENGINE) as ds:
        ds = ds.load()
    stored = ds["dA"].values
    ours = _campaign_derivative(ds, CAMPAIGN_DERIVATIVE)
    np.testing.assert_array_equal(np.isfinite(ours), np.isfinite(stored))
    keep = (ds["segment"].values == 0) & np.isfinite(stored).all(axis=1)
    expected = CAMPAIGN_DERIVATIVE.differentiate(ds["A"].values[keep], ds["time"].values[keep])
    np.testing.assert_array_equal(ours[keep], expected)
    # the chain's own derivative is the smoothed envelope setting, so the two differ
    assert_not_close(ours[keep], stored[keep])
    np.testing.assert_array_equal(_campaign_derivative(ds, None), stored)
    pooled = pool_results(results, PooledSINDy(n_bootstrap=0))
    assert json.loads(pooled.attrs["derivative_json"])["method"] == "tv"
    assert json.loads(pool_results(results, PooledSINDy(n_bootstrap=0), derivative=None).attrs["derivative_json"]) is None


def test_wind_smoothing_is_applied_at_fit_and_to_measured_records_and_kept_in_the_file(tmp_path):
    """``wind_smoothing_s`` smooths the measured wind before the fit, as smoothing the records first does; the
    model then evaluates measured records on the wind so smoothed and its file keeps the smoothing."""
    from vivbench.core.record import Record
    from vivbench.models.model_input import measured_input
    from vivbench.preprocess.wind_smoothing import smooth_wind

    rng = np.random.default_rng(2)
    n = 1200
    t = np.arange(n) * 0.5
    A = 0.1 + 0.05 * np.abs(np.sin(t / 90.0))[:, None] + 0.01 * rng.random((n, 2))
    U = 8.0 + 2.0 * np.sin(t / 200.0)[:, None] + 0.8 * rng.standard_normal((n, 2))
    dA = 1e-3 * (U - 8.0) * A + 1e-4 * rng.standard_normal((n, 2))
    rec = Record(event_id="E0", t=t, A=A, U=U, dA=dA)
    own = PooledSINDy(n_bootstrap=0, wind_smoothing_s=20.0).fit([rec])
    given = PooledSINDy(n_bootstrap=0).fit([smooth_wind(rec, 20.0)])
    assert np.array_equal(own.coef_, given.coef_)
    assert_not_close(own.coef_, PooledSINDy(n_bootstrap=0).fit([rec]).coef_, rtol=1e-3,
                     reason="the 0.8 m/s white wind noise moves the fit unless smoothed")
    assert np.array_equal(measured_input(own, rec).U, smooth_wind(rec, 20.0).U)
    assert getattr(given, "measured_wind", None) is None  # None: the caller's smoothing (measured_input's argument)
    assert np.array_equal(measured_input(given, rec, wind_smoothing_s=5.0).U, smooth_wind(rec, 5.0).U)
    back = PooledSINDy.load(own.save(tmp_path / "m.nc"))
    assert back.wind_smoothing_s == 20.0 and np.array_equal(measured_input(back, rec).U, measured_input(own, rec).U)
    with pytest.raises(ValueError, match="wind_smoothing_s must be None"):
        PooledSINDy(wind_smoothing_s=-1.0).fit([rec])
