"""Figures of identified time-varying models: coefficient maps, regime timelines, decision graphs (Li et al. 2019, Figs. 5-10).

Data in, a PNG out (see :mod:`vivbench.report.figure_style`); axes carry SI units.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402
from matplotlib.colors import SymLogNorm  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402

from vivbench.core.terms import evaluate_library, feature_exponents  # noqa: E402
from vivbench.report.figure_style import REGIME_COLOURS, SECTION_COLOURS, figure_file, section_index  # noqa: E402

__all__ = ["term_scale", "coefficient_map_figure", "regime_timeline_figure", "decision_graph_figure"]


# ------------------------------------------------ Fig. 5-7: coefficient map


def term_scale(result: xr.Dataset) -> np.ndarray:
    """RMS over the event of every library term A_l^i U_l^j, shape (n_features,), in its own unit."""
    A = result["A"].values
    U = result["U"].values
    ok = np.all(np.isfinite(A), axis=1) & np.all(np.isfinite(U), axis=1)
    theta = evaluate_library(A[ok], U[ok])
    return np.sqrt(np.mean(theta**2, axis=0))


def coefficient_map_figure(result: xr.Dataset, path: str | Path, *, equation: str | None = None,
                           lock_in: tuple[float, float] | None = (5.5, 10.5)) -> Path:
    """Time-varying model of one equation: windows x library terms (paper Figs. 5c, 7).

    The colour of a cell is the coefficient times the RMS of its library term
    over the event, xi_j * rms(theta_j) in m/s: the size of that term's
    contribution to dA/dt, comparable across terms whose physical coefficients
    differ by many orders of magnitude. The scale is symmetric-logarithmic,
    linear below 1 % of the largest ``|contribution|``. Below the map: the window
    regime (hatched where not identifiable), the mean winds and the amplitudes.

    Parameters
    ----------
    result : identification result
    path : output PNG
    equation : which equation (dA_k/dt) to map (default the middle section's, S2 of three)
    lock_in : (low, high) lock-in range drawn on the wind panel, m/s (None: not drawn)
    """
    e = section_index(result["equation"].values, equation)
    equation = str(result["equation"].values[e])
    coef = result["coef"].values[:, e, :]
    scaled = coef * term_scale(result)[None, :]
    t0 = result["window_start"].values
    t1 = result["window_end"].values
    step = float(np.median(np.diff(t0))) if t0.size > 1 else float(t1[0] - t0[0])
    centre = 0.5 * (t0 + t1)
    edges_t = np.concatenate((centre - step / 2, [centre[-1] + step / 2])) / 60.0 if centre.size else np.array([0, 1])
    dA = result["dA"].values[:, e]
    rms_dA = float(np.sqrt(np.nanmean(dA**2))) if np.isfinite(dA).any() else 0.0
    big = float(np.nanmax(np.abs(scaled))) if np.isfinite(scaled).any() else 0.0
    # Linear below 1 % of the RMS of dA/dt: smaller contributions do not matter
    # to the model; larger ones (up to many decades above dA/dt, where
    # collinear terms cancel) get a decade per colour step.
    linthresh = 1e-2 * rms_dA if rms_dA > 0 else 1e-12
    vmax = max(big, 10.0 * linthresh)
    ex = feature_exponents(coef.shape[1] // 23)
    sections = [str(s) for s in result["section"].values.tolist()]
    with figure_file(path, 4, 1, figsize=(9, 10), sharex=True, constrained_layout=True,
                 gridspec_kw={"height_ratios": [5, 0.5, 1.3, 1.3]}) as (fig, axes):
        ax = axes[0]
        # gaps between segments: windows that are not adjacent are separated by white columns
        data = np.ma.masked_invalid(scaled.T)
        mesh = ax.pcolormesh(edges_t, np.arange(coef.shape[1] + 1), data, cmap="RdBu_r", shading="flat",
                             norm=SymLogNorm(linthresh=linthresh, vmin=-vmax, vmax=vmax, base=10),
                             rasterized=True)
        # group boundaries: sections and powers of A
        groups = []
        for sec in range(ex[:, 0].max() + 1):
            for i in range(4):
                rows = np.flatnonzero((ex[:, 0] == sec) & (ex[:, 1] == i))
                groups.append((rows[0], rows[-1] + 1, f"{sections[sec]}: A$^{i}$ U$^{{{ex[rows[0], 2]}..5}}$"))
        for lo, hi, _ in groups:
            ax.axhline(lo, color="k", lw=0.6 if lo % 23 else 1.4)
        ax.set_yticks([0.5 * (lo + hi) for lo, hi, _ in groups])
        ax.set_yticklabels([g[2] for g in groups], fontsize=8)
        ax.set_ylim(coef.shape[1], 0)
        ax.set_ylabel("library term (section: power of A, powers of U)")
        ax.set_title(f"(a) event {result.attrs['event_id']}: model of dA/dt at {equation}, "
                     r"coefficient $\times$ RMS of its term", fontsize=10, loc="left")
        cb = fig.colorbar(mesh, ax=ax, pad=0.01, ticks=_symlog_ticks(linthresh, vmax))
        cb.set_label(r"$\xi_j\,\mathrm{rms}(\theta_j)$ (m/s); symlog, linear below " + f"{linthresh:.1e} m/s")
        ax = axes[1]
        reg = result["regime"].values[:, e]
        ident = result["identifiable"].values[:, e].astype(bool)
        for w in range(reg.size):
            if reg[w] == 0:
                continue
            ax.axvspan(edges_t[w], edges_t[w + 1], facecolor=REGIME_COLOURS[int(reg[w])], lw=0,
                       edgecolor="k" if not ident[w] else REGIME_COLOURS[int(reg[w])],
                       hatch=None if ident[w] else "////")
        ax.set_yticks([])
        ax.set_ylabel("regime", rotation=0, ha="right", va="center", fontsize=8)
        handles = [Patch(color=c, label=f"regime {r}") for r, c in REGIME_COLOURS.items()]
        handles.append(Patch(facecolor="white", edgecolor="k", hatch="////", label="not identifiable"))
        ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.0, 1.5), fontsize=7, frameon=False)
        ax.set_title("(b) regime of each window model", fontsize=10, loc="left")
        tg = result["time"].values / 60.0
        ax = axes[2]
        for i, name in enumerate(sections):
            ax.plot(tg, result["U"].values[:, i], lw=1, color=SECTION_COLOURS.get(name), label=f"U {name}")
        if lock_in is not None:
            ax.axhspan(*lock_in, color="#4c9be8", alpha=0.1, label="lock-in range (generator default)")
        ax.set_ylabel("U (m/s)")
        ax.set_title("(c) mean wind perpendicular to the span", fontsize=10, loc="left")
        ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.05), fontsize=7, frameon=False)
        ax = axes[3]
        for i, name in enumerate(sections):
            ax.plot(tg, result["A"].values[:, i], lw=1, color=SECTION_COLOURS.get(name), label=f"A {name}")
        ax.set_ylabel("A (m)")
        ax.set_title("(d) measured amplitudes", fontsize=10, loc="left")
        ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.05), fontsize=7, frameon=False)
        ax.set_xlabel("time since event start (min)")
        ax.set_xlim(edges_t[0], edges_t[-1])
    return Path(path)


def _symlog_ticks(linthresh: float, vmax: float, per_side: int = 4) -> list[float]:
    """0 and at most ``per_side`` decades on each side, from just above ``linthresh`` to ``vmax``."""
    lo = int(np.ceil(np.log10(linthresh))) + 1
    hi = int(np.floor(np.log10(vmax)))
    if hi < lo:
        return [-vmax, 0.0, vmax]
    step = max(1, int(np.ceil((hi - lo + 1) / per_side)))
    decades = [10.0**k for k in range(hi, lo - 1, -step)]
    return [-d for d in decades] + [0.0] + decades[::-1]


# ---------------------------------------------------- Fig. 6: regime timelines


def regime_timeline_figure(results: Sequence[xr.Dataset], truth_regimes: Sequence[np.ndarray | None],
                           path: str | Path, *, equation: str | None = None) -> Path:
    """Identified regime per window against the truth, for a few events (paper Fig. 6, Table 1).

    Parameters
    ----------
    results : identification results (one per event, 1-4 events)
    truth_regimes : per result, the true regime of each window, shape (n_windows, n_sections)
        (:func:`vivbench.validate.truth_window_regimes`), or None for field data
    path : output PNG
    equation : which equation's regime is shown (default the middle section's, S2 of three)

    Notes
    -----
    Each window is drawn over its central ``step`` seconds (windows overlap).
    Hatched: the identified regime is not identifiable (an equally good model
    has another regime). The title of each event gives the share of
    identifiable windows and the agreement with the truth, over all windows
    and over identifiable ones.
    """
    if len(results) != len(truth_regimes):
        raise ValueError(f"got {len(results)} results but {len(truth_regimes)} truth arrays")
    n = len(results)
    if n == 0:
        raise ValueError("regime_timeline_figure needs at least one result")
    with figure_file(path, n, 1, figsize=(9, 1.0 + 1.45 * n), constrained_layout=True, squeeze=False) as (fig, axes):
        for ax, res, truth in zip(axes[:, 0], results, truth_regimes):
            e = section_index(res["equation"].values, equation)
            name = str(res["equation"].values[e])
            t0 = res["window_start"].values
            t1 = res["window_end"].values
            step = float(np.median(np.diff(t0))) if t0.size > 1 else float(t1[0] - t0[0])
            centre = 0.5 * (t0 + t1) / 60.0
            half = step / 120.0
            reg = res["regime"].values[:, e]
            ident = res["identifiable"].values[:, e].astype(bool)
            rows = [("identified", 1.0, reg, ident)]
            if truth is not None:
                rows.append(("truth", 0.0, np.asarray(truth)[:, e], np.ones_like(ident)))
            for _label, y0, r, ok in rows:
                for w in range(r.size):
                    if r[w] == 0:
                        continue
                    ax.bar(centre[w], 0.8, width=2 * half, bottom=y0 + 0.1, color=REGIME_COLOURS[int(r[w])],
                           hatch=None if ok[w] else "////", edgecolor="white" if ok[w] else "k", linewidth=0)
            ax.set_yticks([1.5, 0.5][: len(rows)])
            ax.set_yticklabels(["identified", "truth"][: len(rows)])
            ax.set_ylim(0 if truth is not None else 1, 2)
            title = f"event {res.attrs['event_id']}, equation {name}: identifiable {ident.mean():.0%} of windows"
            if truth is not None:
                tr = np.asarray(truth)[:, e]
                scored = (tr > 0) & (reg > 0)
                agree = reg[scored] == tr[scored]
                acc_all = agree.mean() if agree.size else float("nan")
                ok_s = ident[scored]
                acc_id = agree[ok_s].mean() if ok_s.any() else float("nan")
                title += f"; agreement {acc_all:.0%} (all), "
                title += "n/a (identifiable: none)" if not ok_s.any() else f"{acc_id:.0%} (identifiable)"
            ax.set_title(title, fontsize=9, loc="left")
            ax.set_xlim(centre.min() - 2 * half if centre.size else 0, centre.max() + 2 * half if centre.size else 1)
            ax.set_xlabel("time since event start (min)")
        handles = [Patch(color=c, label=f"regime {r}") for r, c in REGIME_COLOURS.items()]
        handles.append(Patch(facecolor="white", edgecolor="k", hatch="////", label="not identifiable"))
        fig.legend(handles=handles, loc="outside lower center", ncol=5, fontsize=8, frameon=False)
    return Path(path)


# ------------------------------------------------- Figs. 8-10: decision graph


def decision_graph_figure(rho, delta, labels, centers, path: str | Path, *, embedding=None, truth=None,
                          title: str = "") -> Path:
    """Decision graph and clusters (paper Figs. 8-10).

    Parameters
    ----------
    rho, delta : array_like, shape (n,)
        Local density (1) and distance to the nearest denser point (feature units).
    labels : array_like of int, shape (n,)
        Cluster of each point, 0..k-1.
    centers : array_like of int
        Indices of the cluster centres.
    path : output PNG
    embedding : array_like, shape (n, 2), optional
        2-D coordinates of the points (e.g. the first two principal
        components of the features) for the cluster panel.
    truth : array_like of int, shape (n,), optional
        True regime (1..4, 0: none) of each point: adds a panel with the
        share of each cluster's points in each true regime.
    title : figure title
    """
    rho = np.asarray(rho, dtype=float)
    delta = np.asarray(delta, dtype=float)
    labels = np.asarray(labels, dtype=int)
    centers = np.asarray(centers, dtype=int)
    k = int(labels.max()) + 1 if labels.size else 0
    cmap = plt.get_cmap("tab10" if k <= 10 else "tab20")
    colours = [cmap(i % cmap.N) for i in range(max(k, 1))]
    panels = 1 + (embedding is not None) + (truth is not None)
    with figure_file(path, 1, panels, figsize=(4.2 * panels, 4.2), constrained_layout=True,
                 squeeze=False) as (fig, axes):
        axes = list(axes[0])
        ax = axes.pop(0)
        ax.scatter(rho, delta, s=8, c=[colours[lab] for lab in labels], alpha=0.6, lw=0)
        ax.scatter(rho[centers], delta[centers], s=60, facecolor="none", edgecolor="k", lw=1.2, label="centres")
        for i, c in enumerate(centers):
            ax.annotate(str(labels[c]), (rho[c], delta[c]), textcoords="offset points", xytext=(-6, 4), fontsize=8,
                        ha="right")
        ax.set_xlabel(r"local density $\rho$ (1)")
        ax.set_ylabel(r"distance to nearest denser point $\delta$ (feature units)")
        ax.set_title(f"(a) decision graph, {k} cluster{'s' if k != 1 else ''}", fontsize=10, loc="left")
        ax.margins(0.1)
        ax.legend(loc="lower right", bbox_to_anchor=(1.0, 1.0), fontsize=8, frameon=False, borderaxespad=0.1)
        if embedding is not None:
            emb = np.asarray(embedding, dtype=float)
            ax = axes.pop(0)
            ax.scatter(emb[:, 0], emb[:, 1], s=8, c=[colours[lab] for lab in labels], alpha=0.7, lw=0)
            ax.scatter(emb[centers, 0], emb[centers, 1], s=60, facecolor="none", edgecolor="k", lw=1.2)
            ax.set_xlabel("principal component 1 (feature units)")
            ax.set_ylabel("principal component 2 (feature units)")
            ax.set_title("(b) clusters of the window models", fontsize=10, loc="left")
        if truth is not None:
            truth = np.asarray(truth, dtype=int)
            ax = axes.pop(0)
            table = np.zeros((k, 4))
            for lab in range(k):
                m = (labels == lab) & (truth > 0)
                for r in range(1, 5):
                    table[lab, r - 1] = np.mean(truth[m] == r) if m.any() else np.nan
            im = ax.imshow(table, cmap="Greys", vmin=0, vmax=1, aspect="auto")
            for (i, j), val in np.ndenumerate(table):
                if np.isfinite(val):
                    ax.text(j, i, f"{val:.2f}", ha="center", va="center", fontsize=7,
                            color="w" if val > 0.5 else "k")
            counts = np.bincount(labels, minlength=k)
            ax.set_yticks(range(k))
            ax.set_yticklabels([f"{lab} (n={counts[lab]})" for lab in range(k)], fontsize=8)
            ax.set_xticks(range(4))
            ax.set_xticklabels([f"{r}" for r in range(1, 5)])
            ax.set_xlabel("true regime")
            ax.set_ylabel("cluster")
            ax.set_title("(c) share of each cluster per true regime", fontsize=10, loc="left")
            fig.colorbar(im, ax=ax, pad=0.01).set_label("share of the cluster's windows (1)")
        if title:
            fig.suptitle(title, fontsize=10)
    return Path(path)
