"""Recovery metrics on hand-made cases, and ``vivbench validate`` end to end."""

from __future__ import annotations

import csv
import json
import math
import shutil
import subprocess
import sys

import numpy as np
import pytest
import xarray as xr

from tests.helpers import assert_close, run_cli
from vivbench.models.simulate import forecast_table
from vivbench.io.netcdf import NETCDF_ENGINE, write_netcdf_atomic
from vivbench.io.event import read_event, write_event
from vivbench.synth import GeneratorConfig, exact_coefficients
from vivbench.core.terms import feature_exponents
from vivbench.validate import campaign_recovery, cluster_agreement, cluster_purity, confusion_matrix, forecast_summary, merge_support_scores, order_support, pooled_support, regime_report, rhs_error_summary, rhs_relative_error, support_mask, support_scores, validate_campaign
from vivbench.regimes.truth import truth_window_regimes

EX = feature_exponents(3)


def _col(s, i, j):
    return int(np.flatnonzero((EX[:, 0] == s) & (EX[:, 1] == i) & (EX[:, 2] == j))[0])


@pytest.fixture(scope="module")
def xi_true():
    # a true coefficient matrix exists only with the truth in the library: the in_library mode
    return exact_coefficients(GeneratorConfig.in_library().structure, GeneratorConfig.in_library().aero)


# ----------------------------------------------------------------------- regimes


def test_confusion_matrix_counts_hand_made_case():
    truth = np.array([1, 2, 3, 4, 1, 0, 2, 2])
    ident = np.array([1, 3, 3, 4, 2, 1, 2, 0])  # a 0 on either side is not scored
    cm = confusion_matrix(truth, ident)
    expected = np.zeros((4, 4), int)
    expected[0, 0] = expected[1, 2] = expected[2, 2] = expected[3, 3] = expected[0, 1] = expected[1, 1] = 1
    np.testing.assert_array_equal(cm, expected)
    mask = np.array([1, 1, 0, 0, 0, 1, 1, 1], bool)
    assert confusion_matrix(truth, ident, mask).sum() == 3


def test_regime_report_perfect_model_is_diagonal():
    truth = np.array([[1, 2, 3], [4, 4, 1]])
    rep = regime_report(truth, truth, np.ones_like(truth, bool))
    assert rep["n"] == 6 and rep["coverage"] == 1.0
    assert rep["groups"]["identifiable"]["accuracy"] == 1.0 and rep["groups"]["all"]["accuracy"] == 1.0
    cm = np.array(rep["groups"]["all"]["confusion"])
    assert (cm == np.diag(np.diag(cm))).all() and np.diag(cm).tolist() == [2, 1, 1, 2]
    assert rep["groups"]["not_identifiable"]["n"] == 0 and math.isnan(rep["groups"]["not_identifiable"]["accuracy"])


def test_regime_report_splits_identifiable_from_the_rest():
    truth = np.array([1, 2, 3, 4, 2, 1])
    ident = np.array([1, 2, 4, 4, 1, 0])
    ok = np.array([1, 1, 1, 0, 0, 0], bool)
    rep = regime_report(ident, truth, ok)
    assert rep["n"] == 5 and rep["n_no_model"] == 1
    assert_close(rep["coverage"], 3 / 5)
    assert_close(rep["groups"]["identifiable"]["accuracy"], 2 / 3)
    assert_close(rep["groups"]["not_identifiable"]["accuracy"], 1 / 2)
    assert_close(rep["groups"]["all"]["accuracy"], 3 / 5)
    assert np.array(rep["groups"]["identifiable"]["confusion"])[2, 3] == 1


# ----------------------------------------------------------------------- support


def test_support_perfect_model_scores_one_at_every_level(xi_true):
    models = np.broadcast_to(xi_true, (5, *xi_true.shape))
    s = support_scores(models, xi_true)
    assert s["n"] == 15
    for level in ("terms", "pooled_terms", "orders"):
        assert s[level]["precision"] == 1.0 and s[level]["recall"] == 1.0, level
    assert s["order_recall"] == [1.0] * 4
    assert any("phi_k Q" in n for n in s["notes"])


