"""Configuration of the synthetic bridge: frozen, keyword-only dataclasses.

Every generated event stores the full configuration as JSON (``/truth``
attribute ``config_json``), and a configuration can be read from TOML.
Defaults describe a 1650 m twin-box suspension bridge whose first vertical
mode (0.327 Hz) locks in with vortex shedding between about 5.5 and 10.5 m/s
of wind perpendicular to the span (docs/concepts.md (the bridge and the wind)-2.2).
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from vivbench.core.toml import load_toml
from vivbench.synth.curves import (
    Constant,
    Curve,
    GaussianBell,
    LogisticStep,
    Polynomial,
    YawFactor,
    curve_from_data,
)
from vivbench.core.errors import require
from vivbench.io.field_wind import WIND_RULES
from vivbench.synth.changes_config import ChangesConfig
from vivbench.synth.sensor_config import DefectConfig, SensorConfig
from vivbench.synth.turbulence import TurbulenceConfig

__all__ = [
    "Polynomial",
    "bell_polynomial",
    "StructureConfig",
    "AeroConfig",
    "AERO_MODES",
    "WindConfig",
    "FELT_WIND_MODES",
    "SensorConfig",
    "DefectConfig",
    "ChangesConfig",
    "GeneratorConfig",
    "GENERATOR_MODES",
    "DEFAULT_MODE",
    "DEFAULT_LOCK_IN",
    "config_to_dict",
    "config_from_dict",
    "load_config",
]


def bell_polynomial(peak: float, center: float, half_width: float) -> Polynomial:
    """peak * (1 - ((U - center) / half_width)^2): positive on center +- half_width, negative outside."""
    require(half_width > 0, f"half_width must be positive; got {half_width}")
    a = peak / half_width**2
    return Polynomial(coefficients=(peak - a * center**2, 2 * a * center, -a))


_Y1 = bell_polynomial(20.0, 8.0, 2.5)
E1, E2 = 28.0, 400.0


def _linear(value: float, slope: float, center: float) -> Polynomial:
    """value * (1 + slope (U - center))."""
    return Polynomial(coefficients=(value * (1.0 - slope * center), value * slope))


@dataclass(frozen=True, kw_only=True)
class StructureConfig:
    """One vertical bending mode seen at n >= 1 deck sections (docs/concepts.md (the bridge and the wind)).

    The number of instrumented sections is ``len(mode_shape)``; the sections are
    named S1..Sn and sit at k / (n + 1) of the span (1/4, 1/2, 3/4 for the
    default three). A TOML configuration for two sections says, for example,
    ``[structure]`` ``mode_shape = [0.866, 0.866]`` and
    ``tributary_lengths = [825.0, 825.0]``.

    Attributes
    ----------
    frequency : float, Hz
    damping_ratio : float, structural damping ratio zeta
    mode_shape : tuple of float, phi_k at S1..Sn (positive: the sections move in phase);
        its length is the number of sections
    span_length : float, m; section k of n at k / (n + 1) of it
    tributary_lengths : tuple of float, m; strip lengths L_k of the sections, one per section
    depth : float, m; deck depth D
    mass : float, kg/m; equivalent mass per unit length
    air_density : float, kg/m^3
    """

    frequency: float = 0.327
    damping_ratio: float = 0.003
    mode_shape: tuple[float, ...] = (0.707, 1.0, 0.707)
    span_length: float = 1650.0
    tributary_lengths: tuple[float, ...] = (550.0, 550.0, 550.0)
    depth: float = 3.5
    mass: float = 2.77e4
    air_density: float = 1.225

    def __post_init__(self) -> None:
        object.__setattr__(self, "mode_shape", tuple(float(x) for x in self.mode_shape))
        object.__setattr__(self, "tributary_lengths", tuple(float(x) for x in self.tributary_lengths))
        require(0.01 <= self.frequency <= 20.0, f"frequency must be in [0.01, 20] Hz; got {self.frequency}")
        require(0.0 <= self.damping_ratio < 0.2, f"damping_ratio must be in [0, 0.2); got {self.damping_ratio}")
        require(len(self.mode_shape) >= 1, "mode_shape needs one value per section (at least one); got none")
        require(all(x > 0 for x in self.mode_shape),
               f"mode_shape values must be positive (sections in phase, as the truth formulas assume); got {self.mode_shape}")
        n = len(self.mode_shape)
        require(len(self.tributary_lengths) == n,
               f"tributary_lengths needs one value per section ({n}, as mode_shape); got {len(self.tributary_lengths)}")
        require(all(x > 0 for x in self.tributary_lengths),
               f"tributary_lengths must be positive (m); got {self.tributary_lengths}")
        for name in ("span_length", "depth", "mass", "air_density"):
            require(getattr(self, name) > 0, f"{name} must be positive; got {getattr(self, name)}")

    @property
    def omega(self) -> float:
        return 2.0 * math.pi * self.frequency

    @property
    def n_sections(self) -> int:
        """Number of instrumented sections, ``len(mode_shape)``."""
        return len(self.mode_shape)

    @property
    def sections(self) -> tuple[str, ...]:
        """Section labels S1..Sn."""
        return tuple(f"S{k + 1}" for k in range(self.n_sections))

    @property
    def positions(self) -> np.ndarray:
        """Spanwise positions of S1..Sn, m, shape (n,): k / (n + 1) of the span."""
        n = self.n_sections
        return self.span_length * (np.arange(1, n + 1) / (n + 1))

    @property
    def participation(self) -> np.ndarray:
        """beta_k = L_k phi_k / sum_l L_l phi_l^2 (1/m of modal coordinate per m of span)."""
        phi = np.array(self.mode_shape)
        L = np.array(self.tributary_lengths)
        return L * phi / np.sum(L * phi**2)


_AERO_CURVES = ("Y1", "e1", "e2", "Y2", "C_L")
AERO_MODES = ("in_library", "realistic")


@dataclass(frozen=True, kw_only=True)
class AeroConfig:
    """Generalised Simiu-Scanlan force per section (docs/concepts.md (aeroelastic force)).

    ``Y1``, ``e1``, ``e2``, ``Y2`` and ``C_L`` are curves of the local mean
    perpendicular wind speed U (m/s) (:mod:`vivbench.synth.curves`): either
    polynomials in U or non-polynomial shapes in the reduced velocity
    Ur = U / (f1 D) (Gaussian or Lorentzian bells, logistic steps, constants).
    ``yaw``, when given, makes some of them depend on the wind's angle to the
    span as well.

    Two named modes (docs/concepts.md (no inverse crime)), each a constructor:

    - :meth:`realistic` (the defaults, ``AeroConfig()``): a box girder's functions
      of reduced velocity that are not polynomials (a Gaussian lock-in bell for Y1
      centred near Ur = 1/St, logistic e1 and e2, a Gaussian bell of C_L >= 0) and
      a Gaussian yaw factor, so that the truth lies outside the identification's
      model class (no inverse crime).
    - :meth:`in_library`: polynomials in U that
      keep the averaged truth inside the A^i U^j library, so that an exact
      coefficient matrix exists when deg(U Y1 e) <= 5 and deg(U^2 C_L) <= 5.
      The nonlinear e1 and e2 are positive and linear in U (a Simiu-Scanlan
      lambda with a gentle trend): the ``|y|`` term (regime 3) dominates the
      plateaus below the centre of lock-in and the cubic term (regime 4) those
      above it. Outside lock-in, where Y1 < 0, the same terms slightly weaken
      the aerodynamic damping at large amplitude, as in the classical model.
      For exact-recovery tests.

    Attributes
    ----------
    Y1 : aerodynamic damping derivative; bell-shaped over lock-in, negative outside
    e1 : coefficient of the ``|y/D|`` term (gives A^2 in the amplitude equation)
    e2 : Simiu-Scanlan lambda, coefficient of (y/D)^2 (gives A^3)
    Y2 : aerodynamic stiffness derivative (shifts the frequency only)
    C_L : lift coefficient of the shedding force locked to the motion (>= 0 over the wind range;
        checked everywhere for the non-polynomial shapes)
    yaw : YawFactor or None; dependence on the wind's angle to the span (None: none)
    strouhal : Strouhal number St; unlocked shedding runs at St U / D
    cl_unlocked : amplitude of the unlocked (Strouhal-frequency) lift coefficient; it is
        faded out near resonance with the mode, so it averages out of the amplitude equation
    lock_bandwidth : float, Hz; detuning ``|St U/D - f1|`` below which shedding counts as locked
    buffeting_u, buffeting_w : buffeting force F = rho U D (b_u u' + b_w w') per unit length
    """

    Y1: Curve = GaussianBell(peak=20.0, center=7.0, width=1.1, baseline=-4.0)
    e1: Curve = LogisticStep(start=36.0, end=20.0, center=7.0, width=1.5)
    e2: Curve = LogisticStep(start=300.0, end=520.0, center=7.0, width=1.5)
    Y2: Curve = Constant(value=0.5)
    C_L: Curve = GaussianBell(peak=0.04, center=7.0, width=2.0, baseline=0.003)
    yaw: YawFactor | None = YawFactor(shape="gaussian", width_deg=20.0)
    strouhal: float = 0.143
    cl_unlocked: float = 0.05
    lock_bandwidth: float = 0.03
    buffeting_u: float = 0.0
    buffeting_w: float = 0.6

    def __post_init__(self) -> None:
        for name in _AERO_CURVES:
            object.__setattr__(self, name, curve_from_data(getattr(self, name), name))
        if isinstance(self.yaw, dict):
            object.__setattr__(self, "yaw", YawFactor(**_tuples(self.yaw)))
        require(self.yaw is None or isinstance(self.yaw, YawFactor),
               f"yaw must be a YawFactor table (shape, exponent, width_deg, applies_to) or absent; got {self.yaw!r}")
        if not isinstance(self.C_L, Polynomial):
            require(self.C_L.lower_bound >= 0,
                   f"C_L must be >= 0 at every wind speed; {self.C_L.kind} C_L reaches {self.C_L.lower_bound}")
        require(0.01 <= self.strouhal <= 1.0, f"strouhal must be in [0.01, 1]; got {self.strouhal}")
        require(self.cl_unlocked >= 0, f"cl_unlocked must be >= 0; got {self.cl_unlocked}")
        require(self.lock_bandwidth > 0, f"lock_bandwidth must be positive (Hz); got {self.lock_bandwidth}")
        require(self.buffeting_u >= 0 and self.buffeting_w >= 0, "buffeting coefficients must be >= 0")

    @classmethod
    def in_library(cls, **overrides) -> AeroConfig:
        """The ``in_library`` mode: polynomials in U, no yaw factor; keywords override.

        Y1 is the quadratic bell 20 (1 - ((U - 8) / 2.5)^2) (lock-in 5.5-10.5 m/s), e1 and
        e2 are linear in U (28 and 400 at 8 m/s, slopes -0.12 and +0.12 per m/s relative),
        Y2 = 0.5 and C_L the quadratic bell 0.04 (1 - ((U - 8) / 8)^2). The averaged truth
        then has an exact coefficient matrix over the library.
        """
        base = dict(Y1=_Y1, e1=_linear(E1, -0.12, 8.0), e2=_linear(E2, 0.12, 8.0),
                    Y2=Polynomial(coefficients=(0.5,)), C_L=bell_polynomial(0.04, 8.0, 8.0), yaw=None)
        base.update(overrides)
        return cls(**base)

    @classmethod
    def realistic(cls, **overrides) -> AeroConfig:
        """The ``realistic`` mode (the defaults, ``AeroConfig()``): non-polynomial functions of reduced velocity typical of a box girder.

        Reduced velocities Ur = U / (f1 D); with the default structure (f1 = 0.327 Hz,
        D = 3.5 m) Ur = U / (1.14 m/s). Y1 is a Gaussian bell of peak 20 centred on
        Ur0 = 7.0 (about 1/St, i.e. 8 m/s) with width 1.1, over a baseline of -4:
        positive for Ur in about [4.9, 9.1] (lock-in 5.6-10.4 m/s), aerodynamic
        damping outside. e1 falls from 36 to 20 and e2 rises from 300 to 520
        across lock-in (logistic steps, centre 7.0, width 1.5), so the ``|y|`` term
        leads below the centre and the cubic term above it, as in the
        ``in_library`` mode. C_L is a Gaussian bell (0.04 at Ur = 7.0, width 2.0)
        over a floor of 0.003, >= 0 everywhere. Y1 and C_L fall off with the yaw
        angle as exp(-psi^2 / (2 (20 deg)^2)). Keywords override any of these.
        """
        return cls(**overrides)

    @classmethod
    def from_mode(cls, mode: str, **overrides) -> AeroConfig:
        """The named mode ``"in_library"`` or ``"realistic"`` with keyword overrides."""
        require(mode in AERO_MODES, f"aero mode must be one of {list(AERO_MODES)}; got {mode!r}")
        return cls.in_library(**overrides) if mode == "in_library" else cls.realistic(**overrides)

    def polynomials(self) -> dict[str, Polynomial] | None:
        """Y1, e1, e2, C_L as polynomials in U, or None when one is not a polynomial or a yaw factor applies."""
        if self.yaw is not None:
            return None
        polys = {name: getattr(self, name).as_polynomial() for name in ("Y1", "e1", "e2", "C_L")}
        return None if any(p is None for p in polys.values()) else polys

    @property
    def exact_in_library(self) -> bool:
        """True when the averaged truth is a combination of A^i U^j, i <= 3, j <= 5."""
        p = self.polynomials()
        if p is None:
            return False
        d1 = 1 + p["Y1"].degree
        return (d1 <= 5 and d1 + p["e1"].degree <= 5 and d1 + p["e2"].degree <= 5
                and 2 + p["C_L"].degree <= 5)


FELT_WIND_MODES = ("anemometer", "tributary", "smooth")
"""Values of ``WindConfig.felt_wind``; ``"tributary"`` (the default) is the ``realistic`` mode,
``"anemometer"`` the ``in_library`` mode; ``"smooth"`` is the other kind of errors-in-variables
(a smooth felt wind, point turbulence at the anemometers)."""


@dataclass(frozen=True, kw_only=True)
class WindConfig:
    """Mean wind scripts and anemometers (docs/concepts.md (the bridge and the wind)).

    Attributes
    ----------
    span_azimuth_deg : direction of the span axis, degrees from north
    section_offset : rms relative offset of each section's mean wind (fixed per event)
    section_wander : rms relative slow wander of each section's mean wind
    slow_timescales : (min, max) time scales of the slow random wind variation, s
    speed_wander : rms of the slow random part of the mean speed, m/s
    direction_wander_deg : rms of the slow random direction change, degrees
    direction_offset_deg : (min, max) of the event's mean yaw from perpendicular, degrees
    min_speed : lower bound of every scripted mean perpendicular speed, m/s
    felt_cutoff_hz : Hz; turbulence slower than this acts on the deck as part of its
        mean wind: the aeroelastic force and the truth use the scripted mean plus
        the turbulence low-passed here (zero-phase Butterworth), the same time
        scale as the identification's mean-wind filter (1/60 Hz by default)
    turbulence : the turbulence field (spectral representation)
    anemometer_rate : Hz; resolution, m/s; noise : relative rms error
    felt_wind : which wind the deck feels (docs/concepts.md (no inverse crime)):

        - ``"tributary"`` (the default, the ``realistic`` mode): the turbulence is simulated at
          ``points_per_section`` points spread evenly over each section's tributary length
          and at the anemometers, with Davenport coherence between all of them. Section k's
          deck (buffeting and, low-passed at ``felt_cutoff_hz``, the U_k of the aeroelastic
          force and of the truth) feels the average over its points; each anemometer records
          its single point's full turbulence plus the sensor errors. The identification's U
          then carries realistic errors-in-variables.
        - ``"anemometer"`` (the ``in_library`` mode): each section's deck feels its
          anemometer's own turbulence; U_k is the anemometer's wind low-passed at
          ``felt_cutoff_hz`` (before the sensor errors), so the identification's U
          differs from the truth only by sensor noise and filter edges.
        - ``"smooth"``: the deck feels the smooth scripted mean wind (with its slow wander and
          section offsets, but no turbulence): U_k of the aeroelastic force and of the truth. A
          turbulence field at the sections (as in ``"anemometer"`` mode) drives the buffeting
          only, and the anemometers do not record it. Each anemometer records the mean wind plus
          its own point turbulence: independent exponentially correlated (first-order,
          Ornstein-Uhlenbeck) processes per anemometer and component, of integral time scale
          ``point_timescale`` and rms ``point_intensity`` times the section's mean horizontal
          speed for u' (``turbulence.ratio_v`` and ``ratio_w`` times that for v' and w'), plus the
          sensor errors. The truth does not depend on ``point_intensity`` nor ``point_timescale``.
    points_per_section : int, 1..64; points over each tributary length (``"tributary"`` only)
    anemometer_offset : float, m; spanwise distance of each anemometer from its section's
        position (``"tributary"`` only). The field lives on one horizontal line, so an
        anemometer on a mast a few metres above the deck is represented by a point this
        far along the span (same Davenport decay); 0 puts it at the section's position.
    point_intensity : float, in [0, 0.5]; turbulence intensity of the anemometers' point
        turbulence (``"smooth"`` only)
    point_timescale : float, s, in [0.5, 3600]; its integral time scale (``"smooth"`` only)
    yaw_swing_deg : float, degrees, in [0, 20]; amplitude of a direction swing that every event
        shares: the yaw of every event follows its mean plus
        ``yaw_swing_deg sin(2 pi t / yaw_swing_period)`` (t from the event's start) plus the
        random wander. 0: no swing
    yaw_swing_period : float, s, >= 60; period of the shared swing
    event_yaw_scale : float, in [0, 3]; multiplies each event's scripted mean yaw (the campaign
        scripts draw it within +-12 degrees): 2.5 spreads the events' mean yaws over +-30 degrees
    shared_yaw_deg : float or None, degrees, within +-45; when set, every event's mean yaw is this
        value instead of its script's, so that (with a swing and little wander) the yaw is the
        same function of time in every event: yaw and time within an event are confounded.
        None: each event keeps its script's mean yaw
    anemometer_span : tuple of float or None; positions of the anemometers along the span as
        fractions of ``span_length`` (each in [0, 1], distinct; ``(0.5,)``: one anemometer at
        mid-span). None (default): one anemometer per section, at the section (plus
        ``anemometer_offset``). When given, the turbulence field is simulated at these points
        instead (their mean wind is the sections' interpolated along the span), each records
        as an anemometer does, and the event's wind at every section is taken from them by
        ``wind_rule`` as field import does (:func:`vivbench.io.span_weights`); the event
        records each section's distance to its nearest anemometer as ``wind_distance_m_<section>``.
        The deck still feels its own section's wind. Not with ``felt_wind="anemometer"`` (there
        the deck feels its anemometer's turbulence by definition) nor with a nonzero
        ``anemometer_offset``
    wind_rule : {"nearest", "interpolation"}; the rule of ``anemometer_span``

    The fields from ``point_intensity`` on are left out of :func:`config_to_dict` while they
    hold their defaults, so configurations that do not use them save as before they existed.
    """

    span_azimuth_deg: float = 30.0
    section_offset: float = 0.02
    section_wander: float = 0.01
    slow_timescales: tuple[float, float] = (600.0, 3600.0)
    speed_wander: float = 0.25
    direction_wander_deg: float = 4.0
    direction_offset_deg: tuple[float, float] = (-15.0, 15.0)
    min_speed: float = 2.5
    felt_cutoff_hz: float = 1.0 / 60.0
    turbulence: TurbulenceConfig = field(default_factory=TurbulenceConfig)
    anemometer_rate: float = 32.0
    resolution: float = 0.01
    noise: float = 0.01
    felt_wind: str = "tributary"
    points_per_section: int = 5
    anemometer_offset: float = 0.0
    point_intensity: float = 0.07
    point_timescale: float = 10.0
    yaw_swing_deg: float = 0.0
    yaw_swing_period: float = 1800.0
    event_yaw_scale: float = 1.0
    shared_yaw_deg: float | None = None
    anemometer_span: tuple[float, ...] | None = None
    wind_rule: str = "nearest"

    def __post_init__(self) -> None:
        if isinstance(self.turbulence, dict):
            object.__setattr__(self, "turbulence", TurbulenceConfig(**_tuples(self.turbulence)))
        object.__setattr__(self, "slow_timescales", tuple(float(x) for x in self.slow_timescales))
        object.__setattr__(self, "direction_offset_deg", tuple(float(x) for x in self.direction_offset_deg))
        require(0 <= self.span_azimuth_deg < 360, f"span_azimuth_deg must be in [0, 360); got {self.span_azimuth_deg}")
        lo, hi = self.slow_timescales
        require(0 < lo <= hi, f"slow_timescales must be (min, max) with 0 < min <= max seconds; got {self.slow_timescales}")
        dlo, dhi = self.direction_offset_deg
        require(-60 <= dlo <= dhi <= 60, f"direction_offset_deg must be (min, max) within [-60, 60]; got {self.direction_offset_deg}")
        for name in ("section_offset", "section_wander", "speed_wander", "direction_wander_deg", "noise"):
            require(getattr(self, name) >= 0, f"{name} must be >= 0; got {getattr(self, name)}")
        require(self.min_speed > 0, f"min_speed must be positive; got {self.min_speed}")
        require(self.anemometer_rate > 0, f"anemometer_rate must be positive; got {self.anemometer_rate}")
        require(0 < self.felt_cutoff_hz < self.anemometer_rate / 2,
               f"felt_cutoff_hz must be in (0, anemometer_rate/2) Hz; got {self.felt_cutoff_hz}")
        require(self.resolution >= 0, f"resolution must be >= 0; got {self.resolution}")
        require(self.felt_wind in FELT_WIND_MODES,
               f"felt_wind must be one of {', '.join(repr(m) for m in FELT_WIND_MODES)}; got {self.felt_wind!r}")
        pps = self.points_per_section
        require(not isinstance(pps, (bool, np.bool_)) and isinstance(pps, (int, np.integer)) and 1 <= pps <= 64,
               f"points_per_section must be an integer from 1 to 64; got {pps!r}")
        object.__setattr__(self, "points_per_section", int(pps))
        try:
            offset = float(self.anemometer_offset)
        except (TypeError, ValueError):
            offset = float("nan")
        require(math.isfinite(offset) and not isinstance(self.anemometer_offset, (bool, np.bool_)),
               f"anemometer_offset must be a finite distance (m); got {self.anemometer_offset!r}")
        object.__setattr__(self, "anemometer_offset", offset)
        for name in ("point_intensity", "point_timescale", "yaw_swing_deg", "yaw_swing_period", "event_yaw_scale"):
            value = getattr(self, name)
            require(isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value),
                   f"{name} must be a finite number; got {value!r}")
            object.__setattr__(self, name, float(value))
        require(0 <= self.point_intensity <= 0.5,
               f"point_intensity must be in [0, 0.5] (a turbulence intensity); got {self.point_intensity}")
        require(0.5 <= self.point_timescale <= 3600,
               f"point_timescale must be in [0.5, 3600] s; got {self.point_timescale}")
        require(0 <= self.yaw_swing_deg <= 20, f"yaw_swing_deg must be in [0, 20] degrees; got {self.yaw_swing_deg}")
        require(0 <= self.event_yaw_scale <= 3, f"event_yaw_scale must be in [0, 3]; got {self.event_yaw_scale}")
        require(self.yaw_swing_period >= 60, f"yaw_swing_period must be >= 60 s; got {self.yaw_swing_period}")
        if self.shared_yaw_deg is not None:
            value = self.shared_yaw_deg
            require(isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
                   and abs(value) <= 45,
                   f"shared_yaw_deg must be None or a number of degrees within +-45; got {value!r}")
            object.__setattr__(self, "shared_yaw_deg", float(value))
        self._check_anemometer_span()

    def _check_anemometer_span(self) -> None:
        require(self.wind_rule in WIND_RULES,
                f"wind_rule must be one of {', '.join(repr(r) for r in WIND_RULES)}; got {self.wind_rule!r}")
        span = self.anemometer_span
        if span is None:
            return
        bad = (f"anemometer_span must be None (one anemometer per section) or one or more distinct "
               f"fractions of the span length in [0, 1], e.g. [0.5] for mid-span; got {span!r}")
        require(isinstance(span, (list, tuple)) and len(span) >= 1, bad)
        require(all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) and 0 <= x <= 1
                    for x in span) and len(set(span)) == len(span), bad)
        object.__setattr__(self, "anemometer_span", tuple(float(x) for x in span))
        require(self.felt_wind != "anemometer",
                "anemometer_span needs felt_wind 'tributary' or 'smooth': with 'anemometer' the deck feels its "
                "section's own anemometer, so there must be one per section")
        require(self.anemometer_offset == 0.0,
                f"anemometer_span places the anemometers itself; anemometer_offset must then be 0, got "
                f"{self.anemometer_offset}")


@dataclass(frozen=True, kw_only=True)
class GeneratorConfig:
    """Everything the generator needs besides the event script and the seed.

    The defaults are the ``realistic`` mode (docs/concepts.md (no inverse crime)): ``GeneratorConfig()`` equals
    :meth:`realistic` and its fields are their classes' defaults (``AeroConfig()`` and
    ``WindConfig()`` are the realistic aerodynamics and the tributary-averaged felt wind).
    :meth:`in_library` gives the polynomial truth inside the identification's model class.

    Attributes
    ----------
    integration_step : s; RK4 step of the full modal simulation
    truth_step : s; time step of the saved truth grid
    initial_amplitude : m; modal amplitude at t = 0 (full and averaged models alike)
    tau : regime threshold of docs/concepts.md (regimes)
    changes : slow changes of the bridge that the wind does not carry (none by default)
    """

    structure: StructureConfig = field(default_factory=StructureConfig)
    aero: AeroConfig = field(default_factory=AeroConfig)
    wind: WindConfig = field(default_factory=WindConfig)
    sensors: SensorConfig = field(default_factory=SensorConfig)
    integration_step: float = 0.02
    truth_step: float = 0.5
    initial_amplitude: float = 0.002
    tau: float = 0.2
    changes: ChangesConfig = field(default_factory=ChangesConfig)

    def __post_init__(self) -> None:
        for name, cls in (("structure", StructureConfig), ("aero", AeroConfig), ("wind", WindConfig), ("sensors", SensorConfig),
                          ("changes", ChangesConfig)):
            value = getattr(self, name)
            if isinstance(value, dict):
                object.__setattr__(self, name, _aero_from_dict(value) if name == "aero" else cls(**_tuples(value)))
        # a lighter deck after a mass step vibrates faster: the step must resolve that mode too
        period = math.sqrt(min(1.0, self.changes.step_mass_factor)) / self.structure.frequency
        require(0 < self.integration_step <= period / 20,
               f"integration_step must be in (0, T/20] = (0, {period / 20:.4g}] s for the mode; got {self.integration_step}")
        require(0 < self.truth_step <= 5.0, f"truth_step must be in (0, 5] s; got {self.truth_step}")
        require(self.initial_amplitude > 0, f"initial_amplitude must be positive (m); got {self.initial_amplitude}")
        require(0 < self.tau < 1, f"tau must be in (0, 1); got {self.tau}")
        zeta_max = self.structure.damping_ratio * max(1.0, self.changes.step_damping_factor) * (1 + abs(self.changes.drift_amplitude))
        require(zeta_max < 0.2, f"the changed damping ratio must stay below 0.2; it reaches {zeta_max:.4g}")

    @classmethod
    def in_library(cls, **overrides) -> GeneratorConfig:
        """The ``in_library`` mode (docs/concepts.md (no inverse crime)): polynomial aerodynamics in U, the deck feels the anemometer's wind.

        The truth lies in the identification's model class (an exact coefficient matrix
        exists); for exact-recovery tests. Keywords override fields: ``aero`` and ``wind``
        given as dicts override the mode's values key by key; given as instances they
        replace them (so ``wind=WindConfig(...)`` must say ``felt_wind="anemometer"`` to
        stay in this mode).
        """
        return cls.from_mode("in_library", **overrides)

    @classmethod
    def realistic(cls, **overrides) -> GeneratorConfig:
        """The ``realistic`` mode (docs/concepts.md (no inverse crime), the default): the truth lies outside the identification's model class.

        ``aero`` is :meth:`AeroConfig.realistic` (non-polynomial functions of the reduced
        velocity with a yaw factor) and ``wind`` is ``WindConfig(felt_wind="tributary")``
        (the deck feels the tributary-averaged wind of a spatially resolved field; each
        anemometer is one point). Slow changes stay off (``changes`` is a separate option).
        ``GeneratorConfig.realistic()`` equals ``GeneratorConfig()``.

        Keywords override fields. ``aero`` and ``wind`` given as dicts (as read from
        TOML) override the mode's values key by key; given as instances they replace them.
        """
        return cls.from_mode("realistic", **overrides)

    @classmethod
    def from_mode(cls, mode: str, **overrides) -> GeneratorConfig:
        """The named mode ``"in_library"`` or ``"realistic"`` with keyword overrides (see :meth:`realistic`)."""
        require(mode in GENERATOR_MODES, f"mode must be one of {list(GENERATOR_MODES)}; got {mode!r}")
        aero, wind = overrides.pop("aero", {}), overrides.pop("wind", {})
        if isinstance(aero, dict):
            aero = _aero_from_dict(aero, default_mode=mode)
        if isinstance(wind, dict):
            wind = WindConfig(**_tuples({"felt_wind": _FELT_WIND_OF_MODE[mode], **wind}))
        return cls(aero=aero, wind=wind, **overrides)

    @property
    def mode(self) -> str:
        """The named mode this configuration belongs to, implied by its saved values.

        ``"in_library"`` when the aerodynamic functions are polynomials in U without a
        yaw factor and the deck feels the anemometer's wind; ``"realistic"`` when the
        functions are not polynomials (or depend on yaw) and the deck feels the
        tributary-averaged wind; ``"mixed"`` otherwise. Slow changes do not enter. The
        event file's ``config_json`` holds both, so the mode of any event can be recovered.
        """
        aero = "in_library" if self.aero.polynomials() is not None else "realistic"
        wind = "in_library" if self.wind.felt_wind == "anemometer" else "realistic"
        return aero if aero == wind else "mixed"

    @property
    def lock_in(self) -> tuple[float, float] | None:
        """The lock-in range in m/s: where Y1 > 0 around its maximum, wind perpendicular to the span.

        Evaluated for this structure's frequency and depth (curves of reduced velocity)
        on 0.05-60 m/s, the ends refined by linear interpolation. None when Y1 <= 0
        everywhere (no self-excitation). ``(5.5, 10.5)`` for the ``in_library`` mode, about
        ``(5.6, 10.4)`` for the ``realistic`` default.
        """
        U = np.arange(0.05, 60.0, 0.005)
        y = self.aero.Y1.at_wind(U, self.structure.frequency, self.structure.depth)
        k = int(np.argmax(y))
        if not y[k] > 0:
            return None
        neg = np.flatnonzero(y <= 0)
        below, above = neg[neg < k], neg[neg > k]
        lo = U[0] if below.size == 0 else _zero_between(U, y, below[-1])
        hi = U[-1] if above.size == 0 else _zero_between(U, y, above[0] - 1)
        return float(lo), float(hi)


GENERATOR_MODES = AERO_MODES
"""Named generator modes (docs/concepts.md (no inverse crime)); ``GeneratorConfig()`` is the ``realistic`` mode."""
DEFAULT_MODE = "realistic"
"""The mode of ``GeneratorConfig()``, of a configuration file without ``mode`` and of ``vivbench synth``."""
_FELT_WIND_OF_MODE = {"in_library": "anemometer", "realistic": "tributary"}
DEFAULT_LOCK_IN = (5.5, 10.5)
"""Lock-in range (m/s) of the ``in_library`` bridge, for which the campaign scripts were designed
(the ``realistic`` default's, about 5.6-10.4 m/s, is close enough to keep them)."""


def _zero_between(U: np.ndarray, y: np.ndarray, i: int) -> float:
    """Linear-interpolated zero of y between samples i and i + 1 (a sign change)."""
    return U[i] + (U[i + 1] - U[i]) * y[i] / (y[i] - y[i + 1])


def _tuples(d: dict) -> dict:
    """TOML and JSON give lists; the dataclasses hold tuples."""
    return {k: tuple(v) if isinstance(v, list) else v for k, v in d.items()}


# Fields added after configurations were first saved: left out of the saved form while they hold
# their defaults, so that a configuration which does not use them saves (and hashes) as before.
_LATER_FIELDS = {
    "YawFactor": ("strength", "cutoff_deg"),
    "WindConfig": ("point_intensity", "point_timescale", "yaw_swing_deg", "yaw_swing_period", "event_yaw_scale",
                   "shared_yaw_deg", "anemometer_span", "wind_rule"),
}


def _plain(obj: Any) -> Any:
    """Dataclasses as dicts in field order (every field, None included, but later fields at their
    defaults), tuples as lists."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        later = _LATER_FIELDS.get(type(obj).__name__, ())
        return {f.name: _plain(getattr(obj, f.name)) for f in dataclasses.fields(obj)
                if not (f.name in later and getattr(obj, f.name) == f.default)}
    if isinstance(obj, (list, tuple)):
        return [_plain(x) for x in obj]
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    return obj


# Keys that configurations saved before the generator's default became the realistic
# mode left out while they held their in_library values (the default then): the
# felt-wind keys of WindConfig, together, and an absent (None) aero yaw factor.
# config_from_dict restores these values for such saved forms (see _restore_legacy).
_WIND_LEGACY = {"felt_wind": "anemometer", "points_per_section": 5, "anemometer_offset": 0.0}
_SAVED_KEYS = frozenset({"structure", "aero", "wind", "sensors", "integration_step", "truth_step",
                         "initial_amplitude", "tau"})


def _restore_legacy(data: dict[str, Any]) -> dict[str, Any]:
    """The in_library values of the keys an old saved form left out (see :func:`config_from_dict`)."""
    if "mode" in data or not _SAVED_KEYS <= set(data):
        return data
    aero, wind = data["aero"], data["wind"]
    if not (isinstance(aero, dict) and isinstance(wind, dict)):
        return data
    data = dict(data)
    if "yaw" not in aero and "mode" not in aero and set(_AERO_CURVES) <= set(aero):
        data["aero"] = {**aero, "yaw": None}
    if "felt_wind" not in wind:
        data["wind"] = {**_WIND_LEGACY, **wind}
    return data


def config_to_dict(config) -> dict[str, Any]:
    """Plain-data form (JSON-ready) of any configuration dataclass.

    Every field is written, so that the form reads back as the same configuration
    whatever the defaults: curves of reduced velocity carry their ``kind``,
    polynomials are written as ``{"coefficients": [...]}``, an absent yaw factor
    as ``"yaw": null`` (``yaw = false`` in a TOML file) and the felt-wind keys of
    ``WindConfig`` always. The omissions: a generator configuration without
    slow changes leaves out its ``changes`` section (whose default is no change),
    and the options added later (the yaw factor's ``strength`` and ``cutoff_deg``, the
    wind's point turbulence and shared yaw course) are left out while they hold their
    defaults, so files generated without them are the same as before the options existed.
    """
    data = json.loads(json.dumps(_plain(config)))
    if isinstance(config, GeneratorConfig) and not config.changes.any:
        del data["changes"]
    return data


_SECTIONS = {"structure": StructureConfig, "aero": AeroConfig, "wind": WindConfig, "sensors": SensorConfig,
             "changes": ChangesConfig}


def config_from_dict(data: dict[str, Any]) -> GeneratorConfig:
    """Inverse of :func:`config_to_dict`; unknown keys are an error.

    An optional top-level ``mode`` (``"realistic"``, the default, or ``"in_library"``)
    selects :meth:`GeneratorConfig.from_mode`; the other keys override its values
    (``[aero]`` and ``[wind]`` key by key; ``[aero] mode`` still picks the aerodynamics).

    Saved forms from before the realistic default (event files' ``config_json``):
    :func:`config_to_dict` then left out ``aero.yaw`` when it was None and the three
    felt-wind keys of ``[wind]`` when they held their in_library values. A dict without
    ``mode`` that holds every key a saved form always has (``structure``, ``aero``,
    ``wind``, ``sensors``, ``integration_step``, ``truth_step``, ``initial_amplitude``,
    ``tau``) is read as such a form: an ``[aero]`` table with all five curves and no
    ``yaw`` (nor ``mode``) gets ``yaw = None``, and a ``[wind]`` table without
    ``felt_wind`` gets ``felt_wind = "anemometer"``, ``points_per_section = 5`` and
    ``anemometer_offset = 0`` where absent. Old in_library files thus read back as
    in_library; forms written now list these keys and are not affected. A partial
    dict (a hand-written TOML file) takes the realistic defaults for what it leaves out.
    """
    allowed = {f.name for f in dataclasses.fields(GeneratorConfig)} | {"mode"}
    unknown = set(data) - allowed
    require(not unknown, f"unknown configuration keys {sorted(unknown)}; allowed: {sorted(allowed)}")
    data = _restore_legacy(data)
    mode = data.get("mode", DEFAULT_MODE)
    require(mode in GENERATOR_MODES, f"mode must be one of {list(GENERATOR_MODES)}; got {mode!r}")
    kwargs = {}
    for key, value in data.items():
        if key == "mode":
            continue
        if key in _SECTIONS:
            require(isinstance(value, dict), f"[{key}] must be a table; got {value!r}")
            sub_allowed = {f.name for f in dataclasses.fields(_SECTIONS[key])} | ({"mode"} if key == "aero" else set())
            sub_unknown = set(value) - sub_allowed
            require(not sub_unknown, f"unknown keys {sorted(sub_unknown)} in [{key}]; allowed: {sorted(sub_allowed)}")
        kwargs[key] = value
    return GeneratorConfig.from_mode(mode, **kwargs)


def _aero_from_dict(data: dict[str, Any], default_mode: str = DEFAULT_MODE) -> AeroConfig:
    """The ``[aero]`` table: an optional ``mode`` (``default_mode`` otherwise) whose values the other keys override."""
    data = dict(data)
    mode = data.pop("mode", default_mode)
    overrides = {k: (curve_from_data(v, k) if k in _AERO_CURVES else v) for k, v in data.items()}
    if overrides.get("yaw") is False:  # TOML has no null: `yaw = false` removes the mode's yaw factor
        overrides["yaw"] = None
    if isinstance(overrides.get("yaw"), dict):
        overrides["yaw"] = YawFactor(**_tuples(overrides["yaw"]))
    return AeroConfig.from_mode(mode, **overrides)


def load_config(path: str | Path, *, mode: str | None = None) -> GeneratorConfig:
    """Read a generator configuration from TOML (sections as in :func:`config_to_dict`).

    A top-level ``mode = "realistic"`` (the default) or ``"in_library"`` starts from
    :meth:`GeneratorConfig.realistic` (or :meth:`GeneratorConfig.in_library`); the
    file's explicit keys override the mode's values. ``[aero]`` may also name a mode
    of its own for the aerodynamic functions alone. ``mode``, when given (the command
    line's ``--mode``), replaces the file's top-level ``mode``.

    Missing keys take their defaults. Errors name the file.
    """
    def build(data: dict[str, Any]) -> GeneratorConfig:
        return config_from_dict({**data, "mode": mode} if mode is not None else data)

    return load_toml(path, build, "configuration file")
