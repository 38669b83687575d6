"""What a field user cannot measure, drawn for each twin draw from stated priors.

A campaign's records fix its winds, yaws, rates, noise floors and turbulence intensity, which the
twin mirrors (:mod:`vivbench.validate.twin_mirror`). They do not say how the wind the deck feels
differs from the wind the anemometers record, how strongly the deck is buffeted, nor whether the
aerodynamics depend on the wind's angle to the span. A twin that fixed these at one value would
leave their effect out of its spread; each twin draw therefore draws them from the priors of
:class:`NuisancePriors`, by default the generator family's own (:mod:`vivbench.synth.family`):

- the errors in the wind: with probability ``1 - smooth_share`` the deck feels the tributary
  average of a turbulent field of the measured intensity (``felt_wind="tributary"``); otherwise it
  feels a smooth mean wind while each anemometer records point turbulence of the measured intensity
  with an integral time scale drawn log-uniform in ``point_timescale_s`` (``felt_wind="smooth"``);
- the buffeting coefficients, uniform in ``buffeting_w`` and ``buffeting_u``;
- which orders of the amplitude limit it (``e_mix``, as the family's): both, A^2 alone (e1) or A^3
  alone (e2), with the family's probabilities. The campaign model's split of the nonlinear damping
  between A^2 and A^3 is what its regimes 3 and 4 rest on, and errors in the wind can bend it alike
  in every bootstrap replicate; twins that all took the model's own split would share its bias and
  could not see the flags it makes wrong (:func:`vivbench.validate.twin_aero.draw_aero` keeps the
  model's limiting at the measured amplitudes whichever orders carry it);
- a yaw effect on Y1 and C_L (:func:`vivbench.synth.draw_yaw_effect`: absent with probability
  2/5, else one of four shapes), applied along the measured yaw histories. The campaign model's
  curves already average the bridge's aerodynamics over the yaws it met, so Y1 and C_L are divided
  by the factor's mean over the measured yaws: averaged over the campaign's yaws, the twin's
  aerodynamics stay those drawn from the campaign model, while events and times of other yaws
  differ. A yaw effect whose mean factor over the measured yaws is below
  :data:`MIN_MEAN_YAW_FACTOR` (a bridge that could not have shown the vibration that was measured)
  is redrawn, up to :data:`YAW_TRIES` times, then left absent.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from vivbench.core.errors import InputError
from vivbench.synth.config import GeneratorConfig
from vivbench.synth.curves import YawFactor, scaled_bell
from vivbench.synth.family import E_MIX_SHARES, E_MIXES, draw_yaw_effect

__all__ = ["NuisancePriors", "Nuisances", "draw_nuisances", "apply_nuisances", "MIN_MEAN_YAW_FACTOR",
           "YAW_TRIES"]

#: Smallest mean yaw factor over the measured yaws that a drawn yaw effect may have.
MIN_MEAN_YAW_FACTOR = 0.25
#: Draws of a yaw effect before it is left absent.
YAW_TRIES = 20


def _interval(name: str, value, lo: float, hi: float, unit: str) -> tuple[float, float]:
    bad = f"{name} must be (low, high) with {lo:g} <= low <= high <= {hi:g}{unit}; got {value!r}"
    if not (isinstance(value, (list, tuple)) and len(value) == 2):
        raise InputError(bad)
    if not all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in value):
        raise InputError(bad)
    a, b = (float(x) for x in value)
    if not lo <= a <= b <= hi:
        raise InputError(bad)
    return a, b


@dataclass(frozen=True, kw_only=True)
class NuisancePriors:
    """Priors of what the twin cannot measure (module docstring); the defaults are the generator family's.

    Attributes
    ----------
    smooth_share : probability of the smooth felt wind with point turbulence at the anemometers, in [0, 1]
        (else the tributary-averaged felt wind)
    point_timescale_s : (low, high) s, within [0.5, 3600]; log-uniform prior of the point turbulence's
        integral time scale
    buffeting_w, buffeting_u : (low, high), within [0, 5]; uniform priors of the buffeting coefficients
    yaw_effect : draw a yaw effect on Y1 and C_L from the family's prior (False: never)
    e_mix_shares : probabilities of the orders that limit the amplitude, in the order of :data:`vivbench.synth.E_MIXES`
        (each in [0, 1], summing to 1; ``(1, 0, 0)``: always the campaign model's own split)
    """

    smooth_share: float = 0.5
    point_timescale_s: tuple[float, float] = (5.0, 60.0)
    buffeting_w: tuple[float, float] = (0.0, 1.2)
    buffeting_u: tuple[float, float] = (0.0, 0.4)
    yaw_effect: bool = True
    e_mix_shares: tuple[float, float, float] = E_MIX_SHARES

    def __post_init__(self) -> None:
        share = self.smooth_share
        if isinstance(share, bool) or not isinstance(share, (int, float)) or not 0.0 <= share <= 1.0:
            raise InputError(f"smooth_share must be a probability in [0, 1]; got {share!r}")
        object.__setattr__(self, "smooth_share", float(share))
        object.__setattr__(self, "point_timescale_s",
                           _interval("point_timescale_s", self.point_timescale_s, 0.5, 3600.0, " s"))
        for name in ("buffeting_w", "buffeting_u"):
            object.__setattr__(self, name, _interval(name, getattr(self, name), 0.0, 5.0, ""))
        if not isinstance(self.yaw_effect, bool):
            raise InputError(f"yaw_effect must be true or false; got {self.yaw_effect!r}")
        shares = self.e_mix_shares
        bad = (f"e_mix_shares must be {len(E_MIXES)} probabilities ({', '.join(E_MIXES)}) summing to 1; "
               f"got {shares!r}")
        if not (isinstance(shares, (list, tuple)) and len(shares) == len(E_MIXES)) or not all(
                isinstance(x, (int, float)) and not isinstance(x, bool) and 0.0 <= x <= 1.0 for x in shares):
            raise InputError(bad)
        if abs(sum(shares) - 1.0) > 1e-9:
            raise InputError(bad)
        object.__setattr__(self, "e_mix_shares", tuple(float(x) for x in shares))

    def to_dict(self) -> dict[str, Any]:
        """Plain data (JSON-ready)."""
        return {"smooth_share": self.smooth_share, "point_timescale_s": list(self.point_timescale_s),
                "buffeting_w": list(self.buffeting_w), "buffeting_u": list(self.buffeting_u),
                "yaw_effect": self.yaw_effect, "e_mix_shares": list(self.e_mix_shares)}


@dataclass(frozen=True, kw_only=True)
class Nuisances:
    """One twin draw's unmeasurable nuisances.

    Attributes
    ----------
    felt_wind : "tributary" or "smooth"
    point_timescale_s : s; the point turbulence's time scale (smooth only, else None)
    buffeting_w, buffeting_u : buffeting coefficients
    yaw : YawFactor or None
    yaw_shape : "absent" or the yaw factor's shape
    yaw_mean_factor : the yaw factor's mean over the measured yaws (1 when absent); Y1 and C_L are
        divided by it
    e_mix : one of :data:`vivbench.synth.E_MIXES`; the orders that limit the amplitude in the twin's aerodynamics
    """

    felt_wind: str
    point_timescale_s: float | None
    buffeting_w: float
    buffeting_u: float
    yaw: YawFactor | None
    yaw_shape: str
    yaw_mean_factor: float
    e_mix: str = "both"

    def to_dict(self) -> dict[str, Any]:
        """Plain data (JSON-ready): the values and the yaw factor's parameters of its shape."""
        yaw = None
        if self.yaw is not None:
            keys = {"cosine": ("exponent",), "gaussian": ("width_deg",), "sin2": ("strength",),
                    "logistic": ("cutoff_deg", "width_deg")}[self.yaw.shape]
            yaw = {"shape": self.yaw.shape, **{k: getattr(self.yaw, k) for k in keys}}
        return {"felt_wind": self.felt_wind, "point_timescale_s": self.point_timescale_s,
                "buffeting_w": self.buffeting_w, "buffeting_u": self.buffeting_u, "yaw": yaw,
                "yaw_shape": self.yaw_shape, "yaw_mean_factor": self.yaw_mean_factor, "e_mix": self.e_mix}


def draw_nuisances(priors: NuisancePriors, yaws, rng: np.random.Generator) -> Nuisances:
    """One draw of the nuisances (module docstring).

    Parameters
    ----------
    priors : NuisancePriors
    yaws : array_like, degrees; the measured yaws (the mirrored events' yaw knots, all events)
    rng : the draw's own random stream

    Returns
    -------
    Nuisances
    """
    yaws = np.asarray(yaws, dtype=float).ravel()
    yaws = yaws[np.isfinite(yaws)]
    if yaws.size == 0:
        raise InputError("the twin's nuisances need the measured yaws; none is finite")
    smooth = bool(rng.random() < priors.smooth_share)
    lo, hi = priors.point_timescale_s
    timescale = float(math.exp(rng.uniform(math.log(lo), math.log(hi)))) if smooth else None
    b_w = float(rng.uniform(*priors.buffeting_w))
    b_u = float(rng.uniform(*priors.buffeting_u))
    yaw, shape, mean = None, "absent", 1.0
    if priors.yaw_effect:
        for _ in range(YAW_TRIES):
            yaw, shape = draw_yaw_effect(rng)
            mean = 1.0 if yaw is None else float(np.mean(yaw(yaws)))
            if mean >= MIN_MEAN_YAW_FACTOR:
                break
        else:
            yaw, shape, mean = None, "absent", 1.0
    e_mix = E_MIXES[int(rng.choice(len(E_MIXES), p=np.asarray(priors.e_mix_shares)))]
    return Nuisances(felt_wind="smooth" if smooth else "tributary", point_timescale_s=timescale, buffeting_w=b_w,
                     buffeting_u=b_u, yaw=yaw, yaw_shape=shape, yaw_mean_factor=mean, e_mix=e_mix)


def apply_nuisances(generator: GeneratorConfig, nuisances: Nuisances) -> GeneratorConfig:
    """The twin's generator with the nuisances: felt wind, point turbulence of the generator's (measured)
    turbulence intensity, buffeting, and the yaw effect with Y1 and C_L divided by its mean factor."""
    wind = generator.wind
    over: dict[str, Any] = {"felt_wind": nuisances.felt_wind}
    if nuisances.felt_wind == "smooth":
        over.update(point_intensity=float(min(wind.turbulence.intensity, 0.5)),
                    point_timescale=float(nuisances.point_timescale_s))
    aero = generator.aero
    aero_over: dict[str, Any] = {"buffeting_w": nuisances.buffeting_w, "buffeting_u": nuisances.buffeting_u,
                                 "yaw": nuisances.yaw}
    if nuisances.yaw is not None:
        scale = 1.0 / nuisances.yaw_mean_factor
        aero_over.update(Y1=scaled_bell(aero.Y1, scale), C_L=scaled_bell(aero.C_L, scale))
    return dataclasses.replace(generator, wind=dataclasses.replace(wind, **over),
                               aero=dataclasses.replace(aero, **aero_over))
