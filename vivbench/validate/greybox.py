"""The grey-box refit against the truth: curves, net linear growth rate, Y1, bands, regimes, NMSE.

Validation may read an event's ``/truth`` (the fit never does). The truth's
coefficient curves (docs/concepts.md (coefficient curves), ``/truth/curves`` or rebuilt from the
generator configuration) and its aerodynamic function Y1 (from the
configuration, at yaw 0) are compared with the grey-box model's over the
lock-in range: the winds of the truth samples in a self-excited regime (2..4).
Scores (relative RMS errors, band coverage) are those of
:func:`vivbench.validate.curve_errors` on the reference section, so the
campaign model's numbers (``vivbench validate``) compare one to one.

The truth's curves and Y1 are at yaw 0, as are the grey-box curves (its yaw
factor is 1 there); a grey-box model fitted without the measured yaw
averages a truth whose Y1 and C_L fall with yaw over the events' yaw angles.
The dynamics on the true (A, U) are evaluated at the records' measured yaw
(when given), as the truth's are at its own.
"""

from __future__ import annotations

import json
from collections.abc import Sequence

import numpy as np

from vivbench.core.terms import reference_section
from vivbench.models.greybox import GreyBoxRefit
from vivbench.regimes.truth import truth_window_regimes
from vivbench.models.curve_support import curves_inside_data, data_wind_range
from vivbench.validate.metrics import curve_energy_error, curve_errors, curves_rhs, energy_relative_error
from vivbench.validate.recovery import finite_median, model_window_rhs_true_AU, record_yaw_on, regime_scores

__all__ = ["greybox_recovery", "truth_y1", "truth_yaw_factor"]


def truth_y1(truth, wind: np.ndarray) -> np.ndarray | None:
    """The generator's Y1 at winds ``wind`` (yaw 0) from an event's ``config_json``; None if not readable."""
    from vivbench.synth import config_from_dict

    try:
        meta = json.loads(truth.attrs["config_json"])
        config = config_from_dict(meta["generator"])
    except (KeyError, TypeError, ValueError):
        return None
    s = config.structure
    return np.asarray(config.aero.Y1.at_wind(np.asarray(wind, dtype=float), s.frequency, s.depth), dtype=float)


def truth_yaw_factor(truth, yaw_deg: np.ndarray) -> np.ndarray | None:
    """The generator's factor on Y1 at yaw angles ``yaw_deg`` (degrees); 1 without one; None if not readable."""
    from vivbench.synth import config_from_dict

    try:
        config = config_from_dict(json.loads(truth.attrs["config_json"])["generator"])
    except (KeyError, TypeError, ValueError):
        return None
    yaw_deg = np.asarray(yaw_deg, dtype=float)
    f = config.aero.yaw
    if f is None or "Y1" not in f.applies_to:
        return np.ones_like(yaw_deg)
    return np.asarray(f(yaw_deg), dtype=float)


def _coverage(lower, upper, truth) -> float:
    ok = np.isfinite(truth) & np.isfinite(lower) & np.isfinite(upper)
    return float(np.mean((truth[ok] >= lower[ok]) & (truth[ok] <= upper[ok]))) if ok.any() else float("nan")


def _rel_rms(x, ref) -> float:
    ok = np.isfinite(x) & np.isfinite(ref)
    if not ok.any():
        return float("nan")
    return float(np.sqrt(np.mean((x[ok] - ref[ok]) ** 2)) / np.sqrt(np.mean(ref[ok] ** 2)))


