"""The sensor-noise floor of the amplitude envelope, and whether a window is above it.

Below the accelerometers' noise floor the Hilbert envelope A is the envelope
of noise, not of the deck's vibration: it follows a Rayleigh law whatever the
structure does, and its "dynamics" are those of filtered noise. Windowed
regressions fit such envelopes as readily as real ones (dense models that
pass every model-selection test), so the regime of a window whose amplitude is
not clearly above the floor is not identifiable, whatever the regression says.

Estimate. Accelerometer noise is broadband; inside the vibration band it is
hidden under the mode, but just outside it the spectrum is the noise (the
lightly damped mode's response falls off fast away from resonance). The noise
level per section is the mean of the Welch spectrum over a flank on each side
of the band (as wide as the half-width), the smaller of the two sides (a
neighbouring mode inflates one flank, not both), assumed flat across the band.
The mean, not the median: with the few Welch sections of a short record each
bin is a chi-square variable with few degrees of freedom, whose median lies
well below its mean (0.69 of it for two). Band-pass integration to displacement then gives the noise's standard
deviation in the band,

    sigma^2 = S_n * integral over the band of G(f)^2 / (2 pi f)^4 df,

with G the band's gain (vivbench.preprocess.chain.displacement). An
envelope of noise alone has mean sigma sqrt(pi/2) ~ 1.25 sigma; with a
vibration of amplitude a it fluctuates by about sigma around a. The estimate
is an upper bound where the structure's own broadband response reaches the
flanks, so the test errs towards "not identifiable".

The ratio reported per window and section is ``mean(A) / sigma`` over the
window (``amplitude_snr`` in the result files).
"""

from __future__ import annotations

import numpy as np

from vivbench.preprocess.band import band_gain

__all__ = ["band_noise_std", "window_amplitude_snr"]

# Points of the numerical integration of the band's transfer function.
_N_QUAD = 2001


def band_noise_std(f: np.ndarray, psd: np.ndarray, f_mode: float, half_width: float, *, taper: float = 0.5,
                   flank: float = 1.0) -> np.ndarray:
    """Standard deviation of accelerometer noise after band-pass integration to displacement.

    Parameters
    ----------
    f : ndarray, shape (n_freq,), Hz
        Frequencies of a one-sided power spectral density.
    psd : ndarray, shape (n_freq, n_sections), (m/s^2)^2/Hz
        One-sided PSD of each section's acceleration (e.g. Welch).
    f_mode : float
        Centre of the vibration band, Hz.
    half_width : float
        Half-width of the band, Hz (the gain reaches 0 at f_mode +- half_width).
    taper : float
        Fraction of the half-width over which the gain falls from 1 to 0
        (as in the displacement integration).
    flank : float
        Width of each flank outside the band, in half-widths.

    Returns
    -------
    sigma : ndarray, shape (n_sections,), m
        NaN for a section where neither flank has a spectral bin inside
        (0, f[-1]].
    """
    f = np.asarray(f, dtype=float)
    psd = np.asarray(psd, dtype=float)
    if psd.ndim == 1:
        psd = psd[:, None]
    lo, hi = f_mode - half_width, f_mode + half_width
    flanks = ((f > max(lo - flank * half_width, 0.0)) & (f < lo), (f > hi) & (f <= hi + flank * half_width))
    levels = [np.mean(psd[m], axis=0) if m.sum() >= 3 else np.full(psd.shape[1], np.nan) for m in flanks]
    level = np.fmin(levels[0], levels[1])
    fq = np.linspace(max(lo, 1e-9), hi, _N_QUAD)
    g = band_gain(fq, f_mode, half_width, taper) ** 2 / (2.0 * np.pi * fq) ** 4
    weight = float(np.sum(0.5 * (g[1:] + g[:-1]) * np.diff(fq)))
    return np.sqrt(level * weight)


def window_amplitude_snr(t: np.ndarray, A: np.ndarray, window_start: np.ndarray, window_end: np.ndarray,
                         sigma: np.ndarray) -> np.ndarray:
    """Mean amplitude over each window in units of the noise floor.

    Parameters
    ----------
    t : ndarray, shape (n,), s
        Grid of A.
    A : ndarray, shape (n, n_sections), m
        Envelope; NaN samples are ignored.
    window_start, window_end : ndarray, shape (W,), s
        Windows [start, end).
    sigma : ndarray, shape (n_sections,), m
        Noise floor per section (:func:`band_noise_std`).

    Returns
    -------
    snr : ndarray, shape (W, n_sections)
        ``mean(A) / sigma``; NaN where the window has no valid sample or the
        floor is unknown, +inf where the floor is exactly 0 (noise-free data).
    """
    t = np.asarray(t, dtype=float)
    A = np.asarray(A, dtype=float)
    ok = np.isfinite(A)
    # Window sums from cumulative sums: two searches per window, no loop over samples.
    csum = np.vstack([np.zeros((1, A.shape[1])), np.cumsum(np.where(ok, A, 0.0), axis=0)])
    ccnt = np.vstack([np.zeros((1, A.shape[1])), np.cumsum(ok, axis=0)])
    i0 = np.searchsorted(t, window_start, side="left")
    i1 = np.searchsorted(t, window_end, side="left")
    count = ccnt[i1] - ccnt[i0]
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(count > 0, (csum[i1] - csum[i0]) / count, np.nan)
        return mean / np.asarray(sigma, dtype=float)[None, :]
