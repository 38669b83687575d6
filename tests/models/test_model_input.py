"""Campaign models are evaluated on measured records through ``vivbench.models.measured_input``.

The varying model is fitted on the measured wind smoothed (its
``wind_smoothing_s``): validate, forecast and the report must evaluate it on
the measured records' wind smoothed alike, and on the truth's felt wind as it
is. Each test compares a command's number with the direct evaluation, and
checks that the raw (or, for the truth, smoothed) evaluation differs, so that
a site that forgets the routing (or smooths the truth) fails.
"""

from __future__ import annotations

import dataclasses
import json
import shutil

import numpy as np
import pytest

from tests.helpers import assert_close

# A smoothing far above the default 30 s, so that the smoothed and raw winds give clearly different regimes.
SMOOTHING_S = 120.0


@pytest.fixture(scope="module")
def varying_pooled(small_results, tmp_path_factory):
    """``small_results`` pooled by ``vivbench pool --model varying`` with a strong wind smoothing."""
    from vivbench.analysis import load_campaign_model
    from vivbench.cli import main

    camp, res_dir, _ = small_results
    res = tmp_path_factory.mktemp("varying_input") / "res"
    shutil.copytree(res_dir, res)
    assert main(["pool", str(res), "--model", "varying", "--bootstrap", "8", "--block", "20",
                 "--wind-smoothing", str(SMOOTHING_S)]) == 0
    return camp.files[0].parent, res, load_campaign_model(res)


def _events(camp_dir, res):
    from vivbench.io.event import read_event
    from vivbench.io.result import read_result, result_record

    for path in sorted(res.glob("*.identify.nc")):
        result = read_result(path)
        truth = read_event(camp_dir / f"{result.attrs['event_id']}.nc")["truth"].ds
        yield result, result_record(result), truth


def test_measured_input_routes_by_model():
    from vivbench.core.errors import InputError
    from vivbench.core.record import Record
    from vivbench.models import measured_input
    from vivbench.preprocess import smooth_wind

    rng = np.random.default_rng(0)
    t = np.arange(600) * 0.5
    rec = Record(event_id="E", t=t, A=np.abs(rng.normal(size=(600, 2))), U=8 + rng.normal(size=(600, 2)),
                 dA=rng.normal(size=(600, 2)), yaw=rng.normal(size=(600, 2)))

    class Plain:  # a model that knows nothing of its input (PooledSINDy, plug-ins)
        pass

    class Own:  # a model that transforms measured records itself (VaryingCoefficientSINDy)
        def measured_wind(self, record):
            return dataclasses.replace(record, U=record.U + 1.0)

    assert measured_input(Plain(), rec) is rec
    smoothed = measured_input(Plain(), rec, wind_smoothing_s=20.0)
    assert_close(smoothed.U, smooth_wind(rec, 20.0).U, what="U smoothed as pool smoothed it")
    assert_close(smoothed.yaw, smooth_wind(rec, 20.0).yaw, what="yaw smoothed alike")
    assert np.array_equal(smoothed.A, rec.A) and np.array_equal(smoothed.dA, rec.dA)
    # The model's own transformation wins over the pooled file's smoothing.
    assert_close(measured_input(Own(), rec, wind_smoothing_s=20.0).U, rec.U + 1.0, what="model's own input")
    with pytest.raises(InputError, match="wind_smoothing_s"):
        measured_input(Plain(), rec, wind_smoothing_s=-1.0)


