"""Monte-Carlo draws of the aerodynamic functions (docs/concepts.md (aeroelastic force), 2.8).

:func:`draw_aero` draws shapes and parameters within ranges typical of
streamlined box girders, for studies that want many bridges rather than one.
Reduced velocities Ur = U / (f1 D) are dimensionless; with the default
structure (f1 = 0.327 Hz, D = 3.5 m) Ur = 1 is 1.14 m/s.

Ranges of the ``realistic`` draw (uniform within each range):

========  =====================================================================
Y1        Gaussian or Lorentzian bell: centre Ur0 in [5.5, 8.5] (1/St of box
          girders with St 0.12-0.18), width in [0.7, 1.5] (Gaussian standard
          deviation) or [0.5, 1.1] (Lorentzian half width), peak in [12, 30],
          baseline in [-8, -1] (aerodynamic damping outside lock-in)
e1        logistic step across lock-in (start in [25, 50], end in [10, 30],
          centre Ur0 +- 0.5, width in [0.8, 2.5]) or a constant in [15, 40]
e2        logistic step (start in [200, 400], end in [350, 700], same centre
          and width ranges) or a constant in [250, 600]
Y2        constant in [0, 1]
C_L       Gaussian or Lorentzian bell centred on Ur0 +- 0.5 (peak in
          [0.01, 0.06], width in [1.5, 3.0], floor in [0, 0.005]) or a
          constant in [0.002, 0.02]; >= 0 at every wind speed by construction
yaw       cos^n with n in [1, 3] or a Gaussian with width in [15, 35] degrees,
          applied to Y1 and C_L (``yaw=True``); none with ``yaw=False``
strouhal  1 / Ur0, so that unlocked shedding meets the mode at the bell's centre
========  =====================================================================

The ``in_library`` draw gives polynomials in U: a quadratic bell for Y1 (peak
in [12, 30], centre in [7, 9] m/s, half width in [2, 3] m/s), e1 and e2 linear
in U with positive values over lock-in, and a wide quadratic C_L (peak in
[0.02, 0.06], centre 8 m/s, half width 8 m/s: >= 0 between 0 and 16 m/s).
"""

from __future__ import annotations

import numpy as np

from vivbench.core.errors import InputError
from vivbench.synth.config import AeroConfig, bell_polynomial
from vivbench.synth.curves import Constant, GaussianBell, LogisticStep, LorentzianBell, Polynomial, YawFactor

__all__ = ["draw_aero", "DRAW_KINDS"]

DRAW_KINDS = ("realistic", "in_library")


def _bell(rng: np.random.Generator, *, peak: float, center: float, gauss_width: tuple[float, float],
          lorentz_width: tuple[float, float], baseline: float):
    if rng.random() < 0.5:
        return GaussianBell(peak=peak, center=center, width=rng.uniform(*gauss_width), baseline=baseline)
    return LorentzianBell(peak=peak, center=center, width=rng.uniform(*lorentz_width), baseline=baseline)


def _step_or_constant(rng: np.random.Generator, *, start: tuple[float, float], end: tuple[float, float],
                      constant: tuple[float, float], center: float):
    if rng.random() < 0.75:
        return LogisticStep(start=rng.uniform(*start), end=rng.uniform(*end),
                            center=center + rng.uniform(-0.5, 0.5), width=rng.uniform(0.8, 2.5))
    return Constant(value=rng.uniform(*constant))


def draw_aero(rng: np.random.Generator, *, kind: str = "realistic", yaw: bool = True, **overrides) -> AeroConfig:
    """Draw one set of aerodynamic functions within physically typical ranges (module docstring).

    Parameters
    ----------
    rng : numpy Generator
    kind : "realistic" (non-polynomial shapes in reduced velocity) or "in_library"
        (polynomials in U)
    yaw : bool
        Draw a yaw factor too (``realistic`` only).
    **overrides
        Other AeroConfig fields (e.g. ``cl_unlocked``, ``buffeting_w``), or drawn
        ones to replace.

    Returns
    -------
    AeroConfig
    """
    if kind not in DRAW_KINDS:
        raise InputError(f"draw_aero kind must be one of {list(DRAW_KINDS)}; got {kind!r}")
    if kind == "in_library":
        peak = rng.uniform(12.0, 30.0)
        center = rng.uniform(7.0, 9.0)
        e1_0, e2_0 = rng.uniform(20.0, 40.0), rng.uniform(250.0, 550.0)
        s1, s2 = rng.uniform(-0.12, 0.0), rng.uniform(0.0, 0.12)
        drawn = dict(
            Y1=bell_polynomial(peak, center, rng.uniform(2.0, 3.0)),
            e1=Polynomial(coefficients=(e1_0 * (1 - s1 * center), e1_0 * s1)),
            e2=Polynomial(coefficients=(e2_0 * (1 - s2 * center), e2_0 * s2)),
            C_L=bell_polynomial(rng.uniform(0.02, 0.06), 8.0, 8.0),
        )
        drawn.update(overrides)
        return AeroConfig.in_library(**drawn)
    center = rng.uniform(5.5, 8.5)
    drawn = dict(
        Y1=_bell(rng, peak=rng.uniform(12.0, 30.0), center=center, gauss_width=(0.7, 1.5),
                 lorentz_width=(0.5, 1.1), baseline=rng.uniform(-8.0, -1.0)),
        e1=_step_or_constant(rng, start=(25.0, 50.0), end=(10.0, 30.0), constant=(15.0, 40.0), center=center),
        e2=_step_or_constant(rng, start=(200.0, 400.0), end=(350.0, 700.0), constant=(250.0, 600.0), center=center),
        Y2=Constant(value=rng.uniform(0.0, 1.0)),
        C_L=(_bell(rng, peak=rng.uniform(0.01, 0.06), center=center + rng.uniform(-0.5, 0.5),
                   gauss_width=(1.5, 3.0), lorentz_width=(1.5, 3.0), baseline=rng.uniform(0.0, 0.005))
             if rng.random() < 0.8 else Constant(value=rng.uniform(0.002, 0.02))),
        yaw=((YawFactor(shape="cosine", exponent=rng.uniform(1.0, 3.0)) if rng.random() < 0.5
              else YawFactor(shape="gaussian", width_deg=rng.uniform(15.0, 35.0))) if yaw else None),
        strouhal=1.0 / center,
    )
    drawn.update(overrides)
    return AeroConfig.realistic(**drawn)
