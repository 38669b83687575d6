"""Continuous monitoring logs with known VIV events: quiet wind, wind-only gusts and lock-in passages.

A log is a chain of episodes simulated one after the other by the event
generator (:func:`~vivbench.synth.simulate_event`), each starting and ending in
quiet wind, the next one starting from the amplitude where the previous one
ended:

- quiet: a mean wind below the lock-in range, one hour at most per piece;
- gust: a quiet lead, a rise within 1 to 2 min to a wind above the lock-in
  range (buffeting, no VIV: the passage through lock-in is too quick to let
  the vibration grow), held 2 to 20 min, and back;
- VIV: a quiet lead, a rise within 2 to 5 min to a plateau inside the lock-in
  range held 10 to 60 min, a fall back to quiet wind and a quiet tail long
  enough for the vibration to decay.

A true event is where the true vibration amplitude (``/truth`` ``A`` of the
averaged model, the largest over the sections; it leaves out buffeting and
sensor noise) exceeds ``event_amplitude_m``, with the detector's rule for
short gaps and short events (:func:`vivbench.core.threshold_intervals`). :func:`write_continuous_log` writes
the log as a monitoring system would: CSV files of a given length (a day by
default) with local-time ISO 8601 stamps, in field units, and the mapping that
reads them.
"""

from __future__ import annotations

import csv
import io as _io
import math
from dataclasses import dataclass, field, replace
from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np
import pandas as pd

from vivbench.core.errors import InputError, require
from vivbench.core.intervals import threshold_intervals
from vivbench.io.netcdf import atomic_path
from vivbench.io.quality import ACC_UNITS, WIND_UNITS
from vivbench.synth.config import GeneratorConfig
from vivbench.synth.event import EventSpec, simulate_event
from vivbench.synth.wind import WindScript

__all__ = ["ContinuousLogConfig", "ContinuousLog", "generate_continuous_log", "write_continuous_log"]

_QUIET_PIECE_S = 3600  # longest quiet piece simulated at once (memory)
_QUIET_AMPLITUDE = 5e-4  # modal amplitude at the log's start, m (a quiet deck's order of magnitude)


def _pair(name: str, value, low: float = 0.0) -> tuple[float, float]:
    v = tuple(float(x) for x in value)
    require(len(v) == 2 and low <= v[0] <= v[1] and all(math.isfinite(x) for x in v),
            f"{name} must be (min, max) with {low:g} <= min <= max; got {value!r}")
    return v


@dataclass(frozen=True, kw_only=True)
class ContinuousLogConfig:
    """A continuous log: its length, how many VIV events and gusts, their winds, and the bridge.

    Attributes
    ----------
    duration_s : float
        Length of the log, s (whole seconds; at least one hour).
    start : str
        ISO 8601 UTC instant of the first sample.
    seed : int
        Seed of the schedule and of every episode's simulation.
    viv_per_day, gusts_per_day : float
        Rates of VIV events and of wind-only gusts; a log has
        ``max(1, round(rate * duration_s / 86400))`` of each (none at a rate of 0).
    quiet_speed : (float, float)
        Range of the quiet mean wind, m/s (below the bridge's lock-in).
    lock_in_speed : (float, float)
        Range of the VIV plateaus' mean wind, m/s (inside lock-in).
    gust_speed : (float, float)
        Range of the gusts' mean wind, m/s (above lock-in).
    viv_plateau_s, gust_hold_s : (float, float)
        Ranges of the plateau and gust durations, s.
    event_amplitude_m : float
        A true event is where the true amplitude exceeds this, m. Default
        5 mm: above what the gusts' locked shedding and quick passages through
        lock-in give the default bridge (at most about 3 mm), below the
        plateaus of its VIV events (1.5 to 14 cm).
    merge_gap_s, min_duration_s : float
        The truth's merging of gaps shorter than this, and its shortest event, s.
    generator : GeneratorConfig
        The bridge, wind, sensors (rates included).
    """

    duration_s: float = 86400.0
    start: str = "2026-01-14T00:00:00Z"
    seed: int = 0
    viv_per_day: float = 6.0
    gusts_per_day: float = 6.0
    quiet_speed: tuple[float, float] = (2.5, 4.5)
    lock_in_speed: tuple[float, float] = (6.5, 9.5)
    gust_speed: tuple[float, float] = (12.0, 16.0)
    viv_plateau_s: tuple[float, float] = (600.0, 3600.0)
    gust_hold_s: tuple[float, float] = (120.0, 1200.0)
    event_amplitude_m: float = 0.005
    merge_gap_s: float = 300.0
    min_duration_s: float = 60.0
    generator: GeneratorConfig = field(default_factory=GeneratorConfig)

    def __post_init__(self) -> None:
        require(math.isfinite(self.duration_s) and self.duration_s >= 3600 and float(self.duration_s).is_integer(),
                f"duration_s must be a whole number of seconds >= 3600; got {self.duration_s!r}")
        try:
            datetime.fromisoformat(self.start.replace("Z", "+00:00"))
        except (ValueError, AttributeError):
            raise InputError(f"start must be an ISO 8601 UTC instant such as 2026-01-14T00:00:00Z; got {self.start!r}") from None
        require(isinstance(self.seed, int) and self.seed >= 0, f"seed must be a non-negative integer; got {self.seed!r}")
        for name in ("viv_per_day", "gusts_per_day"):
            v = getattr(self, name)
            require(math.isfinite(v) and v >= 0, f"{name} must be a finite rate >= 0 per day; got {v!r}")
        for name in ("quiet_speed", "lock_in_speed", "gust_speed"):
            object.__setattr__(self, name, _pair(name, getattr(self, name), 0.5))
        for name in ("viv_plateau_s", "gust_hold_s"):
            object.__setattr__(self, name, _pair(name, getattr(self, name), 60.0))
        require(self.quiet_speed[1] < self.lock_in_speed[0] and self.lock_in_speed[1] < self.gust_speed[0],
                f"speeds must order quiet < lock-in < gust; got {self.quiet_speed}, {self.lock_in_speed}, {self.gust_speed}")
        require(math.isfinite(self.event_amplitude_m) and self.event_amplitude_m > 0,
                f"event_amplitude_m must be a positive amplitude in m; got {self.event_amplitude_m!r}")
        require(self.merge_gap_s >= 0 and self.min_duration_s >= 0,
                f"merge_gap_s and min_duration_s must be >= 0 s; got {self.merge_gap_s!r}, {self.min_duration_s!r}")

    @property
    def counts(self) -> tuple[int, int]:
        """Numbers of VIV episodes and of gusts."""
        days = self.duration_s / 86400.0
        return tuple(max(1, round(rate * days)) if rate > 0 else 0 for rate in (self.viv_per_day, self.gusts_per_day))


