"""The model protocol (docs/methods.md): both built-in models satisfy it and agree with known polynomial models."""

from __future__ import annotations

import re

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from tests.helpers import assert_close
from vivbench.core import Record, evaluate_library, feature_exponents
from vivbench.io import ModelFileError, read_campaign_model
from vivbench.models import (
    CampaignLevel,
    FittedModel,
    HasEquations,
    Method,
    NotFittedError,
    Persistent,
    PooledSINDy,
    Predictor,
    Simulator,
    EventWindowSINDy,
    WindowSINDy,
)
from vivbench.regimes import campaign_window_verdicts, label_windows, model_window_regimes


def _true_coef(S: int) -> np.ndarray:
    """A sparse physical model (S, 23 S): damping, wind-driven self-excitation, A^2 U and A^3 limits, forcing."""
    ex = feature_exponents(S)
    coef = np.zeros((S, 23 * S))

    def put(k, sec, i, j, value):
        coef[k, np.flatnonzero((ex[:, 0] == sec) & (ex[:, 1] == i) & (ex[:, 2] == j))[0]] = value

    for k in range(S):
        put(k, k, 1, 0, -0.02)
        put(k, k, 1, 2, 5e-4)
        put(k, k, 2, 1, -0.01)
        put(k, k, 3, 0, -2.0)
        put(k, k, 0, 2, 1e-5)
        if k > 0:
            put(k, k - 1, 1, 0, 0.01)  # coupling to the neighbouring section
    return coef


def _records(S: int, coef: np.ndarray, n_records: int = 2, n: int = 1500, dt: float = 0.5, seed: int = 0):
    """Noise-free records: A and U wander independently over wide ranges; dA from the known model."""
    rng = np.random.default_rng(seed)
    out = []
    for r in range(n_records):
        t = 1000.0 * r + dt * np.arange(n)
        ph = rng.uniform(0, 2 * np.pi, (4, S))
        per = rng.uniform(60, 200, (4, S))
        A = 0.1 + 0.06 * np.sin(2 * np.pi * t[:, None] / per[0] + ph[0]) + 0.03 * np.sin(2 * np.pi * t[:, None] / per[1] + ph[1])
        U = 8.0 + 2.5 * np.sin(2 * np.pi * t[:, None] / per[2] + ph[2]) + 1.0 * np.sin(2 * np.pi * t[:, None] / per[3] + ph[3])
        dA = evaluate_library(A, U) @ coef.T
        out.append(Record(event_id=f"E{r + 1:03d}", t=t, A=A, U=U, dA=dA))
    return out


def _true_contributions(rec: Record, coef: np.ndarray) -> np.ndarray:
    theta = evaluate_library(rec.A, rec.U)
    orders = feature_exponents(rec.n_sections)[:, 1]
    return np.stack([theta[:, orders == i] @ coef[:, orders == i].T for i in range(4)], axis=-1)


@pytest.fixture(scope="module", params=[1, 2, 3], ids=lambda s: f"S{s}")
def campaign_fit(request):
    S = request.param
    coef = _true_coef(S)
    recs = _records(S, coef)
    model = PooledSINDy(n_bootstrap=8, block_s=50.0, min_blocks=5, seed=1).fit(recs)
    return S, coef, recs, model


@pytest.fixture(scope="module")
def window_fit():
    coef = _true_coef(2)
    # dt = 0.3 s: no sample falls on a window boundary (50 s is not a multiple of it)
    recs = _records(2, coef, n=1000, dt=0.3, seed=4)
    model = WindowSINDy(window=50.0, step=50.0).fit(recs)
    return coef, recs, model


def test_records_validate_their_arrays():
    t = np.arange(5.0)
    A = np.ones((5, 2))
    with pytest.raises(ValueError, match="strictly increasing"):
        Record(event_id="E", t=t[::-1], A=A, U=A)
    with pytest.raises(ValueError, match=r"Record.U must have shape \(5, 2\)"):
        Record(event_id="E", t=t, A=A, U=A[:, :1])
    with pytest.raises(ValueError, match="finite"):
        Record(event_id="E", t=np.r_[t[:4], np.nan], A=A, U=A)
    with pytest.raises(ValueError, match="event_id"):
        Record(event_id="", t=t, A=A, U=A)
    rec = Record(event_id="E", t=t, A=np.where(t[:, None] > 2, np.nan, A), U=A)  # NaN: no sample
    assert rec.valid().tolist() == [True, True, True, False, False]
    assert not rec.A.flags.writeable
    with pytest.raises(ValueError, match="no dA"):
        rec.valid(need_dA=True)


