"""The mean wind's yaw of results written before identification stored it, measured from their event files.

Since the ``yaw`` variable of the result format, :func:`vivbench.analysis.identify_event`
writes the yaw and :func:`vivbench.analysis.records_from_results` reads it; older
results get it here from the event file's u, v (low-passed like U,
:func:`vivbench.preprocess.mean_yaw`), put on the result's time grid.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from vivbench.core.errors import InputError
from vivbench.core.record import Record
from vivbench.io.event import EventFormatError, read_event
from vivbench.preprocess.yaw import event_yaw

__all__ = ["with_yaw"]


def with_yaw(record: Record, event_file) -> Record:
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
    return dataclasses.replace(record, yaw=yaw)
