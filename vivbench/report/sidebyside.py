"""In-library against realistic: the report's recovery figures of two campaigns side by side (docs/concepts.md (no inverse crime)).

``vivbench report --baseline DIR`` adds one section to the report: the chain's
recovery on the report's campaign (normally the realistic default) beside its
recovery on a baseline campaign (normally ``--mode in_library``, the same seed
and wind scripts: the truth inside the identification's model class, the
inverse crime). Every recovery figure is shown for both: regime coverage and
accuracy, the dA/dt error on the true (A, U), the coefficient curves, the
clusters and the campaign model's forecasts, with one paragraph on what the
inverse crime is and what it costs here, written from the measured numbers.

The scores are :func:`vivbench.validate.validate_campaign`'s, read from a
``vivbench validate`` directory's ``metrics.json`` when it was made from the
same campaign and results, computed otherwise; clusters and forecasts come
from the ``vivbench cluster`` and ``vivbench forecast`` directories of each run
(the demo's layout: ``DIR/campaign``, ``DIR/identify``, ``DIR/cluster``,
``DIR/forecast``, ``DIR/validate``).
"""

from __future__ import annotations

import dataclasses
import json
import math
import shutil
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from urllib.parse import quote

import numpy as np

from vivbench.core.errors import InputError
from vivbench.models.protocol import model_curves
from vivbench.io.event import list_events, read_event_summary
from vivbench.io.netcdf import atomic_path
from vivbench.report.tables import md_table, produced_by
from vivbench.validate.campaign import upgrade_metrics

__all__ = ["CampaignRun", "MODE_LABELS", "baseline_section", "campaign_run", "inverse_crime_paragraph"]

#: How the report names each generator mode (docs/concepts.md (no inverse crime)).
MODE_LABELS = {
    "in_library": "in-library (truth inside the model class: the inverse crime)",
    "realistic": "realistic (default: truth outside the model class)",
    "mixed": "mixed generator configuration",
    "field": "field data (no truth)",
}
_SHORT = {"in_library": "in-library", "realistic": "realistic", "mixed": "mixed", "field": "field"}


@dataclasses.dataclass(frozen=True, kw_only=True)
class CampaignRun:
    """The chain's outputs on one campaign.

    Parameters
    ----------
    campaign : path
        Directory of the event files (``<event_id>.nc``, ``catalogue.csv``).
    results : path
        Identification results (``<event_id>.identify.nc``; ``campaign.regimes.nc``
        and ``campaign.model.nc`` of ``vivbench pool`` when fitted).
    cluster, forecast, validate : path, optional
        Output directories of ``vivbench cluster``, ``forecast`` and
        ``validate`` on these results (None: not run).
    """

    campaign: Path
    results: Path
    cluster: Path | None = None
    forecast: Path | None = None
    validate: Path | None = None

    def __post_init__(self) -> None:
        for name in ("campaign", "results", "cluster", "forecast", "validate"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, Path(value))
        if not self.campaign.is_dir():
            raise InputError(f"{self.campaign}: no such campaign directory")
        if not self.results.is_dir():
            raise InputError(f"{self.results}: no such results directory")


def campaign_run(directory) -> CampaignRun:
    """The :class:`CampaignRun` of a ``vivbench demo`` output directory.

    Parameters
    ----------
    directory : path
        Holds ``campaign/`` and ``identify/``, and optionally ``cluster/``,
        ``forecast/`` and ``validate/`` (the layout ``vivbench demo --out DIR`` writes).

    Raises
    ------
    InputError
        ``campaign/`` or ``identify/`` is missing.
    """
    d = Path(directory)
    if not (d / "campaign").is_dir() or not (d / "identify").is_dir():
        raise InputError(f"{d}: a baseline directory must hold campaign/ and identify/ (the output of "
                         "`vivbench demo --mode in_library --out DIR`)")

    def step(name):
        return d / name if (d / name).is_dir() else None

    return CampaignRun(campaign=d / "campaign", results=d / "identify", cluster=step("cluster"),
                       forecast=step("forecast"), validate=step("validate"))


# ------------------------------------------------------------------ the data


