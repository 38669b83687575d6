"""A campaign model written outside the package goes through pool, validate, forecast and report.

The model below knows nothing of vivbench's built-in models: per bin of the mean wind, a cubic
polynomial of dA_k/dt in A_k (a user's baseline). It has only the protocol's methods (fit,
order_contributions, predict, simulate, curves, save, load) and a verdict of its own
(``window_verdicts``), and must get every feature the built-in campaign models get.
"""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
import xarray as xr

from vivbench.cli import main
from vivbench.io.campaign_model import MODEL_NAME, read_campaign_regimes, regimes_file
from vivbench.models import Simulation, StopRule, nmse, rk4, section_names

N_COEF = 4  # 1, A, A^2, A^3


class BinnedCubic:
    """dA_k/dt = sum_i c_bki A_k^i, one least-squares fit per bin b of the mean wind (``bin_width`` m/s).

    ``window_verdicts`` flags a window identifiable when its regime (the sign of the window's linear
    coefficient: 1 damped, 2 self-excited) is the same under both halves of the campaign's samples.
    """

    def __init__(self, bin_width: float = 1.0):
        self.bin_width = bin_width

    def get_params(self, deep: bool = True) -> dict:
        return {"bin_width": self.bin_width}

    def _bins(self, U):
        with np.errstate(invalid="ignore"):
            return np.floor(np.mean(U, axis=1) / self.bin_width)

    def _fit_coef(self, A, U, dA):
        b = self._bins(U)
        ok = np.isfinite(b)[:, None] & np.isfinite(A) & np.isfinite(dA)
        bins = np.unique(b[ok.any(axis=1)]).astype(int)
        coef = np.full((bins.size, A.shape[1], N_COEF), np.nan)
        for j, bj in enumerate(bins):
            for k in range(A.shape[1]):
                sel = (b == bj) & ok[:, k]
                if sel.sum() >= 20:
                    coef[j, k] = np.linalg.lstsq(A[sel, k, None] ** np.arange(N_COEF), dA[sel, k], rcond=None)[0]
        return bins, coef

    def fit(self, records):
        A = np.concatenate([r.A for r in records])
        U = np.concatenate([r.U for r in records])
        dA = np.concatenate([r.dA for r in records])
        self.bins_, self.coef_ = self._fit_coef(A, U, dA)
        half = A.shape[0] // 2  # the two halves' models, for the verdict
        self.halves_ = [self._fit_coef(A[s], U[s], dA[s]) for s in (slice(None, half), slice(half, None))]
        self.n_sections_ = A.shape[1]
        return self

    @staticmethod
    def _coef_at(bins, coef, b):
        out = np.full((b.size,) + coef.shape[1:], np.nan)
        fin = np.isfinite(b)
        pos = np.minimum(np.searchsorted(bins, b[fin].astype(int)), bins.size - 1)
        hit = bins[pos] == b[fin].astype(int)
        out[np.flatnonzero(fin)[hit]] = coef[pos[hit]]
        return out

    def order_contributions(self, record, bins=None, coef=None):
        bins, coef = (self.bins_, self.coef_) if bins is None else (bins, coef)
        return self._coef_at(bins, coef, self._bins(record.U)) * record.A[:, :, None] ** np.arange(N_COEF)

    def predict(self, record):
        return self.order_contributions(record).sum(axis=-1)

    def _regime(self, record, start, end, bins=None, coef=None):
        """1 (damped) or 2 (self-excited) by the sign of the window mean of r_1 / A; 0 without a sample."""
        r1 = self.order_contributions(record, bins, coef)[..., 1] / record.A
        ok = np.isfinite(r1)
        csum = np.concatenate([np.zeros((1, r1.shape[1])), np.cumsum(np.where(ok, r1, 0.0), axis=0)])
        cnt = np.concatenate([np.zeros((1, r1.shape[1])), np.cumsum(ok, axis=0)])
        lo, hi = np.searchsorted(record.t, start), np.searchsorted(record.t, end)
        total, n = csum[hi] - csum[lo], cnt[hi] - cnt[lo]
        return np.where(n > 0, np.where(total > 0, 2, 1), 0).astype(np.int8)

    def window_verdicts(self, record, window_start, window_end):
        with np.errstate(invalid="ignore", divide="ignore"):  # A = 0 samples give no r_1 / A
            regime = self._regime(record, window_start, window_end)
            halves = [self._regime(record, window_start, window_end, b, c) for b, c in self.halves_]
        same = (halves[0] == regime) & (halves[1] == regime) & (regime > 0)
        return {"regime": regime, "identifiable": same, "agreement": same.astype(float),
                "order_rms": np.zeros(regime.shape + (N_COEF,))}

    def simulate(self, record, t0=None, t1=None, A0=None):
        t = record.t
        i0 = 0 if t0 is None else int(np.searchsorted(t, t0))
        i1 = t.size if t1 is None else int(np.searchsorted(t, t1, side="right"))
        tt, U = t[i0:i1], record.U[i0:i1]
        x0 = record.A[i0] if A0 is None else np.asarray(A0, dtype=float)
        c = self._coef_at(self.bins_, self.coef_, self._bins(U))  # the bin in force at each sample

        def rhs(x, n, stage):
            return np.sum(c[n + (stage == 2)] * x[:, None] ** np.arange(N_COEF), axis=-1)

        run = rk4(rhs, x0, tt, stop=StopRule(upper=10.0 * np.nanmax(record.A), lower=0.0))
        stopped = bool(np.any(run.stop >= 0))
        at = float(tt[int(np.max(run.stop))]) if stopped else None
        meas = record.A[i0:i1]
        return Simulation(t=tt, A_sim=run.x, A_meas=meas, stopped_at=at, reason="bound" if stopped else None,
                          nmse=nmse(run.x, meas), covered=1.0 if at is None else (at - tt[0]) / (tt[-1] - tt[0]),
                          windows=np.zeros(max(tt.size - 1, 0), dtype=int))

    def curves(self, wind):
        c = self._coef_at(self.bins_, self.coef_, np.floor(np.asarray(wind, dtype=float) / self.bin_width))
        out = np.transpose(c, (1, 2, 0))
        dims = ("equation", "order", "wind")
        nan = np.full_like(out, np.nan)
        return xr.Dataset({"curves": (dims, out), "curves_lower": (dims, nan), "curves_upper": (dims, nan)},
                          coords={"equation": section_names(self.n_sections_), "order": np.arange(N_COEF),
                                  "wind": np.asarray(wind, dtype=float)})

    def save(self, path):
        ds = xr.Dataset({"bins": ("bin", self.bins_), "coef": (("bin", "equation", "order"), self.coef_)},
                        attrs={"halves_json": json.dumps([[b.tolist(), np.nan_to_num(c, nan=1e300).tolist()]
                                                          for b, c in self.halves_]),
                               "bin_width": self.bin_width})
        ds.to_netcdf(path)
        return path

    @classmethod
    def load(cls, path):
        with xr.open_dataset(path) as ds:
            model = cls(bin_width=float(ds.attrs["bin_width"]))
            model.bins_, model.coef_ = ds["bins"].values, ds["coef"].values
            model.halves_ = [(np.asarray(b, dtype=int), np.where(np.asarray(c) >= 1e300, np.nan, c))
                             for b, c in json.loads(ds.attrs["halves_json"])]
        model.n_sections_ = model.coef_.shape[1]
        return model


