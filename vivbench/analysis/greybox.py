"""The grey-box reference refit of a campaign's identification results (docs/field_workflow.md (the grey-box reference)).

:func:`greybox_results` reads the results' envelopes and winds (never an
event's ``/truth``), takes the campaign model that ``vivbench pool`` left in
the directory as the warm start when it has curves, fits
:class:`vivbench.models.GreyBoxRefit` to all events at once, then labels
every window with the model's regime and its identifiability verdict
(:func:`vivbench.regimes.greybox_window_verdicts`) and simulates every event
from its first sample with the measured wind (NMSE against the measured A).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import xarray as xr

from vivbench.analysis.pool import (campaign_model_file, curve_wind_grid, load_campaign_model, campaign_wind_smoothing,
                                    records_from_results)
from vivbench.core.errors import InputError
from vivbench.io.campaign_model import read_campaign_regimes, regimes_file
from vivbench.io.result import read_result
from vivbench.models.greybox import BridgeProperties, GreyBoxRefit
from vivbench.models.model_input import measured_input
from vivbench.preprocess.wind_smoothing import smooth_wind
from vivbench.regimes.greybox import greybox_window_verdicts

__all__ = ["GreyBoxOutcome", "greybox_results", "results_frequency", "campaign_warm_start"]


@dataclasses.dataclass
class GreyBoxOutcome:
    """What :func:`greybox_results` produced.

    Attributes
    ----------
    model : GreyBoxRefit, fitted
    windows : xarray.Dataset
        Per window of every event (dimension ``window_all``) and section
        (``equation``): ``regime``, ``identifiable``, ``agreement``,
        ``order_rms`` (window_all, equation, order), ``window_start``,
        ``window_end``, ``event_id``.
    events : list of dict
        Per event: ``event_id``, ``nmse`` (mean over sections), ``nmse_S1``..,
        ``stopped_at`` (s or NaN), ``duration_s``.
    warm_start : str
        Where the warm start came from.
    records : list of Record
        The fitted records (A, U, yaw).
    """

    model: GreyBoxRefit
    windows: xr.Dataset
    events: list
    warm_start: str
    records: list = dataclasses.field(default_factory=list)


def results_frequency(result_files: Sequence) -> float | None:
    """The median mode frequency (Hz) that ``vivbench identify`` found, None when no result carries it."""
    f = []
    for path in result_files:
        ds = read_result(path, ())
        if "f_mode_hz" in ds.attrs and np.isfinite(float(ds.attrs["f_mode_hz"])):
            f.append(float(ds.attrs["f_mode_hz"]))
    return float(np.median(f)) if f else None


def campaign_warm_start(results_dir, wind: np.ndarray):
    """Curves (docs/concepts.md (coefficient curves)) of the campaign model in ``results_dir`` on ``wind``, and a description.

    Returns (None, reason) when there is no campaign model or it has no curves
    (a model rebuilt from an old ``campaign.regimes.nc``).
    """
    path = campaign_model_file(results_dir)
    if path is None:
        return None, "no campaign model in the results directory: equation-error start"
    model = load_campaign_model(path)
    try:
        return model.curves(wind), f"curves of the campaign model {path.name} ({type(model).__name__})"
    except (InputError, AttributeError, ValueError) as exc:
        return None, f"campaign model {path.name} gives no curves ({type(exc).__name__}): equation-error start"


def greybox_results(result_files: Sequence, bridge: BridgeProperties, *, model: GreyBoxRefit | None = None,
                    warm_start: str | xr.Dataset | None = "auto", tau: float = 0.2, agreement: float = 0.95,
                    n_draws: int = 100, callback=None, wind_smoothing_s: float = 30.0,
                    verdict_reference: str | None = "auto") -> GreyBoxOutcome:
    """Fit the grey-box model to identification results; regimes, verdicts and simulations per event.

    Parameters
    ----------
    result_files : paths of ``<event_id>.identify.nc`` (their time, A, U and windows are used)
    bridge : BridgeProperties
        The user's bridge properties.
    model : GreyBoxRefit or None
        Estimator to fit (its ``bridge`` is replaced by ``bridge``); default ``GreyBoxRefit()``.
    warm_start : "auto", None or a curves dataset
        "auto": the campaign model beside the first result (``vivbench pool``), if it has curves.
    tau, agreement, n_draws : regime threshold and verdict settings (:func:`greybox_window_verdicts`)
    callback : progress callback of :meth:`GreyBoxRefit.fit`
    wind_smoothing_s : float, s
        Gaussian smoothing of the measured wind (and yaw) in time before the
        fit, the verdicts and the simulations (:func:`records_from_results`;
        0: none): the deck feels the wind averaged over its tributary
        length, the anemometer is one point. Default 30 s.
    verdict_reference : "auto" or None
        "auto": a window is identifiable only if the campaign model beside the
        first result (when there is one) gives it the same regime
        (``reference`` of :func:`greybox_window_verdicts`); None: the draws alone.

    Returns
    -------
    GreyBoxOutcome
    """
    files = [Path(p) for p in result_files]
    if not files:
        raise InputError("no identification results to fit the grey-box model on")
    # Read once: the grey-box fit smooths the measured wind its own way, the reference model as at its fit.
    raw = records_from_results(files, derivative=None)  # the grey-box fits envelopes: no dA/dt is needed
    records = [smooth_wind(r, wind_smoothing_s) for r in raw]
    wind = curve_wind_grid(np.concatenate([r.U.ravel() for r in records]))
    source = "given curves"
    if isinstance(warm_start, str):
        if warm_start != "auto":
            raise InputError(f"warm_start must be 'auto', None or a curves dataset; got {warm_start!r}")
        warm_start, source = campaign_warm_start(files[0].parent, wind)
    elif warm_start is None:
        source = "equation-error start"
    model = GreyBoxRefit() if model is None else model
    model.set_params(bridge=bridge, warm_start=warm_start)
    model.fit(records, callback=callback)
    if verdict_reference not in ("auto", None):
        raise InputError(f"verdict_reference must be 'auto' or None; got {verdict_reference!r}")
    reference, reference_name = None, "none"
    cm_path = campaign_model_file(files[0].parent) if verdict_reference == "auto" else None
    if cm_path is not None:
        try:
            reference = load_campaign_model(cm_path)
            pooled_path = regimes_file(cm_path.parent)
            ref_smoothing = campaign_wind_smoothing(read_campaign_regimes(pooled_path) if pooled_path.is_file() else None)
            reference_name = f"{cm_path.name} ({type(reference).__name__})"
        except (InputError, ValueError):
            reference = None
    parts, events = [], []
    for path, rec, rec_raw in zip(files, records, raw):
        ds = read_result(path, ["window_start", "window_end"])
        start, end = ds["window_start"].values, ds["window_end"].values
        v = greybox_window_verdicts(model, rec, start, end, tau=tau, agreement=agreement, n_draws=n_draws,
                                    reference=reference, reference_record=None if reference is None else
                                    measured_input(reference, rec_raw, wind_smoothing_s=ref_smoothing))
        parts.append(xr.Dataset(
            {"regime": (("window_all", "equation"), v["regime"]),
             "identifiable": (("window_all", "equation"), v["identifiable"]),
             "agreement": (("window_all", "equation"), v["agreement"]),
             "order_rms": (("window_all", "equation", "order"), v["order_rms"]),
             "window_start": (("window_all",), start), "window_end": (("window_all",), end),
             "event_id": (("window_all",), np.full(start.size, rec.event_id))}))
        sim = model.simulate(rec)
        row = {"event_id": rec.event_id, "nmse": float(np.nanmean(sim.nmse)),
               "stopped_at": float("nan") if sim.stopped_at is None else float(sim.stopped_at),
               "duration_s": float(rec.t[-1] - rec.t[0])}
        row.update({f"nmse_S{k + 1}": float(x) for k, x in enumerate(sim.nmse)})
        events.append(row)
    windows = xr.concat(parts, dim="window_all") if parts else xr.Dataset()
    windows = windows.assign_coords(equation=[f"S{k + 1}" for k in range(model.n_sections_)], order=np.arange(4))
    windows.attrs.update(tau=tau, agreement=agreement, n_draws=n_draws, verdict_bounds="reflect",
                         verdict_reference=reference_name)
    return GreyBoxOutcome(model=model, windows=windows, events=events, warm_start=source, records=records)