def _f(x, digits: int = 3) -> str:
    if x is None or isinstance(x, bool):
        return "n/a"
    x = float(x)
    if not math.isfinite(x):
        return "n/a"
    return f"{x:.{digits}g}" if abs(x) < 1e-3 and x != 0 or abs(x) >= 1e4 else f"{x:.{digits}f}"


def _t0(t0) -> str:
    return f"{float(t0):.0f} s" if isinstance(t0, (int, float)) and math.isfinite(t0) else "n/a"


def _read_json(path: Path) -> dict | None:
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def _describe(run: CampaignRun) -> dict:
    """Mode, seed, size and bridge of a run's campaign, from its event files."""
    from vivbench.synth import config_from_dict

    events = list_events(run.campaign)
    if not events:
        raise InputError(f"{run.campaign}: no event files (<event_id>.nc) in this directory")
    results = sorted(run.results.glob("*.identify.nc"))
    if not results:
        raise InputError(f"{run.results}: no identification result (<event_id>.identify.nc)")
    first = read_event_summary(events[0])
    durations = [read_event_summary(e).duration_s for e in events]
    mode, seed, structure = "field", None, {}
    if first.truth is not None and "config_json" in first.truth.attrs:
        meta = json.loads(first.truth.attrs["config_json"])
        generator = meta.get("generator", meta)
        seed = meta.get("seed", {}).get("campaign_seed")
        try:
            mode = config_from_dict(generator).mode
        except (TypeError, ValueError):
            mode = "mixed"
        structure = generator.get("structure", {})
    return {"mode": mode, "seed": seed, "n_events": len(events), "n_results": len(results),
            "duration_min": (min(durations) / 60.0, max(durations) / 60.0), "first_event": events[0],
            "frequency": structure.get("frequency"), "depth": structure.get("depth")}


def _same_dir(a, b) -> bool:
    try:
        return Path(a).resolve() == Path(b).resolve()
    except (OSError, TypeError):
        return False


def _validation(run: CampaignRun) -> tuple[dict, str]:
    """validate_campaign's scores of a run and where they come from."""
    if run.validate is not None:
        metrics = upgrade_metrics(_read_json(run.validate / "metrics.json"))
        settings = (metrics or {}).get("settings", {})
        if metrics and _same_dir(settings.get("campaign_dir"), run.campaign) and _same_dir(
                settings.get("results_dir"), run.results):
            recorded = run.validate / "command.txt"
            cmd = (recorded.read_text().strip() if recorded.is_file()
                   else f"vivbench validate {run.campaign} {run.results} --out {run.validate}")
            return metrics, cmd
    from vivbench.validate import validate_campaign

    return validate_campaign(run.campaign, run.results), f"vivbench validate {run.campaign} {run.results} --out DIR"


def _model_scores(regime: Mapping | None, rhs_true: Mapping | None) -> dict | None:
    if regime is None:
        return None
    groups = regime["groups"]
    return {"coverage": regime.get("coverage"), "accuracy_identifiable": groups["identifiable"]["accuracy"],
            "accuracy_all": groups["all"]["accuracy"], "confusion": groups["all"]["confusion"],
            "error": None if rhs_true is None else rhs_true["active"]}


def _figure_scores(v: Mapping) -> dict:
    pooled = v.get("campaign_model")
    return {"chance": v["summary"].get("truth_most_common_regime_share"),
            "window": _model_scores(v["regime"], v.get("rhs_true_AU")),
            "campaign": None if pooled is None else _model_scores(pooled["regime"], pooled.get("rhs_true_AU"))}


# ------------------------------------------------------------------ the text


