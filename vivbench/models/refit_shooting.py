"""Gauss-Newton multiple shooting of the library-coefficient refit (the solver of :mod:`vivbench.models.refit`).

The refit's model is dx/dt = f(x, u; c) in the scaled state x = A / a (one
amplitude per section), with c the physical coefficients on the support and
c = G p for the scaled (whitened) decision coefficients p. The segment's grid
is cut into J shooting intervals of ``n_steps`` grid steps (the last one
padded with zero-length steps, which leave the state as it is, so every
interval has the same number of steps and one mapped CasADi function serves
them all). The decision variables are the node states X_j (S each; X_0 fixed
to the first measured sample unless the initial state is free) and p. The
cost is

    Phi = sum over grid samples of |x_sim - x_meas|^2      (each sample once)
        + w_c sum_j |x_end,j - X_{j+1}|^2                  (continuity, weight w_c)
        + ridge |p|^2

whose residual Jacobian is exact: one CasADi function gives the RK4 grid step
and its Jacobians with respect to the state and to c, mapped over the J
intervals, and the sensitivities d x / d(X_j, c) follow by the chain rule
along the steps of an interval (a Python loop over the ``n_steps`` steps of
an interval, never over samples or intervals). The residual Jacobian is
assembled densely (rows: samples and defects; columns: node states and p)
and Phi is minimised by the Levenberg-Marquardt control of
:mod:`vivbench.models.gauss_newton`, with the continuity weight raised 100-fold
per stage from ``first_weight`` to ``continuity_weight`` (as in the grey-box
refit).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from vivbench.models.gauss_newton import continuation_weights, levenberg_marquardt

__all__ = ["LibraryShooting", "LibraryGaussNewtonResult", "solve_library_gauss_newton"]


class LibraryShooting:
    """Residuals and exact Gauss-Newton model of the library refit on one segment.

    Parameters
    ----------
    step : casadi.Function
        ``step(x (S), u0 (S), u1 (S), h, c (n_c)) -> x_next (S)``: one grid step
        (RK4 substeps, U linear between the samples), scaled state.
    x_meas : ndarray, shape (n, S)
        Measured amplitudes divided by their scale a (-).
    U : ndarray, shape (n, S), m/s
    h : ndarray, shape (n - 1,), s
        Grid steps.
    n_steps : int
        Grid steps per shooting interval.
    G : ndarray, shape (n_c, n_p)
        Physical coefficients on the support from the scaled ones: c = G p.
    ridge : float
        Weight of |p|^2.
    fixed_initial_state : bool
        X_0 is the first measured sample (not a variable).
    """

    def __init__(self, step, x_meas, U, h, n_steps: int, G, *, ridge: float = 0.0,
                 fixed_initial_state: bool = True):
        import casadi as ca

        n, S = x_meas.shape
        N = int(max(1, min(n_steps, n - 1)))
        J = -(-(n - 1) // N)
        pad = J * N - (n - 1)
        self.S, self.N, self.J, self.n = S, N, J, n
        self.G = np.asarray(G, dtype=float)
        self.n_c, self.n_p = self.G.shape
        self.ridge = float(ridge)
        self.fixed = bool(fixed_initial_state)
        self.x_first = np.asarray(x_meas[0], dtype=float)
        x_pad = np.concatenate([x_meas, np.repeat(x_meas[-1:], pad, axis=0)])
        U_pad = np.concatenate([U, np.repeat(U[-1:], pad, axis=0)])
        h_pad = np.concatenate([h, np.zeros(pad)])  # zero-length steps keep the state
        k = np.arange(J)[:, None] * N + np.arange(N)[None, :]  # (J, N) step index
        self.u0 = U_pad[k]  # (J, N, S)
        self.u1 = U_pad[k + 1]
        self.h = h_pad[k]  # (J, N)
        kk = np.arange(J)[:, None] * N + np.arange(N + 1)[None, :]
        self.xm = x_pad[kk]  # (J, N + 1, S)
        w = (kk < n).astype(float)
        w[:-1, -1] = 0.0  # an interval's end sample is the next interval's first
        self.sw = np.sqrt(w)
        x = ca.SX.sym("x", S)
        u0 = ca.SX.sym("u0", S)
        u1 = ca.SX.sym("u1", S)
        hs = ca.SX.sym("h")
        c = ca.SX.sym("c", self.n_c)
        xn = step(x, u0, u1, hs, c)
        one = ca.Function("step", [x, u0, u1, hs, c], [xn])
        # mapaccum over the steps of an interval, map over the intervals: one call per trajectory evaluation
        self._traj = one.mapaccum("interval", N).map(J, "serial")
        # the step Jacobians of every step of every interval, one call per linearisation
        self._jac = ca.Function("step_jac", [x, u0, u1, hs, c],
                                [ca.jacobian(xn, x), ca.jacobian(xn, c)]).map(J * N, "serial")
        self._u0 = self.u0.reshape(J * N, S).T.copy()  # (S, J N): column j N + k
        self._u1 = self.u1.reshape(J * N, S).T.copy()
        self._h = self.h.reshape(1, J * N).copy()
        self.continuity_weight = 1.0
        n_nodes = J * S
        self.n_var = n_nodes + self.n_p
        self.free = np.ones(self.n_var, dtype=bool)
        if self.fixed:
            self.free[:S] = False

    # ------------------------------------------------------------------ variables

    def pack(self, X: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Free variables from node states X (J, S) and p (n_p,)."""
        return np.concatenate([np.asarray(X, dtype=float).ravel(), np.asarray(p, dtype=float)])[self.free]

    def unpack(self, z: np.ndarray):
        """Node states (J, S) and p (n_p,) from the free variables."""
        v = np.empty(self.n_var)
        v[self.free] = z
        if self.fixed:
            v[:self.S] = self.x_first
        return v[:self.J * self.S].reshape(self.J, self.S), v[self.J * self.S:]

    # ------------------------------------------------------------------ evaluation

    def trajectories(self, X: np.ndarray, p: np.ndarray, jacobian: bool = False):
        """States on every interval's grid points (J, N + 1, S) and, on request, d x / d(X_j, c).

        The sensitivities have shape (J, N + 1, S, S + n_c): with respect to the
        interval's own node state, then to the physical coefficients.
        """
        J, N, S = self.J, self.N, self.S
        c = self.G @ p
        traj = np.empty((J, N + 1, S))
        traj[:, 0] = X
        with np.errstate(over="ignore", invalid="ignore"):
            out = np.asarray(self._traj(np.asarray(X, dtype=float).T, self._u0, self._u1, self._h, c))
            traj[:, 1:] = out.T.reshape(J, N, S)
            if not jacobian:
                return traj, None
            dx, dc = self._jac(traj[:, :-1].reshape(J * N, S).T, self._u0, self._u1, self._h, c)
            dx = np.asarray(dx).reshape(S, J, N, S).transpose(1, 2, 0, 3)  # (J, N, S, S): [j, k, a, b]
            dc = np.asarray(dc).reshape(S, J, N, self.n_c).transpose(1, 2, 0, 3)  # (J, N, S, n_c)
            sens = np.zeros((J, N + 1, S, S + self.n_c))
            sens[:, 0, :, :S] = np.eye(S)
            for k in range(N):  # the chain rule along an interval; all intervals at once
                sens[:, k + 1] = np.matmul(dx[:, k], sens[:, k])
                sens[:, k + 1, :, S:] += dc[:, k]
        return traj, sens

    def residuals(self, X, p, traj):
        """Data residuals (J, N + 1, S) and scaled continuity defects (J - 1, S)."""
        r = self.sw[..., None] * (traj - self.xm)
        d = np.sqrt(self.continuity_weight) * (traj[:-1, -1] - X[1:])
        return r, d

    def cost(self, z: np.ndarray) -> float:
        """Phi at the free variables z (inf when a trajectory is not finite)."""
        X, p = self.unpack(z)
        traj, _ = self.trajectories(X, p)
        with np.errstate(over="ignore", invalid="ignore"):  # a trial step may blow up: cost inf, step rejected
            r, d = self.residuals(X, p, traj)
            val = float(np.sum(r**2) + np.sum(d**2) + self.ridge * (p @ p))
        return val if np.isfinite(val) else np.inf

    def linearise(self, z: np.ndarray):
        """Phi, the Gauss-Newton matrix J^T J (ridge included), J^T r, and (data sum of squares, max defect)."""
        J, N, S, n_p = self.J, self.N, self.S, self.n_p
        X, p = self.unpack(z)
        traj, sens = self.trajectories(X, p, jacobian=True)
        r, d = self.residuals(X, p, traj)
        sens_p = np.concatenate([sens[..., :S], sens[..., S:] @ self.G], axis=-1)  # (J, N+1, S, S + n_p)
        cw = np.sqrt(self.continuity_weight)
        n_data = J * (N + 1) * S
        n_rows = n_data + (J - 1) * S
        Jm = np.zeros((n_rows, self.n_var))
        pcols = slice(J * S, J * S + n_p)
        data = (self.sw[..., None, None] * sens_p).reshape(J, (N + 1) * S, S + n_p)
        rows = np.arange((N + 1) * S)
        for j in range(J):  # one block of rows per interval (a few dozen intervals)
            Jm[j * (N + 1) * S + rows, j * S:(j + 1) * S] = data[j, :, :S]
            Jm[j * (N + 1) * S:(j + 1) * (N + 1) * S, pcols] = data[j, :, S:]
            if j < J - 1:
                rr = n_data + j * S + np.arange(S)
                Jm[rr, j * S:(j + 1) * S] = cw * sens_p[j, -1, :, :S]
                Jm[rr, pcols] = cw * sens_p[j, -1, :, S:]
                Jm[rr, (j + 1) * S + np.arange(S)] = -cw
        res = np.concatenate([r.ravel(), d.ravel()])
        Jf = Jm[:, self.free]
        H = Jf.T @ Jf
        g = Jf.T @ res
        pf = np.flatnonzero(self.free[J * S:]) + int(self.free[:J * S].sum())
        H[pf, pf] += self.ridge
        g[pf] += self.ridge * p
        data_ssq = float(np.sum(r**2))
        phi = data_ssq + float(np.sum(d**2)) + self.ridge * float(p @ p)
        defect = float(np.max(np.abs(traj[:-1, -1] - X[1:]), initial=0.0))
        return (phi if np.isfinite(phi) else np.inf), H, g, (data_ssq, defect)


