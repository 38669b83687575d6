"""Recovery of the truth by the pooled campaign model (``vivbench.models.campaign``)."""

from __future__ import annotations

import numpy as np
import xarray as xr

from vivbench.validate.recovery import regime_scores, window_rhs_errors
from vivbench.regimes.truth import truth_window_regimes
from vivbench.io.netcdf import NETCDF_ENGINE
from vivbench.core.errors import InputError

__all__ = ["pooled_recovery"]


def pooled_recovery(event_files, pooled_file, result_files, *, active_share: float = 0.1, tau: float = 0.2) -> dict:
    """Regime scores and right-hand-side errors of the pooled model against the truth.

    Parameters
    ----------
    event_files : synthetic event files (with ``/truth``)
    pooled_file : ``campaign.pooled.nc``
    result_files : the ``<event_id>.identify.nc`` the pooled model was fitted on
        (their A and U are where the right-hand sides are compared)
    active_share : as in :func:`vivbench.validate.campaign_recovery`

    Returns
    -------
    dict
        :func:`vivbench.validate.regime_scores` of the pooled regimes plus
        ``rhs_median_rel_error`` and ``rhs_median_rel_error_active`` (the one
        pooled model evaluated over every window).
    """
    from vivbench.analysis.pool import with_campaign_model
    from vivbench.io.event import read_event
    from vivbench.io.result import read_result

    with xr.open_dataset(pooled_file, engine=NETCDF_ENGINE) as ds:
        pooled = ds.load()
    truths = {}
    for path in event_files:
        tree = read_event(path)
        truths[str(tree.attrs["event_id"])] = tree["truth"].ds
    results = {}
    for path in result_files:
        ds = read_result(path)
        results[str(ds.attrs["event_id"])] = ds
    event_of = pooled["event_id"].values.astype(str)
    regimes, truths_w, flags, errs, errs_active = [], [], [], [], []
    for event_id in dict.fromkeys(event_of):
        if event_id not in truths:
            raise InputError(f"{pooled_file}: event {event_id} has no event file among the {len(truths)} given")
        if event_id not in results:
            raise InputError(f"{pooled_file}: event {event_id} has no identification result among those given")
        sel = event_of == event_id
        truth = truths[event_id]
        res = results[event_id]
        if not np.array_equal(pooled["window_start"].values[sel], res["window_start"].values):
            raise InputError(f"{pooled_file}: its windows of {event_id} differ from the result's; re-run vivbench pool")
        regimes.append(pooled["regime"].values[sel])
        flags.append(pooled["identifiable"].values[sel].astype(bool))
        truths_w.append(truth_window_regimes(truth, res["window_start"].values, res["window_end"].values, tau=tau))
        e, act = window_rhs_errors(with_campaign_model(res, pooled), truth["coef"].values, truth["r"].values,
                                   active_share=active_share)
        errs.append(e.ravel())
        errs_active.append(np.where(act, e, np.nan).ravel())
    scores = regime_scores(np.concatenate(regimes), np.concatenate(truths_w), np.concatenate(flags))
    scores["rhs_median_rel_error"] = float(np.nanmedian(np.concatenate(errs)))
    scores["rhs_median_rel_error_active"] = float(np.nanmedian(np.concatenate(errs_active)))
    return scores
