"""Recovery of the truth by the pooled campaign model (``vivbench.identify.pooled``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import xarray as xr

from vivbench.terms import evaluate_library
from vivbench.validate.recovery import regime_scores, rhs_relative_error, truth_window_regimes

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
    from vivbench.io import read_event

    with xr.open_dataset(pooled_file, engine="h5netcdf") as ds:
        pooled = ds.load()
    events = {read_event(p).attrs["event_id"]: p for p in map(Path, event_files)}
    results = {}
    for p in result_files:
        with xr.open_dataset(p, engine="h5netcdf") as ds:
            results[str(ds.attrs["event_id"])] = ds[["A", "U"]].load()
    coef = pooled["coef"].values
    event_of = pooled["event_id"].values.astype(str)
    regimes, truths, flags, errs, errs_active = [], [], [], [], []
    for event_id in dict.fromkeys(event_of):
        if event_id not in events:
            raise ValueError(f"{pooled_file}: event {event_id} has no event file among the {len(events)} given")
        if event_id not in results:
            raise ValueError(f"{pooled_file}: event {event_id} has no identification result among those given")
        sel = event_of == event_id
        truth = read_event(events[event_id])["truth"].ds
        start, end = pooled["window_start"].values[sel], pooled["window_end"].values[sel]
        regimes.append(pooled["regime"].values[sel])
        flags.append(pooled["identifiable"].values[sel].astype(bool))
        truths.append(truth_window_regimes(truth, start, end, tau=tau))
        coef_true = truth["coef"].values
        scale = np.sqrt(np.mean(truth["r"].values.sum(-1) ** 2, axis=0))
        res = results[event_id]
        t, A, U = res["time"].values, res["A"].values, res["U"].values
        for w in range(start.size):
            m = (t >= start[w]) & (t < end[w]) & np.isfinite(A).all(1) & np.isfinite(U).all(1)
            e = rhs_relative_error(coef, coef_true, A[m], U[m])
            f_true = evaluate_library(A[m], U[m]) @ coef_true.T
            active = np.sqrt(np.mean(f_true**2, axis=0)) >= active_share * scale
            errs.append(e)
            errs_active.append(np.where(active, e, np.nan))
    scores = regime_scores(np.concatenate(regimes), np.concatenate(truths), np.concatenate(flags))
    scores["rhs_median_rel_error"] = float(np.nanmedian(np.concatenate(errs)))
    scores["rhs_median_rel_error_active"] = float(np.nanmedian(np.concatenate(errs_active)))
    return scores
