"""Simulation and forecasting with time-varying models (vivbench.models.simulate)."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from tests.helpers import assert_close
from vivbench.models.window import EventWindowSINDy
from vivbench.models.simulate import forecast, forecast_coefficients, forecast_table, nmse, simulate_identified, window_in_force
from vivbench.synth import AeroConfig, StructureConfig, exact_coefficients
from vivbench.core.terms import evaluate_library, feature_exponents, feature_names

FS = 4.0  # Hz, the preprocessed grid
DURATION = 600.0  # s
WINDOW, STEP = 50.0, 25.0
PHI = np.array(StructureConfig().mode_shape)


def _true_coef() -> np.ndarray:
    # an exact coefficient matrix needs the truth in the library: the in_library mode (docs/concepts.md (no inverse crime))
    Xi = exact_coefficients(StructureConfig(), AeroConfig.in_library())
    assert Xi is not None, "the in_library aero configuration must have an exact library representation"
    return Xi


def _wind(t: np.ndarray) -> np.ndarray:
    """Smooth, section-dependent wind through the lock-in range, (n, 3) m/s."""
    t = np.asarray(t, dtype=float)[..., None]
    return 8.0 + 0.8 * np.sin(2 * np.pi * t / 300.0 + np.array([0.0, 0.7, 1.4]))


def _rhs(Xi):
    def f(t, a):
        return (evaluate_library(a[None, :], _wind(np.array([t]))) @ Xi.T)[0]
    return f


def _truth(Xi: np.ndarray, t: np.ndarray, A0: np.ndarray) -> np.ndarray:
    sol = solve_ivp(_rhs(Xi), (t[0], t[-1]), A0, method="DOP853", t_eval=t, rtol=1e-12, atol=1e-14)
    assert sol.success, sol.message
    return sol.y.T


def _windows(t: np.ndarray):
    start = np.arange(t[0], t[-1] - WINDOW + 1e-9, STEP)
    return start, start + WINDOW


def _result(t, A, U, coef, start, end) -> xr.Dataset:
    """A result-like Dataset with the variables forecast.py reads."""
    sections = ["S1", "S2", "S3"]
    return xr.Dataset(
        {
            "coef": (("window", "equation", "feature"), coef),
            "window_start": (("window",), start),
            "window_end": (("window",), end),
            "A": (("time", "section"), A),
            "U": (("time", "section"), U),
            "segment": (("time",), np.zeros(t.size, dtype=np.int32)),
        },
        coords={"window": np.arange(start.size), "equation": sections, "feature": feature_names(3),
                "time": t, "section": sections},
    )


@pytest.fixture(scope="module")
def event():
    t = np.arange(0.0, DURATION + 1e-9, 1.0 / FS)
    Xi = _true_coef()
    A = _truth(Xi, t, 0.02 * PHI)
    start, end = _windows(t)
    coef = np.broadcast_to(Xi, (start.size,) + Xi.shape).copy()
    return {"t": t, "Xi": Xi, "A": A, "U": _wind(t), "start": start, "end": end,
            "result": _result(t, A, _wind(t), coef, start, end)}


def test_truth_is_a_nontrivial_bounded_trajectory(event):
    A = event["A"]
    assert np.all(np.isfinite(A)) and A.min() > 0, "the test trajectory must stay positive"
    assert A.max() > 3 * A[0].max(), f"the test trajectory should grow from {A[0].max():.3g} m; max {A.max():.3g} m"


def test_constant_true_model_reproduces_measurement(event):
    sim = simulate_identified(event["result"])
    assert sim.stopped_at is None and sim.reason is None, sim.reason
    assert sim.covered == 1.0
    assert_close(sim.A_sim, event["A"], rtol=1e-6, atol=0.0,
                 reason="RK4 at 0.25 s plus cubic-spline U at half steps against a 1e-12 reference", what="A_sim")
    assert np.all(sim.nmse < 1e-10), f"NMSE of an exact model should vanish; got {sim.nmse}"


@pytest.mark.parametrize("d", [0.0, 50.0, 150.0, 300.0])
def test_forecast_with_true_model_has_zero_nmse(event, d):
    sim = forecast(event["result"], 200.0, 300.0, d=d)
    assert not sim.stopped, sim.reason
    assert_close(sim.t[[0, -1]], [200.0, 500.0], what="forecast grid")
    assert np.all(sim.nmse < 1e-10), f"d={d}: NMSE {sim.nmse}"
    assert_close(sim.coef, event["Xi"], rtol=1e-12, reason="mean of identical matrices rounds", what="coef")


def test_blow_up_is_stopped_and_reported(event):
    Xi = event["Xi"].copy()
    ex = feature_exponents(3)
    for m in range(3):
        col = int(np.flatnonzero((ex[:, 0] == m) & (ex[:, 1] == 3) & (ex[:, 2] == 0))[0])
        Xi[m, col] += 100.0  # dA/dt ~ 100 A^3: finite-time blow-up in ~25 s from 0.02 m
    coef = np.broadcast_to(Xi, (event["start"].size,) + Xi.shape).copy()
    res = _result(event["t"], event["A"], event["U"], coef, event["start"], event["end"])
    sim = simulate_identified(res)
    assert sim.stopped and sim.stopped_at is not None, "an unbounded model must be stopped"
    assert "exceeded" in sim.reason, sim.reason
    stop = int(np.flatnonzero(sim.t == sim.stopped_at)[0])
    assert 0 < stop < sim.t.size - 1
    assert np.all(np.isnan(sim.A_sim[stop:])), "samples from the stop on must be NaN"
    assert np.all(np.isfinite(sim.A_sim[:stop])), "samples before the stop must be finite"
    assert sim.A_sim[stop - 1].max() <= 10 * np.abs(event["A"]).max()
    assert_close(sim.nmse, nmse(sim.A_sim[:stop], event["A"][:stop]), what="NMSE over the valid part")
    assert np.all(np.isfinite(sim.nmse))
    assert_close(sim.covered, (sim.t[stop - 1] - sim.t[0]) / (sim.t[-1] - sim.t[0]), what="covered")
    assert sim.covered < 0.5, f"the blow-up should come early; covered {sim.covered}"
    rows = forecast_table(res, 100.0, 200.0, ds=(0, 50))
    assert len(rows) == 6 and all(r["stopped"] and r["reason"] for r in rows), rows
    assert all(np.isfinite(r["nmse"]) for r in rows), "stopped runs keep their partial NMSE"


def test_missing_wind_stops_the_run(event):
    U = event["U"].copy()
    U[1000:1010] = np.nan
    res = event["result"].assign(U=(("time", "section"), U))
    sim = simulate_identified(res)
    assert sim.stopped_at == event["t"][1000] and "U is missing" in sim.reason, (sim.stopped_at, sim.reason)
    assert np.all(np.isfinite(sim.A_sim[:1000])) and np.all(np.isnan(sim.A_sim[1000:]))


def test_averaging_picks_the_right_windows(event):
    start, end = event["start"], event["end"]
    base = event["Xi"]
    scale = np.arange(1.0, start.size + 1.0)
    coef = scale[:, None, None] * base
    res = _result(event["t"], event["A"], event["U"], coef, start, end)
    # Centres 25 + 25 w: t0 = 100 s is the centre of window 3; 112.5 s is a tie -> earlier.
    assert_close(window_in_force(res, [0.0, 100.0, 112.5, 113.0, 599.0]), [0, 3, 3, 4, start.size - 1],
                 what="window in force")
    c0, w0 = forecast_coefficients(res, 100.0, 0.0)
    assert list(w0) == [3]
    assert_close(c0, 4.0 * base, what="d = 0")
    for d, expect in [(50.0, [4, 5, 6]), (150.0, [4, 5, 6, 7, 8, 9, 10]), (10.0, [4])]:
        c, w = forecast_coefficients(res, 100.0, d)
        assert list(w) == expect, (d, list(w))
        assert_close(c, scale[expect].mean() * base, rtol=1e-12, reason="mean over windows rounds", what=f"d={d}")
        sim = forecast(res, 100.0, 50.0, d=d)
        assert_close(sim.coef, c, what="forecast uses the averaged coefficients")
        assert list(sim.windows) == expect
    # A window without a model is skipped, both by the nearest-centre rule and by averaging.
    coef_nan = coef.copy()
    coef_nan[3] = np.nan
    res_nan = res.assign(coef=(("window", "equation", "feature"), coef_nan))
    assert int(window_in_force(res_nan, 100.0)) in (2, 4)
    assert list(forecast_coefficients(res_nan, 75.0, 50.0)[1]) == [4, 5]
    with pytest.raises(ValueError, match="no fitted window"):
        forecast_coefficients(res, 1000.0, 50.0)


def test_reidentified_windows_reproduce_the_trajectory(event):
    t, A, U, Xi = event["t"], event["A"], event["U"], event["Xi"]
    dA = evaluate_library(A, U) @ Xi.T  # exact derivative of the true model
    est = EventWindowSINDy(window=WINDOW, step=STEP, keep_path=False).fit(t, A, U, dA)
    res = _result(t, A, U, est.coef_, est.window_start_, est.window_end_)
    sim = simulate_identified(res)
    assert not sim.stopped, sim.reason
    # With exact derivatives every window's model fits dA/dt on the trajectory to
    # rounding (measured NMSE ~1e-18), even though its terms differ from the
    # truth's (ridge, STLSQ, near-collinear sections). 1e-6 leaves room for
    # changes in the engine's selection without letting a wrong model pass.
    assert np.all(sim.nmse < 1e-6), f"NMSE of the re-identified model: {sim.nmse}"


@settings(max_examples=30, deadline=None)
@given(st.integers(min_value=0, max_value=2**32 - 1))
def test_nmse_reference_values(seed):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(20, 3))
    assert_close(nmse(A, A), np.zeros(3), what="perfect match")
    assert_close(nmse(np.broadcast_to(A.mean(axis=0), A.shape), A), np.ones(3), rtol=1e-12,
                 reason="mean predictor, rounding in the sums", what="mean predictor")
    B = A.copy()
    B[:5] = np.nan
    assert_close(nmse(B, A), nmse(A[5:], A[5:]), what="NaNs are left out")


def test_negative_amplitude_is_stopped(event):
    Xi = event["Xi"].copy()
    ex = feature_exponents(3)
    for m in range(3):
        col = int(np.flatnonzero((ex[:, 0] == m) & (ex[:, 1] == 0) & (ex[:, 2] == 1))[0])
        Xi[m, col] -= 1e-3  # dA/dt ~ -8 mm/s: A crosses zero within a few seconds
    coef = np.broadcast_to(Xi, (event["start"].size,) + Xi.shape).copy()
    sim = simulate_identified(_result(event["t"], event["A"], event["U"], coef, event["start"], event["end"]))
    assert sim.stopped and "fell below" in sim.reason, sim.reason
    assert sim.stopped_at < 10.0, f"expected an early stop; got {sim.stopped_at} s"


def test_simulated_sparse_model_is_reidentified():
    """Issue 4: a known sparse model, simulated forward by this module with a varying
    wind, fitted back by the engine on the exact derivative, gives back its coefficients.

    Each section's equation uses its own section's terms only (U, A, A U, A^3),
    so one section's 23-term library holds the model; the engine runs without
    ridge and with a plain least-squares refit (as in tests/regression/test_window_stlsq.py),
    on one window spanning the record so that U and A both vary.
    """
    t = np.arange(0.0, 600.0 + 1e-9, 1.0 / FS)
    U = 8.0 + 1.5 * np.sin(2 * np.pi * t[:, None] / 230.0 + np.array([0.0, 0.9, 1.8]))
    ex = feature_exponents(3)
    Xi = np.zeros((3, 69))
    for k in range(3):
        for (i, j), value in {(0, 1): 1e-4, (1, 0): -0.03, (1, 1): 0.004, (3, 0): -2.0}.items():
            Xi[k, np.flatnonzero((ex[:, 0] == k) & (ex[:, 1] == i) & (ex[:, 2] == j))[0]] = value
    A_meas = np.full((t.size, 3), np.nan)
    A_meas[0] = 0.01
    res = _result(t, A_meas, U, Xi[None].copy(), np.array([0.0]), np.array([t[-1] + 1.0]))
    sim = simulate_identified(res, t0=0.0, t1=t[-1])
    assert not sim.stopped, sim.reason
    A = sim.A_sim
    assert A.max() > 2.0 * A[0].max() and np.ptp(U) > 2.5, "the trajectory must explore A and U"
    dA = evaluate_library(A, U) @ Xi.T  # the exact derivative of the simulated model
    # RK4 at 0.25 s is consistent with it: central differences agree to O(h^2)
    fd = (A[2:] - A[:-2]) / (t[2:] - t[:-2])[:, None]
    assert_close(fd, dA[1:-1], rtol=0, atol=2e-3 * np.abs(dA).max(), reason="central differences, O(h^2)",
                 what="simulated trajectory vs its model")
    for s in range(3):
        est = EventWindowSINDy(window=t[-1] + 0.25, step=t[-1] + 0.25, alpha=0.0, refit_rcond=None, keep_path=False)
        est.fit(t, A[:, s:s + 1], U[:, s:s + 1], dA[:, s:s + 1])
        got = est.coef_[0, 0]
        want = Xi[s, 23 * s:23 * (s + 1)]
        assert np.array_equal(got != 0, want != 0), f"S{s + 1}: support {np.flatnonzero(got)}, not {np.flatnonzero(want)}"
        assert_close(got, want, rtol=1e-6, atol=1e-9 * np.abs(want).max(),
                     reason="least squares in the scaled basis (measured error ~1e-16)", what=f"S{s + 1} coefficients")


@pytest.mark.parametrize("clip", ["u", "au"])
def test_clipping_keeps_exact_models_exact_and_bounds_the_arguments(event, clip):
    """Clipping to the window's own ranges changes nothing while the trajectory stays in them."""
    from vivbench.models.simulate import window_ranges

    a_lo, a_hi, u_lo, u_hi = window_ranges(event["result"])
    t, A, U = event["t"], event["A"], event["U"]
    w = 5
    sel = (t >= event["start"][w]) & (t < event["end"][w])
    assert_close(u_lo[w], U[sel].min(0), what="U range")
    assert_close(a_hi[w], A[sel].max(0), what="A range")
    sim = simulate_identified(event["result"], clip=clip)
    assert not sim.stopped
    # the window in force covers +-12.5 s around its centre, inside its own 50 s range
    assert np.all(sim.nmse < 1e-10), f"clip={clip}: {sim.nmse}"
    with pytest.raises(ValueError, match="clip"):
        simulate_identified(event["result"], clip="bogus")


def test_model_jacobian_matches_finite_differences():
    from vivbench.models.simulate import model_jacobian

    rng = np.random.default_rng(0)
    coef = rng.normal(size=(3, 69))
    A, U = rng.uniform(0.01, 0.1, 3), rng.uniform(7.0, 9.0, 3)
    f = lambda a: (evaluate_library(a[None], U[None]) @ coef.T)[0]
    h = 1e-6
    J = np.stack([(f(A + h * e) - f(A - h * e)) / (2 * h) for e in np.eye(3)], axis=1)
    assert_close(model_jacobian(coef, A, U), J, rtol=1e-7, atol=1e-9 * np.abs(J).max(),
                 reason="central differences", what="Jacobian")
