"""The varying-coefficient campaign model: exact recovery of smooth curves, the protocol, the penalty's effect."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.helpers import assert_close, assert_not_close, bell, bell_records
from vivbench.core import Record
from vivbench.core.errors import InputError
from vivbench.models import (CampaignLevel, FittedModel, HasEquations, Method, NotFittedError, Persistent, Predictor,
                             Simulator, VaryingCoefficientSINDy)
from vivbench.models.varying import bspline_basis, difference_penalty, uniform_knots
from vivbench.preprocess import smooth_wind
from vivbench.regimes import model_window_regimes, varying_window_verdicts


A3 = -2.0  # a_3, 1/(m^2 s)


def _records(n_events: int = 10, seed: int = 0, S: int = 2):
    """Noise-free records: dA/dt = bell(U) A + A3 A^3 on (A, U) histories spanning 5-15 m/s, equal winds."""
    return bell_records(n_events, seed=seed, duration_s=1200.0, dt_s=0.5, mode_shape=np.linspace(1.0, 0.6, S),
                        wind_period_s=(600.0, 100.0), amplitude_period_s=300.0, a3=A3)


@pytest.fixture(scope="module")
def fitted():
    # Exact inputs (no errors-in-variables): the default 30 s wind smoothing would only blur the wind.
    return VaryingCoefficientSINDy(n_bootstrap=10, wind_smoothing_s=0.0).fit(_records())


def test_recovers_bell_and_constant(fitted):
    wind = np.linspace(8.0, 14.0, 25)
    c = fitted.curves(wind)
    assert c["curves"].shape == (2, 4, wind.size)
    for k in range(2):
        assert_close(c["curves"].values[k, 1], bell(wind), atol=2e-4, reason="a spline fit of the bell, 0.4 % of its height")
        assert_close(c["curves"].values[k, 3], A3, rtol=5e-3, reason="the bell is not exactly a spline")
        assert_close(c["curves"].values[k, 0], 0.0, atol=1e-5, reason="no constant in the truth: a fitted zero")
    assert np.all(c["curves_lower"].values <= c["curves"].values)
    assert np.all(c["curves_upper"].values >= c["curves"].values)
    rec = _records(2, seed=5)[1]
    err = np.sqrt(np.mean((fitted.predict(rec) - rec.dA) ** 2) / np.mean(rec.dA**2))
    assert err < 1e-3


def test_protocol(fitted):
    model = VaryingCoefficientSINDy()
    assert isinstance(model, Method)
    for proto in (FittedModel, Predictor, Simulator, CampaignLevel, Persistent, HasEquations):
        assert isinstance(fitted, proto)
    with pytest.raises(NotFittedError):
        model.predict(_records(1)[0])
    rec = _records(1, seed=3)[0]
    r = fitted.order_contributions(rec)
    assert r.shape == (rec.n_samples, 2, 4)
    assert_close(fitted.predict(rec), r.sum(axis=-1), rtol=1e-7, reason="a sum of four terms")
    assert len(fitted.equations()) == 2 and fitted.equations()[0].startswith("dA1/dt = a10(U1)")
    reg = model_window_regimes(fitted, rec, np.array([0.0, 600.0]), np.array([50.0, 650.0]))
    assert reg["regime"].shape == (2, 2)
    v = varying_window_verdicts(fitted, rec, np.array([0.0, 600.0]), np.array([50.0, 650.0]))
    assert v["identifiable"].shape == (2, 2) and np.all(v["regime"] == reg["regime"])
    assert "wind_input" not in repr(model) and repr(VaryingCoefficientSINDy(seed=3)) == "VaryingCoefficientSINDy(seed=3)"


def test_nan_samples_and_simulate(fitted):
    rec = _records(1, seed=4)[0]
    U = rec.U.copy()
    U[10:20, 0] = np.nan
    r = fitted.order_contributions(Record(event_id="x", t=rec.t, A=rec.A, U=U))
    # The default wind is the mean over the sections that have one: a missing section drops out of it.
    assert np.isfinite(r).all()
    own = VaryingCoefficientSINDy(n_bootstrap=0, wind_input="section", n_basis=(11,), wind_smoothing_s=0.0).fit(_records(4))
    r = own.order_contributions(Record(event_id="x", t=rec.t, A=rec.A, U=U))
    assert np.isnan(r[10:20, 0]).all() and np.isfinite(r[10:20, 1]).all()
    sim = fitted.simulate(rec, t0=0.0, t1=100.0)
    assert sim.A_sim.shape == (201, 2) and np.isfinite(sim.A_sim).all()


def test_save_load(fitted, tmp_path):
    path = fitted.save(tmp_path / "vcm.nc")
    loaded = VaryingCoefficientSINDy.load(path)
    rec = _records(1, seed=6)[0]
    np.testing.assert_array_equal(loaded.predict(rec), fitted.predict(rec))
    assert loaded.get_params() == fitted.get_params()


def test_file_carries_its_format_version_and_unversioned_files_still_load(fitted, tmp_path):
    from vivbench.io.varying_model import VARYING_MODEL_FORMAT, VARYING_MODEL_VERSION

    path = fitted.save(tmp_path / "vcm.nc")
    with xr.open_dataset(path) as ds:
        new = ds.load()
    assert (new.attrs["format"], new.attrs["format_version"]) == (VARYING_MODEL_FORMAT, VARYING_MODEL_VERSION)
    rec = _records(2, seed=5)[1]
    # a file written before the format was versioned: the same variables, no format attributes
    old = new.copy()
    del old.attrs["format"], old.attrs["format_version"]
    old.to_netcdf(tmp_path / "old.nc")
    np.testing.assert_array_equal(VaryingCoefficientSINDy.load(tmp_path / "old.nc").predict(rec), fitted.predict(rec))
    future = new.copy()
    future.attrs["format_version"] = VARYING_MODEL_VERSION + 1
    future.to_netcdf(tmp_path / "future.nc")
    with pytest.raises(InputError, match="future.nc: varying-coefficient model format_version"):
        VaryingCoefficientSINDy.load(tmp_path / "future.nc")
    other = new.copy()
    other.attrs["model"] = "PooledSINDy"
    other.to_netcdf(tmp_path / "other.nc")
    with pytest.raises(InputError, match="other.nc: not a VaryingCoefficientSINDy file"):
        VaryingCoefficientSINDy.load(tmp_path / "other.nc")


def test_mean_wind_input():
    recs = _records(6)
    m = VaryingCoefficientSINDy(n_bootstrap=0, wind_input="mean", n_basis=(11,), wind_smoothing_s=0.0).fit(recs)
    err = np.sqrt(np.mean((m.predict(recs[0]) - recs[0].dA) ** 2) / np.mean(recs[0].dA ** 2))
    assert err < 1e-2  # equal winds: the mean is each section's wind


def test_bad_parameters():
    with pytest.raises(InputError):
        VaryingCoefficientSINDy(n_basis=(3,)).fit(_records(2))
    with pytest.raises(InputError):
        VaryingCoefficientSINDy(wind_input="gust").fit(_records(2))
    with pytest.raises(InputError, match="needs at least 2 events"):  # one event: no cross-validation over events
        VaryingCoefficientSINDy().fit(_records(1))
    for margin in (-0.1, 1.0, "0.01"):
        with pytest.raises(InputError, match=r"order_set_margin must be a number in \[0, 1\)"):
            VaryingCoefficientSINDy(order_set_margin=margin).fit(_records(2))


def test_basis_partition_of_unity():
    knots = uniform_knots(5.0, 15.0, 9)
    B = bspline_basis(np.array([4.0, 5.0, 9.3, 15.0, 20.0, np.nan]), knots)
    assert_close(B[:5].sum(axis=1), 1.0)
    assert np.isnan(B[5]).all()
    P = difference_penalty(9)
    assert_close(P @ np.linspace(0, 1, 9), 0.0, atol=1e-12, reason="straight lines are not penalised: zero up to rounding")


def _roughness(model):
    """Sum over sections and orders of ||D2 c||^2 of the standardised coefficients."""
    D = np.diff(np.eye(model.coef_.shape[1]), n=2, axis=0)
    c = model.coef_ / (model.y_scale_[:, None, None] / model.a_ref_[:, None, None] ** np.arange(4))
    return float(np.sum((D @ c) ** 2))


@settings(max_examples=4, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 1000), low=st.floats(-6.0, -2.0), factor=st.floats(10.0, 1e4))
def test_larger_penalty_is_not_rougher(seed, low, factor):
    rng = np.random.default_rng(seed)
    recs = _records(6, seed=seed)
    noisy = [Record(event_id=r.event_id, t=r.t, A=r.A, U=r.U, dA=r.dA + 1e-3 * rng.standard_normal(r.dA.shape))
             for r in recs]
    small = VaryingCoefficientSINDy(n_basis=(15,), penalties=(10.0**low,), n_bootstrap=0).fit(noisy)
    large = VaryingCoefficientSINDy(n_basis=(15,), penalties=(10.0**low * factor,), n_bootstrap=0).fit(noisy)
    assert _roughness(large) <= _roughness(small) * (1 + 1e-9) + 1e-12


def _measured(records, seed: int = 0, rms: float = 1.0, tau_s: float = 20.0):
    """``records`` with a point anemometer's slow turbulence added to U: the deck does not feel it (m/s).

    Gaussian-smoothed white noise of RMS ``rms`` with a ``tau_s`` time scale, independent of dA/dt.
    """
    from scipy.ndimage import gaussian_filter1d

    rng = np.random.default_rng(seed)
    out = []
    for r in records:
        dt = float(r.t[1] - r.t[0])
        w = gaussian_filter1d(rng.standard_normal(r.t.size), tau_s / dt)
        w *= rms / w.std()
        out.append(Record(event_id=r.event_id, t=r.t, A=r.A, U=r.U + w[:, None], dA=r.dA))
    return out


def test_wind_smoothing_chosen_by_cross_validation(tmp_path):
    grid = (0.0, 30.0, 300.0)  # 300 s wipes out the 600-1500 s variations of the deck's wind
    params = {"n_basis": (11,), "n_bootstrap": 0, "wind_smoothing_grid": grid}
    exact = VaryingCoefficientSINDy(**params).fit(_records(8))
    # The deck's own wind: any smoothing only blurs it.
    assert exact.wind_smoothing_s_ == 0.0 and exact.fitted_wind_smoothing() == 0.0
    assert exact.wind_smoothing_cv_.shape == (3,) and np.argmin(exact.wind_smoothing_cv_) == 0
    # The same model with the chosen smoothing fixed is the same fit (the choice is an outer loop).
    fixed = VaryingCoefficientSINDy(n_bootstrap=0, n_basis=(11,), wind_smoothing_s=0.0).fit(_records(8))
    np.testing.assert_array_equal(exact.coef_, fixed.coef_)
    # A point anemometer's 20 s turbulence the deck does not feel: smoothing it away predicts better.
    measured = VaryingCoefficientSINDy(**params).fit(_measured(_records(8)))
    assert measured.wind_smoothing_s_ == 30.0, measured.wind_smoothing_cv_
    rec = _measured(_records(1, seed=9), seed=9)[0]
    np.testing.assert_array_equal(measured.measured_wind(rec).U, smooth_wind(rec, 30.0).U)
    loaded = VaryingCoefficientSINDy.load(measured.save(tmp_path / "cv.nc"))
    assert loaded.wind_smoothing_s_ == 30.0 and loaded.get_params() == measured.get_params()
    np.testing.assert_array_equal(loaded.wind_smoothing_cv_, measured.wind_smoothing_cv_)
    with pytest.raises(InputError, match="wind_smoothing_grid"):
        VaryingCoefficientSINDy(wind_smoothing_grid=(-1.0,)).fit(_records(2))


def test_signed_rank_model_set_is_not_outweighed_by_one_event():
    from vivbench.regression import confidence_set

    rng = np.random.default_rng(0)
    base = 1.0 + rng.random(31)
    worse = base + 0.1 + 0.05 * rng.random(31)  # worse on every event but one ...
    worse[0] = base[0] - 3.0  # ... which is long and energetic: its gain nearly offsets the 30 small losses
    tie = base + 0.1 * rng.standard_normal(31)
    loss = np.stack([base, worse, tie])
    assert 0 < worse.sum() - base.sum() < 1.0 and tie.sum() > base.sum()  # base is the best in total
    z = confidence_set(loss, 0.95, "z")
    ranks = confidence_set(loss, 0.95, "signed_rank")
    assert z.tolist() == [True, True, True]  # the outlier inflates the paired mean's standard error
    assert ranks.tolist() == [True, False, True]
    # Four events cannot reject at 0.95 (the smallest one-sided signed-rank p is 1/16): all stay.
    assert confidence_set(loss[:, 1:5], 0.95, "signed_rank").all()


def test_model_set_test_parameter(tmp_path):
    with pytest.raises(InputError, match="model_set_test"):
        VaryingCoefficientSINDy(model_set_test="t").fit(_records(2))
    m = VaryingCoefficientSINDy(n_basis=(8,), n_bootstrap=0, wind_smoothing_s=0.0, model_set_test="z").fit(_records(4))
    loaded = VaryingCoefficientSINDy.load(m.save(tmp_path / "z.nc"))
    assert loaded.model_set_test == "z" and loaded.get_params() == m.get_params()


def _anemometers(records, sd: float = 0.5, seed: int = 0, tau_s: float = 20.0):
    """Records whose sections' anemometers each add their own slow turbulence (m/s) to the felt wind."""
    from scipy.ndimage import gaussian_filter1d

    rng = np.random.default_rng(seed)
    out = []
    for r in records:
        w = gaussian_filter1d(rng.standard_normal(r.U.shape), tau_s / float(r.t[1] - r.t[0]), axis=0)
        out.append(Record(event_id=r.event_id, t=r.t, A=r.A, U=r.U + sd * w / w.std(axis=0), dA=r.dA))
    return out