def test_validate_scores_the_varying_model_on_its_measured_input(varying_pooled):
    """validate's campaign-model regimes and dA/dt error are the direct ones on the right winds."""
    from vivbench.regimes import model_window_regimes, truth_window_regimes
    from vivbench.validate import validate_campaign
    from vivbench.validate.metrics import regime_report, rhs_error_summary
    from vivbench.validate.campaign_model import campaign_model_recovery
    from vivbench.validate.recovery import model_window_rhs_errors_true_AU, record_yaw_on
    from vivbench.preprocess import smooth_wind

    camp_dir, res, model = varying_pooled
    v = validate_campaign(camp_dir, res)
    reg = {"smoothed": [], "raw": []}
    tru, err, act, err_smoothed_truth = [], [], [], []
    for result, rec, truth in _events(camp_dir, res):
        start, end = result["window_start"].values, result["window_end"].values
        reg["smoothed"].append(model_window_regimes(model, model.measured_wind(rec), start, end, tau=model.tau)["regime"])
        reg["raw"].append(model_window_regimes(model, rec, start, end, tau=model.tau)["regime"])
        tru.append(truth_window_regimes(truth, start, end))
        yaw = record_yaw_on(rec, truth["time"].values)
        e, a = model_window_rhs_errors_true_AU(model, truth, start, end, event_id=rec.event_id, yaw=yaw)
        err.append(e.ravel())
        act.append(a.ravel())
        # The mistake to catch: the truth's felt wind smoothed like a measured one.
        tsm = truth.copy()
        tsm["U"] = (truth["U"].dims, smooth_wind(dataclasses.replace(rec, t=truth["time"].values, A=truth["A"].values,
                                                                     U=truth["U"].values, dA=None, yaw=None),
                                                 SMOOTHING_S).U)
        err_smoothed_truth.append(model_window_rhs_errors_true_AU(model, tsm, start, end, event_id=rec.event_id,
                                                                  yaw=yaw)[0].ravel())
    truth_all = np.concatenate(tru)
    flags = np.zeros(truth_all.shape, dtype=bool)
    direct = {k: regime_report(np.concatenate(r), truth_all, flags)["groups"]["all"] for k, r in reg.items()}
    # Precondition: the raw wind gives other regimes, so a site that skips measured_input is caught.
    assert direct["raw"]["confusion"] != direct["smoothed"]["confusion"]
    assert v["campaign_model"]["regime"]["groups"]["all"]["confusion"] == direct["smoothed"]["confusion"]
    summary = rhs_error_summary(np.concatenate(err), np.concatenate(act))
    assert_close(v["campaign_model"]["rhs_true_AU"]["active"]["median"], summary["active"]["median"],
                 what="validate's dA/dt error on the true (A, U): the truth's felt wind unsmoothed")
    wrong = rhs_error_summary(np.concatenate(err_smoothed_truth), np.concatenate(act))["active"]["median"]
    assert abs(wrong - summary["active"]["median"]) > 1e-6
    # The sweep's scorer (campaign_model_recovery) agrees with validate.
    ps = campaign_model_recovery(sorted(camp_dir.glob("E*.nc"))[:2], res / "campaign.regimes.nc", sorted(res.glob("*.identify.nc")))
    assert_close(ps["accuracy_all"], v["campaign_model"]["regime"]["groups"]["all"]["accuracy"], what="campaign_model_recovery")
    assert_close(ps["rhs_error_true_AU_median_active"], summary["active"]["median"], what="campaign_model_recovery dA/dt")


def test_forecast_simulates_the_varying_model_on_its_measured_input(varying_pooled, tmp_path):
    from vivbench.cli import main
    from vivbench.core.terms import reference_section

    camp_dir, res, model = varying_pooled
    result, rec, _truth = next(_events(camp_dir, res))
    start, end = result["window_start"].values, result["window_end"].values
    t0 = float(start[start.size // 2])
    path = res / f"{rec.event_id}.identify.nc"
    assert main(["forecast", str(path), "--out", str(tmp_path / "fc"), "--t0", str(t0), "--horizon", "100",
                 "--d", "0"]) == 0
    summary = json.loads((tmp_path / "fc" / "summary.json").read_text())
    ref = reference_section(rec.n_sections)
    got = summary[f"campaign_model_simulation_nmse_S{ref + 1}"]
    span = (float(start.min()), float(end.max()))
    want = model.simulate(model.measured_wind(rec), *span).nmse[ref]
    raw = model.simulate(rec, *span).nmse[ref]
    assert abs(raw - want) > 1e-9 * max(abs(want), 1e-12)  # precondition: the input matters
    assert_close(got, want, what="forecast's whole-event NMSE of the campaign model")


def test_validate_applies_pools_smoothing_to_a_pooled_sindy(small_results, tmp_path):
    """``pool --model sindy --wind-smoothing S``: validate's regimes are the pooled file's own (same input)."""
    from vivbench.analysis import load_campaign_model
    from vivbench.cli import main
    from vivbench.io.campaign_model import read_campaign_regimes
    from vivbench.preprocess import smooth_wind
    from vivbench.regimes import model_window_regimes, truth_window_regimes
    from vivbench.validate import validate_campaign
    from vivbench.validate.metrics import regime_report

    camp, res_dir, _ = small_results
    res = tmp_path / "res"
    shutil.copytree(res_dir, res)
    assert main(["pool", str(res), "--model", "pooled", "--bootstrap", "4", "--block", "20",
                 "--wind-smoothing", str(SMOOTHING_S)]) == 0
    pooled = read_campaign_regimes(res / "campaign.regimes.nc")
    assert float(pooled.attrs["wind_smoothing_s"]) == SMOOTHING_S
    model = load_campaign_model(res)
    v = validate_campaign(camp.files[0].parent, res)
    tru, smoothed, raw = [], [], []
    for result, rec, truth in _events(camp.files[0].parent, res):
        start, end = result["window_start"].values, result["window_end"].values
        tru.append(truth_window_regimes(truth, start, end))
        smoothed.append(model_window_regimes(model, smooth_wind(rec, SMOOTHING_S), start, end, tau=model.tau)["regime"])
        raw.append(model_window_regimes(model, rec, start, end, tau=model.tau)["regime"])
    # pool's own verdicts see the wind it fitted on, and the raw wind would give other regimes.
    assert np.array_equal(np.concatenate(smoothed), pooled["regime"].values)
    assert not np.array_equal(np.concatenate(raw), pooled["regime"].values)
    truth_all = np.concatenate(tru)
    own = regime_report(pooled["regime"].values.astype(int), truth_all, np.zeros(truth_all.shape, bool))
    assert v["campaign_model"]["regime"]["groups"]["all"]["confusion"] == own["groups"]["all"]["confusion"]
