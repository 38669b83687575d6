"""Simulation and forecasting with identified time-varying models (docs/field_workflow.md).

An identification result (:func:`vivbench.analysis.identify_event`) holds one
coefficient matrix Xi_w per window, with dA/dt = Theta(A, U) Xi_w^T on the
physical library :func:`vivbench.core.terms.evaluate_library`. This module
integrates that model for the S sections (any S >= 1) with the measured wind U(t):

- :func:`simulate_identified` uses the time-varying coefficients: the window in
  force at time t is the fitted window whose centre (start + end) / 2 is
  nearest to t (ties go to the earlier window). With 50 s windows and 25 s
  steps this gives each window the 25 s around its centre, handles the first
  and last half-windows and gaps between segments without special cases, and
  skips windows with no fitted model (NaN coefficients).
- :func:`forecast` freezes the coefficients at t0 (d = 0: the window in force
  at t0, by the same rule) or averages them over the windows whose starts lie
  in [t0, t0 + d] (the paper's Section VI).

Integration is a classical fixed-step RK4 on the result's own time grid
(4 Hz after preprocessing, so a 1000 s record is ~4000 steps). The
coefficients are constant over a step (those in force at its start) and U is
interpolated at the stages (cubic spline by default). Every U-dependent
quantity is precomputed for all steps in one vectorised pass: for each step
and stage the model reduces to an (S, S, 4) array C with
dA_m/dt = sum_{k,i} C[m, k, i] A_k^i, so the remaining Python loop over steps
does one S x 4S matrix-vector product per stage (~0.1 s for 10^4 steps).
A step cost that small makes the loop acceptable; an adaptive solver would
not be faster here because the model is stiff-free and the grid is fine.

Physical coefficients are large with alternating signs (U barely changes in
a window, so its powers nearly cancel); everything is float64, and a model
used away from its window's ranges of U and A can blow up. Such a run is
stopped, not propagated: the step that produces a non-finite A, an A above
``bound_factor`` times the largest measured A, or an A below
``-negative_tolerance`` times it ends the simulation; the samples from there
on are NaN, and the NMSE covers only the valid part.

Why window models blow up, and what was tried (``clip``). In a 50 s window
A is nearly constant and A_1 : A_2 : A_3 is fixed by the mode shape, so the
data fix dA/dt along the measured path but not how it changes when A leaves
it: the Jacobian d(dA/dt)/dA of an identified model (:func:`model_jacobian`)
is not identified. On the default campaign its largest real eigenvalue at the
forecast start is 0.05-1 1/s for single windows and up to ~60 1/s for
coefficients averaged over several windows (each window's large, cancelling
coefficients average to a model that fits none of them), against about
+-0.006 1/s for the true averaged dynamics (``vivbench forecast`` reports both).
Any deviation of the simulated A from the measurement then grows by e within
seconds. Remedies tried: (1) float64 cancellation is not the cause: the
largest physical term of a window is ~1e8 times dA/dt (8 of 16 digits), and
evaluating the models in their windows' scaled basis instead gives the same
right-hand side to 0.5 % at states within +-10 % of the measured A and the
same Jacobian eigenvalues to 1e-5 (checked on event E001 of the default
campaign);
(2) ``clip="u"``, each model sees U only within the range of its window
("a model is only valid on the data it saw"): no effect, the runs stop
before U leaves the range; (3) ``clip="au"``, A clipped too: the runs last
longer but the NMSE does not improve, since a model frozen at its window's
edge only extrapolates dA/dt as a function of U; (4) a single model refitted
by the engine on the pooled data of [t0, t0 + d] (explored, not kept): also
stopped within 10-60 s. The paper's method (``clip="none"``) stays the
default and the comparison.

NMSE, per section s, over the compared samples (valid simulation and finite
measurement)::

    NMSE_s = sum (A_sim - A_meas)^2 / sum (A_meas - mean(A_meas))^2

0 is a perfect match, 1 is as good as predicting the (compared) mean.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import xarray as xr
from scipy.interpolate import make_interp_spline

from vivbench.core.terms import feature_exponents, section_exponents
from vivbench.core.errors import InputError
from vivbench.models.integrate import ABOVE, NON_FINITE, StopRule, rk4
from vivbench.preprocess.runs import first_gap

__all__ = ["CLIP_MODES", "Simulation", "gap_reason", "model_jacobian", "simulate_identified", "window_ranges", "forecast", "forecast_coefficients", "forecast_table", "nmse",
           "window_in_force"]

_METHODS = ("rk4",)
_U_INTERP = ("cubic", "linear")
CLIP_MODES = ("none", "u", "au")


@dataclass(frozen=True, kw_only=True)
class Simulation:
    """A simulated (or forecast) amplitude history and its comparison with the measurement.

    Attributes
    ----------
    t : ndarray, shape (n,), s
        Grid of the simulation (samples of the result's time grid).
    A_sim : ndarray, shape (n, S), m
        Simulated amplitudes; NaN from the sample at which the run was stopped.
    A_meas : ndarray, shape (n, S), m
        Measured amplitudes on the same grid.
    stopped_at : float or None, s
        Time of the first invalid sample, None when the run reached the end.
    reason : str or None
        Why the run stopped (None when it did not).
    nmse : ndarray, shape (S,)
        Per-section NMSE over the valid part (see module docstring); NaN for a
        section with fewer than two compared samples.
    covered : float
        Fraction of the requested horizon simulated before the stop (1.0 if none).
    windows : ndarray of int
        simulate_identified: window in force at each step, shape (n - 1,);
        forecast: windows whose coefficients were averaged.
    coef : ndarray, shape (S, 23 S) or None
        The fixed coefficients of a forecast (None for simulate_identified).
    """

    t: np.ndarray
    A_sim: np.ndarray
    A_meas: np.ndarray
    stopped_at: float | None
    reason: str | None
    nmse: np.ndarray
    covered: float
    windows: np.ndarray
    coef: np.ndarray | None = None

    @property
    def stopped(self) -> bool:
        return self.stopped_at is not None


def nmse(A_sim, A_meas) -> np.ndarray:
    """Per-column NMSE over the samples where both arrays are finite.

    Parameters
    ----------
    A_sim, A_meas : ndarray, shape (n, S), m

    Returns
    -------
    ndarray, shape (S,)
        sum((A_sim - A_meas)^2) / sum((A_meas - mean(A_meas))^2) over the
        compared samples; NaN with fewer than two samples or a constant measurement.
    """
    A_sim = np.asarray(A_sim, dtype=float)
    A_meas = np.asarray(A_meas, dtype=float)
    ok = np.isfinite(A_sim) & np.isfinite(A_meas)
    n = ok.sum(axis=0)
    meas = np.where(ok, A_meas, 0.0)
    mean = meas.sum(axis=0) / np.maximum(n, 1)
    num = np.where(ok, (A_sim - A_meas) ** 2, 0.0).sum(axis=0)
    den = np.where(ok, (A_meas - mean) ** 2, 0.0).sum(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = num / den
    return np.where((n >= 2) & (den > 0), out, np.nan)


def _window_table(result: xr.Dataset):
    coef = np.asarray(result["coef"].values, dtype=float)
    start = np.asarray(result["window_start"].values, dtype=float)
    end = np.asarray(result["window_end"].values, dtype=float)
    if coef.ndim != 3 or coef.shape[1] < 1 or coef.shape[2] != section_exponents().shape[0] * coef.shape[1]:
        raise InputError(f"result['coef'] must have shape (window, S, 23 S) for S sections; got {coef.shape}")
    fitted = np.all(np.isfinite(coef), axis=(1, 2))
    if not fitted.any():
        raise InputError("the result has no window with a fitted model (all coefficients are NaN)")
    return coef, start, end, fitted


def window_in_force(result: xr.Dataset, t) -> np.ndarray:
    """Index of the fitted window whose centre is nearest to each time (ties: earlier window).

    Parameters
    ----------
    result : xarray.Dataset
        Identification result with ``coef``, ``window_start``, ``window_end``.
    t : array_like, s

    Returns
    -------
    ndarray of int, shape of ``t``
    """
    coef, start, end, fitted = _window_table(result)
    idx = np.flatnonzero(fitted)
    centre = 0.5 * (start[idx] + end[idx])
    t = np.asarray(t, dtype=float)
    order = np.argsort(centre, kind="stable")
    c = centre[order]
    # Nearest of the two neighbouring centres; '<=' sends ties to the earlier one.
    pos = np.clip(np.searchsorted(c, t.ravel()), 1, max(c.size - 1, 1))
    if c.size == 1:
        pick = np.zeros(t.size, dtype=int)
    else:
        left = np.abs(t.ravel() - c[pos - 1]) <= np.abs(c[pos] - t.ravel())
        pick = np.where(left, pos - 1, pos)
    return idx[order[pick]].reshape(t.shape)


def window_ranges(result: xr.Dataset) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Range of the data each window's model was fitted on.

    Parameters
    ----------
    result : xarray.Dataset
        Identification result (``A``, ``U`` on ``time``; ``window_start``, ``window_end``).

    Returns
    -------
    a_lo, a_hi : ndarray, shape (W, S), m
        Smallest and largest finite A of each section over each window [start, end).
    u_lo, u_hi : ndarray, shape (W, S), m/s
        The same for U. NaN for a window without finite samples.
    """
    t = np.asarray(result["time"].values, dtype=float)
    start = np.asarray(result["window_start"].values, dtype=float)
    end = np.asarray(result["window_end"].values, dtype=float)
    dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    tol = 1e-6 * dt
    first = np.searchsorted(t, start - tol, side="left")
    stop = np.searchsorted(t, end - tol, side="left")
    n_max = int(max((stop - first).max(), 1)) if start.size else 1
    offs = np.arange(n_max)
    inwin = offs[None, :] < (stop - first)[:, None]
    idx = np.minimum(first[:, None] + offs[None, :], t.size - 1)
    out = []
    for name in ("A", "U"):
        x = np.asarray(result[name].values, dtype=float)[idx]  # (W, n_max, S)
        ok = inwin[..., None] & np.isfinite(x)
        with np.errstate(invalid="ignore"):
            lo = np.where(ok, x, np.inf).min(axis=1)
            hi = np.where(ok, x, -np.inf).max(axis=1)
        bad = ~ok.any(axis=1)
        out += [np.where(bad, np.nan, lo), np.where(bad, np.nan, hi)]
    return tuple(out)


def forecast_coefficients(result: xr.Dataset, t0: float, d: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The fixed coefficients of a forecast from t0.

    d = 0: the window in force at t0 (:func:`window_in_force`); d > 0: the
    mean over the fitted windows whose starts lie in [t0, t0 + d] (a 1e-6 s
    tolerance absorbs rounding of the window starts).

    Returns
    -------
    coef : ndarray, shape (S, 23 S)
    windows : ndarray of int
        Windows averaged.
    """
    if not (np.isfinite(d) and d >= 0):
        raise InputError(f"d must be a finite duration >= 0 s; got {d}")
    coef, start, _end, fitted = _window_table(result)
    if d == 0:
        w = np.atleast_1d(window_in_force(result, t0))
    else:
        tol = 1e-6
        w = np.flatnonzero(fitted & (start >= t0 - tol) & (start <= t0 + d + tol))
        if w.size == 0:
            raise InputError(f"no fitted window starts in [{t0:g}, {t0 + d:g}] s")
    return coef[w].mean(axis=0), w


def _polynomials(coef: np.ndarray) -> np.ndarray:
    """Coefficients (W, S, S, 4, 6): equation m, section k, power of A i, power of U j."""
    n_sec = coef.shape[1]
    ex = feature_exponents(n_sec)
    P = np.zeros(coef.shape[:2] + (n_sec, 4, 6))
    P[:, :, ex[:, 0], ex[:, 1], ex[:, 2]] = coef
    return P


def model_jacobian(coef, A, U) -> np.ndarray:
    """Jacobian d(dA/dt)/dA of a model on the physical library at one state.

    Parameters
    ----------
    coef : ndarray, shape (S, 23 S)
        Coefficients on :func:`vivbench.core.terms.evaluate_library`.
    A, U : ndarray, shape (S,), m and m/s

    Returns
    -------
    ndarray, shape (S, S), 1/s
        J[m, k] = d f_m / d A_k. Its largest real eigenvalue is the growth rate
        of small deviations of A from the trajectory (the true VIV dynamics
        have rates of order 1e-3..1e-2 1/s).
    """
    P = _polynomials(np.asarray(coef, dtype=float)[None])[0]  # (m, k, i, j)
    A = np.asarray(A, dtype=float)
    U = np.asarray(U, dtype=float)
    i = np.arange(4)
    dApow = i[None, :] * np.where(i[None, :] >= 1, A[:, None] ** np.maximum(i - 1, 0)[None, :], 0.0)  # (k, i)
    Upow = U[:, None] ** np.arange(6)[None, :]  # (k, j)
    return np.einsum("mkij,ki,kj->mk", P, dApow, Upow)


def _grid(result: xr.Dataset, t0: float, t1: float):
    t_all = np.asarray(result["time"].values, dtype=float)
    if not (np.isfinite(t0) and np.isfinite(t1) and t1 > t0):
        raise InputError(f"need finite t0 < t1; got t0={t0}, t1={t1}")
    # The grid is the result's: t0 and t1 snap to the nearest samples.
    i0 = int(np.argmin(np.abs(t_all - t0)))
    i1 = int(np.argmin(np.abs(t_all - t1)))
    if i1 - i0 < 1:
        raise InputError(f"[{t0:g}, {t1:g}] s holds fewer than two samples of the result's grid")
    return i0, i1 + 1


def gap_reason(t: np.ndarray, i: int) -> str:
    """Why a simulation stopped at the gap in the record from sample i to i + 1 of ``t`` (s): its wind is unknown."""
    return f"the record has no samples between t = {t[i]:.2f} and {t[i + 1]:.2f} s (a gap: no wind to integrate on)"


def _stage_U(t: np.ndarray, U: np.ndarray, u_interp: str, gap: int | None = None) -> tuple[np.ndarray, int]:
    """U at t_k, t_k + h/2, t_k + h for every step: (n - 1, 3 stages, S), and the usable steps.

    The spline is built on the samples before the first non-finite U, or up to sample ``gap`` where the
    step from it is a gap in the record; steps past it are reported as unusable so that the run stops there.
    """
    bad = ~np.all(np.isfinite(U), axis=1)
    n_ok = int(np.argmax(bad)) if bad.any() else t.size
    if gap is not None:
        n_ok = min(n_ok, gap + 1)
    n_steps = max(n_ok - 1, 0)
    out = np.full((t.size - 1, 3, U.shape[1]), np.nan)
    if n_steps == 0:
        return out, 0
    tt, UU = t[:n_ok], U[:n_ok]
    k = 3 if (u_interp == "cubic" and n_ok >= 4) else 1
    spline = make_interp_spline(tt, UU, k=k, axis=0)
    mid = 0.5 * (tt[:-1] + tt[1:])
    out[:n_steps, 0] = UU[:-1]
    out[:n_steps, 1] = spline(mid)
    out[:n_steps, 2] = UU[1:]
    return out, n_steps


def _integrate(t, A0, U_stage, n_ok, P, widx, bound, neg, lims=None, clip="none"):
    """Fixed-step RK4; returns A (n, S), index of the first invalid sample (or None), reason.

    ``lims`` = (a_lo, a_hi, u_lo, u_hi), each (n_models, S), indexed like ``P``
    by ``widx``: with ``clip`` "u" the model sees U clipped to its model's
    range, with "au" also A (the state itself is not clipped, only the
    argument of the right-hand side).
    """
    n, n_sec = t.size, P.shape[1]
    A = np.full((n, n_sec), np.nan)
    A[0] = A0
    if not np.all(np.isfinite(A0)):
        return A, 0, "measured A at t0 is not finite"
    w = widx[:n_ok]
    U_use = U_stage[:n_ok]
    if clip != "none":
        U_use = np.clip(U_use, lims[2][w][:, None, :], lims[3][w][:, None, :])
    # C[step, stage, m, k*4 + i] = sum_j P[m, k, i, j] U_k^j, all steps at once.
    Upow = U_use[:, :, :, None] ** np.arange(6)
    C = np.einsum("wmkij,wskj->wsmki", P[w], Upow).reshape(n_ok, 3, n_sec, 4 * n_sec)
    if clip == "au":
        a_lo, a_hi = lims[0][w], lims[1][w]
    else:
        a_lo = np.full((n_ok, n_sec), -np.inf)
        a_hi = np.full((n_ok, n_sec), np.inf)
    pw = np.arange(4)

    def f(a, k, stage):
        return C[k, stage] @ (np.clip(a, a_lo[k], a_hi[k])[:, None] ** pw).ravel()

    run = rk4(f, A[0], t, stop=StopRule(upper=bound, lower=-neg), n_steps=n_ok)
    A = run.x
    if run.stop >= 0:
        k, when = int(run.stop), f"at t = {t[int(run.stop)]:.2f} s"
        if run.reason == NON_FINITE:
            return A, k, f"A became non-finite {when}"
        if run.reason == ABOVE:
            return A, k, f"A exceeded {bound:.3g} m (bound_factor x largest measured A) {when}"
        return A, k, f"A fell below -{neg:.3g} m (negative_tolerance x largest measured A) {when}"
    if n_ok < n - 1:
        return A, n_ok + 1, f"measured U is missing at t = {t[n_ok + 1]:.2f} s"
    return A, None, None


def _run(result, i0, i1, P, widx, *, method, u_interp, bound_factor, negative_tolerance, windows, coef,
         clip="none", lims=None):
    if clip not in CLIP_MODES:
        raise InputError(f"clip must be one of {CLIP_MODES}; got {clip!r}")
    if method not in _METHODS:
        raise InputError(f"method must be one of {_METHODS}; got {method!r}")
    if u_interp not in _U_INTERP:
        raise InputError(f"u_interp must be one of {_U_INTERP}; got {u_interp!r}")
    if not (bound_factor > 1 and negative_tolerance >= 0):
        raise InputError(f"need bound_factor > 1 and negative_tolerance >= 0; got {bound_factor}, {negative_tolerance}")
    A_all = np.asarray(result["A"].values, dtype=float)
    if A_all.ndim != 2 or A_all.shape[1] != P.shape[1]:
        raise InputError(f"result['A'] must have shape (time, {P.shape[1]}), one column per section of "
                         f"result['coef']; got {A_all.shape}")
    a_max = float(np.nanmax(np.abs(A_all))) if np.isfinite(A_all).any() else np.nan
    if not (np.isfinite(a_max) and a_max > 0):
        raise InputError("the measured A has no positive finite value to set the blow-up bounds")
    t = np.asarray(result["time"].values, dtype=float)[i0:i1]
    A_meas = A_all[i0:i1]
    U = np.asarray(result["U"].values, dtype=float)[i0:i1]
    gap = first_gap(result["time"].values, i0, i1)
    gap = None if gap is None else gap - i0
    U_stage, n_ok = _stage_U(t, U, u_interp, gap)
    A_sim, stop, reason = _integrate(t, A_meas[0], U_stage, n_ok, P, widx, bound_factor * a_max,
                                     negative_tolerance * a_max, lims=lims, clip=clip)
    if gap is not None and n_ok == gap and stop == gap + 1:  # the steps ended at the gap, not at a missing U
        reason = gap_reason(t, gap)
    if stop is None:
        stopped_at, covered = None, 1.0
    else:
        stopped_at = float(t[stop])
        covered = float((t[stop - 1] - t[0]) / (t[-1] - t[0])) if stop > 0 else 0.0
    return Simulation(t=t, A_sim=A_sim, A_meas=A_meas, stopped_at=stopped_at, reason=reason,
                      nmse=nmse(A_sim, A_meas), covered=covered, windows=windows, coef=coef)


def simulate_identified(result: xr.Dataset, *, t0: float | None = None, t1: float | None = None, method: str = "rk4",
                   u_interp: str = "cubic", bound_factor: float = 10.0,
                   negative_tolerance: float = 0.05, clip: str = "none") -> Simulation:
    """Integrate the time-varying model from the measured A at t0 to t1.

    Parameters
    ----------
    result : xarray.Dataset
        Identification result (``coef`` (window, S, 23 S), ``window_start``,
        ``window_end``, ``A`` and ``U`` (time, S) on coordinate ``time``).
    t0, t1 : float, s, optional
        Span; default the first fitted window's start to the last one's end.
        Both snap to the nearest sample of the result's grid.
    method : {"rk4"}
        Fixed-step classical Runge-Kutta on the result's grid.
    u_interp : {"cubic", "linear"}
        Interpolation of the measured U at the RK4 half steps.
    bound_factor : float
        The run stops when A exceeds this multiple of the largest measured A.
    negative_tolerance : float
        The run stops when A falls below minus this fraction of the largest measured A.
    clip : {"none", "u", "au"}
        "none" (the paper's method): every model is evaluated wherever the
        trajectory goes. "u": each model sees U clipped, per section, to the
        range of U over the window it was fitted on (:func:`window_ranges`); a
        model is only valid on the data it saw. "au": A clipped likewise (the
        simulated A itself is not changed, only the argument of the model).

    Returns
    -------
    Simulation
        ``windows`` holds the window in force during each step.
    """
    coef, start, end, fitted = _window_table(result)
    t0 = float(start[fitted].min()) if t0 is None else float(t0)
    t1 = float(end[fitted].max()) if t1 is None else float(t1)
    i0, i1 = _grid(result, t0, t1)
    t = np.asarray(result["time"].values, dtype=float)[i0:i1]
    widx = window_in_force(result, t[:-1])
    lims = window_ranges(result) if clip != "none" else None
    return _run(result, i0, i1, _polynomials(coef), widx, method=method, u_interp=u_interp,
                bound_factor=bound_factor, negative_tolerance=negative_tolerance, windows=widx, coef=None,
                clip=clip, lims=lims)


def forecast(result: xr.Dataset, t0: float, horizon: float, *, d: float = 0.0, method: str = "rk4",
             u_interp: str = "cubic", bound_factor: float = 10.0, negative_tolerance: float = 0.05,
             clip: str = "none") -> Simulation:
    """Forecast from the measured A at t0 over [t0, t0 + horizon] with fixed coefficients.

    The coefficients are :func:`forecast_coefficients` (t0, d); the wind is
    the measured U(t). Other parameters as in :func:`simulate_identified`;
    with ``clip`` the range is the union of the ranges of the windows averaged.

    Returns
    -------
    Simulation
        ``coef`` holds the coefficients used, ``windows`` the windows averaged.
    """
    if not (np.isfinite(horizon) and horizon > 0):
        raise InputError(f"horizon must be a finite duration > 0 s; got {horizon}")
    coef, windows = forecast_coefficients(result, t0, d)
    i0, i1 = _grid(result, float(t0), float(t0) + float(horizon))
    widx = np.zeros(i1 - i0 - 1, dtype=int)
    lims = None
    if clip != "none":
        lims = tuple(f(r[windows], axis=0, keepdims=True)
                     for f, r in zip((np.nanmin, np.nanmax, np.nanmin, np.nanmax), window_ranges(result)))
    return _run(result, i0, i1, _polynomials(coef[None]), widx, method=method, u_interp=u_interp,
                bound_factor=bound_factor, negative_tolerance=negative_tolerance, windows=windows, coef=coef,
                clip=clip, lims=lims)


def forecast_table(result: xr.Dataset, t0: float, horizon: float, ds=(0, 50, 150, 300), **kwargs) -> list[dict]:
    """NMSE of forecasts from t0 for several averaging durations d.

    Parameters
    ----------
    result : xarray.Dataset
    t0, horizon : float, s
    ds : sequence of float, s
    **kwargs
        Passed to :func:`forecast`.

    Returns
    -------
    list of dict
        One row per (d, section): ``d``, ``section``, ``nmse`` (over the valid
        part only), ``stopped`` (bool), ``stopped_at`` (s or None), ``reason``,
        ``covered`` (fraction of the horizon), ``n_windows`` (windows averaged).
        A stopped run keeps its partial NMSE and is flagged, never given a
        made-up value.
    """
    sections = ([str(s) for s in result["equation"].values] if "equation" in result.coords
                else [f"S{k + 1}" for k in range(result["A"].shape[1])])
    rows = []
    for d in ds:
        sim = forecast(result, t0, horizon, d=float(d), **kwargs)
        for s, name in enumerate(sections):
            rows.append({"d": float(d), "section": name, "nmse": float(sim.nmse[s]), "stopped": sim.stopped,
                         "stopped_at": sim.stopped_at, "reason": sim.reason, "covered": sim.covered,
                         "n_windows": int(sim.windows.size)})
    return rows