def test_eiv_weights():
    params = {"n_basis": (11,), "n_bootstrap": 0, "wind_smoothing_s": 0.0}
    recs = _records(6, S=3)
    # Equal anemometers: no wind error is estimable, the weights are all one and the fit is unchanged.
    plain = VaryingCoefficientSINDy(**params, eiv_weights=False).fit(recs)
    weighted = VaryingCoefficientSINDy(**params, eiv_weights=True).fit(recs)
    assert np.all(weighted.wind_error_share_ < 1e-12)  # the anemometers agree up to rounding
    assert_close(weighted.coef_, plain.coef_, rtol=1e-6, atol=1e-12, reason="weights 1 up to rounding")
    # Independent anemometers: the wind error carries a share of the residual variance, and the
    # refit keeps the chosen basis and penalty.
    noisy = _anemometers(recs)
    w = VaryingCoefficientSINDy(**params, eiv_weights=True).fit(noisy)
    assert np.all(w.wind_error_share_ > 0.1), w.wind_error_share_
    assert np.all(w.wind_error_share_ <= 1.0)
    p = VaryingCoefficientSINDy(**params, eiv_weights=False).fit(noisy)
    np.testing.assert_array_equal(w.penalty_, p.penalty_)
    assert_not_close(w.coef_, p.coef_, rtol=1e-5, atol=1e-8, reason="a clear difference, not rounding")


