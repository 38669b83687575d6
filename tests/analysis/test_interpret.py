"""Cluster interpretation of window models (vivbench.analysis.interpret) and the cluster/forecast CLIs."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
import xarray as xr

from tests.helpers import assert_close
from vivbench.cli import main
from vivbench.analysis.interpret import ClusterConfig, campaign_windows, cluster_scores, cluster_windows, standardized_coefficients
from vivbench.models.window import EventWindowSINDy
from vivbench.analysis.identify import identify_files
from vivbench.analysis.clustering import DensityPeaks
from vivbench.core.terms import evaluate_library, feature_names
from vivbench.validate import clearest_plateau, measured_plateau, truth_plateau
from vivbench.io.netcdf import NETCDF_ENGINE

FS = 4.0


def _wind(t):
    t = np.asarray(t, dtype=float)[:, None]
    return 8.0 + 0.8 * np.sin(2 * np.pi * t / 300.0 + np.array([0.0, 0.7, 1.4]))


def _index(section, i, j):
    from vivbench.core.terms import feature_exponents

    ex = feature_exponents(3)
    return int(np.flatnonzero((ex[:, 0] == section) & (ex[:, 1] == i) & (ex[:, 2] == j))[0])


@pytest.fixture(scope="module")
def fitted_event():
    """A decoupled sparse model's trajectory, identified by the engine with exact derivatives."""
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 400.0 + 1e-9, 1.0 / FS)
    U = _wind(t) + 0.05 * rng.normal(size=(t.size, 3)).cumsum(0) / 20.0
    A = 0.02 + 0.01 * np.sin(2 * np.pi * t[:, None] / 170.0 + np.array([0.0, 0.5, 1.0])) ** 2
    xi = np.zeros((3, 69))
    for k in range(3):
        xi[k, _index(k, 1, 1)] = 2e-3
        xi[k, _index(k, 3, 0)] = -1.0
    dA = evaluate_library(A, U) @ xi.T
    est = EventWindowSINDy(keep_path=False).fit(t, A, U, dA)
    sections = ["S1", "S2", "S3"]
    ds = xr.Dataset(
        {"coef": (("window", "equation", "feature"), est.coef_),
         "window_start": (("window",), est.window_start_), "window_end": (("window",), est.window_end_),
         "A": (("time", "section"), A), "U": (("time", "section"), U), "dA": (("time", "section"), dA)},
        coords={"window": np.arange(est.window_start_.size), "equation": sections, "feature": feature_names(3),
                "time": t, "section": sections})
    return est, ds


def test_standardized_coefficients_are_the_engines(fitted_event):
    est, ds = fitted_event
    xi = standardized_coefficients(ds)
    scale = np.abs(est.coef_scaled_).max(axis=2, keepdims=True)
    # The inverse of the window's exact basis map loses cond(to_physical) * eps
    # (c/s ~ 10-80 to the fifth power) relative to the largest coefficient.
    assert_close(xi / scale, est.coef_scaled_ / scale, atol=1e-5, reason="inverting an ill-conditioned basis map",
                 what="standardised coefficients")


def _blobs(seed, sizes=(60, 40, 25), dim=6, sep=10.0):
    rng = np.random.default_rng(seed)
    centres = rng.normal(size=(len(sizes), dim))
    centres *= sep / np.linalg.norm(centres, axis=1, keepdims=True)
    X = np.concatenate([c + rng.normal(size=(n, dim)) for c, n in zip(centres, sizes)])
    return X, np.repeat(np.arange(len(sizes)), sizes)


