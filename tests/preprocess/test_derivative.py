"""Tests of vivbench.preprocess.derivative (docs/field_workflow.md: derivative of the envelopes)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.helpers import assert_close, relative_rms
from vivbench.preprocess.vibration import envelope
from vivbench.preprocess.derivative import DERIVATIVE_METHODS, Derivative, estimate_noise_std, tv_derivative

DT = 0.25  # s, a few Hz as in the chain
N = 4800  # 20 min
T = np.arange(N) * DT
INNER = slice(240, N - 240)  # drop 60 s at each end
# The setting for band-limited envelope noise (module docstring of
# vivbench.preprocess.derivative): noise level measured at 10 s, Huber-TV.
BAND_LIMITED = Derivative(time_scale=20.0, huber=10.0, noise_scale=10.0)


def _tanh():
    return 0.1 + 0.05 * np.tanh((T - 600) / 100), 0.05 / 100 / np.cosh((T - 600) / 100) ** 2


def _growth():
    return 0.02 * np.exp(T / 600), 0.02 / 600 * np.exp(T / 600)


def _decay():
    return 0.2 * np.exp(-T / 400), -0.2 / 400 * np.exp(-T / 400)


def _lock_in():
    """Growth into a VIV plateau and decay out of it."""
    s1 = 1 / (1 + np.exp(-(T - 300) / 40))
    s2 = 1 / (1 + np.exp(-(T - 900) / 60))
    a = 0.02 + 0.23 * s1 * (1 - s2)
    da = 0.23 * (s1 * (1 - s1) / 40 * (1 - s2) - s1 * s2 * (1 - s2) / 60)
    return a, da


SMOOTH = {"tanh": _tanh, "growth": _growth, "decay": _decay, "lock_in": _lock_in}


def _noisy(a, seed, level=0.01):
    rng = np.random.default_rng(seed)
    return a + level * np.sqrt(np.mean(a**2)) * rng.standard_normal(a.shape)


# ---------------------------------------------------------------------------
# TV derivative: accuracy


@pytest.mark.parametrize("name", ["tanh", "growth", "decay"])
def test_tv_white_noise_rule_noise_free_signal_matches_analytic(name):
    a, da = SMOOTH[name]()
    dxdt = Derivative(noise_scale=0.0, huber=0.0).differentiate(a, T)
    err = relative_rms(dxdt[INNER], da[INNER])
    # Noise-free: the third differences are at round-off level, so the
    # automatic weight is negligible and what remains is the O(dt^2) central
    # difference.
    assert err < 1e-4, f"{name}: relative RMS error {err:.2e} of the TV derivative of a noise-free signal exceeds 1e-4"


@pytest.mark.parametrize("name", ["tanh", "growth", "decay", "lock_in"])
def test_tv_band_limited_setting_barely_smooths_noise_free_signal(name):
    a, da = SMOOTH[name]()
    err = relative_rms(BAND_LIMITED.differentiate(a, T)[INNER], da[INNER])
    # The noise is measured at 10 s, where a smooth signal's own third
    # differences count as noise, and the Huber part is a fixed smoother with
    # a cut-off near 0.024 Hz; on these envelopes (time scales 40-600 s) the
    # bias stays below 1 %.
    assert err < 0.01, f"{name}: band-limited TV error {err:.2e} on a noise-free signal exceeds 1 %"


@pytest.mark.parametrize("name", list(SMOOTH))
def test_tv_noisy_far_better_than_finite_differences(name):
    a, da = SMOOTH[name]()
    x = _noisy(a, seed=11)
    err_tv = relative_rms(Derivative().differentiate(x, T)[INNER], da[INNER])
    err_fd = relative_rms(Derivative(method="finite_difference").differentiate(x, T)[INNER], da[INNER])
    # Exact TV with default settings staircases a smooth derivative: measured
    # 3-7 % with 1 % noise, where central differences give 1000-2000 %.
    assert err_tv < 0.10, f"{name}: TV relative RMS error {err_tv:.3f} with 1 % noise exceeds 0.10"
    assert err_tv < err_fd / 50, f"{name}: TV error {err_tv:.3f} is not 50x below finite differences' {err_fd:.3f}"


def test_tv_huber_reduces_staircase_on_smooth_signal():
    a, da = _tanh()
    x = _noisy(a, seed=5)
    exact = relative_rms(Derivative(time_scale=10.0, huber=0.0).differentiate(x, T)[INNER], da[INNER])
    smoothed = relative_rms(Derivative(time_scale=40.0, huber=10.0).differentiate(x, T)[INNER], da[INNER])
    assert smoothed < 0.6 * exact, f"Huber-TV error {smoothed:.4f} not clearly below exact TV's {exact:.4f}"


def test_tv_piecewise_linear_gives_piecewise_constant_derivative():
    knots = np.array([0.0, 300.0, 600.0, 900.0, T[-1]])
    slopes = np.array([2e-4, -1e-4, 0.0, 3e-4])  # m/s
    a = 0.1 + np.interp(T, knots, np.concatenate([[0.0], np.cumsum(slopes * np.diff(knots))]))
    x = _noisy(a, seed=3)
    dxdt = Derivative(time_scale=20.0, huber=0.0).differentiate(x, T)
    jumps = np.abs(np.diff(slopes))
    tv_ratio = np.sum(np.abs(np.diff(dxdt))) / np.sum(jumps)
    # A piecewise-constant estimate has the total variation of the truth; any
    # wiggle or noise would add to it (finite differences: ratio ~ 1e4).
    assert tv_ratio < 1.2, f"total variation of the derivative is {tv_ratio:.3f} times the true one"
    for lo, hi, slope in zip(knots[:-1], knots[1:], slopes):
        seg = (T > lo + 30) & (T < hi - 30)
        assert_close(
            dxdt[seg],
            slope,
            atol=0.1 * jumps.min(),
            reason="1 % noise; within 10 % of the smallest slope jump away from the kinks",
            what=f"slope on ({lo}, {hi}) s",
        )


def test_tv_solution_satisfies_optimality_conditions():
    """KKT certificate that the result minimises exact TV (not some other smoother).

    Optimality of 1/2||g - f||^2 + alpha sum|D2 g| / dt: f - g = D' nu with
    D = D2 / dt, |nu| <= alpha, and nu = alpha sign(D g) where D g != 0.
    """
    n = 400
    t = np.arange(n) * DT
    f = 0.1 + 0.05 * np.tanh((t - 50) / 20) + 1e-3 * np.random.default_rng(2).standard_normal(n)
    alpha = 2e-3
    res = tv_derivative(f, DT, alpha=alpha, huber=0.0, tol=1e-10)
    assert res.converged, "solver did not reach tol=1e-10"
    g = res.x_smooth
    # D' nu has D'(affine) = 0 as null space of D: the residual must be
    # orthogonal to constants and to t.
    r = f - g
    assert_close([r.sum(), (r * t).sum() / t.max()], [0.0, 0.0], atol=1e-9, reason="solver round-off", what="affine part")
    dt_matrix = np.zeros((n, n - 2))
    idx = np.arange(n - 2)
    dt_matrix[idx, idx] = 1 / DT
    dt_matrix[idx + 1, idx] = -2 / DT
    dt_matrix[idx + 2, idx] = 1 / DT
    nu = np.linalg.lstsq(dt_matrix, r, rcond=None)[0]
    assert_close(dt_matrix @ nu, r, atol=1e-9, reason="solver round-off", what="f - g = D' nu")
    assert np.all(np.abs(nu) <= alpha * (1 + 1e-6)), f"dual bound violated: max |nu| / alpha = {np.max(np.abs(nu)) / alpha}"
    s = np.diff(g, 2) / DT
    kinks = np.abs(s) > 1e-6 * np.max(np.abs(s))
    assert kinks.sum() >= 2, "expected kinks in a TV solution of a noisy step"
    assert_close(
        nu[kinks], alpha * np.sign(s[kinks]), rtol=1e-4, reason="interior-point tolerance", what="nu at kinks"
    )
    assert kinks.sum() < (n - 2) / 4, f"{kinks.sum()} kinks out of {n - 2}: not a sparse (piecewise-linear) fit"


def test_tv_columns_are_independent():
    cols = [SMOOTH[name]()[0] for name in ("tanh", "growth", "lock_in")]
    x = np.stack([_noisy(c, seed=i) for i, c in enumerate(cols)], axis=1)
    together = Derivative().differentiate(x, T)
    for j in range(3):
        alone = Derivative().differentiate(x[:, j], T)
        assert_close(together[:, j], alone, rtol=1e-9, atol=1e-12 * np.max(np.abs(alone)), reason="stacked solve round-off", what=f"column {j}")


def test_noise_std_estimate():
    a, _ = _lock_in()
    sigma = np.array([1e-3, 2.5e-3])
    x = np.stack([a, 0.707 * a], axis=1) + sigma * np.random.default_rng(4).standard_normal((N, 2))
    assert_close(estimate_noise_std(x), sigma, rtol=0.05, reason="MAD of 4800 correlated third differences: ~2 % standard error")


def test_tv_automatic_alpha_follows_documented_rule():
    a, _ = _tanh()
    x = _noisy(a, seed=8)
    res = tv_derivative(x, DT, time_scale=15.0, noise_scale=7.5)
    # noise_scale 7.5 s is 30 samples.
    # The rule runs on the normalised column: the block means' cumulative sums
    # round differently than on x.
    assert_close(res.alpha, estimate_noise_std(x, 30) * DT * (15.0 / DT) ** 1.5, rtol=1e-9, reason="cumulative-sum round-off")
    white = tv_derivative(x, DT, time_scale=15.0)  # default noise_scale 0: plain third differences
    assert_close(white.alpha, estimate_noise_std(x) * DT * (15.0 / DT) ** 1.5, rtol=1e-12, reason="float round-off")


@pytest.mark.parametrize("lag", [1, 8, 40])
def test_noise_std_estimate_is_unbiased_for_white_noise_at_any_lag(lag):
    sigma = 1e-3
    x = sigma * np.random.default_rng(6).standard_normal((N, 4))
    # 4800 samples: the MAD of overlapping lag-L differences has a standard
    # error of about 2 % at L = 1 and 8 % at L = 40 (fewer independent blocks);
    # averaged over 4 columns.
    assert_close(np.mean(estimate_noise_std(x, lag)), sigma, rtol=0.08, reason="MAD of 4 x 4800 samples", what=f"lag {lag}")


def test_noise_std_estimate_of_correlated_noise_is_its_white_equivalent():
    # Noise averaged over 20 samples (a moving mean) has variance s^2 / 20 but
    # the low-frequency density of white noise of std s: the estimate at a lag
    # much longer than 20 samples must return s, the plain third differences a
    # small fraction of it.
    s = 1e-3
    w = s * np.random.default_rng(0).standard_normal((N + 19, 8))
    x = np.stack([np.convolve(w[:, k], np.ones(20) / 20, mode="valid") for k in range(8)], axis=1)
    assert_close(
        np.mean(estimate_noise_std(x, 100)), s, rtol=0.15,
        reason="mean of 8 columns; one column's estimate has a 14 % standard deviation at lag 100 (measured, 40 seeds)",
    )
    assert np.mean(estimate_noise_std(x)) < 0.1 * s, "third differences should see almost none of the low-passed noise"


def test_tv_band_limited_setting_on_envelope_with_band_limited_noise():
    """The chain's case: Hilbert envelope of a mode plus noise in the vibration band.

    Displacement noise inside f_mode +- 30 % (f_mode = 0.327 Hz) leaves in the
    envelope a fluctuation correlated over seconds, invisible to third
    differences at 4 Hz. Measured (3 seeds): finite differences and the
    default (white-noise rule) 0.9-1.1, the band-limited setting 0.11-0.13.
    """
    a, da = _lock_in()
    f_mode, half = 0.327, 0.3 * 0.327
    rng = np.random.default_rng(0)
    spectrum = np.fft.rfft(rng.standard_normal(N))
    spectrum[np.abs(np.fft.rfftfreq(N, DT) - f_mode) > half] = 0.0
    noise = np.fft.irfft(spectrum, N)
    noise *= 0.01 * np.sqrt(np.mean(a**2)) / noise.std()
    A = envelope(a * np.cos(2 * np.pi * f_mode * T) + noise)
    err = relative_rms(BAND_LIMITED.differentiate(A, T)[INNER], da[INNER])
    err_fd = relative_rms(Derivative(method="finite_difference").differentiate(A, T)[INNER], da[INNER])
    err_white = relative_rms(Derivative().differentiate(A, T)[INNER], da[INNER])
    # The noise matters (finite differences are off by more than the signal),
    # the default white-noise rule does not remove it, the band-limited
    # setting does.
    assert err_fd > 0.5, f"finite-difference error {err_fd:.3f}: the test's noise is too weak to discriminate"
    assert err_white > 0.5 * err_fd, f"white-noise rule error {err_white:.3f} vs finite differences {err_fd:.3f}"
    assert err < 0.2, f"band-limited TV error {err:.3f} on a band-limited-noise envelope exceeds 0.2 (finite differences {err_fd:.3f})"


# ---------------------------------------------------------------------------
# Properties


@settings(max_examples=15, deadline=None)
@given(
    c=st.floats(min_value=1e-3, max_value=1e3),
    shift=st.floats(min_value=-1e5, max_value=1e5),
    seed=st.integers(min_value=0, max_value=2**16),
)
def test_tv_scale_and_time_shift_equivariance(c, shift, seed):
    n = 600
    t = np.arange(n) * DT
    a = 0.1 + 0.05 * np.tanh((t - 75) / 20)
    x = a + 1e-3 * np.random.default_rng(seed).standard_normal(n)
    for d in (Derivative(), BAND_LIMITED):
        base = d.differentiate(x, t)
        # The automatic weight and the Huber threshold scale with the noise
        # estimate, hence with x, whatever the block length of the estimate.
        scaled = d.differentiate(c * x, t + shift)
        assert_close(scaled, c * base, rtol=1e-6, atol=1e-6 * c * np.max(np.abs(base)), reason="solver tolerance",
                     what=f"c x, t + shift ({d})")


@settings(max_examples=10, deadline=None)
@given(c=st.floats(min_value=1e-2, max_value=1e2), seed=st.integers(min_value=0, max_value=2**16))
def test_tv_explicit_alpha_scales_with_signal(c, seed):
    n = 600
    t = np.arange(n) * DT
    x = 0.02 * np.exp(t / 100) + 1e-3 * np.random.default_rng(seed).standard_normal(n)
    base = Derivative(alpha=5e-3).differentiate(x, t)
    # With an explicit weight the caller scales it: alpha has units of x times s.
    scaled = Derivative(alpha=5e-3 * c).differentiate(c * x, t)
    assert_close(scaled, c * base, rtol=1e-6, atol=1e-6 * c * np.max(np.abs(base)), reason="solver tolerance")


@pytest.mark.parametrize("method", DERIVATIVE_METHODS)
def test_constant_signal_has_zero_derivative(method):
    x = np.full((200, 3), 0.137)
    dxdt = Derivative(method=method).differentiate(x, np.arange(200) * DT)
    assert_close(dxdt, 0.0, atol=1e-12, reason="round-off of filters on a constant", what=method)


@pytest.mark.parametrize("method", DERIVATIVE_METHODS)
@pytest.mark.parametrize("shape", [(300,), (300, 1), (300, 3)])
def test_all_methods_return_input_shape(method, shape):
    rng = np.random.default_rng(0)
    t = np.arange(shape[0]) * DT
    base = 0.1 + 0.05 * np.sin(t / 20)
    x = (base if len(shape) == 1 else np.repeat(base[:, None], shape[1], axis=1)) + 1e-3 * rng.standard_normal(shape)
    d = Derivative(method=method)
    smooth, dxdt = d.smooth_and_differentiate(x, t)
    assert dxdt.shape == shape and smooth.shape == shape, f"{method}: shapes {smooth.shape}, {dxdt.shape} for input {shape}"
    assert np.all(np.isfinite(dxdt)), f"{method}: non-finite derivative"
    assert_close(d.differentiate(x, DT), dxdt, rtol=1e-12, reason="step vs times", what=f"{method}: t as a step")


@pytest.mark.parametrize("method", ["savgol", "spline"])
def test_smoothing_methods_beat_finite_differences(method):
    a, da = _tanh()
    x = _noisy(a, seed=9)
    err = relative_rms(Derivative(method=method).differentiate(x, T)[INNER], da[INNER])
    err_fd = relative_rms(Derivative(method="finite_difference").differentiate(x, T)[INNER], da[INNER])
    assert err < err_fd / 5, f"{method}: error {err:.3f} not 5x below finite differences' {err_fd:.3f}"


def test_finite_difference_is_second_order_on_smooth_signal():
    a, da = _tanh()
    err = relative_rms(Derivative(method="finite_difference").differentiate(a, T)[INNER], da[INNER])
    assert err < 1e-4, f"central differences on a noise-free tanh: relative error {err:.2e}"


# ---------------------------------------------------------------------------
# Input validation


@pytest.mark.parametrize("method", DERIVATIVE_METHODS)
def test_nan_is_refused_with_clear_message(method):
    x = np.ones((100, 3))
    x[40, 1] = np.nan
    with pytest.raises(ValueError, match="split the record at gaps"):
        Derivative(method=method).differentiate(x, DT)


@pytest.mark.parametrize("method", ["tv", "savgol"])
def test_uniform_grid_required(method):
    t = np.cumsum(np.r_[0.0, np.full(99, DT)])
    t[50:] += 0.1
    with pytest.raises(ValueError, match="uniform time grid"):
        Derivative(method=method).differentiate(np.ones(100), t)


@pytest.mark.parametrize("method", ["spline", "finite_difference"])
def test_nonuniform_grid_accepted_where_supported(method):
    t = np.cumsum(np.r_[0.0, np.random.default_rng(1).uniform(0.2, 0.3, 299)])
    dxdt = Derivative(method=method).differentiate(0.5 * t + 1.0, t)
    assert_close(dxdt, 0.5, rtol=1e-6, reason="spline fit of a line on an irregular grid", what=method)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"method": "fourier"}, "method must be one of"),
        ({"method": "savgol", "alpha": 1.0}, "applies only to method='tv'"),
        ({"window": 10.0}, "applies only to method='savgol'"),
        ({"alpha": -1.0}, "alpha must be a finite number > 0"),
        ({"time_scale": 0.0}, "time_scale must be a finite number > 0"),
        ({"huber": -0.1}, "huber must be a finite number >= 0"),
        ({"noise_scale": -1.0}, "noise_scale must be a finite number >= 0"),
        ({"method": "savgol", "noise_scale": 5.0}, "applies only to method='tv'"),
        ({"tol": 2.0}, "tol must lie strictly between 0 and 1"),
        ({"max_iter": 0}, "max_iter must be a positive integer"),
        ({"method": "savgol", "polyorder": 2.5}, "polyorder must be a positive integer"),
        ({"method": "spline", "smoothing": -1.0}, "smoothing must be a finite number >= 0"),
    ],
)
def test_config_validation(kwargs, message):
    with pytest.raises(ValueError, match=message):
        Derivative(**kwargs)


def test_bad_shapes_and_times_refused():
    d = Derivative()
    with pytest.raises(ValueError, match=r"shape \(n,\) or \(n, k\)"):
        d.differentiate(np.ones((10, 2, 2)), DT)
    with pytest.raises(ValueError, match="to match x"):
        d.differentiate(np.ones(10), np.arange(9.0))
    with pytest.raises(ValueError, match="strictly increasing"):
        d.differentiate(np.ones(10), np.r_[np.arange(5.0), np.arange(5.0)])
    with pytest.raises(ValueError, match="window"):
        Derivative(method="savgol", window=100.0).differentiate(np.ones(50), DT)


def test_for_envelope_is_the_band_limited_setting_with_overrides():
    assert Derivative.for_envelope() == BAND_LIMITED
    assert Derivative.for_envelope(time_scale=40.0) == Derivative(time_scale=40.0, huber=10.0, noise_scale=10.0)
    assert Derivative.for_envelope("savgol") == Derivative(method="savgol")
