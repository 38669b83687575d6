"""Output-error refit of the coefficients on a fixed support (docs/field_workflow.md): the solve.

The comparison over a segment of an identification result is in :mod:`vivbench.models.refit`.

SINDy fits dA/dt (an equation error), so its coefficients inherit the bias
and noise of the numerical derivative. The refit here fits the *trajectory*
instead: for a support (which library terms each equation may use) it finds
coefficients Xi such that the solution of dA/dt = Theta(A, U) Xi^T, driven by
the measured wind U(t), matches the measured A(t) in least squares over every
grid sample. It is a reference independent of numerical differentiation.

Method (multiple shooting through CasADi; Gauss-Newton by default):

- The segment's grid is cut into shooting intervals of ``shooting_interval``
  seconds. The state at the start of every interval is a decision variable;
  inside an interval the model is integrated by classical RK4 with
  ``substeps`` steps per grid step, U linear between the grid samples (U is
  an input, not a state). Continuity ties the end of each interval to the
  next start.
- The objective is the sum over all grid samples and sections of the squared
  difference between the simulated and the measured A, each section divided
  by the RMS of its measured A, plus ``ridge`` times the squared norm of the
  scaled coefficients.
- Solver ``"gauss-newton"`` (default, :mod:`vivbench.models.refit_shooting`):
  Levenberg-Marquardt on the exact Gauss-Newton matrix of the residuals
  (data rows, continuity defects weighted by ``continuity_weight`` relative to
  one sample, ridge rows), the residual Jacobian built from CasADi Jacobians
  of the vectorised RK4 step; the step control is shared with the grey-box
  refit (:mod:`vivbench.models.gauss_newton`). Continuity holds as a heavy
  penalty, not exactly: ``RefitResult.max_defect`` reports the largest
  defect. Measured (``benchmarks/study_refit.py``, README): on the true
  40-term support of an in-library event (800 s) NMSE 1e-5 in 94 s and
  0.34 GB, where IPOPT stopped at 5 minutes and 2.7 GB with NMSE 4.6. On
  the identified (rank-deficient) support of a realistic VIV segment no
  solver gives a model that simulates the segment: use the grey-box refit
  (:mod:`vivbench.models.greybox`) for reference coefficients there.
- Solver ``"ipopt"``: the NLP with exact continuity constraints, one CasADi
  Function per grid step, ``mapaccum`` over an interval (expanded to SX) and
  ``map`` over the intervals. Hessian exact (CasADi AD) for at most 24
  supported terms, IPOPT's L-BFGS above (the exact Hessian of the expanded
  intervals grows to gigabytes). Kept for comparison: it converges on small
  supports only.
- Start: the given coefficients (their dA/dt on the measured samples
  projected onto the fitted directions) with the node states on their
  simulated trajectory from the first measured A when it stays bounded (a
  feasible start: from the measured A at the nodes IPOPT was seen to end in a
  worse local minimum), else on the measured A; zero coefficients when the
  given ones blow up inside a shooting interval.

Scaling. The solvers see scaled variables only: state x_m = A_m / a_m (a_m the RMS
of the measured A_m), and, per equation, coefficients p_m in a whitened basis
of the supported columns. The supported columns, evaluated on the measured
(A, U), are scaled to unit RMS (matrix D) and decomposed B = W S V^T; the
physical coefficients are xi_m = D^-1 V_r S_r^-1 p_m c_m, so that each p_m
direction moves dx_m/dt by the same RMS amount c_m / a_m (c_m sets it to the
RMS rate of change of x_m). This keeps the problem well conditioned even though the
raw monomials U^j over a narrow band of U are nearly collinear (condition
numbers of 1e6 and more). Directions with singular values below
``rank_rtol`` times the largest are dropped: they do not change dA/dt on the
measured trajectory, so the data cannot fix them. The coefficients are
reported in physical units, with zeros off the support.

Identifiability. With A_k = phi_k Q (one mode) the A columns of the three
sections are proportional, and terms of different sections with the same
power of A differ only through U_k. A support that mixes sections (the full
3-section support of the truth, or a union of SINDy supports) is then exactly
or nearly rank deficient: the refit coefficients are *one* representative of
a family with (nearly) the same trajectories. :class:`RefitResult` reports the
numerical rank and condition number of each equation's supported library;
when the rank is below the support size or the condition number is large,
compare trajectories (NMSE) and order contributions, not raw coefficients.
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass

import numpy as np
import xarray as xr

from vivbench.models.refit_shooting import LibraryShooting, solve_library_gauss_newton
from vivbench.models.simulate import Simulation, simulate_identified
from vivbench.core.terms import evaluate_library, feature_exponents, feature_names, section_exponents
from vivbench.core.errors import InputError

__all__ = ["RefitConfig", "RefitResult", "refit_coefficients", "simulate_coefficients", "order_rms"]

_HESSIANS = ("auto", "exact", "limited-memory")
#: "auto" uses the exact Hessian up to this many supported coefficients: above
#: it, CasADi's exact Hessian of the expanded intervals costs gigabytes.
_EXACT_HESSIAN_MAX_TERMS = 24
_SOLVERS = ("gauss-newton", "ipopt")
#: Library terms per section (A^i U^j, i <= 3, j <= 5, not both 0): S sections give 23 S columns.
_TERMS_PER_SECTION = section_exponents().shape[0]


@dataclass(frozen=True, kw_only=True)
class RefitConfig:
    """Settings of the output-error refit.

    Attributes
    ----------
    shooting_interval : float, s
        Length of a shooting interval (rounded to whole grid steps, at least one).
    substeps : int
        RK4 steps per grid step inside the intervals.
    max_iter : int
        Iteration limit: IPOPT iterations, or Gauss-Newton linearisations
        (all continuation stages of the continuity weight together).
    tol : float or None
        Convergence tolerance: IPOPT's (on the scaled problem; default 1e-10),
        or for Gauss-Newton the relative decrease of the cost below which a
        stage stops (default 1e-6).
    ridge : float
        Weight of the squared norm of the scaled coefficients in the objective
        (0: none). Scaled coefficients are O(1), so 1e-6..1e-3 is "small".
    rank_rtol : float
        Whitened directions with singular value below this fraction of the
        largest are not fitted (see module docstring).
    hessian : {"auto", "exact", "limited-memory"}
        IPOPT Hessian: exact (CasADi AD) or L-BFGS; ``"auto"``: exact for at
        most 24 supported coefficients, L-BFGS above (the exact Hessian of a
        40-term-per-equation support over 100 s took > 4 GB of memory).
    expand : bool
        Expand the (mapped) MX graph into scalar SX operations before solving:
        slower to build, much faster to evaluate for these small states.
    free_initial_state : bool
        Fit the initial state too (classical output error) instead of fixing
        it to the first measured A. Fixed by default, so that the objective
        is the one the reported NMSE measures (simulation from the first
        measured A): on event E001 (seed 0), 300-900 s, a 5-term support per
        section, the free-state fit scored NMSE 0.039 from the measured A,
        the fixed-state fit 0.00026. For coefficient estimation from noisy A
        the free state is better (tests/models/test_refit.py: with 1.5 % noise the
        fixed state beat the equation-error fit in 5 of 8 seeds, the free
        state in 7 of 8).
    bound_factor, negative_tolerance : float
        Blow-up bounds of the evaluation simulations (see vivbench.models.simulate).
    max_wall_time : float or None, s
        Wall-clock limit of IPOPT (None: none; the Gauss-Newton solver is
        bounded by ``max_iter``).
    solver : {"gauss-newton", "ipopt"}
        ``"gauss-newton"`` (default): Levenberg-Marquardt on the exact
        Gauss-Newton matrix (:mod:`vivbench.models.refit_shooting`), the
        continuity conditions as a heavily weighted penalty. ``"ipopt"``: the
        NLP with exact continuity constraints; kept for comparison (see
        ``benchmarks/study_refit.py``), it does not converge on large supports.
    continuity_weight : float
        Gauss-Newton only: final weight of a squared continuity defect
        relative to one grid sample's squared residual (reached by 100-fold
        continuation from 100).
    """

    shooting_interval: float = 20.0
    substeps: int = 1
    max_iter: int = 200
    tol: float | None = None
    ridge: float = 0.0
    rank_rtol: float = 1e-10
    hessian: str = "auto"
    expand: bool = True
    free_initial_state: bool = False
    bound_factor: float = 10.0
    negative_tolerance: float = 0.05
    max_wall_time: float | None = None
    solver: str = "gauss-newton"
    continuity_weight: float = 1e6

    def __post_init__(self) -> None:
        if not (np.isfinite(self.shooting_interval) and self.shooting_interval > 0):
            raise InputError(f"shooting_interval must be a positive number of seconds; got {self.shooting_interval}")
        if not (isinstance(self.substeps, (int, np.integer)) and self.substeps >= 1):
            raise InputError(f"substeps must be an integer >= 1; got {self.substeps!r}")
        if not (isinstance(self.max_iter, (int, np.integer)) and self.max_iter >= 1):
            raise InputError(f"max_iter must be an integer >= 1; got {self.max_iter!r}")
        if self.tol is not None and not (np.isfinite(self.tol) and self.tol > 0):
            raise InputError(f"tol must be > 0; got {self.tol}")
        if not (np.isfinite(self.ridge) and self.ridge >= 0):
            raise InputError(f"ridge must be >= 0; got {self.ridge}")
        if not (0 <= self.rank_rtol < 1):
            raise InputError(f"rank_rtol must be in [0, 1); got {self.rank_rtol}")
        if self.hessian not in _HESSIANS:
            raise InputError(f"hessian must be one of {_HESSIANS}; got {self.hessian!r}")
        if self.solver not in _SOLVERS:
            raise InputError(f"solver must be one of {_SOLVERS}; got {self.solver!r}")
        if not (np.isfinite(self.continuity_weight) and self.continuity_weight >= 1e2):
            raise InputError(f"continuity_weight must be a finite number >= 100; got {self.continuity_weight}")
        if self.max_wall_time is not None and not (np.isfinite(self.max_wall_time) and self.max_wall_time > 0):
            raise InputError(f"max_wall_time must be a positive number of seconds or None; got {self.max_wall_time}")
        if not (self.bound_factor > 1 and self.negative_tolerance >= 0):
            raise InputError(f"need bound_factor > 1 and negative_tolerance >= 0; got {self.bound_factor}, "
                             f"{self.negative_tolerance}")


@dataclass(frozen=True, kw_only=True)
class RefitResult:
    """Outcome of :func:`refit_coefficients`.

    Attributes
    ----------
    coef : ndarray, shape (S, 23 S)
        Refit coefficients in physical units (zeros off the support), S sections.
    support : ndarray of bool, shape (S, 23 S)
    success : bool
        The solver reported success (IPOPT) or convergence (Gauss-Newton).
    status : str
        IPOPT return status, or the Gauss-Newton stopping message.
    iterations : int
        IPOPT iterations, or Gauss-Newton linearisations (all stages).
    objective : float
        Final objective (scaled, see module docstring).
    simulation : Simulation
        The refit model simulated from the first measured A over the whole grid.
    nmse : ndarray, shape (S,)
        ``simulation.nmse``.
    support_size, rank : ndarray of int, shape (S,)
        Supported terms and fitted (whitened) directions per equation.
    cond : ndarray, shape (S,)
        Condition number of each equation's supported library on the measured
        (A, U), columns scaled to unit RMS (inf when rank deficient, NaN for an
        empty support).
    wall_time : float, s
        Building and solving the NLP.
    start : {"coef0-trajectory", "coef0", "zero"}
        Starting point: ``coef0`` with the nodes on its simulated trajectory
        (when that stays bounded), ``coef0`` with the nodes on the measured
        A, or zero coefficients when ``coef0`` made the model blow up inside
        a shooting interval (non-finite objective or derivatives).
    solver : {"gauss-newton", "ipopt"}
    max_defect : float
        Largest continuity defect at the solution (scaled state, -): 0 up to
        IPOPT's tolerance for IPOPT, small but nonzero for the Gauss-Newton
        penalty.
    """

    coef: np.ndarray
    support: np.ndarray
    success: bool
    status: str
    iterations: int
    objective: float
    simulation: Simulation
    nmse: np.ndarray
    support_size: np.ndarray
    rank: np.ndarray
    cond: np.ndarray
    wall_time: float
    start: str = "coef0"
    solver: str = "ipopt"
    max_defect: float = 0.0

    @property
    def identifiable(self) -> bool:
        """Every supported direction was fitted (rank == support size) and cond < 1e6.

        A rule of thumb: with cond >= 1e6 a relative error of 1e-6 in the
        library (far below the envelope's) can move the coefficients by O(1).
        """
        used = self.support_size > 0
        return bool(np.all(self.rank[used] == self.support_size[used]) and np.all(self.cond[used] < 1e6))


# ---------------------------------------------------------------------------- simulation


def _one_window_result(t, A, U, coef) -> xr.Dataset:
    sections = [f"S{k + 1}" for k in range(A.shape[1])]
    return xr.Dataset(
        {
            "coef": (("window", "equation", "feature"), np.asarray(coef, dtype=float)[None]),
            "window_start": (("window",), [float(t[0])]),
            "window_end": (("window",), [float(t[-1])]),
            "A": (("time", "section"), A),
            "U": (("time", "section"), U),
        },
        coords={"window": [0], "equation": sections, "feature": feature_names(len(sections)), "time": t,
                "section": sections},
    )


def simulate_coefficients(t, A, U, coef, *, bound_factor: float = 10.0, negative_tolerance: float = 0.05) -> Simulation:
    """Simulate fixed coefficients from the first measured A, U linear between samples.

    Uses :func:`vivbench.models.simulate.simulate_identified` (RK4 on the
    grid, blow-ups stopped and reported); the bounds refer to the largest
    measured A of this grid.

    Parameters
    ----------
    t : ndarray, shape (n,), s
    A, U : ndarray, shape (n, S), m and m/s
    coef : ndarray, shape (S, 23 S)

    Returns
    -------
    Simulation
    """
    t = np.asarray(t, dtype=float)
    res = _one_window_result(t, np.asarray(A, dtype=float), np.asarray(U, dtype=float), coef)
    return simulate_identified(res, t0=float(t[0]), t1=float(t[-1]), u_interp="linear", bound_factor=bound_factor,
                               negative_tolerance=negative_tolerance)


def order_rms(A, U, coef) -> np.ndarray:
    """RMS over the samples of each order's contribution to dA_m/dt.

    Parameters
    ----------
    A, U : ndarray, shape (n, S), m and m/s
    coef : ndarray, shape (S, 23 S)

    Returns
    -------
    ndarray, shape (S, 4), m/s
        [m, i]: RMS of sum over the columns with A-power i of Theta_c xi_mc.
    """
    theta = evaluate_library(A, U)
    coef = np.asarray(coef, dtype=float)
    power = feature_exponents(coef.shape[0])[:, 1]
    out = np.zeros((coef.shape[0], 4))
    for i in range(4):
        sel = power == i
        contrib = theta[:, sel] @ coef[:, sel].T
        out[:, i] = np.sqrt(np.mean(contrib**2, axis=0))
    return out


# ---------------------------------------------------------------------------- the NLP


def _check_inputs(t, A, U, support, coef0):
    t = np.asarray(t, dtype=float)
    A = np.asarray(A, dtype=float)
    U = np.asarray(U, dtype=float)
    support = np.asarray(support)
    coef0 = np.asarray(coef0, dtype=float)
    if t.ndim != 1 or t.size < 3:
        raise ValueError(f"t must be a 1-D grid of at least 3 samples; got shape {t.shape}")
    if not (np.all(np.isfinite(t)) and np.all(np.diff(t) > 0)):
        raise InputError("t must be finite and strictly increasing")
    if A.ndim != 2 or A.shape[1] < 1:
        raise ValueError(f"A must have shape (n, S), one column per section; got {A.shape}")
    n_sec = A.shape[1]
    n_feat = _TERMS_PER_SECTION * n_sec
    for name, x in (("A", A), ("U", U)):
        if x.shape != (t.size, n_sec):
            raise ValueError(f"{name} must have shape (n, S) = ({t.size}, {n_sec}); got {x.shape}")
        if not np.all(np.isfinite(x)):
            raise InputError(f"{name} has non-finite values on the segment; refit a gap-free segment")
    if support.shape != (n_sec, n_feat) or support.dtype != bool:
        raise ValueError(f"support must be a boolean array of shape (S, 23 S) = ({n_sec}, {n_feat}); "
                         f"got {support.dtype} {support.shape}")
    if not support.any():
        raise InputError("the support is empty: no coefficient to refit")
    if coef0.shape != (n_sec, n_feat) or not np.all(np.isfinite(coef0[support])):
        raise ValueError(f"coef0 must have shape (S, 23 S) = ({n_sec}, {n_feat}) and be finite on the support; "
                         f"got shape {coef0.shape}")
    if np.any(np.sqrt(np.mean(A**2, axis=0)) == 0):
        raise InputError("a section's measured A is identically zero; nothing to scale it by")
    return t, A, U, support, coef0


def _whitening(theta, support, a, rate, rank_rtol):
    """Per equation: G (|S_m|, r_m) mapping scaled p_m to physical xi_m[S_m], rank, cond."""
    n, n_sec = theta.shape[0], support.shape[0]
    G, rank, cond = [], np.zeros(n_sec, dtype=int), np.full(n_sec, np.nan)
    for m in range(n_sec):
        cols = np.flatnonzero(support[m])
        if cols.size == 0:
            G.append(np.zeros((0, 0)))
            continue
        d = np.sqrt(np.mean(theta[:, cols] ** 2, axis=0))
        if np.any(d == 0):
            bad = [feature_names(n_sec)[c] for c in cols[d == 0]]
            raise InputError(f"supported terms {bad} of equation {m + 1} vanish on the whole segment")
        _w, s, vt = np.linalg.svd(theta[:, cols] / d, full_matrices=False)
        keep = s > rank_rtol * s[0]
        rank[m] = int(keep.sum())
        cond[m] = s[0] / s[-1] if (s[-1] > 0 and rank[m] == cols.size) else np.inf
        # B V_r S_r^-1 = W_r has orthonormal columns; sqrt(n) makes them unit RMS.
        G.append((vt[keep].T / s[keep]) / d[:, None] * (np.sqrt(n) * rate[m] * a[m]))
    return G, rank, cond


def _project_start(theta_m, G_m, coef_m):
    """Scaled coefficients p whose dA/dt on the measured samples is closest to ``theta_m @ coef_m``."""
    B = theta_m @ G_m  # orthogonal columns of equal norm (see _whitening)
    return np.linalg.lstsq(B, theta_m @ coef_m, rcond=None)[0]


def _build_rhs(support, a):
    """CasADi Function f(x (S), u (S), c) -> dx/dt (S) in scaled state x = A / a, S sections.

    c holds the physical coefficients on the support, equation by equation
    (row-major order of ``support``); the map from the scaled decision
    variables to c is applied once, outside the integration, so the graph per
    step stays as small as the support.
    """
    import casadi as ca

    n_sec = support.shape[0]
    ex = feature_exponents(n_sec)
    n_c = int(support.sum())
    x = ca.SX.sym("x", n_sec)
    u = ca.SX.sym("u", n_sec)
    c = ca.SX.sym("c", n_c)
    A = x * ca.DM(a)
    theta = {}
    for col in np.flatnonzero(support.any(axis=0)):
        s, i, j = (int(v) for v in ex[col])
        theta[col] = A[s] ** i * u[s] ** j if i and j else (A[s] ** i if i else u[s] ** j)
    rhs, k = [], 0
    for m in range(n_sec):
        cols = np.flatnonzero(support[m])
        terms = [theta[col] * c[k + q] for q, col in enumerate(cols)]
        k += cols.size
        rhs.append(sum(terms[1:], terms[0]) / a[m] if terms else ca.SX(0))
    return ca.Function("rhs", [x, u, c], [ca.vertcat(*rhs)]), n_c


def _hessian(kind: str, n_c: int) -> str:
    if kind == "auto":
        return "exact" if n_c <= _EXACT_HESSIAN_MAX_TERMS else "limited-memory"
    return kind


def _block_diag(G):
    rows = sum(g.shape[0] for g in G)
    cols = sum(g.shape[1] for g in G)
    out = np.zeros((rows, cols))
    r = c = 0
    for g in G:
        out[r:r + g.shape[0], c:c + g.shape[1]] = g
        r, c = r + g.shape[0], c + g.shape[1]
    return out


def _build_step(rhs, n_c, substeps):
    """One grid step: RK4 substeps with U linear between the grid samples."""
    import casadi as ca

    n_sec = rhs.size1_in(0)  # the state: one scaled amplitude per section
    x = ca.SX.sym("x", n_sec)
    u0 = ca.SX.sym("u0", n_sec)
    u1 = ca.SX.sym("u1", n_sec)
    h = ca.SX.sym("h")
    p = ca.SX.sym("c", n_c)
    dt = h / substeps
    xk = x
    for q in range(substeps):
        ua = u0 + (u1 - u0) * (q / substeps)
        um = u0 + (u1 - u0) * ((q + 0.5) / substeps)
        ub = u0 + (u1 - u0) * ((q + 1.0) / substeps)
        k1 = rhs(xk, ua, p)
        k2 = rhs(xk + 0.5 * dt * k1, um, p)
        k3 = rhs(xk + 0.5 * dt * k2, um, p)
        k4 = rhs(xk + dt * k3, ub, p)
        xk = xk + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return ca.Function("step", [x, u0, u1, h, p], [xk])


def _solve(t, x_meas, x_init, U, step, Gblk, p0, config: RefitConfig):
    """Multiple-shooting NLP; returns p, IPOPT stats, objective."""
    import casadi as ca

    n = t.size
    h = np.diff(t)
    n_steps = n - 1
    N = int(max(1, min(n_steps, round(config.shooting_interval / np.median(h)))))
    J_full, rem = divmod(n_steps, N)
    starts = np.array([j * N for j in range(J_full)] + ([J_full * N] if rem else []), dtype=int)
    J = starts.size

    n_c, n_p = Gblk.shape
    n_sec = x_meas.shape[1]
    X = ca.MX.sym("X", n_sec, J)
    p = ca.MX.sym("p", n_p)
    c = ca.mtimes(ca.DM(Gblk), p)  # physical coefficients on the support
    ssq, ends = [], []

    def block(n_int, first_interval, n_j):
        """n_j intervals of n_int steps each: (sum of squared residuals, end states (S, n_j))."""
        acc = step.mapaccum("acc", n_int)
        x0 = ca.MX.sym("x0", n_sec)
        ua = ca.MX.sym("ua", n_sec, n_int)
        ub = ca.MX.sym("ub", n_sec, n_int)
        hh = ca.MX.sym("h", 1, n_int)
        meas = ca.MX.sym("meas", n_sec, n_int + 1)
        w_end = ca.MX.sym("w_end")
        pp = ca.MX.sym("c", n_c)
        xs = acc(x0, ua, ub, hh, pp)  # states after each step, (S, n_int)
        traj = ca.horzcat(x0, xs)
        # the end sample belongs to the next interval, except at the end of the segment
        r = ca.sumsqr(traj[:, :n_int] - meas[:, :n_int]) + w_end * ca.sumsqr(traj[:, n_int] - meas[:, n_int])
        interval = ca.Function("interval", [x0, ua, ub, hh, meas, w_end, pp], [r, xs[:, n_int - 1]])
        if config.expand:
            # one interval as scalar SX code: evaluation and derivatives of the map stay cheap
            interval = interval.expand()
        s0 = starts[first_interval:first_interval + n_j]
        idx = (s0[:, None] + np.arange(n_int)).ravel()
        midx = (s0[:, None] + np.arange(n_int + 1)).ravel()
        w = np.zeros(n_j)
        if first_interval + n_j == J:
            w[-1] = 1.0
        out_r, out_x = interval.map(n_j)(X[:, first_interval:first_interval + n_j], ca.DM(U[idx].T),
                                         ca.DM(U[idx + 1].T), ca.DM(h[idx][None, :]), ca.DM(x_meas[midx].T),
                                         ca.DM(w[None, :]), c)
        ssq.append(ca.sum2(out_r))
        ends.append(out_x)

    if J_full:
        block(N, 0, J_full)
    if rem:
        block(rem, J_full, 1)
    end_states = ca.horzcat(*ends)  # (S, J)
    # a plain sum, not a mean: a mean makes the gradients so small that IPOPT stops at once
    obj = sum(ssq) + config.ridge * ca.sumsqr(p)
    g = ca.vec(end_states[:, :J - 1] - X[:, 1:]) if J > 1 else ca.MX(0, 1)
    w = ca.vertcat(ca.vec(X), p)
    opts = {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes", "ipopt.max_iter": int(config.max_iter),
            "ipopt.tol": float(1e-10 if config.tol is None else config.tol), "ipopt.hessian_approximation": _hessian(config.hessian, n_c),
            # IPOPT's trial points may make the model blow up; it backs off by itself, so no warnings.
            "show_eval_warnings": False}
    if config.max_wall_time is not None:
        opts["ipopt.max_wall_time"] = float(config.max_wall_time)
    solver = ca.nlpsol("refit", "ipopt", {"x": w, "f": obj, "g": g}, opts)
    w0 = np.concatenate([x_init[starts].ravel(), p0])  # vec(X) is column-major: nodes one after another
    fg = ca.Function("fg", [w], [obj, g, ca.gradient(obj, w), ca.jacobian(g, w)])
    start = "coef0"
    if not all(np.all(np.isfinite(np.asarray(v))) for v in fg(w0)):
        # coef0 blows up (or its derivatives overflow) inside a shooting interval;
        # zero coefficients (dA/dt = 0) never do.
        w0 = np.concatenate([x_meas[starts].ravel(), np.zeros(n_p)])
        start = "zero"
    lbx = np.full(w0.size, -np.inf)
    ubx = np.full(w0.size, np.inf)
    if not config.free_initial_state:
        # the first node is the measured A, as in the simulations that score the fit
        lbx[:n_sec] = ubx[:n_sec] = w0[:n_sec] = x_meas[0]
    sol = solver(x0=w0, lbg=0.0, ubg=0.0, lbx=lbx, ubx=ubx)
    stats = solver.stats()
    w_opt = np.asarray(sol["x"]).ravel()
    return w_opt[n_sec * J:], stats, float(sol["f"]), start


def _solve_gauss_newton(t, x_meas, x_init, U, step, Gblk, p0, config: RefitConfig):
    """Levenberg-Marquardt on the exact Gauss-Newton model; returns p, stats, objective, start, max defect."""
    h = np.diff(t)
    N = int(max(1, min(t.size - 1, round(config.shooting_interval / np.median(h)))))
    problem = LibraryShooting(step, x_meas, U, h, N, Gblk, ridge=config.ridge,
                              fixed_initial_state=not config.free_initial_state)
    starts = np.arange(problem.J) * N
    start = "coef0"
    try:
        problem.continuity_weight = 1e2
        ok = np.isfinite(problem.linearise(problem.pack(x_init[starts], p0))[0])
    except ValueError:
        ok = False
    if not ok:
        # coef0 blows up inside a shooting interval; zero coefficients (dA/dt = 0) never do.
        x_init, p0, start = x_meas, np.zeros_like(p0), "zero"
    sol = solve_library_gauss_newton(problem, x_init[starts], p0, max_iter=int(config.max_iter),
                                     tol=float(1e-6 if config.tol is None else config.tol),
                                     continuity_weight=float(config.continuity_weight), first_weight=1e2)
    stats = {"success": sol.converged, "return_status": sol.message, "iter_count": sol.iterations}
    return sol.p, stats, sol.objective, start, sol.max_defect


def refit_coefficients(t, A, U, support, coef0, config: RefitConfig | None = None) -> RefitResult:
    """Refit the coefficients on a support by matching the simulated trajectory to the measured A.

    Parameters
    ----------
    t : ndarray, shape (n,), s
        Time grid (strictly increasing, gap-free segment).
    A : ndarray, shape (n, S), m
        Measured amplitudes at the S sections.
    U : ndarray, shape (n, S), m/s
        Measured wind, linear between the samples.
    support : ndarray of bool, shape (S, 23 S)
        Terms each equation may use (library order of :mod:`vivbench.core.terms`).
        An equation with no term has dA/dt = 0.
    coef0 : ndarray, shape (S, 23 S)
        Starting coefficients (projected onto the fitted directions).
    config : RefitConfig

    Returns
    -------
    RefitResult
    """
    config = config or RefitConfig()
    t, A, U, support, coef0 = _check_inputs(t, A, U, support, coef0)
    t_start = _time.perf_counter()
    a = np.sqrt(np.mean(A**2, axis=0))
    x_meas = A / a
    span = t[-1] - t[0]
    rate = np.maximum(np.sqrt(np.mean((np.diff(x_meas, axis=0) / np.diff(t)[:, None]) ** 2, axis=0)), 1.0 / span)
    theta = evaluate_library(A, U)
    G, rank, cond = _whitening(theta, support, a, rate, config.rank_rtol)
    rhs, n_c = _build_rhs(support, a)
    step = _build_step(rhs, n_c, int(config.substeps))
    Gblk = _block_diag(G)
    n_p = Gblk.shape[1]
    # Starting point: coef0's dA/dt on the measured (A, U) projected onto the fitted directions.
    # (Projecting the coefficients themselves is wrong on an ill-conditioned support: coef0's
    # components along the dropped directions can be huge, and leaving them out changed dA/dt of
    # an equation-error fit on E013 of the default campaign by 1e4 m/s, so the start blew up.)
    p0 = np.concatenate([_project_start(theta[:, support[m]], G[m], coef0[m, support[m]])
                         for m in range(support.shape[0]) if G[m].size]) if n_p else np.zeros(0)
    # Nodes start on coef0's own trajectory when it stays bounded (a feasible start,
    # so IPOPT cannot end worse than coef0 by drifting to another local minimum).
    sim0 = simulate_coefficients(t, A, U, coef0 * support, bound_factor=config.bound_factor,
                                 negative_tolerance=config.negative_tolerance)
    x_init = sim0.A_sim / a if not sim0.stopped else x_meas
    defect = 0.0
    if config.solver == "ipopt":
        p_opt, stats, objective, start = _solve(t, x_meas, x_init, U, step, Gblk, p0, config)
    else:
        p_opt, stats, objective, start, defect = _solve_gauss_newton(t, x_meas, x_init, U, step, Gblk, p0, config)
    if start == "coef0" and not sim0.stopped:
        start = "coef0-trajectory"
    coef = np.zeros(support.shape)
    k = 0
    for m in range(support.shape[0]):
        r = G[m].shape[1] if G[m].size else 0
        if r:
            coef[m, support[m]] = G[m] @ p_opt[k:k + r]
            k += r
    wall = _time.perf_counter() - t_start
    sim = simulate_coefficients(t, A, U, coef, bound_factor=config.bound_factor,
                                negative_tolerance=config.negative_tolerance)
    return RefitResult(coef=coef, support=support.copy(), success=bool(stats.get("success", False)),
                       status=str(stats.get("return_status", "unknown")), iterations=int(stats.get("iter_count", -1)),
                       objective=objective, simulation=sim, nmse=sim.nmse, support_size=support.sum(axis=1),
                       rank=rank, cond=cond, wall_time=wall, start=start, solver=config.solver,
                       max_defect=float(defect))
