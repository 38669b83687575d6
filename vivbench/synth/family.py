"""A family of synthetic bridges drawn from wide priors, with a held-out split (docs/concepts.md (no generator crime)).

Tuning a method on campaigns of one generator configuration and reporting on the same
configuration flatters the method. :func:`draw_bridge` therefore draws whole bridges and
their physics, and the family's seeds are split once, here, into two sets that never meet:

- ``"development"`` draws: any choice (a default, a threshold, a prior) may be made on them;
- ``"evaluation"`` draws: reported only, never used to choose anything. A figure quoted for
  the project comes from evaluation draws, with its spread over draws.

Draw ``index`` of a split comes from ``numpy.random.SeedSequence([FAMILY_ENTROPY, code,
index])`` with ``code`` the split's position in :data:`SPLITS`; its campaign seed carries
the split code in its bits 62-63 (development seeds < 2**62 <= evaluation seeds), so no
campaign of one split is a campaign of the other. The same split and index give the same
configuration, hence the same files, for a given :data:`FAMILY_VERSION`.

Priors (independent unless said; U(a, b) uniform, logU log-uniform):

=====================  ==========================================================================
campaign size          n_events = floor(exp(U(ln 3, ln 61))) (log-uniform: small campaigns are as
                       likely per factor of size as large ones; median about 13); event durations
                       from (lo, hi) minutes with lo ~ U(10, 60), hi ~ U(lo, 90)
sections               1-6 (uniform), at k / (n + 1) of a span of U(800, 2000) m; mode shape
                       sin(pi x / span) times U(0.9, 1.1) per section (in phase), tributary lengths
                       span / (n + 1) times U(0.6, 1.0)
structure              f1 ~ logU(0.1, 1) Hz; deck depth D ~ U(2.5, 7.5) m; mass ~ U(1.2e4, 4.5e4)
                       kg/m; damping ratio ~ logU(0.002, 0.01)
lock-in bell (Y1)      centre Ur0 = 1/St (:func:`vivbench.synth.draw_aero`, 5.5-8.5); shape
                       Gaussian (width U(0.6, 1.6)), Lorentzian (half width U(0.4, 1.1)) or
                       asymmetric (widths U(0.5, 1.8) each side), one third each; baseline
                       -U(0.05, 0.4) times the peak. The peak is set by the bell's strength: the
                       largest aerodynamic negative damping rho U D Y1(U) / (2 m) over the wind
                       range is (1 + g) zeta w1 with g ~ logU(0.3, 3) (self-excited draws) or
                       h zeta w1 with h ~ U(0.2, 0.8) (forced-only draws: Y1 stays below the
                       structural damping everywhere, also after a damping step)
(f1, D, Ur0)           redrawn together (with the rest of the structure and the bell) until
                       the lock-in range (Y1 > 0) lies within 3-25 m/s, where the campaign
                       scripts (which follow the bridge's lock-in) can pass through it; so f1
                       and D are conditioned on a reachable lock-in, and bridges near 0.1 Hz with shallow decks are rarely kept
e1 / e2                draw_aero's shapes; "both" (1/2), "e1 only" (1/4: e2 = 0), "e2 only" (1/4:
                       e1 = 0)
C_L, Y2, St            draw_aero's
yaw effect             absent (2/5) or, 3/20 each, one of the :data:`~vivbench.synth.curves.YAW_SHAPES`
                       applied to Y1 and C_L: cosine^n, n ~ U(1, 8); Gaussian, width U(10, 30)
                       deg; 1 - c sin^2, c ~ U(0.5, 1); logistic cut-off at U(8, 25) deg, width
                       U(2, 6) deg
yaw course             events' mean yaws spread by ``event_yaw_scale`` ~ U(1, 2.5) (scripts draw
                       +-12 deg); shared (1/2): every event's yaw is one mean U(-10, 10) deg plus a
                       swing of U(3, 10) deg with a period of U(0.5, 2) times the mean event
                       duration and a wander of U(0.5, 1.5) deg (yaw confounded with time within an
                       event), else per event (the script's mean plus a 4 deg wander)
errors in the wind     "tributary" (1/2): the deck feels the tributary average of a turbulent field;
                       "smooth" (1/2): the deck feels the smooth mean wind, each anemometer sees
                       point turbulence of intensity U(0.05, 0.12) and time scale logU(5, 60) s
turbulence, buffeting  field intensity U(0.05, 0.12); buffeting_w ~ U(0, 1.2), buffeting_u ~ U(0, 0.4)
noise floors           accelerometer noise density logU(10, 100) micro-g/sqrt(Hz); anemometer
                       relative error U(0.005, 0.02)
forced-only            1/5 of the draws
damping step           1/4 of the draws: from an event drawn uniformly in 2..n_events on, the
                       damping ratio times 1 +- U(0.3, 0.6) (up or down, 1/2 each)
=====================  ==========================================================================
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from vivbench.core.errors import InputError
from vivbench.io.netcdf import atomic_path
from vivbench.synth.campaign import CampaignConfig, CampaignResult, generate_campaign
from vivbench.synth.config import (ChangesConfig, GeneratorConfig, SensorConfig, StructureConfig, WindConfig,
                                   config_to_dict)
from vivbench.synth.curves import AsymmetricBell, Constant, GaussianBell, LorentzianBell, YawFactor, scaled_bell
from vivbench.synth.draw import draw_aero
from vivbench.synth.turbulence import TurbulenceConfig

__all__ = ["E_MIXES", "E_MIX_SHARES", "FAMILY_ENTROPY", "FAMILY_VERSION", "SPLITS", "FamilyDraw", "draw_bridge",
           "draw_yaw_effect", "family_seed", "generate_family_campaign", "FAMILY_FILE"]

#: Fixed entropy of the family's seeds (any 128-bit number; changing it makes a new family).
FAMILY_ENTROPY = 0x5A1F_2C4E_9B07_D3E6_8F11_60AD_C2B5_7E93
#: The splits, in the order of their codes: development draws may be used to choose anything,
#: evaluation draws only to report.
SPLITS = ("development", "evaluation")
#: Version of the priors: a draw is reproducible within one version.
FAMILY_VERSION = 1
#: Name of the file that describes a draw beside its campaign.
FAMILY_FILE = "family.json"
#: Which orders of the amplitude limit it (``e_mix``): both e1 (A^2) and e2 (A^3), e1 alone, e2 alone,
#: and the prior probability of each.
E_MIXES = ("both", "e1_only", "e2_only")
E_MIX_SHARES = (0.5, 0.25, 0.25)

_RHO = 1.225
_MAX_TRIES = 500


def _split_code(split: str) -> int:
    if split not in SPLITS:
        raise InputError(f"family split must be one of {', '.join(SPLITS)}; got {split!r}")
    return SPLITS.index(split)


def _check_index(index) -> int:
    if isinstance(index, bool) or not isinstance(index, (int, np.integer)) or not 0 <= index < 2**31:
        raise InputError(f"family draw index must be an integer in 0..2**31-1; got {index!r}")
    return int(index)


def family_seed(split: str, index: int) -> np.random.SeedSequence:
    """The seed sequence of draw ``index`` of ``split``: ``SeedSequence([FAMILY_ENTROPY, code, index])``."""
    return np.random.SeedSequence([FAMILY_ENTROPY, _split_code(split), _check_index(index)])


@dataclass(frozen=True, kw_only=True)
class FamilyDraw:
    """One bridge of the family and its campaign.

    Attributes
    ----------
    split : "development" or "evaluation"
    index : draw number within the split, >= 0
    config : GeneratorConfig of the bridge
    n_events : events in its campaign, 3-60
    duration : (min, max) event duration, s
    campaign_seed : the campaign's seed (bits 62-63 hold the split's code)
    labels : what was drawn, as plain data (see :func:`draw_bridge`)
    """

    split: str
    index: int
    config: GeneratorConfig
    n_events: int
    duration: tuple[float, float]
    campaign_seed: int
    labels: dict = field(default_factory=dict)

    @property
    def duration_min(self) -> tuple[float, float]:
        """(min, max) event duration, minutes."""
        return self.duration[0] / 60.0, self.duration[1] / 60.0

    def campaign_config(self, *, max_events: int | None = None, max_duration: float | None = None) -> CampaignConfig:
        """The draw's campaign, optionally capped.

        Parameters
        ----------
        max_events : at most this many events (the first ones; None: all)
        max_duration : s; event durations capped at this (None: as drawn). Capped campaigns are
            smaller than the family's: for quick checks only, and every output records the caps.
            The labels describe the whole draw (a damping step after the last kept event is not
            in the capped campaign).
        """
        n = self.n_events if max_events is None else min(self.n_events, int(max_events))
        lo, hi = self.duration
        if max_duration is not None:
            lo, hi = min(lo, float(max_duration)), min(hi, float(max_duration))
        return CampaignConfig(n_events=n, seed=self.campaign_seed, duration=(lo, hi), generator=self.config)

    def to_dict(self) -> dict[str, Any]:
        """Plain data: split, index, version, campaign, labels and the full generator configuration."""
        return {"family_version": FAMILY_VERSION, "split": self.split, "index": self.index,
                "campaign_seed": self.campaign_seed, "n_events": self.n_events,
                "duration_s": list(self.duration), "labels": json.loads(json.dumps(self.labels)),
                "generator": config_to_dict(self.config)}


def _log_uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _structure(rng: np.random.Generator, frequency: float, depth: float) -> StructureConfig:
    n = int(rng.integers(1, 7))
    span = float(rng.uniform(800.0, 2000.0))
    x = np.arange(1, n + 1) / (n + 1)
    phi = np.sin(np.pi * x) * rng.uniform(0.9, 1.1, size=n)
    phi = phi / phi.max()
    trib = span / (n + 1) * rng.uniform(0.6, 1.0, size=n)
    return StructureConfig(frequency=frequency, damping_ratio=_log_uniform(rng, 0.002, 0.01),
                           mode_shape=tuple(float(round(v, 4)) for v in phi), span_length=round(span, 1),
                           tributary_lengths=tuple(float(round(v, 1)) for v in trib), depth=depth,
                           mass=float(rng.uniform(1.2e4, 4.5e4)), air_density=_RHO)


def _unit_bell(rng: np.random.Generator, center: float):
    """A lock-in bell of peak 1 and baseline -b, its shape's name."""
    kind = ("gaussian", "lorentzian", "asymmetric")[int(rng.integers(0, 3))]
    base = -float(rng.uniform(0.05, 0.4))
    if kind == "gaussian":
        return GaussianBell(peak=1.0, center=center, width=rng.uniform(0.6, 1.6), baseline=base), kind
    if kind == "lorentzian":
        return LorentzianBell(peak=1.0, center=center, width=rng.uniform(0.4, 1.1), baseline=base), kind
    return AsymmetricBell(peak=1.0, center=center, width_low=rng.uniform(0.5, 1.8), width_high=rng.uniform(0.5, 1.8),
                          baseline=base), kind