def inverse_crime_paragraph(labels: Sequence[str], summaries: Sequence[Mapping] | None = None, *,
                            campaigns: str = "the two campaigns below") -> str:
    """The paragraph on the inverse crime, with the measured consequence when two runs' summaries are given.

    Parameters
    ----------
    labels : the generator mode of each run (``"in_library"``, ``"realistic"``, ...)
    summaries : ``summary`` of :func:`vivbench.validate.validate_campaign` per run, optional
    campaigns : how the measured campaigns are named in the text
    """
    text = ("**The inverse crime, and how the testbed avoids it.** Synthetic data generated with the inversion's own "
            "model make any inversion look better than it will be on field data; in inverse problems this is called "
            "the inverse crime. The generator's `in_library` mode commits it on purpose: its aerodynamic functions "
            "are polynomials in U chosen so that the averaged dynamics lie exactly in the A^i U^j library of the "
            "identification, and the deck feels exactly the anemometer's low-passed wind. The default `realistic` "
            "mode (docs/concepts.md (no inverse crime)) builds the truth outside that class: a lock-in bell and smooth non-polynomial "
            "functions of the reduced velocity U/(f D) with a yaw factor, a deck that feels the wind averaged over "
            "each section's tributary length of a spatially resolved turbulence field while each anemometer is one "
            "point (so the identification's U carries errors-in-variables), and optional slow changes the wind does "
            "not carry. The identification code cannot import the generator (an import-linter contract), and a "
            "method's recovery figures are to be read on realistic campaigns.")
    if summaries is None or "in_library" not in labels or "realistic" not in labels:
        return text
    lib, real = (summaries[list(labels).index(m)] for m in ("in_library", "realistic"))

    def pair(key):
        return f"{_f(lib.get(key))} in-library against {_f(real.get(key))} realistic"

    parts = []
    if "campaign_model_median_rhs_error_true_AU_active" in lib and "campaign_model_median_rhs_error_true_AU_active" in real:
        parts.append(f"the campaign model's median dA/dt error on the true (A, U) is "
                     f"{pair('campaign_model_median_rhs_error_true_AU_active')} (energy-weighted "
                     f"{pair('campaign_model_energy_rhs_error_true_AU')}), its coverage "
                     f"{pair('campaign_model_regime_coverage')} (accuracy on the windows it flags "
                     f"{pair('campaign_model_regime_accuracy_identifiable')}; n/a: none flagged)")
    parts.append(f"the window models' (the paper's method) error is {pair('median_rhs_error_true_AU_active')} "
                 f"(energy-weighted {pair('energy_rhs_error_true_AU')}) and "
                 f"their coverage {pair('regime_coverage')}")
    return text + (f" Measured on {campaigns}: " + "; ".join(parts)
                   + ". The in-library figures are what the inverse crime would have let us claim.")


def _recovery_rows(vs: Sequence[Mapping], clusters: Sequence[dict | None], forecasts: Sequence[dict | None]) -> list:
    s = [v["summary"] for v in vs]

    def row(label, key, digits=3):
        return [label] + [_f(x.get(key), digits) for x in s]

    rows = [["events scored"] + [str(x.get("n_events")) for x in s],
            ["window-equations scored"] + [str(x.get("n_window_equations")) for x in s],
            row("chance level: share of the most common true regime", "truth_most_common_regime_share"),
            row("window models: coverage (flagged identifiable)", "regime_coverage"),
            row("window models: regime accuracy, flagged windows", "regime_accuracy_identifiable"),
            row("window models: regime accuracy, all windows", "regime_accuracy_all"),
            row("window models: median rel. error of dA/dt on the true (A, U), windows with dynamics",
                "median_rhs_error_true_AU_active"),
            row("window models: 90 % quantile of that error", "q90_rhs_error_true_AU_active"),
            row("window models: rel. error of dA/dt on the true (A, U), energy-weighted over every window sample",
                "energy_rhs_error_true_AU"),
            row("window models: median rel. error of dA/dt on the measured (A, U), exact matrix (in-library only)",
                "median_rhs_rel_error_active")]
    if any("campaign_model_regime_coverage" in x for x in s):
        rows += [row("campaign model: coverage (flagged identifiable)", "campaign_model_regime_coverage"),
                 row("campaign model: regime accuracy, flagged windows", "campaign_model_regime_accuracy_identifiable"),
                 row("campaign model: regime accuracy, all windows", "campaign_model_regime_accuracy_all"),
                 row("campaign model: median rel. error of dA/dt on the true (A, U), windows with dynamics",
                     "campaign_model_median_rhs_error_true_AU_active"),
                 row("campaign model: rel. error of dA/dt on the true (A, U), energy-weighted over every sample",
                     "campaign_model_energy_rhs_error_true_AU"),
                 row("campaign model: curve error over lock-in, net linear a_k1(U) (rel. RMS)",
                     "campaign_model_curve_error_linear"),
                 row("campaign model: curve error over lock-in, sum_i a_ki(U) A^i (rel. RMS)",
                     "campaign_model_curve_error_total"),
                 row("campaign model: curve error, sum_i a_ki(U) A^i at the true (A, U), energy-weighted over every "
                     "sample", "campaign_model_curve_error_energy")]
    for kind in ("coef", "order"):
        rows.append([f"clusters ({kind} features): number, ARI, purity"]
                    + [("not run" if c is None else f"{c.get(f'n_clusters_{kind}', 'n/a')}, "
                        f"{_f(c.get(f'ari_{kind}'))}, {_f(c.get(f'purity_{kind}'))}") for c in clusters])
    rows.append(["forecast event and t0 (clearest true plateau)"]
                + [("not run" if fc is None else f"{fc.get('event_id')}, {_t0(fc.get('t0_s'))}") for fc in forecasts])
    for label, key in (("window models: NMSE of the whole-event simulation", "simulation_nmse_"),
                       ("campaign model: NMSE of the whole-event simulation", "campaign_model_simulation_nmse_"),
                       ("campaign model: NMSE of the 300 s forecast from t0", "campaign_model_forecast_nmse_")):
        cells = []
        for fc in forecasts:
            keys = sorted(k for k in (fc or {}) if k.startswith(key) and "clip" not in k
                          and not k.endswith("stopped"))
            cells.append("not run" if fc is None else
                         ", ".join(f"{_f(fc[k], 3)} ({k[len(key):]})" for k in keys) or "n/a")
        rows.append([label] + cells)
    return rows


