"""The error of a wind taken from an anemometer elsewhere on the span (vivbench.preprocess.unmeasured_wind)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter1d
from scipy.signal import butter, sosfiltfilt

from tests.helpers import assert_close
from vivbench.core.errors import InputError
from vivbench.core.record import Record
from vivbench.preprocess import shifted_unmeasured_wind, unmeasured_wind_error, unmeasured_wind_rms
from vivbench.synth import TurbulenceConfig, simulate_turbulence

U, FS, HOURS = 8.0, 1.0, 24.0


@pytest.mark.parametrize("distance, smoothing", [(400.0, 30.0), (150.0, 0.0)])
def test_it_is_the_rms_difference_of_two_simulated_points_low_passed_and_smoothed(distance, smoothing):
    turb = TurbulenceConfig(intensity=0.1, double_indexing=False, rescale_to_sigma=False)
    priors = {"intensity": 0.1, "kaimal_length_m": float(turb.integral_lengths[0]),
              "coherence_decay": turb.coherence_decay[0]}
    sos = butter(4, 1.0 / 60.0, fs=FS, output="sos")
    trim = int(3600 * FS)
    diffs = []
    for seed in range(4):
        u = simulate_turbulence([0.0, distance], U, HOURS * 3600.0, FS, turb, np.random.default_rng(seed))[:, :, 0]
        slow = sosfiltfilt(sos, u, axis=0)
        if smoothing:
            slow = gaussian_filter1d(slow, smoothing * FS, axis=0, mode="wrap")
        diffs.append((slow[:, 1] - slow[:, 0])[trim:-trim])
    measured = float(np.sqrt(np.mean(np.concatenate(diffs) ** 2)))
    predicted = float(unmeasured_wind_error(U, distance, smoothing, priors=priors))
    assert_close(measured, predicted, rtol=0.05, reason="four 22 h records of a process with minutes of correlation")


def test_zero_where_measured_growing_with_distance_and_shrinking_with_smoothing():
    assert unmeasured_wind_error([5.0, 10.0], 0.0).tolist() == [0.0, 0.0]
    near, far = unmeasured_wind_error(8.0, 100.0), unmeasured_wind_error(8.0, 800.0)
    assert 0 < near < far
    assert unmeasured_wind_error(8.0, 800.0, 60.0) < unmeasured_wind_error(8.0, 800.0, 15.0) < far
    many = np.linspace(3.0, 20.0, 500)  # tabulated and interpolated beyond 64 speeds
    assert_close(unmeasured_wind_error(many, 400.0, 30.0)[::50], unmeasured_wind_error(many[::50], 400.0, 30.0),
                 rtol=2e-3, reason="linear interpolation over a grid of 64 speeds")
    assert np.isnan(unmeasured_wind_error([np.nan, -1.0], 400.0)).all()
    with pytest.raises(InputError, match="distance"):
        unmeasured_wind_error(8.0, -1.0)
    with pytest.raises(InputError, match="unknown priors"):
        unmeasured_wind_error(8.0, 1.0, priors={"intensty": 0.1})


def test_records_without_a_distance_give_none():
    t = np.arange(100.0)
    U = np.full((100, 3), 8.0)
    assert unmeasured_wind_rms(Record(event_id="E", t=t, A=np.ones((100, 3)), U=U), 30.0) is None
    measured = Record(event_id="E", t=t, A=np.ones((100, 3)), U=U, wind_distance=[0.0, 0.0, 0.0])
    assert unmeasured_wind_rms(measured, 30.0) is None
    mid = Record(event_id="F", t=t, A=np.ones((100, 3)), U=U, wind_distance=[400.0, 0.0, 400.0])
    e = unmeasured_wind_error(8.0, 400.0, 30.0)
    assert_close(unmeasured_wind_rms(mid, 30.0), [e, 0.0, e], rtol=1e-12, atol=0, reason="rms of a constant")
    with pytest.raises(ValueError, match="wind_distance"):
        Record(event_id="E", t=t, A=np.ones((100, 3)), U=U, wind_distance=[1.0, -2.0, 0.0])


def test_the_shifted_wind_moves_only_the_sections_measured_elsewhere():
    t = np.arange(100.0)
    U = np.column_stack([np.full(100, 7.0), np.full(100, 8.0), np.full(100, 9.0)])
    plain = Record(event_id="E", t=t, A=np.ones((100, 3)), U=U)
    assert shifted_unmeasured_wind(plain, 30.0, 1.96) is None
    mid = Record(event_id="E", t=t, A=np.ones((100, 3)), U=U, wind_distance=[400.0, 0.0, 200.0])
    up, down = shifted_unmeasured_wind(mid, 30.0, 1.96), shifted_unmeasured_wind(mid, 30.0, -1.96)
    assert np.array_equal(up.U[:, 1], U[:, 1]) and np.array_equal(down.U[:, 1], U[:, 1])
    for k, d in ((0, 400.0), (2, 200.0)):
        e = unmeasured_wind_error(U[0, k], d, 30.0)
        assert_close(up.U[:, k], U[:, k] + 1.96 * e, rtol=1e-12, atol=0, reason="one multiplication and a sum")
        assert_close(down.U[:, k], U[:, k] - 1.96 * e, rtol=1e-12, atol=0, reason="one multiplication and a sum")
    assert up.wind_distance.tolist() == [400.0, 0.0, 200.0]
