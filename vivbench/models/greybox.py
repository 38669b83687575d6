"""Grey-box reference refit: the averaged Simiu-Scanlan amplitude equation with spline functions of the wind.

The model is the amplitude equation of docs/concepts.md (the truth) for the modal amplitude Q
(section amplitudes A_k = |phi_k| Q):

    dQ/dt = sum_k beta_k rho U_k^2 D C_L / (4 m w)
            + [ -zeta w + sum_k beta_k phi_k c_k / 2 ] Q
            - sum_k beta_k phi_k c_k (2 / (3 pi)) (e1 |phi_k| / D) Q^2
            - sum_k beta_k phi_k c_k (1 / 8) (e2 phi_k^2 / D^2) Q^3,
    c_k = rho U_k D Y1(U_k) / m,

with Y1, e1, e2 and C_L evaluated at each section's own wind U_k, and Y1 and C_L multiplied by a yaw factor
(below). They are unknown smooth functions of the reduced velocity Ur = U / (f D), each a cubic B-spline
(P-spline: uniform knots over the data's range of Ur, a second-difference roughness penalty), not the
generator's parametric shapes, so the refit commits no inverse crime. The bridge's properties (modal mass per
length m, deck depth D, frequency f, air density rho, structural damping ratio zeta, mode shape phi and
tributary lengths L, beta_k = L_k phi_k / sum_l L_l phi_l^2) are the user's (:class:`BridgeProperties`); without
a mode shape |phi| is taken from the median amplitude ratios of the data (largest 1).

Structural damping is given, not fitted (:mod:`vivbench.models.greybox_physics`).

Fit (output error, all events at once): multiple shooting of Q over
intervals of ``shooting_interval`` seconds on a grid of step ``dt``, RK4 with
the wind linear between grid samples, residuals |phi_k| Q - A_k of every
section divided by the event's amplitude scale (so each event weighs as its
NMSE), Gauss-Newton/Levenberg-Marquardt on the exact Jacobian from CasADi
(:mod:`vivbench.models.greybox_solve`). Bounds: e1, e2, C_L >= 0 (the
limiting terms damp, the locked force feeds energy).

Yaw. Vortex shedding weakens as the mean wind turns away from the span's normal, and U = V |cos yaw| does not
carry that angle. When the records carry the measured yaw psi_k(t) (``Record.yaw``, degrees), Y1 and C_L at
section k are multiplied by w_k = 1 - c sin^2(psi_k), one coefficient c >= 0 fitted jointly with the splines (a
low-order even function of sin psi, not the generator's Gaussian in psi). Every term of the amplitude equation
holds Y1 or C_L exactly once, so w_k scales all of section k's factors. Records without a yaw get w = 1; when
none carries one, c is not fitted and the fit says so (``fit_info_["yaw"]``): Y1 and C_L are then averages over
the events' yaw angles. The curves (docs/concepts.md (coefficient curves)) and the physical functions are
reported at yaw 0 (w = 1), as the truth's are.

Starts: a multi-start (:mod:`vivbench.models.greybox_starts`), the penalty
scaled once at the first start so every start minimises one objective; the
draws come from ``seed``: the same data and seed give the same fit.

Penalty (``penalty_grid``): the fit at ``penalty`` is continued at every other value of the grid, and the fit
with the least generalised cross-validation score, GCV = n_eff RSS / (n_eff - edf)^2, is kept: edf the trace of
the influence matrix of the fit's Gauss-Newton linearisation, n_eff = n / kappa the effective sample size of the
correlated residuals (kappa of the fit at ``penalty``, below; :func:`vivbench.models.greybox_solve.gcv_score`).
The scores and the chosen value are in ``fit_info_["penalty_selection"]`` and ``fit_info_["penalty"]``.

Uncertainty (``band``), covariances of the spline coefficients
(:mod:`vivbench.models.greybox_solve`), bands by the delta method at ``level``:

- "sandwich_bias": the block sandwich (the estimator's variance,
  residuals correlated within an event) plus the prior-averaged squared
  smoothing bias sigma^2 kappa H^-1 R H^-1 (H = J^T J + R; the bias of the
  penalised estimator is -H^-1 R theta). With independent residuals it is
  the Bayesian posterior covariance below.
- "posterior": the Bayesian posterior covariance of the penalised spline,
  sigma^2 kappa H^-1 (Wahba 1983, Nychka 1988), residual variance sigma^2 =
  RSS / (n - edf), kappa the batch-means variance inflation of the residuals
  (block ``block_s``). The residuals' slow correlation acts on the spline
  directions more strongly than on their plain sum, which is all kappa sees,
  so these bands can be too narrow.
- "sandwich": the block sandwich alone, the estimator's variance only.
- "bootstrap" / "bootstrap_bias" (``n_boot`` > 0): the covariance of refits
  on events drawn with replacement (:mod:`vivbench.models.greybox_bootstrap`),
  alone or plus the bias term above; each replicate costs up to two
  continuation stages of Gauss-Newton iterations.
- "sandwich_bias_wind" (default; ``wind_draws`` >= 2): "sandwich_bias" plus the
  wind's errors-in-variables (:mod:`vivbench.models.greybox_wind`): the
  second moment of ``wind_draws`` refits (``wind_iter`` iterations a
  continuation stage from the optimum) with the wind perturbed by draws of
  the anemometers' error (another event's spread between the sections'
  anemometers, relative, permuted and signed), about the same refit with
  the wind unperturbed: their spread and their mean shift squared (the
  linear SIMEX estimate of the error's bias). ``band_components`` and the
  file's ``band_sd`` give each component's share. The truncated refits make
  the component of the order of the error's effect, not an exact estimate of it.

Bands of the other choices hold no error of the inputs, and none covers the
model's own limits (e.g. a truth whose yaw dependence is not of the form
1 - c sin^2 psi).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Sequence

import numpy as np
import xarray as xr

from vivbench.core.errors import InputError
from vivbench.core.record import Record
from vivbench.library.splines import bspline_basis, difference_penalty, uniform_knots
from vivbench.models.curve_support import mark_extrapolated
from vivbench.models.integrate import rk4
from vivbench.models.greybox_bootstrap import event_bootstrap
from vivbench.models.greybox_curves import FUNCTIONS, GreyBoxCurves
from vivbench.models.greybox_physics import (BridgeProperties, curves_to_functions, g_from_values, mode_geometry,
                                           section_factors)
from vivbench.models.greybox_shooting import shooting_grid
from vivbench.models.greybox_starts import greybox_starts
from vivbench.models.greybox_solve import (
    ShootingProblem,
    gcv_score,
    solve_gauss_newton,
)
from vivbench.models.greybox_wind import (
    relative_spread,
    unmeasured_wind_draws,
    wind_error_draws,
    wind_refits,
    wind_second_moment,
)
from vivbench.models.protocol import ModelBase, as_record, section_names
from vivbench.models.simulate import Simulation, gap_reason, nmse
from vivbench.preprocess.runs import first_gap

__all__ = ["BridgeProperties", "GreyBoxRefit", "FUNCTIONS", "BANDS", "curves_to_functions"]


#: What each ``band`` choice holds (stated in the fit's output).
_BAND_NOTES = {
    "posterior": "Bayesian posterior covariance sigma^2 kappa (J'J + R)^-1 (Wahba; Nychka 1988): variance and "
                 "smoothing bias averaged over the function, residual correlation by kappa",
    "sandwich": "block sandwich covariance: the estimator's variance only (no smoothing bias)",
    "sandwich_bias": "block sandwich plus the prior-averaged squared smoothing bias sigma^2 kappa H^-1 R H^-1 "
                     "(H = J'J + R): variance robust to the residual correlation, and smoothing bias",
    "bootstrap": "event bootstrap: covariance of refits on events drawn with replacement (warm-started "
                 "Gauss-Newton), the estimator's variance over events only (no smoothing bias)",
    "bootstrap_bias": "event bootstrap covariance plus the prior-averaged squared smoothing bias "
                      "sigma^2 kappa H^-1 R H^-1 of the sandwich_bias band",
    "sandwich_bias_wind": "sandwich_bias plus the second moment about the fit of refits with the wind perturbed "
                          "by draws of the anemometers' error (the wind's errors-in-variables: their spread and "
                          "squared mean shift, the linear SIMEX bias)",
}

#: The band choices (covariances of the spline coefficients).
BANDS = tuple(_BAND_NOTES)

#: Continuity weight of the first continuation stage (and of the screening of the starts).
_FIRST_WEIGHT = 1e2


def _thirds(x: np.ndarray) -> np.ndarray:
    """Values at the stage points (I, 2n+1, ...) -> at the start, midpoint and end of every step (I, n, 3, ...)."""
    return np.stack([x[:, 0:-1:2], x[:, 1::2], x[:, 2::2]], axis=2)


def _g_function(B, a, B3, a3, s2, s2_3, use_yaw: bool, zw: float, M: int):
    """``g_of(theta)`` of the shooting problem from the basis B and section factors a at the stage points.

    B (I, 2n+1, S, M), a (I, 2n+1, S, 4), their :func:`_thirds`, the yaw's sin^2 (or None).
    """

    def g_of(theta):
        C = theta[:4 * M].reshape(4, M)
        F = B @ C.T  # (I, 2n+1, S, 4)
        # every order holds Y1 or C_L exactly once: the yaw factor scales each section's factors
        w = 1.0 - theta[4 * M] * s2 if use_yaw else None
        g = g_from_values(F, a if w is None else a * w[..., None], zw)
        F3 = _thirds(F)
        aw3 = a3 if w is None else a3 * _thirds(w)[..., None]

        def dg(wt):
            Y, E1, E2 = F3[..., 0], F3[..., 1], F3[..., 2]
            w0, w1, w2, w3 = (wt[..., i][..., None] for i in range(4))
            cw = np.stack([w1 * aw3[..., 1] + w2 * aw3[..., 2] * E1 + w3 * aw3[..., 3] * E2,
                           w2 * aw3[..., 2] * Y, w3 * aw3[..., 3] * Y, w0 * aw3[..., 0]], axis=-1)
            d = np.einsum("ijpsm,ijpsf->ijfm", B3, cw, optimize=True).reshape(B3.shape[0], B3.shape[1], 4 * M)
            if not use_yaw:
                return d
            hyaw = g_from_values(F3, a3 * s2_3[..., None], 0.0)  # dg/dc = -hyaw, (I, n, 3, 4)
            return np.concatenate([d, -np.einsum("ijpf,ijpf->ij", wt, hyaw)[..., None]], axis=2)

        return g, dg

    return g_of


class GreyBoxRefit(GreyBoxCurves, ModelBase):
    """Grey-box output-error refit of Y1, e1, e2, C_L over a campaign (docs/field_workflow.md (the grey-box reference)).

    Parameters
    ----------
    bridge : BridgeProperties
    n_basis : int
        B-splines per function (cubic, uniform in reduced velocity over the data).
    penalty : float
        Roughness penalty of each function relative to its share of the
        Gauss-Newton matrix at the first start (trace ratio), a dimensionless
        weight: the value of the first fit, and the final one when
        ``penalty_grid`` is None.
    penalty_grid : tuple of float or None
        Penalties (same scale) whose fits are scored by GCV with the
        effective sample size (module docstring); None: ``penalty`` is kept.
    band : {"posterior", "sandwich", "sandwich_bias", "bootstrap", "bootstrap_bias", "sandwich_bias_wind"}
        Covariance of the bands: the Bayesian posterior covariance (bias
        included on average across the function), the block sandwich
        (variance only), the sandwich plus the prior-averaged squared bias
        (module docstring), the event bootstrap's covariance (``n_boot``
        replicates; variance only), the bootstrap's plus the same bias, or
        the sandwich plus bias plus the wind's errors-in-variables
        (``wind_draws`` >= 2).
    dt : float, s
        Step of the fit grid (a multiple of the records' step; the envelope is slow).
    shooting_interval : float, s
        Length of a shooting interval.
    max_iter : int
        Gauss-Newton iterations at most.
    tol : float
        Relative decrease of the cost below which the iterations stop.
    block_s : float, s
        Block length of the sandwich covariance and of the posterior's
        batch-means variance inflation: residuals are taken as
        correlated within a block of one event and independent between
        blocks. The default (a day) makes every event one block, which
        accounts for the slow model error that runs through an event.
    level : float
        Level of the confidence bands.
    continuity_weight : float
        Weight of a continuity defect relative to one grid sample.
    warm_start : xarray.Dataset or None
        Curves of docs/concepts.md (coefficient curves) (``curves``, e.g. the campaign model's ``curves(wind)``)
        to start from; None: an equation-error start.
    yaw_factor : bool
        Multiply Y1 and C_L by 1 - c sin^2(yaw) of the records' measured yaw
        (``Record.yaw``), c >= 0 fitted with the splines. Records without a
        yaw get factor 1 (all of them: c is not fitted).
    n_starts : int
        Starts of the multi-start: the warm start (if given), the
        equation-error start, then perturbed copies of the first. Each runs
        ``screen_iter`` iterations at the loosest continuity weight; the one
        with the lowest penalised cost there is iterated to convergence.
        1: the first start only.
    screen_iter : int
        Gauss-Newton iterations of a start's screening.
    start_spread : float
        Standard deviation of the log of the factors that scale each function
        in a perturbed start.
    seed : int
        Seed of the perturbed starts and of the bootstrap's event draws (the fit is deterministic).
    n_boot : int
        Replicates of the event bootstrap (:mod:`vivbench.models.greybox_bootstrap`)
        run after the fit; 0: none. The "bootstrap" bands need at least 20.
    boot_iter : int
        Levenberg-Marquardt iterations of a bootstrap replicate from the
        full fit's optimum in each of its two continuation stages (each one
        linearisation); a few iterations leave the replicates near the
        optimum and the band too narrow.
    wind_draws : int
        Refits with the wind perturbed by draws of the anemometers' error (their
        spread between sections, and for a section whose wind came from an
        anemometer elsewhere, ``Record.wind_distance``, the error over that
        distance; :mod:`vivbench.models.greybox_wind`) after the fit, for the band
        component of the wind's errors-in-variables (covariance "wind", band
        "sandwich_bias_wind"); 0: none (then pick another ``band``). Each
        costs about 2 (``wind_iter`` + 1) linearisations.
    wind_scale : float
        Factor on the drawn wind error's size (1: the spread between the
        sections' anemometers as it is).
    wind_iter : int
        Levenberg-Marquardt iterations of a wind refit from the optimum in
        each of its two continuation stages (truncated refits understate the
        error's effect, see the module docstring).

    Attributes
    ----------
    coef_ : ndarray, shape (4, n_basis)
        Spline coefficients of Y1, e1, e2, C_L (dimensionless functions).
    yaw_coef_ : float
        c of the yaw factor 1 - c sin^2(yaw) (0 when not fitted).
    yaw_used_ : bool
        Whether the yaw factor was fitted.
    cov_ : ndarray, shape (P, P)
        Covariance of the row-major flattening of ``coef_`` followed, when
        ``yaw_used_``, by ``yaw_coef_`` (P = 4 n_basis + 1): the ``band`` one.
    covariances_ : dict of ndarray, shape (P, P)
        All covariances by ``band`` name (for comparison; the bootstrap ones only with ``n_boot`` > 0).
    wind_coef_ : ndarray, shape (wind_draws, P) or None
        The wind refits' coefficients (None without them or after :meth:`load`).
    wind_reference_ : ndarray, shape (P,) or None
        The same refit with the wind unperturbed, the wind component's centre.
    boot_coef_ : ndarray, shape (n_boot, P) or None
        The bootstrap replicates' coefficients (None without a bootstrap or after :meth:`load`).
    penalty_ : float
        The penalty of the final fit (chosen by GCV when ``penalty_grid`` is given).
    knots_ : ndarray, reduced velocity
    phi_, beta_ : ndarray, shape (S,)
    wind_range_ : (float, float), m/s, the fitted data's range of wind
    fit_info_ : dict
        cost, iterations (of the final solve), converged, message, max_defect,
        seconds (the whole fit), final_solve_seconds, n_intervals,
        n_samples, start (the start that won), starts (each start and its
        screened cost), yaw (how the yaw entered).
    """

    _fitted_attribute = "coef_"

    def __init__(self, *, bridge: BridgeProperties | None = None, n_basis: int = 16, penalty: float = 0.3,
                 penalty_grid: tuple | None = (0.1, 0.3, 1.0),
                 band: str = "sandwich_bias_wind", dt: float = 1.0, shooting_interval: float = 60.0, max_iter: int = 30,
                 tol: float = 1e-3,
                 block_s: float = 86400.0, level: float = 0.95, continuity_weight: float = 1e6, warm_start=None,
                 yaw_factor: bool = True, n_starts: int = 4, screen_iter: int = 6, start_spread: float = 0.4,
                 seed: int = 0, n_boot: int = 0, boot_iter: int = 10, wind_draws: int = 4, wind_scale: float = 1.0,
                 wind_iter: int = 2):
        self.bridge = bridge
        self.n_basis = n_basis
        self.penalty = penalty
        self.penalty_grid = penalty_grid
        self.band = band
        self.dt = dt
        self.shooting_interval = shooting_interval
        self.max_iter = max_iter
        self.tol = tol
        self.block_s = block_s
        self.level = level
        self.continuity_weight = continuity_weight
        self.warm_start = warm_start
        self.yaw_factor = yaw_factor
        self.n_starts = n_starts
        self.screen_iter = screen_iter
        self.start_spread = start_spread
        self.seed = seed
        self.n_boot = n_boot
        self.boot_iter = boot_iter
        self.wind_draws = wind_draws
        self.wind_scale = wind_scale
        self.wind_iter = wind_iter

    def _validate(self) -> None:
        if not isinstance(self.bridge, BridgeProperties):
            raise InputError("GreyBoxRefit needs bridge=BridgeProperties(mass=..., depth=..., frequency=..., "
                             "damping_ratio=...)")
        if not (isinstance(self.n_basis, (int, np.integer)) and 5 <= self.n_basis <= 60):
            raise InputError(f"n_basis must be an integer in 5..60; got {self.n_basis!r}")
        for name in ("penalty", "dt", "shooting_interval", "tol", "block_s", "continuity_weight"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise InputError(f"{name} must be a finite positive number; got {v!r}")
        if self.penalty_grid is not None:
            grid = self.penalty_grid
            if (isinstance(grid, (str, bytes)) or not hasattr(grid, "__len__") or len(grid) == 0
                    or not all(isinstance(v, (int, float)) and math.isfinite(v) and v > 0 for v in grid)):
                raise InputError(f"penalty_grid must be None or a non-empty list of finite positive numbers; "
                                 f"got {grid!r}")
        if self.band not in BANDS:
            raise InputError(f"band must be one of {', '.join(repr(b) for b in BANDS)}; got {self.band!r}")
        if not (isinstance(self.n_boot, (int, np.integer)) and self.n_boot >= 0):
            raise InputError(f"n_boot must be a non-negative integer (0: no bootstrap); got {self.n_boot!r}")
        if self.band.startswith("bootstrap") and self.n_boot < 20:
            raise InputError(f"band {self.band!r} needs n_boot >= 20 bootstrap replicates; got {self.n_boot!r}")
        if not (isinstance(self.wind_draws, (int, np.integer)) and self.wind_draws >= 0):
            raise InputError(f"wind_draws must be a non-negative integer (0: none); got {self.wind_draws!r}")
        if self.band == "sandwich_bias_wind" and self.wind_draws < 2:
            raise InputError(f"band {self.band!r} needs wind_draws >= 2 refits with a perturbed wind; "
                             f"got {self.wind_draws!r}")
        if not (isinstance(self.wind_scale, (int, float)) and math.isfinite(self.wind_scale)
                and self.wind_scale >= 0):
            raise InputError(f"wind_scale must be a finite number >= 0; got {self.wind_scale!r}")
        if not (isinstance(self.wind_iter, (int, np.integer)) and self.wind_iter >= 1):
            raise InputError(f"wind_iter must be a positive integer; got {self.wind_iter!r}")
        if not (isinstance(self.boot_iter, (int, np.integer)) and self.boot_iter >= 1):
            raise InputError(f"boot_iter must be a positive integer; got {self.boot_iter!r}")
        if self.shooting_interval < self.dt:
            raise InputError(f"shooting_interval ({self.shooting_interval}) must be at least dt ({self.dt})")
        if not (isinstance(self.max_iter, (int, np.integer)) and self.max_iter >= 1):
            raise InputError(f"max_iter must be a positive integer; got {self.max_iter!r}")
        if not 0 < self.level < 1:
            raise InputError(f"level must lie strictly between 0 and 1; got {self.level!r}")
        for name in ("n_starts", "screen_iter"):
            v = getattr(self, name)
            if not (isinstance(v, (int, np.integer)) and v >= 1):
                raise InputError(f"{name} must be a positive integer; got {v!r}")
        if not (isinstance(self.start_spread, (int, float)) and math.isfinite(self.start_spread)
                and self.start_spread >= 0):
            raise InputError(f"start_spread must be a finite number >= 0; got {self.start_spread!r}")
        if not isinstance(self.seed, (int, np.integer)):
            raise InputError(f"seed must be an integer; got {self.seed!r}")
        if not isinstance(self.yaw_factor, (bool, np.bool_)):
            raise InputError(f"yaw_factor must be True or False; got {self.yaw_factor!r}")

    # ------------------------------------------------------------------ helpers

    def _ur(self, U):
        return np.asarray(U, dtype=float) / (self.bridge.frequency * self.bridge.depth)

    def basis_values(self, U: np.ndarray) -> np.ndarray:
        """B-spline values at winds U (any shape), shape U.shape + (M,)."""
        U = np.asarray(U, dtype=float)
        return bspline_basis(self._ur(U).ravel(), self.knots_).reshape(U.shape + (self.knots_.size - 4,))

    def function_values(self, U, coef: np.ndarray | None = None) -> np.ndarray:
        """Y1, e1, e2, C_L at winds U (any shape), shape U.shape + (4,) (dimensionless)."""
        self._check_fitted()
        coef = self.coef_ if coef is None else coef
        return self.basis_values(U) @ coef.T

    # ------------------------------------------------------------------ fit

    def fit(self, records: Sequence[Record | tuple], callback=None) -> "GreyBoxRefit":
        """Fit the spline functions (and the yaw coefficient) to the envelopes of all records at once.

        Parameters
        ----------
        records : sequence of Record (A, U and, when present, yaw are used; dA is not)
        callback : callable or None
            ``callback(iteration, cost, mu)`` after each accepted Gauss-Newton step
            (of the screening of the starts, then of the final fit).

        Returns
        -------
        self
        """
        self._validate()
        t_fit = time.perf_counter()
        records = [as_record(r, i) for i, r in enumerate(records)]
        if not records:
            raise InputError("GreyBoxRefit.fit needs at least one record")
        S = records[0].n_sections
        if any(r.n_sections != S for r in records):
            raise InputError("all records must have the same number of sections")
        phi, beta = mode_geometry(self.bridge, records)
        amp = np.abs(phi)
        n_steps = max(1, int(round(self.shooting_interval / self.dt)))
        grid = shooting_grid(records, dt=self.dt, n_steps=n_steps)
        lo, hi = float(np.min(grid.U)), float(np.max(grid.U))  # padding repeats real samples
        self.knots_ = uniform_knots(*self._ur(np.array([lo, hi])), self.n_basis)
        self.phi_, self.beta_, self.n_sections_ = phi, beta, S
        self.wind_range_ = (lo, hi)
        M = self.n_basis
        use_yaw = bool(self.yaw_factor) and bool(grid.has_yaw.any())
        self.yaw_used_ = use_yaw
        P = 4 * M + int(use_yaw)
        B = self.basis_values(grid.U)  # (I, 2n+1, S, M)
        a = section_factors(grid.U, self.bridge, phi, beta)  # (I, 2n+1, S, 4)
        zw = self.bridge.omega * self.bridge.damping_ratio
        scale = np.array([np.sqrt(np.nanmean(r.A**2)) for r in records])[grid.event]
        if np.any(~(scale > 0)):
            raise InputError("a record has no positive amplitude: the grey-box fit needs vibration data")
        Qm = (grid.A @ amp) / np.sum(amp**2)  # least-squares Q of the sections, (I, n+1)

        s2 = np.sin(np.radians(grid.yaw)) ** 2 if use_yaw else None  # (I, 2n+1, S)
        s2_3 = _thirds(s2) if use_yaw else None  # at the start, midpoint and end of every step: (I, n, 3, S)

        def g_builder(U):
            """g_of for the problem with section winds U (I, 2n+1, S): the fit's, or a perturbed one."""
            if U is grid.U:
                B_, a_ = B, a
            else:
                B_, a_ = self.basis_values(U), section_factors(U, self.bridge, phi, beta)
            return _g_function(B_, a_, _thirds(B_), _thirds(a_), s2, s2_3, use_yaw, zw, M)

        g_of = g_builder(grid.U)

        lower = np.concatenate([np.full(M, -np.inf), np.zeros(3 * M), np.zeros(P - 4 * M)])
        probe = ShootingProblem(grid=grid, amp=amp, scale=scale, g_of=g_of, penalty=np.zeros((P, P)), lower=lower,
                                continuity_weight=self.continuity_weight)
        starts = greybox_starts(self, grid, B, a, zw, Qm, phi, beta, P, s2)

        def finite_start(name, theta0):
            theta0 = np.maximum(theta0, lower)
            for shrink in (1.0, 0.5, 0.25, 0.0):  # a start that blows up inside an interval stops Gauss-Newton
                trial = theta0.copy()
                trial[:M] *= shrink  # Y1 = 0 leaves a damped, forced linear model that cannot blow up
                if np.isfinite(probe.cost(trial, Qm[:, 0])):
                    break
            if shrink < 1.0:
                name += f", Y1 scaled by {shrink:g} (the full start blew up inside an interval)"
            return name, trial

        safe = [finite_start(n, t) for n, t in starts]
        # the penalty's scale: the data part of J^T J at the first start (the warm start if given), fixed before
        # any start is iterated, so every start minimises one and the same objective
        probe.set_continuity_weight(0.0)
        _, H, _, _, _ = probe.linearise(safe[0][1], Qm[:, 0])
        K = difference_penalty(M)
        R = np.zeros((P, P))
        for f in range(4):  # each function's penalty relative to its own block of J^T J
            sl = slice(f * M, (f + 1) * M)
            R[sl, sl] = self.penalty * max(np.trace(H[sl, sl]), 1e-300) / np.trace(K) * K
        probe.penalty = R
        screened = []
        if len(safe) > 1:
            # screening: a few iterations of every start at the first (loosest) continuity weight, compared by
            # the penalised cost there
            probe.set_continuity_weight(_FIRST_WEIGHT)
            for name, theta0 in safe:
                try:
                    res = solve_gauss_newton(probe, theta0, Qm[:, 0], max_iter=self.screen_iter, tol=self.tol,
                                             first_weight=_FIRST_WEIGHT, covariance=False, callback=callback)
                    screened.append((res.cost, name, res.theta, res.s))
                except ValueError:  # a start with a non-finite cost is dropped
                    screened.append((np.inf, name, theta0, Qm[:, 0]))
            best = min(range(len(screened)), key=lambda j: screened[j][0])  # first of equal costs: deterministic
            _, start, theta0, s0 = screened[best]
        else:
            start, theta0 = safe[0]
            s0 = Qm[:, 0]
        probe.set_continuity_weight(self.continuity_weight)
        res = solve_gauss_newton(probe, theta0, s0, max_iter=self.max_iter, tol=self.tol, first_weight=_FIRST_WEIGHT,
                                 block_s=self.block_s, callback=callback)
        penalty, selection = float(self.penalty), []
        if self.penalty_grid is not None:
            base, kappa, fits = R.copy(), res.band_info["kappa"], {}
            for v in sorted({float(x) for x in self.penalty_grid}):
                if v == penalty:
                    fits[v] = res
                else:  # continued from the fit at the given penalty, at the full continuity weight
                    probe.penalty = base * (v / penalty)
                    fits[v] = solve_gauss_newton(probe, res.theta, res.s, max_iter=self.max_iter, tol=self.tol,
                                                 first_weight=self.continuity_weight, block_s=self.block_s,
                                                 callback=callback)
                selection.append({"penalty": v, "iterations": fits[v].iterations,
                                  **gcv_score(fits[v].band_info, kappa)})
            best = min(selection, key=lambda x: (x["gcv"], x["penalty"]))["penalty"]
            res = fits[best]
            R = base * (best / penalty)
            penalty = best
        self.coef_ = res.theta[:4 * M].reshape(4, M)
        self.yaw_coef_ = float(res.theta[4 * M]) if use_yaw else 0.0
        self.covariances_ = dict(res.covariances)
        boot_info = None
        self.boot_coef_ = None
        if self.n_boot > 0:
            probe.penalty = R
            probe.set_continuity_weight(self.continuity_weight)
            boot = event_bootstrap(probe, res.theta, res.s, n_boot=int(self.n_boot), n_iter=int(self.boot_iter),
                                   seed=self.seed, tol=min(self.tol, 1e-6))
            bias = res.covariances["sandwich_bias"] - res.covariances["sandwich"]
            self.covariances_["bootstrap"] = boot.cov
            self.covariances_["bootstrap_bias"] = boot.cov + bias
            self.boot_coef_ = boot.theta
            boot_info = {"n_boot": int(self.n_boot), "iterations_max": 2 * int(self.boot_iter), "seed": int(self.seed),
                         "seconds": boot.seconds, "iterations_median": float(np.median(boot.iterations)),
                         "last_step_median": float(np.median(boot.last_step)),
                         "last_step_max": float(np.max(boot.last_step)),
                         "n_events": int(boot.counts.shape[1])}
        wind_info = None
        self.wind_coef_ = self.wind_reference_ = None
        if self.wind_draws > 0:
            probe.penalty = R
            probe.set_continuity_weight(self.continuity_weight)
            draws = wind_error_draws(grid.U, grid.event, n_draws=int(self.wind_draws), seed=int(self.seed),
                                     scale=float(self.wind_scale))
            distances = np.array([np.zeros(S) if r.wind_distance is None else r.wind_distance for r in records])
            unmeasured = unmeasured_wind_draws(grid.U, grid.event, distances, n_draws=int(self.wind_draws),
                                               seed=[int(self.seed), 2])
            if unmeasured is not None:  # winds taken from an anemometer elsewhere on the span
                draws = draws + float(self.wind_scale) * unmeasured
            wr = wind_refits(probe, g_builder, grid.U, res.theta, res.s, draws, levels=(1.0,),
                             n_iter=int(self.wind_iter), tol=min(self.tol, 1e-6))
            self.wind_coef_ = wr.theta[0]
            self.wind_reference_ = wr.reference
            moment = wind_second_moment(wr.reference, wr.theta[0])
            self.covariances_["wind"] = moment
            self.covariances_["sandwich_bias_wind"] = res.covariances["sandwich_bias"] + moment
            shift = self.wind_coef_.mean(axis=0) - wr.reference
            wind_info = {"n_draws": int(self.wind_draws), "scale": float(self.wind_scale),
                         "iterations_max": 2 * int(self.wind_iter), "seconds": wr.seconds,
                         "iterations_median": float(np.median(wr.iterations)),
                         "relative_spread_rms": float(np.sqrt(np.mean(relative_spread(grid.U) ** 2))),
                         "mean_shift_share": float(np.trace(np.outer(shift, shift)) / max(np.trace(moment), 1e-300))}
        self.cov_ = self.covariances_[self.band]
        self.penalty_ = penalty
        self.penalty_matrix_ = R
        if use_yaw:
            n_with = len({int(e) for e in grid.event[grid.has_yaw]})
            yaw_note = (f"yaw factor 1 - c sin^2(yaw) on Y1 and C_L, c fitted; {n_with} of {len(records)} records "
                        f"carry a measured yaw (the others: factor 1)")
        elif self.yaw_factor:
            yaw_note = ("no record carries a measured yaw: factor 1, so Y1 and C_L are averages over the events' "
                        "yaw angles, not their values at yaw 0")
        else:
            yaw_note = "yaw factor switched off (yaw_factor=False): factor 1"
        self.fit_info_ = {"cost": res.cost, "iterations": res.iterations, "converged": bool(res.converged),
                          "message": res.message, "max_defect": res.max_defect,
                          "seconds": time.perf_counter() - t_fit, "final_solve_seconds": res.seconds,
                          "n_intervals": grid.n_intervals, "n_samples": int(grid.weight.sum()),
                          "n_records": len(records), "start": start, "yaw": yaw_note,
                          "starts": [{"start": n, "screened_cost": float(c)} for c, n, _, _ in screened],
                          "penalty": penalty, "penalty_selection": selection,
                          "penalty_criterion": ("GCV of the fits on the grid, edf of the Gauss-Newton "
                                                "linearisation, effective sample size n / kappa"
                                                if self.penalty_grid is not None else "given"),
                          "band": _BAND_NOTES[self.band],
                          "band_info": res.band_info, "bootstrap": boot_info, "wind_error": wind_info}
        return self

    # ------------------------------------------------------------------ evaluation

    def yaw_factor_values(self, yaw, yaw_coef: float | None = None) -> np.ndarray:
        """The factor 1 - c sin^2(yaw) on Y1 and C_L at yaw angles ``yaw`` (degrees, any shape; NaN: 0).

        1 everywhere when the yaw factor was not fitted.
        """
        self._check_fitted()
        c = getattr(self, "yaw_coef_", 0.0) if yaw_coef is None else yaw_coef
        psi = np.nan_to_num(np.asarray(yaw, dtype=float), nan=0.0)
        return 1.0 - c * np.sin(np.radians(psi)) ** 2

    def _yaw_sin2(self, yaw, shape) -> np.ndarray:
        """sin^2 of the yaw (degrees) broadcast to ``shape``; 0 without a yaw or a fitted yaw factor."""
        if yaw is None or not getattr(self, "yaw_used_", False):
            return np.zeros(shape)
        return np.broadcast_to(np.sin(np.radians(np.nan_to_num(np.asarray(yaw, dtype=float), nan=0.0))) ** 2, shape)

    def amplitude_coefficients(self, U, coef: np.ndarray | None = None, yaw=None) -> np.ndarray:
        """g_i(t) of dQ/dt = sum_i g_i Q^i at section winds U (..., S), shape (..., 4).

        ``yaw`` (degrees, the shape of U; None: 0) enters through the fitted yaw factor.
        """
        self._check_fitted()
        U = np.asarray(U, dtype=float)
        F = self.function_values(U, coef)
        a = section_factors(U, self.bridge, self.phi_, self.beta_) * self.yaw_factor_values(
            np.zeros(U.shape) if yaw is None else yaw)[..., None]
        return g_from_values(F, a, self.bridge.omega * self.bridge.damping_ratio)

    def amplitude_coefficient_function(self, U, yaw=None):
        """A function of draws giving g_i at section winds U (n, S) and yaw (n, S) degrees: shape (c, n, 4).

        ``g(coef, yaw_coef=None)`` with spline coefficient draws (c, 4, M) and
        yaw coefficient draws (c,) (None: the fitted one). The basis and
        section factors are evaluated once (for regime verdicts over many draws).
        """
        self._check_fitted()
        U = np.asarray(U, dtype=float)
        B = self.basis_values(U)  # (n, S, M)
        a = section_factors(U, self.bridge, self.phi_, self.beta_)
        s2 = self._yaw_sin2(yaw, U.shape)
        zw = self.bridge.omega * self.bridge.damping_ratio

        def g(coef, yaw_coef=None):
            coef = np.asarray(coef, dtype=float)
            c = np.broadcast_to(np.asarray(self.yaw_coef_ if yaw_coef is None else yaw_coef, dtype=float),
                                (coef.shape[0],))
            F = np.einsum("nsm,cfm->cnsf", B, coef, optimize=True)
            w = 1.0 - c[:, None, None] * s2[None]  # (c, n, S)
            return g_from_values(F, a[None] * w[..., None], zw)

        return g

    def order_contributions(self, record: Record) -> np.ndarray:
        """r_ki = ``|phi_k|`` g_i(U, yaw) (A_k / ``|phi_k|``)^i, shape (n, S, 4), m/s (NaN where A or U is missing).

        The record's yaw (``Record.yaw``) enters through the yaw factor; none: yaw 0.
        """
        record = self._check_record(record)
        amp = np.abs(self.phi_)
        g = self.amplitude_coefficients(record.U, yaw=record.yaw)  # (n, 4)
        Q = record.A / amp
        return amp[None, :, None] * g[:, None, :] * Q[..., None] ** np.arange(4)

    def predict(self, record: Record) -> np.ndarray:
        """dA/dt, shape (n, S), m/s."""
        return self.order_contributions(record).sum(axis=-1)

    def simulate(self, record: Record, t0: float | None = None, t1: float | None = None, A0=None) -> Simulation:
        """Integrate Q by RK4 on the record's grid from A0 (default the measured A at t0) with its wind.

        The run covers the record's samples from t0 to t1 while U is finite;
        it stops at the first missing wind sample, at the far side of a gap in the record's time
        (:func:`vivbench.preprocess.first_gap`) or at a non-finite amplitude.
        """
        record = self._check_record(record)
        t = record.t
        i0 = 0 if t0 is None else int(np.argmin(np.abs(t - t0)))
        i1 = t.size - 1 if t1 is None else int(np.argmin(np.abs(t - t1)))
        amp = np.abs(self.phi_)
        A0 = record.A[i0] if A0 is None else np.asarray(A0, dtype=float)
        ok = np.isfinite(A0)
        Q0 = float(np.sum(A0[ok] * amp[ok]) / np.sum(amp[ok] ** 2)) if ok.any() else np.nan
        ts, U = t[i0:i1 + 1], record.U[i0:i1 + 1]
        badU = ~np.isfinite(U).all(axis=1)
        stop_at = int(np.argmax(badU)) if badU.any() else ts.size
        gap = first_gap(t, i0, i1 + 1)
        gap = None if gap is None or gap - i0 + 1 >= stop_at else gap - i0  # no wind across a gap
        stop_at = stop_at if gap is None else gap + 1
        n = max(stop_at - 1, 0)
        Q = np.full(ts.size, np.nan)
        Q[0] = Q0
        if n > 0:
            Umid = 0.5 * (U[:n] + U[1:n + 1])
            Y = np.zeros_like(U) if record.yaw is None else np.nan_to_num(record.yaw[i0:i1 + 1], nan=0.0)
            ga, gm, gb = (self.amplitude_coefficients(x, yaw=y) for x, y in
                          ((U[:n], Y[:n]), (Umid, 0.5 * (Y[:n] + Y[1:n + 1])), (U[1:n + 1], Y[1:n + 1])))
            g_stage = (ga, gm, gb)  # the coefficients at each step's start, midpoint and end

            def f(q, j, stage):
                c = g_stage[stage][j]
                return c[0] + q * (c[1] + q * (c[2] + q * c[3]))

            Q[1:n + 1] = rk4(f, [Q0], ts[:n + 1]).x[1:, 0]
        bad = ~np.isfinite(Q)
        stopped_at, reason = None, None
        if bad.any():
            k = int(np.argmax(bad))
            Q[k:] = np.nan
            stopped_at = float(ts[k])
            reason = ("non-finite amplitude" if k < stop_at else gap_reason(ts, gap) if gap is not None
                      else "missing wind")
        A_sim = Q[:, None] * amp[None, :]
        A_meas = record.A[i0:i1 + 1]
        covered = 1.0 if stopped_at is None else float((stopped_at - ts[0]) / max(ts[-1] - ts[0], 1e-300))
        return Simulation(t=ts, A_sim=A_sim, A_meas=A_meas, stopped_at=stopped_at, reason=reason,
                          nmse=nmse(A_sim, A_meas), covered=covered, windows=np.zeros(0, dtype=int))

    def equations(self, precision: int = 3) -> list[str]:
        """One line per section: its amplitude equation with the functions named."""
        self._check_fitted()
        out = []
        for k, name in enumerate(section_names(self.n_sections_)):
            out.append(f"dA{k + 1}/dt = |phi_{k + 1}| dQ/dt, Q = A{k + 1}/{abs(self.phi_[k]):.{precision}g}; "
                       f"dQ/dt = averaged Simiu-Scanlan with spline Y1, e1, e2, C_L of U/(f D) "
                       f"({self.n_basis} B-splines each)")
        return out

    # ------------------------------------------------------------------ persistence

    def to_dataset(self, wind=None) -> xr.Dataset:
        """Everything :meth:`load` needs plus the curves (physical and docs/concepts.md (coefficient curves)) on ``wind``."""
        self._check_fitted()
        M = self.n_basis
        params = {k: v for k, v in self.get_params().items() if k not in ("bridge", "warm_start")}
        ds = xr.Dataset(
            {"coef": (("function", "basis"), self.coef_, {"units": "1", "long_name": "B-spline coefficients"}),
             "coef_cov": (("parameter", "parameter_"), self.cov_,
                          {"units": "1", "long_name": f"{self.band} covariance of coef (row-major flattening)"}),
             "coef_cov_sandwich": (("parameter", "parameter_"), self.covariances_.get("sandwich", self.cov_),
                              {"units": "1", "long_name": "block sandwich covariance of coef"}),
             "coef_cov_posterior": (("parameter", "parameter_"), self.covariances_.get("posterior", self.cov_),
                              {"units": "1", "long_name": "Bayesian posterior covariance of coef"}),
             "coef_cov_sandwich_bias": (("parameter", "parameter_"), self.covariances_.get("sandwich_bias", self.cov_),
                              {"units": "1", "long_name": "sandwich plus prior-averaged bias covariance of coef"}),
             **{f"coef_cov_{name}": (("parameter", "parameter_"), self.covariances_[name],
                                     {"units": "1", "long_name": f"{name} covariance of coef"})
                for name in ("bootstrap", "bootstrap_bias", "wind", "sandwich_bias_wind")
                if name in self.covariances_},
             "knots": (("knot",), self.knots_, {"units": "1", "long_name": "knots in reduced velocity U/(f D)"}),
             "mode_shape": (("section",), self.phi_, {"units": "1"}),
             "participation": (("section",), self.beta_, {"units": "1"})},
            coords={"function": list(FUNCTIONS), "section": section_names(self.n_sections_)},
            attrs={"model": type(self).__name__, "bridge_json": self.bridge.to_json(),
                   "params_json": json.dumps(params, sort_keys=True),
                   "fit_info_json": json.dumps(self.fit_info_, sort_keys=True),
                   "wind_min": self.wind_range_[0], "wind_max": self.wind_range_[1], "n_basis_": M,
                   "yaw_used": int(self.yaw_used_), "yaw_model": self.fit_info_.get("yaw", "")},
        )
        cur = self.curves(wind)
        phys = self.physical_curves(cur["wind"].values)
        comp = self.band_components(cur["wind"].values)
        ds = ds.merge(cur.drop_vars("equation")).merge(phys).merge(self.yaw_curve()).merge(comp.drop_vars("equation"))
        ds = ds.assign_coords(equation=section_names(self.n_sections_))
        # The curves outside the fitted data's wind range are extrapolations: marked, as every model's are.
        ds = mark_extrapolated(ds, np.tile(np.asarray(self.wind_range_, dtype=float), (self.n_sections_, 1)))
        ds.attrs.update(model=type(self).__name__)
        return ds

    def save(self, path, wind=None):
        """Write the grey-box file (:mod:`vivbench.io.greybox`) atomically; returns the path."""
        from vivbench.io.greybox import write_greybox

        return write_greybox(self.to_dataset(wind), path)

    @classmethod
    def load(cls, path) -> "GreyBoxRefit":
        """A fitted model from a file written by :meth:`save`."""
        from vivbench.io.greybox import read_greybox

        ds = read_greybox(path)
        return cls.from_dataset(ds)

    @classmethod
    def from_dataset(cls, ds: xr.Dataset) -> "GreyBoxRefit":
        bridge = BridgeProperties.from_dict(json.loads(ds.attrs["bridge_json"]))
        model = cls(bridge=bridge, **json.loads(ds.attrs["params_json"]))
        model.coef_ = np.asarray(ds["coef"].values, dtype=float)
        model.cov_ = np.asarray(ds["coef_cov"].values, dtype=float)
        # files written before the posterior bands hold the sandwich only
        model.covariances_ = {n: np.asarray(ds[f"coef_cov_{n}"].values, dtype=float)
                              for n in (*BANDS, "wind") if f"coef_cov_{n}" in ds}
        model.boot_coef_ = None
        model.wind_coef_ = model.wind_reference_ = None
        model.knots_ = np.asarray(ds["knots"].values, dtype=float)
        model.phi_ = np.asarray(ds["mode_shape"].values, dtype=float)
        model.beta_ = np.asarray(ds["participation"].values, dtype=float)
        model.n_sections_ = int(model.phi_.size)
        model.wind_range_ = (float(ds.attrs["wind_min"]), float(ds.attrs["wind_max"]))
        model.fit_info_ = json.loads(ds.attrs["fit_info_json"])
        # files written before the yaw factor have neither: factor 1
        model.yaw_used_ = bool(int(ds.attrs.get("yaw_used", 0)))
        model.yaw_coef_ = float(ds["yaw_coef"].values) if "yaw_coef" in ds else 0.0
        return model
