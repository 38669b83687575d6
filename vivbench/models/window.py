"""Time-varying SINDy: one sparse model per sliding window (docs/concepts.md (identifiability))."""

from __future__ import annotations


from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from vivbench.models.protocol import ModelBase
from vivbench.preprocess.windows import window_bounds
from vivbench.regression.optimizers import OPTIMIZERS, run_optimizer
from vivbench.regression.settings import DEFAULT_THRESHOLDS, StlsqSettings
from vivbench.library.basis import SCALINGS, basis_orders, library_cond, order_contributions_basis, window_library
from vivbench.core.terms import feature_names
from vivbench.core.errors import InputError

__all__ = ["WindowProblem", "EventWindowSINDy"]


class WindowProblem(NamedTuple):
    """One chunk of windows' regression problem, handed to ``fit``'s ``on_chunk`` callback.

    A verdict on the selected models (``vivbench.regimes``) needs the problem they were
    selected on; the callback gives it without a second pass over the data.

    Attributes
    ----------
    windows : slice
        The chunk's windows among all of the fit.
    theta : ndarray, shape (W, n, 23 S)
        Window libraries in the regression basis (NaN-free only where ``valid``).
    y : ndarray, shape (W, n, S)
        Standardised targets (dA/dt divided by ``y_scale``).
    y_scale : ndarray, shape (W, S), m/s
    A : ndarray, shape (W, n, S), m
    valid : ndarray of bool, shape (W, n)
    path : StlsqPath
        The threshold path fitted to ``theta`` and ``y``.
    settings : StlsqSettings
    """

    windows: slice
    theta: np.ndarray
    y: np.ndarray
    y_scale: np.ndarray
    A: np.ndarray
    valid: np.ndarray
    path: object
    settings: StlsqSettings


