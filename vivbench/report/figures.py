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
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Sequence
from contextlib import contextmanager
from pathlib import Path

import matplotlib
from vivbench.core.errors import InputError

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402
from matplotlib.colors import SymLogNorm  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402
from scipy import signal  # noqa: E402

from vivbench.models.curve_support import EXTRAPOLATED  # noqa: E402
from vivbench.models.simulate import forecast, simulate_identified
from vivbench.preprocess.config import PreprocessConfig
from vivbench.preprocess.vibration import displacement, envelope, modal_frequency
from vivbench.preprocess.wind import mean_wind, perpendicular_speed, wind_speed_direction
from vivbench.io.netcdf import atomic_path
from vivbench.core.terms import evaluate_library, feature_exponents, reference_section

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

#: Resolution of every report figure (dots per inch).
DPI = 100
#: Colours of the regimes 1..4 (same as the event overview figure).
REGIME_COLOURS = {1: "#9e9e9e", 2: "#4c9be8", 3: "#f0a030", 4: "#d62728"}
_SECTION_COLOURS = {"S1": "#1b9e77", "S2": "#d95f02", "S3": "#7570b3"}
# Plotting more points than pixels only slows the drawing down.
_MAX_POINTS = 20000


@contextmanager
def _figure(path, nrows=1, ncols=1, *, figsize, dpi=DPI, **kwargs):
    """Create a figure, yield (fig, axes), write it atomically and close it."""
    fig, axes = plt.subplots(nrows, ncols, figsize=figsize, **kwargs)
    try:
        yield fig, axes
        path = Path(path)
        with atomic_path(path, suffix=".png") as tmp:
            # No software tag or date in the PNG: the same data give the same bytes.
            fig.savefig(tmp, dpi=dpi, format="png", metadata={"Software": None})
    finally:
        plt.close(fig)


