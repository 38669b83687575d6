"""The record a fitted campaign model is evaluated on when the record is measured.

A campaign model may have been fitted on a transformed measured wind: the
varying-coefficient model smooths the anemometers' U and yaw (its
``wind_smoothing_s``, a lower mean-wind cut-off against a point anemometer's
errors-in-variables), and ``vivbench pool --model sindy --wind-smoothing S``
smooths them before fitting a ``PooledSINDy``. Its regimes, verdicts,
predictions and simulations of a measured record (an identification result's)
must then see the wind as it was at fit, while a record of the wind the deck
itself feels (a synthetic truth's ``/truth``) is evaluated as it is. Every
evaluation of a campaign model on measured records goes through
:func:`measured_input`, so no call site decides this on its own.
"""

from __future__ import annotations

import math

from vivbench.core.errors import InputError
from vivbench.core.record import Record
from vivbench.models.protocol import as_record
from vivbench.preprocess.wind_smoothing import smooth_wind

__all__ = ["measured_input"]


def measured_input(model, record: Record, *, wind_smoothing_s: float = 0.0) -> Record:
    """The model's input for a measured record: its wind transformed as at fit.

    Parameters
    ----------
    model : fitted model of the protocol
        A model with a ``measured_wind(record)`` method
        (``VaryingCoefficientSINDy``) transforms the record itself, with its own
        smoothing; ``wind_smoothing_s`` is then ignored. Any other model
        (``PooledSINDy``, window models, plug-ins) gets the record smoothed by
        ``wind_smoothing_s``.
    record : Record
        A measured record (e.g. :func:`vivbench.io.result.result_record`), not
        a truth's: the truth's felt wind is never smoothed.
    wind_smoothing_s : float, s
        The Gaussian smoothing of U and yaw the model's measured records had at
        fit when the model does not know it itself: the ``wind_smoothing_s``
        attribute of ``vivbench pool``'s ``campaign.regimes.nc`` (0: none, the
        record unchanged).

    Returns
    -------
    Record
        Same samples, A and dA; U and yaw as the model saw them at fit.

    Raises
    ------
    InputError
        ``wind_smoothing_s`` not a number >= 0.
    """
    record = as_record(record)
    measured = getattr(model, "measured_wind", None)
    if callable(measured):
        return measured(record)
    try:
        sigma = float(wind_smoothing_s)
    except (TypeError, ValueError):
        sigma = math.nan
    if not (math.isfinite(sigma) and sigma >= 0):
        raise InputError(f"wind_smoothing_s must be a number of seconds >= 0; got {wind_smoothing_s!r}")
    return smooth_wind(record, sigma)
