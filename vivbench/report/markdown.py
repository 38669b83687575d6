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
from vivbench.io.netcdf import atomic_path
from vivbench.io.event import list_events, read_event
from vivbench.core.steps import EXTRA_STEPS
from vivbench.io.event import read_event_summary
from vivbench.io.result import read_result
from vivbench.core.errors import InputError
from vivbench.report.leaderboard import leaderboard_section
from vivbench.report.figure_sections import ReportFigures, campaign_model_figures, paper_figures
from vivbench.report.sidebyside import CampaignRun, baseline_section, campaign_run
from vivbench.report.tables import md_table, produced_by
from vivbench.report.twin import twin_section

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
                 baseline: Path | str | CampaignRun | None = None, twin: Path | str | None = None) -> Path:
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
    twin : path, optional
        Output directory of ``vivbench twin`` on this campaign: adds the section "How far to
        trust this" (:func:`vivbench.report.twin.twin_section`) after the recovery tables. Without
        it the report is unchanged.

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
    command = _report_command(name, campaign_dir, results_dir, Path(out_root), extra_dirs, baseline, twin)
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
        produced_by(command, "(this whole report, its figures and the recovery tables)"),
        "",
    ]
    md += _what_was_run(campaign_dir, results_dir, info, missing, command)
    say("summary")

    written: list[str] = []
    fig = ReportFigures(md=md, written=written, out_dir=out_dir, command=command, say=say)
    timeline_truth = paper_figures(fig, info, events, trees, results, has_truth)
    campaign_model_figures(fig, results_dir, events, trees, results, timeline_truth)

    md += _recovery_section(info, command)
    say("recovery")
    if twin is not None:
        md += twin_section(twin)
        say("twin")
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


def _report_command(name, campaign_dir, results_dir, out_root, extra_dirs, baseline=None, twin=None) -> str:
    parts = ["vivbench report", f"--campaign {campaign_dir}", f"--results {results_dir}", f"--name {name}",
             f"--out-root {out_root}"]
    for step in EXTRA_STEPS:
        if extra_dirs.get(step) is not None:
            parts.append(f"--{step} {extra_dirs[step]}")
    if isinstance(baseline, CampaignRun):
        parts.append(f"--baseline <run of {baseline.campaign} and {baseline.results}>")
    elif baseline is not None:
        parts.append(f"--baseline {baseline}")
    if twin is not None:
        parts.append(f"--twin {twin}")
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
    out.append(md_table(["event", "source", "scenario", "duration (min)", "U min (m/s)", "U max (m/s)", "A max true (m)",
                       "modal frequency (Hz)", "windows"], rows))
    out.append("")
    out.append(produced_by(command, "(from `catalogue.csv`, the event files and the result attributes)"))
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
    return "\n".join("  " + line for line in md_table(["setting", "value"], rows).splitlines())


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
        md_table(header, rows),
        "",
        produced_by(command, "(`vivbench.validate.campaign_recovery` per event and over all events)"),
        "",
        "Regime shares: truth (all windows), identified (all windows), identified (identifiable windows only).",
        "",
        md_table(["events"] + [f"true {k}" for k in (1, 2, 3, 4)] + [f"identified {k}" for k in (1, 2, 3, 4)]
               + [f"identifiable {k}" for k in (1, 2, 3, 4)], shares_rows),
        "",
        produced_by(command, "(regime shares from `truth_window_regimes` and the result files)"),
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
        out += ["Headline numbers (`summary.json`):", "", md_table(["quantity", "value"], rows), "",
                produced_by(cmd, how), ""]
    for path in csvs:
        header, rows = _read_csv(path)
        out.append(f"**{path.name}**" + (f" (first {max_rows} of {len(rows)} rows; full table in `{path}`)"
                                         if len(rows) > max_rows else f" ({len(rows)} rows)")
                   + "; decimals shown to 4 significant digits")
        out.append("")
        out.append(md_table(header, [[_short(c) for c in row] for row in rows[:max_rows]]) if header
                   else "(empty file)")
        out.append("")
        out.append(produced_by(cmd, how))
        out.append("")
    for path in pngs:
        fname = f"{step}_{path.name}"
        with atomic_path(out_dir / fname, suffix=".png") as tmp:
            shutil.copyfile(path, tmp)
        written.append(fname)
        out += [f"![{step}: {path.stem}]({quote(fname)})", "", f"*{path.name}* from `{directory}`. "
                + produced_by(cmd, how), ""]
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
