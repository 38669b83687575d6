"""The varying model's errors-in-variables with winds taken from an anemometer elsewhere on the span."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tests.helpers import assert_close, bell_records
from vivbench.models import VaryingCoefficientSINDy
from vivbench.models.varying_fit import wind_standard_error

SETTINGS = {"n_basis": (8,), "penalties": (1e-4, 1e-2), "n_bootstrap": 4, "n_folds": 3, "wind_smoothing_s": 0.0}


@pytest.fixture(scope="module")
def one_anemometer():
    """Bell records whose sections' winds differ, and the same with section 2's wind recorded at both sections."""
    records = bell_records(4, seed=5, duration_s=900.0, dt_s=1.0, mode_shape=np.array([1.0, 0.8]),
                           wind_period_s=(400.0, 50.0), amplitude_period_s=250.0, noise_m_s=1e-4,
                           section_swing_m_s=0.6)
    copied = [dataclasses.replace(r, U=np.repeat(r.U[:, 1:2], 2, axis=1)) for r in records]
    return records, copied


@pytest.mark.parametrize("wind_input", ["mean", "additive"])
def test_no_distance_recorded_leaves_the_fit_unchanged(one_anemometer, wind_input):
    records, _ = one_anemometer
    plain = VaryingCoefficientSINDy(**SETTINGS, wind_input=wind_input).fit(records)
    zero = VaryingCoefficientSINDy(**SETTINGS, wind_input=wind_input).fit(
        [dataclasses.replace(r, wind_distance=[0.0, 0.0]) for r in records])
    np.testing.assert_array_equal(plain.coef_, zero.coef_)
    np.testing.assert_array_equal(plain.coef_bootstrap_, zero.coef_bootstrap_)
    np.testing.assert_array_equal(plain.wind_error_share_, zero.wind_error_share_)


def test_one_copied_anemometer_shows_no_wind_error_until_the_distance_is_recorded(one_anemometer):
    _, copied = one_anemometer
    blind = VaryingCoefficientSINDy(**SETTINGS).fit(copied)
    assert not blind.wind_error_share_.any()  # the spread of identical winds is 0
    seen = VaryingCoefficientSINDy(**SETTINGS).fit([dataclasses.replace(r, wind_distance=[400.0, 0.0]) for r in copied])
    assert (seen.wind_error_share_ > 0).all()
    assert not np.array_equal(seen.coef_, blind.coef_)


def test_the_error_adds_in_quadrature_to_the_spread():
    U = np.array([[8.0, 9.0], [10.0, 10.0]])
    e = np.array([[0.3, 0.0], [0.4, 0.0]])
    w = np.array([0.5, 0.5])
    spread = wind_standard_error("mean", w, U)
    assert_close(wind_standard_error("mean", w, U, e), np.sqrt(spread**2 + 0.25 * e[:, 0] ** 2))
    per_input = wind_standard_error("additive", w, U, e)
    assert per_input.shape == (2, 2)
    assert_close(per_input, np.sqrt(wind_standard_error("additive", w, U)[:, None] ** 2 + e**2))
    assert_close(wind_standard_error("section", w, U, e), e)
