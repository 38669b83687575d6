"""The leaderboard's outputs: ``leaderboard.csv``, ``leaderboard.md`` and ``leaderboard.png``.

Rows are cells (scenario, method) with the scores of :data:`SCORES`. What a
score means and when it does not apply:

- ``coverage``: share of the window-equations the method flags identifiable.
  A method without an identifiability verdict flags nothing: coverage 0 and
  no accuracy on flagged windows (``has_verdict`` false).
- ``accuracy_flagged``, ``accuracy_all``: regime accuracy against the truth
  (docs/concepts.md (regimes)) on the flagged windows and on all windows.
- ``rhs_error_true_AU``: median relative error of the method's dA/dt on the
  truth's own (A, U), over windows with dynamics; ``rhs_error_true_AU_energy``:
  the same error energy-weighted over every sample (sum of squared errors over
  sum of squared true dA/dt), which the large amplitudes dominate and the
  median hides.
- ``curve_error``: relative RMS error of the coefficient curves a_ki(U)
  (docs/concepts.md (coefficient curves)) over lock-in; ``curve_error_energy``: the dA/dt the curves
  give at the truth's (A, U) of every sample against the truth's curves',
  energy-weighted; only for methods with ``curves`` and truths that store
  curves (not with a damping drift), and only at winds inside the fitted data.

Tables written before the energy-weighted scores existed read with NaN there.
- ``forecast_nmse``: NMSE of the model's free simulation of each record's
  longest run of valid samples from its first measured A with the measured
  wind (median over records and sections), over the part simulated before a
  run left the data's range; ``forecast_covered`` is the median share of the
  run simulated (read the two together). Only for methods that simulate.
- ``fit_time_s``: wall time of ``fit``; the one score that varies between runs.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from vivbench.core.errors import InputError
from vivbench.io.netcdf import atomic_path

__all__ = ["SCORES", "VALUES", "SCORE_LABELS", "LEADERBOARD_COLUMNS", "write_csv", "read_leaderboard", "format_score",
           "leaderboard_markdown", "write_markdown", "plot_leaderboard"]

#: The scores of a cell, in table order.
SCORES = ("coverage", "accuracy_flagged", "accuracy_all", "rhs_error_true_AU", "rhs_error_true_AU_energy",
          "curve_error", "curve_error_energy", "forecast_nmse", "fit_time_s")
#: Every value a cell stores: the scores and the share of the forecast runs simulated.
VALUES = ("coverage", "accuracy_flagged", "accuracy_all", "rhs_error_true_AU", "rhs_error_true_AU_energy",
          "curve_error", "curve_error_energy", "forecast_nmse", "forecast_covered", "fit_time_s")
#: Values added after the first tables were written: absent from an old table, they read as NaN.
_ADDED_VALUES = ("rhs_error_true_AU_energy", "curve_error_energy")
#: Score titles with units.
SCORE_LABELS = {
    "coverage": "coverage: share of window-equations flagged identifiable (-)",
    "accuracy_flagged": "regime accuracy on flagged windows (-)",
    "accuracy_all": "regime accuracy on all windows (-)",
    "rhs_error_true_AU": "median rel. error of dA/dt on the true (A, U), active windows (-)",
    "rhs_error_true_AU_energy": "energy-weighted rel. RMS error of dA/dt on the true (A, U), every sample (-)",
    "curve_error": "rel. RMS error of the coefficient curves a_ki(U) over lock-in (-)",
    "curve_error_energy": "energy-weighted rel. RMS error of the curves' dA/dt at the true (A, U), every sample (-)",
    "forecast_nmse": "forecast NMSE: free simulation of each record's longest valid run, median (-)",
    "fit_time_s": "fit time (wall clock, s)",
}
#: Short panel titles for the figure.
_SHORT = {
    "coverage": "coverage (-)",
    "accuracy_flagged": "accuracy, flagged windows (-)",
    "accuracy_all": "accuracy, all windows (-)",
    "rhs_error_true_AU": "dA/dt error on true (A, U), median (-)",
    "rhs_error_true_AU_energy": "dA/dt error on true (A, U), energy (-)",
    "curve_error": "curve error, lock-in (-)",
    "curve_error_energy": "curve error, energy (-)",
    "forecast_nmse": "forecast NMSE (-)",
    "fit_time_s": "fit time (s)",
}
_HIGHER_IS_BETTER = {"coverage", "accuracy_flagged", "accuracy_all"}
LEADERBOARD_COLUMNS = ("scenario", "scenario_version", "in_class", "method", "has_verdict", *VALUES, "error")


def _value(value) -> str:
    if isinstance(value, float):
        return "nan" if math.isnan(value) else format(value, ".6g")
    return str(value)


def write_csv(rows: Sequence[dict], path: Path) -> Path:
    """``leaderboard.csv``: one row per cell, in the given order; floats to 6 significant digits."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(LEADERBOARD_COLUMNS)
    for r in rows:
        writer.writerow([_value(r[c]) for c in LEADERBOARD_COLUMNS])
    with atomic_path(path) as tmp:
        tmp.write_text(buf.getvalue(), encoding="utf-8")
    return path


