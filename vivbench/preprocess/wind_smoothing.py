"""A slower mean wind for campaign models: Gaussian smoothing of a record's U (and yaw) in time.

An errors-in-variables correction: a point anemometer's slow turbulence
between about 1/300 and 1/60 Hz is barely coherent over a section's tributary
length, so the deck does not feel it, while the scripted mean wind the deck
does feel varies over 10-60 min. Lowering the mean wind's cut-off brings the
measured U closer to the felt one.
"""

from __future__ import annotations

import dataclasses
import weakref

import numpy as np
from scipy.ndimage import gaussian_filter1d

from vivbench.core.errors import InputError
from vivbench.core.record import Record

__all__ = ["smooth_wind"]

#: Smoothed records by input record and time scale, while the input record lives: a campaign model's
#: selection fits and simulates the same records many times (every candidate, fold and held-out run),
#: and records are never changed in place.
_SMOOTHED: "weakref.WeakKeyDictionary[Record, dict[float, Record]]" = weakref.WeakKeyDictionary()


def smooth_wind(record: Record, sigma_s: float) -> Record:
    """``record`` with U (and its yaw, if any) smoothed by a Gaussian of standard deviation ``sigma_s``.

    Parameters
    ----------
    record : Record, on a uniform time grid (gaps as NaN)
    sigma_s : float, s (0: the record unchanged)

    Returns
    -------
    Record
        The same data but U and ``yaw``; NaN samples stay NaN, their
        neighbours are averaged over the valid samples only (normalised
        convolution).
    """
    if sigma_s is None or not np.isfinite(sigma_s) or sigma_s < 0:
        raise InputError(f"the wind smoothing must be a number of seconds >= 0; got {sigma_s!r}")
    if sigma_s == 0 or record.n_samples < 2:
        return record
    done = _SMOOTHED.get(record, {}).get(float(sigma_s))
    if done is not None:
        return done
    width = sigma_s / float(np.median(np.diff(record.t)))

    weights = {}  # the smoothed valid-sample mask, by the mask's bytes: U and yaw usually share theirs

    def smooth(x):
        ok = np.isfinite(x)
        num = gaussian_filter1d(np.where(ok, x, 0.0), width, axis=0, mode="nearest", truncate=3.0)
        key = (ok.shape, ok.tobytes())
        if key not in weights:
            weights[key] = gaussian_filter1d(ok.astype(float), width, axis=0, mode="nearest", truncate=3.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(ok, num / np.maximum(weights[key], 1e-12), np.nan)

    out = dataclasses.replace(record, U=smooth(record.U), yaw=None if record.yaw is None else smooth(record.yaw))
    _SMOOTHED.setdefault(record, {})[float(sigma_s)] = out
    return out