def test_fit_variants_equal_the_models_fitted_one_by_one():
    """Models that differ only in final parameters, fitted together, are the models fitted alone (same bytes)."""
    recs = _records(4, seed=2)
    base = VaryingCoefficientSINDy(n_basis=(6, 8), n_bootstrap=5, wind_smoothing_s=10.0)
    variants = [{"penalty_choice": "least", "n_bootstrap": 0}, {}, {"penalty_choice": "loeo", "n_bootstrap": 3}]
    together = base.fit_variants(recs, variants)
    assert not hasattr(base, "coef_")  # the model itself stays unfitted
    for params, model in zip(variants, together):
        alone = VaryingCoefficientSINDy(**{**base.get_params(), **params}).fit(recs)
        assert model.get_params() == alone.get_params()
        assert model.to_dataset().identical(alone.to_dataset())
        assert np.array_equal(model.coef_bootstrap_, alone.coef_bootstrap_)
    with pytest.raises(InputError, match="may change only"):
        base.fit_variants(recs, [{"n_basis": (8,)}])


def test_simulate_runs_are_each_runs_simulation(fitted):
    """Runs integrated together (each its own span, start and bound) give each run's own simulation."""
    recs = _records(3, seed=4)
    runs = [(recs[0], None, None, None), (recs[1], 100.0, 400.0, None), (recs[2], 50.0, 900.0, np.array([2.0, 1.0])),
            (recs[0], 10.0, 10.0, None)]
    together = fitted.simulate_runs(runs)
    assert together[2].stopped_at is not None  # started far above the record's amplitudes: stopped
    for run, sim in zip(runs, together):
        alone = fitted.simulate(*run)
        assert np.array_equal(sim.t, alone.t) and np.array_equal(sim.A_sim, alone.A_sim, equal_nan=True)
        assert sim.stopped_at == alone.stopped_at and sim.covered == alone.covered
        assert np.array_equal(sim.nmse, alone.nmse, equal_nan=True)


