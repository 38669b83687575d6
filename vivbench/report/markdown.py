"""The Markdown report of a campaign: what was run, the paper's figures, recovery tables, other steps.

:func:`write_report` writes ``<out_root>/<name>/report.md`` and every figure it
links to into the same directory (relative links only, so a committed report
renders on GitHub). It is one call for the whole chain: give it the campaign,
its identification results and the output directories of the other steps
(``cluster``, ``forecast``, ``refit``, ``validate``, ``compare``, ``sweep``);
a step without a directory is listed as "not run".

Every number in the report comes from a file or a computation on files, and
under each table the report prints the command that produced it.
"""

from __future__ import annotations

import csv
import json
import re
import shutil
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from urllib.parse import quote

import numpy as np

import vivbench
from vivbench.io.campaign_model import MODEL_NAME, read_campaign_regimes, regimes_file
from vivbench.analysis.pool import campaign_model_file, load_campaign_model, campaign_wind_smoothing
from vivbench.models.model_input import measured_input
from vivbench.io.netcdf import atomic_path
from vivbench.regimes.model import model_window_regimes
from vivbench.io.event import list_events, read_event
from vivbench.core.regime import DEFAULT_TAU
from vivbench.core.steps import EXTRA_STEPS
from vivbench.core.terms import reference_section, section_exponents
from vivbench.io.event import read_event_summary
from vivbench.io.result import read_result, result_record
from vivbench.core.errors import InputError
from vivbench.report.leaderboard import leaderboard_section
from vivbench.report.sidebyside import CampaignRun, baseline_section, campaign_run

__all__ = ["EXTRA_STEPS", "write_report"]

# Canonical command of each step, used when its directory does not record the
# exact command (a ``command`` key in summary.json or a command.txt file).
_STEP_COMMANDS = {
    "cluster": "vivbench cluster {results} --out {dir}",
    "forecast": "vivbench forecast {results}/<event_id>.identify.nc --out {dir}",
    "refit": "vivbench refit {results}/<event_id>.identify.nc --out {dir}",
    "greybox": "vivbench greybox {results} --out {dir} --bridge <bridge.toml>",
    "validate": "vivbench validate {campaign} {results} --out {dir}",
    "compare": "vivbench compare --grid <grid.toml> --out {dir}",
    "sweep": "vivbench sweep --grid <grid.toml> --out {dir}",
}
_STEP_TITLES = {
    "cluster": "Clustering of the window models (`vivbench cluster`)",
    "forecast": "Simulation and forecasts (`vivbench forecast`)",
    "refit": "CasADi output-error refit (`vivbench refit`)",
    "greybox": "Grey-box reference refit (`vivbench greybox`)",
    "validate": "Validation tables (`vivbench validate`)",
    "compare": "Method comparison (`vivbench compare`)",
    "sweep": "Monte-Carlo sweep (`vivbench sweep`)",
}
_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*")
_MAX_CLUSTER_POINTS = 3000


# ------------------------------------------------------------------ formatting


def _fmt(x, digits: int = 3) -> str:
    if x is None:
        return "n/a"
    if isinstance(x, (bool, np.bool_)):
        return "yes" if x else "no"
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    if isinstance(x, (float, np.floating)):
        if not np.isfinite(x):
            return "n/a"
        if x == 0:
            return f"{0:.{digits}f}"
        return f"{x:.{digits}g}" if abs(x) < 1e-3 or abs(x) >= 1e4 else f"{x:.{digits}f}"
    return str(x)