_WIND = np.arange(0.5, 40.0, 0.01)


def _aero_damping_max(bell, structure: StructureConfig) -> float:
    """max over U of rho U D Y1(U) / (2 m), 1/s, for Y1 = ``bell``."""
    y = bell.at_wind(_WIND, structure.frequency, structure.depth)
    return float(np.max(structure.air_density * _WIND * structure.depth * y / (2.0 * structure.mass)))


def draw_yaw_effect(rng: np.random.Generator) -> tuple[YawFactor | None, str]:
    """A yaw effect on Y1 and C_L from the family's prior (module docstring: absent with probability 2/5,
    else one of :data:`~vivbench.synth.curves.YAW_SHAPES`, 3/20 each, with its parameter drawn uniformly).

    Parameters
    ----------
    rng : the random stream (four or fewer draws are taken from it)

    Returns
    -------
    (YawFactor or None, name): None and ``"absent"``, or the factor and its shape's name
    """
    if rng.random() < 0.4:
        return None, "absent"
    shape = ("cosine", "gaussian", "sin2", "logistic")[int(rng.integers(0, 4))]
    if shape == "cosine":
        return YawFactor(shape="cosine", exponent=rng.uniform(1.0, 8.0)), shape
    if shape == "gaussian":
        return YawFactor(shape="gaussian", width_deg=rng.uniform(10.0, 30.0)), shape
    if shape == "sin2":
        return YawFactor(shape="sin2", strength=rng.uniform(0.5, 1.0)), shape
    return YawFactor(shape="logistic", cutoff_deg=rng.uniform(8.0, 25.0), width_deg=rng.uniform(2.0, 6.0)), shape


