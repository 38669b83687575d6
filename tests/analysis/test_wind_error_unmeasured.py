"""The selection's wind perturbations see winds taken from an anemometer elsewhere on the span."""

from __future__ import annotations

import dataclasses

import numpy as np

from tests.helpers import assert_close
from vivbench.analysis.selection import wind_error_scale
from vivbench.core.record import Record
from vivbench.preprocess import smooth_wind, unmeasured_wind_rms


def _record(U, distance=None):
    t = np.arange(U.shape[0], dtype=float)
    return Record(event_id="E", t=t, A=np.full(U.shape, 0.1), U=U, wind_distance=distance)


def test_one_anemometer_copied_to_every_section_is_perturbed_by_its_distance():
    t = np.arange(1800.0)
    one = 8.0 + np.sin(2 * np.pi * t / 600.0)
    copied = _record(np.repeat(one[:, None], 3, axis=1))
    assert np.all(wind_error_scale(copied, 60.0) < 1e-12)  # no spread (but rounding): no error seen
    mid = dataclasses.replace(copied, wind_distance=[400.0, 0.0, 400.0])
    scale = wind_error_scale(mid, 60.0)
    e = unmeasured_wind_rms(smooth_wind(mid, 60.0), 60.0)  # at the smoothed record's wind
    assert scale[1] < 1e-12 and scale[0] > 0.1
    assert_close(scale, e, rtol=1e-12, atol=1e-12, reason="hypot with a zero spread")


def test_the_distance_adds_in_quadrature_to_the_spread_and_nothing_without_it():
    rng = np.random.default_rng(0)
    U = 8.0 + 0.3 * rng.standard_normal((1800, 3))
    plain = wind_error_scale(_record(U), 60.0)
    assert np.array_equal(wind_error_scale(_record(U, [0.0, 0.0, 0.0]), 60.0), plain)
    far = _record(U, [0.0, 0.0, 600.0])
    scale = wind_error_scale(far, 60.0)
    assert np.array_equal(scale[:2], plain[:2])
    assert_close(scale[2], np.hypot(plain[2], unmeasured_wind_rms(smooth_wind(far, 60.0), 60.0)[2]), rtol=1e-12, atol=0,
                 reason="the same smoothing of the same record")
