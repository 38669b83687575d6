"""Preprocessing of the identification chain (DESIGN 3.1): raw arrays to A and U on one grid.

The chain follows the paper's Section III. Wind: the horizontal speed V and
direction theta come from the east and north components, the component
perpendicular to the span is U~ = V |sin(theta - span azimuth)|, and the
slowly varying mean wind U is a zero-phase low-pass of U~. Vibration: the
vertical acceleration is integrated twice in the frequency domain inside a
band around the VIV mode, and the amplitude A is the Hilbert envelope of that
displacement. Both are put on one coarse time grid (the envelope and the mean
wind are slow) after dropping the samples that the filters corrupt near every
end of the record and near every gap.

Conventions
-----------
- ``u`` points east, ``v`` north (the event file's axes, DESIGN 4).
- ``theta`` is meteorological: the direction the wind blows *from*, in degrees
  clockwise from north in [0, 360). A wind from the west (blowing east,
  ``u > 0, v = 0``) has theta = 270.
- ``span_azimuth_deg`` is the direction of the span axis, degrees clockwise
  from north; azimuths a and a + 180 describe the same span. The wind is
  perpendicular to the span when theta - azimuth is 90 or 270 degrees (the
  paper's Fig. 2) and U~ = V there.

Gaps
----
Gaps are NaN blocks (DESIGN 4), or jumps in the time stamps. Nothing is
interpolated across a gap unless it is no longer than
``PreprocessConfig.max_gap_s`` (default 0: never). Every contiguous valid run
of a stream is filtered on its own and loses ``edge_s`` at both ends; the
output keeps the times trusted by both streams, split into numbered segments.
A time stamp is valid only when every section of the stream is finite there
(``u`` and ``v`` for the wind, ``acc`` for the vibration), so that all
sections share one grid and one segment numbering.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import fft as sp_fft
from scipy import signal

from vivbench.preprocess.band import band_gain
from vivbench.preprocess.noise_floor import band_noise_std
from vivbench.core.errors import InputError

__all__ = [
    "PreprocessConfig",
    "Preprocessed",
    "wind_speed_direction",
    "perpendicular_speed",
    "mean_wind",
    "modal_frequency",
    "welch_psd",
    "spectral_peak",
    "displacement",
    "envelope",
    "segments",
    "common_grid",
    "to_grid",
    "preprocess_arrays",
]

# A step between time stamps larger than this multiple of the nominal step is a
# gap in the record (missing samples), even without NaN.
_TIME_JUMP_FACTOR = 1.5
# The dropped edge must cover this many time constants of each filter.
_SETTLING_TIME_CONSTANTS = 3.0


def _positive(name: str, value: float) -> None:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise InputError(f"{name} must be a positive finite number; got {value!r}")


@dataclass(frozen=True, kw_only=True)
class PreprocessConfig:
    """Settings of the preprocessing chain.

    Parameters
    ----------
    wind_cutoff_hz : float
        Cut-off of the low-pass that turns U~ into the mean wind U, Hz. The
        default 1/60 Hz keeps the dynamics of the 10-60 min mean wind
        (DESIGN 2.4) and removes turbulence with periods shorter than about a
        minute; a 50 s SINDy window then sees a nearly constant U, as the
        paper's amplitude equation assumes.
    wind_filter_order : int
        Order of the Butterworth low-pass. It is applied forward and backward
        (``scipy.signal.sosfiltfilt``): zero phase, squared magnitude, so U is
        not delayed with respect to A.
    band_half_width : float
        Half-width of the vibration band as a fraction of the modal
        frequency, 0 < value < 1 (default 0.3: the band is f_mode +- 30 %).
        Narrow it when other modes lie within 30 % of the VIV mode.
    band_half_width_hz : float or None
        Half-width of the band in Hz; when given it replaces
        ``band_half_width``.
    band_taper : float
        Fraction of the half-width over which the band's gain falls from 1 to
        0 along a raised cosine (0 < value <= 1). Smooth edges keep the ringing
        of the band filter short.
    modal_frequency_hz : float or None
        Frequency of the vibration mode, Hz. None (default) finds it from the
        acceleration spectrum in ``search_band_hz``: other bridges have other
        modes.
    search_band_hz : tuple of float
        (low, high) band searched for the spectral peak when the modal
        frequency is not given, Hz.
    welch_segment_s : float
        Length of the Welch sections of the spectrum, s (resolution about
        1 / value Hz before the peak is interpolated).
    edge_s : float
        Seconds dropped at both ends of every valid run of each stream, at
        least: the chain drops max(edge_s, three time constants of either
        filter), see :meth:`settling_s`. The time constants are
        1 / (2 pi wind_cutoff_hz) for the wind low-pass (9.5 s by default) and
        1 / (pi band_taper half-width) for the vibration band, whose ringing
        is set by its raised-cosine edges (6.5 s for the default band around
        0.327 Hz). The default 60 s covers both for modes above about 0.11 Hz
        (measured on a noise-free synthetic oscillation at 0.327 Hz: the
        band filter's end ringing leaves an envelope error of at most 1.7 %
        20 s from an end, 0.4 % at 30 s and 0.17 % at 60 s).
    grid_step_s : float
        Step of the output grid, s. Grid times are integer multiples of the
        step (counted from the record's start time), so grids of different
        records and of the truth line up. A few Hz is plenty: A and U are slow.
    max_gap_s : float
        Longest gap (missing duration, s) bridged by linear interpolation
        before filtering. The default 0 bridges nothing: any NaN sample splits
        the record. Set it to a few sample steps to bridge isolated dropouts.
    min_segment_s : float
        Shortest output segment kept, s (after the edges are dropped). The
        default 60 s holds one 50 s SINDy window.
    """

    wind_cutoff_hz: float = 1.0 / 60.0
    wind_filter_order: int = 4
    band_half_width: float = 0.3
    band_half_width_hz: float | None = None
    band_taper: float = 0.5
    modal_frequency_hz: float | None = None
    search_band_hz: tuple[float, float] = (0.05, 2.0)
    welch_segment_s: float = 300.0
    edge_s: float = 60.0
    grid_step_s: float = 0.25
    max_gap_s: float = 0.0
    min_segment_s: float = 60.0

    def __post_init__(self) -> None:
        _positive("wind_cutoff_hz", self.wind_cutoff_hz)
        order = self.wind_filter_order
        if isinstance(order, bool) or not (isinstance(order, (int, np.integer)) and 1 <= order <= 10):
            raise InputError(f"wind_filter_order must be an integer from 1 to 10; got {self.wind_filter_order!r}")
        if not (isinstance(self.band_half_width, (int, float)) and 0.0 < self.band_half_width < 1.0):
            raise InputError(
                f"band_half_width is a fraction of the modal frequency and must lie strictly between 0 and 1; "
                f"got {self.band_half_width!r}"
            )
        if self.band_half_width_hz is not None:
            _positive("band_half_width_hz", self.band_half_width_hz)
        if not (isinstance(self.band_taper, (int, float)) and 0.0 < self.band_taper <= 1.0):
            raise InputError(f"band_taper must lie in (0, 1]; got {self.band_taper!r}")
        if self.modal_frequency_hz is not None:
            _positive("modal_frequency_hz", self.modal_frequency_hz)
        band = tuple(self.search_band_hz)
        if len(band) != 2 or not all(math.isfinite(b) for b in band) or not 0.0 < band[0] < band[1]:
            raise InputError(f"search_band_hz must be (low, high) with 0 < low < high, Hz; got {self.search_band_hz!r}")
        object.__setattr__(self, "search_band_hz", (float(band[0]), float(band[1])))
        _positive("welch_segment_s", self.welch_segment_s)
        _positive("grid_step_s", self.grid_step_s)
        _positive("min_segment_s", self.min_segment_s)
        if not (isinstance(self.max_gap_s, (int, float)) and math.isfinite(self.max_gap_s) and self.max_gap_s >= 0):
            raise InputError(f"max_gap_s must be a finite number >= 0 (0 bridges no gap); got {self.max_gap_s!r}")
        if not (isinstance(self.edge_s, (int, float)) and math.isfinite(self.edge_s) and self.edge_s >= 0):
            raise InputError(f"edge_s must be a finite number of seconds >= 0; got {self.edge_s!r}")

    @property
    def wind_settling_s(self) -> float:
        """Three time constants of the wind low-pass, 3 / (2 pi wind_cutoff_hz), s."""
        return _SETTLING_TIME_CONSTANTS / (2.0 * math.pi * self.wind_cutoff_hz)

    def half_width_hz(self, f_mode: float) -> float:
        """Half-width of the vibration band around ``f_mode`` (Hz), Hz."""
        if self.band_half_width_hz is not None:
            return float(self.band_half_width_hz)
        return float(self.band_half_width * f_mode)

    def band_settling_s(self, f_mode: float) -> float:
        """Three time constants of the band filter around ``f_mode`` (Hz), 3 / (pi taper half-width), s."""
        return _SETTLING_TIME_CONSTANTS / (math.pi * self.band_taper * self.half_width_hz(f_mode))

    def settling_s(self, f_mode: float) -> float:
        """Edge dropped at each end of every valid run for a mode at ``f_mode`` (Hz), s."""
        return max(float(self.edge_s), self.wind_settling_s, self.band_settling_s(f_mode))


@dataclass(frozen=True, kw_only=True, eq=False)
class Preprocessed:
    """Result of :func:`preprocess_arrays`.

    Attributes
    ----------
    t : ndarray, shape (n,)
        Output grid, s from the record's start time.
    A : ndarray, shape (n, n_sections)
        Displacement amplitude (Hilbert envelope), m.
    U : ndarray, shape (n, n_sections)
        Mean wind speed perpendicular to the span, m/s.
    segment : ndarray of int, shape (n,)
        Contiguous segment of each grid time, 0, 1, ... in time order. Never
        differentiate or window across a change of segment.
    segment_bounds : ndarray, shape (n_segments, 2)
        Trusted interval [start, end] of each segment, s.
    edge_s : float
        Edge dropped at each end of every valid run, s
        (``config.settling_s(f_mode_hz)``).
    f_mode_hz : float
        Modal frequency used, Hz.
    f_mode_source : str
        ``"given"`` (from the configuration) or ``"spectrum"`` (found).
    band_hz : tuple of float
        (low, high) edges of the vibration band where the gain reaches 0, Hz.
    span_azimuth_deg : float
        Span azimuth used, degrees from north.
    config : PreprocessConfig
        The settings.
    noise_std : ndarray, shape (n_sections,)
        Accelerometer noise after integration to displacement in the band, m:
        the noise floor of A (:mod:`vivbench.preprocess.noise_floor`); NaN
        where it could not be estimated.
    """

    t: np.ndarray
    A: np.ndarray
    U: np.ndarray
    segment: np.ndarray
    segment_bounds: np.ndarray
    edge_s: float
    f_mode_hz: float
    f_mode_source: str
    band_hz: tuple[float, float]
    span_azimuth_deg: float
    config: PreprocessConfig
    noise_std: np.ndarray

    @property
    def n_segments(self) -> int:
        """Number of contiguous segments."""
        return int(self.segment_bounds.shape[0])


# --------------------------------------------------------------------------- wind


def wind_speed_direction(u, v) -> tuple[np.ndarray, np.ndarray]:
    """Horizontal wind speed and meteorological direction.

    Parameters
    ----------
    u, v : array_like, same shape
        Eastward and northward wind components, m/s.

    Returns
    -------
    V : ndarray
        Horizontal speed sqrt(u^2 + v^2), m/s.
    theta : ndarray
        Direction the wind blows FROM, degrees clockwise from north, in
        [0, 360). A calm (V = 0) gets 0.
    """
    u = np.asarray(u, dtype=float)
    v = np.asarray(v, dtype=float)
    if u.shape != v.shape:
        raise ValueError(f"u and v must have the same shape; got {u.shape} and {v.shape}")
    V = np.hypot(u, v)
    # The wind comes from the direction opposite to its velocity vector (-u, -v).
    theta = np.mod(np.degrees(np.arctan2(-u, -v)), 360.0)
    # np.mod can round a tiny negative angle up to exactly 360.
    theta = np.where(theta >= 360.0, 0.0, theta)
    return V, theta


def perpendicular_speed(V, theta, span_azimuth_deg: float) -> np.ndarray:
    """Wind speed perpendicular to the span, U~ = V |sin(theta - span azimuth)|.

    Parameters
    ----------
    V : array_like
        Horizontal wind speed, m/s.
    theta : array_like, broadcastable with ``V``
        Meteorological wind direction (from), degrees from north.
    span_azimuth_deg : float
        Direction of the span axis, degrees from north (a and a + 180 are the
        same span).

    Returns
    -------
    ndarray
        U~, m/s; equal to V when the wind blows across the span and 0 when
        it blows along it.
    """
    V = np.asarray(V, dtype=float)
    theta = np.asarray(theta, dtype=float)
    return V * np.abs(np.sin(np.radians(theta - float(span_azimuth_deg))))


def _lowpass(x: np.ndarray, fs: float, config: PreprocessConfig) -> np.ndarray:
    """Zero-phase Butterworth low-pass along axis 0 of a gap-free run."""
    if config.wind_cutoff_hz >= 0.5 * fs:
        raise InputError(
            f"wind_cutoff_hz = {config.wind_cutoff_hz} Hz must lie below the Nyquist frequency {0.5 * fs} Hz"
        )
    sos = signal.butter(config.wind_filter_order, config.wind_cutoff_hz, btype="low", fs=fs, output="sos")
    # Odd extension over one settling time continues the run's level and
    # slope; on synthetic turbulence it gave about half the end error of
    # mirror (even) extension, which forces a zero slope at the ends.
    padlen = min(x.shape[0] - 1, int(round(config.wind_settling_s * fs)))
    return signal.sosfiltfilt(sos, x, axis=0, padtype="odd", padlen=padlen)


def mean_wind(t, u, v, span_azimuth_deg: float, config: PreprocessConfig | None = None) -> np.ndarray:
    """Mean wind speed perpendicular to the span, U = low-pass(U~).

    Parameters
    ----------
    t : array_like, shape (n,)
        Sample times, s, strictly increasing (nominally 32 Hz).
    u, v : array_like, shape (n,) or (n, n_sections)
        Eastward and northward wind components, m/s; NaN marks missing data.
    span_azimuth_deg : float
        Direction of the span axis, degrees from north.
    config : PreprocessConfig, optional
        Uses ``wind_cutoff_hz``, ``wind_filter_order`` and ``max_gap_s``.

    Returns
    -------
    U : ndarray, shape of ``u``
        Low-passed U~, m/s. Each valid run is filtered on its own; times in
        gaps that are not bridged are NaN. Edges are NOT dropped here: the
        first and last ``config.wind_settling_s`` (or more) of each run
        carry filter transients.
    """
    config = PreprocessConfig() if config is None else config
    t = _check_time(t, "t")
    U_tilde = _wind_perpendicular(t, u, v, span_azimuth_deg)
    U, _ = _mean_wind_runs(t, U_tilde, config)
    return U.reshape(np.shape(u))


def _wind_perpendicular(t: np.ndarray, u, v, span_azimuth_deg: float) -> np.ndarray:
    u = np.asarray(u, dtype=float)
    v = np.asarray(v, dtype=float)
    if u.shape != v.shape or u.shape[0] != t.shape[0] or u.ndim > 2:
        raise ValueError(
            f"u and v must both have shape (n,) or (n, n_sections) with n = len(t) = {t.shape[0]}; "
            f"got {u.shape} and {v.shape}"
        )
    if not math.isfinite(float(span_azimuth_deg)):
        raise InputError(f"span_azimuth_deg must be finite; got {span_azimuth_deg!r}")
    V, theta = wind_speed_direction(u, v)
    return _as_2d(perpendicular_speed(V, theta, span_azimuth_deg))


def _mean_wind_runs(t: np.ndarray, U_tilde: np.ndarray, config: PreprocessConfig):
    """Low-pass each valid run of U~ (n, k); returns U (NaN in gaps) and the runs."""
    filled, starts, ends = _valid_runs(t, U_tilde, config.max_gap_s)
    U = np.full_like(filled, np.nan)
    for i0, i1 in zip(starts, ends):
        if i1 - i0 < 2:
            continue
        U[i0:i1] = _lowpass(filled[i0:i1], _run_rate(t, i0, i1), config)
    return U, (starts, ends)


# ---------------------------------------------------------------------- vibration


def welch_psd(t_or_fs, acc, segment_s: float, lo: float, hi: float) -> tuple[np.ndarray, np.ndarray]:
    """Welch PSD of each section averaged over the valid runs, shape (n_freq, n_sections).

    Each run is weighted by its number of Welch sections. Raises ValueError if
    the longest run cannot resolve ``lo`` (three cycles per section) or ``hi``
    is not below the Nyquist frequency.
    """
    _positive("segment_s", segment_s)
    acc = _as_2d(np.asarray(acc, dtype=float))
    if np.ndim(t_or_fs) == 0:
        fs = float(t_or_fs)
        _positive("sampling rate", fs)
        _, starts, ends = _valid_runs(fs, acc, 0.0)
    else:
        t = _check_time(t_or_fs, "t")
        if t.shape[0] != acc.shape[0]:
            raise ValueError(f"t has {t.shape[0]} samples but acc has {acc.shape[0]}")
        fs = 1.0 / float(np.median(np.diff(t)))
        _, starts, ends = _valid_runs(t, acc, 0.0)
    if hi >= 0.5 * fs:
        raise InputError(f"band upper edge {hi} Hz must lie below the Nyquist frequency {0.5 * fs} Hz")
    lengths = ends - starts
    longest = int(lengths.max()) if lengths.size else 0
    nperseg = min(int(round(segment_s * fs)), longest)
    # Three cycles of the lowest frequency searched per section, so that the
    # bins resolve the band.
    if nperseg < 3.0 * fs / lo:
        raise InputError(
            f"the longest valid run ({longest / fs:.1f} s) is too short to resolve the band down to {lo} Hz "
            f"(needs at least {3.0 / lo:.1f} s)"
        )
    nfft = 1 << int(math.ceil(math.log2(4 * nperseg)))
    step = nperseg - nperseg // 2
    psd_sum = 0.0
    weight = 0
    for i0, i1 in zip(starts, ends):
        if i1 - i0 < nperseg:
            continue
        f, P = signal.welch(acc[i0:i1], fs=fs, window="hann", nperseg=nperseg, nfft=nfft, detrend="linear", axis=0)
        n_sections = 1 + (i1 - i0 - nperseg) // step
        psd_sum = psd_sum + n_sections * P
        weight += n_sections
    return f, psd_sum / weight


def spectral_peak(f: np.ndarray, psd: np.ndarray, lo: float, hi: float) -> float:
    """Highest bin strictly inside [lo, hi], refined by a parabola through the log-PSD."""
    inside = np.flatnonzero((f >= lo) & (f <= hi))
    k = inside[np.argmax(psd[inside])]
    if k == inside[0] or k == inside[-1] or psd[k] <= 0:
        raise InputError(
            f"the acceleration spectrum has no peak strictly inside {lo}-{hi} Hz (its maximum there is at "
            f"{f[k]:.4g} Hz, on the edge); widen the search band or give the modal frequency"
        )
    a, b, c = np.log(psd[k - 1 : k + 2])
    denom = a - 2.0 * b + c
    delta = 0.5 * (a - c) / denom if denom < 0 else 0.0
    return float(f[k] + delta * (f[1] - f[0]))


def modal_frequency(t_or_fs, acc, band: tuple[float, float] = (0.05, 2.0), *, segment_s: float = 300.0) -> float:
    """Dominant frequency of the acceleration in a band, from a Welch spectrum.

    The spectra of all sections and of all valid runs are averaged (each run
    weighted by its number of Welch sections); the highest bin strictly
    inside the band is refined by a parabola through the logarithm of the
    peak bin and its neighbours (exact for a Gaussian peak, close to the Hann
    window's main lobe).

    Parameters
    ----------
    t_or_fs : float or array_like, shape (n,)
        Sampling rate in Hz, or the sample times in s (jumps in the time
        stamps then split the record like NaN gaps).
    acc : array_like, shape (n,) or (n, n_sections)
        Acceleration, m/s^2; NaN marks missing data.
    band : tuple of float
        (low, high) search band, Hz.
    segment_s : float
        Length of the Welch sections, s; shortened to the longest valid run
        when that is shorter.

    Returns
    -------
    float
        Modal frequency, Hz.

    Raises
    ------
    ValueError
        If the record is too short to resolve the band, or the largest value
        in the band lies on its edge (no peak inside the band).
    """
    lo, hi = float(band[0]), float(band[1])
    if not 0.0 < lo < hi:
        raise InputError(f"band must be (low, high) with 0 < low < high, Hz; got {band!r}")
    f, psd = welch_psd(t_or_fs, acc, segment_s, lo, hi)
    return spectral_peak(f, psd.sum(axis=1), lo, hi)


def displacement(acc, fs: float, f_mode: float, half_width: float, *, taper: float = 0.5) -> np.ndarray:
    """Displacement from acceleration by integration in the frequency domain.

    The record (mean removed) is zero-padded to at least twice its length,
    transformed, divided by -(2 pi f)^2 inside the band f_mode +- half_width
    (with raised-cosine edges over the outer ``taper`` fraction of the
    half-width) and set to zero outside, then transformed back. Zero padding
    turns the FFT's circular wrap-around into ordinary end effects, which the
    caller drops with the edges.

    Parameters
    ----------
    acc : array_like, shape (n,) or (n, n_sections)
        Acceleration of one gap-free run sampled uniformly, m/s^2.
    fs : float
        Sampling rate, Hz.
    f_mode : float
        Centre of the band, Hz.
    half_width : float
        Half-width of the band, Hz; the band must lie in (0, fs / 2).
    taper : float
        Fraction of the half-width taken by each raised-cosine edge, (0, 1].

    Returns
    -------
    ndarray, shape of ``acc``
        Band-limited displacement, m.
    """
    acc = np.asarray(acc, dtype=float)
    _positive("fs", fs)
    _positive("f_mode", f_mode)
    _positive("half_width", half_width)
    if not 0.0 < taper <= 1.0:
        raise InputError(f"taper must lie in (0, 1]; got {taper!r}")
    if f_mode - half_width <= 0.0 or f_mode + half_width >= 0.5 * fs:
        raise InputError(
            f"the band {f_mode - half_width:.4g}-{f_mode + half_width:.4g} Hz must lie strictly between 0 Hz and "
            f"the Nyquist frequency {0.5 * fs} Hz"
        )
    if acc.ndim not in (1, 2) or acc.shape[0] < 2:
        raise ValueError(f"acc must have shape (n,) or (n, n_sections) with n >= 2; got {acc.shape}")
    if not np.all(np.isfinite(acc)):
        raise ValueError("acc must be finite: split the record at its gaps first (see segments)")
    n = acc.shape[0]
    nfft = sp_fft.next_fast_len(2 * n, real=True)
    f = sp_fft.rfftfreq(nfft, d=1.0 / fs)
    gain = band_gain(f, f_mode, half_width, taper)
    H = np.zeros_like(f)
    inband = gain > 0
    H[inband] = -gain[inband] / (2.0 * np.pi * f[inband]) ** 2
    H = H.reshape((-1,) + (1,) * (acc.ndim - 1))
    X = sp_fft.rfft(acc - acc.mean(axis=0), n=nfft, axis=0)
    return sp_fft.irfft(X * H, n=nfft, axis=0)[:n]


def envelope(y) -> np.ndarray:
    """Amplitude envelope |y + i H[y]| by the Hilbert transform.

    Parameters
    ----------
    y : array_like, shape (n,) or (n, n_sections)
        Band-limited oscillation of one gap-free run (e.g. from
        :func:`displacement`), m.

    Returns
    -------
    ndarray, shape of ``y``
        Envelope, same unit as ``y``. The analytic signal is computed on the
        record zero-padded to at least twice its length, so the ends do not
        wrap around onto each other; end effects remain and are dropped with
        the edges.
    """
    y = np.asarray(y, dtype=float)
    if y.ndim not in (1, 2) or y.shape[0] < 2:
        raise ValueError(f"y must have shape (n,) or (n, n_sections) with n >= 2; got {y.shape}")
    n = y.shape[0]
    z = signal.hilbert(y, N=sp_fft.next_fast_len(2 * n), axis=0)
    return np.abs(z[:n])


# ------------------------------------------------------------------ gaps and grid


def _run_bounds(mask: np.ndarray, breaks: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Start and end (exclusive) indices of the runs of True in ``mask``.

    ``breaks[i]`` True splits a run between samples i and i + 1.
    """
    mask = np.asarray(mask, dtype=bool)
    cut = ~(mask[:-1] & mask[1:])
    if breaks is not None:
        cut = cut | breaks
    start = mask.copy()
    start[1:] &= cut
    end = mask.copy()
    end[:-1] &= cut
    return np.flatnonzero(start), np.flatnonzero(end) + 1


def _positions(starts: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Concatenation of arange(s, s + l) over the runs, without a Python loop."""
    offsets = np.cumsum(lengths) - lengths
    return np.arange(int(lengths.sum())) + np.repeat(starts - offsets, lengths)


def segments(valid_mask, min_length: int = 1) -> np.ndarray:
    """Number the contiguous runs of valid samples.

    Parameters
    ----------
    valid_mask : array_like of bool, shape (n,)
        True where the sample is usable.
    min_length : int
        Runs shorter than this many samples are dropped.

    Returns
    -------
    ndarray of int, shape (n,)
        Segment id 0, 1, ... of each sample, in time order; -1 for invalid
        samples and for samples of dropped runs.
    """
    mask = np.asarray(valid_mask, dtype=bool)
    if mask.ndim != 1:
        raise ValueError(f"valid_mask must be one-dimensional; got shape {mask.shape}")
    if not (isinstance(min_length, (int, np.integer)) and min_length >= 1):
        raise ValueError(f"min_length must be an integer >= 1 (samples); got {min_length!r}")
    ids = np.full(mask.shape[0], -1, dtype=int)
    if mask.size == 0:
        return ids
    starts, ends = _run_bounds(mask)
    lengths = ends - starts
    keep = lengths >= min_length
    starts, lengths = starts[keep], lengths[keep]
    ids[_positions(starts, lengths)] = np.repeat(np.arange(starts.size), lengths)
    return ids


def common_grid(intervals, step_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Grid times inside intervals, on integer multiples of the step.

    Parameters
    ----------
    intervals : array_like, shape (k, 2)
        Disjoint [start, end] intervals in increasing order, s.
    step_s : float
        Grid step, s.

    Returns
    -------
    t : ndarray, shape (n,)
        All times m * step_s (m integer) inside the intervals, ends included.
    segment : ndarray of int, shape (n,)
        Index of the interval of each time, renumbered 0, 1, ... over the
        intervals that hold at least one grid time.
    """
    t, segment, _ = _grid(intervals, step_s)
    return t, segment


def _grid(intervals, step_s: float):
    """:func:`common_grid` plus the mask of intervals that hold a grid time."""
    _positive("step_s", step_s)
    iv = np.asarray(intervals, dtype=float).reshape(-1, 2)
    if np.any(iv[:, 1] < iv[:, 0]) or np.any(iv[1:, 0] <= iv[:-1, 1]):
        raise ValueError("intervals must be [start, end] pairs with start <= end, disjoint and increasing")
    # A tolerance of a millionth of a step keeps an end that lands on the
    # lattice up to rounding.
    first = np.ceil(iv[:, 0] / step_s - 1e-6).astype(np.int64)
    last = np.floor(iv[:, 1] / step_s + 1e-6).astype(np.int64)
    counts = np.maximum(last - first + 1, 0)
    keep = counts > 0
    first, counts = first[keep], counts[keep]
    m = _positions(first, counts)
    return m * step_s, np.repeat(np.arange(first.size), counts), keep


def to_grid(t_src, x_src, t_grid) -> np.ndarray:
    """Linear interpolation of samples onto grid times.

    Parameters
    ----------
    t_src : array_like, shape (n,)
        Strictly increasing source times, s.
    x_src : array_like, shape (n,) or (n, k)
        Source values; a NaN neighbour makes the interpolated value NaN
        (unless the grid time coincides with a finite sample).
    t_grid : array_like, shape (m,)
        Grid times, s.

    Returns
    -------
    ndarray, shape (m,) or (m, k)
        Interpolated values; NaN outside [t_src[0], t_src[-1]]. Linear
        interpolation suits slow signals (envelope, mean wind) sampled well
        above their bandwidth, as here after the low-pass.
    """
    t_src = _check_time(t_src, "t_src")
    x = np.asarray(x_src, dtype=float)
    if x.shape[0] != t_src.shape[0] or x.ndim > 2:
        raise ValueError(f"x_src must have shape (n,) or (n, k) with n = len(t_src) = {t_src.shape[0]}; got {x.shape}")
    tg = np.asarray(t_grid, dtype=float)
    if tg.ndim != 1:
        raise ValueError(f"t_grid must be one-dimensional; got shape {tg.shape}")
    i = np.clip(np.searchsorted(t_src, tg, side="right") - 1, 0, t_src.shape[0] - 2)
    w = (tg - t_src[i]) / (t_src[i + 1] - t_src[i])
    if x.ndim == 2:
        w = w[:, None]
    x0, x1 = x[i], x[i + 1]
    out = np.where(w == 0.0, x0, np.where(w == 1.0, x1, x0 + w * (x1 - x0)))
    outside = (tg < t_src[0]) | (tg > t_src[-1])
    out[outside] = np.nan
    return out


def _check_time(t, name: str) -> np.ndarray:
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or t.shape[0] < 2:
        raise InputError(f"{name} must be a one-dimensional array of at least 2 times; got shape {t.shape}")
    if not np.all(np.isfinite(t)):
        raise InputError(f"{name} must be finite (times are authoritative; gaps are NaN in the data, not in time)")
    if np.any(np.diff(t) <= 0):
        raise InputError(f"{name} must be strictly increasing")
    return t


def _as_2d(x: np.ndarray) -> np.ndarray:
    return x[:, None] if x.ndim == 1 else x


def _run_rate(t: np.ndarray, i0: int, i1: int) -> float:
    """Mean sampling rate of samples i0..i1-1, Hz."""
    return (i1 - 1 - i0) / (t[i1 - 1] - t[i0])


def _valid_runs(t, x: np.ndarray, max_gap_s: float):
    """Bridge short gaps and find the valid runs of a (n, k) stream.

    ``t`` is the time array, or a sampling rate (then only NaN splits runs).
    A sample is valid when all k channels are finite. Gaps whose missing
    duration is at most ``max_gap_s`` and that lie between valid samples
    without a time jump are filled by linear interpolation in time.

    Returns
    -------
    filled : ndarray (n, k), starts, ends : ndarray of int
    """
    x = _as_2d(np.asarray(x, dtype=float))
    n = x.shape[0]
    if np.ndim(t) == 0:
        t = np.arange(n) / float(t)
        jumps = np.zeros(max(n - 1, 0), dtype=bool)
    else:
        dt = np.diff(t)
        jumps = dt > _TIME_JUMP_FACTOR * np.median(dt)
    valid = np.all(np.isfinite(x), axis=1)
    filled = x.copy()
    if max_gap_s > 0 and not valid.all() and valid.sum() >= 2:
        dt_nominal = float(np.median(np.diff(t)))
        g0, g1 = _run_bounds(~valid)
        inner = (g0 > 0) & (g1 < n)
        g0, g1 = g0[inner], g1[inner]
        missing = t[np.minimum(g1, n - 1)] - t[np.maximum(g0 - 1, 0)] - dt_nominal
        # A time jump next to or inside the gap means more is missing than the NaN count says.
        jump_count = np.concatenate(([0], np.cumsum(jumps)))
        no_jump = jump_count[g1] - jump_count[g0 - 1] == 0
        bridge = (missing <= max_gap_s * (1 + 1e-9)) & no_jump
        if np.any(bridge):
            pos = _positions(g0[bridge], g1[bridge] - g0[bridge])
            for c in range(x.shape[1]):
                filled[pos, c] = np.interp(t[pos], t[valid], x[valid, c])
            valid = valid.copy()
            valid[pos] = True
    starts, ends = _run_bounds(valid, jumps)
    return filled, starts, ends


def _trusted(t: np.ndarray, starts: np.ndarray, ends: np.ndarray, edge_s: float) -> np.ndarray:
    """Intervals (k, 2) of the runs shrunk by edge_s at both ends; empty ones dropped."""
    iv = np.column_stack((t[starts] + edge_s, t[ends - 1] - edge_s)) if starts.size else np.empty((0, 2))
    return iv[iv[:, 1] > iv[:, 0]]


def _intersect(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pairwise intersections of two sets of disjoint sorted intervals, sorted."""
    lo = np.maximum(a[:, None, 0], b[None, :, 0]).ravel()
    hi = np.minimum(a[:, None, 1], b[None, :, 1]).ravel()
    keep = hi > lo
    iv = np.column_stack((lo[keep], hi[keep]))
    return iv[np.argsort(iv[:, 0])]


# --------------------------------------------------------------------- the chain


def preprocess_arrays(
    *,
    wind_time,
    u,
    v,
    accel_time,
    acc,
    span_azimuth_deg: float,
    config: PreprocessConfig | None = None,
) -> Preprocessed:
    """Whole preprocessing chain on arrays: A and U of every section on one grid.

    Parameters
    ----------
    wind_time : array_like, shape (n_w,)
        Anemometer times, s from the record's start (nominally 32 Hz).
    u, v : array_like, shape (n_w, n_sections) or (n_w,)
        Eastward and northward wind, m/s; NaN marks missing data.
    accel_time : array_like, shape (n_a,)
        Accelerometer times, s from the same start (nominally 50 Hz).
    acc : array_like, shape (n_a, n_sections) or (n_a,)
        Vertical deck acceleration, m/s^2; NaN marks missing data.
    span_azimuth_deg : float
        Direction of the span axis, degrees from north (from the event file).
    config : PreprocessConfig, optional
        Settings; defaults as documented there.

    Returns
    -------
    Preprocessed
        The grid, A (m), U (m/s), segment ids and the settings used. The
        output may be empty (no segment long enough); ``n_segments`` says so.

    Notes
    -----
    The modal frequency, when not given, is found once from the whole record
    (all sections and valid runs) and used for every section and segment.
    Each valid run of each stream is processed on its own and trusted from
    ``edge_s`` after its start to ``edge_s`` before its end (``edge_s`` =
    ``config.settling_s(f_mode)``, reported in the result); the output
    segments are the intersections of the two streams' trusted intervals
    that last at least ``min_segment_s``.
    """
    config = PreprocessConfig() if config is None else config
    wind_time = _check_time(wind_time, "wind_time")
    accel_time = _check_time(accel_time, "accel_time")
    U_tilde = _wind_perpendicular(wind_time, u, v, span_azimuth_deg)
    acc = _as_2d(np.asarray(acc, dtype=float))
    if acc.ndim != 2 or acc.shape[0] != accel_time.shape[0]:
        raise ValueError(
            f"acc must have shape (n,) or (n, n_sections) with n = len(accel_time) = {accel_time.shape[0]}; "
            f"got {acc.shape}"
        )
    if acc.shape[1] != U_tilde.shape[1]:
        raise ValueError(f"the wind has {U_tilde.shape[1]} sections but the acceleration has {acc.shape[1]}")

    lo, hi = config.search_band_hz
    if config.modal_frequency_hz is not None:
        f_mode, source = float(config.modal_frequency_hz), "given"
        try:
            f_psd, psd = welch_psd(accel_time, acc, config.welch_segment_s, lo, hi)
        except ValueError:  # a given mode needs no spectrum; the noise floor stays unknown
            f_psd = psd = None
    else:
        # One spectrum serves the mode and the noise floor.
        f_psd, psd = welch_psd(accel_time, acc, config.welch_segment_s, lo, hi)
        f_mode, source = spectral_peak(f_psd, psd.sum(axis=1), lo, hi), "spectrum"
    half_width = config.half_width_hz(f_mode)
    if psd is None:
        noise_std = np.full(acc.shape[1], np.nan)
    else:
        noise_std = band_noise_std(f_psd, psd, f_mode, half_width, taper=config.band_taper)
    edge_s = config.settling_s(f_mode)

    U_wind, (w_starts, w_ends) = _mean_wind_runs(wind_time, U_tilde, config)
    wind_iv = _trusted(wind_time, w_starts, w_ends, edge_s)

    acc_filled, a_starts, a_ends = _valid_runs(accel_time, acc, config.max_gap_s)
    A_acc = np.full_like(acc_filled, np.nan)
    for i0, i1 in zip(a_starts, a_ends):
        # Runs that leave nothing once the edges are dropped are not worth filtering.
        if accel_time[i1 - 1] - accel_time[i0] <= 2.0 * edge_s:
            continue
        y = displacement(
            acc_filled[i0:i1], _run_rate(accel_time, i0, i1), f_mode, half_width, taper=config.band_taper
        )
        A_acc[i0:i1] = envelope(y)
    accel_iv = _trusted(accel_time, a_starts, a_ends, edge_s)

    iv = _intersect(wind_iv, accel_iv)
    iv = iv[iv[:, 1] - iv[:, 0] >= config.min_segment_s]
    t_grid, seg, holds = _grid(iv, config.grid_step_s)
    iv = iv[holds]
    A = to_grid(accel_time, A_acc, t_grid)
    U = to_grid(wind_time, U_wind, t_grid)
    return Preprocessed(
        t=t_grid,
        A=A,
        U=U,
        segment=seg,
        segment_bounds=iv,
        edge_s=edge_s,
        f_mode_hz=f_mode,
        f_mode_source=source,
        band_hz=(f_mode - half_width, f_mode + half_width),
        span_azimuth_deg=float(span_azimuth_deg),
        config=config,
        noise_std=noise_std,
    )
