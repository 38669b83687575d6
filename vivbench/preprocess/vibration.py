"""Vibration: the modal frequency from the acceleration spectrum, displacement in the mode's band, its Hilbert envelope."""

from __future__ import annotations

import math

import numpy as np
from scipy import fft as sp_fft
from scipy import signal

from vivbench.preprocess.band import band_gain
from vivbench.core.errors import InputError
from vivbench.preprocess.runs import as_2d, check_positive, check_time, valid_runs

__all__ = ["welch_psd", "spectral_peak", "modal_frequency", "displacement", "envelope"]


def welch_psd(t_or_fs, acc, segment_s: float, lo: float, hi: float) -> tuple[np.ndarray, np.ndarray]:
    """Welch PSD of each section averaged over the valid runs, shape (n_freq, n_sections).

    Each run is weighted by its number of Welch sections. Raises ValueError if
    the longest run cannot resolve ``lo`` (three cycles per section) or ``hi``
    is not below the Nyquist frequency.
    """
    check_positive("segment_s", segment_s)
    acc = as_2d(np.asarray(acc, dtype=float))
    if np.ndim(t_or_fs) == 0:
        fs = float(t_or_fs)
        check_positive("sampling rate", fs)
        _, starts, ends = valid_runs(fs, acc, 0.0)
    else:
        t = check_time(t_or_fs, "t")
        if t.shape[0] != acc.shape[0]:
            raise ValueError(f"t has {t.shape[0]} samples but acc has {acc.shape[0]}")
        fs = 1.0 / float(np.median(np.diff(t)))
        _, starts, ends = valid_runs(t, acc, 0.0)
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
    check_positive("fs", fs)
    check_positive("f_mode", f_mode)
    check_positive("half_width", half_width)
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
    """Amplitude envelope ``|y + i H[y]|`` by the Hilbert transform.

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

