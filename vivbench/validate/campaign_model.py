"""Recovery of the truth by the campaign model of ``vivbench pool`` (``vivbench.models.campaign``).

The model is used through the model protocol (docs/methods.md): regimes by
:func:`vivbench.regimes.model_window_regimes` on its order contributions,
right-hand sides by its ``predict`` (on the results' measured A and U against
the exact matrix where the truth has one, and on the truth's own A and U
against its dA/dt for any truth). Measured records reach the model through
:func:`vivbench.models.measured_input` (the wind as at fit: the varying
model's smoothing); the truth's felt wind is used as it is. The identifiability verdict of each
window (bootstrap agreement, confidence-region margins) is the one written in
the campaign regimes ``campaign.regimes.nc``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vivbench.core.regime import DEFAULT_TAU
from vivbench.validate.metrics import energy_relative_error
from vivbench.validate.recovery import (
    finite_median,
    model_window_rhs_errors,
    model_window_rhs_true_AU,
    record_yaw_on,
    regime_scores,
    truth_window_activity,
)
from vivbench.models.model_input import measured_input
from vivbench.regimes.model import model_window_regimes
from vivbench.regimes.truth import truth_window_regimes
from vivbench.core.errors import InputError

__all__ = ["campaign_model_recovery"]


def campaign_model_recovery(event_files, regimes_path, result_files, *, active_share: float = 0.1, tau: float = 0.2,
                            model=None) -> dict:
    """Regime scores and right-hand-side errors of the campaign model against the truth.

    Parameters
    ----------
    event_files : synthetic event files (with ``/truth``)
    regimes_path : ``campaign.regimes.nc`` (windows and their identifiability verdicts)
    result_files : the ``<event_id>.identify.nc`` the campaign model was fitted on
        (their A and U are where the right-hand sides are compared)
    active_share : as in :func:`vivbench.validate.campaign_recovery`
    tau : regime threshold of the truth's window regimes (docs/concepts.md (regimes))
    model : fitted model of the protocol, optional
        Default: ``campaign.model.nc`` beside ``regimes_path``, or, for outputs
        without it, the model rebuilt from ``regimes_path``'s ``coef``
        (:func:`vivbench.analysis.load_campaign_model`). Its regimes use its own
        ``tau`` (the one it labelled the windows with).

    Returns
    -------
    dict
        :func:`vivbench.validate.regime_scores` of the model's regimes plus
        ``rhs_median_rel_error`` and ``rhs_median_rel_error_active`` (the one
        model and the exact matrix on the results' measured A and U; NaN
        without ``/truth/coef``) and ``rhs_error_true_AU_median``,
        ``rhs_error_true_AU_median_active`` (the model's ``predict`` on the
        truth's own A and U against the truth's dA/dt, any truth:
        :func:`vivbench.validate.model_window_rhs_errors_true_AU`), and
        ``rhs_error_true_AU_energy``, the same error energy-weighted over every
        truth sample (:func:`vivbench.validate.metrics.energy_relative_error`).
    """
    from vivbench.analysis.pool import campaign_model_file, load_campaign_model, campaign_wind_smoothing
    from vivbench.io.campaign_model import read_campaign_regimes
    from vivbench.io.event import read_event
    from vivbench.io.result import read_result, result_record

    pooled = read_campaign_regimes(regimes_path)
    if model is None:
        model = load_campaign_model(campaign_model_file(Path(regimes_path).parent) or regimes_path)
    model_tau = float(getattr(model, "tau", DEFAULT_TAU))
    smoothing = campaign_wind_smoothing(pooled)
    truths = {}
    for path in event_files:
        tree = read_event(path)
        truths[str(tree.attrs["event_id"])] = tree["truth"].ds
    results = {}
    for path in result_files:
        ds = read_result(path)
        results[str(ds.attrs["event_id"])] = ds
    event_of = pooled["event_id"].values.astype(str)
    regimes, truths_w, flags, errs, errs_active, errs_true, errs_true_active = [], [], [], [], [], [], []
    f_model_all, f_true_all = [], []
    for event_id in dict.fromkeys(event_of):
        if event_id not in truths:
            raise InputError(f"{regimes_path}: event {event_id} has no event file among the {len(truths)} given")
        if event_id not in results:
            raise InputError(f"{regimes_path}: event {event_id} has no identification result among those given")
        sel = event_of == event_id
        truth = truths[event_id]
        res = results[event_id]
        start, end = res["window_start"].values, res["window_end"].values
        if not np.array_equal(pooled["window_start"].values[sel], start):
            raise InputError(f"{regimes_path}: its windows of {event_id} differ from the result's; re-run vivbench pool")
        measured = result_record(res)
        # The model on the measured record's wind as it was at fit; the truth's own wind below as it is.
        record = measured_input(model, measured, wind_smoothing_s=smoothing)
        regimes.append(model_window_regimes(model, record, start, end, tau=model_tau)["regime"])
        flags.append(pooled["identifiable"].values[sel].astype(bool))
        truths_w.append(truth_window_regimes(truth, start, end, tau=tau))
        if "coef" in truth.data_vars:
            e, act = model_window_rhs_errors(model, record, truth["coef"].values, truth["r"].values, start, end,
                                             active_share=active_share)
        else:  # a truth outside the library (docs/concepts.md (no inverse crime)): no error on the measured (A, U)
            act = truth_window_activity(truth, start, end, active_share=active_share)
            e = np.full(act.shape, np.nan)
        errs.append(e.ravel())
        errs_active.append(np.where(act, e, np.nan).ravel())
        # A model using the yaw sees the truth's, or the measured record's where the truth stores none.
        et, act_t, f_model, f_true = model_window_rhs_true_AU(model, truth, start, end, event_id=event_id,
                                                              active_share=active_share,
                                                              yaw=record_yaw_on(measured, truth["time"].values))
        f_model_all.append(f_model.ravel())
        f_true_all.append(f_true.ravel())
        errs_true.append(et.ravel())
        errs_true_active.append(np.where(act_t, et, np.nan).ravel())
    scores = regime_scores(np.concatenate(regimes), np.concatenate(truths_w), np.concatenate(flags))
    scores["rhs_median_rel_error"] = finite_median(np.concatenate(errs))
    scores["rhs_median_rel_error_active"] = finite_median(np.concatenate(errs_active))
    scores["rhs_error_true_AU_median"] = finite_median(np.concatenate(errs_true))
    scores["rhs_error_true_AU_median_active"] = finite_median(np.concatenate(errs_true_active))
    scores["rhs_error_true_AU_energy"] = energy_relative_error(np.concatenate(f_model_all), np.concatenate(f_true_all))
    return scores
