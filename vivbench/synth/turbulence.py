"""Stochastic wind turbulence along the span (docs/concepts.md (the bridge and the wind)).

Zero-mean fluctuations u' (along the mean wind), v' (lateral, horizontal) and
w' (vertical) at points on a straight horizontal line (the deck), simulated by
the spectral representation method of Shinozuka and Deodatis with

- one-sided Kaimal spectra (IEC 61400-1 convention: integral lengths
  L_u = 8.1 Lambda, L_v = 2.7 Lambda, L_w = 0.66 Lambda),
- Davenport coherence exp(-C f dx / U) between points of one component,
- independent components.

Two facts make the method cheap and robust here.

1. The Davenport coherence of points on a line is an exponential kernel in the
   separation, the correlation of a Markov (Ornstein-Uhlenbeck) process. For
   points sorted along the span its Cholesky factor is known in closed form:
   with rho_m = coh(f, x_m - x_{m-1}),

       H_jm(f) = coh(f, x_j - x_m) * d_m(f)   (j >= m),   d_0 = 1,
       d_m = sqrt(1 - rho_m^2),

   so the factor for every frequency costs a few vectorised exponentials, no
   LAPACK call, and it stays exact as f -> 0 where the coherence matrix
   becomes singular and a numerical Cholesky fails.
2. Deodatis' double-indexed frequencies (1996) f_mq = (l + (m+1)/n) n/T for
   source m = 0..n-1 are exactly the bins q = l n + m + 1 of the record's own
   FFT grid (spacing 1/T). So each bin of one inverse real FFT belongs to one
   source m(q) = (q - 1) mod n, and the whole field is one ``irfft`` per point
   and component: O(N log N). Because every bin carries a single random phase,
   the record's variance and cross-covariances (at every lag, circularly) are
   the same for every seed: each simulated record is ergodic in its
   correlation structure. The price is that one source is resolved only every
   n/T Hz; with few points (three deck sections) and records of many minutes
   this is far finer than the spectra vary. It is not, however, finer than
   the Davenport coherence varies for points far apart: the coherence of two
   points dx apart falls by 1/e over U / (C dx) Hz (0.001 Hz for u at 8 m/s
   over 800 m), so with many points spread over a long span (the tributary
   field of ``WindConfig.felt_wind = "tributary"``, 18 points over 1650 m)
   the zero-lag correlations of u come out 0.1-0.4 too high. Use
   ``double_indexing=False`` there (and for many points on a short record):
   independent phases per point and bin, the classical single-indexed scheme,
   whose ensemble coherence is exact at every bin of spacing 1/T; each record's
   sample statistics then scatter as a natural record's do.
3. The same Markov structure makes the single-indexed sum over sources a
   recursion along the sorted points, per bin
   Z_j = rho_j Z_{j-1} + d_j xi_j (xi_j the unit random phasor of point j),
   so it costs O(n N) time and memory (n vectorised steps over all bins), not
   the O(n^2 N) of the full factor.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from vivbench.core.errors import InputError
from vivbench.core.wind_spectra import davenport_coherence, kaimal_psd

__all__ = [
    "KAIMAL_LENGTH_FACTORS",
    "TurbulenceConfig",
    "kaimal_psd",
    "davenport_coherence",
    "target_sigmas",
    "simulate_turbulence",
]

# IEC 61400-1 Kaimal integral lengths L_k = factor_k * Lambda for u, v, w.
KAIMAL_LENGTH_FACTORS = (8.1, 2.7, 0.66)


def _check(cond: bool, msg: str) -> None:
    if not cond:
        raise InputError(msg)


def _finite_number(value, name: str) -> float:
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a real number; got {value!r}") from None
    _check(math.isfinite(out), f"{name} must be finite; got {value!r}")
    return out


@dataclass(frozen=True, kw_only=True)
class TurbulenceConfig:
    """Statistics of the turbulence field.

    Parameters
    ----------
    intensity : float
        Longitudinal turbulence intensity sigma_u / U, 0 <= I < 0.5
        (about 0.05-0.10 over sea).
    ratio_v, ratio_w : float
        sigma_v / sigma_u and sigma_w / sigma_u, each in [0, 2].
    length_scale : float
        Turbulence scale parameter Lambda, m (> 0); integral lengths
        ``KAIMAL_LENGTH_FACTORS`` times Lambda.
    coherence_decay : tuple of 3 floats
        Davenport decay constants (C_u, C_v, C_w), each >= 0 (0 means fully
        coherent along the span).
    double_indexing : bool
        Deodatis' double-indexed frequencies (ergodic records, see module
        docstring); False gives the single-indexed scheme. The tributary field of
        ``WindConfig.felt_wind = "tributary"`` is always single-indexed: double
        indexing misses the Davenport coherence of its many far-apart points.
    rescale_to_sigma : bool
        Scale each point so that the variance of the simulated (discrete)
        spectrum equals sigma^2 exactly. The Kaimal spectrum integrates to
        sigma^2 over (0, inf); the part below 1/T and above fs/2 (a few per
        cent of the u variance at T = 1 h) is otherwise missing. False keeps
        the Kaimal ordinates unscaled.
    """

    intensity: float = 0.08
    ratio_v: float = 0.8
    ratio_w: float = 0.5
    length_scale: float = 42.0
    coherence_decay: tuple[float, float, float] = (10.0, 7.0, 4.0)
    double_indexing: bool = True
    rescale_to_sigma: bool = True

    def __post_init__(self) -> None:
        intensity = _finite_number(self.intensity, "intensity")
        _check(0.0 <= intensity < 0.5, f"intensity (sigma_u / U) must be in [0, 0.5); got {intensity}")
        for name in ("ratio_v", "ratio_w"):
            value = _finite_number(getattr(self, name), name)
            _check(0.0 <= value <= 2.0, f"{name} must be in [0, 2]; got {value}")
            object.__setattr__(self, name, value)
        length = _finite_number(self.length_scale, "length_scale")
        _check(length > 0.0, f"length_scale (Lambda, m) must be positive; got {length}")
        try:
            decay = tuple(_finite_number(c, "coherence_decay entry") for c in self.coherence_decay)
        except TypeError:
            raise InputError(f"coherence_decay must be three numbers (C_u, C_v, C_w); got {self.coherence_decay!r}") from None
        _check(len(decay) == 3, f"coherence_decay must be three numbers (C_u, C_v, C_w); got {self.coherence_decay!r}")
        _check(all(c >= 0.0 for c in decay), f"coherence_decay entries must be >= 0; got {decay}")
        for name in ("double_indexing", "rescale_to_sigma"):
            _check(isinstance(getattr(self, name), (bool, np.bool_)), f"{name} must be True or False; got {getattr(self, name)!r}")
            object.__setattr__(self, name, bool(getattr(self, name)))
        object.__setattr__(self, "intensity", intensity)
        object.__setattr__(self, "length_scale", length)
        object.__setattr__(self, "coherence_decay", decay)

    @property
    def integral_lengths(self) -> np.ndarray:
        """Kaimal integral lengths (L_u, L_v, L_w), m, shape (3,)."""
        return self.length_scale * np.asarray(KAIMAL_LENGTH_FACTORS)


def target_sigmas(mean_speed: float, config: TurbulenceConfig) -> np.ndarray:
    """Standard deviations (sigma_u, sigma_v, sigma_w), m/s, shape (3,).

    Parameters
    ----------
    mean_speed : float
        Mean wind speed U, m/s (> 0).
    config : TurbulenceConfig
    """
    U = _finite_number(mean_speed, "mean_speed")
    _check(U > 0.0, f"mean_speed must be positive (m/s); got {U}")
    sigma_u = config.intensity * U
    return sigma_u * np.array([1.0, config.ratio_v, config.ratio_w])


def _owner_factor(a: np.ndarray, xs: np.ndarray, owner: np.ndarray) -> np.ndarray:
    """Column ``owner[q]`` of the coherence Cholesky factor at each bin q.

    Parameters
    ----------
    a : ndarray, shape (nq,), 1/m
        Davenport exponent per metre, C f_q / U.
    xs : ndarray, shape (n,), m
        Sorted positions.
    owner : ndarray of int, shape (nq,)
        Source (column) index per bin.

    Returns
    -------
    ndarray, shape (n, nq): H[j, owner[q]] at f_q
    """
    n = xs.size
    gap = np.concatenate(([0.0], np.diff(xs)))  # gap[m] = x_m - x_{m-1}
    # d_m = sqrt(1 - rho_m^2); -expm1 keeps precision where rho_m -> 1 (low f).
    d = np.where(owner == 0, 1.0, np.sqrt(-np.expm1(-2.0 * a * gap[owner])))
    dx = xs[:, None] - xs[owner][None, :]
    below = np.arange(n)[:, None] >= owner[None, :]
    # Clip so that the (discarded) upper triangle cannot overflow exp.
    return np.where(below, np.exp(-a * np.maximum(dx, 0.0)) * d, 0.0)


def _markov_sum(a: np.ndarray, xs: np.ndarray, rotor: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Single-indexed combination of the sources, sum_m H[j, m] rotor[m], by the Markov recursion.

    Parameters
    ----------
    a : ndarray, shape (nq,), 1/m; Davenport exponent per metre, C f_q / U
    xs : ndarray, shape (n,), m; sorted positions
    rotor : ndarray, shape (n, nq), complex; unit random phasor per source and bin

    Returns
    -------
    z : ndarray, shape (n, nq), complex; sum_m H[j, m] rotor[m] at each bin
    h2 : ndarray, shape (n, nq); sum_m H[j, m]^2 (1 up to rounding)
    """
    z = np.empty(rotor.shape, dtype=complex)
    h2 = np.empty(rotor.shape)
    z[0], h2[0] = rotor[0], 1.0
    for j, gap in enumerate(np.diff(xs), start=1):  # one vectorised step per point, over all bins
        rho = np.exp(-a * gap)
        d2 = -np.expm1(-2.0 * a * gap)  # 1 - rho^2, precise where rho -> 1
        z[j] = rho * z[j - 1] + np.sqrt(d2) * rotor[j]
        h2[j] = rho**2 * h2[j - 1] + d2
    return z, h2


