"""Methods as plug-ins (docs/methods.md): resolution, pysindy adapters, the standard scores, and a known answer
for a method defined outside the package, run through `vivbench compare`."""

from __future__ import annotations

import csv
import os
import subprocess
import sys
import textwrap

import numpy as np
import pysindy as ps
import pytest
import xarray as xr

from tests.helpers import REPO, assert_close
from vivbench.core import InputError, Record
from vivbench.models import PySINDyCampaign, PySINDyCP, PySINDyWindows, term_orders
from vivbench.validate import above_noise_floor, default_windows, resolve_method, score_fitted, score_method


# A known model, one section: dA/dt = 1e-4 U + (-0.02 + 0.002 U) A - 2 A^3 (m/s), monomials in A and U.
# U and A vary within every 50 s window (periods 20 s and 30 s), so each window's regression is well posed.


def _known(event_id: str, phase: float, *, n: int = 800, dt: float = 0.25) -> tuple[Record, np.ndarray]:
    t = np.arange(n) * dt
    U = (8.0 + 1.5 * np.sin(2 * np.pi * t / 20 + phase))[:, None]
    A = (0.05 + 0.04 * np.sin(2 * np.pi * t / 30 + 2 * phase))[:, None]
    r = np.zeros((n, 1, 4))
    r[..., 0] = 1e-4 * U
    r[..., 1] = (-0.02 + 0.002 * U) * A
    r[..., 3] = -2.0 * A**3
    return Record(event_id=event_id, t=t, A=A, U=U, dA=r.sum(-1)), r


@pytest.fixture(scope="module")
def known():
    return [_known("E1", 0.0), _known("E2", 1.0)]


def _sindy(degree: int = 3, threshold: float = 1e-10):
    return ps.SINDy(feature_library=ps.PolynomialLibrary(degree=degree), optimizer=ps.STLSQ(threshold=threshold))


def test_term_orders_read_the_power_of_A_from_pysindy_names():
    names = ["1", "A1", "U1", "A1^2", "A1 U1", "A1^2 U1^3", "U1 A2^3", "A1^4", "sin(A1)", "A1 A2", "1 U1^2"]
    got = term_orders(names, ["A1", "A2"], ["U1", "U2"])
    assert got.tolist() == [0, 1, 0, 2, 1, 2, 3, -1, -1, 2, 0]


def test_pysindy_campaign_and_windows_reproduce_a_known_model(known):
    records = [r for r, _ in known]
    camp = PySINDyCampaign(sindy=_sindy()).fit(records)
    win = PySINDyWindows(sindy=_sindy(), window=50.0, step=25.0).fit(records)
    cp = PySINDyCP(u_degree=2, threshold=1e-10).fit(records)
    assert win.coef_.shape[0] == 2 * 7, "seven 50 s windows (25 s step) per 200 s record"
    from vivbench.models import CampaignLevel, FittedModel, Method, Predictor, Simulator

    for model in (camp, win, cp):
        assert isinstance(model, Method) and isinstance(model, FittedModel) and isinstance(model, Predictor)
        assert "SINDy(" in repr(model)
    assert isinstance(camp, Simulator) and isinstance(camp, CampaignLevel) and not isinstance(win, CampaignLevel)
    for rec, r in known:
        for name, model in (("pooled", camp), ("windows", win), ("pysindy-cp", cp)):
            got = model.order_contributions(rec)
            assert got.shape == r.shape
            # noise-free, exact dA/dt: least squares on the true library, rounding only
            assert_close(got, r, atol=1e-9 * np.abs(r).max(), reason="least-squares rounding on O(1e-2) data",
                         what=f"{name} order contributions")
            assert_close(model.predict(rec), rec.dA, atol=1e-9 * np.abs(rec.dA).max(),
                         reason="least-squares rounding", what=f"{name} predict")


