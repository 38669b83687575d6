"""`vivbench pool --model varying` and the campaign model's per-event residual checks."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from tests.helpers import assert_close
from vivbench.analysis.changes import change_point_scan, event_residual_checks
from vivbench.core.record import Record


def test_pool_varying_writes_the_pooled_layout_and_the_model_file(small_results, tmp_path):
    """The varying model's pooled file and model file; validate and forecast use it through the protocol."""
    from vivbench.analysis import campaign_model_file, load_campaign_model
    from vivbench.cli import main
    from vivbench.core.errors import InputError
    from vivbench.io.campaign_model import MODEL_NAME, REGIMES_NAME, regimes_model_name, read_campaign_regimes
    from vivbench.io.result import read_result, result_record
    from vivbench.models.varying import VaryingCoefficientSINDy
    from vivbench.regimes import model_window_regimes
    from vivbench.validate import validate_campaign

    camp, res_dir, _ = small_results
    res = tmp_path / "res"
    shutil.copytree(res_dir, res)
    assert main(["pool", str(res), "--model", "varying", "--bootstrap", "8", "--block", "20"]) == 0
    assert not list(res.glob("*.tmp*"))
    pooled = read_campaign_regimes(res / REGIMES_NAME)
    assert regimes_model_name(pooled) == "VaryingCoefficientSINDy" and "coef" not in pooled
    assert {"n_basis", "penalty", "edf", "curves", "event_linear_offset", "event_residual_ratio", "event_offset_flag",
            "event_after_change", "event_change_flag", "event_change_p"} <= set(pooled.data_vars)
    assert "offset_flagged_events" in pooled.attrs and "change_flagged_events" in pooled.attrs
    assert pooled.sizes["event"] == 2 and pooled["curves"].dims == ("equation", "order", "wind")
    model = load_campaign_model(res)
    assert isinstance(model, VaryingCoefficientSINDy) and campaign_model_file(res) == res / MODEL_NAME
    result = read_result(sorted(res.glob("*.identify.nc"))[0])
    start, end = result["window_start"].values, result["window_end"].values
    sel = pooled["event_id"].values.astype(str) == result.attrs["event_id"]
    # The pooled regimes are the model's on the measured wind as it was fitted on it (smoothed).
    regimes = model_window_regimes(model, model.measured_wind(result_record(result)), start, end, tau=model.tau)["regime"]
    assert np.array_equal(regimes, pooled["regime"].values[sel])
    v = validate_campaign(camp.files[0].parent, res)
    assert v["campaign_model"]["model_file"] == str(res / MODEL_NAME)
    # Two events without recorded slow changes: every flag scored, none may be a hit.
    ch = v["campaign_model"]["changes"]
    assert ch["changed_events"] == [] and all(sc["hits"] == 0 for sc in ch["flags"].values())
    t0 = float(start[start.size // 2])
    assert main(["forecast", str(sorted(res.glob("*.identify.nc"))[0]), "--out", str(tmp_path / "fc"),
                 "--t0", str(t0), "--horizon", "100", "--d", "0"]) == 0
    summary = json.loads((tmp_path / "fc" / "summary.json").read_text())
    assert any(k.startswith("campaign_model_simulation_nmse") for k in summary)
    # The pooled file alone holds no varying model; a model file of another kind is refused.
    with pytest.raises(InputError, match="holds no model"):
        load_campaign_model(res / REGIMES_NAME)
    other = tmp_path / "other"
    shutil.copytree(res_dir, other)
    assert main(["pool", str(other), "--model", "pooled", "--bootstrap", "4", "--block", "20"]) == 0
    shutil.copy(other / MODEL_NAME, res / MODEL_NAME)
    with pytest.raises(InputError, match="re-run vivbench pool"):
        load_campaign_model(res)
    sindy = read_campaign_regimes(other / REGIMES_NAME)
    assert "model" not in sindy.attrs and regimes_model_name(sindy) == "PooledSINDy" and "coef" in sindy


class _Offset:
    """A model predicting dA/dt - delta_e A for the event with index e in its id."""

    def __init__(self, deltas):
        self.deltas = deltas

    def predict(self, rec):
        return rec.dA - self.deltas[int(rec.event_id)] * rec.A


def test_event_residual_checks_recover_the_offsets():
    rng = np.random.default_rng(0)
    deltas = np.array([0.0, 1e-3, -2e-3])
    recs = []
    for e in range(3):
        t = np.arange(2400) * 0.25
        A = 0.05 + 0.02 * rng.random((t.size, 3))
        recs.append(Record(event_id=str(e), t=t, A=A, U=np.full_like(A, 8.0), dA=1e-3 * rng.standard_normal(A.shape)))
    out = event_residual_checks(_Offset(deltas), recs, block_s=60.0)
    assert_close(out["linear_offset"], deltas, atol=1e-15, reason="sums of squares in floating point")
    assert np.all(out["linear_offset_se"] < 1e-12) and np.nanmedian(out["residual_ratio"]) == 1.0


def test_change_point_scan_finds_a_step_and_not_noise():
    rng = np.random.default_rng(1)
    E = 20
    se = np.full(E, 1e-4)
    w = 1.0 + rng.random(E)
    noise = 1e-4 * rng.standard_normal(E)
    step = noise + np.where(np.arange(E) >= 10, -1e-3, 0.0)
    found = change_point_scan(step, se, w)
    assert found["detected"] and found["change_index"] == 10 and found["heterogeneity_p"] < 1e-6
    none = change_point_scan(noise, se, w)
    assert not none["detected"] and none["p_value"] > 0.05
    nan = change_point_scan(np.array([np.nan, 1.0]), np.ones(2), np.ones(2))
    assert nan["change_index"] == -1 and np.isnan(nan["p_value"])


@pytest.mark.parametrize("argv, message", [
    (["pool", "{tmp}", "--model", "sindy"], "argument --model: 'sindy' is now named 'pooled'"),
    (["forecast", "{tmp}/E001.identify.nc", "--out", "{tmp}/o", "--pooled", "{tmp}/campaign.pooled.nc"],
     "--pooled is now named --campaign-model"),
])
def test_a_former_name_is_refused_with_the_current_one(argv, message, tmp_path, capsys):
    from vivbench.cli import main

    with pytest.raises(SystemExit) as info:
        main([a.format(tmp=tmp_path) for a in argv])
    assert info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].endswith(message), err


def test_pool_writes_the_selections_own_change_scan_instead_of_a_second(small_results, monkeypatch):
    from vivbench.analysis import CAMPAIGN_DERIVATIVE, changes, pool_results, records_from_results, varying_selection
    from vivbench.models import model_change_inputs

    scan = changes.statistics_change_scan
    calls = []
    monkeypatch.setattr(changes, "statistics_change_scan", lambda *a, **k: calls.append(1) or scan(*a, **k))
    _camp, _dir, files = small_results
    sel = varying_selection(options={"yaw_degree": (0,)}, n_perturbations=0, n_basis=(8,), n_bootstrap=4,
                            block_s=20.0)
    ds = pool_results(files, sel)
    assert len(calls) == 1  # the selection's own scan of its chosen model, written by the pool
    recorded = sel.recorded_change_scan()
    assert recorded["events"] == [str(e) for e in ds["event"].values] and recorded["seed"] == sel.seed
    records = records_from_results(files, derivative=CAMPAIGN_DERIVATIVE)
    fresh = scan(model_change_inputs(sel.model_, [sel.model_.measured_wind(r) for r in records])["statistics"],
                 seed=sel.seed)
    for key in ("misfit", "split_gain"):
        assert np.array_equal(recorded["scan"][key], fresh[key], equal_nan=True)
    assert np.array_equal(ds["event_misfit"].values, fresh["misfit"], equal_nan=True)
    assert np.array_equal(ds["event_model_split_gain"].values, fresh["split_gain"], equal_nan=True)


def test_pool_with_the_pooled_class_alone_writes_a_pooled_model_that_sees_the_smoothed_wind(small_results, tmp_path,
                                                                                          capsys):
    """``--model-classes pooled``: the selection's choice is a PooledSINDy, written, loaded and evaluated on the
    measured wind smoothed as at fit (30 s, the selection's prior)."""
    from vivbench.analysis import load_campaign_model
    from vivbench.cli import main
    from vivbench.io.campaign_model import REGIMES_NAME, read_campaign_regimes
    from vivbench.io.result import read_result, result_record
    from vivbench.models.campaign import PooledSINDy
    from vivbench.preprocess.wind_smoothing import smooth_wind
    from vivbench.regimes import model_window_regimes

    _, res_dir, _ = small_results
    res = tmp_path / "res"
    shutil.copytree(res_dir, res)
    assert main(["pool", str(res), "--model-classes", "pooled", "--bootstrap", "4", "--block", "20"]) == 0
    out = capsys.readouterr().out
    assert "chose pooled from the campaign's own evidence" in out and "PooledSINDy, terms per equation" in out
    model = load_campaign_model(res)
    assert type(model) is PooledSINDy and model.wind_smoothing_s == 30.0
    pooled = read_campaign_regimes(res / REGIMES_NAME)
    assert json.loads(pooled.attrs["selection_json"])["chosen"] == "pooled"
    result = read_result(sorted(res.glob("*.identify.nc"))[0])
    start, end = result["window_start"].values, result["window_end"].values
    rec = smooth_wind(result_record(result), 30.0)
    sel = pooled["event_id"].values.astype(str) == result.attrs["event_id"]
    assert np.array_equal(model_window_regimes(model, rec, start, end, tau=model.tau)["regime"],
                          pooled["regime"].values[sel])
    with pytest.raises(SystemExit):
        main(["pool", str(res), "--model-classes", "pooled,greybox"])
    assert "--model-classes: must be distinct names among varying,pooled" in capsys.readouterr().err