@dataclass(frozen=True)
class ContinuousLog:
    """A simulated continuous log and its truth.

    Attributes
    ----------
    config : ContinuousLogConfig
    wind_time : ndarray (n_w,), s since ``config.start``
    u, v, w : ndarray (n_w, S), m/s, float32; east, north, up
    accel_time : ndarray (n_a,), s
    acc : ndarray (n_a, S), m/s^2, float32
    truth_time : ndarray (n_t,), s
    A : ndarray (n_t, S), m; true amplitude (averaged model)
    U : ndarray (n_t, S), m/s; true mean wind perpendicular to the span
    episodes : list of dict
        ``kind`` ("quiet", "gust", "viv"), ``start_s``, ``end_s`` and the
        episode's wind ``speed`` (plateau or gust; quiet: its level), m/s.
    events : ndarray (n_events, 2), s
        True event intervals (see the module docstring).
    """

    config: ContinuousLogConfig
    wind_time: np.ndarray
    u: np.ndarray
    v: np.ndarray
    w: np.ndarray
    accel_time: np.ndarray
    acc: np.ndarray
    truth_time: np.ndarray
    A: np.ndarray
    U: np.ndarray
    episodes: list
    events: np.ndarray


def _schedule(config: ContinuousLogConfig, rng: np.random.Generator) -> list[tuple[str, tuple, tuple, float]]:
    """Pieces (kind, knot times, speeds, speed) whose durations sum to the log's."""
    n_viv, n_gust = config.counts
    kinds = ["viv"] * n_viv + ["gust"] * n_gust
    rng.shuffle(kinds)
    quiet = lambda: float(rng.uniform(*config.quiet_speed))  # noqa: E731
    episodes = []
    for kind in kinds:
        lead = round(rng.uniform(300, 900))
        if kind == "viv":
            speed = float(rng.uniform(*config.lock_in_speed))
            ramp_up, hold = round(rng.uniform(120, 300)), round(rng.uniform(*config.viv_plateau_s))
            ramp_down, tail = round(rng.uniform(120, 300)), round(rng.uniform(1800, 2400))
        else:
            speed = float(rng.uniform(*config.gust_speed))
            ramp_up, hold = round(rng.uniform(60, 120)), round(rng.uniform(*config.gust_hold_s))
            ramp_down, tail = round(rng.uniform(60, 120)), round(rng.uniform(300, 600))
        t = np.cumsum([0, lead, ramp_up, hold, ramp_down, tail])
        q0, q1 = quiet(), quiet()
        episodes.append((kind, tuple(float(x) for x in t), (q0, q0, speed, speed, q1, q1), speed))
    used = sum(e[1][-1] for e in episodes)
    spare = config.duration_s - used
    if spare < 0:
        raise InputError(f"duration_s = {config.duration_s:g} s is too short for {n_viv} VIV episodes and {n_gust} gusts "
                         f"(they need {used:g} s); lower viv_per_day or gusts_per_day, or lengthen the log")
    # The spare time is quiet, spread at random before, between and after the episodes.
    parts = np.floor(rng.dirichlet(np.ones(len(episodes) + 1)) * spare)
    parts[-1] += spare - parts.sum()
    pieces = []
    for quiet_s, episode in zip(parts, episodes + [None]):
        n_quiet = math.ceil(quiet_s / _QUIET_PIECE_S)
        for k in range(n_quiet):
            d = float(round(quiet_s * (k + 1) / n_quiet) - round(quiet_s * k / n_quiet))
            if d > 0:
                q0, q1 = quiet(), quiet()
                pieces.append(("quiet", (0.0, d), (q0, q1), 0.5 * (q0 + q1)))
        if episode is not None:
            pieces.append(episode)
    return pieces