def test_terms_without_an_order_are_refused_or_set_aside(known):
    records = [r for r, _ in known]
    with pytest.raises(ValueError, match="'A1\\^4' is not a monomial in A of order <= 3"):
        PySINDyCampaign(sindy=_sindy(degree=4, threshold=0.0)).fit(records)
    m = PySINDyCampaign(sindy=_sindy(degree=4, threshold=0.0), other_terms="aside").fit(records)
    assert (m.term_orders_ == -1).sum() > 0 and 0.0 <= m.other_share_ < 1e-3


def test_resolve_method_names_the_spec_and_the_problem(tmp_path, monkeypatch):
    for spec in ("windows", "pooled", "varying", "pysindy-cp"):
        assert callable(resolve_method(spec).fit)
    (tmp_path / "plug_bad.py").write_text("def nofit():\n    return 3\n\ndef boom():\n    raise RuntimeError('no')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    cases = [("not a spec", "is not one of windows"), ("no_such_module_xyz:make", "cannot import module"),
             ("plug_bad:missing", "has no callable 'missing'"), ("plug_bad:nofit", "returned a int, which has no fit"),
             ("plug_bad:boom", "boom\\(\\) failed: RuntimeError: no"),
             ("campaign", "method 'campaign' is now named 'pooled'")]
    for spec, message in cases:
        with pytest.raises(InputError, match=message) as info:
            resolve_method(spec)
        assert repr(spec) in str(info.value)


class _Damped:
    """Always linearly damped: r1 = -c A, other orders 0 (regime 1 everywhere)."""

    def fit(self, records):
        return self

    def order_contributions(self, record):
        r = np.zeros(record.A.shape + (4,))
        r[..., 1] = -0.01 * record.A
        return r


def _truth(rec: Record, r: np.ndarray) -> xr.Dataset:
    from vivbench.core.regime import classify_regime

    regime = classify_regime(r[None], rec.A[None], axis=0)
    return xr.Dataset({"A": (("time", "section"), rec.A), "U": (("time", "section"), rec.U),
                       "r": (("time", "section", "order"), r), "regime": (("time", "section"), regime)},
                      coords={"time": rec.t})


def test_scores_of_exact_and_of_damped_models(known):
    records = [r for r, _ in known]
    truths = [_truth(rec, r) for rec, r in known]
    exact = score_method(PySINDyCampaign(sindy=_sindy()), records, truths)
    assert exact["coverage"] == 0.0, "no identifiability verdict: coverage 0"
    assert exact["accuracy_all"] == 1.0 and np.isnan(exact["accuracy_identifiable"])
    assert exact["rhs_error_true_AU_median"] < 1e-8
    # these truths have no curves; the adapter simulates (covered share in [0, 1])
    assert np.isnan(exact["curve_error_linear"]) and 0.0 <= exact["simulation_covered"] <= 1.0
    assert exact["fit_time_s"] > 0
    damped = score_fitted(_Damped(), records, truths)
    assert np.isnan(damped["simulation_nmse"]) and np.isnan(damped["curve_error_total"]), "no simulate, no curves"
    assert damped["coverage"] == 0.0 and damped["n_scored"] == exact["n_scored"] > 0
    assert damped["accuracy_all"] == damped["truth_share_regime1"]


PLUGIN = textwrap.dedent('''
    """A user's method outside vivbench: always linearly damped dynamics, dA/dt = -c A."""
    import numpy as np

    class Damped:
        def fit(self, records):
            return self

        def order_contributions(self, record):
            r = np.zeros(record.A.shape + (4,))
            r[..., 1] = -0.02 * record.A
            return r

    def make():
        return Damped()
''')


