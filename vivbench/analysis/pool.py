"""Fit the campaign model on a campaign's identification results and label every window with it."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

import xarray as xr

import vivbench
from vivbench.core.record import Record
from vivbench.core.regime import DEFAULT_TAU
from vivbench.models.campaign import PooledSINDy
from vivbench.models.campaign_files import campaign_model_file, load_campaign_model
from vivbench.models.curve_support import EXTRAPOLATED, data_wind_range, mark_extrapolated
from vivbench.regimes.model import measured_verdicts
from vivbench.preprocess.derivative import Derivative
from vivbench.io.result import read_result, result_noise_std, result_wind_distance
from vivbench.io.campaign_model import REGIMES_FORMAT
from vivbench.core.errors import InputError
from vivbench.analysis.wind_inputs import with_yaw
from vivbench.preprocess.wind_smoothing import smooth_wind
from vivbench.models.model_input import measured_input
from vivbench.models.protocol import (model_change_inputs, model_for_records, model_summary,
                                      recorded_change_scan, transforms_wind)

__all__ = ["CAMPAIGN_DERIVATIVE", "CURVE_STEP", "curve_wind_grid", "pool_results", "records_from_results",
           "with_campaign_model", "campaign_model_file", "load_campaign_model", "campaign_wind_smoothing"]

#: Spacing of the wind grid of the campaign model's coefficient curves, m/s.
CURVE_STEP = 0.1


def curve_wind_grid(U, step: float = CURVE_STEP) -> np.ndarray:
    """The wind grid of a campaign model's curves: the data's wind range on multiples of ``step``.

    Parameters
    ----------
    U : array_like, m/s
        The winds the model was fitted on (NaN ignored).
    step : float, m/s

    Returns
    -------
    ndarray, shape (n_wind,), m/s
        From the largest multiple of ``step`` at or below the smallest finite
        positive U to the smallest at or above the largest (a polynomial model
        says nothing beyond its data); at least two points.
    """
    U = np.asarray(U, dtype=float)
    U = U[np.isfinite(U) & (U > 0)]
    if U.size == 0:
        raise InputError("no finite positive wind speed: the campaign model's curves have no wind range")
    lo = max(int(np.floor(U.min() / step + 1e-9)), 1)
    hi = max(int(np.ceil(U.max() / step - 1e-9)), lo + 1)
    return np.arange(lo, hi + 1) * step


#: dA/dt of the campaign model: exact TV with the white-noise weight, which on
#: envelopes is nearly the (unbiased) finite differences (see pool_results).
CAMPAIGN_DERIVATIVE = Derivative(method="tv")


def _campaign_derivative(ds, derivative: Derivative | None) -> np.ndarray:
    """dA/dt for the campaign model: ``derivative`` on each segment where the result has one.

    The same samples as the stored dA (the identification's segments long
    enough for a window); None returns the stored dA unchanged.
    """
    stored = ds["dA"].values
    if derivative is None:
        return stored
    t, A, seg = ds["time"].values, ds["A"].values, ds["segment"].values
    out = np.full_like(stored, np.nan)
    for s in np.unique(seg[seg >= 0]):
        sel = (seg == s) & np.isfinite(stored).all(axis=1)
        if sel.sum() >= 5:
            out[sel] = derivative.differentiate(A[sel], t[sel])
    return out


def _result_record(ds, attrs, derivative: Derivative | None) -> Record:
    noise = result_noise_std(attrs, ds["A"].shape[1])
    yaw = ds["yaw"].values if "yaw" in ds else None  # results written before identify stored the yaw have none
    return Record(event_id=str(attrs["event_id"]), t=ds["time"].values, A=ds["A"].values, U=ds["U"].values,
                  dA=_campaign_derivative(ds, derivative), noise_std=noise, yaw=yaw,
                  wind_distance=result_wind_distance(attrs, ds["A"].shape[1]))


def records_from_results(paths: Sequence, *, derivative: Derivative | None = CAMPAIGN_DERIVATIVE, campaign=None,
                         wind_smoothing_s: float = 0.0) -> list[Record]:
    """The records of identification results, ready for any model of the protocol (docs/methods.md).

    Parameters
    ----------
    paths : paths of ``<event_id>.identify.nc``
        Their ``time``, ``A``, ``U``, ``dA``, ``segment`` and (when present)
        ``yaw`` are read: the records carry the mean wind's yaw (``Record.yaw``).
    derivative : Derivative or None
        dA/dt recomputed from A on each segment (default
        :data:`CAMPAIGN_DERIVATIVE`: the records :func:`pool_results` fits);
        None keeps the results' own dA (the identification's smoothed
        derivative, which its window regressions want).
    campaign : path or None
        Directory of the events the results were made from (their
        ``source_file``): results without a ``yaw`` variable (written before
        identification stored it) get the yaw measured from the event's
        anemometers (:func:`vivbench.analysis.with_yaw`); others keep their own.
    wind_smoothing_s : float, s
        Standard deviation of a Gaussian smoothing of U (and yaw) in time
        (:func:`vivbench.analysis.smooth_wind`; 0: none).

    Returns
    -------
    list of Record
        One per file, ``event_id`` from the file's attribute; dA is NaN
        outside the identification's segments.

    Raises
    ------
    InputError
        One line naming a file that is not an identification result.
    """
    out = []
    for path in paths:
        ds = read_result(path, ["A", "U", "dA", "segment"], optional=["yaw"])
        rec = _result_record(ds, ds.attrs, derivative)
        rec = rec if campaign is None or rec.yaw is not None else _with_event_yaw(rec, ds.attrs, campaign)
        out.append(smooth_wind(rec, wind_smoothing_s))
    return out


def _with_event_yaw(record: Record, attrs, campaign) -> Record:
    source = attrs.get("source_file")
    if not source:
        raise InputError(f"the result of {record.event_id} names no source_file: its wind's yaw cannot be measured")
    return with_yaw(record, Path(campaign) / Path(str(source)).name)


def pool_results(result_files: Sequence, model=None, *,
                 derivative: Derivative | None = CAMPAIGN_DERIVATIVE, campaign=None,
                 wind_smoothing_s: float = 0.0) -> "xr.Dataset":
    """Fit the campaign model on identification results and label every window with it.

    Parameters
    ----------
    result_files : paths of ``<event_id>.identify.nc`` (their A, U, segments and windows are used)
    model : campaign model of the protocol, optional
        Fitted here in place (default: ``PooledSINDy()``): a ``PooledSINDy``, a
        ``VaryingCoefficientSINDy``, a :class:`vivbench.analysis.ModelSelection`
        or a user's model (docs/methods.md). Everything model-specific is asked
        through the protocol: its verdict (:func:`vivbench.regimes.measured_verdicts`),
        what is written of it (:func:`vivbench.models.model_summary`), its
        wind (:func:`vivbench.models.transforms_wind`), the records it takes
        (:func:`vivbench.models.model_for_records`) and its change scan
        (:func:`vivbench.models.model_change_inputs`).
    derivative : Derivative or None
        dA/dt of the campaign model, recomputed from each result's A
        (default :data:`CAMPAIGN_DERIVATIVE`); None uses the results' own dA.
        The window regressions want a smoothed derivative (few samples,
        variance matters most), the campaign model an unbiased one (tens of
        thousands of samples average the noise, but not a smoother's bias).
    campaign : path or None
        Directory of the results' event files, for results without the
        ``yaw`` variable (written before identification stored it): their
        records get the yaw measured from the anemometers. Results with
        ``yaw`` need none (a ``VaryingCoefficientSINDy`` uses the yaw whenever
        every record carries it, see its ``yaw_degree``).
    wind_smoothing_s : float, s
        Gaussian smoothing of U (and yaw) before the fit and the verdicts of a
        ``PooledSINDy`` (:func:`vivbench.preprocess.smooth_wind`; 0: none). A
        ``VaryingCoefficientSINDy`` smooths its own wind (its
        ``wind_smoothing_s``; any model with ``measured_wind``): must be 0 with it.

    Returns
    -------
    xarray.Dataset
        Coordinates ``equation``, ``order``, ``window_all`` (every window of
        every event), ``wind`` and ``event``; per window ``event_id``,
        ``window``, ``window_start``, ``window_end``, ``regime``,
        ``identifiable``, ``agreement``, ``order_rms``; the coefficient curves
        (docs/concepts.md (coefficient curves), the model's ``curves`` at its default 95 % level)
        ``curves``, ``curves_lower``, ``curves_upper`` (equation, order, wind)
        in m^(1-i)/s on ``wind`` (m/s, :func:`curve_wind_grid` of the results'
        U) and ``curves_extrapolated`` (equation, wind; int8, 1 where the wind
        lies outside the equation's fitted data,
        :func:`vivbench.models.mark_extrapolated`); per event the residual checks of :mod:`vivbench.analysis.changes`
        (``event_residual_ratio``, ``event_residual_rel_rms``,
        ``event_linear_offset``, ``event_linear_offset_se``,
        ``event_change_stat``), the change-agnostic "not predicted" flags
        ``event_offset_stratum``, ``event_offset_z``, ``event_offset_p`` and
        ``event_offset_flag`` (:func:`vivbench.analysis.changes.offset_flags`,
        :func:`~vivbench.analysis.changes.offset_strata`) and the attributes
        ``change_event``, ``change_p_value``, ``change_detected``,
        ``change_heterogeneity_p``, ``offset_flagged_events``, ``offset_not_assessed_events`` (JSON lists),
        ``flag_fdr``. With a ``VaryingCoefficientSINDy`` also the model change
        scan (``event_misfit``, ``event_misfit_flag``,
        ``event_model_split_gain``; attributes ``model_change_event``,
        ``model_change_p_value``, ``model_change_detected``) and the flags
        relative to the located change (``event_after_change``,
        ``event_offset_held_out``, ``event_change_p``, ``event_change_flag``, attribute
        ``change_flagged_events``; :func:`vivbench.analysis.changes.change_relative_flags`).
        With a ``PooledSINDy`` also the coordinates ``feature`` and
        ``bootstrap`` and ``coef`` (equation, feature) in physical units (dA/dt
        in m/s), ``coef_bootstrap``, ``n_terms``, ``threshold``, ``rss``,
        ``aicc``, ``robust`` (the file has no ``model`` attribute, as before
        the varying model existed). With a ``VaryingCoefficientSINDy`` the
        attribute ``model = "VaryingCoefficientSINDy"`` and per equation
        ``n_basis``, ``penalty``, ``edf``, ``rss`` instead (no library
        coefficients: the splines are in the model's own file,
        ``campaign.model.nc``). Another model gives what its ``campaign_summary``
        names, and the attributes ``model`` and ``model_class``. Written by :func:`write_campaign_regimes` as
        ``campaign.regimes.nc``.
    """
    from vivbench.analysis.changes import (FLAG_FDR, change_point_scan, change_relative_flags, event_residual_checks,
                                           offset_flags, offset_strata)

    model = PooledSINDy() if model is None else model
    results = []
    for path in result_files:
        ds = read_result(path, ["A", "U", "dA", "segment", "window_start", "window_end"],
                         optional=["amplitude_snr", "yaw"])
        results.append((str(path), ds, dict(ds.attrs), [str(s) for s in ds["equation"].values]))
    if not results:
        raise InputError("no identification results to pool")
    sections = results[0][3]
    for path, _ds, _attrs, eq in results:
        if eq != sections:
            raise InputError(f"{path}: equations {eq} differ from {sections} of the other results")
    own_wind = transforms_wind(model)  # the model smooths its own wind (VaryingCoefficientSINDy(wind_smoothing_s=...))
    if own_wind and wind_smoothing_s:
        raise InputError(f"the campaign model ({type(model).__name__}) smooths its own wind (its wind_smoothing_s): "
                         "give pool_results wind_smoothing_s=0 with it")
    records = [_result_record(ds, attrs, derivative) for _p, ds, attrs, _e in results]
    if campaign is not None:
        records = [r if r.yaw is not None else _with_event_yaw(r, attrs, campaign)
                   for r, (_p, _d, attrs, _e) in zip(records, results)]
    model = model_for_records(model, records)  # e.g. without the candidates needing a yaw the records lack
    model.fit(records if own_wind else [smooth_wind(r, wind_smoothing_s) for r in records])
    summary = model_summary(model)
    # Verdicts and checks on the wind the model was fitted on (a model may smooth its own).
    raw_records = records
    records = [measured_input(model, r, wind_smoothing_s=wind_smoothing_s) for r in records]
    keys = ("regime", "identifiable", "agreement", "order_rms") + tuple(k for k in summary["verdicts"]
                                                                       if k != "identifiable")
    rows = {k: [] for k in ("event_id", "window", "window_start", "window_end") + keys}
    for (_path, ds, attrs, _eq), raw in zip(results, raw_records):
        s, e = ds["window_start"].values, ds["window_end"].values
        out = measured_verdicts(model, raw, s, e, wind_smoothing_s=wind_smoothing_s,
                                tau=float(getattr(model, "tau", DEFAULT_TAU)))
        min_snr = json.loads(attrs.get("identify_config_json", "{}")).get("min_snr")
        if min_snr is not None and "amplitude_snr" in ds:
            # The identification's noise-floor test holds for any model: below the floor A is noise.
            out["identifiable"] = out["identifiable"] & ~(ds["amplitude_snr"].values < min_snr)
        rows["event_id"].append(np.full(s.size, str(attrs["event_id"]), dtype=object))
        rows["window"].append(np.arange(s.size))
        rows["window_start"].append(s)
        rows["window_end"].append(e)
        for key in keys:
            rows[key].append(out[key])
    cat = {k: np.concatenate(v) for k, v in rows.items()}
    data = dict(summary["variables"])
    data.update({
        "event_id": (("window_all",), cat["event_id"].astype(str)),
        "window": (("window_all",), cat["window"].astype(np.int32), {"long_name": "window index in the event's result"}),
        "window_start": (("window_all",), cat["window_start"], {"units": "s"}),
        "window_end": (("window_all",), cat["window_end"], {"units": "s"}),
        "regime": (("window_all", "equation"), cat["regime"].astype(np.int8), {"long_name": "regime of the pooled model (docs/concepts.md (regimes))"}),
        "agreement": (("window_all", "equation"), cat["agreement"], {"units": "1", "long_name": "share of bootstrap models with the same regime"}),
        "order_rms": (("window_all", "equation", "order"), cat["order_rms"], {"units": "m/s"}),
    })
    for key, long_name in summary["verdicts"].items():
        data[key] = (("window_all", "equation"), np.asarray(cat[key]).astype(np.int8), {"long_name": long_name})
    # With a selection: the chosen model's curves, their bands widened to hold the confidence set's.
    grid = curve_wind_grid(np.concatenate([ds["U"].values.ravel() for _p, ds, _a, _e in results]))
    curves = model.curves(grid)
    # Marked where a section's curve lies outside the winds it was fitted on (the wind as at fit).
    curves = mark_extrapolated(curves, data_wind_range(records))
    for name in ("curves", "curves_lower", "curves_upper"):
        data[name] = (("equation", "order", "wind"), curves[name].values, curves[name].attrs)
    data[EXTRAPOLATED] = (("equation", "wind"), curves[EXTRAPOLATED].values.astype(np.int8),
                          curves[EXTRAPOLATED].attrs)
    # Does the model's assumption (one function of (A, U) for the whole campaign) hold? (vivbench.analysis.changes)
    checks = event_residual_checks(model, records)
    scan = change_point_scan(checks["linear_offset"], checks["linear_offset_se"], checks["weight"],
                             seed=int(getattr(model, "seed", 0)))
    data.update({
        "event_residual_ratio": (("event",), checks["residual_ratio"],
                                 {"units": "1", "long_name": "RMS of the event's dA/dt residual over the median of the events'"}),
        "event_residual_rel_rms": (("event",), checks["residual_rel_rms"],
                                   {"units": "1", "long_name": "RMS of the event's dA/dt residual over the RMS of its dA/dt"}),
        "event_linear_offset": (("event",), checks["linear_offset"],
                                {"units": "s-1", "long_name": "least-squares coefficient of the event's residual on A "
                                 "(an unmodelled change of the net linear coefficient; negative: more damped)"}),
        "event_linear_offset_se": (("event",), checks["linear_offset_se"],
                                   {"units": "s-1", "long_name": "block-robust standard error of event_linear_offset"}),
        "event_change_stat": (("event",), scan["split_stat"],
                              {"units": "m2 s-2", "long_name": "between-group sum of squares of event_linear_offset "
                               "for a change just before this event"}),
    })
    stratum = offset_strata(checks["residual_rel_rms"])
    offsets = offset_flags(checks["linear_offset"], checks["linear_offset_se"], n_pieces=checks["n_pieces"],
                           stratum=stratum)
    data.update({
        "event_offset_stratum": (("event",), stratum,
                                 {"long_name": "1: the campaign model explains less than half of the event's mean "
                                  "square of dA/dt (its offset is judged only against such events), else 0"}),
        "event_offset_z": (("event",), offsets["z"],
                           {"units": "1", "long_name": "signed normal quantile of event_offset_p (NaN: not assessed)"}),
        "event_offset_p": (("event",), offsets["p"],
                           {"units": "1", "long_name": "posterior predictive p-value of event_linear_offset under a "
                            "random-effects model of the other events' offsets of its stratum, the between-event "
                            "spread integrated over its posterior (NaN: not assessed)"}),
        "event_offset_flag": (("event",), offsets["flag"].astype(np.int8),
                              {"long_name": "1: not predicted, the event's linear offset departs from the other "
                               "events' of its stratum (Benjamini-Hochberg over the assessed events at FLAG_FDR)"}),
    })
    event_ids = [str(a["event_id"]) for _p, _d, a, _e in results]
    change_inputs, model_scan = _model_change_scan(model, records, event_ids)
    if change_inputs is not None:
        stats = change_inputs["statistics"]
        # Flags relative to the located change, only when the scan reports one.
        ci = model_scan["change_index"] if model_scan["detected"] else -1
        rel = change_relative_flags(stats, ci, checks["linear_offset_se"], change_inputs["a_ref"],
                                    change_inputs["y_scale"], n_pieces=checks["n_pieces"])
        data.update({
            "event_after_change": (("event",), (np.arange(len(records)) >= ci if ci >= 0
                                                else np.zeros(len(records), dtype=bool)).astype(np.int8),
                                   {"long_name": "1: from the change the model change scan located on (its "
                                    "permutation p below its level: the campaign-level false-alarm control)"}),
            "event_offset_held_out": (("event",), rel["offset_held_out"],
                                      {"units": "s-1", "long_name": "linear offset of the event's residual under the "
                                       "model of the other events (NaN: no change located)"}),
            "event_change_p": (("event",), rel["p"],
                               {"units": "1", "long_name": "p-value of event_offset_held_out against a random-effects "
                                "model of the before-events' (events from the located change on)"}),
            "event_change_flag": (("event",), rel["flag"].astype(np.int8),
                                  {"long_name": "1: after the located change and its held-out offset departs from the "
                                   "before-events' (Benjamini-Hochberg over the events after it at FLAG_FDR)"}),
        })
    if model_scan is not None:
        data.update({
            "event_misfit": (("event",), model_scan["misfit"],
                             {"units": "1", "long_name": "leave-one-event-out mean squared dA/dt residual over the median event's"}),
            "event_misfit_flag": (("event",), model_scan["misfit_flag"].astype(np.int8),
                                  {"long_name": "1: the model fitted to the other events does not predict this one "
                                   "(robust outlier of event_misfit)"}),
            "event_model_split_gain": (("event",), model_scan["split_gain"],
                                       {"units": "1", "long_name": "relative drop of the penalised RSS when the model is "
                                        "refitted separately before and after this event"}),
        })
    coords = {"equation": sections, **summary["coords"]}
    coords.update({"order": np.arange(4), "window_all": np.arange(cat["window"].size),
                   "wind": ("wind", curves["wind"].values, {"units": "m/s", "long_name": "mean wind speed of the curves"}),
                   "event": ("event", event_ids, {"long_name": "events in the order of the result files"})})
    attrs = {
        "format": REGIMES_FORMAT,
        "format_version": 1,
        "events": json.dumps(event_ids),
        "note": "",
        "wind_smoothing_s": float(wind_smoothing_s),
        **summary["attrs"],
    }
    attrs.update({
        "coverage": float(np.mean(cat["identifiable"][cat["regime"] > 0])) if (cat["regime"] > 0).any() else float("nan"),
        "derivative_json": json.dumps(None if derivative is None else dataclasses.asdict(derivative), sort_keys=True),
        "wind_yaw": int(all(r.yaw is not None for r in records)),
        "vivbench_version": vivbench.__version__,
        "change_event": "" if scan["change_index"] < 0 else event_ids[scan["change_index"]],
        "change_p_value": scan["p_value"],
        "change_detected": int(scan["detected"]),
        "change_heterogeneity_p": scan["heterogeneity_p"],
    })
    if model_scan is not None:
        ci = model_scan["change_index"]
        attrs.update({"model_change_event": "" if ci < 0 else event_ids[ci],
                      "model_change_p_value": model_scan["p_value"],
                      "model_change_detected": int(model_scan["detected"]),
                      "change_flagged_events": json.dumps([event_ids[i] for i in np.flatnonzero(
                          data["event_change_flag"][1])])})
    attrs["offset_flagged_events"] = json.dumps([event_ids[i] for i in np.flatnonzero(offsets["flag"])])
    attrs["offset_not_assessed_events"] = json.dumps([event_ids[i] for i in np.flatnonzero(np.isnan(offsets["p"]))])
    attrs["flag_fdr"] = FLAG_FDR
    return xr.Dataset(data, coords=coords, attrs=attrs)


def _model_change_scan(model, records: list[Record], event_ids: list[str]) -> tuple[dict | None, dict | None]:
    """The fitted model's change scan inputs and result (:func:`vivbench.models.model_change_inputs`,
    :func:`vivbench.analysis.changes.statistics_change_scan` at the model's seed), (None, None) without them.

    ``records`` are those the model was just fitted on, their wind as at fit. A model that scanned itself
    on them (:func:`vivbench.models.recorded_change_scan`, e.g. a :class:`vivbench.analysis.ModelSelection`'s:
    the same events, inputs and seed) gives its own recorded scan instead of a second one.
    """
    from vivbench.analysis.changes import statistics_change_scan

    seed = int(getattr(model, "seed", 0))
    recorded = recorded_change_scan(model)
    if recorded is not None and recorded["events"] == list(event_ids) and recorded["seed"] == seed:
        return recorded["inputs"], recorded["scan"]
    inputs = model_change_inputs(model, records)
    if inputs is None:
        return None, None
    return inputs, statistics_change_scan(inputs["statistics"], seed=seed)


def campaign_wind_smoothing(pooled) -> float:
    """The smoothing of the measured wind, s, a campaign model of ``vivbench pool`` was fitted with.

    For :func:`vivbench.models.measured_input` of a model that does not know
    it itself (a ``PooledSINDy`` of ``vivbench pool --wind-smoothing S``; a
    ``VaryingCoefficientSINDy`` uses its own ``wind_smoothing_s``).

    Parameters
    ----------
    pooled : xarray.Dataset or None
        A ``campaign.regimes.nc`` (:func:`vivbench.io.campaign_model.read_campaign_regimes`).

    Returns
    -------
    float, s
        Its ``wind_smoothing_s`` attribute; 0 without a campaign regimes file or for
        outputs written before the attribute existed (no smoothing then).
    """
    if pooled is None:
        return 0.0
    value = float(pooled.attrs.get("wind_smoothing_s", 0.0))
    return value if np.isfinite(value) and value >= 0 else 0.0


def with_campaign_model(result, pooled):
    """A copy of an identification result whose every window holds the campaign model's coefficients.

    With it the simulation and forecasting functions of ``vivbench.models.simulate``
    run the pooled model (a forecast with it does not depend on d). The
    commands use the model object instead (:func:`load_campaign_model`, then
    ``predict``, ``simulate``); this stays for code written against result files.

    Parameters
    ----------
    result : xarray.Dataset, an ``<event_id>.identify.nc``
    pooled : xarray.Dataset, a ``campaign.regimes.nc`` with the same equations and features
    """
    missing = [v for v in ("coef", "feature") if v not in pooled]
    if missing:
        source = pooled.encoding.get("source", "the campaign model")
        raise InputError(f"{source}: not a campaign model (campaign.regimes.nc of vivbench pool): missing {missing}")
    if [str(x) for x in pooled["feature"].values] != [str(x) for x in result["feature"].values]:
        raise InputError("the campaign model's features differ from the result's")
    out = result.copy()
    out["coef"] = (result["coef"].dims, np.broadcast_to(pooled["coef"].values, result["coef"].shape).copy(),
                   result["coef"].attrs)
    return out