def test_both_models_satisfy_the_protocol(campaign_fit, window_fit):
    pooled, window = campaign_fit[3], window_fit[2]
    for model in (pooled, window):
        assert isinstance(model, Method) and isinstance(model, FittedModel)
        assert isinstance(model, Predictor) and isinstance(model, Simulator)
        assert isinstance(model, Persistent) and isinstance(model, HasEquations)
    assert isinstance(pooled, CampaignLevel)
    assert not isinstance(window, CampaignLevel)  # window models are not campaign-level
    import vivbench.models

    assert not hasattr(vivbench.models, "CampaignSINDy")  # one name: PooledSINDy
    with pytest.raises(NotFittedError, match="not fitted"):
        PooledSINDy().predict(campaign_fit[2][0])


def test_predict_is_the_sum_of_the_order_contributions(campaign_fit, window_fit):
    for model, rec in ((campaign_fit[3], campaign_fit[2][0]), (window_fit[2], window_fit[1][1])):
        r = model.order_contributions(rec)
        assert r.shape == (rec.n_samples, rec.n_sections, 4)
        assert_close(r.sum(axis=-1), model.predict(rec), rtol=1e-9, atol=1e-12, reason="sum of four matrix products")


def test_campaign_model_recovers_a_known_model(campaign_fit):
    S, coef, recs, model = campaign_fit
    # the physical image of the scaled-basis model carries rounding-level terms (centred U fills in lower powers)
    assert_close(model.coef_, coef, rtol=1e-6, atol=1e-12, reason="noise-free data, wide ranges of A and U")
    rec = recs[1]
    true_r = _true_contributions(rec, coef)
    scale = np.sqrt(np.mean(rec.dA**2))
    assert np.max(np.abs(model.order_contributions(rec) - true_r)) < 1e-6 * scale
    # the regime rule through the protocol agrees with the campaign model's own window regimes
    ws = rec.t[0] + 50.0 * np.arange(12)
    via_protocol = model_window_regimes(model, rec, ws, ws + 50.0, tau=model.tau)
    own = campaign_window_verdicts(model, rec.t, rec.A, rec.U, ws, ws + 50.0)
    assert np.array_equal(via_protocol["regime"], own["regime"])
    assert_close(via_protocol["order_rms"], own["order_rms"], rtol=1e-9, atol=1e-15, reason="same sums, other order")


def test_legacy_tuples_fit_the_same_campaign_model():
    recs = _records(1, _true_coef(1), n=400)
    model = PooledSINDy(n_bootstrap=2, block_s=50.0).fit(recs)
    legacy = PooledSINDy(**model.get_params()).fit([(r.t, r.A, r.U, r.dA) for r in recs])
    assert np.array_equal(legacy.coef_, model.coef_)


def test_save_and_load_give_identical_predictions(campaign_fit, window_fit, tmp_path):
    S, _coef, recs, model = campaign_fit
    path = model.save(tmp_path / "campaign.model.nc")
    back = PooledSINDy.load(path)
    assert back.get_params() == model.get_params()
    assert np.array_equal(back.predict(recs[0]), model.predict(recs[0]))
    assert back.equations() == model.equations()
    ws = recs[0].t[0] + 100.0 * np.arange(5)
    a, b = campaign_window_verdicts(model, recs[0].t, recs[0].A, recs[0].U, ws, ws + 100), campaign_window_verdicts(back, recs[0].t, recs[0].A, recs[0].U, ws, ws + 100)
    assert all(np.array_equal(a[k], b[k], equal_nan=True) for k in a)
    _c, wrecs, wmodel = window_fit
    wpath = wmodel.save(tmp_path / "window.model.nc")
    wback = WindowSINDy.load(wpath)
    assert np.array_equal(wback.predict(wrecs[0]), wmodel.predict(wrecs[0]), equal_nan=True)
    assert wback.equations() == wmodel.equations()
    # the readers name the file in one line
    with pytest.raises(ModelFileError, match=r"window\.model\.nc: not a campaign model"):
        read_campaign_model(wpath)
    with pytest.raises(ModelFileError, match="no such campaign model"):
        PooledSINDy.load(tmp_path / "missing.nc")