def test_support_one_extra_term(xi_true):
    k = int(support_mask(xi_true).sum())
    model = xi_true.copy()
    col = _col(0, 0, 1)  # U1: zero in the truth (forcing starts at U^3)
    assert xi_true[0, col] == 0
    model[0, col] = 1e-3
    s = support_scores(model, xi_true)
    assert_close(s["terms"]["precision"], k / (k + 1))
    assert s["terms"]["recall"] == 1.0 and s["terms"]["fp"] == 1
    kp = int(pooled_support(support_mask(xi_true)).sum())
    assert_close(s["pooled_terms"]["precision"], kp / (kp + 1))


def test_support_dense_model_scores_the_chance_level(xi_true):
    k = int(support_mask(xi_true).sum())
    s = support_scores(np.ones_like(xi_true), xi_true)
    assert s["terms"]["recall"] == 1.0 and s["mean_terms_per_model"] == 69
    assert_close(s["terms"]["precision"], k / xi_true.size)
    assert s["terms"]["precision"] == s["terms"]["precision_dense_model"]
    # the truth holds every order in every equation: order precision cannot fail, and the notes say so
    assert s["orders"]["precision"] == 1.0 and any("says nothing" in n for n in s["notes"])


def test_support_one_missing_term(xi_true):
    k = int(support_mask(xi_true).sum())
    model = xi_true.copy()
    col = _col(1, 3, 4)
    assert xi_true[0, col] != 0
    model[0, col] = 0.0
    s = support_scores(model, xi_true)
    assert_close(s["terms"]["recall"], (k - 1) / k)
    assert s["terms"]["precision"] == 1.0
    # other sections still carry A^3 U^4 in equation 0: nothing lost after pooling
    assert s["pooled_terms"]["recall"] == 1.0


def test_support_term_on_another_section_is_wrong_per_term_but_right_pooled(xi_true):
    # The columns A_k^i U_k^j of different sections are nearly proportional in the synthetic
    # bridge; the truth puts the structural damping of equation 0 on A1 only. Moved to A2:
    src, dst = _col(0, 1, 0), _col(1, 1, 0)
    assert xi_true[0, src] != 0 and xi_true[0, dst] == 0
    model = xi_true.copy()
    model[0, dst], model[0, src] = model[0, src], 0.0
    s = support_scores(model, xi_true)
    assert s["terms"]["fp"] == 1 and s["terms"]["fn"] == 1
    assert s["pooled_terms"]["precision"] == 1.0 and s["pooled_terms"]["recall"] == 1.0


def test_order_support_and_per_order_recall():
    truth = np.zeros((1, 69))
    truth[0, _col(0, 1, 0)] = -0.01
    truth[0, _col(2, 3, 2)] = -1.0
    np.testing.assert_array_equal(order_support(support_mask(truth))[0], [False, True, False, True])
    model = np.zeros((2, 1, 69))
    model[0, 0, _col(1, 1, 3)] = 1.0  # order 1 on another section and power of U: still order 1
    model[1, 0, _col(0, 2, 0)] = 1.0  # order 2 only
    s = support_scores(model, truth)
    assert s["order_recall"][1] == 0.5 and s["order_recall"][3] == 0.0
    assert math.isnan(s["order_recall"][0]) and s["order_precision"][2] == 0.0
    assert {k: s["orders"][k] for k in ("tp", "fp", "fn", "precision", "recall")} == {
        "tp": 1, "fp": 1, "fn": 3, "precision": 0.5, "recall": 0.25}
    assert s["orders"]["precision_dense_model"] == 0.5 and not any("says nothing" in n for n in s["notes"])


def test_support_skips_missing_models_and_merges_counts(xi_true):
    models = np.stack([xi_true, np.full_like(xi_true, np.nan)])
    s = support_scores(models, xi_true)
    assert s["n"] == 3
    s_masked = support_scores(models, xi_true, mask=np.array([[True, False, True], [True, True, True]]))
    assert s_masked["n"] == 2
    m = merge_support_scores([s, s_masked])
    assert m["n"] == 5 and m["terms"]["tp"] == s["terms"]["tp"] + s_masked["terms"]["tp"]


# ----------------------------------------------------------------------- dynamics


