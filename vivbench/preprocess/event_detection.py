"""VIV events in a continuous acceleration record: the mode, the amplitude at the mode, the intervals above a threshold.

The steps (docs/event_detection.md):

1. the mode: the highest peak of the acceleration's Welch spectrum in a search
   band (all sections and all gap-free runs averaged,
   :func:`~vivbench.preprocess.modal_frequency`), unless given;
2. the amplitude at the mode: the acceleration decimated (anti-aliasing
   polyphase filter; before the spectrum, to four samples per period of the
   search band's upper edge) to about ten samples per period of the mode
   band's upper edge, integrated twice in a band of +-``half_width`` around the mode
   (:func:`~vivbench.preprocess.displacement`), its Hilbert envelope
   (:func:`~vivbench.preprocess.envelope`) averaged over a centred window of
   ``smoothing_s``: the vibration amplitude of each section, in m;
3. the threshold: ``threshold_factor`` times each section's noise floor, the
   median of its amplitude over the log (robust while events and gusts cover
   less than half of it), or an absolute ``threshold_m``;
4. the events: where any section's amplitude is above its threshold, gaps
   shorter than ``merge_gap_s`` merged, events shorter than
   ``min_duration_s`` dropped (:func:`vivbench.core.threshold_intervals`).
   Each event file adds ``margin_s`` before and after.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal
from scipy.ndimage import uniform_filter1d

from vivbench.core.errors import InputError, require
from vivbench.core.intervals import threshold_intervals
from vivbench.preprocess.runs import as_2d, valid_runs
from vivbench.preprocess.vibration import displacement, envelope, modal_frequency

__all__ = ["EventDetectionConfig", "EventDetection", "detect_events"]

# Samples per period of the upper edge of the search band, then of the mode's band, after decimation.
_SEARCH_SAMPLES_PER_PERIOD = 4.0
_SAMPLES_PER_PERIOD = 10.0
# Stamps further than this fraction of a step from the regular clock are refused.
_CLOCK_TOLERANCE = 0.25


def _finite(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


@dataclass(frozen=True, kw_only=True)
class EventDetectionConfig:
    """Settings of the VIV event detector.

    Attributes
    ----------
    threshold_factor : float
        The threshold as a multiple of each section's noise floor (the median
        of its amplitude over the log), > 1. Default 12.
    threshold_m : float or None
        An absolute amplitude threshold, m, for every section; replaces
        ``threshold_factor`` when given.
    min_duration_s : float
        Shortest event, s (after merging). Default 60 s.
    merge_gap_s : float
        Events separated by less than this are one, s. Default 300 s.
    margin_s : float
        Record kept before and after each event in its file, s. Default 300 s.
    frequency_hz : float or None
        The mode's frequency, Hz; None: from the spectrum.
    band_hz : (float, float)
        Search band of the spectral peak, Hz. Default (0.05, 2.0).
    segment_s : float
        Length of the Welch sections, s. Default 300 s.
    half_width : float
        Half-width of the band around the mode, as a fraction of its
        frequency, in (0, 0.5]. Default 0.1.
    smoothing_s : float
        Length of the centred moving average of the envelope, s. Default 20 s.
    """

    threshold_factor: float = 12.0
    threshold_m: float | None = None
    min_duration_s: float = 60.0
    merge_gap_s: float = 300.0
    margin_s: float = 300.0
    frequency_hz: float | None = None
    band_hz: tuple[float, float] = (0.05, 2.0)
    segment_s: float = 300.0
    half_width: float = 0.1
    smoothing_s: float = 20.0

    def __post_init__(self) -> None:
        require(_finite(self.threshold_factor) and self.threshold_factor > 1,
                f"threshold_factor must be a number > 1 (a multiple of the noise floor); got {self.threshold_factor!r}")
        require(self.threshold_m is None or (_finite(self.threshold_m) and self.threshold_m > 0),
                f"threshold_m must be None (use threshold_factor) or a positive amplitude in m; got {self.threshold_m!r}")
        for name in ("min_duration_s", "merge_gap_s", "margin_s"):
            v = getattr(self, name)
            require(_finite(v) and v >= 0, f"{name} must be a finite number of seconds >= 0; got {v!r}")
        require(self.frequency_hz is None or (_finite(self.frequency_hz) and self.frequency_hz > 0),
                f"frequency_hz must be None (from the spectrum) or a positive frequency in Hz; got {self.frequency_hz!r}")
        band = tuple(self.band_hz) if isinstance(self.band_hz, (tuple, list)) else ()
        require(len(band) == 2 and all(_finite(b) for b in band) and 0 < band[0] < band[1],
                f"band_hz must be (low, high) in Hz with 0 < low < high; got {self.band_hz!r}")
        object.__setattr__(self, "band_hz", (float(band[0]), float(band[1])))
        require(_finite(self.segment_s) and self.segment_s > 0, f"segment_s must be a positive number of seconds; got {self.segment_s!r}")
        require(_finite(self.half_width) and 0 < self.half_width <= 0.5,
                f"half_width must be in (0, 0.5] (a fraction of the mode's frequency); got {self.half_width!r}")
        require(_finite(self.smoothing_s) and self.smoothing_s >= 0,
                f"smoothing_s must be a number of seconds >= 0; got {self.smoothing_s!r}")


@dataclass(frozen=True)
class EventDetection:
    """What the detector found in a record.

    Attributes
    ----------
    frequency_hz : float
        The mode's frequency, Hz.
    t : ndarray (n,), s
        Times of the amplitude (decimated grid, the record's time origin).
    amplitude : ndarray (n, S), m
        Smoothed vibration amplitude at the mode per section; NaN in gaps.
    noise_floor_m : ndarray (S,), m
        Median amplitude of each section.
    threshold_m : ndarray (S,), m
        Each section's threshold.
    intervals : ndarray (n_events, 2), s
        Start and end of each event (without margins).
    """

    frequency_hz: float
    t: np.ndarray
    amplitude: np.ndarray
    noise_floor_m: np.ndarray
    threshold_m: np.ndarray
    intervals: np.ndarray

    def peak(self, start: float, end: float) -> tuple[float, int]:
        """Largest amplitude (m) between two times (s) and the index of its section."""
        inside = (self.t >= start) & (self.t <= end)
        a = np.where(np.isfinite(self.amplitude[inside]), self.amplitude[inside], -np.inf)
        i, k = np.unravel_index(int(np.argmax(a)), a.shape)
        return float(a[i, k]), int(k)


def _regular(t: np.ndarray, acc: np.ndarray, name: str) -> tuple[np.ndarray, float]:
    """The record on its regular clock from t[0], NaN where a sample is missing, and the rate (Hz)."""
    steps = np.diff(t)
    if t.size < 2 or not np.all(steps > 0):
        raise InputError(f"{name}: the time stamps must increase strictly (at least 2 samples)")
    fs = 1.0 / float(np.median(steps))
    pos = (t - t[0]) * fs
    idx = np.rint(pos).astype(np.int64)
    off = np.abs(pos - idx)
    if off.max() > _CLOCK_TOLERANCE:
        i = int(np.argmax(off))
        raise InputError(f"{name}: the time stamp {t[i] - t[0]:.6g} s after the first is {off[i]:.2f} steps away from "
                         f"a regular {fs:.6g} Hz clock (at most {_CLOCK_TOLERANCE} allowed); the record needs one sample clock")
    out = np.full((int(idx[-1]) + 1, acc.shape[1]), np.nan)
    out[idx] = acc
    return out, fs


def _decimate(x: np.ndarray, q: int) -> np.ndarray:
    """Every gap-free run of at least two output samples decimated by q (anti-aliasing polyphase filter); NaN elsewhere.

    Decimated sample j stands for input sample j * q.
    """
    if q == 1:
        return x
    out = np.full((-(-x.shape[0] // q), x.shape[1]), np.nan)
    _, starts, ends = valid_runs(1.0, x, 0.0)
    for i0, i1 in zip(starts, ends):
        j0 = -(-int(i0) // q)  # first decimated sample inside the run
        if i1 - j0 * q < 2 * q:
            continue
        run = x[j0 * q:i1]
        mean = run.mean(axis=0)
        y = signal.resample_poly(run - mean, 1, q, axis=0) + mean
        out[j0:j0 + y.shape[0]] = y
    return out


def _amplitude(x: np.ndarray, fs: float, f_mode: float, config: EventDetectionConfig) -> np.ndarray:
    """Smoothed envelope of the mode's displacement (m) of every gap-free run of four periods; NaN elsewhere."""
    shortest = int(math.ceil(4.0 * fs / (f_mode * (1.0 - config.half_width))))  # four periods
    width = max(1, int(round(config.smoothing_s * fs)))
    amp = np.full(x.shape, np.nan)
    _, starts, ends = valid_runs(fs, x, 0.0)
    for i0, i1 in zip(starts, ends):
        if i1 - i0 < shortest:
            continue
        env = envelope(displacement(x[i0:i1], fs, f_mode, config.half_width * f_mode))
        amp[i0:i1] = uniform_filter1d(env, width, axis=0, mode="nearest") if width > 1 else env
    return amp


def detect_events(t, acc, config: EventDetectionConfig | None = None, *, name: str = "acc") -> EventDetection:
    """Find VIV events in a continuous acceleration record.

    Parameters
    ----------
    t : array_like, shape (n,), s
        Sample times; missing samples are missing times or NaN values.
    acc : array_like, shape (n,) or (n, S), m/s^2
        Vertical deck acceleration of each section.
    config : EventDetectionConfig, optional
    name : str
        What to call the record in error messages (a file name).

    Returns
    -------
    EventDetection
        Possibly with no interval.

    Raises
    ------
    InputError
        A record off a regular clock, too short to resolve the search band,
        without a spectral peak inside it, or with no valid amplitude.
    """
    config = config or EventDetectionConfig()
    t = np.asarray(t, dtype=float)
    acc = as_2d(np.asarray(acc, dtype=float))
    if t.ndim != 1 or t.shape[0] != acc.shape[0]:
        raise InputError(f"{name}: t has shape {t.shape} but acc has {acc.shape}; expected (n,) and (n, S)")
    x, fs = _regular(t, acc, name)
    # Two decimations keep a long record small: to the search band, then to the mode's band.
    hi = config.band_hz[1] if config.frequency_hz is None else config.frequency_hz * (1.0 + config.half_width)
    if hi >= 0.5 * fs:
        raise InputError(f"{name}: the band up to {hi:.4g} Hz must lie below the Nyquist frequency {0.5 * fs:g} Hz; "
                         f"lower band_hz")
    per_period = _SEARCH_SAMPLES_PER_PERIOD if config.frequency_hz is None else _SAMPLES_PER_PERIOD
    q0 = max(1, int(fs // (per_period * hi)))
    x, fs = _decimate(x, q0), fs / q0
    try:
        f_mode = config.frequency_hz or modal_frequency(fs, x, config.band_hz, segment_s=config.segment_s)
    except InputError as exc:
        raise InputError(f"{name}: {exc}") from None
    q1 = max(1, int(fs // (_SAMPLES_PER_PERIOD * f_mode * (1.0 + config.half_width))))
    x, fs = _decimate(x, q1), fs / q1
    amp = _amplitude(x, fs, f_mode, config)
    t_d = t[0] + np.arange(amp.shape[0]) / fs
    finite = np.isfinite(amp)
    if not finite.any(axis=0).all():
        raise InputError(f"{name}: no gap-free run of four periods of the {f_mode:.4g} Hz mode at some section")
    floor = np.nanmedian(amp, axis=0)
    threshold = np.full(amp.shape[1], config.threshold_m) if config.threshold_m is not None else config.threshold_factor * floor
    above = np.any(np.where(finite, amp, -np.inf) > threshold[None, :], axis=1)
    intervals = threshold_intervals(t_d, above, merge_gap_s=config.merge_gap_s, min_duration_s=config.min_duration_s)
    return EventDetection(frequency_hz=float(f_mode), t=t_d, amplitude=amp, noise_floor_m=floor,
                          threshold_m=threshold, intervals=intervals)
