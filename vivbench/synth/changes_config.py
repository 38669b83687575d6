"""Configuration of the bridge's slow changes that the wind does not carry: a frozen, keyword-only dataclass."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vivbench.core.errors import require

__all__ = ["ChangesConfig"]


@dataclass(frozen=True, kw_only=True)
class ChangesConfig:
    """Slow changes of the bridge that the wind does not carry (docs/concepts.md (no inverse crime)); none by default.

    Campaign time ``t_c`` is the time in seconds since the campaign's start
    (``CampaignConfig.start``; an event records its own start as
    ``EventSpec.campaign_time``), so a drift runs on continuously from one
    event to the next. Event numbers count from 1, as the event ids E001, E002, ...

    - Damping drift (temperature-like, deterministic so that it is continuous
      across events and the same for any worker count): the structural damping
      ratio is ``zeta(t_c) = zeta_e (1 + drift_amplitude sin(2 pi t_c / drift_period
      + drift_phase))``, where ``zeta_e`` is the event's damping ratio (the
      structure's, times ``step_damping_factor`` from the step on). With the
      default 24 h period and events that start at random hours, each event sees
      a different part of the cycle and the damping changes within an event.
    - Step between events: from event ``step_event`` on, the damping ratio is
      multiplied by ``step_damping_factor`` and the mass per unit length by
      ``step_mass_factor`` (the stiffness is unchanged, so the modal frequency
      is divided by sqrt(step_mass_factor)).
    - Retrofit of the deck aerodynamics: from event ``retrofit_event`` on, Y1,
      e1, e2 and C_L are multiplied by their ``retrofit_*_factor``; this scales the
      aerodynamic parts of the four orders r0..r3 by C_L, Y1, Y1 e1 and Y1 e2
      factors (the unlocked shedding and the buffeting are unchanged).

    The full simulation and the averaged truth use the same time-varying
    parameters, so the truth stays exact; the event file's ``/truth`` records
    them (``damping_ratio``, ``mass_factor``, ``aero_factor``) whenever
    :attr:`any` is true.

    Attributes
    ----------
    drift_amplitude : float, relative amplitude a of the damping drift, ``|a|`` < 1 (0: no drift)
    drift_period : float, s; period P of the drift (default 86400 s, a daily temperature cycle)
    drift_phase_deg : float, degrees; phase of the drift at campaign time 0
    step_event : int, first event number with the step (0: no step)
    step_damping_factor : float, > 0; damping ratio multiplier from the step on
    step_mass_factor : float, in [0.5, 2]; mass multiplier from the step on
    retrofit_event : int, first event number with the retrofit (0: no retrofit)
    retrofit_Y1_factor, retrofit_e1_factor, retrofit_e2_factor, retrofit_CL_factor : float, >= 0;
        multipliers of Y1, e1, e2 and C_L from the retrofit on
    """

    drift_amplitude: float = 0.0
    drift_period: float = 86400.0
    drift_phase_deg: float = 0.0
    step_event: int = 0
    step_damping_factor: float = 1.0
    step_mass_factor: float = 1.0
    retrofit_event: int = 0
    retrofit_Y1_factor: float = 1.0
    retrofit_e1_factor: float = 1.0
    retrofit_e2_factor: float = 1.0
    retrofit_CL_factor: float = 1.0

    def __post_init__(self) -> None:
        for name in ("drift_amplitude", "drift_period", "drift_phase_deg", "step_damping_factor", "step_mass_factor",
                     *self._RETROFIT):
            require(isinstance(getattr(self, name), (int, float)) and not isinstance(getattr(self, name), bool)
                   and math.isfinite(getattr(self, name)), f"{name} must be a finite number; got {getattr(self, name)!r}")
            object.__setattr__(self, name, float(getattr(self, name)))
        for name in ("step_event", "retrofit_event"):
            value = getattr(self, name)
            require(isinstance(value, int) and not isinstance(value, bool) and value >= 0,
                   f"{name} must be an event number >= 1 (0: none); got {value!r}")
        require(abs(self.drift_amplitude) < 1.0, f"drift_amplitude must be in (-1, 1); got {self.drift_amplitude}")
        require(self.drift_period >= 600.0, f"drift_period must be >= 600 s (a slow change); got {self.drift_period}")
        require(self.step_damping_factor > 0, f"step_damping_factor must be positive; got {self.step_damping_factor}")
        require(0.5 <= self.step_mass_factor <= 2.0, f"step_mass_factor must be in [0.5, 2]; got {self.step_mass_factor}")
        for name in self._RETROFIT:
            require(getattr(self, name) >= 0, f"{name} must be >= 0; got {getattr(self, name)}")
        require(self.step_event > 0 or (self.step_damping_factor == 1.0 and self.step_mass_factor == 1.0),
               "step_damping_factor and step_mass_factor need step_event >= 1 (the first event with the step)")
        require(self.retrofit_event > 0 or all(getattr(self, n) == 1.0 for n in self._RETROFIT),
               "retrofit_*_factor need retrofit_event >= 1 (the first event with the retrofit)")

    _RETROFIT = ("retrofit_Y1_factor", "retrofit_e1_factor", "retrofit_e2_factor", "retrofit_CL_factor")

    @property
    def any(self) -> bool:
        """True when some slow change is configured (the truth then records the parameters)."""
        return self != ChangesConfig()

    def damping_factor(self, number: int) -> float:
        """Multiplier of the structure's damping ratio for event ``number`` (before the drift)."""
        return self.step_damping_factor if self.step_event and number >= self.step_event else 1.0

    def mass_factor(self, number: int) -> float:
        """Multiplier of the mass per unit length for event ``number``."""
        return self.step_mass_factor if self.step_event and number >= self.step_event else 1.0

    def aero_factors(self, number: int) -> np.ndarray:
        """Multipliers of the aerodynamic parts of the orders 0..3 for event ``number``, shape (4,).

        (C_L, Y1, Y1 e1, Y1 e2) factors from the retrofit on, ones before it.
        """
        if not (self.retrofit_event and number >= self.retrofit_event):
            return np.ones(4)
        y1 = self.retrofit_Y1_factor
        return np.array([self.retrofit_CL_factor, y1, y1 * self.retrofit_e1_factor, y1 * self.retrofit_e2_factor])

    def drift(self, campaign_time) -> np.ndarray:
        """Relative damping drift 1 + a sin(2 pi t_c / P + phase) at campaign times t_c (s), same shape."""
        t = np.asarray(campaign_time, dtype=float)
        return 1.0 + self.drift_amplitude * np.sin(2.0 * np.pi * t / self.drift_period + np.deg2rad(self.drift_phase_deg))
