"""Figures that put two campaigns' recovery side by side (in-library against realistic, docs/concepts.md (no inverse crime)).

Like :mod:`vivbench.report.figures`: data in, a PNG out, matplotlib's Agg
backend at a fixed size and dpi, written atomically without a software tag or
date (the same data give the same bytes), axes labelled with units, nothing
printed.

=========================  =====================================================
function                   what it shows, one colour per campaign
=========================  =====================================================
recovery_pair_figure       regime coverage and accuracy (window models and the
                           campaign model), the dA/dt error on the true (A, U)
                           as quantiles, the campaign model's regime confusion
=========================  =====================================================
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from vivbench.core.errors import InputError  # noqa: E402
from vivbench.io.netcdf import atomic_path  # noqa: E402
from vivbench.report.figure_style import DPI  # noqa: E402

__all__ = ["PAIR_COLOURS", "recovery_pair_figure"]

#: Colour of each campaign in the paired figures: the first (the in-library baseline), the second (realistic).
PAIR_COLOURS = ("#4c9be8", "#d62728")
_QUANTILES = ("q10", "q25", "q50", "q75", "q90")


def _value(x) -> float:
    """A score that may be None (JSON null) or NaN as a float (NaN when missing)."""
    return float("nan") if x is None else float(x)


def recovery_pair_figure(scores: Sequence[Mapping], labels: Sequence[str], path: str | Path, *,
                         target_error: float | None = 0.1) -> Path:
    """Regime and dA/dt recovery of two (or more) campaigns side by side.

    Parameters
    ----------
    scores : sequence of mappings, one per campaign
        Each with ``chance`` (share of the most common true regime, -),
        ``window`` and optionally ``campaign`` (None when the campaign model was
        not fitted), themselves mappings with ``coverage``,
        ``accuracy_identifiable``, ``accuracy_all`` (shares, -; None or NaN when
        undefined, e.g. no window flagged), ``error`` (quantiles ``q10``,
        ``q25``, ``q50``, ``q75``, ``q90`` of the per-window relative RMS error
        of dA/dt on the true (A, U), windows with dynamics, -) and
        ``confusion`` (4 x 4 counts, true regime by row, identified regime by
        column, all windows).
    labels : one label per campaign (legend and panel titles)
    path : output PNG
    target_error : float, optional
        A reference level drawn on the dA/dt panel (the issue's 10 % target).

    Returns
    -------
    Path

    Notes
    -----
    Panel (a): coverage, accuracy on the flagged windows and accuracy on all
    windows, for the window models and the campaign model; a missing bar is
    an undefined score (no window flagged: "none"). Short dashed lines give
    each campaign's chance level (always guessing its most common true
    regime). Panel (b): the per-window error quantiles as boxes (q25-q75) with
    whiskers (q10-q90) and the median, on a log axis. Bottom row: the campaign
    model's confusion matrices (the window models' when no campaign model
    was fitted), shares of each true regime's windows.
    """
    if len(scores) != len(labels) or len(scores) < 1:
        raise InputError(f"recovery_pair_figure needs one label per campaign; got {len(scores)} scores and "
                         f"{len(labels)} labels")
    n = len(scores)
    colours = [PAIR_COLOURS[i % len(PAIR_COLOURS)] for i in range(n)]
    models = [("window", "window models")] + ([("campaign", "campaign model")]
                                              if any(s.get("campaign") is not None for s in scores) else [])
    fig = plt.figure(figsize=(11, 8.5), constrained_layout=True)
    grid = fig.add_gridspec(2, max(n, 2), height_ratios=(1.1, 1.0))
    ax_reg = fig.add_subplot(grid[0, : max(n, 2) // 2 + (max(n, 2) % 2)])
    ax_err = fig.add_subplot(grid[0, max(n, 2) // 2 + (max(n, 2) % 2):])
    try:
        # (a) regime recovery
        quantities = (("coverage", "coverage"), ("accuracy_identifiable", "accuracy,\nflagged"),
                      ("accuracy_all", "accuracy,\nall"))
        width = 0.8 / n
        ticks, ticklabels = [], []
        x = 0.0
        for key, model_name in models:
            for q, q_label in quantities:
                for i, s in enumerate(scores):
                    m = s.get(key)
                    v = _value(None if m is None else m.get(q))
                    xi = x + (i - (n - 1) / 2) * width
                    if np.isfinite(v):
                        ax_reg.bar(xi, v, width=width * 0.95, color=colours[i], label=labels[i] if x == 0 else None)
                        ax_reg.text(xi, v + 0.01, f"{v:.2f}", ha="center", va="bottom", fontsize=7)
                    else:
                        if x == 0:
                            ax_reg.bar(xi, 0.0, width=width * 0.95, color=colours[i], label=labels[i])
                        ax_reg.text(xi, 0.01, "none" if m is not None else "n/a", ha="center", va="bottom",
                                    fontsize=7, rotation=90, color=colours[i])
                    if q == "accuracy_all" and m is not None:
                        chance = _value(s.get("chance"))
                        ax_reg.plot([xi - width / 2, xi + width / 2], [chance, chance], ls="--", color="k", lw=1.0,
                                    label="chance level (most common true regime)" if (i == 0 and key == "window")
                                    else None)
                ticks.append(x)
                ticklabels.append(q_label)
                x += 1.0
            ax_reg.text(x - 2.0, 1.08, model_name, ha="center", va="center", fontsize=9)
            x += 0.4
        ax_reg.set_xticks(ticks, ticklabels, fontsize=7)
        # Headroom above 1 for the model names and the legend, clear of the bars.
        ax_reg.set_ylim(0.0, 1.42)
        ax_reg.set_yticks(np.linspace(0.0, 1.0, 6))
        ax_reg.set_ylabel("share of window-equations (-)")
        ax_reg.set_title("(a) regime recovery (docs/concepts.md (regimes))", fontsize=10, loc="left")
        ax_reg.legend(loc="upper center", ncol=2, fontsize=7)

        # (b) dA/dt error on the true (A, U)
        x = 0.0
        ticks, ticklabels = [], []
        low = []
        for key, model_name in models:
            for i, s in enumerate(scores):
                m = s.get(key)
                err = None if m is None else m.get("error")
                xi = x + (i - (n - 1) / 2) * 0.35
                if err is None:
                    continue
                q10, q25, q50, q75, q90 = (_value(err.get(k)) for k in _QUANTILES)
                if not np.isfinite(q50):
                    continue
                low.append(q10)
                ax_err.add_patch(plt.Rectangle((xi - 0.14, q25), 0.28, q75 - q25, facecolor=colours[i], alpha=0.35,
                                               edgecolor=colours[i]))
                ax_err.plot([xi, xi], [q10, q25], color=colours[i], lw=1.0)
                ax_err.plot([xi, xi], [q75, q90], color=colours[i], lw=1.0)
                ax_err.plot([xi - 0.14, xi + 0.14], [q50, q50], color=colours[i], lw=2.0)
                ax_err.text(xi + 0.16, q50, f"{q50:.3g}", fontsize=7, va="center", color=colours[i])
            ticks.append(x)
            ticklabels.append(model_name)
            x += 1.0
        if target_error is not None:
            ax_err.axhline(target_error, color="0.4", lw=0.8, ls=":", label=f"{target_error:.0%} target")
            ax_err.legend(loc="upper right", fontsize=7)
        ax_err.set_yscale("log")
        finite_low = [v for v in low if np.isfinite(v) and v > 0]
        if finite_low:
            ax_err.set_ylim(bottom=min(finite_low) / 2)
        ax_err.set_xlim(-0.6, x - 0.4)
        ax_err.set_xticks(ticks, ticklabels, fontsize=8)
        ax_err.set_ylabel("relative RMS error of dA/dt (-)")
        ax_err.set_title("(b) dA/dt error on the true (A, U), windows with dynamics\n"
                         "box: quartiles, whiskers: 10-90 %, bar: median", fontsize=10, loc="left")

        # bottom row: confusion matrices
        key, model_name = models[-1]
        for i, s in enumerate(scores):
            ax = fig.add_subplot(grid[1, i])
            m = s.get(key)
            cm = None if m is None or m.get("confusion") is None else np.asarray(m["confusion"], dtype=float)
            if cm is None or cm.shape != (4, 4):
                ax.set_axis_off()
                ax.text(0.5, 0.5, f"{labels[i]}:\nno {model_name}", ha="center", va="center", fontsize=9)
                continue
            rows = cm.sum(axis=1, keepdims=True)
            share = np.divide(cm, rows, out=np.zeros_like(cm), where=rows > 0)
            ax.imshow(share, vmin=0.0, vmax=1.0, cmap="Greys")
            for a in range(4):
                for b in range(4):
                    ax.text(b, a, f"{int(cm[a, b])}", ha="center", va="center", fontsize=7,
                            color="w" if share[a, b] > 0.5 else "k")
            ax.set_xticks(range(4), [str(k) for k in range(1, 5)])
            ax.set_yticks(range(4), [f"{k} ({int(rows[k - 1, 0])})" for k in range(1, 5)])
            ax.set_xlabel(f"regime of the {model_name}")
            ax.set_ylabel("true regime (windows)")
            agree = np.trace(cm) / cm.sum() if cm.sum() > 0 else float("nan")
            ax.set_title(f"({'cdefgh'[i]}) {labels[i]}\n{model_name}, all windows: accuracy {agree:.3f}",
                         fontsize=9, loc="left", color=colours[i])
        with atomic_path(Path(path), suffix=".png") as tmp:
            # No software tag or date in the PNG: the same data give the same bytes.
            fig.savefig(tmp, dpi=DPI, format="png", metadata={"Software": None})
    finally:
        plt.close(fig)
    return Path(path)
