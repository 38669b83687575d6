"""The grey-box band component for the wind's errors-in-variables (vivbench.models.greybox_wind)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.models.test_greybox import BRIDGE, _records, _true_curves
from vivbench.core.errors import InputError
from vivbench.core.record import Record
from vivbench.models.greybox import GreyBoxRefit
from vivbench.models.greybox_wind import (
    relative_spread,
    simex_extrapolate,
    unmeasured_wind_draws,
    wind_error_draws,
    wind_second_moment,
)
from tests.helpers import assert_close, is_close

PARAMS = {"peak": 18.0, "center": 6.8, "width": 1.1, "baseline": -4.0, "e1": 25.0, "e2": 400.0, "cl": 0.03}


def _grid(seed=0, n_events=3, n_int=4, m=11, S=3):
    rng = np.random.default_rng(seed)
    U = 8.0 + rng.standard_normal((n_events * n_int, m, S)) * np.array([0.3, 0.1, 0.5])
    return U, np.repeat(np.arange(n_events), n_int)


def test_relative_spread_is_the_error_size_and_zero_for_one_section():
    rng = np.random.default_rng(1)
    sigma = 0.05
    U = 10.0 * (1.0 + sigma * rng.standard_normal((200_000, 4)))  # independent anemometer errors, 5 %
    assert_close(np.std(relative_spread(U)), sigma, rtol=0.03, reason="a standard deviation from 200 000 draws")
    np.testing.assert_array_equal(relative_spread(U[:, :1]), 0.0)
    np.testing.assert_array_equal(relative_spread(np.full((5, 3), 7.0)), 0.0)


def test_wind_error_draws_are_seeded_from_other_events_and_scale_linearly():
    U, ev = _grid()
    d = wind_error_draws(U, ev, n_draws=4, seed=3)
    assert d.shape == (4,) + U.shape
    np.testing.assert_array_equal(d, wind_error_draws(U, ev, n_draws=4, seed=3))
    assert not np.array_equal(d, wind_error_draws(U, ev, n_draws=4, seed=4))
    np.testing.assert_array_equal(d[:2], wind_error_draws(U, ev, n_draws=2, seed=3))  # independent of n_draws
    np.testing.assert_array_equal(wind_error_draws(U, ev, n_draws=4, seed=3, scale=0.0), 0.0)
    assert_close(wind_error_draws(U, ev, n_draws=4, seed=3, scale=2.0), 2.0 * d, rtol=1e-12)
    # each event's error is another event's relative spread (permuted, signed) times this event's mean wind
    rel = np.abs(relative_spread(U))
    mean = U.mean(axis=-1, keepdims=True)
    for e in range(3):
        got = np.sort(np.abs(d[0, ev == e] / mean[ev == e]).ravel())
        donors = [np.sort(rel[ev == j].ravel()) for j in range(3) if j != e]
        assert any(is_close(got, x, rtol=1e-5, atol=1e-8, reason="ratios of resampled winds: rounding") for x in donors)
    with pytest.raises(ValueError, match="n_draws"):
        wind_error_draws(U, ev, n_draws=0, seed=0)


def test_unmeasured_wind_draws_are_the_error_over_the_distance_where_the_spread_shows_none():
    from vivbench.preprocess.unmeasured_wind import unmeasured_wind_error

    U = np.full((12, 11, 3), 9.0)  # one anemometer copied to every section: no spread, no spread's error
    ev = np.repeat(np.arange(3), 4)
    np.testing.assert_array_equal(wind_error_draws(U, ev, n_draws=2, seed=0), 0.0)
    assert unmeasured_wind_draws(U, ev, np.zeros((3, 3)), n_draws=2, seed=0) is None
    dist = np.tile([300.0, 0.0, 300.0], (3, 1))  # the anemometer at section 2
    d = unmeasured_wind_draws(U, ev, dist, n_draws=400, seed=1)
    assert d.shape == (400,) + U.shape
    np.testing.assert_array_equal(d[..., 1], 0.0)
    sigma = float(unmeasured_wind_error(np.array([9.0]), 300.0)[0])
    assert sigma > 0
    # constant over an event (one z per draw, record and section), with the error's rms over the draws
    assert np.all(d[:, ev == 0][..., 0] == d[:, :1, :1, 0])
    assert_close(np.std(d[:, 0, 0, 0]), sigma, rtol=0.15, reason="a standard deviation from 400 draws")
    np.testing.assert_array_equal(d, unmeasured_wind_draws(U, ev, dist, n_draws=400, seed=1))


def test_second_moment_is_spread_plus_squared_shift():
    rng = np.random.default_rng(2)
    theta = np.array([1.0, -1.0, 0.5])
    refits = theta + 0.3 + rng.standard_normal((50, 3)) * [0.1, 0.2, 0.0]
    d = refits - refits.mean(axis=0)
    shift = refits.mean(axis=0) - theta
    assert_close(wind_second_moment(theta, refits), d.T @ d / 50 + np.outer(shift, shift), rtol=1e-7, reason="sums in another order")


def test_simex_extrapolation_is_exact_for_polynomials():
    th0 = np.array([1.0, 2.0])
    lin = lambda lam: th0 + lam * np.array([0.5, -1.0])
    assert_close(simex_extrapolate(th0, np.stack([lin(1.0)]), (1.0,)), lin(-1.0))
    quad = lambda lam: th0 + lam * np.array([0.5, -1.0]) + lam**2 * np.array([0.2, 0.1])
    assert_close(simex_extrapolate(th0, np.stack([quad(1.0), quad(2.0)]), (1.0, 2.0), order=2),
                               quad(-1.0))


def _measured(records, rel_error, seed):
    """Records whose anemometers read the felt wind with a slow relative error (independent per section)."""
    rng = np.random.default_rng(seed)
    out = []
    for r in records:
        t = r.t
        err = np.zeros(r.U.shape)
        for k in range(r.U.shape[1]):  # a few sinusoids of 1-5 min periods: slow, like smoothed turbulence
            for _ in range(4):
                err[:, k] += np.sin(2 * np.pi * t / rng.uniform(60, 300) + rng.uniform(0, 6.3))
        err *= rel_error / np.std(err, axis=0)
        out.append(Record(event_id=r.event_id, t=t, A=r.A, U=r.U * (1.0 + err), yaw=r.yaw))
    return out


START = _true_curves(PARAMS, np.arange(2.5, 13.01, 0.1), scale=(0.9, 1.1, 0.9, 1.1))


@pytest.fixture(scope="module")
def wind_fit():
    """A small fit with wind refits: 2 events, anemometers 1 % off the felt wind."""
    records = _measured(_records(PARAMS, n_events=2, duration=600.0, step=1.0), 0.01, seed=0)
    kw = {"bridge": BRIDGE, "warm_start": START, "n_basis": 6, "n_starts": 1, "penalty": 0.01,
          "penalty_grid": None, "wind_draws": 2, "wind_iter": 1}
    return GreyBoxRefit(**kw).fit(records), records, kw


def test_wind_component_is_seeded_zero_without_error_and_grows_with_it(wind_fit, tmp_path):
    model, records, kw = wind_fit
    covs = model.covariances_
    assert set(covs) >= {"wind", "sandwich_bias_wind"}
    assert_close(covs["wind"], wind_second_moment(model.wind_reference_, model.wind_coef_), rtol=1e-7, reason="the same sums")
    assert_close(covs["sandwich_bias_wind"] - covs["sandwich_bias"], covs["wind"], rtol=1e-7,
                               atol=1e-9 * np.abs(covs["sandwich_bias_wind"]).max(), reason="a difference of sums")
    assert np.trace(covs["wind"]) > 0
    again = GreyBoxRefit(**kw).fit(records)
    np.testing.assert_array_equal(again.covariances_["wind"], covs["wind"])
    zero = GreyBoxRefit(**{**kw, "wind_scale": 0.0}).fit(records)
    np.testing.assert_array_equal(zero.covariances_["wind"], 0.0)
    np.testing.assert_array_equal(zero.covariances_["sandwich_bias_wind"], zero.covariances_["sandwich_bias"])
    half = GreyBoxRefit(**{**kw, "wind_scale": 0.5}).fit(records)
    ratio = np.trace(half.covariances_["wind"]) / np.trace(covs["wind"])
    assert 0.15 < ratio < 0.35, f"half the wind error: second moment ratio {ratio:.3f} (linear response: 0.25)"
    # the file says how much of the band is the wind's error
    model.band = "sandwich_bias_wind"
    model.cov_ = covs["sandwich_bias_wind"]
    back = GreyBoxRefit.load(model.save(tmp_path / "greybox.nc"))
    np.testing.assert_array_equal(back.covariances_["wind"], covs["wind"])
    from vivbench.io.greybox import read_greybox

    ds = read_greybox(tmp_path / "greybox.nc")
    assert list(ds["band_sd_used"].values) == [1, 1, 1]
    sd = ds["band_sd"]
    total = np.sqrt((sd**2).sum("component"))
    half_width = 0.5 * (ds["curves_upper"] - ds["curves_lower"])
    assert_close(half_width.values, model._z() * total.values, rtol=1e-6, atol=1e-15, reason="bands stored from a square root")
    with pytest.raises(InputError, match="wind_draws"):
        GreyBoxRefit(**{**kw, "wind_draws": -1}).fit(records)
    with pytest.raises(InputError, match="wind_draws"):
        GreyBoxRefit(**{**kw, "wind_draws": 0, "band": "sandwich_bias_wind"}).fit(records)


def test_winds_taken_from_an_anemometer_elsewhere_widen_the_wind_component(wind_fit):
    import dataclasses

    model, records, kw = wind_fit
    S = records[0].n_sections
    far = [dataclasses.replace(r, wind_distance=np.full(S, 400.0)) for r in records]
    wider = GreyBoxRefit(**kw).fit(far)
    assert np.trace(wider.covariances_["wind"]) > np.trace(model.covariances_["wind"])
    # the fit itself does not read the distance
    np.testing.assert_array_equal(wider.coef_, model.coef_)


def test_wind_component_has_the_size_of_the_known_wind_errors_effect():
    """Anemometers 1 % off the felt wind: the component against the fit's actual move from the felt-wind fit."""
    felt = _records(PARAMS, n_events=3, duration=1000.0, step=1.0)
    records = _measured(felt, 0.01, seed=0)
    kw = {"bridge": BRIDGE, "warm_start": START, "n_basis": 8, "n_starts": 1, "penalty": 1e-3, "penalty_grid": None}
    clean = GreyBoxRefit(**kw).fit(felt)
    model = GreyBoxRefit(**kw, wind_draws=4).fit(records)
    wind = model.default_wind()
    ur = wind / (BRIDGE.frequency * BRIDGE.depth)
    lock = np.abs(ur - PARAMS["center"]) < 1.5 * PARAMS["width"]
    move = model.curves(wind)["curves"].values[1, 1] - clean.curves(wind)["curves"].values[1, 1]
    sd = model.band_components(wind)["band_sd"].sel(component="wind").values[1, 1]
    ratio = float(np.sqrt(np.mean(sd[lock] ** 2)) / np.sqrt(np.mean(move[lock] ** 2)))
    # measured 0.50 here (0.43 with a 2 % error; 0.31 with 3 x 1500 s and 10 B-splines, 0.43 there with 10
    # iterations a stage; the sandwich's SD is 4.8 times the move): the truncated refits leave it short of the
    # actual move, but of its order; 0 (no component) or a runaway refit fails
    assert 0.15 < ratio < 3.0, f"wind component / actual move of a_k1 = {ratio:.2f}"