def test_params_follow_scikit_learn():
    model = PooledSINDy(n_bootstrap=5)
    assert model.get_params()["n_bootstrap"] == 5
    assert set(model.get_params()) == {"thresholds", "alpha", "scaling", "n_bootstrap", "block_s", "agreement",
                                       "confidence", "min_blocks", "tau", "seed", "chunk_size", "wind_smoothing_s"}
    assert model.set_params(alpha=0.1) is model and model.alpha == 0.1
    assert repr(model) == "PooledSINDy(alpha=0.1, n_bootstrap=5)"
    with pytest.raises(ValueError, match="unknown parameter 'beta'"):
        model.set_params(beta=1)
    w = WindowSINDy(window=40.0)
    assert repr(w) == "WindowSINDy(window=40.0)"
    assert EventWindowSINDy(**w.get_params()).window == 40.0


def test_curves_have_bands_around_the_point_curve(campaign_fit):
    S, coef, recs, model = campaign_fit
    wind = np.linspace(5.0, 11.0, 7)
    ds = model.curves(wind)
    assert ds["curves"].shape == (S, 4, wind.size)
    assert ds["wind"].attrs["units"] == "m/s"
    assert np.all(ds["curves_lower"].values <= ds["curves"].values)
    assert np.all(ds["curves"].values <= ds["curves_upper"].values)
    # exact curves of the known model: own terms plus the coupling folded in with the amplitude ratios
    rho = model.amplitude_ratios_
    assert rho.shape == (S, S)
    assert_close(np.diag(rho), 1.0)
    expect = np.zeros((S, 4, wind.size))
    expect[:, 0] = 1e-5 * wind**2
    expect[:, 1] = -0.02 + 5e-4 * wind**2
    expect[:, 2] = -0.01 * wind
    expect[:, 3] = -2.0
    for k in range(1, S):
        expect[k, 1] += 0.01 * rho[k, k - 1]
    assert_close(ds["curves"].values, expect, rtol=1e-6, atol=1e-9, reason="noise-free fit of the known model")


def test_simulate_reproduces_a_directly_integrated_trajectory(campaign_fit):
    S, coef, recs, model = campaign_fit
    rec = recs[0]
    # a record whose wind is a known smooth function; A itself is irrelevant beyond A0
    t = np.arange(0.0, 300.0, 0.25)
    Ufun = lambda tt: 8.0 + 2.0 * np.sin(2 * np.pi * np.asarray(tt)[..., None] / 150.0 + np.arange(S))  # noqa: E731
    sim_rec = Record(event_id="sim", t=t, A=np.full((t.size, S), 0.1), U=Ufun(t))
    A0 = np.linspace(0.05, 0.12, S)
    sim = model.simulate(sim_rec, 0.0, 250.0, A0=A0)
    assert not sim.stopped and sim.A_sim.shape == (sim.t.size, S)

    def rhs(tt, a):
        return (evaluate_library(a[None], Ufun(tt)[None]) @ coef.T)[0]

    ref = solve_ivp(rhs, (0.0, 250.0), A0, t_eval=sim.t, rtol=1e-10, atol=1e-12, method="DOP853")
    # RK4 at 0.25 s with U from a cubic spline of its samples: 1e-6 relative to the amplitude
    assert np.max(np.abs(sim.A_sim - ref.y.T)) < 1e-6 * np.max(np.abs(ref.y))
    assert rec.n_sections == S


def test_equations_parse_back(campaign_fit, window_fit, capsys):
    S, coef, recs, model = campaign_fit
    eqs = model.equations()
    model.print()
    assert capsys.readouterr().out.splitlines() == eqs
    assert len(eqs) == S
    for k, line in enumerate(eqs):
        lhs, rhs = line.split(" = ")
        assert lhs == f"dA{k + 1}/dt"
        terms = re.split(r" [+-] ", rhs.lstrip("-"))
        assert len(terms) == int(np.count_nonzero(model.coef_[k]))
        for term in terms:
            number, _, names = term.partition(" ")
            float(number)
            assert names in model.feature_names_
    _c, wrecs, wmodel = window_fit
    lines = wmodel.equations(event_id="E001")
    assert len(lines) == 2 * int(np.sum(wmodel.window_event_ == 0))
    assert lines[0].startswith("[E001 0-50 s] dA1/dt = ")