@pytest.mark.parametrize("choice", ["cv", "least"])
def test_a_fit_without_model_sets_predicts_the_same_and_gives_no_verdict(choice):
    """model_sets=False (fits made only to predict) changes no coefficient or prediction; the verdict refuses it."""
    recs = _records(5, seed=3)
    base = VaryingCoefficientSINDy(n_basis=(6, 8), n_bootstrap=0, wind_smoothing_s=10.0, penalty_choice=choice)
    full, bare = base.fit_variants(recs, [{}, {"model_sets": False}])
    assert np.array_equal(full.coef_, bare.coef_) and np.array_equal(full.penalty_coef_, bare.penalty_coef_)
    assert np.array_equal(full.penalty_, bare.penalty_)
    assert np.array_equal(full.predict(recs[0]), bare.predict(recs[0]))
    assert full.subset_plausible_.any() and not bare.subset_plausible_.any()
    ws, we = np.array([0.0, 600.0]), np.array([600.0, 1200.0])
    varying_window_verdicts(full, recs[0], ws, we)
    with pytest.raises(InputError, match="model_sets=False"):
        varying_window_verdicts(bare, recs[0], ws, we)
    with pytest.raises(InputError, match="model_sets must be True or False"):
        VaryingCoefficientSINDy(model_sets="no").fit(recs)


def test_a_simulation_stops_at_a_gap_in_the_record(fitted):
    from tests.helpers import assert_stops_at_the_gap

    assert_stops_at_the_gap(fitted, _records(1, seed=5)[0])
