"""Aerodynamic functions of a twin, drawn from a fitted campaign model within its bands.

A campaign model of the protocol (docs/methods.md) gives coefficient curves a_ki(U) with a band
(``curves``, ``curves_lower``, ``curves_upper``: :func:`vivbench.models.model_curves`). The
averaged truth of the generator has a_ki = phi_k^(1 - i) p_i(U), where p_i follow from the
aerodynamic functions Y1, e1, e2, C_L and the structure (:func:`vivbench.synth.truth_curves`).
A draw of the twin's aerodynamics:

1. perturbs the model's curves within their band: per order i, a_ki(U) + h_ki(U) (z_i0 + z_i1 x(U))
   / (1.96 sqrt 2), with h the band's half width, x(U) running linearly from -1 to 1 over the
   data's wind range and z standard normal draws (a shift and a tilt of each order's curves,
   one standard deviation at the band's 95 % level);
2. fits the generator's shapes to the perturbed curves over the data's wind range by weighted
   least squares (weights the band's width, floored at 5 % of each curve's largest value): a
   Gaussian bell of the reduced velocity for Y1 and for C_L (C_L >= 0), logistic steps for e1 and
   e2 centred on Y1's bell (width 1.5 in reduced velocity), 0 <= e1 <= 100 and 0 <= e2 <= 1500 (they
   limit the amplitude, as in the generator family, whose values stay below 50 and 700; a negative
   one, or a large one where Y1 < 0, can make the truth grow without bound), no yaw factor.

The twin's truth thus lies in the generator's class, outside the identification's, and within the
field model's uncertainty where the data constrain it; outside the data's winds it follows the
fitted shapes.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import least_squares

from vivbench.core.errors import InputError
from vivbench.models.protocol import model_curves
from vivbench.synth.aero import amplitude_coefficients
from vivbench.synth.config import AeroConfig, StructureConfig
from vivbench.synth.curves import GaussianBell, LogisticStep

__all__ = ["band_curves", "perturbed_curves", "fit_aero", "draw_aero"]

_E_WIDTH = 1.5
#        Y1: peak centre width baseline | e1: start end | e2: start end | C_L: peak centre width baseline
_LOWER = np.array([-50.0, 0.5, 0.05, -200.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.5, 0.05, 0.0])
_UPPER = np.array([500.0, 40.0, 20.0, 50.0, 100.0, 100.0, 1500.0, 1500.0, 5.0, 40.0, 20.0, 1.0])


def band_curves(model, wind: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The model's curves and their band's half width on ``wind`` (m/s).

    Returns
    -------
    curves, half : ndarray, shape (S, 4, n_wind), m^(1-i)/s; ``half`` is 0 where the model gives no band

    Raises
    ------
    InputError
        The model gives no coefficient curves (the twin needs them).
    """
    ds = model_curves(model, wind)
    if ds is None:
        raise InputError("the campaign model gives no coefficient curves: the twin draws its aerodynamics from them")
    point = np.asarray(ds["curves"].values, dtype=float)
    lower = np.asarray(ds["curves_lower"].values, dtype=float) if "curves_lower" in ds else np.full_like(point, np.nan)
    upper = np.asarray(ds["curves_upper"].values, dtype=float) if "curves_upper" in ds else np.full_like(point, np.nan)
    half = np.nan_to_num(0.5 * (upper - lower), nan=0.0)
    return np.nan_to_num(point, nan=0.0), np.maximum(half, 0.0)