def test_rhs_error_perfect_and_one_extra_term():
    A = np.tile([[0.1, 0.14, 0.1], [0.3, 0.42, 0.3]], (10, 1))
    U = np.full_like(A, 8.0)
    a, c = -0.02, 1e-4
    truth = np.zeros((3, 69))
    for m in range(3):
        truth[m, _col(m, 1, 0)] = a
    assert_close(rhs_relative_error(truth, truth, A, U), np.zeros(3))
    model = truth.copy()
    model[0, _col(0, 0, 1)] = c  # + c U1 in equation 0
    # rms(c U1) / rms(a A1) with U1 = 8 and A1 alternating 0.1, 0.3 (rms sqrt(0.05))
    expected = c * 8.0 / (abs(a) * math.sqrt(0.05))
    assert_close(rhs_relative_error(model, truth, A, U), [expected, 0.0, 0.0], rtol=1e-12,
                 reason="float round-off of sums over 20 samples")


def test_rhs_error_summary_quantiles_and_active_split():
    e = np.array([[0.1, 0.2], [0.3, np.nan], [0.5, 10.0]])
    active = np.array([[True, True], [True, False], [False, False]])
    s = rhs_error_summary(e, active)
    assert s["all"]["n"] == 5 and s["n_nonfinite"] == 1 and s["all"]["median"] == 0.3
    assert s["active"]["n"] == 3 and s["active"]["median"] == 0.2
    assert s["inactive"]["median"] == 5.25
    assert_close(s["active"]["q10"], 0.12, reason="linear interpolation of quantiles")
    assert_close(s["active_share"], 0.5)


# ----------------------------------------------------------------------- clusters


def test_cluster_agreement_perfect_and_permuted():
    truth = np.array([1, 1, 2, 2, 3, 3, 4, 4])
    for labels in (truth, np.array([7, 7, 0, 0, 5, 5, 1, 1])):
        r = cluster_agreement(labels, truth)
        assert r["ari"] == 1.0 and r["purity"] == 1.0 and r["n_clusters"] == 4


def test_cluster_agreement_small_known_cases():
    truth = np.array([1, 1, 2, 2])
    labels = np.array([0, 0, 0, 1])
    # pairs: sum C(n_ij, 2) = 1, rows 2, columns 3, C(4, 2) = 6: expected index 1 = index -> ARI 0
    r = cluster_agreement(labels, truth)
    assert_close(r["ari"], 0.0, atol=1e-15, reason="exact zero up to round-off")
    assert r["purity"] == 0.75
    # the odd point as halo, ignored: perfect; kept: as above
    halo = np.array([0, 0, 1, 0], bool)
    assert cluster_agreement(labels, truth, halo)["ari"] == 1.0
    assert cluster_agreement(labels, truth, halo)["n_halo_ignored"] == 1
    assert_close(cluster_agreement(labels, truth, halo, ignore_halo=False)["ari"], 0.0, atol=1e-15,
                 reason="exact zero up to round-off")
    # one cluster for everything: purity is the majority share, ARI 0
    assert cluster_purity(np.zeros(5, int), np.array([1, 1, 1, 2, 3])) == 0.6
    # points without truth (0) are not scored
    assert cluster_agreement(np.array([0, 1, 2]), np.array([1, 2, 0]))["n"] == 2


# ----------------------------------------------------------------------- forecasts


def test_forecast_summary_counts_stopped_runs_apart():
    nmse = np.array([0.1, 0.3, 1e9, np.nan, 2.0, 0.5])
    stopped = np.array([0, 0, 1, 0, 0, 1], bool)
    d = np.array([0, 0, 0, 0, 50, 50.0])
    rows = forecast_summary(nmse, stopped, d)
    assert [r["d_s"] for r in rows] == [0.0, 50.0]
    r0, r50 = rows
    assert r0["n"] == 4 and r0["n_stopped"] == 1 and r0["n_nonfinite"] == 1 and r0["n_completed"] == 2
    assert_close(r0["median"], 0.2, rtol=1e-15, reason="mean of two floats")
    assert r0["share_below_1"] == 1.0
    assert r50["n_completed"] == 1 and r50["median"] == 2.0 and r50["stopped_share"] == 0.5


# ----------------------------------------------------------------------- campaign and CLI


@pytest.fixture(scope="module")
def identified(small_results_in_library):
    # validate's coefficient and support scores need a true coefficient matrix: the in_library mode
    return small_results_in_library


