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
2. moves the nonlinear damping to the orders the draw's ``e_mix`` keeps (``"both"``: as the model split
   it): A^2 alone (e1), a_k2 + a_k3 A_k; A^3 alone (e2), a_k3 + a_k2 / A_k, with A_k the 99th percentile of the
   section's measured amplitude, so that the damping at the large amplitudes stays the model's whichever
   order carries it
   (:func:`limiter_curves`);
3. fits the generator's shapes to these curves over the data's wind range by weighted
   least squares (weights the band's width, floored at 5 % of each curve's largest value): a
   Gaussian bell of the reduced velocity for Y1 and for C_L (C_L >= 0), logistic steps for e1 and
   e2 centred on Y1's bell (width 1.5 in reduced velocity), 0 <= e1 <= 100 and 0 <= e2 <= 1500 (they
   limit the amplitude, as in the generator family, whose values stay below 50 and 700; a negative
   one, or a large one where Y1 < 0, can make the truth grow without bound), no yaw factor; e2 (A^3)
   is 0 when A^2 alone limits, e1 (A^2) when A^3 alone does.

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
from vivbench.synth.family import E_MIXES

__all__ = ["band_curves", "perturbed_curves", "limiter_curves", "fit_aero", "draw_aero"]

_E_WIDTH = 1.5
#        Y1: peak centre width baseline | e1: start end | e2: start end | C_L: peak centre width baseline
_LOWER = np.array([-50.0, 0.5, 0.05, -200.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.5, 0.05, 0.0])
_UPPER = np.array([500.0, 40.0, 20.0, 50.0, 100.0, 100.0, 1500.0, 1500.0, 5.0, 40.0, 20.0, 1.0])
_E1, _E2 = [4, 5], [6, 7]  # the parameters of e1 (A^2) and of e2 (A^3)


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


def limiter_curves(curves: np.ndarray, half: np.ndarray, amplitude, e_mix: str) -> tuple[np.ndarray, np.ndarray]:
    """Step 2 of the module docstring: the curves and band half widths with the nonlinear damping moved.

    Parameters
    ----------
    curves, half : ndarray, shape (S, 4, n_wind), m^(1-i)/s
    amplitude : array_like, shape (S,), m; each section's 99th percentile of the measured amplitude
        (where the nonlinear damping acts); the half widths of the two orders add in quadrature at it
    e_mix : "both" (unchanged), "e1_only" (A^2 alone, the Larsen-type e1) or "e2_only" (A^3 alone, the
        Simiu-Scanlan e2)

    Returns
    -------
    curves, half : as given, with a_k2 A_k^2 + a_k3 A_k^3 unchanged at A_k and one of the two orders 0
    """
    _check_e_mix(e_mix)
    curves, half = np.array(curves, dtype=float), np.array(half, dtype=float)
    if e_mix == "both":
        return curves, half
    a = np.asarray(amplitude, dtype=float)
    if a.shape != (curves.shape[0],) or not np.all(np.isfinite(a) & (a > 0)):
        raise InputError(f"the measured amplitudes must be {curves.shape[0]} positive numbers (m); got {amplitude!r}")
    a = a[:, None]
    keep, drop, factor = (2, 3, a) if e_mix == "e1_only" else (3, 2, 1.0 / a)
    curves[:, keep] = curves[:, keep] + factor * curves[:, drop]
    half[:, keep] = np.hypot(half[:, keep], factor * half[:, drop])
    curves[:, drop] = 0.0
    half[:, drop] = 0.0
    return curves, half


def _check_e_mix(e_mix) -> None:
    if e_mix not in E_MIXES:
        raise InputError(f"e_mix must be one of {', '.join(map(repr, E_MIXES))}; got {e_mix!r}")


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


def fit_aero(target: np.ndarray, weight: np.ndarray, structure: StructureConfig, wind: np.ndarray,
             e_mix: str = "both") -> tuple[AeroConfig, float]:
    """Step 3 of the module docstring.

    Parameters
    ----------
    target : ndarray, shape (S, 4, n_wind), m^(1-i)/s; the curves to follow
    weight : ndarray, same shape; the residuals' scale (a standard deviation)
    structure : the twin's structure
    wind : ndarray, shape (n_wind,), m/s
    e_mix : "both" (e1 and e2 free), "e1_only" (e2 = 0) or "e2_only" (e1 = 0)

    Returns
    -------
    aero : AeroConfig
    misfit : float; rms of the scaled residuals at the optimum
    """
    free = np.ones(_LOWER.size, dtype=bool)
    if e_mix == "e1_only":
        free[_E2] = False
    elif e_mix == "e2_only":
        free[_E1] = False
    else:
        _check_e_mix(e_mix)

    def full(x):
        theta = np.zeros(_LOWER.size)
        theta[free] = x
        return theta

    def residual(x):
        return ((_model_curves(full(x), structure, wind) - target) / weight).ravel()

    fit = least_squares(residual, _start(target, structure, wind)[free], bounds=(_LOWER[free], _UPPER[free]),
                        x_scale="jac", max_nfev=400)
    return _aero(full(fit.x)), float(np.sqrt(np.mean(fit.fun**2)))


def draw_aero(model, structure: StructureConfig, wind_range: tuple[float, float], rng: np.random.Generator,
              n_wind: int = 40, *, e_mix: str = "both", amplitude=None) -> tuple[AeroConfig, float]:
    """One draw of the twin's aerodynamics from a fitted campaign model (module docstring).

    Parameters
    ----------
    model : fitted campaign model of the protocol with ``curves``
    structure : the twin's structure
    wind_range : (low, high) m/s; the data's winds
    rng : the draw's random stream
    n_wind : winds of the fit over the range
    e_mix : the orders that limit the amplitude (:func:`limiter_curves`)
    amplitude : array_like, shape (S,), m; each section's 99th percentile of the measured amplitude
        (:attr:`vivbench.validate.twin_mirror.CampaignMirror.amplitude_scale`; needed unless ``e_mix`` is "both")

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
    target, half = limiter_curves(target, half, amplitude, e_mix)
    curves, _ = limiter_curves(curves, np.zeros_like(curves), amplitude, e_mix)
    floor = 0.05 * np.max(np.abs(curves), axis=2, keepdims=True) + 1e-12
    weight = np.maximum(half / 1.96, floor)
    return fit_aero(target, weight, structure, wind, e_mix)