def _full_factor(a: np.ndarray, xs: np.ndarray) -> np.ndarray:
    """Whole coherence Cholesky factor at each bin, shape (n, n, nq)."""
    n = xs.size
    return np.stack([_owner_factor(a, xs, np.full(a.shape, m)) for m in range(n)], axis=1)


def simulate_turbulence(positions, mean_speed: float, duration: float, fs: float, config: TurbulenceConfig, rng: np.random.Generator) -> np.ndarray:
    """Simulate turbulence fluctuations at points along the span.

    Parameters
    ----------
    positions : array_like, shape (n_points,)
        Spanwise coordinates of the points, m (any order; equal positions give
        identical records).
    mean_speed : float
        Stationary mean wind speed U, m/s (> 0); sets the spectra and the
        coherence.
    duration : float
        Record length, s (> 0).
    fs : float
        Sampling rate, Hz (> 0).
    config : TurbulenceConfig
    rng : numpy.random.Generator
        Source of the random phases. The same state gives identical output
        bytes; the draws do not depend on the intensity, so the output is
        exactly proportional to the intensity for a given state (zero
        intensity still advances ``rng`` and returns zeros).

    Returns
    -------
    ndarray, shape (n_samples, n_points, 3), m/s
        u', v', w' at each point, with n_samples = round(duration * fs);
        sample i is at time i / fs. Every record has zero mean.

    Notes
    -----
    The record is periodic with period n_samples / fs (an inverse FFT), and
    with double indexing its variance and cross-covariances are exact for
    every seed (see the module docstring).
    """
    if not isinstance(config, TurbulenceConfig):
        raise TypeError(f"config must be a TurbulenceConfig; got {type(config).__name__}")
    if not isinstance(rng, np.random.Generator):
        raise TypeError(f"rng must be a numpy.random.Generator (numpy.random.default_rng(seed)); got {type(rng).__name__}")
    xs = np.asarray(positions, dtype=float)
    _check(xs.ndim == 1 and xs.size >= 1, f"positions must be a 1-D array of at least one spanwise coordinate (m); got shape {xs.shape}")
    _check(bool(np.all(np.isfinite(xs))), "positions must be finite")
    U = _finite_number(mean_speed, "mean_speed")
    _check(U > 0.0, f"mean_speed must be positive (m/s); got {U}")
    duration = _finite_number(duration, "duration")
    fs = _finite_number(fs, "fs")
    _check(duration > 0.0, f"duration must be positive (s); got {duration}")
    _check(fs > 0.0, f"fs must be positive (Hz); got {fs}")
    n_samples = int(round(duration * fs))
    _check(n_samples >= 4, f"duration * fs must round to at least 4 samples; got {n_samples}")

    n = xs.size
    order = np.argsort(xs, kind="stable")
    xs = xs[order]
    # Bins 1..nyq: the mean (bin 0) is zero, and an even record's Nyquist bin
    # is dropped because its phase cannot be random in a real signal.
    n_bins = (n_samples - 1) // 2
    q = np.arange(1, n_bins + 1)
    f = q * (fs / n_samples)
    df = fs / n_samples
    n_sources = 1 if config.double_indexing else n
    if config.double_indexing:
        _check(n_bins >= n, f"with double indexing every point needs a frequency bin of its own: {n} points need at least "
               f"{2 * n + 1} samples; got {n_samples} (use a longer record or double_indexing=False)")
    # Draw everything first so the stream does not depend on the intensity.
    phases = rng.uniform(0.0, 2.0 * np.pi, size=(3, n_sources, n_bins))

    out = np.zeros((n_samples, n, 3))
    sigmas = target_sigmas(U, config)
    if config.intensity == 0.0:
        return out
    spectrum = np.zeros((n, n_bins + 1), dtype=complex)
    owner = (q - 1) % n
    for c in range(3):
        s_unit = kaimal_psd(f, U, 1.0, config.integral_lengths[c])
        a = config.coherence_decay[c] * f / U
        rotor = np.exp(1j * phases[c])
        if config.double_indexing:
            # Each bin belongs to one source, which is n bins apart from its
            # neighbours: its spectral weight is n df.
            h = _owner_factor(a, xs, owner)
            weight = n * df * s_unit
            spectrum[:, 1:] = np.sqrt(weight / 2.0) * h * rotor[0]
            variance = np.sum(weight * h**2, axis=1)
        else:
            z, h2 = _markov_sum(a, xs, rotor)
            weight = df * s_unit
            spectrum[:, 1:] = np.sqrt(weight / 2.0) * z
            variance = np.sum(weight * h2, axis=1)
        # Ensemble variance of the discrete spectrum; with double indexing it
        # is also the variance of every record.
        scale = sigmas[c] / np.sqrt(variance) if config.rescale_to_sigma else np.full(n, sigmas[c])
        # norm="forward": a bin X gives the cosine 2|X| cos(2 pi f t + arg X).
        records = np.fft.irfft(spectrum, n=n_samples, axis=1, norm="forward")
        out[:, order, c] = (records * scale[:, None]).T
    return out
