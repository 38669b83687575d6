"""Output-error refit over a segment of an identification result (docs/field_workflow.md).

:func:`refit_event` compares, on one segment, SINDy's coefficients, their
equation-error least-squares fit on a support and the output-error refit of
:mod:`vivbench.models.refit_solve` (whose names are importable from here too).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import xarray as xr

from vivbench.core.errors import InputError
from vivbench.core.terms import evaluate_library, feature_names
from vivbench.models.refit_solve import RefitConfig, RefitResult, order_rms, refit_coefficients, simulate_coefficients
from vivbench.models.simulate import Simulation, simulate_identified, window_in_force

__all__ = ["RefitConfig", "RefitResult", "EventRefit", "refit_coefficients", "refit_event", "simulate_coefficients",
           "order_rms"]

_SUPPORTS = ("identified", "window", "truth")


# ---------------------------------------------------------------------------- events


@dataclass(frozen=True, kw_only=True)
class EventRefit:
    """Side-by-side comparison of coefficient sets over one segment of an identification result.

    Coefficient sets (each (S, 23 S) for S sections, physical units): ``sindy`` (SINDy's, see
    :func:`refit_event`), ``lsq`` (equation-error least squares on the same
    support with the result's dA/dt: the refit's starting point), ``refit``
    and, when given, ``truth``. ``sindy_tv`` is the time-varying SINDy model
    (simulation only, no single coefficient matrix).

    Attributes
    ----------
    event_id : str
    t0, t1 : float, s
        Segment, snapped to the result's grid.
    support_kind : str
    support : ndarray of bool, shape (S, 23 S)
    coef : dict of str -> ndarray (S, 23 S)
    simulations : dict of str -> Simulation
        Every set (and ``sindy_tv``) simulated from the first measured A of the segment.
    orders : dict of str -> ndarray (S, 4), m/s
        RMS over the segment of each order's contribution to dA_m/dt on the measured (A, U).
    fit : RefitResult
    sindy_windows : ndarray of int
        Windows whose coefficients make up ``coef["sindy"]``.
    """

    event_id: str
    t0: float
    t1: float
    support_kind: str
    support: np.ndarray
    coef: dict
    simulations: dict
    orders: dict
    fit: RefitResult
    sindy_windows: np.ndarray

    def rows(self) -> list[dict]:
        """One row per (equation, feature) nonzero in any coefficient set."""
        names = feature_names(self.support.shape[0])
        sets = [k for k in ("sindy", "lsq", "refit", "truth") if k in self.coef]
        nonzero = np.zeros(self.support.shape, dtype=bool)
        for k in sets:
            nonzero |= self.coef[k] != 0
        out = []
        for m, c in zip(*np.nonzero(nonzero)):
            row = {"equation": f"S{m + 1}", "feature": names[c], "in_support": bool(self.support[m, c])}
            for k in ("sindy", "lsq", "refit", "truth"):
                row[k] = float(self.coef[k][m, c]) if k in self.coef else float("nan")
            out.append(row)
        return out

    def order_rows(self) -> list[dict]:
        """One row per (equation, order): RMS contribution of each set, m/s."""
        out = []
        for m in range(self.support.shape[0]):
            for i in range(4):
                row = {"equation": f"S{m + 1}", "order": i}
                for k in ("sindy", "lsq", "refit", "truth"):
                    row[k] = float(self.orders[k][m, i]) if k in self.orders else float("nan")
                out.append(row)
        return out

    def summary(self) -> dict:
        """Flat dict of headline numbers. A simulation that blew up has NMSE None and its stop time.

        ``ipopt_status``, ``ipopt_success`` and ``ipopt_iterations`` keep their
        names for existing readers but hold the status of the solver named by
        ``solver``.
        """
        f = self.fit
        s = {"event_id": self.event_id, "t0_s": self.t0, "t1_s": self.t1, "support": self.support_kind,
             "ipopt_status": f.status, "ipopt_success": f.success, "ipopt_iterations": f.iterations,
             "objective": f.objective, "wall_time_s": f.wall_time, "refit_start": f.start,
             "coefficients_identifiable": f.identifiable, "solver": f.solver,
             "max_continuity_defect": f.max_defect}
        n_sec = self.support.shape[0]
        for m in range(n_sec):
            s[f"support_size_S{m + 1}"] = int(f.support_size[m])
            s[f"support_rank_S{m + 1}"] = int(f.rank[m])
            s[f"support_cond_S{m + 1}"] = float(f.cond[m])
        for name, sim in self.simulations.items():
            s[f"stopped_{name}"] = sim.stopped
            s[f"stopped_at_{name}_s"] = sim.stopped_at
            for m in range(n_sec):
                s[f"nmse_{name}_S{m + 1}"] = None if sim.stopped else float(sim.nmse[m])
            s[f"nmse_{name}_mean"] = None if sim.stopped else float(np.mean(sim.nmse))
        return s


def _segment(result: xr.Dataset, t0: float, t1: float):
    t_all = np.asarray(result["time"].values, dtype=float)
    if not (np.isfinite(t0) and np.isfinite(t1) and t1 > t0):
        raise InputError(f"need finite t0 < t1; got t0={t0}, t1={t1}")
    if t0 < t_all[0] - 1e-9 or t1 > t_all[-1] + 1e-9:
        raise InputError(f"[{t0:g}, {t1:g}] s is outside the result's grid [{t_all[0]:g}, {t_all[-1]:g}] s")
    i0 = int(np.argmin(np.abs(t_all - t0)))
    i1 = int(np.argmin(np.abs(t_all - t1))) + 1
    if i1 - i0 < 3:
        raise InputError(f"[{t0:g}, {t1:g}] s holds fewer than three samples of the result's grid")
    A = np.asarray(result["A"].values, dtype=float)[i0:i1]
    U = np.asarray(result["U"].values, dtype=float)[i0:i1]
    if not (np.all(np.isfinite(A)) and np.all(np.isfinite(U))):
        raise InputError(f"[{t0:g}, {t1:g}] s contains missing A or U; choose a gap-free segment")
    if "segment" in result:
        seg = np.asarray(result["segment"].values)[i0:i1]
        if np.any(seg != seg[0]) or seg[0] < 0:
            raise InputError(f"[{t0:g}, {t1:g}] s crosses a gap between preprocessing segments")
    return i0, i1, t_all[i0:i1], A, U


def _equation_error_fit(theta, dA, support):
    """Least squares of dA_m/dt on each equation's supported columns (columns scaled to unit RMS)."""
    coef = np.zeros(support.shape)
    for m in range(support.shape[0]):
        cols = np.flatnonzero(support[m])
        ok = np.isfinite(dA[:, m])
        if cols.size == 0 or ok.sum() < 1:
            continue
        X = theta[ok][:, cols]
        d = np.sqrt(np.mean(X**2, axis=0))
        d[d == 0] = 1.0
        coef[m, cols] = np.linalg.lstsq(X / d, dA[ok, m], rcond=None)[0] / d
    return coef