# ---------------------------------------------------------------- the section


def baseline_section(run: CampaignRun, baseline: CampaignRun, *, out_dir, command: str,
                     written: list[str], progress: Callable[[str], None] | None = None) -> list[str]:
    """The report's section that shows a baseline campaign's recovery beside the report's campaign's.

    Parameters
    ----------
    run : the report's campaign (normally the realistic default)
    baseline : the campaign shown beside it (normally ``--mode in_library``, same seed)
    out_dir : the report's directory; figures are written there
    command : the report's command (cited under every table and figure)
    written : names of the figures written so far; this section's are appended
    progress : called with a short label as each part is done

    Returns
    -------
    list of str
        Markdown lines; the baseline column comes first.
    """
    from vivbench.analysis.pool import campaign_model_file, curve_wind_grid, load_campaign_model, campaign_wind_smoothing
    from vivbench.io.campaign_model import read_campaign_regimes, regimes_file
    from vivbench.models.model_input import measured_input
    from vivbench.io.result import read_result, result_record
    from vivbench.report.figures import curves_figure, model_forecast_figure
    from vivbench.report.pair_figures import recovery_pair_figure
    from vivbench.validate.campaign import event_truth_curves

    say = progress or (lambda _label: None)
    out_dir = Path(out_dir)
    runs = [baseline, run]
    info = [_describe(r) for r in runs]
    modes = [i["mode"] for i in info]
    roles = ["baseline (`--baseline`)", "this report's campaign"]
    headers = [f"{MODE_LABELS.get(m, m)}; {roles[k]}" for k, m in enumerate(modes)]
    # Labelled with the number of events scored (those with results): the size of what each column measures.
    short = [f"{_SHORT.get(m, m)}, {i['n_results']} events" for m, i in zip(modes, info)]
    validations, validate_cmds = zip(*(_validation(r) for r in runs))
    say("baseline: scores")
    clusters = [None if r.cluster is None else _read_json(r.cluster / "summary.json") for r in runs]
    forecasts = [None if r.forecast is None else _read_json(r.forecast / "summary.json") for r in runs]

    out = ["## In-library against realistic: the inverse crime, side by side", ""]
    sizes_differ = info[0]["n_results"] != info[1]["n_results"] or info[0]["duration_min"] != info[1]["duration_min"]
    same_seed = info[0]["seed"] is not None and info[0]["seed"] == info[1]["seed"]
    which = ("the two campaigns below (the same seed and wind scripts" if same_seed and not sizes_differ
             else "the two campaigns below (" + ("different sizes" if sizes_differ else "different seeds"))
    which += f"; {info[0]['n_results']} and {info[1]['n_results']} events scored)"
    out += [inverse_crime_paragraph(modes, [v["summary"] for v in validations], campaigns=which), ""]
    out += ["The two campaigns:" + (" **they differ in size** (the baseline is a smaller campaign; its figures are "
                                    "those of its own size)." if sizes_differ else ""), ""]
    out.append(md_table(["", *headers], [
        ["generator mode (docs/concepts.md (no inverse crime))"] + [f"`{m}`" for m in modes],
        ["campaign directory"] + [f"`{r.campaign}`" for r in runs],
        ["results directory"] + [f"`{r.results}`" for r in runs],
        ["events (with results); seed"] + [f"{i['n_events']} ({i['n_results']}); {i['seed']}" for i in info],
        ["durations (min)"] + [f"{i['duration_min'][0]:.1f}-{i['duration_min'][1]:.1f}" for i in info],
    ]))
    out += ["", produced_by(command, "(from the event files' generator configuration)"), ""]

    out += ["### Recovery side by side", "",
            "The same scores for both campaigns (`vivbench.validate.validate_campaign`, the numbers of `vivbench "
            "validate`): regimes by the rule of docs/concepts.md (regimes) against the truth's, coverage beside accuracy; the dA/dt "
            "error on the true (A, U), i.e. each model's `predict` on the truth's own A and U against the truth's "
            "dA/dt, the only dA/dt error a truth outside the library has; the campaign model's coefficient curves "
            "against the truth's over the lock-in range; the clusters' agreement with the true regimes "
            "(`vivbench cluster`) and the simulations and forecasts of `vivbench forecast` on each campaign's "
            "clearest plateau. n/a: undefined (no window flagged, no exact coefficient matrix) or not computed.", ""]
    out.append(md_table(["quantity", *short], _recovery_rows(validations, clusters, forecasts)))
    out += ["", produced_by(command, "(scores of " + "; ".join(f"`{c}`" for c in validate_cmds)
                             + "; clusters and forecasts from each run's `summary.json`)"), ""]

    def pair_table(cells: Sequence[str]) -> str:
        return md_table(short, [cells])

    name = "sbs_recovery.png"
    try:
        recovery_pair_figure([_figure_scores(v) for v in validations], short, out_dir / name)
    except (ValueError, np.linalg.LinAlgError) as exc:
        out += [f"**Figure not made:** {' '.join(str(exc).split())}", ""]
    else:
        written.append(name)
        out += ["### Regime coverage, accuracy and the dA/dt error", "", f"![recovery side by side]({quote(name)})", "",
                "(a) regime coverage and accuracy of the window models and the campaign model on each campaign "
                "(dashed: each campaign's chance level); (b) the per-window relative error of dA/dt on the true "
                "(A, U), windows with dynamics; (c, d) the campaign model's regimes against the truth's, all "
                "windows (counts; shading: share of each true regime's windows).", "",
                produced_by(command, "(`vivbench.report.recovery_pair_figure`)"), ""]
    say(name)

    # Coefficient curves of each campaign model against its own truth.
    cells = []
    for k, (r, i) in enumerate(zip(runs, info)):
        pooled_path = regimes_file(r.results)
        if not pooled_path.is_file():
            cells.append("campaign model not fitted (`vivbench pool` not run)")
            continue
        pooled = read_campaign_regimes(pooled_path)
        model = load_campaign_model(campaign_model_file(r.results))
        curves = pooled if "curves" in pooled.data_vars else None
        if curves is None:
            U = [read_result(p, variables=("U",))["U"].values.ravel() for p in sorted(r.results.glob("*.identify.nc"))]
            curves = model_curves(model, curve_wind_grid(np.concatenate(U)))
        if curves is None:
            cells.append("no curves (re-run `vivbench pool`)")
            continue
        summary = read_event_summary(i["first_event"])
        truth = None if summary.truth is None else event_truth_curves(summary.truth)
        fname = f"sbs_curves_{k + 1}_{modes[k]}.png"
        try:
            curves_figure(curves, out_dir / fname, truth=truth, frequency=i["frequency"], depth=i["depth"],
                            name=f"campaign model ({_SHORT.get(modes[k], modes[k])})")
        except (ValueError, np.linalg.LinAlgError) as exc:
            cells.append(f"figure not made: {' '.join(str(exc).split())}")
            continue
        written.append(fname)
        cells.append(f"![curves, {short[k]}]({quote(fname)})")
    out += ["### Coefficient curves side by side", "", pair_table(cells), "",
            "docs/concepts.md (coefficient curves): the coefficients a_i(U) of dA/dt = sum_i a_i(U) A^i at the reference section, each campaign "
            "model (dashed, its 95 % block-bootstrap band shaded; grey dotted where the curve lies outside the winds "
            "of its fitted data: an extrapolation) against its own campaign's truth (black), as in "
            "the coefficient-curve figure above. In-library, the truth is a polynomial in U that the library holds; "
            "realistic, a bell in reduced velocity that a degree-5 polynomial can only approximate, seen through "
            "a point anemometer's wind.", "", produced_by(command, "(`vivbench.report.curves_figure` per campaign)"), ""]
    say("curves")

    # Clusters: the decision graphs `vivbench cluster` drew for each campaign.
    for kind in ("coef", "order"):
        cells = []
        for k, r in enumerate(runs):
            src = None if r.cluster is None else r.cluster / f"decision_graph_{kind}.png"
            if src is None or not src.is_file():
                cells.append("`vivbench cluster` not run" if r.cluster is None else f"no `{src.name}` in `{r.cluster}`")
                continue
            fname = f"sbs_cluster_{k + 1}_{modes[k]}_{kind}.png"
            with atomic_path(out_dir / fname, suffix=".png") as tmp:
                shutil.copyfile(src, tmp)
            written.append(fname)
            cells.append(f"![clusters ({kind}), {short[k]}]({quote(fname)})")
        cmds = [(r.cluster / "command.txt").read_text().strip() if r.cluster is not None
                and (r.cluster / "command.txt").is_file() else "vivbench cluster RESULTS --out DIR" for r in runs]
        out += [f"### Clusters of the window models side by side ({kind} features)", "", pair_table(cells), "",
                "Density-peaks clustering of all window models of each campaign (`vivbench cluster`, its decision "
                "graph, the clusters on the first two principal components and their split between the true "
                "regimes); ARI and purity in the table above.", "",
                produced_by(cmds[0], "(baseline) and `" + cmds[1] + "` (this report's campaign)"), ""]
    say("clusters")

    # Forecasts: each campaign model on its campaign's clearest plateau.
    cells = []
    for k, (r, fc) in enumerate(zip(runs, forecasts)):
        model_path = campaign_model_file(r.results)
        if model_path is None:
            cells.append("campaign model not fitted (`vivbench pool` not run)")
            continue
        results = sorted(r.results.glob("*.identify.nc"))
        eid = (fc or {}).get("event_id")
        path = r.results / f"{eid}.identify.nc" if eid else results[0]
        if not path.is_file():
            path = results[0]
        res = read_result(path)
        starts = res["window_start"].values
        span = (float(starts.min()), float(res["window_end"].values.max()))
        t0 = (fc or {}).get("t0_s")
        if not isinstance(t0, (int, float)) or not span[0] <= t0 < span[1]:
            t0 = float(starts[np.argmin(np.abs(starts - (span[0] + 0.4 * (span[1] - span[0]))))])
        fname = f"sbs_forecast_{k + 1}_{modes[k]}.png"
        try:
            model = load_campaign_model(model_path)
            pooled_path = regimes_file(r.results)
            smoothing = campaign_wind_smoothing(read_campaign_regimes(pooled_path) if pooled_path.is_file() else None)
            record = measured_input(model, result_record(res), wind_smoothing_s=smoothing)
            model_forecast_figure(model, record, out_dir / fname,
                                  t0=float(t0), span=span, name=f"campaign model ({_SHORT.get(modes[k], modes[k])})")
        except (ValueError, np.linalg.LinAlgError) as exc:
            cells.append(f"figure not made: {' '.join(str(exc).split())}")
            continue
        written.append(fname)
        cells.append(f"![forecast, {short[k]}]({quote(fname)})")
    out += ["### Simulation and forecast with the campaign model side by side", "", pair_table(cells), "",
            "Each campaign model simulates its campaign's forecast event (the clearest true plateau, as "
            "`vivbench forecast` chose it; else the first event) from the measured A and wind, and forecasts "
            "300 s from the same t0 (`model.simulate`), as in Fig. 11b.", "",
            produced_by(command, "(`vivbench.report.model_forecast_figure` per campaign)"), ""]
    say("forecasts")
    return out
