"""The mean wind's yaw of each identification result, from its event's anemometers.

The identification result files hold U (the perpendicular mean wind), not the
wind's angle to the span; the varying-coefficient model can use that angle as a
second covariate (the realistic aerodynamics fall off with it). It is measured
here from the event file's u, v (low-passed like U, :func:`vivbench.preprocess.mean_yaw`)
and put on the result's time grid.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vivbench.core.errors import InputError
from vivbench.core.record import Record
from vivbench.io.event import EventFormatError, read_event
from vivbench.models.yaw_record import YawRecord
from vivbench.preprocess.yaw import mean_yaw

__all__ = ["event_yaw", "with_yaw"]


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