def _cli(*args):
    """``python -m vivbench.cli validate`` in a fresh interpreter (the entry point's exit code and stderr)."""
    return subprocess.run([sys.executable, "-m", "vivbench.cli", "validate", *map(str, args)], capture_output=True, text=True)


def test_validate_agrees_with_campaign_recovery(identified):
    camp, res_dir, results = identified
    v = validate_campaign(camp.files[0].parent, res_dir)
    old = campaign_recovery(camp.files[:2], results)
    assert v["regime"]["n"] == old["n"]
    assert_close(v["regime"]["coverage"], old["coverage"])
    assert_close(v["regime"]["groups"]["all"]["accuracy"], old["accuracy_all"])
    assert_close(v["rhs"]["active"]["median"], old["rhs_median_rel_error_active"])
    assert_close(v["rhs"]["all"]["median"], old["rhs_median_rel_error"])
    assert len(v["per_event"]) == len(results)


def test_validate_perfect_results_score_perfectly(identified, tmp_path):
    # replace every model by the truth: the chain's bookkeeping must then give a perfect score
    camp, _res_dir, results = identified
    labels = []
    for path in results:
        with xr.open_dataset(path, engine=NETCDF_ENGINE) as ds:
            ds = ds.load()
        truth = read_event(camp.files[0].parent / f"{ds.attrs['event_id']}.nc")["truth"].ds
        xi = truth["coef"].values
        ds["coef"].values[:] = xi
        ds["regime"].values[:] = truth_window_regimes(truth, ds["window_start"].values, ds["window_end"].values)
        ds["identifiable"].values[:] = 1
        write_netcdf_atomic(ds, tmp_path / "res" / path.name)
        labels.append((ds.attrs["event_id"], ds["regime"].values, ds["equation"].values))
    # cluster labels equal to the true regimes up to renaming: ARI and purity 1
    csv_path = tmp_path / "cluster_labels.csv"
    with csv_path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["event_id", "window", "equation", "window_start", "window_end", "feature_set", "label", "halo"])
        for event_id, reg, eqs in labels:
            for win in range(reg.shape[0]):
                for e, eq in enumerate(eqs):
                    w.writerow([event_id, win, eq, 0, 0, "coef", 10 + int(reg[win, e]), 0])
    v = validate_campaign(camp.files[0].parent, tmp_path / "res", clusters_csv=csv_path)
    s = v["summary"]
    assert s["regime_accuracy_all"] == 1.0 and s["regime_coverage"] == 1.0
    cm = np.array(v["regime"]["groups"]["all"]["confusion"])
    assert cm.sum() == np.trace(cm)
    assert s["support_precision_terms"] == 1.0 and s["support_recall_terms"] == 1.0
    assert s["support_recall_pooled_terms"] == 1.0 and s["support_recall_orders"] == 1.0
    assert s["median_rhs_rel_error"] == 0.0 and v["rhs"]["all"]["q90"] == 0.0
    assert s["ari_coef"] == 1.0 and s["purity_coef"] == 1.0


def test_cli_validate_writes_every_file(identified, tmp_path):
    camp, res_dir, results = identified
    # forecast tables as forecast_table writes them: stopped runs are counted, never averaged
    fc = tmp_path / "fc"
    fc.mkdir()
    with xr.open_dataset(results[0], engine=NETCDF_ENGINE) as res:
        res = res.load()
    rows = forecast_table(res, float(res["window_start"].values[0]), 60.0, ds=(0, 50))
    with (fc / f"forecast_{res.attrs['event_id']}.csv").open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    out = tmp_path / "val"
    run = _cli(camp.files[0].parent, res_dir, "--out", out, "--forecasts", fc)
    assert run.returncode == 0, run.stderr
    names = sorted(p.name for p in out.iterdir())
    assert names == ["forecast_nmse.csv", "metrics.json", "per_event.csv", "regime_confusion.csv", "summary.json",
                     "support.csv"]
    table = list(csv.DictReader((out / "forecast_nmse.csv").open()))
    assert [float(r["d_s"]) for r in table] == [0.0, 50.0]
    for r, d in zip(table, (0.0, 50.0)):
        sel = [x for x in rows if x["d"] == d]
        assert int(r["n"]) == len(sel) and int(r["n_stopped"]) == sum(x["stopped"] for x in sel)
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["notes"] and metrics["support"]["all"]["notes"]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["n_events"] == len(results)
    rows = list(csv.DictReader((out / "regime_confusion.csv").open()))
    assert [r["group"] for r in rows[::4]] == ["identifiable", "not_identifiable", "all"]
    assert sum(int(r["n"]) for r in rows if r["group"] == "all") == summary["n_window_equations"]
    per_event = list(csv.DictReader((out / "per_event.csv").open()))
    assert [r["event_id"] for r in per_event] == [p.stem for p in camp.files[:2]]


