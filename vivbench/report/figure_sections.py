"""The report's figure sections: the paper's figures of the featured events and those of the campaign model.

Each figure is made by a function of :mod:`vivbench.report.figures` into the
report's directory and shown with its caption and the command that
reproduces it; a figure the data do not allow is reported as not made.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from urllib.parse import quote

import numpy as np

from vivbench.analysis.pool import campaign_model_file, load_campaign_model, campaign_wind_smoothing
from vivbench.core.errors import InputError
from vivbench.core.regime import DEFAULT_TAU
from vivbench.core.terms import reference_section, section_exponents
from vivbench.io.campaign_model import MODEL_NAME, read_campaign_regimes, regimes_file
from vivbench.io.result import result_record
from vivbench.models.model_input import measured_input
from vivbench.models.protocol import model_curves, model_description
from vivbench.regimes.model import model_window_regimes
from vivbench.report.tables import produced_by

__all__ = ["ReportFigures", "paper_figures", "campaign_model_figures"]

_MAX_CLUSTER_POINTS = 3000


class ReportFigures:
    """Makes the report's figures and appends their Markdown.

    Parameters
    ----------
    md : list of str
        The report's lines, appended to.
    written : list of str
        Names of the PNGs written into ``out_dir``, appended to.
    out_dir : Path
        The report's directory.
    command : str
        The command that reproduces the report (shown under each figure).
    say : callable
        Called with each figure's file name once it is written.
    """

    def __init__(self, *, md: list[str], written: list[str], out_dir: Path, command: str,
                 say: Callable[[str], None]):
        self.md, self.written, self.out_dir, self.command, self.say = md, written, Path(out_dir), command, say

    def add(self, fname: str, title: str, caption: str, make: Callable[[Path], object], func: str) -> None:
        """Make ``out_dir / fname`` by ``make(path)`` and show it under ``title`` (or say why it was not made).

        ``func`` names the :mod:`vivbench.report` function that draws it.
        """
        md = self.md
        md.append(f"### {title}")
        md.append("")
        try:
            make(self.out_dir / fname)
        except (ValueError, np.linalg.LinAlgError) as exc:
            md.append(f"**Figure not made:** {' '.join(str(exc).split())}")
            md.append("")
            return
        self.written.append(fname)
        md.append(f"![{title}]({quote(fname)})")
        md.append("")
        md.append(caption)
        md.append("")
        md.append(produced_by(self.command, f"(`vivbench.report.{func}`)"))
        md.append("")
        self.say(fname)


def paper_figures(fig: ReportFigures, info: Sequence[dict], events: Sequence[str], trees: Mapping,
                  results: Mapping, has_truth: bool) -> list | None:
    """The section "Figures": the paper's Figs. 1-12 for the featured events, with the event overview.

    Parameters
    ----------
    fig : ReportFigures
    info : sequence of dict
        Per event: ``event_id``, ``res`` (its identification result) and ``truth`` (its ``/truth`` or None).
    events : sequence of str
        Featured events; the first is shown in the single-event figures.
    trees : mapping event id -> xarray.DataTree
        The featured events.
    results : mapping event id -> xarray.Dataset
        Identification results of every event.
    has_truth : bool
        Every event has a truth.

    Returns
    -------
    list of ndarray or None
        The true window regimes of the featured events (None without truth), for the campaign model's timeline.
    """
    from vivbench.report import figures as F
    from vivbench.report.event_figure import event_figure

    e0 = events[0]
    tree0, res0 = trees[e0], results[e0]
    # Any number of sections: captions name them; single-section panels show the middle one (S2 of three).
    sec_names = [str(s) for s in res0["equation"].values.tolist()]
    n_sec = len(sec_names)
    ref_name = sec_names[reference_section(n_sec)]
    n_feat = section_exponents().shape[0] * n_sec
    the_sections = "the section" if n_sec == 1 else f"the {F.count_word(n_sec)} sections"
    fig.md += ["## Figures", "",
           f"Single-event figures show event {e0}"
           + (f"; the regime timeline shows {', '.join(events)}." if len(events) > 1 else "."), ""]
    fig.add("fig00_event.png", f"Event {e0}: overview",
            "Wind perpendicular to the span (grey) and the true mean wind (black), the deck acceleration, the true "
            "amplitude and the true regime over time (synthetic events only have the last two). Look for the "
            "amplitude growing while the wind is in the lock-in band and decaying after it leaves.",
            lambda p: event_figure(tree0, p), "event_figure")
    fig.add("fig01_sensor_layout.png", "Fig. 1: sensor layout and mode shape",
            f"Paper Fig. 1 and Fig. 3(a). {_layout_phrase(sec_names)} of the main span, each with one "
            "3-D anemometer and one vertical accelerometer. The mode shape values are those of the generator "
            f"configuration stored in the event (only "
            + ("the section value enters" if n_sec == 1 else f"the {F.count_word(n_sec)} section values enter")
            + " the model; the dashed line "
            "between them is a guide)."
            + (f" Sections in phase with phi({sec_names[0]}) = phi({sec_names[-1]}) give identical amplitudes at "
               f"{sec_names[0]} and {sec_names[-1]} in the figures below." if n_sec > 1 else ""),
            lambda p: F.sensor_layout_figure(tree0, p), "sensor_layout_figure")
    fig.add("fig02_wind.png", "Fig. 2: wind preprocessing",
            "Paper Fig. 2. (a) the measured components; (b) horizontal speed V and direction theta, with the two "
            "directions perpendicular to the span dashed; (c) the perpendicular component U~ = V |sin(theta - "
            "azimuth)| and its zero-phase low-pass U, the mean wind used by the identification. On synthetic events "
            "the true mean wind is dashed red: U should lie on it except near the ends of the record, which the "
            "identification drops.",
            lambda p: F.wind_figure(tree0, p), "wind_figure")
    fig.add("fig03_time_frequency.png", "Fig. 3: time-frequency analysis of the acceleration",
            "Paper Fig. 3(b, c), with a short-time Fourier spectrogram instead of the paper's wavelet transform. "
            f"The energy should stay at the modal frequency ({float(res0.attrs['f_mode_hz']):.4f} Hz found from the "
            "Welch spectrum, dashed) while the amplitude changes: the frequency does not shift, so only the "
            "amplitude A(t) needs a model.",
            lambda p: F.time_frequency_figure(tree0, p, f_mode=float(res0.attrs["f_mode_hz"])),
            "time_frequency_figure")
    fig.add("fig04_displacement.png", "Fig. 4: displacement, envelope and derivative",
            "Paper Fig. 4. (a) displacement from band-limited frequency-domain integration of the acceleration, "
            "and its Hilbert envelope A; the shaded edges are dropped by the identification. (b) A at "
            f"{the_sections} on the identification grid; (c) dA/dt by the configured differentiation. Dashed lines are "
            "the truth of the averaged model (synthetic events): compare A and dA/dt with them.",
            lambda p: F.displacement_figure(tree0, res0, p), "displacement_figure")
    fig.add("fig05_coefficients.png", "Fig. 5-7: the time-varying model of an event",
            f"Paper Figs. 5(c) and 7. (a) each column is one window's model of dA/dt at {ref_name}, each row one of the {n_feat} "
            "library terms A_l^i U_l^j. Colour: coefficient times the RMS of its library term over the event "
            "(m/s, the size of that term's contribution to dA/dt), on a symmetric log scale, linear below 1 % of "
            "the RMS of dA/dt. Contributions many decades larger than dA/dt itself that change sign between "
            "neighbouring terms cancel each other: they are the near-collinear library columns inside a 50 s "
            "window, not physics. (b) the window's regime, hatched where it is not identifiable. (c, d) the mean "
            "wind against the generator's default lock-in range and the amplitudes.",
            lambda p: F.coefficient_map_figure(res0, p), "coefficient_map_figure")

    timeline_truth = None
    if has_truth:
        from vivbench.regimes.truth import truth_window_regimes

        timeline_truth = [truth_window_regimes(trees[e]["truth"].ds, results[e]["window_start"].values,
                                               results[e]["window_end"].values,
                                               tau=json.loads(results[e].attrs["identify_config_json"])["tau"])
                          for e in events]
    fig.add("fig06_regimes.png", "Fig. 6: regimes of three events against the truth",
            f"Paper Fig. 6 and Table 1. For each event, the regime of the selected window model of dA/dt at {ref_name} "
            "(top row; hatched: not identifiable, i.e. an equally good sparse model has another regime) and the "
            "true regime of the same window by the same rule (bottom row). The titles give the share of "
            "identifiable windows and the agreement with the truth; agreement on unflagged windows is not a "
            "finding (see the recovery tables for the chance level).",
            lambda p: F.regime_timeline_figure([results[e] for e in events],
                                               timeline_truth or [None] * len(events), p),
            "regime_timeline_figure")

    cluster_inputs = _cluster_inputs(info, with_truth=has_truth)
    for kind, label in (("coef", f"standardised coefficients ({n_sec * n_feat} per window)"),
                        ("order", f"shares of the order contributions ({4 * n_sec} per window)")):
        fig.add(f"fig08_decision_graph_{kind}.png", f"Fig. 8-10: decision graph and clusters ({kind} features)",
                "Paper Figs. 8-10. Density-peaks clustering (Rodriguez and Laio 2014; "
                "`vivbench.analysis.DensityPeaks` with its defaults) of the window models of all events, one point "
                f"per window, features: {label}. (a) decision graph: centres are points with both a high density "
                "and a large distance to any denser point; (b) the clusters on the first two principal components; "
                f"(c) how each cluster's windows split between the true regimes (of {ref_name}) - a cluster that matches a "
                "regime has one dark cell. "
                + cluster_inputs.get("note", ""),
                lambda p, kind=kind: _cluster_figure(cluster_inputs, kind, p),
                "decision_graph_figure")

    fig.add("fig11_forecast.png", "Fig. 11-12: simulation and forecasts",
            "Paper Figs. 11-12. (a) the whole event simulated with the time-varying window models from the measured "
            "A at the first window and the measured wind, against the measured A; (b) forecasts from t0 with "
            "coefficients fixed at t0 or averaged over the windows starting in [t0, t0 + d]. NMSE (0: perfect, "
            "1: as good as the mean) is over the valid part of each run; a run whose A left the plausible range "
            "(non-finite, above 10x the largest measured A, or below -5 % of it) is stopped, drawn only up to "
            "there and marked x.",
            lambda p: F.forecast_figure(res0, p), "forecast_figure")
    return timeline_truth


def campaign_model_figures(fig: ReportFigures, results_dir: Path, events: Sequence[str], trees: Mapping,
                           results: Mapping, timeline_truth: list | None) -> None:
    """The section on the campaign model of ``vivbench pool`` (nothing when ``results_dir`` holds none).

    Its description, its regimes of the featured events (Fig. 6b), its coefficient curves against the
    truth and its simulation and forecast of the first featured event (Fig. 11b); arguments as
    :func:`paper_figures`, whose return value is ``timeline_truth``.
    """
    from vivbench.report import figures as F

    e0 = events[0]
    tree0, res0 = trees[e0], results[e0]
    sec_names = [str(s) for s in res0["equation"].values.tolist()]
    ref_name = sec_names[reference_section(len(sec_names))]
    pooled_path = regimes_file(results_dir)
    if not pooled_path.is_file():
        return
    # The campaign model through the model protocol (campaign.model.nc, or rebuilt from the pooled
    # result's coef for older outputs); the windows' identifiability verdicts from the campaign regimes.
    pooled = read_campaign_regimes(pooled_path)
    model_path = campaign_model_file(results_dir)
    model = load_campaign_model(model_path)
    smoothing = campaign_wind_smoothing(pooled)  # the measured wind as at fit (vivbench.models.measured_input)
    described = model_description(model, pooled)  # the model's own account of itself and its verdict
    fig.md += ["## The campaign model (`vivbench pool`)", "", described["text"], "",
               f"Model file: `{model_path.name}`"
               + ("" if model_path.name == MODEL_NAME else
                  " (no campaign.model.nc: the model is rebuilt from the regimes file's coefficients)") + ".", "",
               produced_by(f"vivbench pool {results_dir}" + described["pool_options"]), ""]
    ev_of = pooled["event_id"].values.astype(str)
    pres = []
    for e in events:
        r = results[e].copy()
        sel = ev_of == e
        start, end = r["window_start"].values, r["window_end"].values
        if sel.sum() != start.size or not np.array_equal(pooled["window_start"].values[sel], start):
            raise InputError(f"{pooled_path}: its windows of {e} differ from the result's; re-run vivbench pool")
        reg = model_window_regimes(model, measured_input(model, result_record(r), wind_smoothing_s=smoothing),
                                   start, end, tau=float(getattr(model, "tau", DEFAULT_TAU)))
        r["regime"] = (r["regime"].dims, reg["regime"])
        r["identifiable"] = (r["identifiable"].dims, pooled["identifiable"].values[sel])
        pres.append(r)
    fig.add("fig06b_regimes_campaign_model.png", "Fig. 6b: regimes of the campaign model against the truth",
            "As Fig. 6, with the regimes of the campaign model (hatched: not identifiable by the confidence-region "
            "and bootstrap tests) instead of the window models'.",
            lambda p: F.regime_timeline_figure(pres, timeline_truth or [None] * len(events), p),
            "regime_timeline_figure")
    curves_ds = _campaign_curves(pooled, model, results)
    if curves_ds is not None:
        from vivbench.validate.campaign import event_truth_curves

        truth0 = event_truth_curves(tree0["truth"].ds) if "truth" in tree0.children else None
        structure = (_generator_config_of(tree0) or {}).get("structure", {})
        f_struct, d_struct = structure.get("frequency"), structure.get("depth")
        fig.add("fig12_curves.png", "Coefficient curves of the campaign model against the truth",
                f"docs/concepts.md (coefficient curves). The coefficients a_i(U) of dA/dt = sum_i a_i(U) A^i at {ref_name} when every section "
                "sees the mean wind U (the other sections folded in through the mode's amplitude ratios), drawn "
                "like aerodynamic derivatives: (a) order 0, the locked shedding force; (b) order 1, the net "
                "linear coefficient (positive: negative net damping, self-excitation); (c, d) the amplitude "
                "limiting orders. Black: the truth of the generator (`/truth/curves`"
                + ("" if truth0 is not None else ", not available for this campaign") + "); dashed: the campaign "
                "model over its data's wind range, shaded: its 95 % block-bootstrap band (widened to contain the "
                "model); grey dotted: where the curve lies outside the winds of the equation's fitted data "
                "(`curves_extrapolated`), an extrapolation of the model, not a finding."
                + (" The top axis gives the reduced velocity U/(f D) with the generator's f and D."
                   if f_struct and d_struct else ""),
                lambda p: F.curves_figure(curves_ds, p, truth=truth0, frequency=f_struct, depth=d_struct),
                "curves_figure")
    starts0 = res0["window_start"].values
    span0 = (float(starts0.min()), float(res0["window_end"].values.max()))
    t0_cm = float(starts0[np.argmin(np.abs(starts0 - (span0[0] + 0.4 * (span0[1] - span0[0]))))])
    fig.add("fig11b_forecast_campaign_model.png", "Fig. 11b: simulation and forecast with the campaign model",
            "As Fig. 11, with the campaign model (`model.simulate(record, t0, t1)`) over the span of the "
            "windows and from the same t0: one fixed model, so there is one forecast (d plays no role).",
            lambda p: F.model_forecast_figure(model, measured_input(model, result_record(res0),
                                                                    wind_smoothing_s=smoothing), p, t0=t0_cm, span=span0,
                                              name="campaign model"),
            "model_forecast_figure")


def _layout_phrase(names: Sequence[str]) -> str:
    """'Sections S1, S2, S3 at 1/4, 1/2 and 3/4': section k of n sits at k / (n + 1) of the span."""
    from fractions import Fraction

    n = len(names)
    where = [str(Fraction(k, n + 1)) for k in range(1, n + 1)]
    if n == 1:
        return f"Section {names[0]} at {where[0]}"
    return f"Sections {', '.join(names)} at {', '.join(where[:-1])} and {where[-1]}"


# ------------------------------------------------------------------- clusters


def _cluster_inputs(info: Sequence[dict], *, with_truth: bool) -> dict:
    """Window features, true regimes (middle section, S2 of three) and a deterministic subsample for the decision graphs."""
    from vivbench.regimes.truth import truth_window_regimes

    coefs, orders, truths = [], [], []
    for item in info:
        res = item["res"]
        coef = res["coef"].values
        fitted = np.all(np.isfinite(coef), axis=(1, 2))
        coefs.append(coef[fitted])
        orders.append(res["order_rms"].values[fitted])
        if with_truth:
            truth = item["truth"]
            tau = json.loads(res.attrs["identify_config_json"])["tau"]
            tw = truth_window_regimes(truth, res["window_start"].values, res["window_end"].values, tau=tau)
            names = [str(s) for s in res["equation"].values.tolist()]
            truths.append(tw[fitted, reference_section(len(names))])
    coef = np.concatenate(coefs)
    order = np.concatenate(orders)
    truth = np.concatenate(truths) if truths else None
    n = coef.shape[0]
    note = ""
    keep = np.arange(n)
    if n > _MAX_CLUSTER_POINTS:
        # Memory of density peaks is O(n^2): an evenly spaced subsample keeps it bounded.
        keep = np.unique(np.linspace(0, n - 1, _MAX_CLUSTER_POINTS).round().astype(int))
        note = f"Every {n / keep.size:.1f}-th window is used ({keep.size} of {n}) to bound the O(n^2) memory."
    return {"coef": coef[keep], "order": order[keep], "truth": None if truth is None else truth[keep], "note": note}


def _cluster_figure(inputs: dict, kind: str, path: Path) -> None:
    from sklearn.decomposition import PCA

    from vivbench.analysis.clustering import DensityPeaks, coefficient_features, order_features
    from vivbench.report.figures import decision_graph_figure

    X = coefficient_features(inputs["coef"]) if kind == "coef" else order_features(inputs["order"])
    if X.shape[0] < 3 or X.shape[1] < 2:
        raise InputError(f"too few windows or varying features to cluster ({X.shape[0]} windows, {X.shape[1]} features)")
    dp = DensityPeaks().fit(X)
    emb = PCA(n_components=2, svd_solver="full").fit_transform(X)
    decision_graph_figure(dp.rho_, dp.delta_, dp.labels_, dp.centers_, path, embedding=emb, truth=inputs["truth"],
                          title=f"{X.shape[0]} windows, {X.shape[1]} {kind} features, d_c = {dp.dc_:.3g}")


def _generator_config_of(tree) -> dict | None:
    """The generator configuration stored in an event's ``/truth`` (None for field data)."""
    if "truth" not in tree.children or "config_json" not in tree["truth"].attrs:
        return None
    cfg = json.loads(tree["truth"].attrs["config_json"])
    return cfg.get("generator", cfg)


def _campaign_curves(pooled, model, results):
    """The campaign model's curves: those of ``campaign.regimes.nc``, or drawn by the model; None if it has none."""
    if "curves" in pooled.data_vars:
        return pooled
    from vivbench.analysis.pool import curve_wind_grid

    return model_curves(model, curve_wind_grid(np.concatenate([r["U"].values.ravel() for r in results.values()])))