def _changes(rng: np.random.Generator, n_events: int) -> tuple[ChangesConfig, dict]:
    if rng.random() >= 0.25:
        return ChangesConfig(), {"change": "none", "step_event": 0, "step_damping_factor": 1.0}
    event = int(rng.integers(2, n_events + 1))
    factor = 1.0 + (1.0 if rng.random() < 0.5 else -1.0) * rng.uniform(0.3, 0.6)
    return (ChangesConfig(step_event=event, step_damping_factor=float(factor)),
            {"change": "damping_step", "step_event": event, "step_damping_factor": float(factor)})


def draw_bridge(split: str, index: int) -> FamilyDraw:
    """Draw bridge ``index`` of the family's ``split`` (module docstring: the priors).

    Parameters
    ----------
    split : one of :data:`SPLITS`
    index : int >= 0

    Returns
    -------
    FamilyDraw
        Its ``labels`` hold: ``forced_only``, ``bell`` (gaussian, lorentzian, asymmetric),
        ``bell_strength`` (largest aerodynamic negative damping over the structural damping),
        ``e_mix`` (both, e1_only, e2_only), ``cl_shape``, ``yaw_effect`` (absent or the yaw
        shape), ``yaw_course`` (shared, per_event), ``eiv`` (tributary, smooth),
        ``point_intensity`` and ``point_timescale_s`` (smooth only, else null),
        ``n_sections``, ``frequency_hz``, ``depth_m``, ``mass_kg_m``, ``damping_ratio``,
        ``lock_in_m_s``, ``turbulence_intensity``, ``buffeting_w``, ``noise_density``,
        ``change`` (none, damping_step), ``step_event``, ``step_damping_factor``,
        ``n_events``, ``duration_min``.
    """
    code = _split_code(split)
    index = _check_index(index)
    rng = np.random.default_rng(family_seed(split, index))
    campaign_seed = (code << 62) | int(rng.integers(0, 2**62, dtype=np.int64))
    n_events = min(60, int(math.floor(math.exp(rng.uniform(math.log(3.0), math.log(61.0))))))
    lo = float(rng.uniform(10.0, 60.0))
    hi = float(rng.uniform(lo, 90.0))
    duration = (round(lo * 60.0), round(hi * 60.0))
    forced_only = bool(rng.random() < 0.2)
    changes, change_labels = _changes(rng, n_events)
    for _ in range(_MAX_TRIES):
        aero0 = draw_aero(rng, yaw=False)
        center = 1.0 / aero0.strouhal
        structure = _structure(rng, _log_uniform(rng, 0.1, 1.0), float(rng.uniform(2.5, 7.5)))
        unit, bell_kind = _unit_bell(rng, center)
        zeta_w = structure.damping_ratio * structure.omega
        if forced_only:
            strength = float(rng.uniform(0.2, 0.8)) * min(1.0, changes.step_damping_factor)
        else:
            strength = 1.0 + _log_uniform(rng, 0.3, 3.0)
        Y1 = scaled_bell(unit, strength * zeta_w / _aero_damping_max(unit, structure))
        lock = GeneratorConfig(structure=structure, aero=dataclasses.replace(aero0, Y1=Y1)).lock_in
        if lock is not None and 3.0 <= lock[0] and lock[1] <= 25.0:
            break
    else:  # pragma: no cover - the priors make a reachable lock-in likely on every try
        raise InputError(f"family draw {split} {index}: no bridge with a reachable lock-in in {_MAX_TRIES} tries")
    mix = float(rng.random())
    e_mix = E_MIXES[int(np.searchsorted(np.cumsum(E_MIX_SHARES), mix, side="right"))]
    yaw, yaw_kind = draw_yaw_effect(rng)
    aero_over = {"Y1": Y1, "yaw": yaw, "buffeting_w": float(rng.uniform(0.0, 1.2)),
                 "buffeting_u": float(rng.uniform(0.0, 0.4))}
    if e_mix == "e1_only":
        aero_over["e2"] = Constant(value=0.0)
    elif e_mix == "e2_only":
        aero_over["e1"] = Constant(value=0.0)
    aero = dataclasses.replace(aero0, **aero_over)
    shared = bool(rng.random() < 0.5)
    yaw_scale = float(rng.uniform(1.0, 2.5))
    eiv = "tributary" if rng.random() < 0.5 else "smooth"
    wind_over: dict[str, Any] = {"turbulence": TurbulenceConfig(intensity=float(rng.uniform(0.05, 0.12))),
                                 "noise": float(rng.uniform(0.005, 0.02)), "felt_wind": eiv,
                                 "event_yaw_scale": yaw_scale}
    if shared:
        wind_over.update(shared_yaw_deg=float(rng.uniform(-10.0, 10.0)), yaw_swing_deg=float(rng.uniform(3.0, 10.0)),
                         yaw_swing_period=float(rng.uniform(0.5, 2.0)) * 0.5 * (duration[0] + duration[1]),
                         direction_wander_deg=float(rng.uniform(0.5, 1.5)))
    if eiv == "smooth":
        wind_over.update(point_intensity=float(rng.uniform(0.05, 0.12)), point_timescale=_log_uniform(rng, 5.0, 60.0))
    sensors = SensorConfig(noise_density=_log_uniform(rng, 10.0, 100.0))
    config = GeneratorConfig(structure=structure, aero=aero, wind=WindConfig(**wind_over), sensors=sensors,
                             changes=changes)
    lock = config.lock_in
    labels = {
        "forced_only": forced_only, "bell": bell_kind, "bell_strength": round(strength, 4), "e_mix": e_mix,
        "cl_shape": getattr(aero.C_L, "kind", "polynomial"),
        "yaw_effect": yaw_kind, "yaw_course": "shared" if shared else "per_event", "event_yaw_scale": yaw_scale,
        "eiv": eiv, "point_intensity": config.wind.point_intensity if eiv == "smooth" else None,
        "point_timescale_s": config.wind.point_timescale if eiv == "smooth" else None,
        "n_sections": structure.n_sections, "frequency_hz": structure.frequency, "depth_m": structure.depth,
        "mass_kg_m": structure.mass, "damping_ratio": structure.damping_ratio,
        "lock_in_m_s": None if lock is None else [round(lock[0], 3), round(lock[1], 3)],
        "turbulence_intensity": config.wind.turbulence.intensity, "buffeting_w": aero.buffeting_w,
        "noise_density": sensors.noise_density, **change_labels,
        "n_events": n_events, "duration_min": [duration[0] / 60.0, duration[1] / 60.0],
    }
    return FamilyDraw(split=split, index=index, config=config, n_events=n_events,
                      duration=(float(duration[0]), float(duration[1])), campaign_seed=int(campaign_seed),
                      labels=labels)


