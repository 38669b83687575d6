"""Scripted mean wind of an event and the anemometer records (DESIGN 2.4).

An event's script gives the mean wind perpendicular to the span as a smooth
curve through a few knots (so that the event passes into, through and out of
the lock-in range as intended); a slow random wander with time scales of 10 to
60 min, small per-section offsets and a slowly turning direction make it
realistic. Turbulence comes from the spectral representation method.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import PchipInterpolator
from scipy.signal import butter, sosfiltfilt

from vivbench.synth.config import StructureConfig, WindConfig
from vivbench.synth.turbulence import simulate_turbulence
from vivbench.core.errors import InputError

__all__ = ["WindScript", "MeanWind", "mean_wind", "slow_process", "anemometer_records", "felt_mean_wind"]


@dataclass(frozen=True, kw_only=True)
class WindScript:
    """The designed course of an event's mean perpendicular wind speed.

    Attributes
    ----------
    times : knot times, s (first 0, last the event duration)
    speeds : mean perpendicular speed at the knots, m/s
    side : +1 if the wind comes from the span azimuth + 90 deg, -1 from azimuth - 90 deg
    yaw_deg : mean angle between the wind and the span's normal, degrees
    """

    times: tuple[float, ...]
    speeds: tuple[float, ...]
    side: int = 1
    yaw_deg: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "times", tuple(float(x) for x in self.times))
        object.__setattr__(self, "speeds", tuple(float(x) for x in self.speeds))
        t = np.array(self.times)
        if len(t) < 2 or len(t) != len(self.speeds):
            raise InputError(f"WindScript needs >= 2 knots with as many speeds as times; got {len(t)} times, {len(self.speeds)} speeds")
        if t[0] != 0.0 or np.any(np.diff(t) <= 0):
            raise InputError(f"WindScript knot times must start at 0 and increase strictly; got {self.times}")
        if min(self.speeds) <= 0:
            raise InputError(f"WindScript speeds must be positive (m/s); got {self.speeds}")
        if self.side not in (1, -1):
            raise InputError(f"WindScript side must be +1 or -1; got {self.side}")
        if abs(self.yaw_deg) >= 60:
            raise InputError(f"WindScript yaw_deg must be within +-60 degrees; got {self.yaw_deg}")

    @property
    def duration(self) -> float:
        return self.times[-1]


@dataclass(frozen=True)
class MeanWind:
    """Mean wind of an event on a time grid.

    Attributes
    ----------
    t : ndarray, shape (n,), s
    U : ndarray, shape (n, S), m/s; mean speed perpendicular to the span per section
    V : ndarray, shape (n, S), m/s; mean horizontal speed per section
    direction : ndarray, shape (n,), degrees from north the wind blows from
    yaw : ndarray, shape (n, S), degrees, or None; angle between each section's mean
        wind and the span's normal (0: perpendicular), the angle the aerodynamic
        functions' yaw factor sees
    """

    t: np.ndarray
    U: np.ndarray
    V: np.ndarray
    direction: np.ndarray
    yaw: np.ndarray | None = None


def slow_process(t: np.ndarray, rms: float, timescales: tuple[float, float], rng: np.random.Generator, n_modes: int = 8) -> np.ndarray:
    """Zero-mean smooth random process: a sum of cosines with periods in ``timescales``.

    Returns
    -------
    ndarray, shape (n,), with sample rms close to ``rms`` (exactly ``rms`` in expectation).
    """
    periods = rng.uniform(timescales[0], timescales[1], size=n_modes)
    phases = rng.uniform(0.0, 2 * np.pi, size=n_modes)
    amps = rng.rayleigh(1.0, size=n_modes)
    amps *= rms * np.sqrt(2.0 / np.sum(amps**2))
    return (amps[None, :] * np.cos(2 * np.pi * t[:, None] / periods[None, :] + phases[None, :])).sum(axis=1)


def mean_wind(script: WindScript, t: np.ndarray, wind: WindConfig, rng: np.random.Generator,
              n_sections: int = 3) -> MeanWind:
    """Evaluate the scripted mean wind with its random wander at times ``t`` (s) at ``n_sections`` sections."""
    t = np.asarray(t, dtype=float)
    base = PchipInterpolator(script.times, script.speeds)(np.clip(t, 0.0, script.duration))
    common = slow_process(t, wind.speed_wander, wind.slow_timescales, rng)
    offsets = rng.normal(0.0, wind.section_offset, size=n_sections)
    wander = np.stack([slow_process(t, wind.section_wander, wind.slow_timescales, rng) for _ in range(n_sections)], axis=1)
    U = (base + common)[:, None] * (1.0 + offsets[None, :] + wander)
    U = np.maximum(U, wind.min_speed)
    yaw = script.yaw_deg + slow_process(t, wind.direction_wander_deg, wind.slow_timescales, rng)
    V = U / np.cos(np.radians(yaw))[:, None]
    direction = np.mod(wind.span_azimuth_deg + 90.0 * script.side + yaw, 360.0)
    return MeanWind(t=t, U=U, V=V, direction=direction, yaw=np.repeat(np.abs(yaw)[:, None], n_sections, axis=1))


def anemometer_records(mw: MeanWind, structure: StructureConfig, wind: WindConfig, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Anemometer u (east), v (north), w (up) at the sections and the turbulence itself.

    The turbulence is simulated stationary at the event's mean horizontal speed
    and its amplitude then follows the mean speed (turbulence intensity stays
    constant as the wind changes).

    Parameters
    ----------
    mw : MeanWind on the anemometer time grid (uniform, ``wind.anemometer_rate``)

    Returns
    -------
    u, v, w : ndarray, shape (n, S), float32, m/s
        Measured components with noise and resolution applied.
    turb : ndarray, shape (n, S, 3), m/s
        Turbulence (along-wind, lateral, vertical) per section, before the sensor.
    """
    n = mw.t.size
    V_ref = float(np.mean(mw.V))
    turb = simulate_turbulence(structure.positions, V_ref, n / wind.anemometer_rate, wind.anemometer_rate,
                               wind.turbulence, rng)[:n]
    turb = turb * (mw.V / V_ref)[:, :, None]
    # Meteorological direction: the wind blows from `direction`, so it moves towards direction + 180.
    d = np.radians(mw.direction)[:, None]
    along_e, along_n = -np.sin(d), -np.cos(d)
    speed = mw.V + turb[:, :, 0]
    u = speed * along_e - turb[:, :, 1] * along_n
    v = speed * along_n + turb[:, :, 1] * along_e
    w = turb[:, :, 2]
    noise = wind.noise * mw.V
    out = []
    for comp in (u, v, w):
        comp = comp + noise * rng.standard_normal(comp.shape)
        if wind.resolution > 0:
            comp = np.round(comp / wind.resolution) * wind.resolution
        out.append(comp.astype(np.float32))
    return out[0], out[1], out[2], turb