def generate_continuous_log(config: ContinuousLogConfig | None = None, *, progress=None) -> ContinuousLog:
    """Simulate a continuous log: quiet wind, wind-only gusts and VIV events with known boundaries.

    Parameters
    ----------
    config : ContinuousLogConfig, optional
    progress : callable, optional
        Called with (pieces done, pieces in all) after each simulated piece.

    Returns
    -------
    ContinuousLog
        Same config, same arrays (bit for bit).
    """
    config = config or ContinuousLogConfig()
    rng = np.random.default_rng(np.random.SeedSequence(config.seed, spawn_key=(0,)))
    pieces = _schedule(config, rng)
    side, yaw = int(rng.choice([-1, 1])), float(rng.uniform(-10.0, 10.0))
    seeds = np.random.SeedSequence(config.seed, spawn_key=(1,)).spawn(len(pieces))
    gen = config.generator
    phi = np.array(gen.structure.mode_shape)
    amplitude = _QUIET_AMPLITUDE
    out = {k: [] for k in ("wind_time", "u", "v", "w", "accel_time", "acc", "truth_time", "A", "U")}
    episodes, offset = [], 0.0
    for i, ((kind, times, speeds, speed), seed) in enumerate(zip(pieces, seeds)):
        script = WindScript(times=times, speeds=speeds, side=side, yaw_deg=yaw)
        spec = EventSpec(event_id=f"P{i + 1:04d}", start_time=config.start, kind=kind, script=script)
        ev = simulate_event(spec, replace(gen, initial_amplitude=amplitude), seed)
        amplitude = float(ev.Q[-1])
        keep_t = ev.truth_time < script.duration - 1e-9
        for key, values in (("wind_time", ev.wind_time + offset), ("u", ev.u), ("v", ev.v), ("w", ev.w),
                            ("accel_time", ev.accel_time + offset), ("acc", ev.acc),
                            ("truth_time", ev.truth_time[keep_t] + offset),
                            ("A", ev.Q[keep_t, None] * phi[None, :]), ("U", ev.U[keep_t])):
            out[key].append(values)
        episodes.append({"kind": kind, "start_s": offset, "end_s": offset + script.duration, "speed": float(speed)})
        offset += script.duration
        if progress is not None:
            progress(i + 1, len(pieces))
    arrays = {k: np.concatenate(v) for k, v in out.items()}
    events = threshold_intervals(arrays["truth_time"], arrays["A"].max(axis=1) > config.event_amplitude_m,
                                 merge_gap_s=config.merge_gap_s, min_duration_s=config.min_duration_s)
    return ContinuousLog(config=config, episodes=episodes, events=events, **arrays)


def _iso(start: datetime, seconds: float) -> str:
    return (start + timedelta(seconds=float(seconds))).strftime("%Y-%m-%dT%H:%M:%S.%fZ")


def _stamps(start: datetime, t: np.ndarray, offset_hours: float) -> np.ndarray:
    """ISO 8601 local-time stamps (microseconds) with their offset from UTC."""
    local = np.datetime64(start.replace(tzinfo=None), "us") + np.round((t + offset_hours * 3600.0) * 1e6).astype("timedelta64[us]")
    sign = "+" if offset_hours >= 0 else "-"
    minutes = round(abs(offset_hours) * 60)
    return np.char.add(np.datetime_as_string(local, unit="us"), f"{sign}{minutes // 60:02d}:{minutes % 60:02d}")