def _step(n: int) -> int:
    return max(1, n // _MAX_POINTS)


_COUNT_WORDS = ("one", "two", "three", "four", "five", "six", "seven", "eight", "nine", "ten")


def count_word(n: int) -> str:
    """A count in words for captions and titles: 'three' for 3, digits above ten."""
    return _COUNT_WORDS[n - 1] if 1 <= n <= len(_COUNT_WORDS) else str(n)


def _section_index(sections, section: str | None) -> int:
    """Index of ``section`` among ``sections``; None: the middle section (S2 of three)."""
    names = [str(s) for s in np.asarray(sections).tolist()]
    if section is None:
        return reference_section(len(names))
    if section not in names:
        raise InputError(f"section {section!r} is not in the data; sections are {names}")
    return names.index(section)


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
    with _figure(path, 2, 1, figsize=(8, 5.2), sharex=True, constrained_layout=True,
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
    k = _section_index(wind["section"].values, section)
    section = str(wind["section"].values[k])
    t = wind["time"].values
    u, v, w = (wind[c].values[:, k].astype(float) for c in ("u", "v", "w"))
    az = float(tree.attrs["span_azimuth_deg"])
    V, theta = wind_speed_direction(u, v)
    U_tilde = perpendicular_speed(V, theta, az)
    U = mean_wind(t, u, v, az, config)
    s = _step(t.size)
    tm = t[::s] / 60.0
    with _figure(path, 3, 1, figsize=(8, 7.5), sharex=True, constrained_layout=True) as (fig, axes):
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
    k = _section_index(accel["section"].values, section)
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
    with _figure(path, 2, 1, figsize=(8, 6), sharex=True, constrained_layout=True,
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
    k = _section_index(accel["section"].values, section)
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
    with _figure(path, 3, 1, figsize=(8, 7.5), sharex=True, constrained_layout=True) as (fig, axes):
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
            c = _SECTION_COLOURS.get(name, None)
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
            c = _SECTION_COLOURS.get(name, None)
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
    e = _section_index(result["equation"].values, equation)
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
    with _figure(path, 4, 1, figsize=(9, 10), sharex=True, constrained_layout=True,
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
            ax.plot(tg, result["U"].values[:, i], lw=1, color=_SECTION_COLOURS.get(name), label=f"U {name}")
        if lock_in is not None:
            ax.axhspan(*lock_in, color="#4c9be8", alpha=0.1, label="lock-in range (generator default)")
        ax.set_ylabel("U (m/s)")
        ax.set_title("(c) mean wind perpendicular to the span", fontsize=10, loc="left")
        ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.05), fontsize=7, frameon=False)
        ax = axes[3]
        for i, name in enumerate(sections):
            ax.plot(tg, result["A"].values[:, i], lw=1, color=_SECTION_COLOURS.get(name), label=f"A {name}")
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
    with _figure(path, n, 1, figsize=(9, 1.0 + 1.45 * n), constrained_layout=True, squeeze=False) as (fig, axes):
        for ax, res, truth in zip(axes[:, 0], results, truth_regimes):
            e = _section_index(res["equation"].values, equation)
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
    with _figure(path, 1, panels, figsize=(4.2 * panels, 4.2), constrained_layout=True,
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


# ----------------------------------------------------- Figs. 11-12: forecasts


def forecast_figure(result: xr.Dataset, path: str | Path, *, t0: float | None = None, horizon: float = 300.0,
                    ds: Sequence[float] = (0.0, 50.0, 150.0, 300.0), equation: str | None = None) -> Path:
    """Simulation with the time-varying model and fixed-coefficient forecasts (paper Figs. 11-12).

    Panel (a): the measured amplitudes against the simulation of the whole
    event with the time-varying window models, from the measured A at the
    first window's start and the measured wind
    (:func:`vivbench.models.simulate.simulate_identified`). Panel (b): the
    measured amplitude of ``equation`` against forecasts from ``t0`` with
    coefficients fixed at t0 (d = 0) or averaged over the windows starting in
    [t0, t0 + d] (:func:`vivbench.models.simulate.forecast`). A run that blew
    up is drawn only up to where it was stopped and marked with a cross.

    Parameters
    ----------
    result : identification result
    path : output PNG
    t0 : forecast start, s (None: the window start nearest to 40 % of the identified span)
    horizon : forecast horizon, s (shortened to the end of the record)
    ds : averaging durations d, s
    equation : section shown in panel (b) (default the middle one, S2 of three)

    Returns
    -------
    Path
    """
    e = _section_index(result["equation"].values, equation)
    equation = str(result["equation"].values[e])
    sections = [str(s) for s in result["section"].values.tolist()]
    starts = result["window_start"].values
    t_first, t_last = float(starts.min()), float(result["window_end"].values.max())
    if t0 is None:
        target = t_first + 0.4 * (t_last - t_first)
        t0 = float(starts[np.argmin(np.abs(starts - target))])
    horizon = min(float(horizon), float(result["time"].values[-1]) - t0)
    sim = simulate_identified(result)
    runs = [(d, forecast(result, t0, horizon, d=float(d))) for d in ds if t0 + d <= t_last]
    cmap = plt.get_cmap("viridis")
    with _figure(path, 2, 1, figsize=(9, 7.5), constrained_layout=True) as (fig, (ax, ax2)):
        _simulation_panel(ax, result["time"].values, result["A"].values, sections, sim, t0, horizon,
                          f"(a) event {result.attrs['event_id']}: time-varying model from the measured "
                          f"A(t = {sim.t[0]:.0f} s) and U")
        sel = (result["time"].values >= t0 - 1e-9) & (result["time"].values <= t0 + horizon + 1e-9)
        ax2.plot(result["time"].values[sel], result["A"].values[sel, e], lw=2.0, color="k", label=f"measured {equation}")
        for n_run, (d, fc) in enumerate(runs):
            c = cmap(n_run / max(len(runs) - 1, 1) * 0.9)
            what = "fixed at t0 (window in force)" if d == 0 else f"mean over [t0, t0+{d:g} s] ({fc.windows.size} windows)"
            ax2.plot(fc.t, fc.A_sim[:, e], lw=1.2, color=c, label=f"{what}: {_forecast_status(fc, e)}")
            _mark_stop(ax2, fc, e, colour=c, minutes=False)
        ax2.set_xlabel("time since event start (s)")
        ax2.set_ylabel(f"amplitude A at {equation} (m)")
        ax2.set_title(f"(b) forecasts from t0 = {t0:.0f} s with fixed coefficients (x: blow-up, run stopped)",
                      fontsize=10, loc="left")
        ax2.legend(loc="best", fontsize=7)
    return Path(path)


def model_forecast_figure(model, record, path: str | Path, *, t0: float, horizon: float = 300.0,
                          span: tuple[float, float] | None = None, equation: str | None = None,
                          name: str = "the model") -> Path:
    """Simulation and forecast of one record with a model of the protocol (paper Figs. 11-12).

    Panel (a): the measured amplitudes against ``model.simulate(record, *span)``,
    from the measured A at the span's start with the measured wind. Panel (b):
    the measured amplitude of ``equation`` against
    ``model.simulate(record, t0, t0 + horizon)``, the forecast from the
    measured A at t0. A run that blew up is drawn only up to where it was
    stopped and marked with a cross. A time-invariant model (the campaign
    model) has one forecast: the averaging duration d of the window models
    plays no role.

    Parameters
    ----------
    model : fitted model with ``simulate(record, t0, t1)`` returning a
        :class:`vivbench.models.simulate.Simulation`
    record : vivbench.core.Record
        t (s), A (m), U (m/s) of shape (n_samples, S); section names S1..Sn.
    path : output PNG
    t0 : forecast start, s
    horizon : forecast length, s (shortened to the end of the record)
    span : (start, end), s, optional
        Span of panel (a) (default: the whole record).
    equation : section shown in panel (b) (default the middle one, S2 of three)
    name : how the model is named in the titles

    Returns
    -------
    Path
    """
    sections = [f"S{k + 1}" for k in range(record.n_sections)]
    e = _section_index(sections, equation)
    equation = sections[e]
    t, A = record.t, record.A
    horizon = min(float(horizon), float(t[-1]) - float(t0))
    if not horizon > 0:
        raise InputError(f"t0 = {t0:g} s leaves no forecast horizon before the record ends at {t[-1]:g} s")
    span = (float(t[0]), float(t[-1])) if span is None else (float(span[0]), float(span[1]))
    sim = model.simulate(record, *span)
    fc = model.simulate(record, float(t0), float(t0) + horizon)
    with _figure(path, 2, 1, figsize=(9, 7.5), constrained_layout=True) as (fig, (ax, ax2)):
        _simulation_panel(ax, t, A, sections, sim, t0, horizon,
                          f"(a) event {record.event_id}: {name} from the measured A(t = {sim.t[0]:.0f} s) and U")
        sel = (t >= t0 - 1e-9) & (t <= t0 + horizon + 1e-9)
        ax2.plot(t[sel], A[sel, e], lw=2.0, color="k", label=f"measured {equation}")
        c = plt.get_cmap("viridis")(0.0)
        ax2.plot(fc.t, fc.A_sim[:, e], lw=1.2, color=c, label=f"{name}: {_forecast_status(fc, e)}")
        _mark_stop(ax2, fc, e, colour=c, minutes=False)
        ax2.set_xlabel("time since event start (s)")
        ax2.set_ylabel(f"amplitude A at {equation} (m)")
        ax2.set_title(f"(b) forecast from t0 = {t0:.0f} s (x: blow-up, run stopped)", fontsize=10, loc="left")
        ax2.legend(loc="best", fontsize=7)
    return Path(path)


def _simulation_panel(ax, t, A, sections, sim, t0, horizon, title):
    """Panel (a) of the forecast figures: measured amplitudes against a simulation over the whole span."""
    for i, sec in enumerate(sections):
        c = _SECTION_COLOURS.get(sec)
        ax.plot(t / 60.0, A[:, i], lw=1.2, color=c, label=f"measured {sec}")
        ax.plot(sim.t / 60.0, sim.A_sim[:, i], lw=1.0, ls="--", color=c,
                label=f"simulated {sec} (NMSE {sim.nmse[i]:.3g})")
    _mark_stop(ax, sim, None)
    ax.axvspan(t0 / 60.0, (t0 + horizon) / 60.0, color="0.9", lw=0, zorder=0, label="forecast span of (b)")
    ax.set_ylabel("amplitude A (m)")
    ax.set_xlabel("time since event start (min)")
    ax.set_title(title, fontsize=10, loc="left")
    if sim.stopped:
        ax.text(0.99, 0.03, f"simulation stopped (x): {sim.reason}", transform=ax.transAxes, ha="right",
                va="bottom", fontsize=7, wrap=True)
    ax.legend(loc="upper left", fontsize=7, ncol=2)


def _forecast_status(fc, e: int) -> str:
    """Legend text of a forecast of section e: its NMSE, and where a blown-up run was stopped."""
    if not fc.stopped:
        return f"NMSE {fc.nmse[e]:.3g}"
    if np.isfinite(fc.nmse[e]):
        return f"NMSE {fc.nmse[e]:.3g} before the stop at {fc.stopped_at:.0f} s"
    return f"stopped at {fc.stopped_at:.0f} s, no valid interval"


def _mark_stop(ax, sim, column, *, colour="k", minutes=True):
    """Cross at the last valid sample of a stopped run."""
    if not sim.stopped:
        return
    valid = np.flatnonzero(np.all(np.isfinite(sim.A_sim), axis=1))
    if valid.size == 0:
        return
    i = valid[-1]
    cols = range(sim.A_sim.shape[1]) if column is None else [column]
    for c in cols:
        ax.plot(sim.t[i] / (60.0 if minutes else 1.0), sim.A_sim[i, c], "x", ms=9, mew=2, color=colour)


_CURVE_UNITS = ("m/s", "1/s", "1/(m s)", "1/(m$^2$ s)")


def curves_figure(curves: xr.Dataset, path: str | Path, *, truth: tuple[np.ndarray, np.ndarray] | None = None,
                  equation: str | None = None, frequency: float | None = None, depth: float | None = None,
                  name: str = "campaign model") -> Path:
    """Coefficient curves a_ki(U) of a campaign-level model against the truth's (docs/concepts.md (coefficient curves)).

    One panel per order i = 0..3 for one equation k, drawn the way
    aerodynamic derivatives are drawn against reduced velocity: the truth as
    a black line, the model as a coloured line with its band shaded.

    Parameters
    ----------
    curves : xarray.Dataset
        ``curves`` and optionally ``curves_lower``, ``curves_upper``
        (equation, order, wind) in m^(1-i)/s with coordinate ``wind`` (m/s),
        e.g. a ``campaign.regimes.nc`` or :meth:`vivbench.models.PooledSINDy.curves`;
        with ``curves_extrapolated`` (equation, wind; :func:`vivbench.models.mark_extrapolated`)
        the extrapolated parts are drawn grey dotted, with their own legend entry.
    path : output PNG
    truth : (curves, wind), optional
        The truth's curves (S, 4, n_true) in m^(1-i)/s on wind (n_true,) m/s
        (``/truth/curves``), drawn over the model's wind range and 1 m/s beyond.
    equation : section whose equation is drawn (default the reference section, S2 of three)
    frequency, depth : float, optional
        Modal frequency f (Hz) and deck depth D (m); with both, a secondary
        axis gives the reduced velocity U / (f D).
    name : how the model is named in the legend

    Returns
    -------
    Path
    """
    sections = [str(s) for s in curves["equation"].values]
    k = _section_index(sections, equation)
    wind = np.asarray(curves["wind"].values, dtype=float)
    point = np.asarray(curves["curves"].values, dtype=float)[k]
    band = None
    if "curves_lower" in curves and "curves_upper" in curves:
        band = (np.asarray(curves["curves_lower"].values, dtype=float)[k],
                np.asarray(curves["curves_upper"].values, dtype=float)[k])
    extrapolated = None
    if EXTRAPOLATED in curves:
        extrapolated = np.asarray(curves[EXTRAPOLATED].values, dtype=bool)[k]
    colour = plt.get_cmap("viridis")(0.35)
    with _figure(path, 2, 2, figsize=(10, 7), constrained_layout=True, sharex=True) as (fig, axes):
        for i, ax in enumerate(axes.ravel()):
            if truth is not None:
                tc, tw = np.asarray(truth[0], dtype=float)[k, i], np.asarray(truth[1], dtype=float)
                shown = (tw >= wind.min() - 1.0) & (tw <= wind.max() + 1.0)
                ax.plot(tw[shown], tc[shown], color="k", lw=1.8, label="truth")
            if band is not None and np.isfinite(band[0][i]).any():
                ax.fill_between(wind, band[0][i], band[1][i], color=colour, alpha=0.25, lw=0, label=f"{name}: band")
            if extrapolated is not None and extrapolated.any():
                # Inside the data dashed; outside grey dotted, joined to the inside at the data's edge.
                edge = extrapolated | np.r_[extrapolated[1:], False] | np.r_[False, extrapolated[:-1]]
                ax.plot(wind, np.where(extrapolated, np.nan, point[i]), color=colour, lw=1.4, ls="--", label=name)
                ax.plot(wind, np.where(edge, point[i], np.nan), color="0.55", lw=1.4, ls=":",
                        label=f"{name}: extrapolated (outside its data's winds)")
            else:
                ax.plot(wind, point[i], color=colour, lw=1.4, ls="--", label=name)
            ax.axhline(0.0, color="0.6", lw=0.6, zorder=0)
            # The y range follows the lines (a wide band at the data's edges would flatten them).
            seen = [point[i]] + ([tc[shown]] if truth is not None else [])
            vals = np.concatenate([v[np.isfinite(v)] for v in seen] + [np.zeros(1)])
            lo, hi = float(vals.min()), float(vals.max())
            pad = 0.15 * (hi - lo) if hi > lo else max(abs(hi), 1e-12)
            ax.set_ylim(lo - pad, hi + pad)
            ax.set_ylabel(f"a$_{{{i}}}$(U) at {sections[k]} ({_CURVE_UNITS[i]})")
            ax.set_title(f"({'abcd'[i]}) order {i}: coefficient of A$^{{{i}}}$ in dA/dt", fontsize=10, loc="left")
            if i >= 2:
                ax.set_xlabel("mean wind speed U (m/s)")
            if frequency and depth and i < 2:
                fd = float(frequency) * float(depth)
                sec = ax.secondary_xaxis("top", functions=(lambda u, fd=fd: u / fd, lambda ur, fd=fd: ur * fd))
                sec.set_xlabel("reduced velocity U/(f D) (-)")
            if i == 0:
                ax.legend(loc="best", fontsize=8)
    return Path(path)
