"""The report's figures, one function per figure of the paper (Li et al. 2019).

Every function takes data (an event tree, identification results as
``xarray.Dataset``, or plain arrays) and an output path, draws with
matplotlib's Agg backend at a fixed size and dpi, and writes the PNG
atomically without a software tag or date, so the same data give the same
bytes. Axes carry SI units. The functions print nothing and return the path.

=========================  =====================================================
function                   paper figure
=========================  =====================================================
sensor_layout_figure       Fig. 1 (sensor network) and Fig. 3(a) (mode shape)
wind_figure                Fig. 2 (wind preprocessing)
time_frequency_figure      Fig. 3(b, c) (acceleration and its time-frequency map)
displacement_figure        Fig. 4 (displacement, envelope, dA/dt)
coefficient_map_figure     Figs. 5(c), 6, 7 (time-varying model of an event)
regime_timeline_figure     Fig. 6 and Table 1 (regimes of three events), with truth
decision_graph_figure      Figs. 8-10 (decision graph, clusters)
forecast_figure            Figs. 11-12 (simulation and forecasts)
model_forecast_figure      Figs. 11-12 for any model of the protocol (``simulate``)
curves_figure              coefficient curves a_i(U) against the truth (docs/concepts.md (coefficient curves)),
                           drawn like aerodynamic derivatives
=========================  =====================================================

The figures of single events (Figs. 1-4) are drawn here; those of identified
models in :mod:`vivbench.report.model_figures`, of forecasts and curves in
:mod:`vivbench.report.forecast_figures`, with the common style in
:mod:`vivbench.report.figure_style`; all are importable from here.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402
from scipy import signal  # noqa: E402

from vivbench.core.errors import InputError  # noqa: E402
from vivbench.preprocess.config import PreprocessConfig  # noqa: E402
from vivbench.preprocess.vibration import displacement, envelope, modal_frequency  # noqa: E402
from vivbench.preprocess.wind import mean_wind, perpendicular_speed, wind_speed_direction  # noqa: E402
from vivbench.report.figure_style import (DPI, REGIME_COLOURS, SECTION_COLOURS, count_word, figure_file,  # noqa: E402
                                          section_index)
from vivbench.report.forecast_figures import curves_figure, forecast_figure, model_forecast_figure  # noqa: E402
from vivbench.report.model_figures import (coefficient_map_figure, decision_graph_figure,  # noqa: E402
                                           regime_timeline_figure, term_scale)


__all__ = [
    "DPI",
    "REGIME_COLOURS",
    "sensor_layout_figure",
    "wind_figure",
    "time_frequency_figure",
    "displacement_figure",
    "coefficient_map_figure",
    "regime_timeline_figure",
    "decision_graph_figure",
    "forecast_figure",
    "model_forecast_figure",
    "curves_figure",
    "term_scale",
]

# Plotting more points than pixels only slows the drawing down.
_MAX_POINTS = 20000


def _step(n: int) -> int:
    return max(1, n // _MAX_POINTS)


def _generator_config(tree: xr.DataTree) -> dict | None:
    if "truth" not in tree.children or "config_json" not in tree["truth"].attrs:
        return None
    cfg = json.loads(tree["truth"].attrs["config_json"])
    return cfg.get("generator", cfg)


def _longest_finite_run(x: np.ndarray) -> slice:
    """Longest run of rows of ``x`` (n, k) that are finite in every column."""
    ok = np.all(np.isfinite(x), axis=1)
    if not ok.any():
        raise InputError("the record holds no finite sample")
    edges = np.diff(np.concatenate(([0], ok.astype(np.int8), [0])))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    k = int(np.argmax(ends - starts))
    return slice(int(starts[k]), int(ends[k]))



# ---------------------------------------------------------------- Fig. 1: layout


def sensor_layout_figure(tree: xr.DataTree, path: str | Path) -> Path:
    """Sketch of the deck with the sensors at S1..Sn and the mode shape (paper Figs. 1 and 3a).

    Parameters
    ----------
    tree : xarray.DataTree
        An event (docs/formats.md). The span length and the mode shape phi_k come from
        the generator configuration (``/truth`` attribute ``config_json``) when
        present; otherwise positions are drawn as fractions of the span and
        the mode shape is left out (field data do not carry it).
    path : output PNG

    Returns
    -------
    Path
    """
    sections = [str(s) for s in tree["accel"]["section"].values.tolist()]
    cfg = _generator_config(tree)
    structure = (cfg or {}).get("structure", {})
    span = float(structure.get("span_length", 1.0))
    unit = "m" if "span_length" in structure else "fraction of span"
    phi = structure.get("mode_shape")
    freq = structure.get("frequency")
    x = span * np.arange(1, len(sections) + 1) / (len(sections) + 1)
    az = float(tree.attrs["span_azimuth_deg"])
    with figure_file(path, 2, 1, figsize=(8, 5.2), sharex=True, constrained_layout=True,
                 gridspec_kw={"height_ratios": [1.2, 1]}) as (fig, (ax, ax2)):
        ax.plot([0, span], [0, 0], color="k", lw=3, solid_capstyle="butt", label="deck (main span)")
        for xt in (0, span):
            ax.plot([xt, xt], [-0.6, 1.6], color="0.3", lw=4)
        ax.scatter(x, np.full_like(x, 0.9), marker="^", s=70, color="#1f77b4", zorder=3,
                   label="3-D ultrasonic anemometer (u, v, w; 32 Hz)")
        ax.scatter(x, np.zeros_like(x), marker="s", s=60, color="#d62728", zorder=3,
                   label="vertical accelerometer (50 Hz)")
        for xi, name in zip(x, sections):
            ax.plot([xi, xi], [0, 0.9], color="0.6", lw=0.8, ls=":")
            ax.annotate(name, (xi, -0.35), ha="center", va="top", fontsize=9)
        ax.set_ylim(-1.0, 2.4)
        ax.set_yticks([])
        ax.set_title(f"sensor layout, event {tree.attrs['event_id']}; span axis azimuth {az:.0f} deg from north",
                     fontsize=10)
        ax.legend(loc="upper center", fontsize=8, ncol=3, frameon=False)
        ax2.axhline(0, color="0.7", lw=0.8)
        if phi is not None:
            phi = np.asarray(phi, dtype=float)
            xs = np.concatenate(([0.0], x, [span]))
            ys = np.concatenate(([0.0], phi, [0.0]))
            ax2.plot(xs, ys, color="0.5", ls="--", lw=1,
                     label="linear between sections and towers (shape between sections not modelled)")
            ax2.plot(x, phi, "o", color="k", label=r"mode shape $\phi_k$ (generator configuration)")
            for xi, p in zip(x, phi):
                ax2.annotate(f"{p:.3g}", (xi, p), textcoords="offset points", xytext=(6, -12), fontsize=8)
            ftxt = f" of the {float(freq):.3g} Hz mode" if freq is not None else ""
            ax2.set_title(f"vertical mode shape{ftxt}", fontsize=10)
            ax2.set_ylim(min(-0.1, ys.min() - 0.1), ys.max() * 1.35)
            ax2.legend(loc="upper right", fontsize=7, frameon=False)
        else:
            ax2.text(0.5, 0.5, "no generator configuration in this event file: mode shape unknown", ha="center", va="center",
                     transform=ax2.transAxes)
        ax2.set_ylabel(r"$\phi$ (normalised, 1)")
        ax2.set_xlabel(f"position along the main span ({unit})")
        ax2.set_xlim(-0.03 * span, 1.03 * span)
    return Path(path)


# ------------------------------------------------------------------ Fig. 2: wind


def wind_figure(tree: xr.DataTree, path: str | Path, *, section: str | None = None,
                config: PreprocessConfig | None = None) -> Path:
    """Wind preprocessing of one section (paper Fig. 2).

    Panels: (a) u, v, w; (b) horizontal speed V and direction theta with the
    directions perpendicular to the span; (c) the perpendicular component
    U~ = V ``|sin(theta - azimuth)|`` and its zero-phase low-pass, the mean wind U
    (with the true mean wind when the event is synthetic).

    Parameters
    ----------
    tree : an event (docs/formats.md)
    path : output PNG
    section : section shown (default the middle one, S2 of three)
    config : preprocessing settings (low-pass cut-off), default PreprocessConfig()
    """
    config = config or PreprocessConfig()
    wind = tree["wind"].ds
    k = section_index(wind["section"].values, section)
    section = str(wind["section"].values[k])
    t = wind["time"].values
    u, v, w = (wind[c].values[:, k].astype(float) for c in ("u", "v", "w"))
    az = float(tree.attrs["span_azimuth_deg"])
    V, theta = wind_speed_direction(u, v)
    U_tilde = perpendicular_speed(V, theta, az)
    U = mean_wind(t, u, v, az, config)
    s = _step(t.size)
    tm = t[::s] / 60.0
    with figure_file(path, 3, 1, figsize=(8, 7.5), sharex=True, constrained_layout=True) as (fig, axes):
        ax = axes[0]
        for name, x, c in (("u (east)", u, "#1f77b4"), ("v (north)", v, "#ff7f0e"), ("w (up)", w, "#2ca02c")):
            ax.plot(tm, x[::s], lw=0.4, color=c, label=name)
        ax.set_ylabel("wind component (m/s)")
        ax.set_title(f"(a) measured wind at {section} (32 Hz)", fontsize=10, loc="left")
        ax.legend(loc="upper right", fontsize=8, ncol=3)
        ax = axes[1]
        ax.plot(tm, V[::s], lw=0.4, color="k", label="horizontal speed V")
        ax.set_ylabel("V (m/s)")
        ax.set_title(f"(b) speed, direction (span azimuth {az:.0f} deg)", fontsize=10, loc="left")
        axd = ax.twinx()
        axd.plot(tm, theta[::s], ",", color="#9467bd", alpha=0.5)
        for perp in ((az + 90) % 360, (az + 270) % 360):
            axd.axhline(perp, color="#9467bd", ls="--", lw=0.8)
        axd.set_ylim(0, 360)
        axd.set_yticks([0, 90, 180, 270, 360])
        axd.set_ylabel(r"direction $\theta$ (deg from north)", color="#9467bd")
        ax.legend(handles=[plt.Line2D([], [], color="k", lw=1, label="V"),
                           plt.Line2D([], [], color="#9467bd", marker=".", ls="", label=r"$\theta$ (from)"),
                           plt.Line2D([], [], color="#9467bd", ls="--", label="perpendicular to span")],
                  loc="lower right", bbox_to_anchor=(1.0, 1.0), fontsize=8, ncol=3, frameon=False)
        ax = axes[2]
        ax.plot(tm, U_tilde[::s], lw=0.4, color="0.6", label=r"perpendicular component $\tilde U$")
        ax.plot(tm, U[::s], lw=1.5, color="k",
                label=f"mean wind U (zero-phase low-pass, cut-off {config.wind_cutoff_hz:.3g} Hz)")
        if "truth" in tree.children:
            tr = tree["truth"].ds
            ax.plot(tr["time"].values / 60.0, tr["U"].values[:, k], lw=1.0, ls="--", color="#d62728",
                    label="true mean wind (generator)")
        ax.set_ylabel("wind speed (m/s)")
        ax.set_title("(c) component perpendicular to the span and its mean", fontsize=10, loc="left")
        ax.legend(loc="upper right", fontsize=8)
        axes[-1].set_xlabel("time since event start (min)")
    return Path(path)


# -------------------------------------------------------- Fig. 3: time-frequency


def time_frequency_figure(tree: xr.DataTree, path: str | Path, *, section: str | None = None,
                          f_mode: float | None = None, f_max: float = 1.0, segment_s: float = 60.0) -> Path:
    """Acceleration history and its spectrogram with the modal frequency marked (paper Fig. 3b, c).

    The paper uses a continuous wavelet transform; a short-time Fourier
    spectrogram (``scipy.signal.spectrogram``, Hann windows of ``segment_s``
    with 90 % overlap) shows the same thing: whether the frequency stays at the
    mode while the amplitude changes.

    Parameters
    ----------
    tree : an event (docs/formats.md)
    path : output PNG
    section : section shown (default the middle one, S2 of three)
    f_mode : modal frequency, Hz (None: from the Welch spectrum,
        :func:`vivbench.preprocess.chain.modal_frequency`)
    f_max : upper frequency shown, Hz
    segment_s : length of the spectrogram segments, s
    """
    accel = tree["accel"].ds
    k = section_index(accel["section"].values, section)
    section = str(accel["section"].values[k])
    t = accel["time"].values
    acc_all = accel["acc"].values.astype(float)
    if f_mode is None:
        f_mode = modal_frequency(t, acc_all)
    run = _longest_finite_run(acc_all[:, [k]])
    a = acc_all[run, k]
    fs = 1.0 / float(np.median(np.diff(t)))
    nper = min(int(round(segment_s * fs)), a.size)
    f, tt, S = signal.spectrogram(a, fs=fs, window="hann", nperseg=nper, noverlap=int(0.9 * nper),
                                  detrend="linear", scaling="density")
    keep = f <= f_max
    S_db = 10.0 * np.log10(np.maximum(S[keep], np.max(S[keep]) * 1e-8))
    s = _step(t.size)
    with figure_file(path, 2, 1, figsize=(8, 6), sharex=True, constrained_layout=True,
                 gridspec_kw={"height_ratios": [1, 1.4]}) as (fig, (ax, ax2)):
        ax.plot(t[::s] / 60.0, acc_all[::s, k], lw=0.3, color="#1f4e79")
        ax.set_ylabel(r"acceleration (m/s$^2$)")
        ax.set_title(f"(a) vertical acceleration at {section} (50 Hz), event {tree.attrs['event_id']}",
                     fontsize=10, loc="left")
        mesh = ax2.pcolormesh((t[run][0] + tt) / 60.0, f[keep], S_db, shading="nearest", cmap="magma",
                              vmin=S_db.max() - 60.0, vmax=S_db.max(), rasterized=True)
        ax2.axhline(f_mode, color="c", ls="--", lw=1, label=f"modal frequency {f_mode:.4f} Hz (Welch peak)")
        ax2.set_ylabel("frequency (Hz)")
        ax2.set_xlabel("time since event start (min)")
        ax2.set_title(f"(b) spectrogram ({segment_s:g} s Hann segments, 90 % overlap)", fontsize=10, loc="left")
        ax2.legend(loc="upper right", fontsize=8)
        cb = fig.colorbar(mesh, ax=ax2, pad=0.01)
        cb.set_label(r"PSD (dB re 1 (m/s$^2$)$^2$/Hz)")
    return Path(path)


# ------------------------------------------------- Fig. 4: displacement, envelope


def displacement_figure(tree: xr.DataTree, result: xr.Dataset, path: str | Path, *,
                        section: str | None = None) -> Path:
    """Displacement and its envelope, amplitudes of all sections, dA/dt (paper Fig. 4).

    Panel (a) integrates the longest gap-free run of the acceleration in the
    frequency domain inside the band used by the identification
    (:func:`vivbench.preprocess.chain.displacement`) and takes its Hilbert
    envelope (:func:`~vivbench.preprocess.chain.envelope`); the edges the
    identification drops are shaded. Panels (b) and (c) are the result's A and
    dA/dt on the common grid, with the truth (synthetic events) dashed.

    Parameters
    ----------
    tree : an event (docs/formats.md)
    result : its identification result (``vivbench identify``)
    path : output PNG
    section : section of panel (a) (default the middle one, S2 of three)
    """
    cfg = json.loads(result.attrs["identify_config_json"])["preprocess"]
    known = {f.name for f in dataclasses.fields(PreprocessConfig)}
    pcfg = PreprocessConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in cfg.items() if k in known})
    f_mode = float(result.attrs["f_mode_hz"])
    edge = float(result.attrs["edge_s"])
    accel = tree["accel"].ds
    k = section_index(accel["section"].values, section)
    section = str(accel["section"].values[k])
    t_all = accel["time"].values
    run = _longest_finite_run(accel["acc"].values.astype(float))
    t = t_all[run]
    a = accel["acc"].values[run, k].astype(float)
    fs = 1.0 / float(np.median(np.diff(t)))
    y = displacement(a, fs, f_mode, pcfg.half_width_hz(f_mode), taper=pcfg.band_taper)
    env = envelope(y)
    sections = [str(s) for s in result["section"].values.tolist()]
    tg = result["time"].values / 60.0
    truth = tree["truth"].ds if "truth" in tree.children else None
    s = _step(t.size)
    with figure_file(path, 3, 1, figsize=(8, 7.5), sharex=True, constrained_layout=True) as (fig, axes):
        ax = axes[0]
        ax.plot(t[::s] / 60.0, y[::s], lw=0.3, color="0.55", label="displacement y (band-limited integration)")
        ax.plot(t[::s] / 60.0, env[::s], lw=1.2, color="k", label="Hilbert envelope A")
        for lo, hi in ((t[0], t[0] + edge), (t[-1] - edge, t[-1])):
            ax.axvspan(lo / 60.0, hi / 60.0, color="#f0a030", alpha=0.2, lw=0)
        ax.set_ylabel("displacement (m)")
        ax.set_title(f"(a) {section}: y and A; band {f_mode:.3f} ± {pcfg.half_width_hz(f_mode):.3f} Hz; "
                     f"shaded: {edge:.0f} s edges dropped", fontsize=10, loc="left")
        ax.legend(loc="upper left", fontsize=8, ncol=1)
        ax = axes[1]
        for i, name in enumerate(sections):
            c = SECTION_COLOURS.get(name, None)
            ax.plot(tg, result["A"].values[:, i], lw=1.2, color=c, label=f"A {name}")
            if truth is not None:
                ax.plot(truth["time"].values / 60.0, truth["A"].values[:, i], lw=0.9, ls="--", color=c)
        ax.set_ylabel("amplitude A (m)")
        ax.set_title(f"(b) amplitudes of the {count_word(len(sections))} section{'s' if len(sections) > 1 else ''}" + (" (dashed: truth)" if truth is not None else ""),
                     fontsize=10, loc="left")
        ax.legend(loc="upper left", fontsize=8, ncol=3)
        ax = axes[2]
        method = json.loads(result.attrs["identify_config_json"])["derivative"]["method"]
        for i, name in enumerate(sections):
            c = SECTION_COLOURS.get(name, None)
            ax.plot(tg, result["dA"].values[:, i], lw=0.8, color=c, label=f"dA/dt {name}")
            if truth is not None:
                ax.plot(truth["time"].values / 60.0, truth["r"].values[:, i].sum(axis=-1), lw=0.8, ls="--",
                        color=c)
        ax.set_ylabel("dA/dt (m/s)")
        ax.set_title(f"(c) time derivatives ({method})" + (" (dashed: true averaged model)" if truth is not None else ""),
                     fontsize=10, loc="left")
        ax.legend(loc="lower left", fontsize=8, ncol=3)
        axes[-1].set_xlabel("time since event start (min)")
        axes[-1].set_xlim(t[0] / 60.0, t[-1] / 60.0)
    return Path(path)
