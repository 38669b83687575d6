"""The estimated error of a campaign's measured mean wind, and winds perturbed by it.

:class:`vivbench.analysis.ModelSelection` refits its choice on winds perturbed by this error: errors in
the wind bias every bootstrap replicate alike, so a regime must also survive them to be flagged.
"""

from __future__ import annotations

import math

import numpy as np

from vivbench.core.record import Record
from vivbench.preprocess.unmeasured_wind import unmeasured_wind_rms
from vivbench.preprocess.wind_smoothing import smooth_wind

__all__ = ["SINGLE_SECTION_SHARE", "perturbed_wind", "wind_error_scale"]

#: Error of a single section's measured mean wind, as a share of its mean (a stated prior: one section has no
#: other to compare with).
SINGLE_SECTION_SHARE = 0.03


def wind_error_scale(record: Record, timescale_s: float,
                     single_section_share: float = SINGLE_SECTION_SHARE) -> np.ndarray:
    """Estimated rms error of each section's measured mean wind at a time scale, shape (S,), m/s.

    With two sections or more: the spread between the sections' winds smoothed at
    ``timescale_s`` (rms over time of each section's deviation from the sections' mean,
    pooled over sections): independent anemometers' point turbulence and offsets. With one
    section there is nothing to compare with, and the error is taken as
    ``single_section_share`` of the event's mean wind (a stated prior). A section whose wind was taken
    from an anemometer elsewhere (``Record.wind_distance`` > 0; one copied to every section has no spread)
    adds in quadrature its error over the distance (:func:`vivbench.preprocess.unmeasured_wind_rms`).
    """
    rec = smooth_wind(record, float(timescale_s))
    U = rec.U
    S = U.shape[1]
    if S == 1:
        m = float(np.nanmean(U)) if np.isfinite(U).any() else 0.0
        return _with_unmeasured(np.array([single_section_share * m]), rec, timescale_s)
    dev = U - np.nanmean(U, axis=1, keepdims=True)
    ok = np.isfinite(dev)
    if not ok.any():
        return _with_unmeasured(np.zeros(S), rec, timescale_s)
    # pooled over sections, with the S/(S-1) correction for the mean taken over the same sections
    s = math.sqrt(float(np.mean(dev[ok] ** 2)) * S / (S - 1))
    return _with_unmeasured(np.full(S, s), rec, timescale_s)


def _with_unmeasured(scale: np.ndarray, rec: Record, timescale_s: float) -> np.ndarray:
    e = unmeasured_wind_rms(rec, float(timescale_s))  # winds taken away from their sections, in quadrature
    return scale if e is None else np.hypot(scale, e)


def perturbed_wind(record: Record, scale: np.ndarray, timescale_s: float, rng: np.random.Generator) -> Record:
    """The record with each section's U perturbed by smooth Gaussian noise of rms ``scale`` (S,), m/s.

    The noise is white noise smoothed by a Gaussian of standard deviation ``timescale_s``
    and rescaled to unit variance; NaN samples stay NaN.
    """
    noise = rng.standard_normal(record.U.shape)
    probe = Record(event_id=record.event_id, t=record.t, A=record.A, U=noise, dA=record.dA)
    smooth = smooth_wind(probe, float(timescale_s)).U
    sd = smooth.std(axis=0)
    smooth = smooth / np.where(sd > 0, sd, 1.0)
    U = record.U + smooth * np.asarray(scale, dtype=float)[None, :]
    return Record(event_id=record.event_id, t=record.t, A=record.A, U=U, dA=record.dA, yaw=record.yaw,
                  noise_std=record.noise_std, wind_distance=record.wind_distance)