def _float(text) -> float:
    try:
        return float(text)
    except (TypeError, ValueError):
        return float("nan")


def read_leaderboard(directory: str | Path) -> list[dict]:
    """The rows of ``DIR/leaderboard.csv`` (scores as floats, NaN where not scored)."""
    path = Path(directory) / "leaderboard.csv"
    try:
        with path.open(newline="", encoding="utf-8") as fh:
            rows = list(csv.DictReader(fh))
    except FileNotFoundError:
        raise InputError(f"{path}: no leaderboard table here (run `vivbench leaderboard --out {directory}`)") from None
    if not rows or set(LEADERBOARD_COLUMNS) - set(_ADDED_VALUES) - set(rows[0]):
        raise InputError(f"{path}: not a leaderboard table (expected columns {', '.join(LEADERBOARD_COLUMNS)})")
    out = []
    for r in rows:
        row = dict(r)
        try:
            row["scenario_version"] = int(r["scenario_version"])
        except ValueError:
            raise InputError(f"{path}: scenario_version {r['scenario_version']!r} is not an integer") from None
        row["in_class"] = r["in_class"] == "True"
        row["has_verdict"] = r["has_verdict"] == "True"
        for k in VALUES:
            row[k] = _float(r.get(k))
        out.append(row)
    return out


def format_score(row: dict, score: str) -> str:
    """Table text of one score of a cell, saying why a score is missing."""
    if row.get("error"):
        return "failed"
    value = row[score]
    if score == "coverage" and not row["has_verdict"]:
        return "0 (no verdict)"
    if score == "accuracy_flagged" and not row["has_verdict"]:
        return "n/a (no verdict)"
    if not math.isfinite(value):
        if score == "accuracy_flagged":
            return "- (none flagged)"
        return "n/a"
    if score == "forecast_nmse" and row.get("forecast_covered", 1.0) < 0.995:
        return f"{value:.3g} ({row['forecast_covered']:.0%} run)"
    return f"{value:.3g}"


def _scenario_cell(row: dict) -> str:
    tag = " (in-class)" if row["in_class"] else ""
    return f"{row['scenario']} v{row['scenario_version']}{tag}"


def leaderboard_markdown(rows: Sequence[dict], *, scenarios: Sequence | None = None, figure: str | None = None,
                         heading: str = "##") -> str:
    """The leaderboard as Markdown: one table per score (scenarios x methods), legend and notes.

    Parameters
    ----------
    rows : cells as in ``leaderboard.csv``
    scenarios : the :class:`~vivbench.validate.Scenario` objects, for the legend (descriptions); optional
    figure : file name of the heat-map figure to embed, or None
    heading : Markdown heading level of the sections
    """
    methods = list(dict.fromkeys(r["method"] for r in rows))
    scen = list(dict.fromkeys(r["scenario"] for r in rows))
    by = {(r["scenario"], r["method"]): r for r in rows}
    first = {r["scenario"]: r for r in rows}
    lines = ["Every method is fitted on the same records of each scenario (the identification's A, U and dA, "
             "dA by the chain's default derivative) and scored on the same windows (the identification's, by default "
             "50 s every 25 s) against the truth, by `vivbench.validate.methods.score_fitted`.", ""]
    in_class = [s for s in scen if first[s]["in_class"]]
    if in_class:
        lines += [f"**In-class scenarios: {', '.join(in_class)}.** Their truth lies inside the identification's "
                  "A^i U^j library (an exact coefficient matrix exists), so the library-based methods (windows, "
                  "campaign, varying, pysindy-cp, and any plug-in whose model class holds these polynomials) are "
                  "scored on their own model class there: an exactness check, not field performance. Read "
                  "field-like performance from the other scenarios.", ""]
    lines += ["Not applicable: a method without an identifiability verdict flags no window, so its coverage is 0 "
              "and it has no accuracy on flagged windows (\"no verdict\"); \"- (none flagged)\" means a method "
              "with a verdict flagged nothing; the curve error needs a method with coefficient curves and a truth "
              "that stores them (none with a damping drift) and self-excited truth samples (none on a forced-only "
              "bridge), the forecast NMSE a method that simulates (\"n/a\"); "
              "\"(62 % run)\" after a forecast NMSE: the median simulation left the data's range after that share of "
              "its run and the NMSE covers only the part before. The built-in windows method simulates with the "
              "model of the window in force at each time, re-identified every window step from the very data it "
              "simulates: its forecast NMSE is not that of a model fixed in advance and is not comparable with the "
              "campaign-level models'. "
              "Fit time is wall-clock time on the machine that ran the cell and varies between runs.", ""]
    if figure:
        lines += [f"![Leaderboard heat maps]({figure})", ""]
    for score in SCORES:
        better = "higher is better" if score in _HIGHER_IS_BETTER else "lower is better"
        lines += [f"{heading} {SCORE_LABELS[score]}", "", f"({better})", ""]
        lines.append("| scenario | " + " | ".join(methods) + " |")
        lines.append("|---|" + "---|" * len(methods))
        for s in scen:
            cells = [format_score(by[(s, m)], score) if (s, m) in by else "" for m in methods]
            lines.append(f"| {_scenario_cell(first[s])} | " + " | ".join(cells) + " |")
        lines.append("")
    if scenarios:
        lines += [f"{heading} Scenarios", "", "| scenario | version | events x duration | seed | description |",
                  "|---|---|---|---|---|"]
        for sc in scenarios:
            lo, hi = sc.duration
            dur = f"{lo / 60:g} min" if lo == hi else f"{lo / 60:g}-{hi / 60:g} min"
            lines.append(f"| {sc.name} | {sc.version} | {sc.n_events} x {dur} | {sc.seed} | {sc.description} |")
        lines.append("")
    failed = [r for r in rows if r.get("error")]
    if failed:
        lines += [f"{heading} Failed cells", ""]
        lines += [f"- {r['scenario']} / {r['method']}: {r['error']}" for r in failed]
        lines.append("")
    return "\n".join(lines)