def test_cli_validate_bad_inputs_give_one_line(identified, tmp_path):
    camp, res_dir, results = identified
    run = run_cli("validate", camp.files[0].parent, tmp_path / "missing", "--out", tmp_path / "o1")
    assert run.returncode == 2 and len(run.stderr.strip().splitlines()) == 1, run.stderr
    assert run.stderr.startswith("vivbench validate:") and "missing" in run.stderr
    # a result without its event file
    lonely = tmp_path / "lonely"
    lonely.mkdir()
    shutil.copy(results[0], lonely / "E999.identify.nc")
    run = run_cli("validate", camp.files[0].parent, lonely, "--out", tmp_path / "o2")
    assert run.returncode == 2 and len(run.stderr.strip().splitlines()) == 1, run.stderr
    assert "E999.identify.nc" in run.stderr and "E999.nc" in run.stderr


def test_validate_field_events_are_skipped_with_a_message(identified, tmp_path):
    camp, _res_dir, results = identified
    field = tmp_path / "field"
    field.mkdir()
    write_event(read_event(camp.files[0]).drop_nodes("truth"), field / camp.files[0].name)
    shutil.copy(camp.files[1], field / camp.files[1].name)
    res = tmp_path / "res"
    res.mkdir()
    shutil.copy(results[0], res / results[0].name)
    with pytest.raises(ValueError, match="no event with a /truth group"):
        validate_campaign(field, res)
    # the field event beside a synthetic one: skipped with a line, the other is scored
    shutil.copy(results[1], res / results[1].name)
    run = run_cli("validate", field, res, "--out", tmp_path / "o")
    assert run.returncode == 0, run.stderr
    assert "no /truth group (field data)" in run.stderr and camp.files[0].name in run.stderr
    assert json.loads((tmp_path / "o" / "summary.json").read_text())["n_events"] == 1


def test_energy_relative_error_weights_large_values_and_counts_misses():
    from vivbench.validate import energy_relative_error

    f_true = np.array([[1.0, 0.0], [10.0, 2.0]])
    f_model = np.array([[2.0, 0.0], [10.0, np.nan]])  # 1 off on a small value, the 2 missed entirely
    assert_close(energy_relative_error(f_model, f_true), math.sqrt((1.0 + 4.0) / (1.0 + 100.0 + 4.0)))
    # the median of per-sample relative errors would say 50 % off; energy weighting says 22 %
    assert energy_relative_error(f_true, f_true) == 0.0
    assert math.isnan(energy_relative_error(np.zeros(3), np.zeros(3)))
    with pytest.raises(ValueError, match="same shape"):
        energy_relative_error(np.zeros(2), np.zeros(3))


class _ScaledTruth:
    """A model whose dA/dt is the truth's 0.1 A, 50 % too large where A > 0.05 m (the large amplitudes)."""

    def order_contributions(self, record):
        r = np.zeros(record.A.shape + (4,))
        r[..., 1] = 0.1 * (1.0 + 0.5 * (record.A > 0.05))
        return r * record.A[..., None] ** np.arange(4)


