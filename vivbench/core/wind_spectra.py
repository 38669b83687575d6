"""Spectra of atmospheric turbulence shared by the generator and the identification.

The one-sided Kaimal spectrum of a turbulence component and the Davenport
coherence of two points along a line: the generator draws its turbulence fields
from them (:mod:`vivbench.synth.turbulence`), and the error of a wind measured
away from its section is integrated over them
(:mod:`vivbench.preprocess.unmeasured_wind`).
"""

from __future__ import annotations

import numpy as np

from vivbench.core.errors import InputError

__all__ = ["davenport_coherence", "kaimal_psd"]


def _check(cond: bool, msg: str) -> None:
    if not cond:
        raise InputError(msg)


def kaimal_psd(f, U, sigma, L) -> np.ndarray:
    """One-sided Kaimal spectrum S(f) = sigma^2 (4 L / U) / (1 + 6 f L / U)^(5/3).

    It integrates to sigma^2 over f in (0, inf). Arguments broadcast.

    Parameters
    ----------
    f : array_like
        Frequency, Hz (>= 0).
    U : array_like
        Mean wind speed, m/s (> 0).
    sigma : array_like
        Standard deviation of the component, m/s (>= 0).
    L : array_like
        Integral length of the component, m (> 0).

    Returns
    -------
    ndarray, broadcast shape of the arguments, (m/s)^2/Hz
    """
    f, U, sigma, L = (np.asarray(a, dtype=float) for a in (f, U, sigma, L))
    _check(bool(np.all(f >= 0)), "frequencies f must be >= 0 (one-sided spectrum)")
    _check(bool(np.all(U > 0)), "mean speed U must be positive (m/s)")
    _check(bool(np.all(sigma >= 0)), "sigma must be >= 0 (m/s)")
    _check(bool(np.all(L > 0)), "integral length L must be positive (m)")
    tau = L / U
    return sigma**2 * 4.0 * tau / (1.0 + 6.0 * f * tau) ** (5.0 / 3.0)


def davenport_coherence(f, separation, U, decay) -> np.ndarray:
    """Davenport root-coherence (real coherency) exp(-decay f ``|separation|`` / U).

    Arguments broadcast.

    Parameters
    ----------
    f : array_like
        Frequency, Hz (>= 0).
    separation : array_like
        Distance between the two points, m (sign ignored).
    U : array_like
        Mean wind speed, m/s (> 0).
    decay : array_like
        Decay constant C (>= 0), dimensionless.

    Returns
    -------
    ndarray, broadcast shape of the arguments, in (0, 1]
    """
    f, separation, U, decay = (np.asarray(a, dtype=float) for a in (f, separation, U, decay))
    _check(bool(np.all(f >= 0)), "frequencies f must be >= 0")
    _check(bool(np.all(U > 0)), "mean speed U must be positive (m/s)")
    _check(bool(np.all(decay >= 0)), "decay constant must be >= 0")
    return np.exp(-decay * f * np.abs(separation) / U)
