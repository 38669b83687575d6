"""Validation of a campaign's identification results against its synthetic truth.

:func:`validate_campaign` pairs every ``<event_id>.identify.nc`` of a results
directory with ``<event_id>.nc`` of the campaign, scores it with
:mod:`vivbench.validate.metrics` and returns plain tables (lists of dicts);
:func:`write_validation` writes them as CSV and JSON. Events without a
``/truth`` group (field data) cannot be validated and are listed under
``skipped`` with the reason.
"""

from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path

import numpy as np

from vivbench.core.regime import DEFAULT_TAU
from vivbench.validate.metrics import (
    REGIMES,
    SUPPORT_NOTES,
    cluster_agreement,
    curve_energy_error,
    curve_errors,
    curves_rhs,
    energy_relative_error,
    forecast_summary,
    merge_support_scores,
    regime_report,
    rhs_error_summary,
    support_scores,
)
from vivbench.models.model_input import measured_input
from vivbench.models.curve_support import data_wind_range
from vivbench.models.protocol import model_curves, model_size
from vivbench.regimes.model import model_window_regimes
from vivbench.regimes.truth import truth_window_regimes
from vivbench.validate.recovery import (
    model_window_rhs_errors,
    model_window_rhs_true_AU,
    record_yaw_on,
    window_rhs_errors,
    window_rhs_true_AU,
)
from vivbench.core.errors import InputError
from vivbench.validate.drift import event_structural_state, score_change_flags

__all__ = ["validate_campaign", "write_validation", "upgrade_metrics", "read_cluster_labels", "read_forecast_tables", "event_truth_curves",
           "NO_TRUE_SUPPORT"]

#: What the support scores say for a truth without an exact coefficient matrix.
NO_TRUE_SUPPORT = "n/a (no exact coefficient matrix: truth outside the library)"

_NOTES = (
    "Regime accuracy is reported for identifiable window-equations apart from the others, with coverage "
    "(share flagged identifiable) beside it; labels of unflagged windows are not findings (README, known limitations).",
    "RHS error (rhs, median_rhs_rel_error): relative RMS of identified minus true dA/dt, both evaluated on the "
    "result's own (measured) A and U over the window with the exact coefficient matrix (in-library truths only); "
    "'active' window-equations are those whose true dA/dt RMS is at least active_share of the event's.",
    "RHS error on the true (A, U) (rhs_true_AU, median_rhs_error_true_AU): relative RMS of the model's predict on "
    "the truth's own time, A and U minus the truth's dA/dt (sum of /truth/r over the orders) over the window's "
    "truth samples, for any truth (no coefficient matrix needed); window models use each window's own model, "
    "'active' as above with the truth's dA/dt. Beside the median over windows, the same error energy-weighted "
    "(energy_rhs_error_true_AU, rhs_true_AU.energy): sqrt(sum of squared errors / sum of squared true dA/dt) over "
    "every sample (the window models: over their windows' samples), which the large amplitudes dominate.",
    "Curve errors (pooled.curves): the campaign model's coefficient curves a_ki(U) (campaign.regimes.nc) against "
    "the truth's (/truth/curves), over the lock-in range (winds of the truth samples whose regime is "
    "self-excited, 2..4): relative RMS of the net linear coefficient a_k1 on the model's wind grid, and of "
    "sum_i a_ki(U) A^i on those samples; and energy-weighted (campaign_model_curve_error_energy): sum_i a_ki(U_k) A_k^i "
    "at the truth's (A, U) of every sample of every equation against the same sum with the truth's curves. "
    "The curves are scored only at winds inside each equation's fitted data (the extrapolated parts, "
    "curves_extrapolated, are left out).",
    *SUPPORT_NOTES,
)