def make() -> BinnedCubic:
    """The factory of ``vivbench pool --model tests.models.test_protocol_plugin:make``."""
    return BinnedCubic()


@pytest.fixture(scope="module")
def pooled_plugin(small_results, tmp_path_factory):
    """``vivbench pool --model tests.models.test_protocol_plugin:make`` on a copy of the small campaign's results."""
    campaign, results_dir, _files = small_results
    results = tmp_path_factory.mktemp("plugin") / "results"
    shutil.copytree(results_dir, results)
    assert main(["pool", str(results), "--model", "tests.models.test_protocol_plugin:make"]) == 0
    return campaign, results


def test_pool_takes_a_plugin_model(pooled_plugin):
    """pool writes the regimes of the plug-in's own verdict and its curves, and saves the model."""
    _campaign, results = pooled_plugin
    ds = read_campaign_regimes(regimes_file(results))
    assert ds.attrs["model"] == "BinnedCubic"
    assert ds.attrs["model_class"] == "tests.models.test_protocol_plugin:BinnedCubic"
    model = BinnedCubic.load(results / MODEL_NAME)
    first = str(ds["event_id"].values[0])
    sel = ds["event_id"].values.astype(str) == first
    from vivbench.io.result import read_result, result_record

    res = read_result(results / f"{first}.identify.nc")
    own = model.window_verdicts(result_record(res), res["window_start"].values, res["window_end"].values)
    np.testing.assert_array_equal(ds["regime"].values[sel], own["regime"])
    flags = ds["identifiable"].values[sel].astype(bool)
    assert not (flags & ~own["identifiable"]).any()  # the noise floor may only narrow the model's verdict
    assert (ds["regime"].values > 0).any() and ds["identifiable"].values.any()
    assert np.isfinite(ds["curves"].values).any()


