"""Figures of simulations and forecasts (Li et al. 2019, Figs. 11-12) and of coefficient curves a_i(U).

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

from vivbench.core.errors import InputError  # noqa: E402
from vivbench.models.curve_support import EXTRAPOLATED  # noqa: E402
from vivbench.models.simulate import forecast, simulate_identified  # noqa: E402
from vivbench.report.figure_style import SECTION_COLOURS, figure_file, section_index  # noqa: E402

__all__ = ["forecast_figure", "model_forecast_figure", "curves_figure"]


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
    e = section_index(result["equation"].values, equation)
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
    with figure_file(path, 2, 1, figsize=(9, 7.5), constrained_layout=True) as (fig, (ax, ax2)):
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
    e = section_index(sections, equation)
    equation = sections[e]
    t, A = record.t, record.A
    horizon = min(float(horizon), float(t[-1]) - float(t0))
    if not horizon > 0:
        raise InputError(f"t0 = {t0:g} s leaves no forecast horizon before the record ends at {t[-1]:g} s")
    span = (float(t[0]), float(t[-1])) if span is None else (float(span[0]), float(span[1]))
    sim = model.simulate(record, *span)
    fc = model.simulate(record, float(t0), float(t0) + horizon)
    with figure_file(path, 2, 1, figsize=(9, 7.5), constrained_layout=True) as (fig, (ax, ax2)):
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
        c = SECTION_COLOURS.get(sec)
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
    k = section_index(sections, equation)
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
    with figure_file(path, 2, 2, figsize=(10, 7), constrained_layout=True, sharex=True) as (fig, axes):
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