def write_markdown(rows: Sequence[dict], scenarios: Sequence, path: Path, *, figure: str | None = None) -> Path:
    """``leaderboard.md``: title, then :func:`leaderboard_markdown`."""
    methods = list(dict.fromkeys(r["method"] for r in rows))
    text = (f"# Leaderboard\n\n{len(methods)} method(s) on {len(scenarios)} scenario(s) of the vivbench suite: "
            f"{', '.join(methods)}.\n\n" + leaderboard_markdown(rows, scenarios=scenarios, figure=figure))
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return path


def plot_leaderboard(rows: Sequence[dict], path: Path) -> Path:
    """``leaderboard.png``: one heat map per score, scenarios (rows) x methods (columns), values written in.

    Scores in [0, 1] share a linear colour scale; errors, NMSE and fit time use a
    logarithmic one. Cells without a score are grey and say why.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm, Normalize

    methods = list(dict.fromkeys(r["method"] for r in rows))
    scen = list(dict.fromkeys(r["scenario"] for r in rows))
    by = {(r["scenario"], r["method"]): r for r in rows}
    first = {r["scenario"]: r for r in rows}
    ncol = 4
    nrow = math.ceil(len(SCORES) / ncol)
    width = max(3.2, 0.9 * len(methods) + 1.6)
    fig, axes = plt.subplots(nrow, ncol, figsize=(ncol * width, nrow * (0.45 * len(scen) + 1.6)),
                             constrained_layout=True, squeeze=False)
    for ax, score in zip(axes.flat, SCORES):
        grid = np.full((len(scen), len(methods)), np.nan)
        for i, s in enumerate(scen):
            for j, m in enumerate(methods):
                r = by.get((s, m))
                applies = score not in ("coverage", "accuracy_flagged") or (r is not None and r["has_verdict"])
                if r is not None and not r.get("error") and applies:
                    grid[i, j] = r[score]
        finite = grid[np.isfinite(grid)]
        if score in _HIGHER_IS_BETTER:
            norm, cmap = Normalize(0.0, 1.0), "viridis"
        else:
            pos = finite[finite > 0]
            lo, hi = (pos.min(), pos.max()) if pos.size else (1e-3, 1.0)
            norm, cmap = LogNorm(lo, hi if hi > lo else lo * 10), "viridis_r"
        shown = np.ma.masked_invalid(np.where(grid > 0, grid, np.nan) if score not in _HIGHER_IS_BETTER else grid)
        ax.set_facecolor("0.85")
        im = ax.imshow(shown, cmap=cmap, norm=norm, aspect="auto")
        for i, s in enumerate(scen):
            for j, m in enumerate(methods):
                r = by.get((s, m))
                text = format_score(r, score) if r is not None else ""
                text = text.replace(" (no verdict)", "\nno verdict").replace(" (none flagged)", "\nnone").replace(
                    " (", "\n(")
                ax.text(j, i, text, ha="center", va="center", fontsize=7,
                        bbox={"facecolor": "white", "alpha": 0.6, "linewidth": 0, "pad": 1})
        ax.set_xticks(range(len(methods)))
        ax.set_xticklabels(methods, rotation=30, ha="right", fontsize=8)
        ax.set_yticks(range(len(scen)))
        ax.set_yticklabels([s + (" *" if first[s]["in_class"] else "") for s in scen], fontsize=8)
        ax.set_title(_SHORT[score], fontsize=9)
        fig.colorbar(im, ax=ax, shrink=0.8)
    for ax in list(axes.flat)[len(SCORES):]:
        ax.axis("off")
    if len(axes.flat) > len(SCORES):
        ax = list(axes.flat)[len(SCORES)]
        ax.text(0.0, 0.5, "rows: scenarios (* in-class: truth inside the\nA^i U^j library, not field performance)\n"
                "columns: methods\ngrey: not applicable or failed\n(-) dimensionless; fit time in s",
                fontsize=8, va="center", transform=ax.transAxes)
    fig.suptitle("vivbench leaderboard: scenarios x methods", fontsize=11)
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, format="png", dpi=100, metadata={"Software": None})
    plt.close(fig)
    return path