def greybox_recovery(model: GreyBoxRefit, event_files: Sequence, windows, events: Sequence[dict], *,
                     campaign_curves=None, tau: float = 0.2, active_share: float = 0.1, records=None) -> dict:
    """Score a fitted grey-box model against the truth of a synthetic campaign.

    Parameters
    ----------
    model : GreyBoxRefit, fitted on the campaign's results
    event_files : the synthetic event files (with ``/truth``)
    windows : xarray.Dataset of :func:`vivbench.analysis.greybox_results` (regimes, verdicts)
    events : its per-event rows (``event_id``, ``nmse``)
    campaign_curves : xarray.Dataset or None
        Curves (docs/concepts.md (coefficient curves)) of another campaign-level model (the campaign
        model) scored the same way, for comparison.
    tau : regime threshold of the truth's window regimes
    active_share : see :func:`vivbench.validate.model_window_rhs_errors_true_AU`
    records : sequence of Record or None
        The fitted records: their measured yaw (``Record.yaw``), put on the
        truth's grid, is the yaw of the model's dA/dt on the true (A, U).

    Returns
    -------
    dict
        ``curves`` (per-equation :func:`curve_errors` and the reference
        section's ``linear``, ``total``, ``linear_band_coverage`` and
        ``lock_in_wind``; ``energy``: :func:`curve_energy_error` over every
        sample and equation against the truth's curves; with ``records``
        every curve score leaves out the winds outside the fitted data),
        ``y1`` (relative RMS error and band coverage of Y1
        over the lock-in range; NaN when the truth's Y1 is not readable),
        ``regime`` (:func:`regime_scores` plus ``precision_identifiable``: share
        of flagged windows with the true regime), ``rhs_error_true_AU_median``
        (and ``_active``; ``rhs_error_true_AU_energy``: the same error
        energy-weighted over every truth sample), ``nmse_median``, ``campaign_curves`` (the same
        scores for ``campaign_curves``, or None), ``summary`` (flat numbers).
    """
    from vivbench.io.event import read_event
    from vivbench.validate.campaign import event_truth_curves

    truths = {}
    for path in event_files:
        tree = read_event(path)
        truths[str(tree.attrs["event_id"])] = tree["truth"].ds
    event_of = windows["event_id"].values.astype(str)
    U, A, excited, regimes, truth_reg, flags, errs, errs_act = [], [], [], [], [], [], [], []
    f_model_all, f_true_all = [], []
    truth_curves = None
    by_id = {r.event_id: r for r in (records or [])}
    for event_id in dict.fromkeys(event_of):
        if event_id not in truths:
            continue
        truth = truths[event_id]
        if truth_curves is None:
            truth_curves = event_truth_curves(truth)
        sel = event_of == event_id
        start, end = windows["window_start"].values[sel], windows["window_end"].values[sel]
        regimes.append(windows["regime"].values[sel])
        flags.append(windows["identifiable"].values[sel])
        truth_reg.append(truth_window_regimes(truth, start, end, tau=tau))
        U.append(truth["U"].values)
        A.append(truth["A"].values)
        excited.append(truth["regime"].values >= 2)
        rec = by_id.get(event_id)
        yaw = None if rec is None else record_yaw_on(rec, truth["time"].values)
        e, act, f_model, f_true = model_window_rhs_true_AU(model, truth, start, end, event_id=event_id,
                                                           active_share=active_share, yaw=yaw)
        f_model_all.append(f_model.ravel())
        f_true_all.append(f_true.ravel())
        errs.append(e.ravel())
        errs_act.append(np.where(act, e, np.nan).ravel())
    out: dict = {"n_events_scored": len(U)}
    k = reference_section(model.n_sections_)
    cur = model.curves()
    wind = cur["wind"].values
    # Curves scored only inside the fitted data's winds, when the fitted records are given.
    wind_range = data_wind_range(records) if records else None
    if truth_curves is not None and U:
        tc, tw = truth_curves
        Uc, Ac, Xc = np.concatenate(U), np.concatenate(A), np.concatenate(excited)
        f_ref = curves_rhs(tc, tw, Uc, Ac)
        err = curve_errors(curves_inside_data(cur, wind_range), wind, tc, tw, Uc, Ac, Xc)
        lock = err["lock_in_wind"][k]
        g = (wind >= lock[0]) & (wind <= lock[1]) if lock else np.zeros(wind.size, dtype=bool)
        a_true = np.interp(wind, tw, tc[k, 1], left=np.nan, right=np.nan)
        cov_lin = _coverage(cur["curves_lower"].values[k, 1, g], cur["curves_upper"].values[k, 1, g], a_true[g])
        out["curves"] = {**err, "reference_equation": f"S{k + 1}", "linear": err["linear"][k],
                         "total": err["total"][k], "linear_band_coverage": cov_lin, "lock_in_wind": lock,
                         "energy": curve_energy_error(cur["curves"].values, wind, Uc, Ac, f_ref, wind_range)}
        phys = model.physical_curves(wind)
        y1_true = truth_y1(next(iter(truths.values())), wind)
        if y1_true is not None and g.any():
            out["y1"] = {"error": _rel_rms(phys["Y1"].values[g], y1_true[g]),
                         "band_coverage": _coverage(phys["Y1_lower"].values[g], phys["Y1_upper"].values[g],
                                                    y1_true[g])}
        else:
            out["y1"] = {"error": float("nan"), "band_coverage": float("nan")}
        if campaign_curves is not None:
            cw = campaign_curves["wind"].values
            e2 = curve_errors(curves_inside_data(campaign_curves, wind_range), cw, tc, tw, Uc, Ac, Xc)
            g2 = (cw >= lock[0]) & (cw <= lock[1]) if lock else np.zeros(cw.size, dtype=bool)
            a2 = np.interp(cw, tw, tc[k, 1], left=np.nan, right=np.nan)
            cov2 = (_coverage(campaign_curves["curves_lower"].values[k, 1, g2],
                              campaign_curves["curves_upper"].values[k, 1, g2], a2[g2])
                    if "curves_lower" in campaign_curves else float("nan"))
            out["campaign_curves"] = {"linear": e2["linear"][k], "total": e2["total"][k],
                                      "linear_band_coverage": cov2,
                                      "energy": curve_energy_error(campaign_curves["curves"].values, cw, Uc, Ac, f_ref,
                                                                   wind_range)}
        else:
            out["campaign_curves"] = None
    else:
        out["curves"] = None
        out["y1"] = {"error": float("nan"), "band_coverage": float("nan")}
        out["campaign_curves"] = None
    if regimes:
        ident, tr, fl = np.concatenate(regimes), np.concatenate(truth_reg), np.concatenate(flags).astype(bool)
        sc = regime_scores(ident, tr, fl)
        m = fl & (tr > 0) & (ident > 0)
        sc["precision_identifiable"] = float(np.mean(ident[m] == tr[m])) if m.any() else float("nan")
        sc["n_identifiable"] = int(m.sum())
        out["regime"] = sc
    else:
        out["regime"] = None
    out["rhs_error_true_AU_median"] = finite_median(np.concatenate(errs)) if errs else float("nan")
    out["rhs_error_true_AU_median_active"] = finite_median(np.concatenate(errs_act)) if errs_act else float("nan")
    out["rhs_error_true_AU_energy"] = (energy_relative_error(np.concatenate(f_model_all), np.concatenate(f_true_all))
                                       if f_model_all else float("nan"))
    nm = np.array([row["nmse"] for row in events], dtype=float)
    out["nmse_median"] = finite_median(nm)
    c = out["curves"] or {}
    summary = {
        "curve_error_linear": c.get("linear", float("nan")), "curve_error_total": c.get("total", float("nan")),
        "linear_band_coverage": c.get("linear_band_coverage", float("nan")),
        "y1_error": out["y1"]["error"], "y1_band_coverage": out["y1"]["band_coverage"],
        "nmse_median": out["nmse_median"], "rhs_error_true_AU_median_active": out["rhs_error_true_AU_median_active"],
        "rhs_error_true_AU_energy": out["rhs_error_true_AU_energy"],
        "curve_error_energy": c.get("energy", float("nan")),
    }
    if out["regime"] is not None:
        summary.update(regime_coverage=out["regime"]["coverage"],
                       regime_precision_identifiable=out["regime"]["precision_identifiable"],
                       regime_accuracy_all=out["regime"]["accuracy_all"])
    if out["campaign_curves"] is not None:
        summary.update(campaign_curve_error_linear=out["campaign_curves"]["linear"],
                       campaign_curve_error_total=out["campaign_curves"]["total"],
                       campaign_linear_band_coverage=out["campaign_curves"]["linear_band_coverage"],
                       campaign_curve_error_energy=out["campaign_curves"]["energy"])
    alternatives = model.band_alternatives() if out["curves"] is not None else {}
    if alternatives and g.any():
        # the same fit's bands with each covariance, to set them side by side
        half = 0.5 * (cur["curves_upper"].values[k, 1, g] - cur["curves_lower"].values[k, 1, g])
        for name, alt in alternatives.items():
            cs, ps = alt.curves(wind), alt.physical_curves(wind)
            half_s = 0.5 * (cs["curves_upper"].values[k, 1, g] - cs["curves_lower"].values[k, 1, g])
            summary[f"{name}_linear_band_coverage"] = _coverage(cs["curves_lower"].values[k, 1, g],
                                                                cs["curves_upper"].values[k, 1, g], a_true[g])
            summary[f"{name}_y1_band_coverage"] = (_coverage(ps["Y1_lower"].values[g], ps["Y1_upper"].values[g],
                                                             y1_true[g]) if y1_true is not None else float("nan"))
            summary[f"{name}_band_halfwidth_ratio"] = float(np.median(half_s / np.maximum(half, 1e-300)))
    out["summary"] = summary
    return out