def test_window_model_regimes_match_the_pipeline(window_fit):
    _coef, recs, model = window_fit
    rec = recs[0]
    est = EventWindowSINDy(window=50.0, step=50.0)
    pipeline = label_windows(est, rec.t, rec.A, rec.U, rec.dA)
    assert np.array_equal(est.coef_, model.coef_[model.window_event_ == 0], equal_nan=True)
    via = model_window_regimes(model, rec, est.window_start_, est.window_end_)
    assert np.array_equal(via["regime"], pipeline["regime"])
    # physical coefficients of an ill-conditioned window cancel to a few digits (models/simulate.py notes)
    assert_close(via["order_rms"], est.order_rms_, rtol=0.05, atol=1e-12,
                 reason="physical against scaled basis of ill-conditioned windows")


def test_window_model_follows_its_windows(window_fit):
    coef, recs, model = window_fit
    rec = recs[1]
    # noise-free data: every window predicts dA/dt closely
    assert np.max(np.abs(model.predict(rec) - rec.dA)) < 1e-3 * np.max(np.abs(rec.dA))
    with pytest.raises(KeyError, match="not fitted"):
        model.predict(Record(event_id="other", t=rec.t, A=rec.A, U=rec.U))
    sim = model.simulate(rec, rec.t[0], rec.t[0] + 40.0)
    assert sim.A_sim.shape[1] == 2


def _fake_result(path, event_id: str, seed: int):
    """A minimal ``<event_id>.identify.nc``: two sections, two segments, a gap, windows."""
    import xarray as xr

    t = 0.5 * np.arange(1600)
    A = 0.1 + 0.05 * np.sin(t[:, None] / np.array([40.0, 55.0]) + seed)
    U = 8.0 + 2.0 * np.sin(t[:, None] / np.array([90.0, 97.0]) + 2 * seed)
    dA = evaluate_library(A, U) @ _true_coef(2).T
    seg = np.where(t < 400, 0, 1)
    seg[(t > 390) & (t < 410)] = -1
    dA[seg < 0] = np.nan
    ws = np.arange(0.0, 750.0, 25.0)
    ds = xr.Dataset({"A": (("time", "section"), A), "U": (("time", "section"), U), "dA": (("time", "section"), dA),
                     "segment": (("time",), seg.astype(np.int32)), "window_start": (("window",), ws),
                     "window_end": (("window",), ws + 50)},
                    coords={"time": t, "equation": ["S1", "S2"], "section": ["S1", "S2"], "window": np.arange(ws.size)},
                    attrs={"format": "vivbench-identify", "format_version": 1, "event_id": event_id})
    ds.to_netcdf(path)
    return path


def test_records_from_results_feed_the_protocol_and_the_pooled_file_reads(tmp_path):
    from vivbench.analysis import pool_results, records_from_results
    from vivbench.io import read_campaign_regimes, write_campaign_regimes
    from vivbench.preprocess.derivative import Derivative

    paths = [_fake_result(tmp_path / f"E{k}.identify.nc", f"E{k}", k) for k in range(2)]
    recs = records_from_results(paths)
    assert [r.event_id for r in recs] == ["E0", "E1"] and recs[0].A.shape == (1600, 2)
    fd = records_from_results(paths, derivative=Derivative(method="finite_difference"))
    assert np.isnan(fd[0].dA[(recs[0].t > 390) & (recs[0].t < 410)]).all()
    model = PooledSINDy(n_bootstrap=3, block_s=100.0).fit(recs)
    # the records pool_results fits are records_from_results' by default (the campaign derivative)
    pooled = read_campaign_regimes(write_campaign_regimes(pool_results(paths, PooledSINDy(n_bootstrap=3, block_s=100.0)),
                                                          tmp_path))
    assert np.array_equal(pooled["coef"].values, model.coef_)
    with pytest.raises(ModelFileError, match=r"E0\.identify\.nc: not a campaign regimes"):
        read_campaign_regimes(paths[0])


def test_a_pooled_simulation_stops_at_a_gap_in_the_record(campaign_fit):
    from tests.helpers import assert_stops_at_the_gap

    _, _, recs, model = campaign_fit
    assert_stops_at_the_gap(model, recs[0])


def test_settings_text_is_the_models_own_or_its_class_and_size(campaign_fit):
    """``model_settings_text``: the model's ``settings_text()``, else its class's name and ``terms_per_equation()``."""
    from vivbench.models import model_settings_text

    _, _, _, pooled = campaign_fit
    assert model_settings_text(pooled) == pooled.settings_text()
    assert model_settings_text(pooled).startswith("PooledSINDy, terms per equation ")

    class Sized:
        def terms_per_equation(self):
            return [3, 5]

    class Bare:
        pass

    assert model_settings_text(Sized()) == "Sized, size per equation 3, 5"
    assert model_settings_text(Bare()) == "Bare"
