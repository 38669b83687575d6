"""Scripted mean wind of an event and the anemometer records (docs/concepts.md (the bridge and the wind)).

An event's script gives the mean wind perpendicular to the span as a smooth
curve through a few knots (so that the event passes into, through and out of
the lock-in range as intended); a slow random wander with time scales of 10 to
60 min, small per-section offsets and a slowly turning direction make it
realistic. Turbulence comes from the spectral representation method.

Which signal is which (``WindConfig.felt_wind``, docs/concepts.md (no inverse crime)):

- anemometer records (``u, v, w`` of the event file): the section's mean wind
  plus the turbulence at ONE point, the anemometer (``WindField.anemometer``),
  plus the sensor errors (:func:`measure_wind`);
- deck turbulence (``WindField.deck``): with ``"tributary"`` the field averaged
  over ``points_per_section`` points spread over the section's tributary
  length, simulated together with the anemometers (Davenport coherence over
  all points); with ``"anemometer"`` (``in_library``) the anemometer's own
  turbulence; with ``"smooth"`` a field at the sections that the anemometers
  do not record (they see their own point turbulence instead,
  :func:`point_turbulence`). Buffeting uses it;
- felt mean wind U_k (:func:`felt_mean_wind`): the scripted mean plus the
  deck turbulence low-passed at ``felt_cutoff_hz`` (with ``"smooth"``, the
  scripted mean alone). The aeroelastic force of
  the full simulation and the averaged truth (``/truth/U``) both use it, so the
  truth is exact; the identification only sees the anemometer records, whose
  low-passed perpendicular wind differs from U_k in ``"tributary"`` mode (the
  errors-in-variables of field data).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import PchipInterpolator
from scipy.signal import butter, lfilter, sosfiltfilt

from vivbench.io.field_wind import span_weights
from vivbench.synth.config import StructureConfig, WindConfig
from vivbench.synth.turbulence import simulate_turbulence
from vivbench.core.errors import InputError

__all__ = ["WindScript", "MeanWind", "WindField", "AnemometerLayout", "mean_wind", "slow_process", "anemometer_positions",
           "anemometer_layout", "at_anemometers", "section_records",
           "tributary_points", "wind_field", "measure_wind", "anemometer_records", "felt_mean_wind", "point_turbulence"]


@dataclass(frozen=True, kw_only=True)
class WindScript:
    """The designed course of an event's mean perpendicular wind speed.

    Attributes
    ----------
    times : knot times, s (first 0, last the event duration)
    speeds : mean perpendicular speed at the knots, m/s
    side : +1 if the wind comes from the span azimuth + 90 deg, -1 from azimuth - 90 deg
    yaw_deg : mean angle between the wind and the span's normal, degrees
    yaws : angle between the wind and the span's normal at the knots, degrees, or None;
        when given, the yaw follows these knots (a scripted yaw history, e.g. a measured one)
        instead of the constant ``yaw_deg`` and the wind's ``event_yaw_scale``/``shared_yaw_deg``
    """

    times: tuple[float, ...]
    speeds: tuple[float, ...]
    side: int = 1
    yaw_deg: float = 0.0
    yaws: tuple[float, ...] | None = None

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
        if self.yaws is not None:
            object.__setattr__(self, "yaws", tuple(float(x) for x in self.yaws))
            if len(self.yaws) != len(t) or not all(abs(y) < 60 for y in self.yaws):
                raise InputError(f"WindScript yaws must give one angle within +-60 degrees per knot ({len(t)}); "
                                 f"got {self.yaws}")

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
    """Evaluate the scripted mean wind with its random wander at times ``t`` (s) at ``n_sections`` sections.

    The yaw is the script's mean yaw times ``wind.event_yaw_scale`` (or ``wind.shared_yaw_deg``
    when set; or the script's ``yaws`` interpolated between its knots when given) plus the slow
    random wander plus the shared swing ``wind.yaw_swing_deg sin(2 pi t / wind.yaw_swing_period)``.
    """
    t = np.asarray(t, dtype=float)
    base = PchipInterpolator(script.times, script.speeds)(np.clip(t, 0.0, script.duration))
    common = slow_process(t, wind.speed_wander, wind.slow_timescales, rng)
    offsets = rng.normal(0.0, wind.section_offset, size=n_sections)
    wander = np.stack([slow_process(t, wind.section_wander, wind.slow_timescales, rng) for _ in range(n_sections)], axis=1)
    U = (base + common)[:, None] * (1.0 + offsets[None, :] + wander)
    U = np.maximum(U, wind.min_speed)
    mean_yaw = script.yaw_deg * wind.event_yaw_scale if wind.shared_yaw_deg is None else wind.shared_yaw_deg
    if script.yaws is not None:
        mean_yaw = PchipInterpolator(script.times, script.yaws)(np.clip(t, 0.0, script.duration))
    yaw = mean_yaw + slow_process(t, wind.direction_wander_deg, wind.slow_timescales, rng)
    if wind.yaw_swing_deg:
        yaw = yaw + wind.yaw_swing_deg * np.sin(2.0 * np.pi * t / wind.yaw_swing_period)
    V = U / np.cos(np.radians(yaw))[:, None]
    direction = np.mod(wind.span_azimuth_deg + 90.0 * script.side + yaw, 360.0)
    return MeanWind(t=t, U=U, V=V, direction=direction, yaw=np.repeat(np.abs(yaw)[:, None], n_sections, axis=1))


@dataclass(frozen=True)
class WindField:
    """Turbulence of an event at the anemometers and as the deck feels it.

    Both arrays are the zero-mean fluctuations (along-wind u', lateral v',
    vertical w') on the uniform anemometer grid, amplitude-modulated by the
    section's mean horizontal speed ``V_k(t) / V_ref``; neither carries sensor
    errors.

    Attributes
    ----------
    anemometer : ndarray, shape (n, n_anem, 3), m/s
        Turbulence at each anemometer, a single point (with ``felt_wind = "smooth"``,
        its own :func:`point_turbulence`); one per section (n_anem = S) unless
        ``WindConfig.anemometer_span`` places them (:func:`anemometer_layout`). The
        anemometer records are the mean wind plus this plus the sensor errors.
    deck : ndarray, shape (n, S, 3), m/s
        Turbulence the deck of section k feels: with ``felt_wind = "tributary"``
        the average of the field over the points of the section's tributary
        length; with ``"anemometer"`` (the ``in_library`` mode) the very array
        ``anemometer``; with ``"smooth"`` the field at the section. Buffeting uses
        it whole; its slow part (below ``felt_cutoff_hz``) enters the felt mean
        wind U_k of the aeroelastic force and of the truth (:func:`felt_mean_wind`),
        except with ``"smooth"``.
    positions : ndarray, shape (n_points,), m
        Spanwise coordinates simulated: the n_anem anemometers first, then the
        tributary points section by section (S * points_per_section); only the
        S sections in ``"anemometer"`` and ``"smooth"`` modes.
    """

    anemometer: np.ndarray
    deck: np.ndarray
    positions: np.ndarray


def anemometer_positions(structure: StructureConfig, wind: WindConfig) -> np.ndarray:
    """Spanwise coordinates of the anemometers, m, shape (n_anem,).

    With ``wind.anemometer_span`` its fractions of the span length. Otherwise one per
    section (n_anem = S): the section's position (k / (n + 1) of the span) plus
    ``wind.anemometer_offset`` in ``"tributary"`` mode; the section's position in
    ``"anemometer"`` and ``"smooth"`` modes.
    """
    if wind.anemometer_span is not None:
        return structure.span_length * np.asarray(wind.anemometer_span)
    if wind.felt_wind != "tributary":
        return structure.positions
    return structure.positions + wind.anemometer_offset


@dataclass(frozen=True)
class AnemometerLayout:
    """Where the anemometers are and how the event's wind at each section is taken from them.

    Attributes
    ----------
    positions : ndarray, shape (n_anem,), m
    from_sections : ndarray, shape (S, n_anem)
        The anemometers' mean wind from the sections': ``mean_anem = mean_sec @ from_sections``
        (linear interpolation along the span, the nearest section beyond the outermost).
    to_sections : ndarray, shape (n_anem, S)
        The recorded wind at each section from the anemometers' records, by ``wind.wind_rule``
        (:func:`vivbench.io.span_weights`, as field import does).
    distance : ndarray, shape (S,), m
        Each section's distance to its nearest anemometer.
    per_section : bool
        One anemometer per section (``wind.anemometer_span`` None): both maps are the identity
        and no distance is recorded.
    """

    positions: np.ndarray
    from_sections: np.ndarray
    to_sections: np.ndarray
    distance: np.ndarray
    per_section: bool


def anemometer_layout(structure: StructureConfig, wind: WindConfig) -> AnemometerLayout:
    """The anemometers of ``wind.anemometer_span`` (or one per section) and their maps to and from the sections."""
    positions = anemometer_positions(structure, wind)
    S = structure.n_sections
    if wind.anemometer_span is None:
        eye = np.eye(S)
        return AnemometerLayout(positions=positions, from_sections=eye, to_sections=eye, distance=np.zeros(S),
                                per_section=True)
    from_sections, _ = span_weights(structure.positions, positions, "interpolation")
    to_sections, distance = span_weights(positions, structure.positions, wind.wind_rule)
    return AnemometerLayout(positions=positions, from_sections=from_sections, to_sections=to_sections,
                            distance=distance, per_section=False)


def at_anemometers(mw: MeanWind, layout: AnemometerLayout) -> MeanWind:
    """The mean wind at the anemometers of ``layout`` (``mw`` itself with one per section)."""
    if layout.per_section:
        return mw
    W = layout.from_sections
    return MeanWind(t=mw.t, U=mw.U @ W, V=mw.V @ W, direction=mw.direction,
                    yaw=None if mw.yaw is None else mw.yaw @ W)


def section_records(u: np.ndarray, v: np.ndarray, w: np.ndarray, layout: AnemometerLayout):
    """The event's wind at each section, (n, S) float32 each, from the anemometers' records (n, n_anem)."""
    if layout.per_section:
        return u, v, w
    return tuple((c.astype(np.float64) @ layout.to_sections).astype(np.float32) for c in (u, v, w))


def tributary_points(structure: StructureConfig, wind: WindConfig) -> np.ndarray:
    """Spanwise coordinates of the points over which each section's deck wind is averaged.

    Section k's tributary length L_k, centred on its position x_k, is cut into
    P = ``wind.points_per_section`` equal strips and the field is taken at their
    midpoints, x_k + L_k ((j + 1/2) / P - 1/2), j = 0..P-1; the average over the
    points is then the midpoint rule for the strip average (1 / L_k) int u' dx.

    Returns
    -------
    ndarray, shape (S, P), m
    """
    P = wind.points_per_section
    frac = (np.arange(P) + 0.5) / P - 0.5
    return structure.positions[:, None] + np.asarray(structure.tributary_lengths)[:, None] * frac[None, :]


def wind_field(mw: MeanWind, structure: StructureConfig, wind: WindConfig, rng: np.random.Generator) -> WindField:
    """Simulate the turbulence of an event at the anemometers and over the deck.

    The field is simulated stationary at the event's mean horizontal speed
    V_ref (the mean of ``mw.V`` over time and sections), with Davenport
    coherence between all points, by one call of :func:`simulate_turbulence`
    (vectorised, one inverse FFT per point and component; single-indexed in
    ``"tributary"`` mode whatever ``turbulence.double_indexing`` says, see the
    turbulence module's docstring; as configured in ``"anemometer"`` mode); its amplitude then
    follows each section's mean speed, V_k(t) / V_ref (turbulence intensity
    stays constant as the wind changes). All points of section k (its
    anemometer and its tributary points) follow V_k.

    With ``felt_wind = "smooth"`` the field at the sections is the deck's (buffeting only)
    and the anemometers get their own :func:`point_turbulence`, drawn after the field.

    Parameters
    ----------
    mw : MeanWind on the uniform anemometer grid (``wind.anemometer_rate``), n samples, S sections
    structure, wind : configurations; ``wind.felt_wind`` selects the deck's wind
    rng : numpy.random.Generator; its draws are the random phases of the field (then, in
        ``"smooth"`` mode, the point turbulence)

    Returns
    -------
    WindField
    """
    n = mw.t.size
    S = mw.V.shape[1]
    V_ref = float(np.mean(mw.V))
    scale = (mw.V / V_ref)[:, :, None]  # (n, S, 1)
    layout = anemometer_layout(structure, wind)
    mw_anem = at_anemometers(mw, layout)
    if wind.felt_wind != "tributary":  # the field at the sections (anemometer_span needs "smooth" here)
        sections = structure.positions
        turb = simulate_turbulence(sections, V_ref, n / wind.anemometer_rate, wind.anemometer_rate, wind.turbulence, rng)[:n]
        turb = turb * scale
        if wind.felt_wind == "smooth":
            return WindField(anemometer=point_turbulence(mw_anem, wind, rng), deck=turb, positions=sections)
        return WindField(anemometer=turb, deck=turb, positions=sections)
    anemo = layout.positions
    n_a = anemo.size
    trib = tributary_points(structure, wind)  # (S, P)
    positions = np.concatenate([anemo, trib.ravel()])
    # Single indexing: with double indexing each of the n points' sources is resolved only every
    # n / T Hz, coarser than the Davenport coherence of points hundreds of metres apart varies.
    single = dataclasses.replace(wind.turbulence, double_indexing=False)
    field_ = simulate_turbulence(positions, V_ref, n / wind.anemometer_rate, wind.anemometer_rate, single, rng)[:n]
    deck = field_[:, n_a:].reshape(n, S, wind.points_per_section, 3).mean(axis=2)
    return WindField(anemometer=field_[:, :n_a] * (mw_anem.V / V_ref)[:, :, None], deck=deck * scale,
                     positions=positions)


def point_turbulence(mw: MeanWind, wind: WindConfig, rng: np.random.Generator) -> np.ndarray:
    """Point turbulence of each anemometer in ``felt_wind = "smooth"`` mode (the deck does not feel it).

    Independent exponentially correlated (first-order autoregressive, the sampled
    Ornstein-Uhlenbeck) processes per anemometer and component, started in their stationary
    state: autocorrelation exp(-|lag| / ``wind.point_timescale``), so the integral time scale is
    ``point_timescale``. Their rms is ``wind.point_intensity`` times the section's mean
    horizontal speed V_k(t) for u' and ``turbulence.ratio_v``, ``ratio_w`` times that for v', w'.

    Parameters
    ----------
    mw : MeanWind on the uniform anemometer grid, n samples, S sections
    wind : WindConfig
    rng : numpy.random.Generator; draws the initial states (S, 3), then the innovations (n, S, 3)

    Returns
    -------
    ndarray, shape (n, S, 3), m/s: u', v', w'
    """
    n, S = mw.V.shape
    a = math.exp(-1.0 / (wind.anemometer_rate * wind.point_timescale))
    start = rng.standard_normal((1, S, 3))
    unit = lfilter([math.sqrt(1.0 - a * a)], [1.0, -a], rng.standard_normal((n, S, 3)), axis=0, zi=a * start)[0]
    ratios = wind.point_intensity * np.array([1.0, wind.turbulence.ratio_v, wind.turbulence.ratio_w])
    return unit * mw.V[:, :, None] * ratios[None, None, :]


def measure_wind(mw: MeanWind, turb: np.ndarray, wind: WindConfig, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Anemometer records: mean wind plus the point's turbulence plus the sensor errors.

    Parameters
    ----------
    mw : MeanWind on the anemometer grid, n samples, S sections
    turb : ndarray, shape (n, S, 3), m/s; turbulence at the anemometers (``WindField.anemometer``)
    rng : numpy.random.Generator; draws the sensor noise, u then v then w

    Returns
    -------
    u, v, w : ndarray, shape (n, S), float32, m/s
        East, north and up components with a white error of rms ``wind.noise`` times
        the mean speed and rounded to ``wind.resolution``.
    """
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
    return out[0], out[1], out[2]


def anemometer_records(mw: MeanWind, structure: StructureConfig, wind: WindConfig, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Anemometer u (east), v (north), w (up) at the sections and the turbulence itself.

    :func:`wind_field` then :func:`measure_wind` with the same ``rng``; the
    deck's turbulence (different from the anemometers' in ``"tributary"``
    mode) is not returned: use :func:`wind_field` for it.

    Parameters
    ----------
    mw : MeanWind on the anemometer time grid (uniform, ``wind.anemometer_rate``)

    Returns
    -------
    u, v, w : ndarray, shape (n, S), float32, m/s
        Measured components with noise and resolution applied.
    turb : ndarray, shape (n, S, 3), m/s
        Turbulence (along-wind, lateral, vertical) at the anemometers, before the sensor.
    """
    field_ = wind_field(mw, structure, wind, rng)
    u, v, w = measure_wind(mw, field_.anemometer, wind, rng)
    return u, v, w, field_.anemometer


def felt_mean_wind(mw: MeanWind, turb: np.ndarray, wind: WindConfig) -> MeanWind:
    """The mean wind the deck feels: scripted mean plus the slow part of the deck's turbulence.

    Turbulence slower than ``wind.felt_cutoff_hz`` changes the wind over the
    time scale of the aeroelastic dynamics (minutes), so the deck responds to it
    as to a change of the mean; it is also what a low-pass filter of the
    measured wind keeps. With ``felt_wind = "smooth"`` the deck feels the
    scripted mean alone (``turb`` then drives the buffeting only). The perpendicular component of the slow horizontal wind
    vector becomes the new ``U``.

    Parameters
    ----------
    mw : MeanWind on the uniform anemometer grid
    turb : ndarray, shape (n, S, 3), m/s; along-wind, lateral, vertical turbulence the
        deck feels (``WindField.deck``: the tributary average, or the anemometer's own
        turbulence in ``"anemometer"`` mode)

    Returns
    -------
    MeanWind with ``U``, ``V`` and ``yaw`` replaced (``direction`` stays the scripted one;
    ``yaw`` is the angle of the slow wind vector to the span's normal, in [0, 90] degrees):
    ``U`` (n, S), m/s, is the U_k of the aeroelastic force and of the truth.
    """
    sos = butter(4, wind.felt_cutoff_hz, fs=wind.anemometer_rate, output="sos")
    slow = np.zeros_like(turb[:, :, :2]) if wind.felt_wind == "smooth" else sosfiltfilt(sos, turb[:, :, :2], axis=0)
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
