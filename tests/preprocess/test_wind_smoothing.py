"""The Gaussian wind smoothing of campaign models (vivbench.preprocess.smooth_wind) and its cache."""

from __future__ import annotations

import dataclasses
import gc

import numpy as np

from tests.helpers import assert_close
from vivbench.core.record import Record
from vivbench.preprocess import wind_smoothing
from vivbench.preprocess.wind_smoothing import smooth_wind


def _record(seed: int = 0) -> Record:
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 600.0, 0.5)
    U = 8.0 + rng.standard_normal((t.size, 2)).cumsum(axis=0) * 0.05
    U[100:120, 0] = np.nan  # a gap: normalised convolution around it
    A = np.abs(rng.standard_normal((t.size, 2))) * 0.01
    return Record(event_id="E001", t=t, A=A, U=U, dA=np.zeros_like(A), yaw=rng.uniform(-10, 10, (t.size, 2)))


def test_a_record_smoothed_twice_is_smoothed_once_and_alike():
    rec = _record()
    first = smooth_wind(rec, 30.0)
    assert smooth_wind(rec, 30.0) is first  # the cached result
    copy = dataclasses.replace(rec)  # an equal record, another object: computed afresh
    again = smooth_wind(copy, 30.0)
    assert again is not first
    assert_close(again.U, first.U, rtol=0.0, atol=0.0)
    assert_close(again.yaw, first.yaw, rtol=0.0, atol=0.0)
    assert np.isnan(first.U[100:120, 0]).all() and np.isfinite(first.U[120:, 0]).all()
    assert smooth_wind(rec, 10.0) is not first  # another time scale, another result


def test_the_cache_lets_go_of_a_record_no_longer_used():
    rec = _record(1)
    smooth_wind(rec, 30.0)
    n = len(wind_smoothing._SMOOTHED)
    del rec
    gc.collect()
    assert len(wind_smoothing._SMOOTHED) == n - 1


def test_u_and_yaw_with_different_gaps_are_each_smoothed_over_their_own_valid_samples():
    rec = _record(2)
    yaw = rec.yaw.copy()
    yaw[300:340, 1] = np.nan  # a gap the wind does not have
    both = smooth_wind(dataclasses.replace(rec, yaw=yaw), 30.0)
    alone = smooth_wind(dataclasses.replace(rec, U=yaw, yaw=None), 30.0)  # the yaw smoothed as a wind
    assert_close(both.yaw, alone.U, rtol=0.0, atol=0.0)
    assert np.isnan(both.yaw[300:340, 1]).all() and np.isfinite(both.U[300:340, 1]).all()