def _cell(text) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def _table(header: Sequence[str], rows: Sequence[Sequence]) -> str:
    lines = ["| " + " | ".join(_cell(h) for h in header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(_cell(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def _produced_by(command: str, note: str = "") -> str:
    extra = f" {note}" if note else ""
    return f"*Produced by:* `{command}`{extra}"


# ------------------------------------------------------------------- the data


def _pairs(campaign_dir: Path, results_dir: Path) -> tuple[list[tuple[str, Path, Path]], list[str]]:
    """(event id, event file, result file) for events with a result; ids without one."""
    events = list_events(campaign_dir)
    if not events:
        raise InputError(f"{campaign_dir}: no event files (<event_id>.nc) in this directory")
    if not Path(results_dir).is_dir():
        raise InputError(f"{results_dir}: no such results directory")
    pairs, missing = [], []
    for ev in events:
        res = Path(results_dir) / f"{ev.stem}.identify.nc"
        (pairs.append((ev.stem, ev, res)) if res.exists() else missing.append(ev.stem))
    if not pairs:
        raise InputError(f"{results_dir}: no identification result (<event_id>.identify.nc) for the events of {campaign_dir}")
    return pairs, missing


def _event_info(eid: str, event_path: Path, result_path: Path) -> dict:
    """What the report needs of one event, read once: attributes, truth, duration, seed and the result.

    Only the small groups are loaded (the 32 Hz and 50 Hz records stay on disk).
    """
    summary = read_event_summary(event_path)
    truth = summary.truth
    seed = None
    if truth is not None and "config_json" in truth.attrs:
        seed = json.loads(truth.attrs["config_json"]).get("seed", {}).get("campaign_seed")
    return {"event_id": eid, "event": event_path, "result": result_path, "attrs": summary.attrs, "truth": truth,
            "duration": summary.duration_s, "seed": seed, "res": read_result(result_path)}


def _catalogue(campaign_dir: Path) -> dict[str, dict]:
    path = Path(campaign_dir) / "catalogue.csv"
    if not path.exists():
        return {}
    with open(path, newline="") as f:
        return {row["event_id"]: row for row in csv.DictReader(f)}


_FLOAT_TEXT = re.compile(r"[-+]?(\d+\.\d*|\.\d+|\d+)([eE][-+]?\d+)?")


def _short(cell: str) -> str:
    """A CSV cell for display: decimals with many digits to 4 significant digits; other text as is."""
    if _FLOAT_TEXT.fullmatch(cell) and ("." in cell or "e" in cell.lower()):
        digits = len(re.sub(r"[^0-9]", "", cell.split("e")[0].split("E")[0]).lstrip("0"))
        if digits > 4:
            return f"{float(cell):.4g}"
    return cell


def _read_csv(path: Path) -> tuple[list[str], list[list[str]]]:
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    if not rows:
        return [], []
    return rows[0], rows[1:]


# ------------------------------------------------------------------ the report


def write_report(name: str, campaign_dir, results_dir, *, out_root="reports",
                 extra_dirs: Mapping[str, Path | str | None] | None = None, events: Sequence[str] | None = None,
                 max_rows: int = 30, progress: Callable[[str], None] | None = None,
                 baseline: Path | str | CampaignRun | None = None) -> Path:
    """Write ``<out_root>/<name>/report.md`` with its figures.

    Parameters
    ----------
    name : str
        Report name (letters, digits, ``_ . -``); the report's directory.
    campaign_dir : path
        Campaign directory (``<event_id>.nc`` files and ``catalogue.csv``).
    results_dir : path
        Identification results (``<event_id>.identify.nc``) of those events.
    out_root : path
        Parent of the report directory.
    extra_dirs : mapping step -> directory, optional
        Output directories of the other steps (keys from :data:`EXTRA_STEPS`;
        others are embedded the same way). Each ``*.csv`` becomes a table (first
        ``max_rows`` rows), each ``*.png`` is copied beside report.md and shown,
        ``summary.json`` gives the headline numbers. A step without a directory,
        or whose directory does not exist, is listed as "not run".
    events : sequence of str, optional
        Event ids featured in the figures (the first one in the single-event
        figures, up to three in the regime timeline). Default: the first three
        events that have a result.
    max_rows : int
        Rows of each embedded CSV shown before the table is cut (the report says so).
    progress : callable, optional
        Called with a short label as each part is done.
    baseline : path or CampaignRun, optional
        A second run of the chain shown beside this one (normally ``vivbench demo
        --mode in_library --out DIR``: the same seed with the truth inside the
        model class), a directory holding ``campaign/`` and ``identify/`` and
        optionally ``cluster/``, ``forecast/``, ``validate/`` (or a
        :class:`vivbench.report.sidebyside.CampaignRun` naming them). Adds the section
        of :func:`vivbench.report.sidebyside.baseline_section` after the
        recovery tables. Without it the report is unchanged.

    Returns
    -------
    Path of report.md.

    Notes
    -----
    Figures are PNGs made by :mod:`vivbench.report.figures` (deterministic
    bytes); PNGs left in the report directory by an earlier run and not
    produced by this one are removed so that the directory holds only what
    report.md shows. report.md itself carries no date: the same inputs give
    the same report.
    """
    from vivbench.report import figures as F
    from vivbench.report.event_figure import event_figure

    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise InputError(f"report name {name!r} must be letters, digits, '_', '.' or '-' (it names a directory)")
    if not (isinstance(max_rows, int) and max_rows >= 1):
        raise InputError(f"max_rows must be a positive integer; got {max_rows!r}")
    campaign_dir, results_dir = Path(campaign_dir), Path(results_dir)
    extra_dirs = dict(extra_dirs or {})
    baseline_run = (baseline if isinstance(baseline, CampaignRun) or baseline is None
                    else campaign_run(baseline))
    unknown = sorted(set(extra_dirs) - set(EXTRA_STEPS))
    step_names = list(EXTRA_STEPS) + unknown
    pairs, missing = _pairs(campaign_dir, results_dir)
    by_id = {eid: (ev, res) for eid, ev, res in pairs}
    if events is None:
        events = [eid for eid, _, _ in pairs[:3]]
    else:
        events = [str(e) for e in events]
        bad = [e for e in events if e not in by_id]
        if not events or bad:
            raise InputError(f"events {bad or events} have no event file with a result in {campaign_dir} and "
                             f"{results_dir}; available: {sorted(by_id)}")
    out_dir = Path(out_root) / name
    out_dir.mkdir(parents=True, exist_ok=True)
    command = _report_command(name, campaign_dir, results_dir, Path(out_root), extra_dirs, baseline)
    say = progress or (lambda _label: None)

    info = [_event_info(eid, ev, res) for eid, ev, res in pairs]
    say("read")
    trees = {e: read_event(by_id[e][0]) for e in events}
    results = {i["event_id"]: i["res"] for i in info}
    has_truth = all(i["truth"] is not None for i in info)

    md: list[str] = [f"# vivbench report: {name}", ""]
    md += [
        "Reproduction of the time-varying SINDy chain of Li, Kaiser, Laima, Li, Brunton and Kutz, "
        "*Phys. Rev. E* 2019 (arXiv:1809.05707), on the campaign below, checked against its truth where the "
        "events are synthetic. Every figure and table below was produced from the files named here; the "
        "command under each reproduces it.",
        "",
        _produced_by(command, "(this whole report, its figures and the recovery tables)"),
        "",
    ]
    md += _what_was_run(campaign_dir, results_dir, info, missing, command)
    say("summary")

    written: list[str] = []

    def figure(fname: str, title: str, caption: str, make: Callable[[Path], object], func: str) -> None:
        md.append(f"### {title}")
        md.append("")
        try:
            make(out_dir / fname)
        except (ValueError, np.linalg.LinAlgError) as exc:
            md.append(f"**Figure not made:** {' '.join(str(exc).split())}")
            md.append("")
            return
        written.append(fname)
        md.append(f"![{title}]({quote(fname)})")
        md.append("")
        md.append(caption)
        md.append("")
        md.append(_produced_by(command, f"(`vivbench.report.{func}`)"))
        md.append("")
        say(fname)

    e0 = events[0]
    tree0, res0 = trees[e0], results[e0]
    # Any number of sections: captions name them; single-section panels show the middle one (S2 of three).
    sec_names = [str(s) for s in res0["equation"].values.tolist()]
    n_sec = len(sec_names)
    ref_name = sec_names[reference_section(n_sec)]
    n_feat = section_exponents().shape[0] * n_sec
    the_sections = "the section" if n_sec == 1 else f"the {F.count_word(n_sec)} sections"
    md += ["## Figures", "",
           f"Single-event figures show event {e0}"
           + (f"; the regime timeline shows {', '.join(events)}." if len(events) > 1 else "."), ""]
    figure("fig00_event.png", f"Event {e0}: overview",
           "Wind perpendicular to the span (grey) and the true mean wind (black), the deck acceleration, the true "
           "amplitude and the true regime over time (synthetic events only have the last two). Look for the "
           "amplitude growing while the wind is in the lock-in band and decaying after it leaves.",
           lambda p: event_figure(tree0, p), "event_figure")
    figure("fig01_sensor_layout.png", "Fig. 1: sensor layout and mode shape",
           f"Paper Fig. 1 and Fig. 3(a). {_layout_phrase(sec_names)} of the main span, each with one "
           "3-D anemometer and one vertical accelerometer. The mode shape values are those of the generator "
           f"configuration stored in the event (only "
           + ("the section value enters" if n_sec == 1 else f"the {F.count_word(n_sec)} section values enter")
           + " the model; the dashed line "
           "between them is a guide)."
           + (f" Sections in phase with phi({sec_names[0]}) = phi({sec_names[-1]}) give identical amplitudes at "
              f"{sec_names[0]} and {sec_names[-1]} in the figures below." if n_sec > 1 else ""),
           lambda p: F.sensor_layout_figure(tree0, p), "sensor_layout_figure")
    figure("fig02_wind.png", "Fig. 2: wind preprocessing",
           "Paper Fig. 2. (a) the measured components; (b) horizontal speed V and direction theta, with the two "
           "directions perpendicular to the span dashed; (c) the perpendicular component U~ = V |sin(theta - "
           "azimuth)| and its zero-phase low-pass U, the mean wind used by the identification. On synthetic events "
           "the true mean wind is dashed red: U should lie on it except near the ends of the record, which the "
           "identification drops.",
           lambda p: F.wind_figure(tree0, p), "wind_figure")
    figure("fig03_time_frequency.png", "Fig. 3: time-frequency analysis of the acceleration",
           "Paper Fig. 3(b, c), with a short-time Fourier spectrogram instead of the paper's wavelet transform. "
           f"The energy should stay at the modal frequency ({float(res0.attrs['f_mode_hz']):.4f} Hz found from the "
           "Welch spectrum, dashed) while the amplitude changes: the frequency does not shift, so only the "
           "amplitude A(t) needs a model.",
           lambda p: F.time_frequency_figure(tree0, p, f_mode=float(res0.attrs["f_mode_hz"])),
           "time_frequency_figure")
    figure("fig04_displacement.png", "Fig. 4: displacement, envelope and derivative",
           "Paper Fig. 4. (a) displacement from band-limited frequency-domain integration of the acceleration, "
           "and its Hilbert envelope A; the shaded edges are dropped by the identification. (b) A at "
           f"{the_sections} on the identification grid; (c) dA/dt by the configured differentiation. Dashed lines are "
           "the truth of the averaged model (synthetic events): compare A and dA/dt with them.",
           lambda p: F.displacement_figure(tree0, res0, p), "displacement_figure")
    figure("fig05_coefficients.png", "Fig. 5-7: the time-varying model of an event",
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
    figure("fig06_regimes.png", "Fig. 6: regimes of three events against the truth",
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
        figure(f"fig08_decision_graph_{kind}.png", f"Fig. 8-10: decision graph and clusters ({kind} features)",
               "Paper Figs. 8-10. Density-peaks clustering (Rodriguez and Laio 2014; "
               "`vivbench.analysis.DensityPeaks` with its defaults) of the window models of all events, one point "
               f"per window, features: {label}. (a) decision graph: centres are points with both a high density "
               "and a large distance to any denser point; (b) the clusters on the first two principal components; "
               f"(c) how each cluster's windows split between the true regimes (of {ref_name}) - a cluster that matches a "
               "regime has one dark cell. "
               + cluster_inputs.get("note", ""),
               lambda p, kind=kind: _cluster_figure(cluster_inputs, kind, p),
               "decision_graph_figure")

    figure("fig11_forecast.png", "Fig. 11-12: simulation and forecasts",
           "Paper Figs. 11-12. (a) the whole event simulated with the time-varying window models from the measured "
           "A at the first window and the measured wind, against the measured A; (b) forecasts from t0 with "
           "coefficients fixed at t0 or averaged over the windows starting in [t0, t0 + d]. NMSE (0: perfect, "
           "1: as good as the mean) is over the valid part of each run; a run whose A left the plausible range "
           "(non-finite, above 10x the largest measured A, or below -5 % of it) is stopped, drawn only up to "
           "there and marked x.",
           lambda p: F.forecast_figure(res0, p), "forecast_figure")

    pooled_path = regimes_file(results_dir)
    if pooled_path.is_file():
        # The campaign model through the model protocol (campaign.model.nc, or rebuilt from the regimes
        # file's coef for older outputs); the windows' identifiability verdicts from the campaign regimes.
        pooled = read_campaign_regimes(pooled_path)
        model_path = campaign_model_file(results_dir)
        model = load_campaign_model(model_path)
        varying = pooled.attrs.get("model") == "VaryingCoefficientSINDy"
        smoothing = campaign_wind_smoothing(pooled)  # the measured wind as at fit (vivbench.models.measured_input)
        if varying:
            intro = ("One varying-coefficient model dA_k/dt = sum_i a_ki(U) A_k^i for the whole campaign, the curves "
                     "penalised cubic B-splines in U (`vivbench.models.varying`, `vivbench pool --model varying`). A "
                     "window's regime is the rule of docs/concepts.md (regimes) applied to this model's order contributions over the "
                     "window's data; it counts as identifiable when at least "
                     f"{json.loads(pooled.attrs['model_config_json'])['agreement']:.0%} of block-bootstrap replicates "
                     "of the spline coefficients agree, every order subset in the model's confidence set "
                     "(leave-one-event-out) gives the same regime, and the amplitude is above the noise floor. "
                     f"The measured wind (and its yaw, a second covariate when the results store it: "
                     f"{'yes' if int(pooled.attrs.get('wind_yaw', 0)) else 'no'}) is smoothed over "
                     f"{smoothing:g} s (Gaussian sigma) before the fit and every evaluation on measured records; "
                     "the truth's felt wind is used as it is. "
                     f"B-splines per curve: {', '.join(str(int(k)) for k in pooled['n_basis'].values)}; "
                     f"{int(pooled.attrs['n_samples'])} samples in {int(pooled.attrs['n_blocks'])} blocks; "
                     f"coverage {float(pooled.attrs['coverage']):.3f}.")
        md += ["## The campaign model (`vivbench pool`)", ""] + ([intro] if varying else [
               "One sparse model dA/dt = Theta(A, U) xi for the whole campaign, fitted by the same STLSQ path and "
               "AICc on all samples of all events (`vivbench.models.campaign`). A window's regime is the rule of "
               "docs/concepts.md (regimes) applied to this model's order contributions over the window's data; it counts as "
               "identifiable when (i) no model inside the coefficients' joint 95 % confidence region (residual "
               "variance inflated by the residuals' correlation time) gives the window another regime, and (ii) at "
               f"least {json.loads(pooled.attrs['model_config_json'])['agreement']:.0%} of block-bootstrap "
               "replicates of the whole selection agree. "
               f"Terms per equation: {', '.join(str(int(k)) for k in pooled['n_terms'].values)}; "
               f"{int(pooled.attrs['n_samples'])} samples in {int(pooled.attrs['n_blocks'])} blocks; "
               f"coverage {float(pooled.attrs['coverage']):.3f}."
               + (f" **{pooled.attrs['note']}**" if pooled.attrs.get("note") else "")]) + ["",
               f"Model file: `{model_path.name}`"
               + ("" if model_path.name == MODEL_NAME else
                  " (no campaign.model.nc: the model is rebuilt from the regimes file's coefficients)") + ".", "",
               _produced_by(f"vivbench pool {results_dir}" + (" --model varying" if varying else "")), ""]
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
        figure("fig06b_regimes_campaign_model.png", "Fig. 6b: regimes of the campaign model against the truth",
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
            figure("fig12_curves.png", "Coefficient curves of the campaign model against the truth",
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
        figure("fig11b_forecast_campaign_model.png", "Fig. 11b: simulation and forecast with the campaign model",
               "As Fig. 11, with the campaign model (`model.simulate(record, t0, t1)`) over the span of the "
               "windows and from the same t0: one fixed model, so there is one forecast (d plays no role).",
               lambda p: F.model_forecast_figure(model, measured_input(model, result_record(res0),
                                                                       wind_smoothing_s=smoothing), p, t0=t0_cm, span=span0,
                                                 name="campaign model"),
               "model_forecast_figure")

    md += _recovery_section(info, command)
    say("recovery")
    if baseline_run is not None:
        md += _side_by_side_section(campaign_dir, results_dir, extra_dirs, baseline_run, out_dir, command, written, say)

    for step in step_names:
        if step == "leaderboard":  # its own section module (vivbench.report.leaderboard)
            md += leaderboard_section(extra_dirs.get(step), out_dir, written)
        else:
            md += _step_section(step, extra_dirs.get(step), campaign_dir, results_dir, out_dir, written, max_rows)
        say(step)

    _remove_stale_pngs(out_dir, written)
    report = out_dir / "report.md"
    with atomic_path(report, suffix=".md") as tmp:
        tmp.write_text("\n".join(md).rstrip() + "\n", encoding="utf-8")
    return report


def _report_command(name, campaign_dir, results_dir, out_root, extra_dirs, baseline=None) -> str:
    parts = ["vivbench report", f"--campaign {campaign_dir}", f"--results {results_dir}", f"--name {name}",
             f"--out-root {out_root}"]
    for step in EXTRA_STEPS:
        if extra_dirs.get(step) is not None:
            parts.append(f"--{step} {extra_dirs[step]}")
    if isinstance(baseline, CampaignRun):
        parts.append(f"--baseline <run of {baseline.campaign} and {baseline.results}>")
    elif baseline is not None:
        parts.append(f"--baseline {baseline}")
    return " ".join(parts)


def _side_by_side_section(campaign_dir, results_dir, extra_dirs, baseline_run, out_dir, command, written, say):
    """The baseline campaign beside this one (docs/concepts.md (no inverse crime); :mod:`vivbench.report.sidebyside`)."""

    def step(name):
        d = extra_dirs.get(name)
        return Path(d) if d is not None and Path(d).is_dir() else None

    this_run = CampaignRun(campaign=campaign_dir, results=results_dir, cluster=step("cluster"),
                           forecast=step("forecast"), validate=step("validate"))
    return baseline_section(this_run, baseline_run, out_dir=out_dir, command=command, written=written, progress=say)


def _what_was_run(campaign_dir, results_dir, info, missing, command) -> list[str]:
    cat = _catalogue(campaign_dir)
    n_events = len(info) + len(missing)
    seeds, durations, configs, versions, rows = set(), [], {}, set(), []
    for item in info:
        eid, res, attrs = item["event_id"], item["res"], item["attrs"]
        if item["seed"] is not None:
            seeds.add(int(item["seed"]))
        duration = item["duration"]
        durations.append(duration)
        configs.setdefault(res.attrs.get("identify_config_json", "{}"), []).append(eid)
        versions.add(str(res.attrs.get("vivbench_version", "unknown")))
        c = cat.get(eid, {})
        rows.append([eid, attrs.get("source", ""), c.get("scenario", attrs.get("scenario", "")),
                     f"{duration / 60:.1f}", c.get("U_min", ""), c.get("U_max", ""), c.get("A_max_m", ""),
                     f"{float(res.attrs['f_mode_hz']):.4f} ({res.attrs.get('f_mode_source', '')})",
                     int(res.sizes["window"])])
    out = ["## What was run", ""]
    out.append(f"- Campaign: `{campaign_dir}`, {n_events} event files"
               + (f", seed {', '.join(str(s) for s in sorted(seeds))}" if seeds else ", seed not recorded (field data?)")
               + f"; durations {min(durations) / 60:.1f}-{max(durations) / 60:.1f} min.")
    out.append(f"- Identification results: `{results_dir}`, {len(info)} of {n_events} events"
               + (f"; **no result for {', '.join(missing)}** (identification failed or was not run)." if missing else "."))
    out.append(f"- vivbench version of the results: {', '.join(sorted(versions))}; of this report: {vivbench.__version__}.")
    if len(configs) == 1:
        out.append("- Identification settings (the same for every result; from the `identify_config_json` attribute):")
    else:
        out.append(f"- **The results were made with {len(configs)} different settings** (event ids listed):")
    out.append("")
    for cfg_json, ids in configs.items():
        cfg = json.loads(cfg_json)
        if len(configs) > 1:
            out.append(f"  - {', '.join(ids)}:")
        out.append(_settings_table(cfg))
        out.append("")
    out.append("Events (scenario, wind and peak amplitude from `catalogue.csv`; modal frequency and windows from the "
               "result files):")
    out.append("")
    out.append(_table(["event", "source", "scenario", "duration (min)", "U min (m/s)", "U max (m/s)", "A max true (m)",
                       "modal frequency (Hz)", "windows"], rows))
    out.append("")
    out.append(_produced_by(command, "(from `catalogue.csv`, the event files and the result attributes)"))
    out.append("")
    return out


def _settings_table(cfg: dict) -> str:
    pre = cfg.get("preprocess", {})
    der = cfg.get("derivative", {})
    deriv = ", ".join(f"{k}={v}" for k, v in sorted(der.items()) if v is not None)
    thresholds = cfg.get("thresholds", [])
    rows = [
        ["window / step (s)", f"{cfg.get('window')} / {cfg.get('step')}"],
        ["derivative", deriv],
        ["library basis; ridge alpha", f"{cfg.get('scaling')}; {cfg.get('alpha')}"],
        ["STLSQ thresholds", f"{len(thresholds)} from {_fmt(min(thresholds, default=float('nan')))} to "
                             f"{_fmt(max(thresholds, default=float('nan')))} (standardised)"],
        ["regime threshold tau", cfg.get("tau")],
        ["identifiability: AICc margin; fit tolerance", f"{cfg.get('aicc_margin')}; {cfg.get('fit_tolerance')}"],
        ["mean-wind low-pass cut-off (Hz)", _fmt(pre.get("wind_cutoff_hz"), 4)],
        ["vibration band half-width (fraction of f_mode)", pre.get("band_half_width")],
        ["edges dropped (s); grid step (s)", f"{pre.get('edge_s')}; {pre.get('grid_step_s')}"],
        ["modal frequency", "from the spectrum" if pre.get("modal_frequency_hz") is None
         else f"given, {pre.get('modal_frequency_hz')} Hz"],
    ]
    return "\n".join("  " + line for line in _table(["setting", "value"], rows).splitlines())


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


# ------------------------------------------------------------------- recovery


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
    if getattr(model, "amplitude_ratios_", None) is None:
        return None
    from vivbench.analysis.pool import curve_wind_grid

    return model.curves(curve_wind_grid(np.concatenate([r["U"].values.ravel() for r in results.values()])))


def _recovery_section(info, command) -> list[str]:
    from vivbench.validate import recovery_by_event

    out = ["## Recovery of the truth", ""]
    truth_pairs = [(i["event_id"], i["event"], i["result"]) for i in info if i["truth"] is not None]
    results = {i["event_id"]: i["res"] for i in info}
    if not truth_pairs:
        return out + ["No event has a truth (field data): recovery is not scored.", ""]
    rows = []
    header = ["events", "window-equations scored", "coverage (identifiable)", "regime accuracy: identifiable",
              "regime accuracy: not identifiable", "regime accuracy: all", "most common true regime (chance level)",
              "median rel. error of dA/dt: all", "median rel. error of dA/dt: windows with dynamics",
              "share of windows with dynamics", "median rel. error of dA/dt on the true (A, U): windows with dynamics",
              "rel. error of dA/dt on the true (A, U): energy-weighted over every window sample"]
    shares_rows = []
    # Every event scored once; the campaign row aggregates the same windows.
    total, per_event = recovery_by_event([ev for _e, ev, _r in truth_pairs], [res for _e, _ev, res in truth_pairs])
    for (label, subset), s in zip([(eid, [(eid, ev, res)]) for eid, ev, res in truth_pairs] + [("all", truth_pairs)],
                                  per_event + [total]):
        shares = s["truth_regime_shares"]
        top = max(shares, key=shares.get)
        rows.append([f"**{label}**" if label == "all" else label, s["n"], _fmt(s["coverage"]),
                     _fmt(s["accuracy_identifiable"]), _fmt(s["accuracy_not_identifiable"]), _fmt(s["accuracy_all"]),
                     f"{top}: {_fmt(shares[top])}", _fmt(s["rhs_median_rel_error"]),
                     _fmt(s["rhs_median_rel_error_active"]), _fmt(s["active_share"]),
                     _fmt(s["rhs_error_true_AU_median_active"]), _fmt(s["rhs_error_true_AU_energy"])])
        ident = []
        for eid, _ev, _res in subset:
            r = results[eid]
            ident.append((r["regime"].values, r["identifiable"].values.astype(bool)))
        reg = np.concatenate([a.ravel() for a, _ in ident])
        ok = np.concatenate([b.ravel() for _, b in ident])
        shares_rows.append([f"**{label}**" if label == "all" else label]
                           + [_fmt(shares[k]) for k in (1, 2, 3, 4)]
                           + [_fmt(float(np.mean(reg[reg > 0] == k))) if (reg > 0).any() else "n/a" for k in (1, 2, 3, 4)]
                           + [_fmt(float(np.mean(reg[ok & (reg > 0)] == k))) if (ok & (reg > 0)).any() else "none"
                              for k in (1, 2, 3, 4)])
    out += [
        "Window by window (`vivbench.validate.campaign_recovery`): the true regime of each window and equation by "
        "the rule of docs/concepts.md (regimes) applied to the true order contributions, against the regime of the selected window "
        "model; and the relative RMS error of the identified dA/dt against the true one evaluated on the same "
        "measured A and U with the exact coefficient matrix (in-library truths only; n/a otherwise), and on the "
        "true (A, U): each window's model evaluated on the truth's own A and U against the truth's dA/dt (any "
        "truth). *Coverage* is the share of window-equations flagged identifiable; accuracy on "
        "identifiable and on not-identifiable windows is reported apart, never pooled silently. A constant guess "
        "of the most common true regime scores the chance level shown. 'Windows with dynamics' are those whose "
        "true dA/dt RMS is at least 10 % of the event's. The last column weighs the same error by energy: "
        "sqrt(sum of squared errors / sum of squared true dA/dt) over every window sample, which the "
        "large-amplitude phases dominate where the median over windows hides them.",
        "",
        _table(header, rows),
        "",
        _produced_by(command, "(`vivbench.validate.campaign_recovery` per event and over all events)"),
        "",
        "Regime shares: truth (all windows), identified (all windows), identified (identifiable windows only).",
        "",
        _table(["events"] + [f"true {k}" for k in (1, 2, 3, 4)] + [f"identified {k}" for k in (1, 2, 3, 4)]
               + [f"identifiable {k}" for k in (1, 2, 3, 4)], shares_rows),
        "",
        _produced_by(command, "(regime shares from `truth_window_regimes` and the result files)"),
        "",
    ]
    return out


# ----------------------------------------------------------- the other steps


def _step_command(step: str, directory: Path, campaign_dir: Path, results_dir: Path, summary: dict | None) -> tuple[str, str]:
    if summary and isinstance(summary.get("command"), str):
        return summary["command"], "(recorded in summary.json)"
    recorded = directory / "command.txt"
    if recorded.exists():
        return recorded.read_text().strip(), "(recorded in command.txt)"
    template = _STEP_COMMANDS.get(step, f"vivbench {step} ... --out {{dir}}")
    return (template.format(results=results_dir, campaign=campaign_dir, dir=directory),
            "(canonical form: the directory does not record its exact command)")


def _step_section(step, directory, campaign_dir, results_dir, out_dir, written, max_rows) -> list[str]:
    if step == "greybox" and directory is not None and (Path(directory) / "summary.json").is_file():
        from vivbench.report.greybox import greybox_section  # its own module (docs/field_workflow.md (the grey-box reference))

        return greybox_section(directory, out_dir, written, max_rows=max_rows)
    title = _STEP_TITLES.get(step, f"`{step}`")
    out = [f"## {title}", ""]
    if directory is None:
        return out + [f"**Not run**: no `--{step}` directory was given.", ""]
    directory = Path(directory)
    if not directory.is_dir():
        return out + [f"**Not run**: the directory `{directory}` does not exist.", ""]
    summary = None
    summary_path = directory / "summary.json"
    if summary_path.exists():
        try:
            summary = json.loads(summary_path.read_text())
        except json.JSONDecodeError as exc:
            raise InputError(f"{summary_path}: not valid JSON ({exc})") from None
        if not isinstance(summary, dict):
            raise InputError(f"{summary_path}: must hold a JSON object of headline numbers; got {type(summary).__name__}")
    cmd, how = _step_command(step, directory, campaign_dir, results_dir, summary)
    out += [f"Output directory: `{directory}`.", ""]
    csvs = sorted(directory.glob("*.csv"))
    pngs = sorted(directory.glob("*.png"))
    if summary is None and not csvs and not pngs:
        return out + ["The directory holds no `summary.json`, `*.csv` or `*.png`: nothing to show.", ""]
    if summary is not None:
        rows = [[k, _fmt(v) if isinstance(v, (int, float, bool)) or v is None else json.dumps(v)]
                for k, v in summary.items() if k != "command"]
        out += ["Headline numbers (`summary.json`):", "", _table(["quantity", "value"], rows), "",
                _produced_by(cmd, how), ""]
    for path in csvs:
        header, rows = _read_csv(path)
        out.append(f"**{path.name}**" + (f" (first {max_rows} of {len(rows)} rows; full table in `{path}`)"
                                         if len(rows) > max_rows else f" ({len(rows)} rows)")
                   + "; decimals shown to 4 significant digits")
        out.append("")
        out.append(_table(header, [[_short(c) for c in row] for row in rows[:max_rows]]) if header
                   else "(empty file)")
        out.append("")
        out.append(_produced_by(cmd, how))
        out.append("")
    for path in pngs:
        fname = f"{step}_{path.name}"
        with atomic_path(out_dir / fname, suffix=".png") as tmp:
            shutil.copyfile(path, tmp)
        written.append(fname)
        out += [f"![{step}: {path.stem}]({quote(fname)})", "", f"*{path.name}* from `{directory}`. "
                + _produced_by(cmd, how), ""]
    others = sorted(p.name for p in directory.iterdir() if p.is_file() and p.suffix not in (".csv", ".png")
                    and p.name not in ("summary.json", "command.txt") and not p.name.startswith("."))
    if others:
        out += [f"Other files in the directory (not embedded): {', '.join(f'`{o}`' for o in others)}.", ""]
    return out


def _remove_stale_pngs(out_dir: Path, written: Sequence[str]) -> None:
    keep = set(written)
    for png in out_dir.glob("*.png"):
        if png.name not in keep:
            png.unlink()