def perturbed_curves(curves: np.ndarray, half: np.ndarray, wind: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Step 1 of the module docstring: curves shifted and tilted within their band, shape of ``curves``."""
    z = rng.standard_normal((4, 2))
    x = np.linspace(-1.0, 1.0, wind.size)
    shape = (z[:, :1] + z[:, 1:] * x[None, :]) / (1.96 * math.sqrt(2.0))  # (4, n_wind)
    return curves + half * shape[None, :, :]


def _aero(theta: np.ndarray) -> AeroConfig:
    y_peak, y_c, y_w, y_b, e1a, e1b, e2a, e2b, c_peak, c_c, c_w, c_b = (float(v) for v in theta)
    return AeroConfig(Y1=GaussianBell(peak=y_peak, center=y_c, width=y_w, baseline=y_b),
                      e1=LogisticStep(start=e1a, end=e1b, center=y_c, width=_E_WIDTH),
                      e2=LogisticStep(start=e2a, end=e2b, center=y_c, width=_E_WIDTH),
                      C_L=GaussianBell(peak=c_peak, center=c_c, width=c_w, baseline=c_b), yaw=None)


def _model_curves(theta: np.ndarray, structure: StructureConfig, wind: np.ndarray) -> np.ndarray:
    phi = np.array(structure.mode_shape)
    U = np.repeat(wind[:, None], phi.size, axis=1)
    p = amplitude_coefficients(U, structure, _aero(theta))  # (n_wind, 4)
    return phi[:, None, None] ** (1 - np.arange(4))[None, :, None] * p.T[None, :, :]


def _start(target: np.ndarray, structure: StructureConfig, wind: np.ndarray) -> np.ndarray:
    """Initial shapes from the curves inverted at each wind (Y1 from the linear order, C_L from the constant)."""
    s = structure
    phi = np.array(s.mode_shape)
    p1 = target[:, 1, :].mean(axis=0)
    p0 = (target[:, 0, :] / phi[:, None]).mean(axis=0)
    ur = wind / (s.frequency * s.depth)
    y1 = 2.0 * s.mass * (p1 + s.damping_ratio * s.omega) / (s.air_density * wind * s.depth)
    cl = p0 * 4.0 * s.mass * s.omega / (s.air_density * s.depth * wind**2 * s.participation.sum())
    k = int(np.argmax(y1))
    j = int(np.argmax(cl))
    theta = np.array([max(y1[k], 0.5), ur[k], 1.0, min(float(np.min(y1)), 0.0), 28.0, 28.0, 400.0, 400.0,
                      max(cl[j], 1e-3), ur[j], 2.0, max(float(np.min(cl)), 0.0)])
    return np.clip(theta, _LOWER + 1e-9, _UPPER - 1e-9)


def fit_aero(target: np.ndarray, weight: np.ndarray, structure: StructureConfig, wind: np.ndarray
             ) -> tuple[AeroConfig, float]:
    """Step 2 of the module docstring.

    Parameters
    ----------
    target : ndarray, shape (S, 4, n_wind), m^(1-i)/s; the curves to follow
    weight : ndarray, same shape; the residuals' scale (a standard deviation)
    structure : the twin's structure
    wind : ndarray, shape (n_wind,), m/s

    Returns
    -------
    aero : AeroConfig
    misfit : float; rms of the scaled residuals at the optimum
    """
    def residual(theta):
        return ((_model_curves(theta, structure, wind) - target) / weight).ravel()

    fit = least_squares(residual, _start(target, structure, wind), bounds=(_LOWER, _UPPER), x_scale="jac",
                        max_nfev=400)
    return _aero(fit.x), float(np.sqrt(np.mean(fit.fun**2)))


def draw_aero(model, structure: StructureConfig, wind_range: tuple[float, float], rng: np.random.Generator,
              n_wind: int = 40) -> tuple[AeroConfig, float]:
    """One draw of the twin's aerodynamics from a fitted campaign model (module docstring).

    Parameters
    ----------
    model : fitted campaign model of the protocol with ``curves``
    structure : the twin's structure
    wind_range : (low, high) m/s; the data's winds
    rng : the draw's random stream

    Returns
    -------
    aero : AeroConfig; misfit : rms scaled residual of the shapes' fit
    """
    lo, hi = (float(x) for x in wind_range)
    if not (0 < lo < hi and math.isfinite(hi)):
        raise InputError(f"the data's wind range must be 0 < low < high m/s; got {wind_range}")
    wind = np.linspace(lo, hi, n_wind)
    curves, half = band_curves(model, wind)
    if curves.shape[0] != structure.n_sections:
        raise InputError(f"the campaign model has {curves.shape[0]} equations for {structure.n_sections} sections")
    target = perturbed_curves(curves, half, wind, rng)
    floor = 0.05 * np.max(np.abs(curves), axis=2, keepdims=True) + 1e-12
    weight = np.maximum(half / 1.96, floor)
    return fit_aero(target, weight, structure, wind)