@dataclass(frozen=True)
class LibraryGaussNewtonResult:
    """Outcome of :func:`solve_library_gauss_newton`.

    Attributes
    ----------
    p : ndarray, shape (n_p,)
        Scaled coefficients.
    X : ndarray, shape (J, S)
        Node states (scaled).
    objective : float
        Data sum of squares plus ridge term (the IPOPT refit's objective).
    cost : float
        Phi with the final continuity weight.
    max_defect : float
        Largest continuity defect (scaled state units, -).
    iterations : int
        Linearisations (Jacobian evaluations), all stages.
    converged : bool
    message : str
    seconds : float, s
    history : list of float
        Phi at the start of every iteration.
    """

    p: np.ndarray
    X: np.ndarray
    objective: float
    cost: float
    max_defect: float
    iterations: int
    converged: bool
    message: str
    seconds: float
    history: list


def solve_library_gauss_newton(problem: LibraryShooting, X0: np.ndarray, p0: np.ndarray, *, max_iter: int = 100,
                               tol: float = 1e-6, continuity_weight: float = 1e6, first_weight: float = 1e2,
                               callback=None) -> LibraryGaussNewtonResult:
    """Levenberg-Marquardt on the exact Gauss-Newton model, with continuation on the continuity weight.

    Parameters
    ----------
    problem : LibraryShooting
    X0 : ndarray, shape (J, S)
        Starting node states (row 0 is replaced by the first measured sample
        when the initial state is fixed).
    p0 : ndarray, shape (n_p,)
    max_iter : int
        Linearisations at most, all continuation stages together.
    tol : float
        Stop a stage when an accepted step lowers Phi by less than ``tol`` times Phi.
    continuity_weight : float
        Final weight of a squared continuity defect relative to one grid sample's.
    first_weight : float
        First stage's weight (100-fold per stage up to ``continuity_weight``).
    callback : callable or None
        ``callback(iteration, cost, mu)`` after every accepted step.

    Returns
    -------
    LibraryGaussNewtonResult

    Raises
    ------
    ValueError
        When Phi is not finite at the start (a trajectory blows up inside an interval).
    """
    t_start = time.perf_counter()
    weights = continuation_weights(continuity_weight, first_weight)
    z = problem.pack(X0, p0)
    lower = np.full(z.size, -np.inf)
    history: list = []
    total, converged, message = 0, False, "no iteration"
    lin = None
    for stage, weight in enumerate(weights):
        problem.continuity_weight = weight
        # the budget is shared: early stages get an equal part, the last stage what is left
        budget = max_iter - total if stage == len(weights) - 1 else max_iter // len(weights)
        z, lin, it, converged, message = levenberg_marquardt(
            problem.linearise, problem.cost, z, lower, max_iter=max(0, budget), tol=tol, history=history,
            callback=callback, offset=total,
            start_error="the refit's start gives a non-finite cost (a simulation blows up inside an interval)")
        total += it
    X, p = problem.unpack(z)
    data_ssq, defect = lin[3]
    return LibraryGaussNewtonResult(p=p, X=X, objective=data_ssq + problem.ridge * float(p @ p), cost=float(lin[0]),
                                    max_defect=defect, iterations=total, converged=converged, message=message,
                                    seconds=time.perf_counter() - t_start, history=history)
