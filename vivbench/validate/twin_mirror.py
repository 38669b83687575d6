"""The layout of a campaign measured from its files, and a generator configuration that mirrors it.

A synthetic twin of a campaign (docs/field_workflow.md (how far to trust this)) needs what decides
how well the chain can identify that bridge, measured from the campaign's own event files and
identification results:

- the sections, the rates of the anemometers and accelerometers, the span's azimuth;
- the number of events, their start times and durations;
- each event's mean wind perpendicular to the span and its yaw (low-passed from the anemometers as
  the identification forms them, averaged over the sections, smoothed over a quarter of the knots'
  spacing), as knots of a wind script
  (:class:`vivbench.synth.WindScript` with ``yaws``), and the side the wind comes from;
- the turbulence intensity of the anemometers (10-minute blocks less a quadratic trend) and the relative
  spread of the sections' mean winds;
- the accelerometers' noise floor, from the spectrum above the mode;
- the anemometers' layout when the import recorded it (``import_anemometer_position_m_<name>``,
  ``import_position_m_<section>``, ``import_span_length_m``, ``import_wind_rule``): the twin's
  anemometers are placed among its sections as the campaign's are among its own (positions mapped
  piecewise linearly from the campaign's sections to the twin's) and each section's wind is taken
  from them by the same rule; otherwise one anemometer per section, at the mean recorded distance
  from it (``wind_distance_m_<section>``, 0 when none is recorded).

The bridge's structural properties come from a small TOML file (:func:`read_bridge`), the same
keys as ``vivbench greybox --bridge``; what it leaves out (frequency, mode shape) is measured.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.signal import welch

from vivbench.core.errors import InputError
from vivbench.core.toml import load_toml
from vivbench.io.event import read_event
from vivbench.io.result import read_result
from vivbench.models.greybox import BridgeProperties
from vivbench.preprocess.wind import mean_wind
from vivbench.preprocess.yaw import mean_yaw
from vivbench.synth.config import AeroConfig, GeneratorConfig, SensorConfig, StructureConfig, WindConfig
from vivbench.synth.event import EventSpec
from vivbench.synth.turbulence import TurbulenceConfig
from vivbench.synth.wind import WindScript

__all__ = ["BRIDGE_KEYS", "TwinBridge", "EventMirror", "CampaignMirror", "read_bridge", "measure_campaign",
           "mirror_structure", "mirror_generator", "mirror_specs", "anemometer_fractions"]

#: Keys of the bridge file: those of ``vivbench greybox --bridge`` and the span's length.
BRIDGE_KEYS = ("mass", "depth", "frequency", "damping_ratio", "air_density", "mode_shape", "tributary_lengths",
               "span_length")
_G = 9.80665
_BLOCK_S = 600.0  # turbulence intensity per 10-minute block, as anemometry reports it


@dataclass(frozen=True, kw_only=True)
class TwinBridge:
    """The bridge's structural properties as the twin uses them (a field user's design values).

    Attributes
    ----------
    mass : float, kg/m; equivalent modal mass per unit length
    depth : float, m; deck depth D
    damping_ratio : float; structural damping ratio
    air_density : float, kg/m^3
    frequency : float or None, Hz (None: the frequency the identification found)
    mode_shape : tuple of float or None (None: the measured amplitude ratios)
    tributary_lengths : tuple of float or None, m (None: equal shares of the span)
    span_length : float or None, m (None: the sum of the tributary lengths, or 1650 m)
    source : the file it was read from
    """

    mass: float
    depth: float
    damping_ratio: float
    air_density: float = 1.225
    frequency: float | None = None
    mode_shape: tuple[float, ...] | None = None
    tributary_lengths: tuple[float, ...] | None = None
    span_length: float | None = None
    source: str = ""

    def __post_init__(self) -> None:
        # the same checks as the grey-box's properties (a frequency of 1 Hz stands in for a measured one)
        BridgeProperties(mass=self.mass, depth=self.depth, frequency=self.frequency or 1.0,
                         damping_ratio=self.damping_ratio, air_density=self.air_density,
                         mode_shape=self.mode_shape, tributary_lengths=self.tributary_lengths)
        for name in ("mode_shape", "tributary_lengths"):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, tuple(float(x) for x in getattr(self, name)))
        span = self.span_length
        if span is not None and not (isinstance(span, (int, float)) and math.isfinite(span) and span > 0):
            raise InputError(f"span_length must be a positive number of metres; got {span!r}")


def read_bridge(path) -> TwinBridge:
    """The bridge file: TOML with a ``[bridge]`` table (or top-level keys) of :data:`BRIDGE_KEYS`.

    ``mass``, ``depth`` and ``damping_ratio`` are required; ``frequency`` defaults to the one the
    identification found, ``mode_shape`` to the measured amplitude ratios, ``tributary_lengths``
    to equal shares of ``span_length``. Errors are one line naming the file.
    """
    path = Path(path)

    def build(raw: dict) -> TwinBridge:
        data = dict(raw.get("bridge", raw))
        unknown = sorted(set(data) - set(BRIDGE_KEYS))
        if unknown:
            raise InputError(f"unknown bridge key(s) {unknown}; allowed: {list(BRIDGE_KEYS)}")
        missing = [k for k in ("mass", "depth", "damping_ratio") if k not in data]
        if missing:
            raise InputError(f"the bridge's {', '.join(missing)} must be given (kg/m, m, ratio)")
        return TwinBridge(**data, source=str(path))

    return load_toml(path, build, "bridge file")


@dataclass(frozen=True, kw_only=True)
class EventMirror:
    """One measured event as a wind script.

    Attributes
    ----------
    event_id, start_time : as in the event file
    duration : s; the record's length
    times : knot times, s (0 to ``duration``)
    speeds : mean wind perpendicular to the span at the knots, m/s (the sections' mean)
    yaws : mean wind's angle to the span's normal at the knots, degrees
    side : +1 when the wind comes from the span azimuth + 90 degrees, -1 from azimuth - 90
    """

    event_id: str
    start_time: str
    duration: float
    times: tuple[float, ...]
    speeds: tuple[float, ...]
    yaws: tuple[float, ...]
    side: int

    def script(self) -> WindScript:
        """The wind script of the twin's event."""
        return WindScript(times=self.times, speeds=self.speeds, side=self.side, yaw_deg=0.0, yaws=self.yaws)


@dataclass(frozen=True, kw_only=True)
class CampaignMirror:
    """What the twin mirrors of a campaign (module docstring), measured by :func:`measure_campaign`.

    Attributes
    ----------
    sections : section names
    wind_rate, accel_rate : Hz
    span_azimuth_deg : degrees from north
    turbulence_intensity : sigma_u / U of the anemometers (median over blocks, sections and events)
    section_offset : rms relative departure of a section's event-mean wind from the sections' mean
    noise_density : micro-g per sqrt(Hz); the accelerometers' noise floor (median over sections and events)
    anemometer_offset : m; mean distance between a section and the anemometer that gives its wind
        (0 unless the import recorded it)
    positions : section positions along the span, m, when the import recorded them (else empty)
    frequency : Hz; median modal frequency the identification found
    mode_shape : measured amplitude ratios (energy per section, largest 1)
    identify_json : the identification's settings (``identify_config_json`` of the results)
    events : EventMirror per event, in event-id order
    anemometer_positions : m; the anemometers' positions along the span when the import recorded them
        (else empty: one anemometer per section)
    span_length : m; the span length the import recorded with them (None without)
    wind_rule : the import's rule for the wind at a section ("nearest" or "interpolation")
    amplitude_scale : m; each section's 99th percentile of the identified amplitude over the events (where
        the nonlinear damping acts; empty when none is finite)
    """

    sections: tuple[str, ...]
    wind_rate: float
    accel_rate: float
    span_azimuth_deg: float
    turbulence_intensity: float
    section_offset: float
    noise_density: float
    anemometer_offset: float
    positions: tuple[float, ...]
    frequency: float
    mode_shape: tuple[float, ...]
    identify_json: str
    events: tuple[EventMirror, ...] = field(default_factory=tuple)
    anemometer_positions: tuple[float, ...] = ()
    span_length: float | None = None
    wind_rule: str = "nearest"
    amplitude_scale: tuple[float, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """Plain data (JSON-ready)."""
        data = {k: getattr(self, k) for k in self.__dataclass_fields__ if k != "events"}
        data["events"] = [dict(e.__dict__) for e in self.events]
        return json.loads(json.dumps(data))


def _rate(t: np.ndarray, path: Path, what: str) -> float:
    steps = np.diff(np.asarray(t, dtype=float))
    if steps.size == 0 or not np.median(steps) > 0:
        raise InputError(f"{path}: the {what} record has fewer than two increasing time stamps")
    return float(1.0 / np.median(steps))


def _side(u: np.ndarray, v: np.ndarray, azimuth: float) -> int:
    """+1 when the mean wind comes from the span azimuth + 90 degrees, else -1."""
    mu, mv = float(np.nanmean(u)), float(np.nanmean(v))
    frm = math.degrees(math.atan2(-mu, -mv))  # direction the wind blows from, degrees from north
    diff = (frm - (azimuth + 90.0) + 180.0) % 360.0 - 180.0
    return 1 if abs(diff) <= 90.0 else -1


def _turbulence(t: np.ndarray, u: np.ndarray, v: np.ndarray) -> list[float]:
    """sigma / mean of the horizontal speed in 10-minute blocks less a quadratic trend (the mean wind's course), per
    block and section."""
    V = np.hypot(u, v)
    rate = 1.0 / np.median(np.diff(t))
    n = max(int(round(_BLOCK_S * rate)), 16)
    out = []
    for start in range(0, V.shape[0] - n // 2, n):
        block = V[start:start + n]
        x = np.arange(block.shape[0], dtype=float)
        for k in range(block.shape[1]):
            y = block[:, k]
            ok = np.isfinite(y)
            if ok.sum() < 16 or not np.mean(y[ok]) > 0.5:
                continue
            fit = np.polyval(np.polyfit(x[ok], y[ok], 2), x[ok])
            out.append(float(np.std(y[ok] - fit) / np.mean(y[ok])))
    return out


def _noise_density(t: np.ndarray, acc: np.ndarray, f_mode: float) -> list[float]:
    """Noise floor per section, micro-g per sqrt(Hz): the median of the one-sided PSD between 3 f_mode
    (at least 1 Hz) and 0.4 times the rate, where a single vertical mode leaves only the sensor's floor."""
    fs = 1.0 / np.median(np.diff(t))
    out = []
    for k in range(acc.shape[1]):
        x = acc[:, k]
        x = x[np.isfinite(x)]
        if x.size < 256:
            continue
        f, psd = welch(x - np.mean(x), fs=fs, nperseg=min(4096, x.size))
        band = (f >= max(3.0 * f_mode, 1.0)) & (f <= 0.4 * fs)
        if band.sum() >= 4:
            out.append(float(np.sqrt(np.median(psd[band])) / _G * 1e6))
    return out


def _knots(t: np.ndarray, x: np.ndarray, duration: float, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Knots every ``step`` s from 0 to ``duration`` of x(t) (NaNs bridged, Gaussian-smoothed over step / 4)."""
    ok = np.isfinite(x)
    if ok.sum() < 2:
        raise InputError("no finite samples")
    grid = np.arange(0.0, duration + 0.5, 1.0)  # 1 Hz is plenty for a wind low-passed at minutes
    filled = np.interp(grid, t[ok], x[ok])
    smooth = gaussian_filter1d(filled, sigma=max(step / 4.0, 1.0), mode="nearest")
    times = np.unique(np.append(np.arange(0.0, duration, step), duration))
    return times, np.interp(times, grid, smooth)


def measure_campaign(event_files: Sequence, result_files: Sequence, *, knot_step: float = 120.0) -> CampaignMirror:
    """Measure a campaign's layout, winds, turbulence and noise floors (module docstring).

    Parameters
    ----------
    event_files : the campaign's event files
    result_files : their ``<event_id>.identify.nc`` (events without a result are left out)
    knot_step : s; spacing of the wind scripts' knots (the mean wind is smoothed over half of it)

    Returns
    -------
    CampaignMirror
    """
    if not (isinstance(knot_step, (int, float)) and 10.0 <= knot_step <= 1800.0):
        raise InputError(f"knot_step must be 10-1800 s; got {knot_step!r}")
    by_id = {}
    for path in result_files:
        res = read_result(path, ["U", "A"], optional=["yaw"])
        by_id[str(res.attrs["event_id"])] = (Path(path), res)
    events, wind_rates, accel_rates, ti, noise, offsets, energy, freqs, distances = [], [], [], [], [], [], [], [], []
    amplitudes = []
    sections, azimuth, identify_json, positions, layout = None, None, None, (), {}
    for path in sorted((Path(p) for p in event_files), key=lambda p: p.name):
        tree = read_event(path, truth=False)
        eid = str(tree.attrs["event_id"])
        if eid not in by_id:
            continue
        _, res = by_id[eid]
        wind, accel = tree["wind"].ds, tree["accel"].ds
        secs = tuple(str(s) for s in accel["section"].values)
        if sections is None:
            sections, azimuth = secs, float(tree.attrs["span_azimuth_deg"])
            identify_json = str(res.attrs.get("identify_config_json", "{}"))
            positions = tuple(float(tree.attrs[f"import_position_m_{s}"]) for s in secs
                              if f"import_position_m_{s}" in tree.attrs)
            layout = _layout(tree.attrs, len(positions) == len(secs))
        elif secs != sections:
            raise InputError(f"{path}: sections {list(secs)} differ from the campaign's {list(sections)}")
        tw, ta = wind["time"].values, accel["time"].values
        rw, ra = _rate(tw, path, "wind"), _rate(ta, path, "acceleration")
        wind_rates.append(rw)
        accel_rates.append(ra)
        duration = round(max(ta.size / ra, tw.size / rw), 3)
        u, v = wind["u"].values.astype(float), wind["v"].values.astype(float)
        ti += _turbulence(tw, u, v)
        f_mode = float(res.attrs.get("f_mode_hz", math.nan))
        if math.isfinite(f_mode):
            freqs.append(f_mode)
        noise += _noise_density(ta, accel["acc"].values.astype(float), f_mode if math.isfinite(f_mode) else 0.3)
        distances += [float(tree.attrs[f"wind_distance_m_{s}"]) for s in secs if f"wind_distance_m_{s}" in tree.attrs]
        U = mean_wind(tw, u, v, azimuth)  # the whole record's low-passed wind, as the identification forms it
        yaw = mean_yaw(tw, u, v, azimuth)
        means = np.nanmean(U, axis=0)
        if np.all(np.isfinite(means)) and np.nanmean(means) > 0:
            offsets += list(means / np.mean(means) - 1.0)
        energy.append(np.nansum(res["A"].values ** 2, axis=0))
        amplitudes.append(np.asarray(res["A"].values, dtype=float))
        try:
            times, speeds = _knots(tw, np.nanmean(U, axis=1), duration, knot_step)
            _, yaws = _knots(tw, np.nanmean(yaw, axis=1), duration, knot_step)
        except InputError:
            raise InputError(f"{path}: no finite mean wind to mirror") from None
        events.append(EventMirror(event_id=eid, start_time=str(tree.attrs["start_time"]), duration=float(duration),
                                  times=tuple(float(x) for x in times),
                                  speeds=tuple(float(x) for x in np.maximum(speeds, 0.5)),
                                  yaws=tuple(float(x) for x in np.clip(yaws, -55.0, 55.0)),
                                  side=_side(u, v, azimuth)))
    if not events:
        raise InputError("no event file has an identification result: nothing to mirror")
    e = np.sqrt(np.sum(energy, axis=0))
    return CampaignMirror(
        sections=sections, wind_rate=round(float(np.median(wind_rates)), 6),
        accel_rate=round(float(np.median(accel_rates)), 6),
        span_azimuth_deg=azimuth, turbulence_intensity=float(np.median(ti)) if ti else 0.08,
        section_offset=float(np.sqrt(np.mean(np.square(offsets)))) if offsets else 0.0,
        noise_density=float(np.median(noise)) if noise else 30.0,
        anemometer_offset=float(np.mean(distances)) if distances else 0.0, positions=positions,
        frequency=float(np.median(freqs)) if freqs else math.nan,
        mode_shape=tuple(float(x) for x in e / e.max()), identify_json=identify_json, events=tuple(events),
        amplitude_scale=_amplitude_scale(amplitudes), **layout)


def _amplitude_scale(amplitudes: list[np.ndarray]) -> tuple[float, ...]:
    """Each section's 99th percentile of the amplitude over the events' samples, m (empty when a section has no
    positive one)."""
    A = np.concatenate(amplitudes, axis=0)
    with np.errstate(invalid="ignore"):
        A = np.where(A > 0, A, np.nan)
    if not np.all(np.isfinite(A).any(axis=0)):
        return ()
    return tuple(float(x) for x in np.nanpercentile(A, 99.0, axis=0))


_ANEMOMETER_PREFIX = "import_anemometer_position_m_"


def _layout(attrs, all_positions: bool) -> dict[str, Any]:
    """The anemometers' layout an import recorded (CampaignMirror's fields), or {} when it recorded none."""
    found = sorted(float(v) for k, v in attrs.items() if str(k).startswith(_ANEMOMETER_PREFIX))
    span = attrs.get("import_span_length_m")
    if not (found and all_positions and span is not None and math.isfinite(float(span)) and float(span) > 0):
        return {}
    return {"anemometer_positions": tuple(found), "span_length": float(span),
            "wind_rule": str(attrs.get("import_wind_rule", "nearest"))}


def anemometer_fractions(mirror: CampaignMirror, structure: StructureConfig) -> tuple[float, ...] | None:
    """The twin's anemometers as fractions of its span (``WindConfig.anemometer_span``), or None for one per section.

    The campaign's anemometer positions are mapped piecewise linearly from its sections' positions (and
    the span's ends) to the twin's sections (k / (n + 1) of its span), so that each anemometer lies
    among the twin's sections as it lies among the campaign's; when the campaign's sections are not in
    increasing order along the span, the anemometers keep their fractions of the span instead.
    """
    if not mirror.anemometer_positions or mirror.span_length is None:
        return None
    span = float(mirror.span_length)
    x = np.asarray(mirror.positions, dtype=float)
    p = np.asarray(mirror.anemometer_positions, dtype=float)
    knots = np.concatenate([[0.0], x, [span]])
    if x.size == len(mirror.sections) and np.all(np.diff(knots) > 0):
        target = np.concatenate([[0.0], structure.positions / structure.span_length, [1.0]])
        frac = np.interp(p, knots, target)
    else:
        frac = p / span
    frac = np.clip(frac, 0.0, 1.0)
    if np.unique(np.round(frac, 9)).size != frac.size:
        raise InputError(f"the recorded anemometer positions {list(p)} m do not map to distinct places on the twin's "
                         "span")
    return tuple(float(round(f, 9)) for f in frac)


def mirror_structure(mirror: CampaignMirror, bridge: TwinBridge) -> StructureConfig:
    """The twin's structure: the bridge file's properties, the measured frequency and mode shape where it gives none."""
    n = len(mirror.sections)
    frequency = bridge.frequency if bridge.frequency is not None else mirror.frequency
    if not (frequency and math.isfinite(frequency)):
        raise InputError(f"{bridge.source or 'bridge'}: no frequency given and the results carry none (f_mode_hz)")
    phi = bridge.mode_shape if bridge.mode_shape is not None else mirror.mode_shape
    if len(phi) != n:
        raise InputError(f"{bridge.source or 'bridge'}: mode_shape has {len(phi)} values for {n} sections")
    span = bridge.span_length
    lengths = bridge.tributary_lengths
    if lengths is None:
        span = span or 1650.0
        lengths = (span / n,) * n
    if len(lengths) != n:
        raise InputError(f"{bridge.source or 'bridge'}: tributary_lengths has {len(lengths)} values for {n} sections")
    return StructureConfig(frequency=float(frequency), damping_ratio=bridge.damping_ratio,
                           mode_shape=tuple(max(abs(x), 1e-3) for x in phi), span_length=span or float(sum(lengths)),
                           tributary_lengths=lengths, depth=bridge.depth, mass=bridge.mass,
                           air_density=bridge.air_density)


def mirror_generator(mirror: CampaignMirror, structure: StructureConfig, aero: AeroConfig) -> GeneratorConfig:
    """The twin's generator: the measured rates, turbulence, section spread, noise floor and anemometer layout;
    the scripted mean wind and yaw carry the measured histories (no random wander added). The nuisances a
    twin draws (:func:`vivbench.validate.twin_nuisance.apply_nuisances`) are applied to it afterwards."""
    span = anemometer_fractions(mirror, structure)
    layout = ({"anemometer_offset": mirror.anemometer_offset} if span is None else
              {"anemometer_span": span, "wind_rule": mirror.wind_rule})
    wind = WindConfig(span_azimuth_deg=mirror.span_azimuth_deg % 360.0, section_offset=mirror.section_offset,
                      section_wander=0.0, speed_wander=0.0, direction_wander_deg=0.0,
                      anemometer_rate=mirror.wind_rate, **layout,
                      turbulence=TurbulenceConfig(intensity=float(np.clip(mirror.turbulence_intensity, 0.0, 0.45))))
    sensors = SensorConfig(rate=mirror.accel_rate, noise_density=mirror.noise_density)
    step = min(0.02, 1.0 / (20.0 * structure.frequency))
    return GeneratorConfig(structure=structure, aero=aero, wind=wind, sensors=sensors, integration_step=step)


def mirror_specs(mirror: CampaignMirror) -> list[EventSpec]:
    """One event specification per measured event: its id, start time and wind script."""
    return [EventSpec(event_id=e.event_id, start_time=e.start_time, kind="twin", script=e.script(), number=i + 1)
            for i, e in enumerate(mirror.events)]