def test_known_answer_of_a_plugin_through_the_cli(tmp_path):
    """A method defined outside the package, on PYTHONPATH, run by `vivbench compare` in a subprocess:
    it answers regime 1 everywhere, so its accuracy on all windows is the share of true regime-1 windows,
    and its coverage is 0; pysindy-cp runs beside it."""
    from vivbench.io.event import read_event
    from vivbench.io.result import read_result
    from vivbench.regimes.truth import truth_window_regimes

    (tmp_path / "my_methods.py").write_text(PLUGIN)
    grid = tmp_path / "grid.toml"
    # the product design runs exactly the listed methods (one_at_a_time would add the "windows" base cell)
    grid.write_text('design = "product"\n[campaign]\nevents = 1\nduration = [400.0, 400.0]\nseed = 2\n'
                    '[grid]\nmethod = ["my_methods:make", "pysindy-cp"]\n')
    out = tmp_path / "out"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tmp_path), str(REPO)]))
    proc = subprocess.run([sys.executable, "-m", "vivbench", "compare", "--grid", str(grid), "--out", str(out),
                           "--workers", "1"], env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    with open(out / "compare.csv", newline="") as fh:
        rows = {r["method"]: r for r in csv.DictReader(fh)}
    assert set(rows) == {"my_methods:make", "pysindy-cp"}
    plug = rows["my_methods:make"]
    assert plug["error"] == "" and rows["pysindy-cp"]["error"] == "", (plug["error"], rows["pysindy-cp"]["error"])
    # The expected figure, computed here from the truth and the cell's windows alone.
    truth_reg = []
    for res_path in sorted((out / "cells" / plug["cell_id"]).glob("*.identify.nc")):
        res = read_result(res_path)
        truth = read_event(out / "campaigns" / "k00" / f"{res.attrs['event_id']}.nc")["truth"].ds
        truth_reg.append(truth_window_regimes(truth, res["window_start"].values, res["window_end"].values).ravel())
    truth_reg = np.concatenate(truth_reg)
    n_scored, n_regime1 = int((truth_reg > 0).sum()), int((truth_reg == 1).sum())
    assert int(plug["n_scored"]) == n_scored > 0
    assert 0 < n_regime1 < n_scored, "the campaign must hold regime-1 and other windows for the answer to mean something"
    assert float(plug["coverage"]) == 0.0
    # exact as counts: the CSV holds 6 significant digits
    assert round(float(plug["accuracy_all"]) * n_scored) == n_regime1
    assert_close(float(plug["accuracy_all"]), n_regime1 / n_scored, rtol=1e-5, reason="CSV holds 6 significant digits")
    for k in ("curve_error_linear", "simulation_nmse"):
        assert plug[k] == "nan", k
    assert float(rows["pysindy-cp"]["coverage"]) == 0.0 and 0.0 <= float(rows["pysindy-cp"]["accuracy_all"]) <= 1.0
    assert float(rows["pysindy-cp"]["fit_time_s"]) > 0


def test_campaign_adapter_curves_are_the_known_coefficients(known):
    m = PySINDyCampaign(sindy=_sindy()).fit([r for r, _ in known])
    wind = np.array([6.0, 8.0, 10.0])
    c = m.curves(wind)["curves"].values  # (1, 4, 3)
    expected = np.stack([1e-4 * wind, -0.02 + 0.002 * wind, 0 * wind, -2.0 + 0 * wind])[None]
    assert_close(c, expected, atol=1e-9, reason="least-squares rounding", what="a_ki(U)")


def test_campaign_adapter_simulates_the_known_model(known):
    """The fitted model integrated over a record whose A solves the known model (solve_ivp, tight tolerances)."""
    from scipy.integrate import solve_ivp

    m = PySINDyCampaign(sindy=_sindy()).fit([r for r, _ in known])
    t = np.arange(0.0, 300.0, 0.25)

    def wind(tt):
        return 8.0 + 1.0 * np.sin(2 * np.pi * tt / 600)

    def rhs(tt, a):
        u = wind(tt)
        return 1e-4 * u + (-0.02 + 0.002 * u) * a - 2.0 * a**3

    A = solve_ivp(rhs, (t[0], t[-1]), [0.02], t_eval=t, rtol=1e-12, atol=1e-14).y.T
    sim = m.simulate(Record(event_id="S", t=t, A=A, U=wind(t)[:, None]))
    assert sim.covered == 1.0 and sim.stopped_at is None
    # RK4 with 0.25 s steps and U linear between samples against a tight reference
    assert_close(sim.A_sim, A, rtol=1e-6, reason="RK4 step 0.25 s, U interpolated linearly", what="simulated A")


def test_method_levels_are_checked_before_any_campaign_is_made(tmp_path):
    from vivbench.validate import compare_config_from_dict, compare_cells

    cfg = compare_config_from_dict({"grid": {"method": ["pooled", "pysindy-cp"]}, "campaign": {"duration": 600}})
    assert [c["method"] for c in compare_cells(cfg)] == ["windows", "pooled", "pysindy-cp"]
    for levels, message in ((["nope"], "method 'nope' is not one of"),
                            (["no_such_module_xyz:make"], "cannot import module 'no_such_module_xyz'")):
        with pytest.raises(InputError, match=message):
            compare_config_from_dict({"grid": {"method": levels}})


def test_builtin_windows_method_gives_the_identification_regimes_and_verdicts(small_results):
    """"windows" through the method API refits the chain's estimator on the results' records: the same
    windows, regimes and verdicts as the identification, noise-floor test included (the records carry
    the identification's noise floor). It differentiates A again with the identification's derivative, so
    records carrying another dA/dt (the campaign models', as vivbench study gives every method) change nothing."""
    from vivbench.analysis import CAMPAIGN_DERIVATIVE, records_from_results
    from vivbench.io.result import read_result

    _campaign, _dir, files = small_results
    fitted = resolve_method("windows").fit(records_from_results(files, derivative=CAMPAIGN_DERIVATIVE))
    for rec, path in zip(records_from_results(files), files):
        res = read_result(path)
        s, e = res["window_start"].values, res["window_end"].values
        np.testing.assert_array_equal(fitted.window_regimes(rec, s, e), res["regime"].values)
        assert rec.noise_std is not None and np.all(rec.noise_std > 0)
        np.testing.assert_array_equal(fitted.identifiable(rec, s, e), res["identifiable"].values.astype(bool))


def test_builtin_verdicts_refuse_windows_below_the_noise_floor(small_results):
    """A window whose mean amplitude is below min_snr times the record's noise floor is never flagged,
    whatever the method's own verdict (there A is the envelope of noise); an unknown floor tests nothing."""
    import dataclasses

    from vivbench.analysis import records_from_results

    _campaign, _dir, files = small_results
    records = records_from_results(files)
    rec = records[0]
    start, end = default_windows(rec)
    assert above_noise_floor(rec, start, end).shape == (start.size, rec.n_sections)
    loud = dataclasses.replace(rec, noise_std=np.full(rec.n_sections, 1.0))  # 1 m: every window below 3x
    assert not above_noise_floor(loud, start, end).any()
    assert above_noise_floor(dataclasses.replace(rec, noise_std=None), start, end).all()
    assert above_noise_floor(dataclasses.replace(rec, noise_std=np.full(rec.n_sections, np.nan)), start, end).all()
    fitted = resolve_method("pooled").fit(records)
    assert not fitted.identifiable(loud, start, end).any()
    with pytest.raises(ValueError, match="noise_std"):
        dataclasses.replace(rec, noise_std=np.ones(rec.n_sections + 1))


def test_windows_and_the_window_method_stop_at_a_gap_in_time(small_results):
    """Samples missing without NaN (a result's segments, a logger's outage) end a run: no window spans the gap,
    and the window method differentiates each side on its own uniform grid instead of refusing the record."""
    import dataclasses

    from vivbench.analysis import records_from_results

    _campaign, _dir, files = small_results
    rec = records_from_results(files)[0]
    keep = np.ones(rec.n_samples, dtype=bool)
    mid = rec.n_samples // 2
    keep[mid:mid + 600] = False  # 150 s of samples missing at the 0.25 s step
    fields = {name: getattr(rec, name)[keep] for name in ("t", "A", "U", "dA")}
    gapped = dataclasses.replace(rec, **fields, yaw=None if rec.yaw is None else rec.yaw[keep])
    before, after = rec.t[mid - 1], rec.t[mid + 600]
    start, end = default_windows(gapped)
    assert start.size > 0 and not np.any((start <= before) & (end > after))
    fitted = resolve_method("windows").fit([gapped])
    s, e = fitted.model.window_start_, fitted.model.window_end_
    assert s.size > 0 and not np.any((s <= before) & (e > after))