@pytest.mark.parametrize("kernel", ["cutoff", "gaussian"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_unequal_blobs_recovered_and_invariant(kernel, seed):
    X, truth = _blobs(seed)
    m = DensityPeaks(kernel=kernel).fit(X)
    assert m.centers_.size == 3, f"found {m.centers_.size} centres, expected 3"
    assert cluster_scores(m.labels_, truth + 1)["ari"] == 1.0, "blobs of unequal size not recovered exactly"
    perm = np.random.default_rng(seed + 10).permutation(X.shape[0])
    p = DensityPeaks(kernel=kernel).fit(X[perm])
    assert np.array_equal(p.labels_, m.labels_[perm]), "labels depend on the order of the points"
    s = DensityPeaks(kernel=kernel).fit(1e-3 * X)
    assert np.array_equal(s.labels_, m.labels_), "labels change under a common scaling of the features"


def test_cluster_scores_reference_values():
    labels = np.array([0, 0, 0, 1, 1, 1, 1, 0])
    truth = np.array([1, 1, 2, 3, 3, 3, 3, 0])  # last point has no truth
    s = cluster_scores(labels, truth)
    assert s["n_scored"] == 7
    assert_close(s["purity"], 6 / 7, what="purity")
    assert cluster_scores(labels[:7], labels[:7] + 1)["ari"] == 1.0
    assert np.isnan(cluster_scores(labels, np.zeros(8, int))["ari"])


def test_config_validation():
    with pytest.raises(ValueError, match="kernel"):
        ClusterConfig(kernel="box")
    with pytest.raises(ValueError, match="dc_fraction"):
        ClusterConfig(dc_fraction=0.0)
    with pytest.raises(ValueError, match="n_centers"):
        ClusterConfig(n_centers=0)


@pytest.fixture(scope="module")
def identified(small_campaign, tmp_path_factory):
    """Two events of the small campaign identified (results directory, campaign directory)."""
    out = tmp_path_factory.mktemp("identified")
    files = sorted(small_campaign.files)[:2]
    written, failures = identify_files(files, out, workers=1)
    assert not failures, failures
    return out, files[0].parent, written


def test_campaign_windows_and_clustering(identified):
    out, campaign, written = identified
    cw = campaign_windows(written, campaign)
    assert cw.has_truth and cw.n_points > 10
    assert set(cw.truth_regime.tolist()) <= {1, 2, 3, 4}
    assert cw.features["coef"].shape == (cw.n_points, 69) and cw.features["order"].shape == (cw.n_points, 4)
    assert_close(cw.features["order"].sum(1), 1.0, rtol=1e-12, reason="shares", what="order shares")
    res = cluster_windows(cw, ClusterConfig(n_centers=2))
    for name, r in res.items():
        assert r.n_clusters == 2
        assert sum(row["size"] for row in r.summary) == cw.n_points
        assert np.isfinite(r.scores["ari"]) and 0 <= r.scores["purity"] <= 1
        assert all(row["dominant_terms"] for row in r.summary)
    # the partition depends on the points, not on the order of the files
    cw_rev = campaign_windows(written[::-1], campaign)
    rev = cluster_windows(cw_rev, ClusterConfig(n_centers=2))
    key = lambda c: {(e, w, q): i for e, w, q, i in zip(c.event_id, c.window, c.equation, range(c.n_points))}
    k1, k2 = key(cw), key(cw_rev)
    idx = np.array([k2[k] for k in k1])
    assert np.array_equal(rev["order"].model.labels_[idx], res["order"].model.labels_)


def test_cluster_cli_writes_every_file(identified, tmp_path):
    out, campaign, _ = identified
    dest = tmp_path / "clu"
    assert main(["cluster", str(out), "--out", str(dest), "--campaign", str(campaign), "--kernel", "gaussian"]) == 0
    for name in ("cluster_labels.csv", "cluster_summary.csv", "decision_graph_coef.png", "decision_graph_order.png",
                 "summary.json"):
        assert (dest / name).stat().st_size > 0, name
    with open(dest / "cluster_labels.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0]) == ["event_id", "window", "equation", "window_start", "window_end", "feature_set", "label",
                             "halo"]
    assert {r["feature_set"] for r in rows} == {"coef", "order"}
    assert all(int(r["label"]) >= 0 for r in rows)
    summary = json.loads((dest / "summary.json").read_text())
    assert {"n_clusters_coef", "n_clusters_order", "ari_coef", "ari_order"} <= set(summary)
    assert summary["n_clusters_coef"] >= 1


def test_forecast_cli_writes_every_file(identified, tmp_path):
    out, campaign, written = identified
    dest = tmp_path / "fc"
    assert main(["forecast", str(written[0]), "--out", str(dest), "--t0", "100", "--horizon", "60",
                 "--d", "0,50", "--campaign", str(campaign)]) == 0
    eid = written[0].name.split(".")[0]
    for name in (f"forecast_{eid}.csv", f"forecast_{eid}.png", "summary.json"):
        assert (dest / name).stat().st_size > 0, name
    summary = json.loads((dest / "summary.json").read_text())
    assert summary["t0_s"] == 100.0 and "nmse_S2_d0" in summary and "nmse_falls_with_d" in summary
    with open(dest / f"forecast_{eid}.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert {r["kind"] for r in rows} == {"simulation", "forecast"}
    assert {r["d_s"] for r in rows if r["kind"] == "forecast"} == {"0", "50"}


@pytest.mark.parametrize("argv, message", [
    (["cluster", "{missing}", "--out", "{tmp}/o"], "not a directory"),
    (["cluster", "{tmp}", "--out", "{tmp}/o"], "no identification results"),
    (["forecast", "{missing}/E001.identify.nc", "--out", "{tmp}/o"], "no such result file"),
    (["forecast", "{bad}", "--out", "{tmp}/o"], "cannot be read"),
])
def test_bad_input_exits_2_with_one_line(argv, message, tmp_path, capsys):
    bad = tmp_path / "bad.identify.nc"
    bad.write_text("not netcdf")
    argv = [a.format(missing=tmp_path / "nope", tmp=tmp_path / "empty", bad=bad) for a in argv]
    (tmp_path / "empty").mkdir()
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err, err


def test_forecast_t0_outside_record_exits_2(identified, tmp_path, capsys):
    _out, _campaign, written = identified
    assert main(["forecast", str(written[0]), "--out", str(tmp_path), "--t0", "1e6"]) == 2
    assert "outside the record" in capsys.readouterr().err


def test_plateau_pickers(small_campaign, identified):
    t = np.arange(0.0, 1000.0, 0.5)
    reg = np.ones((t.size, 3), dtype=np.int8)
    reg[(t >= 100) & (t < 200), 1] = 4  # 100 s run
    reg[(t >= 300) & (t < 700), 1] = 4  # 400 s run: the longest
    reg[(t >= 800) & (t < 990), 0] = 4  # longer than the first but at S1
    A = np.full((t.size, 3), 0.1)
    truth = xr.Dataset({"regime": (("time", "section"), reg), "A": (("time", "section"), A)}, coords={"time": t})
    p = truth_plateau(truth, "E9")
    assert (p.start, p.end, p.t0) == (300.0, 699.5, 350.0), p
    reg[:, 1] = 1
    assert truth_plateau(truth.assign(regime=(("time", "section"), reg))) is None
    # the small campaign's events never reach regime 4: said so, not guessed
    with pytest.raises(ValueError, match="no event has a run of true regime 4"):
        clearest_plateau(small_campaign.files[0].parent)
    _out, _c, written = identified
    with xr.open_dataset(written[0], engine=NETCDF_ENGINE) as res:
        m = measured_plateau(res.load())
        A2 = res["A"].values[:, 1]
        inside = (res["time"].values >= m.start) & (res["time"].values <= m.end)
        assert np.all(A2[inside] >= 0.8 * np.nanmax(A2)) and m.start <= m.t0 <= m.end
