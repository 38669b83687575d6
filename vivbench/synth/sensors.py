"""Accelerometer model and sensor defects (docs/concepts.md (the bridge and the wind))."""

from __future__ import annotations

import numpy as np

from vivbench.synth.config import DefectConfig, SensorConfig

__all__ = ["G", "accelerometer", "add_dropouts", "add_spikes", "sample_times"]

G = 9.80665  # m/s^2 per g


def accelerometer(acc: np.ndarray, sensors: SensorConfig, rng: np.random.Generator) -> np.ndarray:
    """Measured acceleration: white noise floor, clipping and quantisation.

    Parameters
    ----------
    acc : ndarray, shape (n, S), m/s^2
        True vertical acceleration at the sections.

    Returns
    -------
    ndarray, shape (n, S), float32, m/s^2
    """
    sigma = sensors.noise_density * 1e-6 * G * np.sqrt(sensors.rate / 2.0)
    out = acc + sigma * rng.standard_normal(acc.shape)
    full = sensors.full_scale * G
    if sensors.bits:
        lsb = 2.0 * full / 2**sensors.bits
        out = np.clip(np.round(out / lsb), -(2 ** (sensors.bits - 1)), 2 ** (sensors.bits - 1) - 1) * lsb
    else:
        out = np.clip(out, -full, full)
    return out.astype(np.float32)


def sample_times(duration: float, rate: float) -> np.ndarray:
    """Nominal sample times 0, 1/rate, ... below ``duration`` (s), float64."""
    return np.arange(int(np.floor(duration * rate + 1e-9))) / rate


def add_dropouts(x: np.ndarray, rate: float, defects: DefectConfig, rng: np.random.Generator) -> tuple[np.ndarray, list[tuple[float, float]]]:
    """NaN blocks across all channels of one logger (a logger drops out as a whole).

    Returns the record with gaps and the list of (start, end) times in s.
    """
    n = x.shape[0]
    hours = n / rate / 3600.0
    count = rng.poisson(defects.dropouts_per_hour * hours) if defects.dropouts_per_hour else 0
    x = x.copy()
    blocks = []
    for _ in range(count):  # a handful of blocks per record, not a per-sample loop
        length = rng.uniform(*defects.dropout_duration)
        start = rng.uniform(0.0, max(n / rate - length, 0.0))
        i0, i1 = int(start * rate), min(int((start + length) * rate) + 1, n)
        x[i0:i1] = np.nan
        blocks.append((i0 / rate, i1 / rate))
    return x, blocks


def add_spikes(x: np.ndarray, rate: float, defects: DefectConfig, rng: np.random.Generator) -> tuple[np.ndarray, int]:
    """Single-sample spikes of ``spike_amplitude`` times the channel rms, random sign.

    Returns the record and the number of spikes added.
    """
    if not defects.spikes_per_hour:
        return x, 0
    n, k = x.shape
    count = rng.poisson(defects.spikes_per_hour * n / rate / 3600.0 * k)
    rows = rng.integers(0, n, size=count)
    cols = rng.integers(0, k, size=count)
    rms = np.sqrt(np.nanmean(np.asarray(x, dtype=float) ** 2, axis=0))
    x = x.copy()
    x[rows, cols] = (x[rows, cols] + rng.choice([-1.0, 1.0], size=count) * defects.spike_amplitude * rms[cols]).astype(x.dtype)
    return x, int(count)
