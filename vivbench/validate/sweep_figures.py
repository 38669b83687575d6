"""Figures and headline numbers of a recovery sweep (from its table rows)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from scipy.stats import spearmanr  # noqa: E402

from vivbench.io.netcdf import atomic_path
from vivbench.validate.sweep_parameters import PARAMETERS

__all__ = ["plot_recovery", "sweep_summary"]

# (column, panel title, y label); the accuracy panel also shows the chance level.
_PANELS = (
    ("accuracy_all", "regime accuracy", "share of window-equations (-)"),
    ("coverage", "coverage (flagged identifiable)", "share of window-equations (-)"),
    ("rhs_median_rel_error_active", "error of identified dA/dt", "median relative RMS error (-)"),
    ("rhs_error_true_AU_energy", "error of dA/dt on the true (A, U)", "energy-weighted relative RMS error (-)"),
)
_MAX_DISCRETE = 12  # more distinct x values than this are binned


def _axis_label(name: str) -> str:
    return PARAMETERS[name].axis_label


def _column(rows, name: str) -> np.ndarray:
    return np.array([float(r.get(name, math.nan)) for r in rows], dtype=float)


def _medians(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Median of y per distinct x, or per equal-count bin of x when x takes many values."""
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    if x.size == 0:
        return np.array([]), np.array([])
    values = np.unique(x)
    if values.size <= _MAX_DISCRETE:
        return values, np.array([np.median(y[x == v]) for v in values])
    order = np.argsort(x, kind="stable")
    bins = np.array_split(order, 6)
    return np.array([np.median(x[b]) for b in bins]), np.array([np.median(y[b]) for b in bins])


def plot_recovery(rows: Sequence[dict], parameters: Sequence[str], path: str | Path, *,
                  varied: Sequence[str] = ()) -> Path:
    """Recovery against sweep parameters: one row of panels per parameter.

    Panels: regime accuracy over all scored window-equations (with the share of
    the most common true regime, the accuracy of always guessing it, as the
    chance level), coverage (share flagged identifiable), and the median
    relative error of the identified dA/dt on windows with dynamics, and the
    error of dA/dt on the true (A, U) energy-weighted over every sample (the
    large amplitudes the median hides; NaN in tables written before it). Each
    campaign is a dot; the line joins the medians per parameter value.

    Parameters
    ----------
    rows : table rows of the sweep (dicts with the parameter and metric columns)
    parameters : columns to put on the x axes (see ``SWEEP_PARAMETERS``)
    path : PNG written atomically (byte-identical for identical rows)
    varied : parameters the sweep varied; the others are marked "not varied"
    """
    path = Path(path)
    ok_rows = [r for r in rows if not r.get("error")]
    n_rows = len(parameters)
    height = 3.2 * n_rows + 0.6
    fig, axes = plt.subplots(n_rows, len(_PANELS), figsize=(4 * len(_PANELS), height), squeeze=False)
    # Fixed margins: constrained layout costs more than the rest of the figure.
    fig.subplots_adjust(left=0.065, right=0.985, bottom=0.75 / height, top=1 - 0.55 / height, wspace=0.3,
                        hspace=0.75 / 3.2)
    for i, name in enumerate(parameters):
        x = _column(ok_rows, name)
        for j, (col, title, ylabel) in enumerate(_PANELS):
            ax = axes[i, j]
            y = _column(ok_rows, col)
            ax.plot(x, y, "o", color="0.55", ms=4, alpha=0.8, label="campaign")
            mx, my = _medians(x, y)
            ax.plot(mx, my, "-", color="C0", lw=2, marker="s", ms=5, label="median, window models")
            pooled = _column(ok_rows, f"campaign_model_{col}") if ok_rows and f"campaign_model_{col}" in ok_rows[0] else None
            if pooled is not None and np.isfinite(pooled).any():
                px, py = _medians(x, pooled)
                ax.plot(px, py, "-", color="C2", lw=2, marker="^", ms=5, label="median, campaign model (vivbench pool)")
            if col == "accuracy_all":
                cx, cy = _medians(x, _column(ok_rows, "truth_majority_share"))
                ax.plot(cx, cy, "--", color="C3", lw=1.2, label="chance (always the most common true regime)")
                ax.set_ylim(-0.03, 1.03)
            elif col == "coverage":
                ax.set_ylim(-0.03, 1.03)
            else:
                pos = y[np.isfinite(y) & (y > 0)]
                if pos.size and pos.max() / pos.min() >= 20:
                    ax.set_yscale("log")
            finite = x[np.isfinite(x)]
            if finite.size and finite.min() > 0 and finite.max() / finite.min() >= 10:
                ax.set_xscale("log")
            label = _axis_label(name)
            if name not in varied:
                label += " — not varied"
            ax.set_xlabel(label)
            ax.set_ylabel(ylabel)
            ax.set_title(title, fontsize=10)
            ax.grid(alpha=0.3)
            if i == 0 and j == 0:
                ax.legend(fontsize=7, loc="best")
    n_failed = len(rows) - len(ok_rows)
    fig.suptitle(f"recovery over {len(ok_rows)} campaigns" + (f" ({n_failed} failed, not shown)" if n_failed else ""),
                 fontsize=11)
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=100, metadata={"Software": None})
    plt.close(fig)
    return path


def _finite_or_none(value: float) -> float | None:
    return float(value) if value is not None and math.isfinite(value) else None


def _median(rows, col: str) -> float | None:
    y = _column(rows, col)
    y = y[np.isfinite(y)]
    return _finite_or_none(float(np.median(y))) if y.size else None


def sweep_summary(rows: Sequence[dict], varied: Sequence[str], n_tasks: int) -> dict:
    """Headline numbers of a sweep: a flat dict (NaN and undefined values as None).

    Medians over the campaigns that finished, and for each varied parameter the
    Spearman rank correlation of the campaigns' regime accuracy and dA/dt error
    with it (None with fewer than three campaigns or a constant column).
    """
    ok_rows = [r for r in rows if not r.get("error")]
    out: dict[str, object] = {
        "campaigns_total": int(n_tasks),
        "campaigns_finished": len(ok_rows),
        "campaigns_failed": len(rows) - len(ok_rows),
        "varied_parameters": ",".join(varied),
        "n_window_equations": int(np.nansum(_column(ok_rows, "n_window_equations"))) if ok_rows else 0,
    }
    for col in ("accuracy_all", "accuracy_identifiable", "truth_majority_share", "coverage",
                "rhs_median_rel_error", "rhs_median_rel_error_active", "campaign_model_coverage", "campaign_model_accuracy_all",
                "campaign_model_accuracy_identifiable", "campaign_model_rhs_median_rel_error_active", "rhs_error_true_AU_median_active",
                "rhs_error_true_AU_energy", "campaign_model_rhs_error_true_AU_median_active",
                "campaign_model_rhs_error_true_AU_energy"):
        out[f"median_{col}"] = _median(ok_rows, col)
    for name in varied:
        x = _column(ok_rows, name)
        for col in ("accuracy_all", "rhs_median_rel_error_active"):
            y = _column(ok_rows, col)
            m = np.isfinite(x) & np.isfinite(y)
            rho = None
            if m.sum() >= 3 and np.ptp(x[m]) > 0 and np.ptp(y[m]) > 0:
                rho = _finite_or_none(float(spearmanr(x[m], y[m]).statistic))
            out[f"spearman_{col}_vs_{name}"] = rho
    return out
