"""The generator settings a recovery sweep can vary, with how to read and set each one."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

from vivbench.synth.config import AeroConfig, GeneratorConfig, Polynomial
from vivbench.core.errors import InputError

__all__ = ["PARAMETERS", "SWEEP_PARAMETERS", "Parameter"]



def _y1_peak(gen: GeneratorConfig) -> float:
    """Peak of a bell-shaped Y1 (a downward quadratic in U, or a Gaussian or Lorentzian bell); NaN for any other form."""
    y1 = gen.aero.Y1
    if getattr(y1, "kind", None) in ("gaussian", "lorentzian"):
        return y1.peak
    c = getattr(y1, "coefficients", ())
    if len(c) != 3 or not c[2] < 0:
        return float("nan")
    return float(c[0] - c[1] ** 2 / (4.0 * c[2]))


def _set_y1_peak(gen: GeneratorConfig, value: float) -> GeneratorConfig:
    peak = _y1_peak(gen)
    if not peak > 0:
        raise InputError("y1_peak needs the base generator's aero.Y1 to be a bell (a quadratic in U, or a gaussian or "
                         f"lorentzian curve, with a positive peak); got {gen.aero.Y1}")
    if not value >= 0:
        raise InputError(f"y1_peak must be >= 0 (the height of the Y1 bell; 0 removes self-excitation); got {value}")
    # Scaling the whole bell keeps its centre and its zero crossings (the lock-in range).
    if getattr(gen.aero.Y1, "kind", None) in ("gaussian", "lorentzian"):
        y1 = dataclasses.replace(gen.aero.Y1, peak=value, baseline=gen.aero.Y1.baseline * value / peak)
        return dataclasses.replace(gen, aero=dataclasses.replace(gen.aero, Y1=y1))
    y1 = Polynomial(coefficients=tuple(value / peak * c for c in gen.aero.Y1.coefficients))
    return dataclasses.replace(gen, aero=dataclasses.replace(gen.aero, Y1=y1))


@dataclass(frozen=True)
class Parameter:
    """A generator setting a sweep can vary: what it sets, its axis label, how to read and set it.

    ``switch`` is True for an on/off setting coded 0 or 1: a grid axis only, never a range.
    """

    description: str
    axis_label: str
    read: Callable[[GeneratorConfig], float]
    apply: Callable[[GeneratorConfig, float], GeneratorConfig]
    switch: bool = False


def _check_switch(name: str, value: float, off: str, on: str) -> None:
    if value not in (0.0, 1.0):
        raise InputError(f"{name} must be 0 ({off}) or 1 ({on}); got {value}")


def _aero_realistic(gen: GeneratorConfig) -> float:
    """1 when the aerodynamic functions are outside the library (not polynomials in U, or a yaw factor), else 0."""
    return 0.0 if gen.aero.polynomials() is not None else 1.0


_AERO_SCALARS = ("strouhal", "cl_unlocked", "lock_bandwidth", "buffeting_u", "buffeting_w")


def _set_aero_realistic(gen: GeneratorConfig, value: float) -> GeneratorConfig:
    _check_switch("aero_realistic", value, "in_library polynomials", "realistic functions of reduced velocity")
    if value == _aero_realistic(gen):
        return gen  # the base generator's own functions already belong to that mode
    # The mode's curves (and yaw factor); the base's shedding and buffeting settings are kept.
    kept = {k: getattr(gen.aero, k) for k in _AERO_SCALARS}
    aero = AeroConfig.realistic(**kept) if value else AeroConfig.in_library(**kept)
    return dataclasses.replace(gen, aero=aero)


def _set_felt_wind(gen: GeneratorConfig, value: float) -> GeneratorConfig:
    _check_switch("felt_wind_tributary", value, "the anemometer's wind", "the tributary-averaged wind")
    felt = "tributary" if value else "anemometer"
    return dataclasses.replace(gen, wind=dataclasses.replace(gen.wind, felt_wind=felt))


def _set_drift(gen: GeneratorConfig, value: float) -> GeneratorConfig:
    if not -1.0 < value < 1.0:
        raise InputError(f"drift_amplitude must be in (-1, 1) (relative damping drift); got {value}")
    return dataclasses.replace(gen, changes=dataclasses.replace(gen.changes, drift_amplitude=value))


def _replace_in(section: str, name: str):
    def apply(gen: GeneratorConfig, value: float) -> GeneratorConfig:
        sub = dataclasses.replace(getattr(gen, section), **{name: value})
        return dataclasses.replace(gen, **{section: sub})
    return apply


def _set_turbulence(gen: GeneratorConfig, value: float) -> GeneratorConfig:
    turb = dataclasses.replace(gen.wind.turbulence, intensity=value)
    return dataclasses.replace(gen, wind=dataclasses.replace(gen.wind, turbulence=turb))


PARAMETERS: dict[str, Parameter] = {
    "noise_density": Parameter(
        "accelerometer noise floor, micro-g/sqrt(Hz) (sensors.noise_density)",
        "accelerometer noise floor (µg/√Hz)",
        lambda g: g.sensors.noise_density, _replace_in("sensors", "noise_density")),
    "anemometer_noise": Parameter(
        "anemometer rms error relative to the wind speed, 1 (wind.noise)",
        "anemometer rms error (fraction of wind speed)",
        lambda g: g.wind.noise, _replace_in("wind", "noise")),
    "turbulence_intensity": Parameter(
        "longitudinal turbulence intensity sigma_u / U, 1 (wind.turbulence.intensity)",
        "turbulence intensity σ_u/U (-)",
        lambda g: g.wind.turbulence.intensity, _set_turbulence),
    "damping_ratio": Parameter(
        "structural damping ratio zeta, 1 (structure.damping_ratio)",
        "structural damping ratio ζ (-)",
        lambda g: g.structure.damping_ratio, _replace_in("structure", "damping_ratio")),
    "y1_peak": Parameter(
        "peak of the bell-shaped aerodynamic damping derivative Y1(U), 1 (aero.Y1 scaled as a whole)",
        "peak of Y1(U) (-)",
        _y1_peak, _set_y1_peak),
    "aero_realistic": Parameter(
        "realism of the aerodynamic functions (docs/concepts.md (no inverse crime)): 0 = in_library (polynomials in U), "
        "1 = realistic (AeroConfig.realistic(): functions of reduced velocity with a yaw factor); grid only",
        "aerodynamic functions (0 in_library, 1 realistic)",
        _aero_realistic, _set_aero_realistic, switch=True),
    "felt_wind_tributary": Parameter(
        "wind the deck feels (docs/concepts.md (no inverse crime)): 0 = its anemometer's low-passed wind, "
        "1 = the tributary-averaged wind of a spatially resolved field (wind.felt_wind); grid only",
        "felt wind (0 anemometer, 1 tributary)",
        lambda g: float(g.wind.felt_wind == "tributary"), _set_felt_wind, switch=True),
    "drift_amplitude": Parameter(
        "relative amplitude of the daily damping drift, 1 (changes.drift_amplitude; 0: none)",
        "damping drift amplitude (-)",
        lambda g: g.changes.drift_amplitude, _set_drift),
}

#: Parameters a sweep can vary: name -> what it sets, with its unit.
SWEEP_PARAMETERS: dict[str, str] = {name: p.description for name, p in PARAMETERS.items()}