def refit_event(result: xr.Dataset, *, t0: float | None = None, t1: float | None = None, support="identified",
                truth_coef=None, config: RefitConfig | None = None) -> EventRefit:
    """Refit one segment of an identification result and compare with SINDy (and the truth).

    Parameters
    ----------
    result : xarray.Dataset
        ``<event_id>.identify.nc`` (``coef`` per window, ``window_start``,
        ``window_end``; ``A``, ``U``, ``dA`` on coordinate ``time``).
    t0, t1 : float, s, optional
        Segment (snapped to the grid); default the whole grid. It must be
        gap-free (one preprocessing segment, finite A and U).
    support : {"identified", "window", "truth"} or ndarray of bool (S, 23 S)
        ``"identified"``: the union of the supports of every window in force
        during the segment (the truth is one fixed model, so one fixed support
        over the segment is what a refit should use); SINDy's coefficients are
        then the mean of those windows' coefficients. ``"window"``: the support
        of the window in force at t0, SINDy's coefficients those of that window.
        ``"truth"``: the nonzero entries of ``truth_coef``. An array: that mask.
        In all but ``"window"`` SINDy's coefficients are the mean over the
        windows in force during the segment.
    truth_coef : ndarray (S, 23 S), optional
        Exact coefficients (the event file's ``/truth/coef``).
    config : RefitConfig

    Returns
    -------
    EventRefit
        The refit starts from the equation-error least-squares fit on the same
        support (``lsq``), so that no set is favoured by the starting point.
    """
    config = config or RefitConfig()
    t_grid = np.asarray(result["time"].values, dtype=float)
    t0 = float(t_grid[0]) if t0 is None else float(t0)
    t1 = float(t_grid[-1]) if t1 is None else float(t1)
    i0, i1, t, A, U = _segment(result, t0, t1)
    coef_w = np.asarray(result["coef"].values, dtype=float)
    shape = coef_w.shape[1:]  # (S, 23 S)
    if truth_coef is not None:
        truth_coef = np.asarray(truth_coef, dtype=float)
        if truth_coef.shape != shape or not np.all(np.isfinite(truth_coef)):
            raise ValueError(f"truth_coef must be a finite {shape} array, as the result's coefficients; "
                             f"got shape {truth_coef.shape}")
    in_force = np.unique(window_in_force(result, t[:-1]))
    sindy = coef_w[in_force].mean(axis=0)
    if isinstance(support, str):
        if support not in _SUPPORTS:
            raise InputError(f"support must be one of {_SUPPORTS} or a {shape} boolean mask; got {support!r}")
        kind = support
        if support == "identified":
            mask = np.any(coef_w[in_force] != 0, axis=0)
        elif support == "window":
            in_force = np.atleast_1d(window_in_force(result, t[0]))
            sindy = coef_w[in_force[0]]
            mask = sindy != 0
        else:
            if truth_coef is None:
                raise InputError("support='truth' needs truth_coef (the event file's /truth/coef)")
            mask = truth_coef != 0
    else:
        kind = "mask"
        mask = np.asarray(support)
        if mask.shape != shape or mask.dtype != bool:
            raise ValueError(f"a support mask must be a boolean {shape} array; got {mask.dtype} {mask.shape}")
    theta = evaluate_library(A, U)
    dA = np.asarray(result["dA"].values, dtype=float)[i0:i1] if "dA" in result else np.full_like(A, np.nan)
    lsq = _equation_error_fit(theta, dA, mask)
    fit = refit_coefficients(t, A, U, mask, lsq, config)
    coef = {"sindy": sindy, "lsq": lsq, "refit": fit.coef}
    if truth_coef is not None:
        coef["truth"] = truth_coef
    bounds = {"bound_factor": config.bound_factor, "negative_tolerance": config.negative_tolerance}
    sims = {k: (fit.simulation if k == "refit" else simulate_coefficients(t, A, U, c, **bounds))
            for k, c in coef.items()}
    sims["sindy_tv"] = simulate_identified(result.isel(time=slice(i0, i1)), t0=float(t[0]), t1=float(t[-1]),
                                           u_interp="linear", **bounds)
    orders = {k: order_rms(A, U, c) for k, c in coef.items()}
    return EventRefit(event_id=str(result.attrs.get("event_id", "")), t0=float(t[0]), t1=float(t[-1]),
                      support_kind=kind, support=mask, coef=coef, simulations=sims, orders=orders, fit=fit,
                      sindy_windows=in_force)
