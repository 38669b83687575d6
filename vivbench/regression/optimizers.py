"""Alternative sparse regressions for the windowed SINDy: pysindy's SR3 and bagged STLSQ.

The fast engine (:mod:`vivbench.regression.stlsq`) runs STLSQ over a threshold
path and selects by AICc. For the method comparison two pysindy optimisers
run on exactly the same problem: the same scaled window library
(:func:`vivbench.library.basis.window_library`), the same standardised
targets, the same threshold path and the same AICc rule (residual floor,
exclusion of the empty model and of models with N - k - 1 <= 0). Both return
an :class:`~vivbench.regression.stlsq.StlsqPath`, so the regimes and the
identifiability flag (:func:`vivbench.regimes.window.window_regimes`)
apply unchanged to the chosen coefficients.

``"sr3"``
    ``pysindy.optimizers.SR3`` with the L0 regulariser, one fit per threshold
    of the path (weight ``lambda = threshold**2 / (2 nu)``, pysindy's
    ``calculate_l0_weight``: the L0 prox then hard-thresholds at
    ``threshold``), relaxation ``nu`` (``relax_coeff_nu``, default 1) and
    pysindy's unbiased refit on each support; per window and equation the
    model with the smallest AICc is chosen. SR3 starts from the ridge
    solution with the engine's ``alpha`` (STLSQ's iteration 0), not from
    pysindy's default least-squares guess: on the ill-conditioned window
    libraries (cond ~1e15) the least-squares coefficients are so large that
    no threshold of the path removes a term and SR3 stops after one
    iteration at the dense model. All equations of a window are
    fitted jointly (SR3 decouples per target; only the stopping rule is
    shared). SR3 does not converge on every window within ``max_iter``
    iterations (default 100); the last iterate is used, as pysindy does.

``"ensemble"``
    Bagging (Fasel et al. 2022, E-SINDy) with ``pysindy.optimizers.
    EnsembleOptimizer`` around ``pysindy.optimizers.STLSQ``. Per window and
    equation the STLSQ threshold is the one the engine's AICc selects on the
    whole window; ``n_models`` (default 20) bootstrap samples of the window's
    rows (with replacement) are fitted at that threshold, the ridge problems
    solved by SVD (scikit-learn's ``solver="svd"``; the default Cholesky of
    the normal equations loses every digit on these ill-conditioned windows
    and keeps spurious terms even on exact data). The *inclusion
    probability* of a term is the share of bootstrap models in which it is
    non-zero. The chosen model keeps the terms with inclusion probability
    >= ``inclusion_cut`` (default 0.5: the term is in most bootstrap models);
    its coefficients are the least-squares refit on the whole window
    (``coef_rule="refit"``, default; truncated like the engine's refit,
    ``refit_rcond``) or the median of the bootstrap coefficients
    (``coef_rule="median"``, pysindy's default aggregation, zeroed off the
    chosen support). If no term reaches the cut the window has no model
    (unless ``allow_empty``). The returned path holds the engine's STLSQ path
    followed by the ensemble model as its last entry (threshold NaN), which
    is the one selected: the STLSQ models within the AICc margin remain
    competitors for the identifiability flag.

    pysindy draws the bootstrap samples from numpy's global random state; it
    is seeded per window from ``SeedSequence(seed).spawn(W)`` and restored
    afterwards, so results depend on the seed only.

Competitors restricted to subsets of the orders of A (the second test of the
identifiability flag) are searched by the engine's STLSQ path whatever the
optimiser: they ask whether *some* sparse model without that order fits as
well, which does not depend on how the selected model was found.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from vivbench.regression.stlsq import StlsqPath, aicc, stlsq_path
from vivbench.regression.settings import StlsqSettings
from vivbench.regression.lstsq import as_batches
from vivbench.regression.lstsq import empty_path as _engine_empty_path
from vivbench.library.basis import condition_number
from vivbench.core.errors import InputError

__all__ = ["OPTIMIZERS", "OptimizerOptions", "run_optimizer", "sr3_path", "ensemble_path"]

OPTIMIZERS = ("stlsq", "sr3", "ensemble")
COEF_RULES = ("refit", "median")
# pysindy drops coefficients at or below this magnitude (as the engine does).
_ZERO_COEF = 1e-14


@dataclass(frozen=True, kw_only=True)
class OptimizerOptions:
    """Settings of the pysindy-based optimisers (ignored by ``"stlsq"``).

    Parameters
    ----------
    relax_coeff_nu : float
        sr3: relaxation parameter nu (> 0).
    sr3_max_iter : int
        sr3: maximum SR3 iterations per fit.
    sr3_tol : float
        sr3: convergence tolerance on the change of the sparse coefficients.
    n_models : int
        ensemble: bootstrap models per window and equation (>= 2).
    inclusion_cut : float
        ensemble: inclusion probability from which a term is kept, in (0, 1].
    coef_rule : {"refit", "median"}
        ensemble: coefficients of the chosen support.
    """

    relax_coeff_nu: float = 1.0
    sr3_max_iter: int = 100
    sr3_tol: float = 1e-5
    n_models: int = 20
    inclusion_cut: float = 0.5
    coef_rule: str = "refit"

    def __post_init__(self) -> None:
        if not (np.isfinite(self.relax_coeff_nu) and self.relax_coeff_nu > 0):
            raise InputError(f"relax_coeff_nu must be finite and > 0; got {self.relax_coeff_nu}")
        for name, low in (("sr3_max_iter", 1), ("n_models", 2)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
                raise InputError(f"{name} must be an integer >= {low}; got {value!r}")
        if not (np.isfinite(self.sr3_tol) and self.sr3_tol > 0):
            raise InputError(f"sr3_tol must be finite and > 0; got {self.sr3_tol}")
        if not 0 < self.inclusion_cut <= 1:
            raise InputError(f"inclusion_cut must lie in (0, 1]; got {self.inclusion_cut}")
        if self.coef_rule not in COEF_RULES:
            raise InputError(f"coef_rule must be one of {COEF_RULES}; got {self.coef_rule!r}")


def _prepare(theta, y):
    theta, y = as_batches(theta, y)
    valid = np.isfinite(theta).all(axis=2) & np.isfinite(y).all(axis=2)
    return theta, y, valid


def _score(X, Y, coef, n, settings: StlsqSettings):
    """RSS, number of terms and AICc of models coef (q, M, p) on one window X (n, p), Y (n, q)."""
    res = Y.T[:, None, :] - np.einsum("np,qmp->qmn", X, coef)
    rss = np.sum(res**2, axis=2)
    k = np.count_nonzero(coef, axis=2)
    floor = np.maximum(settings.residual_floor**2 * np.sum(Y**2, axis=0), np.finfo(float).tiny)[:, None]
    a = aicc(rss, k, n, floor=floor)
    a = np.where(((k > 0) | settings.allow_empty) & np.isfinite(a), a, np.inf)
    return rss, k, a


def empty_path(W, q, T, p, thresholds) -> dict:
    return dict(thresholds=np.asarray(thresholds, dtype=float), **_engine_empty_path(W, q, T, p),
                n_samples=np.zeros(W, dtype=int), cond=np.full(W, np.nan))


def _select(a: np.ndarray) -> np.ndarray:
    finite = np.isfinite(a)
    return np.where(finite.any(axis=2), np.argmin(np.where(finite, a, np.inf), axis=2), -1)


def _ridge(X, Y, alpha):
    """Ridge solutions (q, p) of X (n, p), Y (n, q), by least squares on the augmented system (accurate
    where the normal equations are not); alpha = 0: minimum-norm least squares."""
    if alpha:
        X = np.vstack([X, np.sqrt(alpha) * np.eye(X.shape[1])])
        Y = np.vstack([Y, np.zeros((X.shape[1], Y.shape[1]))])
    return np.linalg.lstsq(X, Y, rcond=None)[0].T


def sr3_path(theta, y, settings: StlsqSettings | None = None, options: OptimizerOptions | None = None) -> StlsqPath:
    """pysindy's SR3 (L0) over the threshold path of ``settings``, selected by AICc.

    Parameters
    ----------
    theta : ndarray, shape (W, n, p) or (n, p)
        Window designs (rows with a non-finite entry in ``theta`` or ``y`` are ignored).
    y : ndarray, shape (W, n, q) or (n, q)
    settings : StlsqSettings
        Threshold path, ``unbias``, ``allow_empty`` and ``residual_floor``
        as for the engine; ``alpha`` is the ridge of the initial guess;
        ``solver`` does not apply.
    options : OptimizerOptions

    Returns
    -------
    StlsqPath
        ``n_iter``: SR3 iterations; ``converged``: below ``sr3_tol`` before ``sr3_max_iter``.
    """
    from pysindy.optimizers import SR3
    from sklearn.exceptions import ConvergenceWarning

    settings = settings or StlsqSettings()
    options = options or OptimizerOptions()
    theta, y, valid = _prepare(theta, y)
    W, _, p = theta.shape
    q = y.shape[2]
    th = np.asarray(settings.thresholds)
    T = th.size
    out = empty_path(W, q, T, p, th)
    nu = options.relax_coeff_nu
    for w in range(W):
        rows = valid[w]
        n = int(rows.sum())
        out["n_samples"][w] = n
        if n < p + 2:
            continue
        X, Y = theta[w][rows], y[w][rows]
        out["cond"][w] = condition_number(X)
        guess = _ridge(X, Y, settings.alpha)
        coefs = np.zeros((q, T, p))
        for t, thr in enumerate(th):
            opt = SR3(reg_weight_lam=SR3.calculate_l0_weight(thr, nu), regularizer="L0", relax_coeff_nu=nu,
                      tol=options.sr3_tol, max_iter=options.sr3_max_iter, unbias=settings.unbias,
                      initial_guess=guess)
            with warnings.catch_warnings():
                # Non-convergence is recorded in ``converged``; lstsq warnings on singular supports are expected.
                warnings.simplefilter("ignore", ConvergenceWarning)
                warnings.simplefilter("ignore", RuntimeWarning)
                opt.fit(X, Y)
            c = np.where(np.abs(opt.coef_) > _ZERO_COEF, opt.coef_, 0.0)
            coefs[:, t] = c
            out["n_iter"][w, :, t] = opt.iters
            out["converged"][w, :, t] = opt.iters < options.sr3_max_iter
        rss, k, a = _score(X, Y, coefs, n, settings)
        out["coef"][w], out["support"][w] = coefs, coefs != 0
        out["rss"][w], out["n_terms"][w], out["aicc"][w] = rss, k, a
    return StlsqPath(selected=_select(out["aicc"]), solves={}, **out)


def _refit(X, y, support, rcond):
    coef = np.zeros(support.shape)
    if support.any():
        sol = scipy.linalg.lstsq(X[:, support], y, cond=rcond, lapack_driver="gelsd")[0]
        coef[support] = sol
    return coef


def ensemble_path(theta, y, settings: StlsqSettings | None = None, options: OptimizerOptions | None = None,
                  *, seed=0) -> tuple[StlsqPath, np.ndarray, np.ndarray]:
    """Bagged STLSQ (pysindy's EnsembleOptimizer) at the AICc threshold of each window and equation.

    Parameters
    ----------
    theta : ndarray, shape (W, n, p) or (n, p)
    y : ndarray, shape (W, n, q) or (n, q)
    settings : StlsqSettings
        The engine's path, used to choose the threshold, and the STLSQ
        settings of every bootstrap fit (alpha, max_iter, unbias).
    options : OptimizerOptions
    seed : int, SeedSequence or sequence of W SeedSequence
        Seeds the bootstrap samples: one child per window spawned from an int
        or a SeedSequence, or the windows' own seeds.

    Returns
    -------
    path : StlsqPath
        The engine's T thresholds, then the ensemble model (index T, threshold NaN), selected.
    inclusion : ndarray, shape (W, q, p)
        Inclusion probability of every term in [0, 1]; NaN where the window is not fitted.
    threshold : ndarray, shape (W, q)
        STLSQ threshold of the bootstrap fits; NaN where none.
    """
    from pysindy.optimizers import STLSQ, EnsembleOptimizer

    settings = settings or StlsqSettings()
    options = options or OptimizerOptions()
    theta, y, valid = _prepare(theta, y)
    W, _, p = theta.shape
    q = y.shape[2]
    base = stlsq_path(theta, y, settings)
    T = base.thresholds.size
    th = base.thresholds
    inclusion = np.full((W, q, p), np.nan)
    threshold = np.full((W, q), np.nan)
    ens_coef = np.full((W, q, p), np.nan)
    ens = dict(rss=np.full((W, q), np.nan), k=np.zeros((W, q), dtype=int), aicc=np.full((W, q), np.inf))
    if isinstance(seed, (list, tuple)):
        if len(seed) != W:
            raise ValueError(f"seed: expected {W} window seeds, got {len(seed)}")
        children = list(seed)
    else:
        root = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
        children = root.spawn(W)
    rcond = settings.refit_rcond if settings.refit_rcond else None
    saved = np.random.get_state()
    try:
        for w in range(W):
            rows = valid[w]
            n = int(rows.sum())
            if n < p + 2 or not (base.selected[w] >= 0).any():
                continue
            X, Y = theta[w][rows], y[w][rows]
            # pysindy's bagging draws from the global state: seed it per window.
            np.random.seed(children[w].generate_state(1, dtype=np.uint32)[0])
            coef_w = np.zeros((q, p))
            for t in np.unique(base.selected[w][base.selected[w] >= 0]):
                eqs = np.flatnonzero(base.selected[w] == t)
                opt = STLSQ(threshold=float(th[t]), alpha=settings.alpha, max_iter=settings.max_iter,
                            unbias=settings.unbias, ridge_kw={"solver": "svd"})
                bag = EnsembleOptimizer(opt, bagging=True, n_models=options.n_models, replace=True)
                with warnings.catch_warnings():
                    # STLSQ warns when a bootstrap sample loses every term or hits max_iter.
                    warnings.simplefilter("ignore")
                    bag.fit(X, Y[:, eqs])
                models = np.asarray(bag.coef_list)  # (n_models, len(eqs), p)
                nz = np.abs(models) > _ZERO_COEF
                prob = nz.mean(axis=0)
                inclusion[w, eqs] = prob
                threshold[w, eqs] = th[t]
                keep = prob >= options.inclusion_cut
                for j, e in enumerate(eqs):
                    if options.coef_rule == "refit":
                        coef_w[e] = _refit(X, Y[:, e], keep[j], rcond)
                    else:
                        coef_w[e] = np.where(keep[j], np.median(models[:, j], axis=0), 0.0)
            coef_w = np.where(np.abs(coef_w) > _ZERO_COEF, coef_w, 0.0)
            fitted = base.selected[w] >= 0
            rss, k, a = _score(X, Y, coef_w[:, None, :], n, settings)
            ens_coef[w] = np.where(fitted[:, None], coef_w, np.nan)
            ens["rss"][w] = np.where(fitted, rss[:, 0], np.nan)
            ens["k"][w] = np.where(fitted, k[:, 0], 0)
            ens["aicc"][w] = np.where(fitted, a[:, 0], np.inf)
    finally:
        np.random.set_state(saved)

    def cat(a, b):
        return np.concatenate([a, b[:, :, None]], axis=2)

    path = StlsqPath(
        thresholds=np.append(th, np.nan),
        coef=cat(base.coef, ens_coef),
        support=cat(base.support, np.nan_to_num(ens_coef) != 0),
        rss=cat(base.rss, ens["rss"]),
        n_terms=cat(base.n_terms, ens["k"]),
        aicc=cat(base.aicc, ens["aicc"]),
        n_iter=cat(base.n_iter, np.zeros((W, q), dtype=int)),
        converged=cat(base.converged, np.isfinite(ens["aicc"])),
        lower_bound=cat(base.lower_bound, np.zeros((W, q), dtype=bool)),
        n_samples=base.n_samples,
        cond=base.cond,
        selected=np.where(np.isfinite(ens["aicc"]), T, -1),
        solves=base.solves,
    )
    return path, inclusion, threshold


def run_optimizer(name: str, theta, y, settings: StlsqSettings, options: OptimizerOptions | None = None,
                  *, seed=0) -> tuple[StlsqPath, dict]:
    """Run optimiser ``name`` on a batch of windows.

    Returns
    -------
    path : StlsqPath (with ``selected`` the chosen model)
    extra : dict of ndarray
        ``"inclusion"`` (W, q, p) and ``"threshold"`` (W, q) for ``"ensemble"``; empty otherwise.
    """
    if name not in OPTIMIZERS:
        raise InputError(f"optimizer must be one of {OPTIMIZERS}; got {name!r}")
    if name == "stlsq":
        return stlsq_path(theta, y, settings), {}
    if name == "sr3":
        return sr3_path(theta, y, settings, options), {}
    path, inclusion, threshold = ensemble_path(theta, y, settings, options, seed=seed)
    return path, {"inclusion": inclusion, "threshold": threshold}
