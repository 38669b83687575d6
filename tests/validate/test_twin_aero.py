"""A twin's aerodynamics drawn from a campaign model (vivbench.validate.twin_aero)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import xarray as xr
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.helpers import assert_close
from vivbench.core.errors import InputError
from vivbench.synth.aero import amplitude_coefficients
from vivbench.synth.config import AeroConfig, StructureConfig
from vivbench.synth.curves import Constant
from vivbench.validate.twin_aero import draw_aero, fit_aero, limiter_curves

STRUCTURE = StructureConfig()  # three sections, mode shape (0.707, 1, 0.707), 0.327 Hz
WIND = np.linspace(5.0, 10.0, 30)


def _curves(aero: AeroConfig, wind=WIND) -> np.ndarray:
    """a_ki(U) = phi_k^(1 - i) p_i(U) of the generator's averaged truth, shape (S, 4, n_wind)."""
    phi = np.array(STRUCTURE.mode_shape)
    p = amplitude_coefficients(np.repeat(wind[:, None], phi.size, axis=1), STRUCTURE, aero)  # (n_wind, 4)
    return phi[:, None, None] ** (1 - np.arange(4))[None, :, None] * p.T[None, :, :]


class _CurvesModel:
    """A fitted campaign model reduced to its curves and band (what the twin reads of it)."""

    def __init__(self, aero: AeroConfig, band: float = 0.1):
        self.aero, self.band = aero, band

    def curves(self, wind, level: float = 0.95) -> xr.Dataset:
        c = _curves(self.aero, np.asarray(wind, dtype=float))
        dims = ("equation", "order", "wind")
        h = self.band * np.max(np.abs(c), axis=2, keepdims=True)
        return xr.Dataset({"curves": (dims, c), "curves_lower": (dims, c - h), "curves_upper": (dims, c + h)})


@settings(max_examples=50, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), e_mix=st.sampled_from(["e1_only", "e2_only"]))
def test_moving_the_nonlinear_damping_keeps_it_at_the_measured_amplitude(seed, e_mix):
    rng = np.random.default_rng(seed)
    curves, half = rng.normal(size=(3, 4, 7)), rng.uniform(0.0, 1.0, size=(3, 4, 7))
    a = rng.uniform(0.01, 0.5, size=3)
    moved, moved_half = limiter_curves(curves, half, a, e_mix)
    A = a[:, None]
    assert_close(moved[:, 2] * A**2 + moved[:, 3] * A**3, curves[:, 2] * A**2 + curves[:, 3] * A**3,
                 atol=1e-12, reason="rounding of a sum of terms of order 1",
                 what="the nonlinear damping at each section's amplitude")
    dropped = 3 if e_mix == "e1_only" else 2  # e1 limits with A^2, e2 with A^3
    assert np.all(moved[:, dropped] == 0.0) and np.all(moved_half[:, dropped] == 0.0)
    assert np.array_equal(moved[:, :2], curves[:, :2]) and np.array_equal(moved_half[:, :2], half[:, :2])
    assert np.all(moved_half[:, 5 - dropped] >= half[:, 5 - dropped])  # the band widens by the moved order's


def test_both_orders_leave_the_curves_as_they_are():
    rng = np.random.default_rng(1)
    curves, half = rng.normal(size=(2, 4, 5)), rng.uniform(size=(2, 4, 5))
    moved, moved_half = limiter_curves(curves, half, None, "both")
    assert np.array_equal(moved, curves) and np.array_equal(moved_half, half)


@pytest.mark.parametrize("amplitude, e_mix, message", [
    ([0.1, 0.1, 0.1], "cubic", "e_mix must be one of 'both', 'e1_only', 'e2_only'"),
    (None, "e1_only", "the measured amplitudes must be 3 positive numbers"),
    ([0.1, 0.0, 0.1], "e2_only", "the measured amplitudes must be 3 positive numbers"),
    ([0.1, 0.1], "e2_only", "the measured amplitudes must be 3 positive numbers"),
])
def test_bad_limiter_inputs_are_refused(amplitude, e_mix, message):
    with pytest.raises(InputError, match=message):
        limiter_curves(np.zeros((3, 4, 5)), np.zeros((3, 4, 5)), amplitude, e_mix)


@pytest.mark.parametrize("e_mix, zero", [("e1_only", "e2"), ("e2_only", "e1")])
def test_a_one_order_limiter_is_fitted_with_the_other_order_absent(e_mix, zero):
    aero = dataclasses.replace(AeroConfig(yaw=None), **{zero: Constant(value=0.0)})
    target = _curves(aero)
    weight = 0.05 * np.max(np.abs(target), axis=2, keepdims=True) + 1e-12
    fitted, misfit = fit_aero(target, weight, STRUCTURE, WIND, e_mix)
    step = getattr(fitted, zero)
    assert (step.start, step.end) == (0.0, 0.0)
    # the generator's own one-order truth lies in the fitted class: its curves are followed
    assert misfit < 0.5
    assert_close(_curves(fitted)[:, 1:], target[:, 1:], atol=float(np.max(np.abs(target[:, 1:]))) * 0.05,
                 reason="least squares of the generator's shapes, weighted at 5 % of each curve's largest value")


def test_a_drawn_one_order_limiter_keeps_the_damping_at_the_measured_amplitude():
    """A model whose damping is split between A^2 and A^3, redrawn with A^2 alone (e1): the twin's nonlinear
    damping at the measured amplitudes follows the model's (its band is narrow), and its A^3 is absent."""
    model = _CurvesModel(AeroConfig(yaw=None), band=0.02)
    a = np.array([0.05, 0.07, 0.05])
    aero, _ = draw_aero(model, STRUCTURE, (5.0, 10.0), np.random.default_rng(0), e_mix="e1_only", amplitude=a)
    assert (aero.e2.start, aero.e2.end) == (0.0, 0.0)
    twin, model_curves = _curves(aero), _curves(model.aero)
    A = a[:, None]
    damping = model_curves[:, 2] * A**2 + model_curves[:, 3] * A**3
    assert_close(twin[:, 2] * A**2, damping, atol=float(np.max(np.abs(damping))) * 0.15,
                 reason="the shapes' least squares within a 2 % band and its 5 % floor, and the band's draw")


def test_the_default_draw_follows_the_models_own_split():
    model = _CurvesModel(AeroConfig(yaw=None), band=0.0)
    one = draw_aero(model, STRUCTURE, (5.0, 10.0), np.random.default_rng(3))
    again = draw_aero(model, STRUCTURE, (5.0, 10.0), np.random.default_rng(3), e_mix="both", amplitude=None)
    assert one == again
    assert one[0].e1.start > 0 and one[0].e2.start > 0
