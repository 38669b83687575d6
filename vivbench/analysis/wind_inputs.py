"""The campaign model's wind inputs: the mean wind's yaw from the anemometers, and a slower mean wind.

The identification result files hold U (the perpendicular mean wind), not the
wind's angle to the span; the varying-coefficient model can use that angle as a
second covariate (the realistic aerodynamics fall off with it). It is measured
here from the event file's u, v (low-passed like U, :func:`vivbench.preprocess.mean_yaw`)
and put on the result's time grid.

:func:`smooth_wind` lowers the mean wind's cut-off for the campaign model (an
errors-in-variables correction): a point anemometer's slow turbulence between
about 1/300 and 1/60 Hz is barely coherent over a section's tributary length,
so the deck does not feel it, while the scripted mean wind the deck does feel
varies over 10-60 min.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scipy.ndimage import gaussian_filter1d

from vivbench.core.errors import InputError
from vivbench.core.record import Record
from vivbench.io.event import EventFormatError, read_event
from vivbench.models.yaw_record import YawRecord
from vivbench.preprocess.yaw import mean_yaw

__all__ = ["event_yaw", "smooth_wind", "with_yaw"]


def event_yaw(t_wind, u, v, span_azimuth_deg: float, t_out) -> np.ndarray:
    """The low-passed mean wind's yaw at times ``t_out``.

    Parameters
    ----------
    t_wind : ndarray, shape (n,), s; u, v : ndarray, shape (n, S), m/s (east, north)
    span_azimuth_deg : float, degrees from north
    t_out : ndarray, shape (m,), s

    Returns
    -------
    ndarray, shape (m, S), degrees (NaN outside the wind record or in its gaps)
    """
    yaw = mean_yaw(t_wind, u, v, span_azimuth_deg)
    t_out = np.asarray(t_out, dtype=float)
    return np.stack([np.interp(t_out, t_wind, yaw[:, k], left=np.nan, right=np.nan)
                     for k in range(yaw.shape[1])], axis=1)


def with_yaw(record: Record, event_file) -> YawRecord:
    """``record`` with the yaw measured from ``event_file``'s anemometers (section by section).

    Raises
    ------
    InputError
        One line naming the event file when it cannot be read or its sections differ.
    """
    path = Path(event_file)
    try:
        tree = read_event(path)
    except EventFormatError as exc:
        raise InputError(f"{path}: the event of {record.event_id} cannot be read for its wind's yaw ({exc})") from None
    wind = tree["wind"].to_dataset()
    u, v = wind["u"].values, wind["v"].values
    if u.shape[1] != record.n_sections:
        raise InputError(f"{path}: {u.shape[1]} anemometer sections, the result of {record.event_id} has {record.n_sections}")
    yaw = event_yaw(wind["time"].values, u, v, float(tree.attrs["span_azimuth_deg"]), record.t)
    return YawRecord.from_record(record, yaw)


def smooth_wind(record: Record, sigma_s: float) -> Record:
    """``record`` with U (and its yaw, if any) smoothed by a Gaussian of standard deviation ``sigma_s``.

    Parameters
    ----------
    record : Record (or YawRecord), on a uniform time grid (gaps as NaN)
    sigma_s : float, s (0: the record unchanged)

    Returns
    -------
    Record of the same class; NaN samples stay NaN, their neighbours are
    averaged over the valid samples only (normalised convolution).
    """
    if sigma_s < 0 or not np.isfinite(sigma_s):
        raise InputError(f"the wind smoothing must be a number of seconds >= 0; got {sigma_s!r}")
    if sigma_s == 0 or record.n_samples < 2:
        return record
    width = sigma_s / float(np.median(np.diff(record.t)))

    def smooth(x):
        ok = np.isfinite(x)
        num = gaussian_filter1d(np.where(ok, x, 0.0), width, axis=0, mode="nearest", truncate=3.0)
        den = gaussian_filter1d(ok.astype(float), width, axis=0, mode="nearest", truncate=3.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(ok, num / np.maximum(den, 1e-12), np.nan)

    yaw = getattr(record, "yaw", None)
    out = Record(event_id=record.event_id, t=record.t, A=record.A, U=smooth(record.U), dA=record.dA, noise_std=record.noise_std)
    return out if yaw is None else YawRecord.from_record(out, smooth(yaw))