def generate_family_campaign(split: str, index: int, out_dir: str | Path, *, workers: int = 1,
                             max_events: int | None = None, max_duration: float | None = None,
                             progress: Callable[[str], None] | None = None) -> tuple[CampaignResult, Path]:
    """Generate draw ``index`` of ``split``: its events, ``catalogue.csv`` and ``family.json``.

    Parameters
    ----------
    split, index : see :func:`draw_bridge`
    out_dir : directory (created)
    workers : worker processes (the files do not depend on it)
    max_events, max_duration : optional caps (:meth:`FamilyDraw.campaign_config`); ``family.json``
        records them under ``caps``
    progress : optional callback with each finished event id

    Returns
    -------
    (CampaignResult, path of family.json)
    """
    draw = draw_bridge(split, index)
    campaign = draw.campaign_config(max_events=max_events, max_duration=max_duration)
    result = generate_campaign(campaign, out_dir, workers=workers, progress=progress)
    data = draw.to_dict()
    data["caps"] = {"max_events": max_events, "max_duration_s": max_duration,
                    "n_events_generated": campaign.n_events, "duration_s_generated": list(campaign.duration)}
    path = Path(out_dir) / FAMILY_FILE
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(data, indent=1, sort_keys=True) + "\n", encoding="utf-8")
    return result, path
