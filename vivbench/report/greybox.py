"""Figures and the report section of the grey-box refit (``vivbench greybox``, docs/field_workflow.md (the grey-box reference)).

- :func:`greybox_functions_figure`: Y1, e1, e2, C_L against reduced velocity
  with their bands, beside the truth's functions when known.
- :func:`greybox_curves_figure`: the coefficient curves a_ki(U) of the
  reference section (docs/concepts.md (coefficient curves)) of the grey-box model, the campaign model
  and the truth.
- :func:`greybox_simulation_figure`: measured and simulated envelopes of a few events.
- :func:`greybox_yaw_figure`: the fitted yaw factor on Y1 and C_L with its band,
  beside the truth's when known.
- :func:`greybox_section`: the Markdown of the report's grey-box section from
  a ``vivbench greybox`` output directory.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from urllib.parse import quote

import matplotlib

matplotlib.use("Agg")
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402

from vivbench.core.terms import reference_section  # noqa: E402
from vivbench.io.netcdf import atomic_path  # noqa: E402
from vivbench.report.figure_style import figure_file  # noqa: E402

__all__ = ["greybox_functions_figure", "greybox_curves_figure", "greybox_simulation_figure", "greybox_yaw_figure",
           "greybox_section", "GREYBOX_FIGURES"]

_UNITS = ("m/s", "1/s", "1/(m s)", "1/(m$^2$ s)")
_COLOURS = {"greybox": "#d95f02", "campaign": "#7570b3", "truth": "k"}
#: The figures ``vivbench greybox`` writes, in report order.
GREYBOX_FIGURES = ("greybox_functions.png", "greybox_yaw.png", "greybox_curves.png", "greybox_simulations.png",
                   "greybox_benchmark.png")


def greybox_functions_figure(phys: xr.Dataset, path, *, truth: dict | None = None) -> Path:
    """Y1, e1, e2 and C_L of the grey-box model with bands against reduced velocity.

    Parameters
    ----------
    phys : xarray.Dataset of :meth:`vivbench.models.GreyBoxRefit.physical_curves`
    path : output PNG
    truth : dict or None
        ``{"Ur": (n,), "Y1": (n,), ...}`` the truth's functions (yaw 0), drawn in black.
    """
    ur = phys["reduced_velocity"].values
    with figure_file(path, 2, 2, figsize=(10, 7), constrained_layout=True, sharex=True) as (fig, axes):
        for ax, name in zip(axes.ravel(), ("Y1", "e1", "e2", "C_L")):
            if truth is not None and name in truth:
                sel = (truth["Ur"] >= ur.min()) & (truth["Ur"] <= ur.max())
                ax.plot(truth["Ur"][sel], truth[name][sel], color=_COLOURS["truth"], lw=1.8, label="truth (yaw 0)")
            ax.fill_between(ur, phys[f"{name}_lower"].values, phys[f"{name}_upper"].values, color=_COLOURS["greybox"],
                            alpha=0.25, lw=0, label="grey-box: 95 % band")
            ax.plot(ur, phys[name].values, color=_COLOURS["greybox"], lw=1.4, ls="--", label="grey-box")
            ax.axhline(0.0, color="0.6", lw=0.6, zorder=0)
            ax.set_ylabel(f"{name} (-)")
            ax.set_title(f"{name} against reduced velocity", fontsize=10, loc="left")
        for ax in axes[1]:
            ax.set_xlabel("reduced velocity U/(f D) (-)")
        axes[0, 0].legend(loc="best", fontsize=8)
    return Path(path)


def greybox_yaw_figure(yaw: xr.Dataset, path, *, truth: np.ndarray | None = None,
                       measured: np.ndarray | None = None) -> Path:
    """The yaw factor 1 - c sin^2(yaw) on Y1 and C_L with its band against the yaw angle.

    Parameters
    ----------
    yaw : xarray.Dataset of :meth:`vivbench.models.GreyBoxRefit.yaw_curve`
    path : output PNG
    truth : ndarray, shape (n_yaw,), or None
        The truth's factor at the same angles, drawn in black.
    measured : ndarray or None, degrees
        Measured yaw angles of the fitted records (their range is shaded).
    """
    psi = yaw["yaw"].values
    with figure_file(path, 1, 1, figsize=(6, 4), constrained_layout=True) as (fig, ax):
        if measured is not None and np.isfinite(measured).any():
            ax.axvspan(np.nanmin(measured), np.nanmax(measured), color="0.9", label="measured yaw range")
        if truth is not None:
            ax.plot(psi, truth, color=_COLOURS["truth"], lw=1.8, label="truth")
        ax.fill_between(psi, yaw["yaw_factor_lower"].values, yaw["yaw_factor_upper"].values,
                        color=_COLOURS["greybox"], alpha=0.25, lw=0, label="grey-box: 95 % band")
        ax.plot(psi, yaw["yaw_factor"].values, color=_COLOURS["greybox"], lw=1.4, ls="--",
                label=f"grey-box: 1 - {float(yaw['yaw_coef']):.3g} sin$^2$(yaw)" if int(yaw.attrs.get("yaw_used", 0))
                else "grey-box: no yaw measured (factor 1)")
        ax.set_xlabel("yaw: mean wind's angle to the span's normal (degree)")
        ax.set_ylabel("factor on Y1 and C_L (-)")
        ax.set_title("yaw factor", fontsize=10, loc="left")
        ax.legend(loc="lower center", fontsize=8)
    return Path(path)


def greybox_curves_figure(curves: xr.Dataset, path, *, campaign: xr.Dataset | None = None,
                          truth: tuple[np.ndarray, np.ndarray] | None = None) -> Path:
    """Coefficient curves a_ki(U) of the reference section: grey-box, campaign model and truth."""
    sections = [str(s) for s in curves["equation"].values]
    k = reference_section(len(sections))
    wind = curves["wind"].values
    with figure_file(path, 2, 2, figsize=(10, 7), constrained_layout=True, sharex=True) as (fig, axes):
        for i, ax in enumerate(axes.ravel()):
            vals = [curves["curves"].values[k, i]]
            if truth is not None:
                tc, tw = truth
                sel = (tw >= wind.min()) & (tw <= wind.max())
                ax.plot(tw[sel], tc[k, i, sel], color=_COLOURS["truth"], lw=1.8, label="truth (yaw 0)")
                vals.append(tc[k, i, sel])
            if campaign is not None:
                cw = campaign["wind"].values
                if "curves_lower" in campaign:
                    ax.fill_between(cw, campaign["curves_lower"].values[k, i], campaign["curves_upper"].values[k, i],
                                    color=_COLOURS["campaign"], alpha=0.15, lw=0)
                ax.plot(cw, campaign["curves"].values[k, i], color=_COLOURS["campaign"], lw=1.2, ls=":",
                        label="campaign model")
                vals.append(campaign["curves"].values[k, i])
            ax.fill_between(wind, curves["curves_lower"].values[k, i], curves["curves_upper"].values[k, i],
                            color=_COLOURS["greybox"], alpha=0.25, lw=0, label="grey-box: 95 % band")
            ax.plot(wind, curves["curves"].values[k, i], color=_COLOURS["greybox"], lw=1.4, ls="--", label="grey-box")
            ax.axhline(0.0, color="0.6", lw=0.6, zorder=0)
            v = np.concatenate([np.asarray(x)[np.isfinite(x)] for x in vals] + [np.zeros(1)])
            lo, hi = float(v.min()), float(v.max())
            pad = 0.15 * (hi - lo) if hi > lo else 1e-12
            ax.set_ylim(lo - pad, hi + pad)
            ax.set_ylabel(f"a$_{{{i}}}$(U) at {sections[k]} ({_UNITS[i]})")
            ax.set_title(f"order {i}: coefficient of A$^{{{i}}}$ in dA/dt", fontsize=10, loc="left")
        for ax in axes[1]:
            ax.set_xlabel("mean wind speed U (m/s)")
        axes[0, 0].legend(loc="best", fontsize=8)
    return Path(path)


def greybox_simulation_figure(sims: list, path) -> Path:
    """Measured and simulated envelopes of the reference section: ``sims`` is a list of (event_id, Simulation)."""
    n = max(len(sims), 1)
    with figure_file(path, n, 1, figsize=(10, 2.4 * n), constrained_layout=True, squeeze=False) as (fig, axes):
        for ax, (eid, sim) in zip(axes[:, 0], sims):
            k = reference_section(sim.A_sim.shape[1])
            ax.plot(sim.t / 60.0, sim.A_meas[:, k], color="0.4", lw=1.0, label="measured A")
            ax.plot(sim.t / 60.0, sim.A_sim[:, k], color=_COLOURS["greybox"], lw=1.2, ls="--",
                    label="grey-box simulation")
            ax.set_ylabel(f"A at S{k + 1} (m)")
            ax.set_title(f"{eid}: NMSE {np.nanmean(sim.nmse):.3g} (mean over sections)", fontsize=10, loc="left")
        axes[-1, 0].set_xlabel("time (min)")
        axes[0, 0].legend(loc="best", fontsize=8)
    return Path(path)


def _isnum(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _fmt(x) -> str:
    if isinstance(x, bool) or x is None:
        return str(x)
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    if isinstance(x, float):
        return "n/a" if not np.isfinite(x) else f"{x:.4g}"
    return str(x)


_COMPARED = (
    ("a_k1 (net linear growth rate) error over lock-in", "truth_curve_error_linear", "truth_campaign_curve_error_linear", "<= 0.10"),
    ("dA/dt from the curves, error over self-excited samples", "truth_curve_error_total", "truth_campaign_curve_error_total", "<= 0.10 (second bridge)"),
    ("dA/dt from the curves at the true (A, U), energy-weighted over every sample", "truth_curve_error_energy",
     "truth_campaign_curve_error_energy", "-"),
    ("dA/dt on the true (A, U), median over windows with dynamics", "truth_rhs_error_true_AU_median_active", None, "-"),
    ("dA/dt on the true (A, U), energy-weighted over every sample", "truth_rhs_error_true_AU_energy", None, "-"),
    ("band coverage of the truth's a_k1 over lock-in", "truth_linear_band_coverage", "truth_campaign_linear_band_coverage", "1"),
    ("Y1 error over lock-in", "truth_y1_error", None, "<= 0.10"),
    ("band coverage of the truth's Y1 over lock-in", "truth_y1_band_coverage", None, "1"),
    ("band coverage of a_k1, posterior bands", "truth_posterior_linear_band_coverage", None, "1"),
    ("band coverage of a_k1, sandwich bands (variance only)", "truth_sandwich_linear_band_coverage", None, "1"),
    ("band coverage of a_k1, sandwich + bias bands", "truth_sandwich_bias_linear_band_coverage", None, "1"),
    ("median simulation NMSE per event", "nmse_median", None, "<= 0.01"),
    ("share of flagged windows with the true regime", "truth_regime_precision_identifiable", None, ">= 0.95"),
    ("regime coverage (windows flagged identifiable)", "regime_coverage", None, "-"),
)


def greybox_section(directory, out_dir, written: list, max_rows: int = 40) -> list[str]:
    """Markdown lines of the report's grey-box section from a ``vivbench greybox`` output directory.

    The figures are copied into ``out_dir`` (their names appended to ``written``).
    """
    directory = Path(directory)
    out = ["## Grey-box reference refit (`vivbench greybox`)", ""]
    summary_path = directory / "summary.json"
    if not summary_path.is_file():
        return out + [f"**Not run**: `{directory}` holds no `summary.json` of `vivbench greybox`.", ""]
    summary = json.loads(summary_path.read_text())
    cmd = summary.get("command", f"vivbench greybox ... --out {directory}")
    out += ["The averaged Simiu-Scanlan amplitude equation (docs/concepts.md (the truth)) with B-spline functions Y1, e1, e2, C_L of "
            "the reduced velocity, fitted by output error to the envelopes of all events at once (CasADi multiple "
            "shooting, Gauss-Newton). Bands (delta method): "
            f"{summary.get('band') or 'block-sandwich covariance (files written before the band choice)'}. "
            f"Penalty {_fmt(summary.get('penalty'))}: {summary.get('penalty_criterion') or 'given'}.", ""]
    if any(key in summary for _, key, _, _ in _COMPARED[:5]):
        out += ["Against the truth (issue 14 targets beside the measured numbers; the campaign model of "
                "`vivbench pool` scored the same way):", "", "| quantity | grey-box | campaign model | target |",
                "|---|---|---|---|"]
        out += [f"| {label} | {_fmt(summary.get(key))} | {_fmt(summary.get(ckey)) if ckey else '-'} | {target} |"
                for label, key, ckey, target in _COMPARED]
        out.append("")
    rows = [f"| {k} | {_fmt(v)} |" for k, v in summary.items() if k != "command" and not isinstance(v, (dict, list))]
    out += ["| quantity | value |", "|---|---|", *rows, "", f"Produced by `{cmd}`.", ""]
    events = directory / "greybox_events.csv"
    if events.is_file():
        import csv

        with events.open(newline="") as fh:
            table = list(csv.reader(fh))
        if table:
            head, body = table[0], table[1:max_rows + 1]
            out += [f"Per-event simulation from the first sample with the measured wind (`{events.name}`, "
                    f"{len(table) - 1} events):", "", "| " + " | ".join(head) + " |",
                    "|" + "---|" * len(head)]
            out += ["| " + " | ".join(_fmt(float(c)) if _isnum(c) else c for c in row) + " |" for row in body]
            out.append("")
    for name in GREYBOX_FIGURES:
        src = directory / name
        if not src.is_file():
            continue
        fname = f"greybox_{name}" if not name.startswith("greybox_") else name
        with atomic_path(Path(out_dir) / fname, suffix=".png") as tmp:
            shutil.copyfile(src, tmp)
        written.append(fname)
        out += [f"![grey-box: {src.stem}]({quote(fname)})", "", f"*{name}* from `{directory}`.", ""]
    return out