def test_score_fitted_reports_the_energy_weighted_error_beside_the_window_median():
    """Four 50 s windows, the model exact on three small-amplitude ones and 50 % off on the large one.

    Median over windows 0; energy-weighted sqrt(0.25 * 100 / (1 + 1 + 1 + 100)) (the large window has
    ten times the dA/dt, a hundred times the energy).
    """
    from vivbench.core import Record
    from vivbench.validate import score_fitted

    t = np.arange(200.0)
    A = np.where(t >= 150, 0.1, 0.01)[:, None]
    U = np.full_like(A, 8.0)
    r = np.zeros((t.size, 1, 4))
    r[..., 1] = 0.1 * A
    truth = xr.Dataset({"A": (("time", "section"), A), "U": (("time", "section"), U),
                        "r": (("time", "section", "order"), r)}, coords={"time": t})
    rec = Record(event_id="E1", t=t, A=A, U=U, dA=r.sum(-1))
    windows = [(np.array([0.0, 50.0, 100.0, 150.0]), np.array([50.0, 100.0, 150.0, 200.0]))]
    s = score_fitted(_ScaledTruth(), [rec], [truth], windows=windows, simulate=False)
    assert s["rhs_error_true_AU_median"] == 0.0
    assert s["rhs_error_true_AU_median_active"] == 0.0
    assert_close(s["rhs_error_true_AU_energy"], math.sqrt(0.25 * 100 / 103))
    assert math.isnan(s["curve_error_energy"])  # no curves


def test_curve_energy_error_scores_inside_the_data_and_counts_holes_as_misses():
    from vivbench.validate import curve_energy_error, curves_rhs

    wind = np.array([6.0, 8.0, 10.0, 12.0])
    true = np.zeros((1, 4, 4))
    true[0, 1] = 0.01
    true[0, 3] = -0.5
    model = true.copy()
    model[0, 1, 3] = 0.03  # wrong only at 12 m/s
    U = np.array([[7.0], [9.0], [11.0], [12.0]])
    A = np.full((4, 1), 0.1)
    f_true = curves_rhs(true, wind, U, A)
    assert_close(f_true[:, 0], np.full(4, 0.01 * 0.1 - 0.5e-3))
    f_model = curves_rhs(model, wind, U, A)
    expected = math.sqrt(np.sum((f_model - f_true) ** 2) / np.sum(f_true**2))
    assert_close(curve_energy_error(model, wind, U, A, f_true), expected)
    assert expected > 0
    # the data end at 10.5 m/s: the samples at 11 and 12 m/s are extrapolations, left out
    assert curve_energy_error(model, wind, U, A, f_true, [[6.5, 10.5]]) == 0.0
    # a hole inside the data is a total miss (the 9 m/s sample interpolates a NaN at 8 m/s)
    holed = model.copy()
    holed[0, :, 1] = np.nan
    assert_close(curve_energy_error(holed, wind, U, A, f_true, [[6.5, 10.5]]), math.sqrt(2 / 2))


def test_extrapolated_parts_of_the_curves_are_marked_per_equation():
    from vivbench.core import Record
    from vivbench.models import EXTRAPOLATED, curves_inside_data, data_wind_range, mark_extrapolated

    U = np.array([[7.0, 6.0], [9.0, np.nan], [8.0, 10.0]])
    A = np.full((3, 2), 0.1)
    dA = np.array([[0.0, 0.0], [0.0, 0.0], [np.nan, 0.0]])
    rec = Record(event_id="E", t=np.arange(3.0), A=A, U=U, dA=dA)
    rng = data_wind_range([rec])
    assert_close(rng, [[7.0, 9.0], [6.0, 10.0]])  # the 8 m/s sample of section 1 has no dA: not fitted
    assert_close(data_wind_range([rec], need_dA=False), [[7.0, 9.0], [6.0, 10.0]])
    wind = np.array([5.0, 6.5, 7.0, 9.5])
    curves = xr.Dataset({"curves": (("equation", "order", "wind"), np.ones((2, 4, 4)))},
                        coords={"equation": ["S1", "S2"], "order": np.arange(4), "wind": wind})
    marked = mark_extrapolated(curves, rng)
    np.testing.assert_array_equal(marked[EXTRAPOLATED].values, [[True, True, False, True], [True, False, False, False]])
    np.testing.assert_array_equal(marked["curves"].values, curves["curves"].values)  # values unchanged
    inside = curves_inside_data(curves, rng)
    assert np.isnan(inside[0, :, [0, 1, 3]]).all() and (inside[0, :, 2] == 1).all()
    with pytest.raises(ValueError, match=r"shape \(2, 2\)"):
        mark_extrapolated(curves, [[7.0, 9.0]])