def felt_mean_wind(mw: MeanWind, turb: np.ndarray, wind: WindConfig) -> MeanWind:
    """The mean wind the deck feels: scripted mean plus the slow part of the turbulence.

    Turbulence slower than ``wind.felt_cutoff_hz`` changes the wind over the
    time scale of the aeroelastic dynamics (minutes), so the deck responds to it
    as to a change of the mean; it is also what a low-pass filter of the
    measured wind keeps. The perpendicular component of the slow horizontal wind
    vector becomes the new ``U``.

    Parameters
    ----------
    mw : MeanWind on the uniform anemometer grid
    turb : ndarray, shape (n, S, 3), m/s; along-wind, lateral, vertical turbulence

    Returns
    -------
    MeanWind with ``U``, ``V`` and ``yaw`` replaced (``direction`` stays the scripted one;
    ``yaw`` is the angle of the slow wind vector to the span's normal, in [0, 90] degrees).
    """
    sos = butter(4, wind.felt_cutoff_hz, fs=wind.anemometer_rate, output="sos")
    slow = sosfiltfilt(sos, turb[:, :, :2], axis=0)
    d = np.radians(mw.direction)[:, None]
    along = np.stack([-np.sin(d), -np.cos(d)], axis=-1)  # (n, 1, 2) east, north
    lateral = np.stack([np.cos(d), -np.sin(d)], axis=-1)
    vec = (mw.V + slow[:, :, 0])[..., None] * along + slow[:, :, 1][..., None] * lateral
    az = np.radians(wind.span_azimuth_deg)
    span = np.array([np.sin(az), np.cos(az)])
    U = np.abs(vec[..., 0] * span[1] - vec[..., 1] * span[0])
    along_span = np.abs(vec[..., 0] * span[0] + vec[..., 1] * span[1])
    yaw = np.degrees(np.arctan2(along_span, U))
    U = np.maximum(U, wind.min_speed)
    return MeanWind(t=mw.t, U=U, V=np.hypot(vec[..., 0], vec[..., 1]), direction=mw.direction, yaw=yaw)
