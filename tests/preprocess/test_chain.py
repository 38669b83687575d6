"""Tests of the preprocessing chain (vivbench.preprocess.chain) on signals built here."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import signal

from tests.helpers import assert_close, relative_rms
from vivbench.preprocess.config import PreprocessConfig
from vivbench.preprocess.runs import common_grid, segments, to_grid
from vivbench.preprocess.vibration import displacement, envelope, modal_frequency
from vivbench.preprocess.wind import mean_wind, perpendicular_speed, wind_speed_direction
from vivbench.preprocess.chain import preprocess_arrays

FS_WIND = 32.0
FS_ACC = 50.0
F_MODE = 0.327


def _wind_components(speed, from_deg):
    """East and north components of a wind of ``speed`` blowing FROM ``from_deg``."""
    rad = np.radians(from_deg)
    return -speed * np.sin(rad), -speed * np.cos(rad)


def _ar1(rng, n, fs, sigma, time_scale):
    """Turbulence-like noise: AR(1) with std ``sigma`` and integral time scale ``time_scale``."""
    a = np.exp(-1.0 / (fs * time_scale))
    return signal.lfilter([1.0], [1.0, -a], rng.standard_normal(n) * sigma * np.sqrt(1.0 - a * a))


def _growth_plateau(t, q0=0.02, q1=0.2, t_mid=600.0, tau=200.0):
    """Amplitude Q(t) growing from q0 to a plateau q1, with its first two derivatives (m, m/s, m/s^2)."""
    th = np.tanh((t - t_mid) / tau)
    half = 0.5 * (q1 - q0)
    Q = q0 + half * (th + 1.0)
    dQ = half * (1.0 - th**2) / tau
    ddQ = -2.0 * half * th * (1.0 - th**2) / tau**2
    return Q, dQ, ddQ


def _vibration(t, f, phase=0.3, **amp):
    """Displacement Q cos(w t + phase) and its exact second derivative."""
    Q, dQ, ddQ = _growth_plateau(t, **amp)
    w = 2.0 * np.pi * f
    c, s = np.cos(w * t + phase), np.sin(w * t + phase)
    return Q, Q * c, ddQ * c - 2.0 * w * dQ * s - w * w * Q * c


def _steady_wind(duration, speed=8.0, from_deg=90.0, n_sections=3):
    t = np.arange(int(duration * FS_WIND)) / FS_WIND
    u, v = _wind_components(speed, from_deg)
    return t, np.full((t.size, n_sections), u), np.full((t.size, n_sections), v)


# ----------------------------------------------------------------------------- wind


@pytest.mark.parametrize(
    ("u", "v", "theta"),
    [(0.0, -5.0, 0.0), (-5.0, 0.0, 90.0), (0.0, 5.0, 180.0), (5.0, 0.0, 270.0), (-3.0, -3.0, 45.0)],
)
def test_direction_is_meteorological(u, v, theta):
    """Wind from the north blows south (v < 0) and has theta = 0; from the east, 90; and so on."""
    V, th = wind_speed_direction(u, v)
    assert_close(V, np.hypot(u, v), what="speed")
    assert_close(th, theta, atol=1e-12, reason="degrees from arctan2 round-off", what="direction")


@settings(max_examples=60, deadline=None, derandomize=True)
@given(
    speed=st.floats(0.1, 40.0),
    from_deg=st.floats(0.0, 359.999),
    azimuth=st.floats(-360.0, 360.0),
)
def test_speed_direction_and_perpendicular_component_exact(speed, from_deg, azimuth):
    u, v = _wind_components(speed, from_deg)
    V, theta = wind_speed_direction(u, v)
    assert_close(V, speed, rtol=1e-12, reason="trigonometric round-off", what="speed")
    wrapped = (theta - from_deg + 180.0) % 360.0 - 180.0
    assert abs(wrapped) < 1e-9, f"direction {theta} differs from {from_deg}"
    assert 0.0 <= theta < 360.0, f"direction {theta} outside [0, 360)"
    # Independent geometry: |projection of (u, v) on the unit normal of the span|,
    # the span's unit vector being (sin az, cos az) in (east, north).
    az = np.radians(azimuth)
    expected = abs(u * np.cos(az) - v * np.sin(az))
    U_tilde = perpendicular_speed(V, theta, azimuth)
    assert_close(U_tilde, expected, atol=1e-9 * speed, reason="trigonometric round-off", what="U~")
    assert_close(perpendicular_speed(V, theta, azimuth + 180.0), U_tilde, atol=1e-9 * speed,
                 reason="trigonometric round-off", what="azimuth + 180 is the same span")


def test_perpendicular_speed_limits():
    assert_close(perpendicular_speed(7.0, 120.0, 30.0), 7.0, rtol=1e-15, reason="sin(90 deg) round-off",
                 what="across the span")
    assert_close(perpendicular_speed(7.0, 210.0, 30.0), 0.0, atol=1e-14, reason="sin(180 deg) round-off",
                 what="along the span")


def test_mean_wind_follows_a_slow_wind_at_an_angle():
    """Noise-free: U = U(t) |sin(theta - azimuth)| for a slow U(t) at 50 degrees to the span."""
    t = np.arange(int(2400 * FS_WIND)) / FS_WIND
    speed = 8.0 + 1.5 * np.sin(2 * np.pi * t / 1800.0) + 0.5 * np.cos(2 * np.pi * t / 900.0)
    azimuth, from_deg = 30.0, 80.0
    u, v = _wind_components(speed, from_deg)
    U = mean_wind(t, u, v, azimuth)
    inner = (t >= 60.0) & (t <= t[-1] - 60.0)
    assert U.shape == t.shape
    assert_close(U[inner], speed[inner] * np.sin(np.radians(50.0)), rtol=1e-3,
                 reason="the 1/60 Hz low-pass slightly smooths a 15-30 min signal", what="mean wind")


def test_mean_wind_removes_turbulence():
    """U(t) + along-wind turbulence (10 % intensity) + along-span gusts: U recovered to the low-frequency residue."""
    rng = np.random.default_rng(11)
    t = np.arange(int(2400 * FS_WIND)) / FS_WIND
    slow = 8.0 + 1.5 * np.sin(2 * np.pi * t / 1800.0)
    sigma, time_scale = 0.8, 1.5
    along = _ar1(rng, t.size, FS_WIND, sigma, time_scale)
    across = _ar1(rng, t.size, FS_WIND, sigma, time_scale)
    azimuth, from_deg = 30.0, 120.0  # wind perpendicular to the span
    u, v = _wind_components(slow + along, from_deg)
    u = u + across * np.sin(np.radians(azimuth))
    v = v + across * np.cos(np.radians(azimuth))
    config = PreprocessConfig()
    U = mean_wind(t, np.column_stack([u, u]), np.column_stack([v, v]), azimuth, config)
    inner = (t >= 60.0) & (t <= t[-1] - 60.0)
    err = np.sqrt(np.mean((U[inner, 0] - slow[inner]) ** 2))
    # The across-span gusts do not enter U~; the along-wind turbulence below the
    # cut-off stays (an AR(1) has the fraction (2/pi) atan(2 pi fc T) of its
    # variance below fc, for a brick-wall filter).
    expected = sigma * np.sqrt(2.0 / np.pi * np.arctan(2.0 * np.pi * config.wind_cutoff_hz * time_scale))
    assert err < 1.5 * expected, f"mean-wind RMS error {err:.3f} m/s exceeds 1.5 x the predicted {expected:.3f} m/s"
    assert err < 0.5 * sigma, f"mean-wind RMS error {err:.3f} m/s: the low-pass removed too little of sigma = {sigma}"
    assert_close(U[:, 1], U[:, 0], what="sections are filtered alike")


def test_mean_wind_leaves_gaps_empty():
    t, u, v = _steady_wind(600.0, n_sections=1)
    u[4000:4100] = np.nan
    U = mean_wind(t, u, v, 0.0)
    assert np.all(np.isnan(U[4000:4100])), "the gap must stay NaN"
    assert np.all(np.isfinite(U[:4000])) and np.all(np.isfinite(U[4100:])), "valid runs must be filtered"
    assert_close(U[:4000], 8.0, rtol=1e-9, what="constant wind before the gap")


# ------------------------------------------------------------------------ vibration


def test_modal_frequency_displacement_and_envelope():
    """50 Hz acceleration of Q(t) cos(2 pi f t) (growth then plateau) plus white noise."""
    rng = np.random.default_rng(5)
    t = np.arange(int(1800 * FS_ACC)) / FS_ACC
    Q, y, acc = _vibration(t, F_MODE)
    acc = acc + 0.05 * rng.standard_normal(t.size)
    f = modal_frequency(FS_ACC, acc, (0.05, 2.0))
    assert abs(f / F_MODE - 1.0) < 0.005, f"modal frequency {f:.5f} Hz is more than 0.5 % from {F_MODE} Hz"
    y_hat = displacement(acc, FS_ACC, f, 0.3 * f)
    A = envelope(y_hat)
    inner = (t >= 60.0) & (t <= t[-1] - 60.0)
    err_y = relative_rms(y_hat[inner], y[inner])
    err_A = relative_rms(A[inner], Q[inner])
    assert err_y < 0.02, f"displacement relative RMS error {err_y:.4f} over 2 %"
    assert err_A < 0.02, f"envelope relative RMS error {err_A:.4f} over 2 %"


def test_envelope_of_a_clean_oscillation_is_exact_away_from_the_ends():
    t = np.arange(int(900 * FS_ACC)) / FS_ACC
    Q, y, acc = _vibration(t, F_MODE, t_mid=400.0, tau=100.0)
    A = envelope(displacement(np.column_stack([acc, 2 * acc]), FS_ACC, F_MODE, 0.1))
    inner = (t >= 60.0) & (t <= t[-1] - 60.0)
    assert_close(A[inner, 0], Q[inner], rtol=2e-3, reason="the band filter's end ringing, 0.17 % 60 s from an end",
                 what="envelope")
    assert_close(A[:, 1], 2 * A[:, 0], rtol=1e-9, what="sections are processed alike")


@pytest.mark.parametrize("f_true", [0.2, 1.1])
def test_other_modes_are_found_when_not_given(f_true):
    rng = np.random.default_rng(int(f_true * 100))
    duration = 1200.0
    t_acc = np.arange(int(duration * FS_ACC)) / FS_ACC
    Q, _, acc = _vibration(t_acc, f_true, t_mid=300.0, tau=100.0, q0=0.02, q1=0.1)
    acc = np.column_stack([acc, 0.7 * acc, acc]) + 0.01 * rng.standard_normal((t_acc.size, 3))
    t_w, u, v = _steady_wind(duration)
    out = preprocess_arrays(wind_time=t_w, u=u, v=v, accel_time=t_acc, acc=acc, span_azimuth_deg=0.0)
    assert out.f_mode_source == "spectrum"
    assert abs(out.f_mode_hz / f_true - 1.0) < 0.005, f"found {out.f_mode_hz:.5f} Hz for a mode at {f_true} Hz"
    assert out.band_hz[0] < f_true < out.band_hz[1]
    expected = to_grid(t_acc, Q, out.t)
    err = relative_rms(out.A[:, 1], 0.7 * expected)
    assert err < 0.02, f"envelope relative RMS error {err:.4f} over 2 % for the mode at {f_true} Hz"


def test_given_modal_frequency_is_used():
    t_acc = np.arange(int(600 * FS_ACC)) / FS_ACC
    _, _, acc = _vibration(t_acc, F_MODE)
    t_w, u, v = _steady_wind(600.0, n_sections=1)
    out = preprocess_arrays(wind_time=t_w, u=u, v=v, accel_time=t_acc, acc=acc, span_azimuth_deg=0.0,
                            config=PreprocessConfig(modal_frequency_hz=0.33))
    assert out.f_mode_source == "given"
    assert out.f_mode_hz == 0.33
    assert_close(out.band_hz, (0.33 * 0.7, 0.33 * 1.3), rtol=1e-12, reason="float products", what="band")


def test_modal_frequency_refuses_a_peak_on_the_band_edge():
    t = np.arange(int(600 * FS_ACC)) / FS_ACC
    with pytest.raises(ValueError, match="no peak strictly inside"):
        modal_frequency(t, np.sin(2 * np.pi * 3.0 * t), (0.05, 2.0))


def test_displacement_refuses_gaps():
    acc = np.zeros(1000)
    acc[10] = np.nan
    with pytest.raises(ValueError, match="finite"):
        displacement(acc, FS_ACC, F_MODE, 0.1)


# ---------------------------------------------------------------- the whole chain


def _event(duration=1800.0, seed=3):
    rng = np.random.default_rng(seed)
    t_acc = np.arange(int(duration * FS_ACC)) / FS_ACC
    Q, _, acc = _vibration(t_acc, F_MODE)
    phi = np.array([0.707, 1.0, 0.707])
    acc = acc[:, None] * phi + 0.02 * rng.standard_normal((t_acc.size, 3))
    t_w = np.arange(int(duration * FS_WIND)) / FS_WIND
    slow = 8.0 + np.sin(2 * np.pi * t_w / 1800.0)
    u, v = _wind_components(slow, 90.0)
    return t_acc, acc, Q, phi, t_w, np.tile(u[:, None], 3), np.tile(v[:, None], 3), slow


def _check_against_truth(out, t_acc, Q, phi, t_w, slow):
    err_A = relative_rms(out.A, to_grid(t_acc, Q, out.t)[:, None] * phi)
    assert err_A < 0.02, f"envelope relative RMS error {err_A:.4f} over 2 %"
    err_U = relative_rms(out.U, np.tile(to_grid(t_w, slow, out.t)[:, None], 3))
    assert err_U < 1e-3, f"mean-wind relative RMS error {err_U:.2e} over 0.1 %"


def test_clean_event_gives_one_segment_on_the_grid():
    t_acc, acc, Q, phi, t_w, u, v, slow = _event()
    out = preprocess_arrays(wind_time=t_w, u=u, v=v, accel_time=t_acc, acc=acc, span_azimuth_deg=0.0)
    assert out.n_segments == 1 and np.all(out.segment == 0)
    assert out.A.shape == out.U.shape == (out.t.size, 3)
    assert_close(np.diff(out.t), 0.25, rtol=1e-12, reason="float multiples of the step", what="grid step")
    assert out.t[0] >= out.edge_s and out.t[-1] <= t_acc[-1] - out.edge_s, "edges must be dropped"
    assert out.t[0] - out.edge_s < 0.25 and t_acc[-1] - out.edge_s - out.t[-1] < 0.25, "no more than the edges lost"
    _check_against_truth(out, t_acc, Q, phi, t_w, slow)


def test_nan_block_splits_the_record():
    t_acc, acc, Q, phi, t_w, u, v, slow = _event()
    gap = (t_acc >= 900.0) & (t_acc < 960.0)
    acc[gap, 1] = np.nan  # one section's dropout invalidates the time for all
    out = preprocess_arrays(wind_time=t_w, u=u, v=v, accel_time=t_acc, acc=acc, span_azimuth_deg=0.0)
    assert out.n_segments == 2
    assert_close(np.unique(out.segment), [0, 1], what="segment ids")
    last_before, first_after = t_acc[~gap & (t_acc < 900.0)][-1], t_acc[~gap & (t_acc > 900.0)][0]
    near = (out.t > last_before - out.edge_s) & (out.t < first_after + out.edge_s)
    assert not np.any(near), f"{near.sum()} output samples inside the gap or within {out.edge_s} s of it"
    assert np.all(out.t[out.segment == 0] < 900.0) and np.all(out.t[out.segment == 1] > 960.0)
    assert np.all(np.isfinite(out.A)) and np.all(np.isfinite(out.U)), "no NaN may reach the output"
    _check_against_truth(out, t_acc, Q, phi, t_w, slow)


def test_gaps_in_both_streams_and_short_segments():
    t_acc, acc, Q, phi, t_w, u, v, slow = _event()
    acc[(t_acc >= 900.0) & (t_acc < 960.0)] = np.nan
    u[(t_w >= 1400.0) & (t_w < 1410.0), 2] = np.nan
    out = preprocess_arrays(wind_time=t_w, u=u, v=v, accel_time=t_acc, acc=acc, span_azimuth_deg=0.0)
    assert out.n_segments == 3
    bounds = out.segment_bounds
    assert_close(bounds[:, 0], [out.edge_s, 960.0 + out.edge_s, 1410.0 + out.edge_s], atol=1 / FS_WIND,
                 reason="runs start on a sample", what="segment starts")
    _check_against_truth(out, t_acc, Q, phi, t_w, slow)
    # A segment shorter than min_segment_s is dropped (here the last, the shortest).
    lengths = bounds[:, 1] - bounds[:, 0]
    assert np.argmin(lengths) == 2
    longer = PreprocessConfig(min_segment_s=lengths[2] + 1.0)
    out2 = preprocess_arrays(wind_time=t_w, u=u, v=v, accel_time=t_acc, acc=acc, span_azimuth_deg=0.0,
                             config=longer)
    assert out2.n_segments == 2 and not np.any(out2.t > 1400.0), "the short last segment must be dropped"


def test_short_dropouts_are_bridged_only_when_allowed():
    t_acc, acc, Q, phi, t_w, u, v, slow = _event(duration=900.0)
    acc[20000:20003] = np.nan  # three samples, 0.06 s
    kwargs = dict(wind_time=t_w, u=u, v=v, accel_time=t_acc, span_azimuth_deg=0.0)
    assert preprocess_arrays(acc=acc, **kwargs).n_segments == 2
    bridged = preprocess_arrays(acc=acc, config=PreprocessConfig(max_gap_s=0.1), **kwargs)
    assert bridged.n_segments == 1
    err = relative_rms(bridged.A, to_grid(t_acc, Q, bridged.t)[:, None] * phi)
    assert err < 0.02, f"envelope relative RMS error {err:.4f} over 2 % across a bridged dropout"


def test_missing_time_stamps_split_the_record():
    t_acc, acc, Q, phi, t_w, u, v, slow = _event(duration=900.0)
    keep = (t_w < 400.0) | (t_w >= 410.0)  # samples missing without NaN
    out = preprocess_arrays(wind_time=t_w[keep], u=u[keep], v=v[keep], accel_time=t_acc, acc=acc,
                            span_azimuth_deg=0.0, config=PreprocessConfig(max_gap_s=60.0))
    assert out.n_segments == 2, "a jump in the time stamps is a gap that is never bridged"


def test_no_segment_long_enough_gives_an_empty_result():
    t_acc, acc, Q, phi, t_w, u, v, slow = _event(duration=900.0)
    acc[::1000] = np.nan
    out = preprocess_arrays(wind_time=t_w, u=u, v=v, accel_time=t_acc, acc=acc, span_azimuth_deg=0.0,
                            config=PreprocessConfig(modal_frequency_hz=F_MODE))
    assert out.n_segments == 0 and out.t.size == 0 and out.A.shape == (0, 3)


# ------------------------------------------------------------------ grid helpers


def _segments_reference(mask, min_length):
    ids = np.full(mask.size, -1)
    k, i = 0, 0
    while i < mask.size:
        if mask[i]:
            j = i
            while j < mask.size and mask[j]:
                j += 1
            if j - i >= min_length:
                ids[i:j] = k
                k += 1
            i = j
        else:
            i += 1
    return ids


@settings(max_examples=80, deadline=None, derandomize=True)
@given(mask=st.lists(st.booleans(), min_size=0, max_size=60), min_length=st.integers(1, 6))
def test_segments_match_a_reference(mask, min_length):
    mask = np.array(mask, dtype=bool)
    np.testing.assert_array_equal(segments(mask, min_length), _segments_reference(mask, min_length))


def test_common_grid_uses_multiples_of_the_step():
    t, seg = common_grid([[0.1, 1.0], [1.3, 1.4], [2.0, 2.6]], 0.25)
    assert_close(t, [0.25, 0.5, 0.75, 1.0, 2.0, 2.25, 2.5], what="grid times")
    np.testing.assert_array_equal(seg, [0, 0, 0, 0, 1, 1, 1])
    with pytest.raises(ValueError, match="disjoint"):
        common_grid([[0.0, 2.0], [1.0, 3.0]], 0.25)


@settings(max_examples=40, deadline=None, derandomize=True)
@given(slope=st.floats(-5, 5), offset=st.floats(-5, 5), jitter_seed=st.integers(0, 2**16))
def test_to_grid_is_exact_on_linear_signals(slope, offset, jitter_seed):
    rng = np.random.default_rng(jitter_seed)
    t_src = np.cumsum(rng.uniform(0.01, 0.05, 200))
    x = np.column_stack([slope * t_src + offset, -slope * t_src])
    t_grid = np.linspace(t_src[0] - 0.1, t_src[-1] + 0.1, 77)
    out = to_grid(t_src, x, t_grid)
    inside = (t_grid >= t_src[0]) & (t_grid <= t_src[-1])
    assert np.all(np.isnan(out[~inside])), "values outside the source span must be NaN"
    assert_close(out[inside, 0], slope * t_grid[inside] + offset, atol=1e-12, reason="float interpolation",
                 what="linear signal")
    assert_close(out[inside, 1], -slope * t_grid[inside], atol=1e-12, reason="float interpolation",
                 what="second column")


# ------------------------------------------------------------------- configuration


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        (dict(wind_cutoff_hz=0.0), "wind_cutoff_hz"),
        (dict(wind_filter_order=0), "wind_filter_order"),
        (dict(band_half_width=1.2), "band_half_width"),
        (dict(band_half_width_hz=-0.1), "band_half_width_hz"),
        (dict(band_taper=0.0), "band_taper"),
        (dict(modal_frequency_hz=float("nan")), "modal_frequency_hz"),
        (dict(search_band_hz=(2.0, 0.05)), "search_band_hz"),
        (dict(grid_step_s=0.0), "grid_step_s"),
        (dict(max_gap_s=-1.0), "max_gap_s"),
        (dict(edge_s=-5.0), "edge_s"),
        (dict(min_segment_s=0.0), "min_segment_s"),
    ],
)
def test_config_validation(kwargs, message):
    with pytest.raises(ValueError, match=message):
        PreprocessConfig(**kwargs)


def test_edge_covers_the_filters():
    config = PreprocessConfig(edge_s=5.0)
    assert config.settling_s(F_MODE) >= 3.0 / (2.0 * np.pi * config.wind_cutoff_hz)
    assert config.settling_s(0.05) > PreprocessConfig().edge_s, "a slow mode's narrow band needs a longer edge"
    assert PreprocessConfig().settling_s(F_MODE) == 60.0


@given(mask=st.lists(st.booleans(), max_size=60))
@settings(max_examples=80, deadline=None)
def test_mask_runs_are_the_maximal_runs_of_true(mask):
    from vivbench.preprocess import mask_runs

    expected, start = [], None
    for i, v in enumerate(mask + [False]):  # a plain loop over the samples, for reference
        if v and start is None:
            start = i
        elif not v and start is not None:
            expected.append((start, i))
            start = None
    assert [(r.start, r.stop) for r in mask_runs(np.array(mask, dtype=bool))] == expected


@given(mask=st.lists(st.booleans(), min_size=2, max_size=60), gaps=st.sets(st.integers(0, 58), max_size=4))
@settings(max_examples=80, deadline=None)
def test_mask_runs_end_at_time_gaps(mask, gaps):
    """With the sample times, a run also ends where samples are missing without NaN (a step of more than 1.5
    times the median step), and the runs are the maximal ones of the mask within each gap-free stretch."""
    from vivbench.preprocess import mask_runs

    n = len(mask)
    gaps = {g for g in gaps if g < n - 1}
    steps = np.full(n - 1, 0.25)
    steps[sorted(gaps)] = 188.25 if len(gaps) < (n - 1) / 2 else 0.25  # a minority of gaps keeps the median step
    t = np.concatenate([[0.0], np.cumsum(steps)])
    jumps = {i for i in range(n - 1) if steps[i] > 0.25}
    expected, start = [], None
    for i, v in enumerate(mask + [False]):  # a plain loop over the samples, for reference
        if start is not None and (not v or i - 1 in jumps):  # a run ends at a False or at a gap before sample i
            expected.append((start, i))
            start = None
        if v and start is None:
            start = i
    got = [(r.start, r.stop) for r in mask_runs(np.array(mask, dtype=bool), t)]
    assert got == expected
    from vivbench.preprocess import first_gap

    for lo in range(n):  # the first gap step of a span [lo, n): the simulations stop at its far side
        assert first_gap(t, lo) == min((j for j in jumps if j >= lo), default=None)
    assert [(r.start, r.stop) for r in mask_runs(np.array(mask, dtype=bool), np.arange(n) * 0.25)] == \
        [(r.start, r.stop) for r in mask_runs(np.array(mask, dtype=bool))]  # no gap: the mask's runs
