"""Multiple shooting of the averaged amplitude equation over a whole campaign, with exact sensitivities.

The grey-box model (:mod:`vivbench.models.greybox`) integrates the modal
amplitude Q of docs/concepts.md (the truth),

    dQ/dt = g_0(t) + g_1(t) Q + g_2(t) Q^2 + g_3(t) Q^3,

whose coefficients g_i(t) are fixed by the wind history and the unknown
B-spline coefficients theta of Y1, e1, e2 and C_L. This module holds the
numerical side of the output-error fit:

- :func:`shooting_grid` cuts every record into runs of finite samples on the
  fit grid and every run into shooting intervals of ``n`` steps (the last
  interval of a run padded with zero weights, so all intervals have the same
  length and one mapped CasADi function serves them all);
- :class:`StepFunctions` is one classical RK4 step of the cubic amplitude
  equation as a CasADi function, with its exact Jacobian with respect to Q and
  to the twelve g values it reads (at the step's start, midpoint and end),
  mapped over all intervals: a Python loop runs over the ``n`` steps of an
  interval, never over samples or intervals;
- :func:`propagate` integrates all intervals at once and, on request, the
  forward sensitivities dQ/d(s_i, theta) by the chain rule through g, which is
  linear in the spline values (so dg/dtheta costs one small product per step).

The Gauss-Newton normal equations are assembled in
:mod:`vivbench.models.greybox_solve`.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from vivbench.preprocess.runs import mask_runs

__all__ = ["ShootingGrid", "shooting_grid", "StepFunctions", "propagate", "rk4_step_function"]


@dataclass(frozen=True)
class ShootingGrid:
    """All shooting intervals of a campaign on the fit grid.

    Attributes
    ----------
    U : ndarray, shape (I, 2 n + 1, S), m/s
        Section winds at the RK4 stage points of each interval (grid points at
        even indices, midpoints, the mean of their neighbours, at odd ones).
    A : ndarray, shape (I, n + 1, S), m
        Measured amplitudes at the grid points (0 where padded).
    weight : ndarray, shape (I, n + 1)
        1 where a residual counts (each grid sample once: the end point of an
        interval counts only for the last interval of a run), 0 elsewhere.
    event : ndarray of int, shape (I,)
        Index of the record each interval comes from.
    next : ndarray of int, shape (I,)
        Index of the following interval of the same run, -1 at a run's end
        (continuity ties the end of interval i to the start of ``next[i]``).
    t : ndarray, shape (I, n + 1), s
        Times of the grid points (padded points continue the grid).
    h : float, s
        Step of the fit grid.
    yaw : ndarray, shape (I, 2 n + 1, S), degrees
        The mean wind's yaw at the stage points, like ``U``; 0 where the
        record carries none or it is missing (perpendicular wind: no yaw
        effect is assumed there).
    has_yaw : ndarray of bool, shape (I,)
        Whether the interval's record carries a measured yaw.
    """

    U: np.ndarray
    A: np.ndarray
    weight: np.ndarray
    event: np.ndarray
    next: np.ndarray
    t: np.ndarray
    h: float
    yaw: np.ndarray
    has_yaw: np.ndarray

    @property
    def n_intervals(self) -> int:
        return int(self.A.shape[0])

    @property
    def n_steps(self) -> int:
        return int(self.A.shape[1] - 1)


def shooting_grid(records, *, dt: float, n_steps: int, min_points: int = 10) -> ShootingGrid:
    """Cut records into runs on a grid of step ``dt`` and the runs into intervals of ``n_steps``.

    Parameters
    ----------
    records : sequence of Record
        Their samples must lie on a uniform time grid whose step divides ``dt``
        (up to 1 %); NaN marks missing samples, which end a run.
    dt : float, s
        Step of the fit grid (a multiple of the records' step).
    n_steps : int
        Steps per shooting interval.
    min_points : int
        Runs with fewer grid points are left out.

    Returns
    -------
    ShootingGrid
    """
    Us, As, Ws, Ev, Ts, nxt, Ys, HY = [], [], [], [], [], [], [], []
    for e, rec in enumerate(records):
        t = rec.t
        if t.size < 2:
            continue
        step = float(np.median(np.diff(t)))
        stride = max(1, int(round(dt / step)))
        if abs(stride * step - dt) > 0.01 * dt:
            raise ValueError(f"record {rec.event_id}: its step {step:g} s does not divide the fit step {dt:g} s")
        idx = np.arange(0, t.size, stride)
        ts, A, U = t[idx], rec.A[idx], rec.U[idx]
        measured = getattr(rec, "yaw", None) is not None
        Y = np.nan_to_num(rec.yaw[idx], nan=0.0) if measured else np.zeros_like(U)
        ok = np.isfinite(A).all(axis=1) & np.isfinite(U).all(axis=1) & (U > 0).all(axis=1)
        # a gap in time (samples missing from the record) also ends a run
        ok[1:] &= np.abs(np.diff(ts) - stride * step) < 0.5 * step
        for run in mask_runs(ok):
            a, b = run.start, run.stop
            if b - a < min_points:
                continue
            n_pts = b - a
            n_int = int(np.ceil((n_pts - 1) / n_steps))
            pad = n_int * n_steps + 1 - n_pts
            sl = slice(a, b)
            Ar = np.concatenate([A[sl], np.repeat(A[b - 1:b], pad, axis=0)])
            Ur = np.concatenate([U[sl], np.repeat(U[b - 1:b], pad, axis=0)])
            Yr = np.concatenate([Y[sl], np.repeat(Y[b - 1:b], pad, axis=0)])
            tr = ts[a] + dt * np.arange(n_pts + pad)
            wr = np.concatenate([np.ones(n_pts), np.zeros(pad)])
            first = len(Ev)
            for j in range(n_int):  # a handful of intervals per run
                sl_j = slice(j * n_steps, j * n_steps + n_steps + 1)
                Aj, Uj, wj = Ar[sl_j], Ur[sl_j], wr[sl_j].copy()
                if j < n_int - 1:
                    wj[-1] = 0.0  # counted as the next interval's first point
                Umid = 0.5 * (Uj[1:] + Uj[:-1])
                Ufine = np.empty((2 * n_steps + 1, Uj.shape[1]))
                Ufine[0::2], Ufine[1::2] = Uj, Umid
                Us.append(Ufine)
                Yj = Yr[sl_j]
                Yfine = np.empty_like(Ufine)
                Yfine[0::2], Yfine[1::2] = Yj, 0.5 * (Yj[1:] + Yj[:-1])
                Ys.append(Yfine)
                HY.append(measured)
                As.append(Aj)
                Ws.append(wj)
                Ts.append(tr[sl_j])
                Ev.append(e)
                nxt.append(first + j + 1 if j < n_int - 1 else -1)
    if not Ev:
        raise ValueError("no run of finite samples long enough for the grey-box fit")
    return ShootingGrid(U=np.stack(Us), A=np.stack(As), weight=np.stack(Ws), event=np.array(Ev),
                        next=np.array(nxt), t=np.stack(Ts), h=float(dt), yaw=np.stack(Ys), has_yaw=np.array(HY))


def rk4_step_function() -> ca.Function:
    """One RK4 step of dQ/dt = g0 + g1 Q + g2 Q^2 + g3 Q^3 as a CasADi function.

    Inputs ``Q`` (1), ``g`` (12: the four g at the step's start, midpoint and
    end), ``h`` (1, s); output ``Q_next`` (1).
    """
    Q = ca.SX.sym("Q")
    g = ca.SX.sym("g", 12)
    h = ca.SX.sym("h")

    def f(q, c):
        return c[0] + q * (c[1] + q * (c[2] + q * c[3]))

    ga, gm, gb = g[0:4], g[4:8], g[8:12]
    k1 = f(Q, ga)
    k2 = f(Q + 0.5 * h * k1, gm)
    k3 = f(Q + 0.5 * h * k2, gm)
    k4 = f(Q + h * k3, gb)
    Qn = Q + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return ca.Function("rk4_step", [Q, g, h], [Qn], ["Q", "g", "h"], ["Q_next"])


class StepFunctions:
    """RK4 trajectories of ``n_parallel`` intervals of ``n_steps`` steps, and the step Jacobians, one call each.

    The mapped functions are evaluated through CasADi's buffer interface on
    numpy memory: converting arrays of a million numbers to CasADi matrices
    and back cost several times the evaluation itself.
    """

    def __init__(self, n_parallel: int, n_steps: int, h: float):
        step = rk4_step_function()
        Q, g, hs = step.mx_in()
        Qn = step(Q, g, hs)
        jac = ca.Function("rk4_step_jac", [Q, g, hs], [Qn, ca.jacobian(Qn, Q), ca.jacobian(Qn, g)]).expand()
        self.n_parallel, self.n_steps = int(n_parallel), int(n_steps)
        N = self.n_parallel * self.n_steps
        # mapaccum over the steps of an interval, map over the intervals
        self._traj = step.mapaccum("interval", self.n_steps).map(self.n_parallel, "serial")
        self._jac = jac.map(N, "serial")
        self._h = np.full(N, float(h))
        self._s = np.zeros(self.n_parallel)
        self._G = np.zeros((N, 12))  # column-major (12, N): the twelve g of each step contiguous
        self._Q = np.zeros(N)
        self._Qout = np.zeros(N)
        self._dQ = np.zeros(N)
        self._dG = np.zeros((N, 12))
        self._tb, self._tev = self._traj.buffer()
        for i, arr in enumerate((self._s, self._G, self._h)):
            self._tb.set_arg(i, memoryview(arr))
        self._tb.set_res(0, memoryview(self._Qout))
        self._jb, self._jev = self._jac.buffer()
        for i, arr in enumerate((self._Q, self._G, self._h)):
            self._jb.set_arg(i, memoryview(arr))
        for i, arr in enumerate((self._Qout, self._dQ, self._dG)):
            self._jb.set_res(i, memoryview(arr))

    def trajectory(self, s: np.ndarray, G: np.ndarray) -> np.ndarray:
        """Q after every step, shape (I, n), from node states s (I,) and G (I, n, 12)."""
        self._s[:] = s
        self._G[:] = G.reshape(-1, 12)
        self._tev()
        return self._Qout.reshape(self.n_parallel, self.n_steps).copy()

    def jacobian(self, Q: np.ndarray, G: np.ndarray):
        """dQ_next/dQ (I, n) and dQ_next/dg (I, n, 12) at step starts Q (I, n) with G (I, n, 12)."""
        self._Q[:] = Q.ravel()
        self._G[:] = G.reshape(-1, 12)
        self._jev()
        return (self._dQ.reshape(self.n_parallel, self.n_steps).copy(),
                self._dG.reshape(self.n_parallel, self.n_steps, 12).copy())


def propagate(funcs: StepFunctions, s: np.ndarray, g: np.ndarray, h: float, dg_dtheta=None):
    """Integrate every interval from its node state; optionally the sensitivities.

    Parameters
    ----------
    funcs : StepFunctions for I intervals of n steps
    s : ndarray, shape (I,)
        Node states (modal amplitude at each interval's start), m.
    g : ndarray, shape (I, 2 n + 1, 4)
        Coefficients of the amplitude equation at the stage points.
    h : float, s (the step the functions were built with)
    dg_dtheta : callable or None
        ``dg_dtheta(w)`` with the step Jacobians ``w`` (I, n, 3, 4) =
        dQ_{j+1}/dg at the start, midpoint and end of step j returns
        sum_p,i w[..., p, i] dg_{p,i}/dtheta, shape (I, n, P). None: values only.

    Returns
    -------
    Q : ndarray, shape (I, n + 1), m
    sens : ndarray, shape (I, n + 1, 1 + P) or None
        dQ_j / d(s, theta).
    """
    I, nf, _ = g.shape
    n = (nf - 1) // 2
    # the twelve g of every step: start, midpoint, end
    G = np.concatenate([g[:, 0:-1:2], g[:, 1::2], g[:, 2::2]], axis=2)  # (I, n, 12)
    Q = np.empty((I, n + 1))
    Q[:, 0] = s
    with np.errstate(over="ignore", invalid="ignore"):
        Q[:, 1:] = funcs.trajectory(s, G)
        if dg_dtheta is None:
            return Q, None
        dQ, dG = funcs.jacobian(Q[:, :-1], G)
        D = dg_dtheta(dG.reshape(I, n, 3, 4))  # (I, n, P)
        sens = np.empty((I, n + 1, 1 + D.shape[2]))
        sens[:, 0, 0], sens[:, 0, 1:] = 1.0, 0.0
        for j in range(n):  # the chain rule along an interval; all intervals at once
            sens[:, j + 1] = dQ[:, j, None] * sens[:, j]
            sens[:, j + 1, 1:] += D[:, j]
    return Q, sens