def read_cluster_labels(path) -> list[dict]:
    """Rows of ``cluster_labels.csv`` (see ``vivbench cluster``), typed.

    Returns
    -------
    list of dict with ``event_id`` (str), ``window`` (int), ``equation`` (str),
    ``feature_set`` (str), ``label`` (int), ``halo`` (bool)
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such cluster labels file")
    need = ("event_id", "window", "equation", "feature_set", "label", "halo")
    with path.open(newline="") as fh:
        reader = csv.DictReader(fh)
        missing = [c for c in need if c not in (reader.fieldnames or [])]
        if missing:
            raise InputError(f"{path}: missing columns {missing}; expected {list(need)}")
        rows = []
        for k, row in enumerate(reader, start=2):
            try:
                rows.append({"event_id": row["event_id"], "window": int(row["window"]), "equation": row["equation"],
                             "feature_set": row["feature_set"], "label": int(row["label"]),
                             "halo": row["halo"].strip().lower() in ("1", "true", "yes")})
            except ValueError as exc:
                raise InputError(f"{path}: line {k}: {exc}") from None
    return rows


def read_forecast_tables(directory) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """NMSE rows of every ``forecast_<event_id>.csv`` in a directory (``vivbench forecast``).

    Each file needs the columns ``d`` (s), ``nmse`` and ``stopped`` (as written
    from :func:`vivbench.models.forecast_table`), or is the table of
    ``vivbench forecast`` (columns ``kind``, ``clip``, ``d_s``, ``nmse``,
    ``stopped``), of which the window models' forecasts without clipping (the
    paper's method) are read; other columns are ignored.

    Returns
    -------
    nmse, stopped, d : ndarray, shape (n_rows,)
    event_ids : list of str, one per row
    """
    directory = Path(directory)
    if not directory.is_dir():
        raise InputError(f"{directory}: no such forecast directory")
    files = sorted(directory.glob("forecast_*.csv"))
    if not files:
        raise InputError(f"{directory}: no forecast tables (forecast_<event_id>.csv) in this directory")
    nmse, stopped, d, ids = [], [], [], []
    for f in files:
        with f.open(newline="") as fh:
            reader = csv.DictReader(fh)
            names = reader.fieldnames or []
            cli = {"kind", "clip", "d_s"} <= set(names)
            dcol = "d_s" if cli else "d"
            missing = [c for c in (dcol, "nmse", "stopped") if c not in names]
            if missing:
                raise InputError(f"{f}: missing columns {missing}; a forecast table needs d (or kind, clip, d_s), "
                                 "nmse and stopped")
            for k, row in enumerate(reader, start=2):
                if cli and (row["kind"] != "forecast" or row["clip"] != "none"):
                    continue
                try:
                    d.append(float(row[dcol]))
                    nmse.append(float(row["nmse"]) if row["nmse"].strip() else math.nan)
                except ValueError as exc:
                    raise InputError(f"{f}: line {k}: {exc}") from None
                stopped.append(row["stopped"].strip().lower() in ("1", "true", "yes"))
                ids.append(f.stem[len("forecast_"):])
    return np.array(nmse, dtype=float), np.array(stopped, dtype=bool), np.array(d, dtype=float), ids


def _cluster_tables(rows: list[dict], truth_regimes: dict) -> list[dict]:
    """Cluster agreement per feature set, with and without the halo points."""
    out = []
    for fs in sorted({r["feature_set"] for r in rows}):
        sel = [r for r in rows if r["feature_set"] == fs]
        labels = np.array([r["label"] for r in sel])
        halo = np.array([r["halo"] for r in sel])
        truth = np.array([truth_regimes.get((r["event_id"], r["window"], r["equation"]), 0) for r in sel])
        for ignore in (False, True):
            row = {"feature_set": fs, "halo_ignored": ignore, "n_labels": len(sel),
                   "n_without_truth": int((truth == 0).sum())}
            row.update(cluster_agreement(labels, truth, halo, ignore_halo=ignore))
            out.append(row)
    return out


def event_truth_curves(truth) -> tuple[np.ndarray, np.ndarray] | None:
    """The exact coefficient curves of an event's truth (docs/concepts.md (coefficient curves)), stored or rebuilt.

    Parameters
    ----------
    truth : xarray.Dataset, an event's ``/truth``

    Returns
    -------
    (curves, wind) or None
        ``curves`` (S, 4, n_wind) in m^(1-i)/s and ``wind`` (n_wind,) in m/s:
        ``/truth/curves`` when stored; for files written before it, rebuilt
        from the generator configuration in ``config_json`` with
        :func:`vivbench.synth.event_truth_curves` (the same function the
        generator uses); None when neither gives curves (a drifting damping,
        no ``config_json``, as in truths of other generators, or one that is
        not vivbench's): whatever needs the curves reports them unavailable.
    """
    if "curves" in truth.data_vars:
        return truth["curves"].values, truth["wind"].values
    from vivbench.synth import config_from_dict
    from vivbench.synth.event import event_truth_curves as rebuild

    try:
        meta = json.loads(truth.attrs["config_json"])
        config = config_from_dict(meta["generator"])
        number = int(meta.get("event", {}).get("number", 1))
    except (KeyError, TypeError, ValueError):
        return None
    curves = rebuild(config, number)
    return None if curves is None else (curves.values, curves["wind"].values)


def validate_campaign(campaign_dir, results_dir, *, clusters_csv=None, forecasts_dir=None, tau: float = DEFAULT_TAU,
                      active_share: float = 0.1) -> dict:
    """Score every identification result of a campaign against the truth.

    Parameters
    ----------
    campaign_dir : directory of ``<event_id>.nc`` event files
    results_dir : directory of ``<event_id>.identify.nc`` results
    clusters_csv : optional ``cluster_labels.csv`` of ``vivbench cluster``
    forecasts_dir : optional directory of ``forecast_<event_id>.csv`` (``vivbench forecast``);
        see :func:`read_forecast_tables`
    tau : regime threshold for the truth's window regimes (docs/concepts.md (regimes))
    active_share : see :func:`vivbench.validate.window_rhs_errors`

    Returns
    -------
    dict
        ``regime`` (:func:`regime_report` over all events), ``regime_confusion``
        (rows group, true regime, counts per identified regime), ``rhs``
        (:func:`rhs_error_summary` of the window models' dA/dt error on the
        result's measured A and U with the exact coefficient matrix; None when
        no truth has ``coef``), ``rhs_true_AU`` (:func:`rhs_error_summary` of
        their dA/dt error on the truth's own A and U against the truth's dA/dt,
        :func:`vivbench.validate.window_rhs_errors_true_AU`, any truth),
        ``support`` (:func:`support_scores` for all models and for identifiable
        ones; None without ``coef``), ``support_note`` (None, or
        :data:`NO_TRUE_SUPPORT`), ``support_table`` (rows), ``per_event``
        (rows; events without ``coef`` have ``support`` = :data:`NO_TRUE_SUPPORT`
        instead of support scores), ``clusters`` (rows, or None), ``forecast`` (rows of
        :func:`forecast_summary` per d, or None), ``truth_regime_shares``,
        ``campaign_model`` (regime report, ``rhs`` and ``rhs_true_AU`` errors and
        ``curves`` (:func:`curve_errors` of its coefficient curves against the
        truth's, or ``scored`` False with the reason) of the campaign model when
        ``results_dir/campaign.regimes.nc`` is present, else None: regimes and
        dA/dt of the model object of ``campaign.model.nc`` through the model
        protocol, or of the model rebuilt from the regimes file's ``coef``
        for outputs without that file; identifiability verdicts from the
        campaign regimes),
        ``skipped`` (event file -> reason), ``notes``, ``settings``, ``summary``
        (flat headline numbers).

    Raises
    ------
    ValueError
        No result files; a result without its event file (the message names
        both); no event with a ``/truth`` group.
    """
    from vivbench.io.event import read_event

    if not 0.0 <= active_share < 1.0:
        raise InputError(f"active_share must lie in [0, 1); got {active_share}")
    if not 0.0 < tau < 1.0:
        raise InputError(f"tau must lie strictly between 0 and 1; got {tau}")
    campaign_dir, results_dir = Path(campaign_dir), Path(results_dir)
    for d, what in ((campaign_dir, "campaign"), (results_dir, "results")):
        if not d.is_dir():
            raise InputError(f"{d}: no such {what} directory")
    from vivbench.io.result import list_results, read_result, result_record

    result_files = list_results(results_dir)
    pairs = []
    for rp in result_files:
        event_id = rp.name[: -len(".identify.nc")]
        ep = campaign_dir / f"{event_id}.nc"
        if not ep.is_file():
            raise InputError(f"{rp}: no event file {ep} for this result")
        pairs.append((event_id, ep, rp))

    regimes, truths, flags, errs, actives, per_event = [], [], [], [], [], []
    f_win, f_win_true, p_f, p_f_true, fitted_records = [], [], [], [], []
    errs_true, actives_true, truth_U, truth_A, truth_excited, truth_curves = [], [], [], [], [], []
    sup_all, sup_ok = [], []
    skipped, truth_by_key, change_states = {}, {}, {}
    # The campaign model of ``vivbench pool``, scored beside the window models when present: the
    # model object (campaign.model.nc, or rebuilt from the regimes file's coef for older outputs)
    # through the protocol, the windows' identifiability verdicts from the campaign regimes.
    from vivbench.io.campaign_model import read_campaign_regimes, regimes_file
    from vivbench.analysis.pool import campaign_model_file, load_campaign_model, campaign_wind_smoothing

    pooled_path = regimes_file(results_dir)
    pooled = model = model_path = None
    if pooled_path.is_file():
        pooled = read_campaign_regimes(pooled_path)
        model_path = campaign_model_file(results_dir)
        model = load_campaign_model(model_path)
        model_tau = float(getattr(model, "tau", DEFAULT_TAU))
        smoothing = campaign_wind_smoothing(pooled)
    p_reg, p_ok, p_errs, p_act, p_errs_true, p_act_true = [], [], [], [], [], []
    for event_id, ep, rp in pairs:
        tree = read_event(ep)
        if "truth" not in tree.children:
            skipped[str(ep)] = "no /truth group (field data): nothing to validate against"
            continue
        truth = tree["truth"].ds
        change_states[event_id] = event_structural_state(truth)
        res = read_result(rp)
        start, end = res["window_start"].values, res["window_end"].values
        reg = res["regime"].values.astype(int)
        tru = truth_window_regimes(truth, start, end, tau=tau).astype(int)
        ok = res["identifiable"].values.astype(bool)
        equations = [str(x) for x in res["equation"].values]
        truth_by_key.update({(event_id, w, eq): int(tru[w, e]) for w in range(tru.shape[0]) for e, eq in enumerate(equations)})
        report = regime_report(reg, tru, ok)
        row = {"event_id": event_id, "n_windows": int(start.size), "n_window_equations": report["n"],
               "coverage": report["coverage"]}
        for g in ("identifiable", "not_identifiable", "all"):
            row[f"accuracy_{g}"] = report["groups"][g]["accuracy"]
        regimes.append(reg)
        truths.append(tru)
        flags.append(ok)
        if pooled is not None:
            sel = pooled["event_id"].values.astype(str) == event_id
            if sel.sum() != start.size or not np.array_equal(pooled["window_start"].values[sel], start):
                raise InputError(f"{pooled_path}: its windows of {event_id} differ from {rp}; re-run vivbench pool")
            measured = result_record(res)
            # The model on the measured record's wind as it was at fit; the truth's own wind below as it is.
            record = measured_input(model, measured, wind_smoothing_s=smoothing)
            p_reg.append(model_window_regimes(model, record, start, end, tau=model_tau)["regime"].astype(int))
            p_ok.append(pooled["identifiable"].values[sel].astype(bool))
            if "coef" in truth.data_vars:
                pe, pact = model_window_rhs_errors(model, record, truth["coef"].values, truth["r"].values, start, end,
                                                   active_share=active_share)
                p_errs.append(pe.ravel())
                p_act.append(pact.ravel())
            fitted_records.append(record)
            # A model using the yaw sees the truth's, or the measured record's where the truth stores none.
            pet, pact_t, fm, ft = model_window_rhs_true_AU(model, truth, start, end, event_id=event_id,
                                                           active_share=active_share,
                                                           yaw=record_yaw_on(measured, truth["time"].values))
            p_f.append(fm.ravel())
            p_f_true.append(ft.ravel())
            p_errs_true.append(pet.ravel())
            p_act_true.append(pact_t.ravel())
        et, act_t, fw, fwt = window_rhs_true_AU(res, truth, active_share=active_share)
        errs_true.append(et.ravel())
        actives_true.append(act_t.ravel())
        f_win.append(fw.ravel())
        f_win_true.append(fwt.ravel())
        row.update(rhs_error_true_AU_median=float(np.nanmedian(et)) if np.isfinite(et).any() else math.nan,
                   rhs_error_true_AU_median_active=(float(np.nanmedian(et[act_t])) if np.isfinite(et[act_t]).any()
                                                    else math.nan),
                   rhs_error_true_AU_energy=energy_relative_error(fw, fwt))
        truth_U.append(truth["U"].values)
        truth_A.append(truth["A"].values)
        truth_excited.append(truth["regime"].values >= 2)
        truth_curves.append(event_truth_curves(truth))
        if "coef" in truth.data_vars:
            coef_true = truth["coef"].values
            e, act = window_rhs_errors(res, coef_true, truth["r"].values, active_share=active_share)
            sup = support_scores(res["coef"].values, coef_true)
            sup_all.append(sup)
            sup_ok.append(support_scores(res["coef"].values, coef_true, mask=ok))
            errs.append(e.ravel())
            actives.append(act.ravel())
            row.update(rhs_median_rel_error=float(np.nanmedian(e)) if np.isfinite(e).any() else math.nan,
                       rhs_median_rel_error_active=float(np.nanmedian(e[act])) if np.isfinite(e[act]).any() else math.nan)
            for level in ("terms", "pooled_terms", "orders"):
                row[f"support_precision_{level}"] = sup[level]["precision"]
                row[f"support_recall_{level}"] = sup[level]["recall"]
        else:
            # Support recall means nothing without a true support; the dA/dt error on the true (A, U) stands.
            row["support"] = NO_TRUE_SUPPORT
        per_event.append(row)
    pooled_out = None
    if pooled is not None and p_reg:
        pr = regime_report(np.concatenate(p_reg), np.concatenate(truths), np.concatenate(p_ok))
        pooled_out = {"regime": pr, "rhs": rhs_error_summary(np.concatenate(p_errs), np.concatenate(p_act)) if p_errs else None,
                      "rhs_true_AU": {**rhs_error_summary(np.concatenate(p_errs_true), np.concatenate(p_act_true)),
                                      "energy": energy_relative_error(np.concatenate(p_f), np.concatenate(p_f_true))},
                      "file": str(pooled_path), "model_file": str(model_path),
                      "model": type(model).__name__,
                      "n_terms": model_size(model),
                      "curves": _pooled_curve_errors(pooled, model, truth_curves, truth_U, truth_A, truth_excited,
                                                     data_wind_range(fitted_records)),
                      "changes": score_change_flags(pooled, change_states)}
    if not regimes:
        raise InputError(f"{campaign_dir}: no event with a /truth group among the {len(pairs)} results; "
                         "validation needs synthetic events")

    reg, tru, ok = (np.concatenate(x) for x in (regimes, truths, flags))
    regime = regime_report(reg, tru, ok)
    confusion_rows = []
    groups = [(g, regime) for g in ("identifiable", "not_identifiable", "all")]
    if pooled_out is not None:
        groups += [(f"campaign_model_{g}", pooled_out["regime"]) for g in ("identifiable", "not_identifiable", "all")]
    for g, rep in groups:
        cm = rep["groups"][g.removeprefix("campaign_model_")]["confusion"]
        for a in REGIMES:
            confusion_rows.append({"group": g, "truth_regime": a, **{f"identified_{b}": cm[a - 1][b - 1] for b in REGIMES},
                                   "n": int(sum(cm[a - 1]))})

    rhs = support = None
    support_rows = []
    if errs:
        rhs = rhs_error_summary(np.concatenate(errs), np.concatenate(actives))
        support = {"all": merge_support_scores(sup_all), "identifiable": merge_support_scores(sup_ok)}
        for g, sc in support.items():
            for level in ("terms", "pooled_terms", "orders"):
                support_rows.append({"models": g, "level": level, "item": "all", "n_models": sc["n"], **sc[level]})
            for i in range(4):
                support_rows.append({"models": g, "level": "order", "item": f"A^{i}", "n_models": sc["n"],
                                     **sc["order_counts"][i]})

    clusters = None
    if clusters_csv is not None:
        clusters = _cluster_tables(read_cluster_labels(clusters_csv), truth_by_key)

    forecast = None
    if forecasts_dir is not None:
        forecast = forecast_summary(*read_forecast_tables(forecasts_dir)[:3])

    truth_all = tru.ravel()
    out = {
        "regime": regime,
        "regime_confusion": confusion_rows,
        "rhs": rhs,
        "rhs_true_AU": {**rhs_error_summary(np.concatenate(errs_true), np.concatenate(actives_true)),
                        "energy": energy_relative_error(np.concatenate(f_win), np.concatenate(f_win_true))},
        "support_note": None if support is not None else NO_TRUE_SUPPORT,
        "support": support,
        "support_table": support_rows,
        "per_event": per_event,
        "clusters": clusters,
        "forecast": forecast,
        "campaign_model": pooled_out,
        "truth_regime_shares": {str(k): float(np.mean(truth_all == k)) for k in REGIMES},
        "skipped": skipped,
        "notes": list(_NOTES),
        "settings": {"tau": float(tau), "active_share": float(active_share), "campaign_dir": str(campaign_dir),
                     "results_dir": str(results_dir), "clusters_csv": None if clusters_csv is None else str(clusters_csv),
                     "forecasts_dir": None if forecasts_dir is None else str(forecasts_dir)},
    }
    out["summary"] = _summary(out)
    return out


def _pooled_curve_errors(pooled, model, truth_curves, U, A, excited, wind_range) -> dict:
    """Curve errors of the campaign model against the truth, or why they are not scored.

    :func:`curve_errors` and :func:`curve_energy_error` against the truth's curves (needs one
    campaign curve), only inside ``wind_range`` (S, 2), the fitted data's winds per equation.
    """
    from vivbench.core.terms import reference_section
    from vivbench.models.curve_support import curves_inside_data

    if "curves" in pooled.data_vars:
        c = pooled[["curves"]]
    else:
        from vivbench.analysis.pool import curve_wind_grid

        c = model_curves(model, curve_wind_grid(np.concatenate([u.ravel() for u in U])))
    if c is None:
        return {"scored": False, "reason": "the campaign model has no curves (re-run vivbench pool)"}
    curves, wind = c["curves"].values, c["wind"].values
    if curves.shape[0] != U[0].shape[1]:
        return {"scored": False, "reason": f"the truth has {U[0].shape[1]} equations, the model {curves.shape[0]}"}
    U, A = np.concatenate(U), np.concatenate(A)
    inside = curves_inside_data(c, wind_range)
    if not truth_curves or any(tc is None for tc in truth_curves):
        return {"scored": False,
                "reason": "an event's truth has no coefficient curves (a damping drift, or a truth "
                          "without /truth/curves nor vivbench's config_json to rebuild them)"}
    tc0, tw0 = truth_curves[0]
    if any(tw.shape != tw0.shape or not np.array_equal(tw, tw0) or not np.array_equal(tc, tc0)
           for tc, tw in truth_curves[1:]):
        return {"scored": False,
                "reason": "the truth's curves differ between events (slow changes): no single "
                          "campaign curve to compare with"}
    energy = curve_energy_error(curves, wind, U, A, curves_rhs(tc0, tw0, U, A), wind_range)
    err = curve_errors(inside, wind, tc0, tw0, U, A, np.concatenate(excited))
    k = reference_section(curves.shape[0])
    return {"scored": True, **err, "energy": energy, "reference_equation": f"S{k + 1}",
            "reference": {"linear": err["linear"][k], "total": err["total"][k], "lock_in_wind": err["lock_in_wind"][k]}}


def _summary(v: dict) -> dict:
    """Flat headline numbers (units in the names where they have any)."""
    g = v["regime"]["groups"]
    out = {
        "n_events": len(v["per_event"]),
        "n_events_skipped": len(v["skipped"]),
        "n_window_equations": v["regime"]["n"],
        "regime_coverage": v["regime"]["coverage"],
        "regime_accuracy_identifiable": g["identifiable"]["accuracy"],
        "regime_accuracy_not_identifiable": g["not_identifiable"]["accuracy"],
        "regime_accuracy_all": g["all"]["accuracy"],
        "truth_most_common_regime_share": max(v["truth_regime_shares"].values()),
    }
    rt = v["rhs_true_AU"]
    out.update(median_rhs_error_true_AU=rt["all"]["median"], median_rhs_error_true_AU_active=rt["active"]["median"],
               q90_rhs_error_true_AU_active=rt["active"]["q90"], rhs_true_AU_active_share=rt["active_share"],
               energy_rhs_error_true_AU=rt["energy"])
    if v["rhs"] is not None:
        out.update(median_rhs_rel_error=v["rhs"]["all"]["median"],
                   median_rhs_rel_error_active=v["rhs"]["active"]["median"],
                   q90_rhs_rel_error_active=v["rhs"]["active"]["q90"],
                   rhs_active_share=v["rhs"]["active_share"])
    if v["support"] is not None:
        s = v["support"]["all"]
        out["support_mean_terms_per_model"] = s["mean_terms_per_model"]
        for level in ("terms", "pooled_terms", "orders"):
            out[f"support_precision_{level}"] = s[level]["precision"]
            out[f"support_recall_{level}"] = s[level]["recall"]
            out[f"support_precision_{level}_dense_model"] = s[level]["precision_dense_model"]
        for i in range(4):
            out[f"order_recall_A{i}"] = s["order_recall"][i]
    if v.get("campaign_model") is not None:
        pg = v["campaign_model"]["regime"]["groups"]
        out.update(campaign_model_regime_coverage=v["campaign_model"]["regime"]["coverage"],
                   campaign_model_regime_accuracy_identifiable=pg["identifiable"]["accuracy"],
                   campaign_model_regime_accuracy_not_identifiable=pg["not_identifiable"]["accuracy"],
                   campaign_model_regime_accuracy_all=pg["all"]["accuracy"])
        if v["campaign_model"]["rhs"] is not None:
            out["campaign_model_median_rhs_rel_error_active"] = v["campaign_model"]["rhs"]["active"]["median"]
        prt = v["campaign_model"]["rhs_true_AU"]
        out.update(campaign_model_median_rhs_error_true_AU=prt["all"]["median"],
                   campaign_model_median_rhs_error_true_AU_active=prt["active"]["median"],
                   campaign_model_energy_rhs_error_true_AU=prt["energy"])
        ch = v["campaign_model"].get("changes")
        if ch is not None:
            for key, sc in ch["flags"].items():
                name = key.removeprefix("event_")
                out.update({f"campaign_model_{name}_hits": sc["hits"], f"campaign_model_{name}_false_alarms": sc["false_alarms"]})
            out["campaign_model_changed_events"] = len(ch["changed_events"])
        c = v["campaign_model"]["curves"]
        out["campaign_model_curve_error_energy"] = c.get("energy", math.nan)
        if c.get("scored"):
            out.update(campaign_model_curve_error_linear=c["reference"]["linear"], campaign_model_curve_error_total=c["reference"]["total"])
    for row in v["clusters"] or []:
        tag = f"{row['feature_set']}{'_no_halo' if row['halo_ignored'] else ''}"
        out[f"ari_{tag}"] = row["ari"]
        out[f"purity_{tag}"] = row["purity"]
        out[f"n_clusters_{tag}"] = row["n_clusters"]
    for row in v["forecast"] or []:
        tag = f"d{row['d_s']:g}s"
        out[f"forecast_median_nmse_{tag}"] = row["median"]
        out[f"forecast_stopped_share_{tag}"] = row["stopped_share"]
    return out


def upgrade_metrics(metrics: dict | None) -> dict | None:
    """A ``metrics.json`` of :func:`write_validation` in the current names, whatever version wrote it.

    Earlier versions named the campaign model's part ``pooled``, its summary
    keys ``pooled_*`` and its regime-confusion groups ``pooled_*``; they are
    renamed ``campaign_model``, ``campaign_model_*``. Current metrics come
    back unchanged (a new dict); None stays None.

    Parameters
    ----------
    metrics : dict or None
        As read from ``metrics.json`` (or returned by :func:`validate_campaign`).

    Returns
    -------
    dict or None
    """
    if metrics is None:
        return None

    def renamed(key):
        return "campaign_model_" + key.removeprefix("pooled_") if key.startswith("pooled_") else key

    out = {("campaign_model" if k == "pooled" else k): v for k, v in metrics.items()}
    if isinstance(out.get("summary"), dict):
        out["summary"] = {renamed(k): v for k, v in out["summary"].items()}
    if isinstance(out.get("regime_confusion"), list):
        out["regime_confusion"] = [{**r, "group": renamed(r["group"])} if isinstance(r, dict) and "group" in r else r
                                   for r in out["regime_confusion"]]
    return out


def _json_safe(obj):
    """NaN and infinities become null (strict JSON); numpy scalars become Python numbers."""
    if isinstance(obj, dict):
        return {str(k): _json_safe(x) for k, x in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_json_safe(x) for x in obj]
    if isinstance(obj, (np.integer, np.bool_)):
        return obj.item()
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    return obj


def _csv_text(rows: list[dict]) -> str:
    buf = io.StringIO()
    if rows:
        fields = list(rows[0])
        for r in rows[1:]:
            fields += [k for k in r if k not in fields]
        w = csv.DictWriter(buf, fieldnames=fields, lineterminator="\n")
        w.writeheader()
        for r in rows:
            w.writerow({k: _fmt(r.get(k, "")) for k in fields})
    return buf.getvalue()


def _fmt(x):
    if isinstance(x, (float, np.floating)):
        return "nan" if not math.isfinite(x) else repr(float(x))
    return x


def write_validation(v: dict, out_dir) -> list[Path]:
    """Write :func:`validate_campaign`'s tables atomically.

    Files: ``regime_confusion.csv``, ``per_event.csv``, ``support.csv``,
    ``clusters.csv`` (when cluster labels were given), ``forecast_nmse.csv``
    (when forecast tables were given), ``metrics.json``
    (everything, NaN as null) and ``summary.json`` (flat headline numbers).

    Returns
    -------
    list of pathlib.Path, the files written
    """
    from vivbench.io.netcdf import atomic_path

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    texts = {"regime_confusion.csv": _csv_text(v["regime_confusion"]), "per_event.csv": _csv_text(v["per_event"]),
             "support.csv": _csv_text(v["support_table"])}
    if v["clusters"] is not None:
        texts["clusters.csv"] = _csv_text(v["clusters"])
    if v["forecast"] is not None:
        texts["forecast_nmse.csv"] = _csv_text(v["forecast"])
    texts["metrics.json"] = json.dumps(_json_safe(v), indent=2, sort_keys=True) + "\n"
    texts["summary.json"] = json.dumps(_json_safe(v["summary"]), indent=2) + "\n"
    written = []
    for name, text in texts.items():
        path = out_dir / name
        with atomic_path(path) as tmp:
            tmp.write_text(text)
        written.append(path)
    return written