def test_validate_forecast_report_take_the_plugin(pooled_plugin, tmp_path):
    """validate, forecast and report load the plug-in through its class path and use it as a built-in one."""
    from vivbench.analysis.pool import load_campaign_model

    campaign, results = pooled_plugin
    assert type(load_campaign_model(results)).__name__ == "BinnedCubic"
    out = tmp_path / "validation"
    assert main(["validate", str(campaign.files[0].parent), str(results), "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert np.isfinite(summary["campaign_model_regime_accuracy_all"])
    result = sorted(results.glob("*.identify.nc"))[0]
    fc = tmp_path / "forecast"
    assert main(["forecast", str(result), "--out", str(fc), "--campaign", str(campaign.files[0].parent)]) == 0
    fsum = json.loads((fc / "summary.json").read_text())
    assert any(k.startswith("campaign_model_simulation_nmse") and v is not None for k, v in fsum.items())
    assert main(["report", "--campaign", str(campaign.files[0].parent), "--results", str(results), "--name", "plugin",
                 "--out-root", str(tmp_path / "reports")]) == 0
    text = (tmp_path / "reports" / "plugin" / "report.md").read_text()
    assert "BinnedCubic" in text


def test_model_verdicts_default_is_the_rule_without_flags(short_event):
    """A model without window_verdicts gets the regime rule on its order contributions and no flag; with
    ``identifiable`` its own flags."""
    from vivbench.regimes import model_verdicts, model_window_regimes
    from vivbench.testing import event_records

    record = event_records([short_event])[0]  # the truth's A > 0: every window regime 1 under r_1 = -0.02 A

    class Damped:
        def order_contributions(self, rec):
            r = np.zeros(rec.A.shape + (N_COEF,))
            r[..., 1] = -0.02 * rec.A
            return r

    start = record.t[0] + np.array([0.0, 50.0])
    end = start + 50.0
    out = model_verdicts(Damped(), record, start, end)
    np.testing.assert_array_equal(out["regime"], model_window_regimes(Damped(), record, start, end)["regime"])
    assert (out["regime"] == 1).all() and not out["identifiable"].any()

    class Flagged(Damped):
        def identifiable(self, rec, s, e):
            return np.ones((len(s), rec.n_sections), dtype=bool)

    assert model_verdicts(Flagged(), record, start, end)["identifiable"].all()


def test_pool_events_fits_and_labels_only_the_chosen_events(small_results, tmp_path, capsys):
    """``pool --events`` pools the events it names, writes their regimes alone into --out, and says so."""
    _campaign, results, files = small_results
    ids = sorted(p.name.removesuffix(".identify.nc") for p in files)
    out = tmp_path / "part"
    before = sorted((p.name, p.stat().st_mtime_ns) for p in results.iterdir())
    assert main(["pool", str(results), "--model", "tests.models.test_protocol_plugin:make", "--events",
                 f"{ids[-1]}..", "--out", str(out)]) == 0
    ds = read_campaign_regimes(regimes_file(out))
    assert set(ds["event_id"].values.astype(str)) == {ids[-1]}
    assert f"1 events ({ids[-1]}..)" in capsys.readouterr().out
    assert sorted((p.name, p.stat().st_mtime_ns) for p in results.iterdir()) == before  # the campaign's own untouched


def test_pool_split_at_change_pools_each_side_of_the_located_change(small_results, tmp_path, capsys, monkeypatch):
    """``pool --split-at-change`` writes the whole campaign's outputs and, where a change is located, each side's
    into before_<event> and from_<event>; without a located change it says so and splits nothing."""
    import vivbench.analysis.pool as pool_module

    _campaign, results, files = small_results
    ids = sorted(p.name.removesuffix(".identify.nc") for p in files)
    args = ["pool", str(results), "--model", "tests.models.test_protocol_plugin:make", "--split-at-change"]
    assert main([*args, "--out", str(tmp_path / "none")]) == 0
    assert "no change located" in capsys.readouterr().out
    assert sorted(p.name for p in (tmp_path / "none").iterdir() if p.is_dir()) == []
    real = pool_module.pool_results
    calls = []

    def located(files_, model, **kwargs):  # the whole campaign's scan locates a change at the second event
        ds = real(files_, model, **kwargs)
        calls.append(len(files_))
        if len(calls) == 1:
            ds.attrs.update(change_detected=1, change_event=ids[1], change_p_value=0.01)
        return ds

    monkeypatch.setattr(pool_module, "pool_results", located)
    out = tmp_path / "split"
    assert main([*args, "--out", str(out)]) == 0
    assert calls == [len(ids), 1, len(ids) - 1]
    for side, events in ((f"before_{ids[1]}", ids[:1]), (f"from_{ids[1]}", ids[1:])):
        ds = read_campaign_regimes(regimes_file(out / side))
        assert sorted(set(ds["event_id"].values.astype(str))) == events
        assert (out / side / MODEL_NAME).exists()
    printed = capsys.readouterr()
    assert f"({ids[0]}..{ids[0]})" in printed.out and f"--events {ids[1]}.." in printed.err