class EventWindowSINDy(ModelBase):
    """Time-varying SINDy on one event's record: STLSQ with AICc selection on sliding windows.

    The paper's method (docs/concepts.md, identifiability); :class:`vivbench.models.WindowSINDy`
    fits it to every record of a campaign (method ``windows``).

    Each window's library (:func:`vivbench.library.basis.window_library`,
    69 terms for three sections) is regressed against each section's dA/dt
    in a well-conditioned basis; the targets are divided by their window RMS
    (unless ``scaling="raw"``), so thresholds act on standardised
    coefficients: a coefficient of 0.1 means the term, at unit RMS, carries a
    tenth of the target's RMS. Coefficients are reported in physical units.

    Parameters
    ----------
    window, step : float, s
        Window width and step (the paper: 50 s and 25 s).
    thresholds : sequence of float, optional
        STLSQ threshold path; default :data:`DEFAULT_THRESHOLDS` (0 and 21
        log-spaced values from 1e-3 to 1e2).
    alpha : float
        Ridge parameter on X^T X (pysindy's ``alpha``; its default 0.05).
        The basis columns have unit RMS, so diag(X^T X) equals the number of
        samples (200 for 50 s at 4 Hz). Some ridge is needed: three sections'
        constant-like terms are nearly interchangeable in a window (condition
        numbers ~1e15), and without it the least-squares coefficients at
        iteration 0 are so large that no threshold removes anything (on the
        test campaigns even 0.1 % derivative noise gives 69-term models). The
        price: a ridge resolves those non-identifiable directions by minimum
        norm, not sparsity, so even noise-free sparse models are not
        recovered exactly; alpha = 0 recovers them (single section) when the
        data are exact.
    max_iter : int
        STLSQ iterations, iteration 0 included (pysindy's ``max_iter``).
    scaling : {"scaled", "normalized", "raw"}
        Library basis, see :mod:`vivbench.library.basis`.
    unbias, allow_empty, residual_floor, refit_rcond, solver
        See :class:`StlsqSettings`.
    chunk_size : int
        Windows processed together (memory grows linearly with it).
    keep_path : bool
        Keep the per-threshold results (``path_*_`` attributes).
    raw_cond : bool
        Also compute the condition number of the physical library (one more
        SVD per window).
    optimizer : {"stlsq", "sr3", "ensemble"}
        Sparse regression per window: this engine's STLSQ path (default), or
        pysindy's SR3 path or bagged STLSQ on the same scaled problem, see
        :mod:`vivbench.regression.optimizers`.
    optimizer_options : OptimizerOptions, optional
        Settings of ``"sr3"`` and ``"ensemble"`` (None: their defaults).
    random_state : int
        Seed of the bootstrap samples of ``"ensemble"`` (one child seed per window).

    Attributes
    ----------
    thresholds_ : ndarray, shape (T,)
    window_start_, window_end_ : ndarray, shape (W,), s
    n_samples_ : ndarray of int, shape (W,)
        Valid samples per window (finite A, U and dA).
    coef_ : ndarray, shape (W, S, 23 S)
        Selected model per window and equation on the physical library
        :func:`vivbench.core.terms.evaluate_library` (A in m, U in m/s, dA/dt in
        m/s); NaN where no model could be fitted.
    coef_scaled_ : ndarray, shape (W, S, 23 S)
        The same model on the regression basis (standardised coefficients).
    support_ : ndarray of bool, shape (W, S, 23 S)
        Non-zero terms of the basis model (its physical image has at least
        these orders of A; centring U fills in lower powers of U).
    threshold_, aicc_, rss_ : ndarray, shape (W, S)
        Chosen threshold, its AICc and residual sum of squares (m^2/s^2;
        AICc from the physical RSS).
    n_terms_, selected_ : ndarray of int, shape (W, S)
        Number of basis terms; index into ``thresholds_`` (-1: none).
    cond_ : ndarray, shape (W,)
        Condition number of each window's basis library.
    cond_raw_ : ndarray, shape (W,) or None
        Condition number of the physical library (if ``raw_cond``).
    a_scale_, u_center_, u_scale_, u_ref_ : ndarray, shape (W, S)
        Basis constants (m, m/s), see :class:`WindowLibrary`.
    col_scale_ : ndarray, shape (W, 23 S)
    y_scale_ : ndarray, shape (W, S), m/s
        RMS of dA/dt per window and equation (1 for ``"raw"``).
    path_support_ : ndarray of bool, shape (W, S, T, 23 S)
    path_aicc_, path_rss_ : ndarray, shape (W, S, T)
    path_n_terms_, n_iter_ : ndarray of int, shape (W, S, T)
    converged_, path_lower_bound_ : ndarray of bool, shape (W, S, T)
        See :class:`StlsqPath` (``converged``, ``lower_bound``).
    inclusion_ : ndarray, shape (W, S, 23 S)
        ``optimizer="ensemble"`` only: inclusion probability in [0, 1] of each
        basis term over the bootstrap models (NaN where no model was fitted).
        For ``"ensemble"`` the path attributes have T + 1 entries, the last
        the ensemble model, and ``threshold_`` is the bootstrap fits' threshold.
    order_rms_ : ndarray, shape (W, S, 4), m/s
        RMS over the window of each order's contribution to dA/dt.
    feature_names_ : list of str
    n_sections_ : int
    solves_ : dict
        Work done, summed over chunks (see :class:`StlsqPath`).
    """

    def __init__(
        self,
        *,
        window: float = 50.0,
        step: float = 25.0,
        thresholds=None,
        alpha: float = 0.05,
        max_iter: int = 20,
        scaling: str = "scaled",
        unbias: bool = True,
        allow_empty: bool = False,
        residual_floor: float = 1e-8,
        refit_rcond: float | None = 1e-6,
        solver: str = "auto",
        chunk_size: int = 128,
        keep_path: bool = True,
        raw_cond: bool = False,
        optimizer: str = "stlsq",
        optimizer_options=None,
        random_state: int = 0,
    ):
        self.window = window
        self.step = step
        self.thresholds = thresholds
        self.alpha = alpha
        self.max_iter = max_iter
        self.scaling = scaling
        self.unbias = unbias
        self.allow_empty = allow_empty
        self.residual_floor = residual_floor
        self.refit_rcond = refit_rcond
        self.solver = solver
        self.chunk_size = chunk_size
        self.keep_path = keep_path
        self.raw_cond = raw_cond
        self.optimizer = optimizer
        self.optimizer_options = optimizer_options
        self.random_state = random_state

    def settings(self) -> StlsqSettings:
        """The :class:`StlsqSettings` these parameters define (validated)."""
        return StlsqSettings(
            thresholds=DEFAULT_THRESHOLDS if self.thresholds is None else tuple(np.ravel(self.thresholds)),
            alpha=self.alpha,
            max_iter=self.max_iter,
            unbias=self.unbias,
            allow_empty=self.allow_empty,
            residual_floor=self.residual_floor,
            refit_rcond=self.refit_rcond,
            solver=self.solver,
        )

    def fit(self, t, A, U, dA, *, on_chunk: Callable[[WindowProblem], None] | None = None) -> "EventWindowSINDy":
        """Identify one model per window and equation.

        Parameters
        ----------
        t : ndarray, shape (n,), s
            Strictly increasing sample times (one grid for A, U and dA).
        A : ndarray, shape (n, S), m
            Amplitudes of the S sections.
        U : ndarray, shape (n, S), m/s
            Mean wind speeds.
        dA : ndarray, shape (n, S), m/s
            Time derivatives of A: one equation per section.
            Samples with a non-finite A, U or dA are ignored.
        on_chunk : callable, optional
            Called with each chunk's :class:`WindowProblem` after its fit (for
            verdicts such as :func:`vivbench.regimes.label_windows`).

        Returns
        -------
        self
        """
        settings = self.settings()
        if self.optimizer not in OPTIMIZERS:
            raise InputError(f"optimizer must be one of {OPTIMIZERS}; got {self.optimizer!r}")
        if self.scaling not in SCALINGS:
            raise InputError(f"scaling must be one of {SCALINGS}; got {self.scaling!r}")
        chunk = self.chunk_size
        if isinstance(chunk, bool) or not isinstance(chunk, (int, np.integer)) or chunk < 1:
            raise InputError(f"chunk_size must be an integer >= 1; got {self.chunk_size!r}")
        t = np.asarray(t, dtype=float)
        A = np.asarray(A, dtype=float)
        U = np.asarray(U, dtype=float)
        dA = np.asarray(dA, dtype=float)
        if A.ndim != 2 or A.shape != U.shape or A.shape != dA.shape or t.shape != (A.shape[0],):
            raise ValueError(
                f"t must have shape (n,) and A, U, dA shape (n, n_sections); got t {t.shape}, "
                f"A {A.shape}, U {U.shape}, dA {dA.shape}"
            )
        start, end, first, stop = window_bounds(t, self.window, self.step)
        if start.size == 0:
            raise InputError(f"the record ({t[-1] - t[0]:.6g} s) is shorter than one window ({self.window} s)")
        n, S = A.shape
        p = 23 * S
        W = start.size
        # The ensemble's path ends with the ensemble model itself.
        T = len(settings.thresholds) + (self.optimizer == "ensemble")
        n_max = int((stop - first).max())

        res = {
            "coef_": np.full((W, S, p), np.nan),
            "coef_scaled_": np.full((W, S, p), np.nan),
            "support_": np.zeros((W, S, p), dtype=bool),
            "threshold_": np.full((W, S), np.nan),
            "aicc_": np.full((W, S), np.nan),
            "rss_": np.full((W, S), np.nan),
            "n_terms_": np.zeros((W, S), dtype=int),
            "selected_": np.full((W, S), -1),
            "n_samples_": np.zeros(W, dtype=int),
            "cond_": np.full(W, np.nan),
            "a_scale_": np.ones((W, S)),
            "u_center_": np.zeros((W, S)),
            "u_scale_": np.ones((W, S)),
            "u_ref_": np.ones((W, S)),
            "col_scale_": np.ones((W, p)),
            "y_scale_": np.ones((W, S)),
            "order_rms_": np.full((W, S, 4), np.nan),
        }
        if self.keep_path:
            res.update(
                path_support_=np.zeros((W, S, T, p), dtype=bool),
                path_aicc_=np.full((W, S, T), np.inf),
                path_rss_=np.full((W, S, T), np.nan),
                path_n_terms_=np.zeros((W, S, T), dtype=int),
                n_iter_=np.zeros((W, S, T), dtype=int),
                converged_=np.zeros((W, S, T), dtype=bool),
                path_lower_bound_=np.zeros((W, S, T), dtype=bool),
            )
        if self.optimizer == "ensemble":
            res["inclusion_"] = np.full((W, S, p), np.nan)
        seeds = np.random.SeedSequence(self.random_state).spawn(W)
        cond_raw = np.full(W, np.nan) if self.raw_cond else None
        solves = {"qr": 0, "cholesky": 0, "svd": 0, "lstsq": 0}

        for c0 in range(0, W, self.chunk_size):
            ch = slice(c0, min(W, c0 + self.chunk_size))
            offs = np.arange(n_max)
            inwin = offs[None, :] < (stop[ch] - first[ch])[:, None]
            idx = np.minimum(first[ch][:, None] + offs[None, :], n - 1)
            Aw, Uw, dAw = A[idx], U[idx], dA[idx]
            valid = inwin & np.isfinite(Aw).all(-1) & np.isfinite(Uw).all(-1) & np.isfinite(dAw).all(-1)
            lib = window_library(Aw, Uw, scaling=self.scaling, valid=valid)
            if self.scaling == "raw":
                ys = np.ones((idx.shape[0], S))
            else:
                sq = np.where(valid[..., None], dAw**2, 0.0).sum(axis=1)
                with np.errstate(invalid="ignore", divide="ignore"):
                    ys = np.sqrt(sq / lib.n_valid[:, None])
                ys = np.where(np.isfinite(ys) & (ys > 0), ys, 1.0)
            y = np.where(valid[..., None], dAw / ys[:, None, :], np.nan)
            path, extra = run_optimizer(self.optimizer, lib.theta, y, settings, self.optimizer_options,
                                        seed=seeds[ch])
            for key in solves:
                solves[key] += path.solves.get(key, 0)

            N = path.n_samples
            with np.errstate(divide="ignore", invalid="ignore"):
                shift = N[:, None] * np.log(ys**2)  # AICc offset from scaled to physical RSS
            best = path.best_coef
            res["coef_scaled_"][ch] = best
            res["coef_"][ch] = lib.physical_coef(np.where(np.isfinite(best), best, 0.0)) * ys[:, :, None]
            res["coef_"][ch] = np.where(np.isfinite(best).all(axis=2, keepdims=True), res["coef_"][ch], np.nan)
            res["support_"][ch] = path.best_support
            res["threshold_"][ch] = extra.get("threshold", path.best_threshold)
            if "inclusion" in extra:
                res["inclusion_"][ch] = extra["inclusion"]
            res["aicc_"][ch] = path.best_aicc + shift
            res["rss_"][ch] = path.best_rss * ys**2
            res["n_terms_"][ch] = path.best_n_terms
            res["selected_"][ch] = path.selected
            res["n_samples_"][ch] = N
            res["cond_"][ch] = path.cond
            res["a_scale_"][ch] = lib.a_scale
            res["u_center_"][ch] = lib.u_center
            res["u_scale_"][ch] = lib.u_scale
            res["u_ref_"][ch] = lib.u_ref
            res["col_scale_"][ch] = lib.col_scale
            res["y_scale_"][ch] = ys
            if self.keep_path:
                res["path_support_"][ch] = path.support
                res["path_aicc_"][ch] = path.aicc + shift[:, :, None]
                res["path_rss_"][ch] = path.rss * (ys**2)[:, :, None]
                res["path_n_terms_"][ch] = path.n_terms
                res["n_iter_"][ch] = path.n_iter
                res["converged_"][ch] = path.converged
                res["path_lower_bound_"][ch] = path.lower_bound
            if self.raw_cond:
                cond_raw[ch] = library_cond(Aw, Uw, scaling="raw", valid=valid)
            r_best = order_contributions_basis(lib.theta, path.best_coef, basis_orders(S)) * ys[:, :, None, None]
            nv = np.maximum(valid.sum(axis=1), 1)
            res["order_rms_"][ch] = np.sqrt((np.where(valid[:, None, :, None], r_best, 0.0) ** 2).sum(axis=2)
                                            / nv[:, None, None])
            if on_chunk is not None:
                on_chunk(WindowProblem(ch, lib.theta, y, ys, Aw, valid, path, settings))

        if "inclusion_" not in res and hasattr(self, "inclusion_"):
            delattr(self, "inclusion_")
        path_names = ("path_support_", "path_aicc_", "path_rss_", "path_n_terms_", "n_iter_", "converged_")
        for name in path_names + ("path_lower_bound_",):
            # No stale path from an earlier fit with keep_path=True.
            if name not in res and hasattr(self, name):
                delattr(self, name)
        for name, value in res.items():
            setattr(self, name, value)
        self.thresholds_ = np.asarray(settings.thresholds)
        self.window_start_ = start
        self.window_end_ = end
        self.cond_raw_ = cond_raw
        self.n_sections_ = S
        self.feature_names_ = feature_names(S)
        self.solves_ = solves
        return self