def write_continuous_log(log: ContinuousLog, out_dir, *, file_s: float = 86400.0, utc_offset_hours: float = 8.0,
                         wind_units: str = "km/h", acc_units: str = "mg") -> Path:
    """Write a log as a monitoring system's CSV files, the mapping that reads them and the true events.

    Files: ``wind/wind_<local start>.csv`` (time, u_S1, v_S1, w_S1, ...) and
    ``accel/accel_<local start>.csv`` (time, acc_S1, ...), one per ``file_s``
    seconds, stamps in local time with their offset; ``mapping.toml`` (globs
    over the files, the units, ``start_time`` the log's start) and
    ``events_truth.csv`` (``event_id``, ``start``, ``end`` ISO UTC,
    ``start_s``, ``end_s`` since the log's start, ``peak_amplitude_m``).

    Parameters
    ----------
    log : ContinuousLog
    out_dir : str or os.PathLike
        Directory (created).
    file_s : float
        Length of each file, s.
    utc_offset_hours : float
        Offset of the local time written in the stamps, hours.
    wind_units, acc_units : str
        Units written (keys of ``vivbench.io.WIND_UNITS`` / ``ACC_UNITS``).

    Returns
    -------
    pathlib.Path
        The mapping file.
    """
    require(wind_units in WIND_UNITS and acc_units in ACC_UNITS,
            f"units must be one of {list(WIND_UNITS)} (wind) and {list(ACC_UNITS)} (acc); got {wind_units!r}, {acc_units!r}")
    require(file_s >= 60 and math.isfinite(file_s), f"file_s must be at least 60 s; got {file_s!r}")
    require(abs(utc_offset_hours) <= 14, f"utc_offset_hours must be within +-14 h; got {utc_offset_hours!r}")
    out = Path(out_dir)
    start = datetime.fromisoformat(log.config.start.replace("Z", "+00:00")).astimezone(timezone.utc)
    sections = list(log.config.generator.structure.sections)
    groups = {
        "wind": (log.wind_time, {f"{var}_{sec}": getattr(log, var)[:, j] for j, sec in enumerate(sections)
                                 for var in ("u", "v", "w")}, WIND_UNITS[wind_units], wind_units),
        "accel": (log.accel_time, {f"acc_{sec}": log.acc[:, j] for j, sec in enumerate(sections)},
                  ACC_UNITS[acc_units], acc_units),
    }
    duration = log.config.duration_s
    for group, (t, columns, factor, _) in groups.items():
        (out / group).mkdir(parents=True, exist_ok=True)
        bounds = np.searchsorted(t, np.arange(0.0, duration, file_s))
        for i0, i1 in zip(bounds, np.append(bounds[1:], t.size)):
            local = start + timedelta(seconds=float(t[i0]) + utc_offset_hours * 3600.0)
            frame = {"time": _stamps(start, t[i0:i1], utc_offset_hours)}
            frame.update({name: np.asarray(x[i0:i1], dtype=np.float64) / factor for name, x in columns.items()})
            with atomic_path(out / group / f"{group}_{local:%Y%m%dT%H%M%S}.csv") as tmp:
                pd.DataFrame(frame).to_csv(tmp, index=False, na_rep="NaN", float_format="%.7g")
    lines = ["event_id = \"LOG\"", f"start_time = \"{_iso(start, 0.0)}\"",
             f"span_azimuth_deg = {float(log.config.generator.wind.span_azimuth_deg)!r}", ""]
    for group, (_, _, _, units) in groups.items():
        lines += [f"[{group}]", f"file = \"{group}/{group}_*.csv\"", "time = \"time\"", "time_format = \"iso8601\"",
                  f"units = \"{units}\"", ""]
        for sec in sections:
            lines.append(f"[{group}.{sec}]")
            lines += [f"{var} = \"{var}_{sec}\"" for var in (("u", "v", "w") if group == "wind" else ("acc",))]
            lines.append("")
    mapping = out / "mapping.toml"
    with atomic_path(mapping) as tmp:
        tmp.write_text("\n".join(lines))
    buf = _io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(["event_id", "start", "end", "start_s", "end_s", "peak_amplitude_m"])
    peak = log.A.max(axis=1)
    for k, (a, b) in enumerate(log.events):
        inside = (log.truth_time >= a) & (log.truth_time <= b)
        writer.writerow([f"T{k + 1:03d}", _iso(start, a), _iso(start, b), f"{a:.1f}", f"{b:.1f}",
                         f"{float(peak[inside].max()):.5f}"])
    with atomic_path(out / "events_truth.csv") as tmp:
        tmp.write_text(buf.getvalue())
    return mapping
