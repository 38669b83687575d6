"""The sections' weights in the varying model's one wind (``wind_weights``).

Averaging (docs/concepts.md (the truth)) weights section j's aerodynamic force by L_j phi_j^2 in
the linear order: the mode's antinode drives it more than a quarter point.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vivbench.core.errors import InputError
from vivbench.models import VaryingCoefficientSINDy
from vivbench.models.wind_weights import (check_wind_weights, modal_wind_weights, resolve_wind_weights,
                                          weighted_mean_standard_error, weighted_section_mean)
from tests.helpers import assert_close, bell_records

PHI = np.array([0.45, 1.0, 0.8])  # an asymmetric in-phase mode
W_MODAL = PHI**2 / np.sum(PHI**2)
A3 = -2.0  # 1/(m^2 s)


def _records(weights, n_events: int = 8, seed: int = 0):
    """Noise-free records of one mode, A_k = phi_k Q, whose linear coefficient is bell(sum_j weights_j U_j).

    The sections' winds differ by persistent offsets of +-1.5 m/s, so the weighted and the plain mean differ.
    """
    return bell_records(n_events, seed=seed, duration_s=1200.0, dt_s=2.0, mode_shape=PHI, modal=True,
                        wind_period_s=(600.0, 100.0), wind_offsets_m_s=1.5, section_swing_m_s=0.2,
                        section_swing_period_s=(170.0, 37.0, 1.0), section_swing_phased=False,
                        amplitude_period_s=300.0, wind_weights=weights, a3=A3)


def _fit(records, wind_weights):
    return VaryingCoefficientSINDy(n_bootstrap=0, n_basis=(11,), penalties=(1e-6,), wind_smoothing_s=0.0,
                                   wind_weights=wind_weights).fit(records)


def _rel_err(model, records):
    num = sum(np.sum((model.predict(r) - r.dA) ** 2) for r in records)
    return float(np.sqrt(num / sum(np.sum(r.dA**2) for r in records)))


@pytest.fixture(scope="module")
def modal_truth():
    return _records(W_MODAL), _records(W_MODAL, n_events=2, seed=9)


def test_modal_weights_are_the_modes_energy_shares():
    rng = np.random.default_rng(1)
    Q = np.abs(rng.normal(0.1, 0.05, 5000))
    A = Q[:, None] * PHI + 1e-4 * rng.standard_normal((5000, 3))
    A[::7, 1] = np.nan  # samples missing in one section are left out of every section's sum
    assert_close(modal_wind_weights(A), W_MODAL, rtol=1e-3, reason="the sensors' noise (1e-4 m) adds to each sum")
    assert_close(resolve_wind_weights("equal", A), np.full(3, 1 / 3))
    assert_close(resolve_wind_weights([2.0, 1.0, 1.0], A), [0.5, 0.25, 0.25])


def test_modal_weights_follow_a_bell_of_the_weighted_wind(modal_truth):
    fit, held_out = modal_truth
    modal = _fit(fit, "modal")
    assert_close(modal.wind_weights_, W_MODAL)
    equal = _fit(fit, "equal")
    assert_close(equal.wind_weights_, np.full(3, 1 / 3))
    # One curve of the plain mean cannot carry a bell of the weighted mean when the sections' winds differ.
    assert _rel_err(equal, held_out) > 5 * _rel_err(modal, held_out)
    assert _rel_err(modal, held_out) < 0.02
    # Given weights are normalised; the modal ones given as numbers give the same model.
    given = _fit(fit, tuple(3.0 * PHI**2))
    assert_close(given.predict(held_out[0]), modal.predict(held_out[0]), rtol=1e-6, atol=1e-12,
                 reason="weights normalised in another order: rounding through the fit")


def test_weights_survive_save_and_load(modal_truth, tmp_path):
    model = _fit(modal_truth[0], "modal")
    back = VaryingCoefficientSINDy.load(model.save(tmp_path / "m.nc"))
    assert back.wind_weights == "modal"
    assert_close(back.wind_weights_, model.wind_weights_)
    rec = modal_truth[1][0]
    np.testing.assert_array_equal(back.predict(rec), model.predict(rec))
    # A file written before the weights existed was fitted with the plain mean.
    ds = model.to_dataset().drop_vars("wind_weights")
    old = tmp_path / "old.nc"
    ds.to_netcdf(old)
    assert_close(VaryingCoefficientSINDy.load(old).wind_weights_, np.full(3, 1 / 3))


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(-50, 50), min_size=6, max_size=6), st.integers(0, 5))
def test_equal_weights_are_the_plain_mean_and_its_standard_error(values, missing):
    X = np.array(values).reshape(2, 3)
    X[0, missing % 3] = np.nan
    w = np.full(3, 1 / 3)
    # absolute: a sum of thirds and a sum over three differ by rounding, also where the mean is 0
    assert_close(weighted_section_mean(X, w), np.nanmean(X, axis=1), atol=1e-12, reason="rounding at a zero mean")
    n = np.isfinite(X).sum(axis=1)
    assert_close(weighted_mean_standard_error(X, w), np.nanstd(X, axis=1, ddof=1) / np.sqrt(n), atol=1e-12,
                 reason="rounding at a zero spread")


def test_weighted_mean_renormalises_over_finite_sections():
    X = np.array([[1.0, 2.0, 4.0], [1.0, np.nan, 4.0], [np.nan, np.nan, np.nan]])
    out = weighted_section_mean(X, np.array([0.25, 0.5, 0.25]))
    assert_close(out[:2], [2.25, 2.5])
    assert np.isnan(out[2])


@pytest.mark.parametrize("bad", ["mode", [1.0, -1.0, 1.0], [0.0, 0.0], [], [np.nan, 1.0], 3.0])
def test_bad_wind_weights_are_refused(bad):
    with pytest.raises(InputError, match="wind_weights"):
        check_wind_weights(bad)
    with pytest.raises(InputError, match="wind_weights"):
        VaryingCoefficientSINDy(wind_weights=bad).fit(_records(W_MODAL, n_events=2))


def test_given_weights_must_match_the_sections():
    with pytest.raises(InputError, match="2 weights for 3 sections"):
        VaryingCoefficientSINDy(wind_weights=(1.0, 2.0), n_basis=(6,), penalties=(1e-3,)).fit(
            _records(W_MODAL, n_events=2))
