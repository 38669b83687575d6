"""Fitting :class:`vivbench.models.VaryingCoefficientSINDy`: from the campaign's samples to its fitted arrays.

The steps, each on per-block sufficient statistics (:mod:`vivbench.models.varying_design`):

1. :func:`campaign_samples`: the pooled samples of the (smoothed) records, their
   ``block_s`` blocks and the seeded folds of whole events.
2. :func:`select_basis`: per section, the scales and the basis size M and relative
   penalty chosen by the cross-validated error over the folds.
3. :func:`eiv_weight`: optionally, effective-variance weights for a weighted refit at
   that choice (errors-in-variables of the mean wind).
4. :func:`fit_section`: per section, the penalty choice, the final coefficients,
   the block-bootstrap replicates and the confidence sets of order subsets and of
   penalties (leave-one-event-out errors, :func:`vivbench.regression.confidence_set`).

:func:`choose_smoothing` runs 1-3 for every candidate wind smoothing and keeps the
prior unless another's cross-validated error is lower by more than one standard error
(:func:`smoothing_choice`); :func:`fitted_arrays` gathers the sections'
fits into the model's fitted attributes. Steps 1-3 do not depend on the
parameters of :data:`FINAL_PARAMS`: :func:`fit_shared` runs them once
(:class:`SharedFit`) and :func:`fit_final` step 4 for one model, so models that
differ only in those parameters share the costly part (the model's ``fit_variants``). The model (``model``) is passed for its
parameters and its wind inputs (``wind_inputs``, ``yaw_covariate``, ``n_inputs``).
"""

from __future__ import annotations

import copy
import math
import warnings
from dataclasses import dataclass, replace

import numpy as np

from vivbench.core.errors import InputError
from vivbench.core.record import Record
from vivbench.models.protocol import as_record
from vivbench.library.splines import DEGREE, difference_penalty, uniform_knots
from vivbench.models.varying_design import input_contributions, untie
from vivbench.models.varying_stats import BlockStats, block_statistics, tied_statistics
from vivbench.models.wind_weights import (WIND_WEIGHT_MODES, check_wind_weights, resolve_wind_weights,
                                          weighted_mean_standard_error)
from vivbench.preprocess.wind_smoothing import smooth_wind
from vivbench.regression.bootstrap import block_counts
from vivbench.regression.model_set import MODEL_SET_TESTS, confidence_set
from vivbench.regression.penalised import held_out_errors, penalised_solve, penalty_scale, quadratic_error

__all__ = ["ORDER_SUBSETS", "ORDER_SET_MARGIN", "SMOOTHING_MIN_FOLDS", "PENALTY_CHOICES", "FINAL_PARAMS", "SharedFit", "fit_shared", "fit_final", "check_parameters", "CampaignSamples", "BasisChoice", "SectionSamples",
           "SectionFit", "equation_inputs", "valid_samples", "campaign_samples", "wind_standard_error", "cv_error", "fold_errors", "select_orders", "select_basis",
           "eiv_weight", "choose_smoothing", "smoothing_candidates", "smoothing_choice", "smoothing_evidence", "settle_smoothing", "fit_section", "fitted_arrays", "event_statistics", "WIND_INPUTS",
           "fitted_inputs", "as_inputs", "section_statistics"]

#: Values of ``wind_input`` (:class:`vivbench.models.VaryingCoefficientSINDy`): the sections' weighted mean wind, the
#: section's own, every section's wind with a curve of its own (summed), or every section's wind with one shared
#: curve, weighted by the sections' weights (summed).
WIND_INPUTS = ("mean", "section", "additive", "sum")

PENALTY_CHOICES = ("cv", "least", "loeo")
"""Values of ``penalty_choice``: the 5-fold cross-validated error's minimum, the least penalty of the confidence
set of the leave-one-event-out errors, or their minimum. Which suits a campaign is chosen from its own held-out
evidence by :func:`vivbench.analysis.varying_selection` (``vivbench pool``)."""

#: Order subsets of the confidence set of models (all with the linear order 1), rows (0, 1, 2, 3) kept.
ORDER_SUBSETS = np.array([[o0, True, o2, o3] for o0 in (True, False) for o2 in (True, False)
                          for o3 in (True, False)])

#: Relative excess of leave-one-event-out error within which an order subset stays in the confidence set
#: whatever the paired test says (``order_set_margin``): a stated prior, chosen on development draws of the
#: generator family (docs/results/studies/order_margin).
ORDER_SET_MARGIN = 0.005

#: Folds of events below which the wind smoothing stays at its prior (:func:`smoothing_choice`): a standard
#: error from fewer paired differences is too rough to overrule it (a stated prior).
SMOOTHING_MIN_FOLDS = 5


#: Parameters of the model that act only in the last step (:func:`fit_section`, or not in the fit at all):
#: fits that differ only in them share steps 1-3 (:func:`fit_shared`).
FINAL_PARAMS = ("penalty_choice", "n_bootstrap", "select_orders", "model_set_level", "order_set_margin",
                "model_set_test", "agreement", "tau", "model_sets")


@dataclass(frozen=True)
class CampaignSamples:
    """The pooled samples of a campaign's records, shared by every section's fit (n samples, S sections).

    ``U`` (n, S) the equations' wind inputs (m/s), ``Z`` (n, S) their yaw covariate sin^2(psi) (None without),
    ``A``, ``dA`` (n, S); ``event`` and ``block`` (n,) each sample's event and ``block_s`` block;
    ``fold_of_event`` (E,); ``wind_se`` (n,) the wind inputs' standard error (None: not estimable);
    ``rng`` the generator of the folds, then of the bootstrap.
    """

    records: list
    n_sections: int
    yaw_degree: int
    n_folds: int
    n_events: int
    rng: np.random.Generator
    event: np.ndarray
    block: np.ndarray
    fold_of_event: np.ndarray
    A: np.ndarray
    U: np.ndarray
    dA: np.ndarray
    Z: np.ndarray | None
    wind_se: np.ndarray | None


@dataclass(frozen=True)
class BasisChoice:
    """The cross-validated choice of one section: its error per sample, M, the relative penalty, the knots
    (m/s), the block statistics (:class:`vivbench.models.varying_stats.BlockStats`), the penalty P (p, p) and
    the error per sample of each fold held out (K,), whose sum is ``error``."""

    error: float
    n_basis: int
    penalty: float
    knots: np.ndarray
    stats: BlockStats
    P: np.ndarray
    fold_errors: np.ndarray


@dataclass(frozen=True)
class SectionSamples:
    """One section's samples and choice: n valid samples in ``n_blocks`` blocks, the target's RMS ``y_scale``
    (m/s) and A's ``a_ref`` (m), the wind range (m/s), each block's event and fold, the yaw covariate's
    fallback (median), reference (RMS) and minimum, the cross-validated errors (n_basis, penalties) and
    the choice ``best``."""

    n: int
    n_blocks: int
    y_scale: float
    a_ref: float
    wind_range: tuple[float, float]
    event_of_block: np.ndarray
    fold_of_block: np.ndarray
    yaw_fallback: float
    yaw_ref: float
    yaw_min: float
    yaw_max: float
    cv_error: np.ndarray
    best: BasisChoice


@dataclass(frozen=True)
class SectionFit:
    """One section's final fit, coefficients in physical units (L = n_in M per curve, J yaw powers):
    ``coef`` (L, 4, J + 1), ``bootstrap`` (R, L, 4, J + 1), ``subset_coef`` (n_subsets, L, 4, J + 1),
    ``penalty_coef`` (n_penalties, L, 4, J + 1); the relative ``penalty`` and ``penalty_cv``, the kept
    ``orders`` (4,), ``edf``, ``rss`` (m^2/s^2), ``subset_loeo`` (n_subsets, E) held-out errors (of the
    standardised target; NaN for events without samples) and the confidence sets ``subset_plausible`` (n_subsets,), ``penalty_plausible`` (n_penalties,)."""

    coef: np.ndarray
    bootstrap: np.ndarray
    subset_coef: np.ndarray
    penalty_coef: np.ndarray
    penalty: float
    penalty_cv: float
    orders: np.ndarray
    edf: float
    rss: float
    subset_loeo: np.ndarray
    subset_plausible: np.ndarray
    penalty_plausible: np.ndarray


def check_parameters(model) -> None:
    """Check the model's parameters; raises InputError saying what is wrong and what is allowed."""
    nb = np.asarray(model.n_basis)
    if nb.ndim != 1 or nb.size == 0 or np.any(nb < DEGREE + 1) or np.any(nb != np.round(nb)):
        raise InputError(f"n_basis must be a non-empty sequence of integers >= {DEGREE + 1}; got {model.n_basis!r}")
    pen = np.asarray(model.penalties, dtype=float)
    if pen.ndim != 1 or pen.size == 0 or np.any(~np.isfinite(pen)) or np.any(pen < 0):
        raise InputError(f"penalties must be a non-empty sequence of finite numbers >= 0; got {model.penalties!r}")
    if int(model.n_folds) < 2:
        raise InputError(f"n_folds must be an integer >= 2; got {model.n_folds!r}")
    if int(model.n_bootstrap) < 0:
        raise InputError(f"n_bootstrap must be an integer >= 0; got {model.n_bootstrap!r}")
    if not (np.isfinite(model.block_s) and model.block_s > 0):
        raise InputError(f"block_s must be a positive number of seconds; got {model.block_s!r}")
    if not 0.0 < model.agreement <= 1.0:
        raise InputError(f"agreement must lie in (0, 1]; got {model.agreement!r}")
    if not 0.0 < model.tau < 1.0:
        raise InputError(f"tau must lie strictly between 0 and 1; got {model.tau!r}")
    if not 0.5 <= model.model_set_level < 1.0:
        raise InputError(f"model_set_level must lie in [0.5, 1); got {model.model_set_level!r}")
    if not (isinstance(model.order_set_margin, (int, float, np.floating)) and 0.0 <= model.order_set_margin < 1.0):
        raise InputError(f"order_set_margin must be a number in [0, 1) (a relative excess of held-out error); "
                         f"got {model.order_set_margin!r}")
    J = model.yaw_degree
    if J is not None and (int(J) != J or not 0 <= int(J) <= 3):
        raise InputError(f"yaw_degree must be None (1 when the records carry the yaw, else 0) or an integer "
                         f"in 0..3; got {model.yaw_degree!r}")
    if not (np.isfinite(model.wind_smoothing_s) and model.wind_smoothing_s >= 0):
        raise InputError(f"wind_smoothing_s must be a number of seconds >= 0; got {model.wind_smoothing_s!r}")
    if model.wind_smoothing_grid is not None:
        g = np.asarray(model.wind_smoothing_grid, dtype=float)
        if g.ndim != 1 or g.size == 0 or np.any(~np.isfinite(g)) or np.any(g < 0):
            raise InputError("wind_smoothing_grid must be None (use wind_smoothing_s) or a non-empty sequence "
                             f"of seconds >= 0; got {model.wind_smoothing_grid!r}")
    if model.model_set_test not in MODEL_SET_TESTS:
        raise InputError(f"model_set_test must be 'z' or 'signed_rank'; got {model.model_set_test!r}")
    if model.wind_input not in WIND_INPUTS:
        raise InputError(f"wind_input must be one of {', '.join(map(repr, WIND_INPUTS))}; got {model.wind_input!r}")
    if not isinstance(model.wind_weights, str):
        check_wind_weights(model.wind_weights)
    elif model.wind_weights not in WIND_WEIGHT_MODES:
        raise InputError(f"wind_weights must be 'modal', 'equal' or a sequence of one weight per "
                         f"section; got {model.wind_weights!r}")
    if model.penalty_choice not in PENALTY_CHOICES:
        raise InputError(f"penalty_choice must be one of {', '.join(map(repr, PENALTY_CHOICES))}; "
                         f"got {model.penalty_choice!r}")
    if not isinstance(model.model_sets, (bool, np.bool_)):
        raise InputError(f"model_sets must be True or False; got {model.model_sets!r}")


def fitted_inputs(model, n_sections: int) -> int:
    """Wind inputs with curves of their own in the fit: those of ``model.n_inputs``, but one shared by every
    section's wind with ``wind_input="sum"``."""
    return 1 if model.wind_input == "sum" else model.n_inputs(n_sections)


def as_inputs(model, coef: np.ndarray, n_yaw: int, M: int) -> np.ndarray:
    """Standardised coefficients (..., p) of the fit in the layout of every wind input (``model.n_inputs``):
    with ``wind_input="sum"`` the shared curve times each section's weight (:func:`untie`), else as they are."""
    return untie(coef, model.wind_weights_, n_yaw, M) if model.wind_input == "sum" else coef


def equation_inputs(wind_input: str, U: np.ndarray, Z: np.ndarray | None, k: int):
    """Equation ``k``'s wind and yaw covariate: (n,) columns, or (n, S) every section's ("additive", "sum")."""
    if wind_input in ("additive", "sum"):
        return U, Z
    return U[:, k], None if Z is None else Z[:, k]


def valid_samples(wind_input: str, A: np.ndarray, U: np.ndarray, dA: np.ndarray | None, Z: np.ndarray | None,
                  k: int) -> np.ndarray:
    """Samples where equation ``k`` is defined: finite A_k (dA_k), and every wind (and yaw) it uses, shape (n,)."""
    Uk, Zk = equation_inputs(wind_input, U, Z, k)
    ok = np.isfinite(A[:, k]) & np.isfinite(Uk).reshape(Uk.shape[0], -1).all(axis=1)
    if dA is not None:
        ok &= np.isfinite(dA[:, k])
    if Zk is not None:
        ok &= np.isfinite(Zk).reshape(Zk.shape[0], -1).all(axis=1)
    return ok


def wind_standard_error(wind_input: str, wind_weights: np.ndarray, U: np.ndarray) -> np.ndarray | None:
    """Standard error of each equation's wind input, shape (n,), m/s (None: not estimable).

    The spread of the S (smoothed) anemometers about their mean times
    sqrt(sum_j w_j^2) (``wind_weights``; 1/sqrt(S) for equal weights): the
    weighted mean's error if each anemometer's slow turbulence, which the deck
    does not feel, is independent of the others'. With ``wind_input="additive"``
    each section's own anemometer is an input, whose error is the spread itself.
    Only for ``wind_input`` "mean" or "additive" with two or more sections.
    """
    if wind_input == "section" or U.shape[1] < 2:
        return None
    if wind_input == "mean":
        se = weighted_mean_standard_error(U, wind_weights)
    else:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # rows with fewer than two winds: NaN
            se = np.nanstd(U, axis=1, ddof=1)
    return np.where(np.isfinite(se), se, np.nanmedian(se))


def campaign_samples(model, records: list[Record]) -> CampaignSamples:
    """The pooled samples, blocks and folds of (already smoothed) records; sets ``model.yaw_degree_``."""
    S = records[0].n_sections
    for rec in records:
        if rec.dA is None:
            raise ValueError(f"record {rec.event_id!r} has no dA: the model is fitted to dA/dt")
    t = np.concatenate([r.t for r in records])
    with_yaw = all(r.yaw is not None for r in records)
    J = (1 if with_yaw else 0) if model.yaw_degree is None else int(model.yaw_degree)
    if J and not with_yaw:
        raise InputError("yaw_degree > 0 needs every record to carry the mean wind's yaw (Record.yaw)")
    model.yaw_degree_ = J  # the model's yaw covariate reads it
    event = np.concatenate([np.full(r.n_samples, e) for e, r in enumerate(records)])
    # Blocks: block_s-long pieces of each event, numbered across the campaign.
    t0 = np.concatenate([np.full(r.n_samples, r.t[0]) for r in records])
    piece = np.floor((t - t0) / model.block_s).astype(np.int64)
    _, block_all = np.unique(event * (piece.max() + 1) + piece, return_inverse=True)
    n_ev = len(records)
    rng = np.random.default_rng(model.seed)
    K = min(int(model.n_folds), n_ev)
    fold_of_event = np.empty(n_ev, dtype=np.int64)
    fold_of_event[rng.permutation(n_ev)] = np.arange(n_ev) % K
    U_raw = np.concatenate([r.U for r in records])
    return CampaignSamples(
        records=records, n_sections=S, yaw_degree=J, n_folds=K, n_events=n_ev, rng=rng, event=event,
        block=block_all, fold_of_event=fold_of_event, A=np.concatenate([r.A for r in records]),
        U=model.wind_inputs(U_raw), dA=np.concatenate([r.dA for r in records]),
        Z=np.concatenate([model.yaw_covariate(r, r.n_samples) for r in records]) if J else None,
        wind_se=wind_standard_error(model.wind_input, model.wind_weights_, U_raw))


def fold_errors(stats: BlockStats, fold_of_block, K, P, pen, keep) -> np.ndarray:
    """Held-out squared error of each of the K folds, for every relative penalty ``pen``, shape (K, L)."""
    Gf, bf, yf = stats.by(fold_of_block, K)
    Gs, bs = Gf.sum(axis=0), bf.sum(axis=0)
    return held_out_errors(Gs, bs, Gf, bf, yf, P, pen * penalty_scale(Gs, P), keep)


def cv_error(stats: BlockStats, fold_of_block, K, P, pen, keep) -> np.ndarray:
    """Summed held-out squared error over the K folds, for every relative penalty ``pen``, shape (L,)."""
    return fold_errors(stats, fold_of_block, K, P, pen, keep).sum(axis=0)


def section_statistics(model, U, A, y, block, n_blocks, knots, a_ref, z, n_yaw, weight=None) -> BlockStats:
    """One equation's block statistics (:func:`vivbench.models.varying_stats.block_statistics`); with
    ``wind_input="sum"`` those of the tied design (one curve for every section's wind, :func:`tied_statistics`)."""
    if model.wind_input != "sum":
        return block_statistics(U, A, y, block, n_blocks, knots, a_ref, z, n_yaw, weight)
    return tied_statistics(U, A, y, block, n_blocks, knots, a_ref, model.wind_weights_, z, n_yaw, weight)


def select_orders(stats, fold_of_block, K, P, lam_rel, M, err_all) -> np.ndarray:
    """Backward elimination of orders by the cross-validated error (order 1 always kept), shape (4,) bool."""
    keep = np.ones(4, dtype=bool)
    current = err_all
    while True:
        trials = {}
        for i in (0, 2, 3):
            if keep[i]:
                trial = keep.copy()
                trial[i] = False
                trials[i] = float(cv_error(stats, fold_of_block, K, P, np.array([lam_rel]), np.repeat(trial, M))[0])
        if not trials:
            return keep
        i = min(trials, key=trials.get)
        if trials[i] > current:
            return keep
        keep[i] = False
        current = trials[i]


def select_basis(model, samples: CampaignSamples, k: int, weight: np.ndarray | None = None,
                 fixed: tuple[int, float] | None = None) -> SectionSamples:
    """Section ``k``'s scales, blocks and its (M, lambda) chosen by the cross-validated error over events.

    ``weight`` (n_all,): sample weights of a weighted fit; ``fixed`` (M, relative penalty): no choice.
    """
    A, U, dA, Z, J, K = samples.A, samples.U, samples.dA, samples.Z, samples.yaw_degree, samples.n_folds
    n_basis = np.array(model.n_basis if fixed is None else [fixed[0]], dtype=int)
    pen = np.asarray(model.penalties if fixed is None else [fixed[1]], dtype=float)
    ok = valid_samples(model.wind_input, A, U, dA, Z if J else None, k)
    n = int(ok.sum())
    n_fit = fitted_inputs(model, samples.n_sections)
    p_max = 4 * (J + 1) * n_fit * int(n_basis.max())
    if n < p_max + 2:
        raise InputError(f"section {k + 1}: {n} valid samples are too few for {p_max} spline coefficients")
    Uall, Zall = equation_inputs(model.wind_input, U, Z, k)
    Ak, Uk, yk = A[ok, k], Uall[ok], dA[ok, k]
    zk, yaw_fallback, yaw_ref, yaw_min, yaw_max = None, 0.0, 1.0, 0.0, 0.0
    if J:
        # sin^2 psi over its RMS keeps the yaw columns on the scale of the others.
        zraw = Zall[ok]
        yaw_min, yaw_max = float(np.min(zraw)), float(np.max(zraw))
        yaw_fallback = float(np.median(zraw))
        yaw_ref = float(np.sqrt(np.mean(zraw**2))) or 1.0
        zk = zraw / yaw_ref
    ys = float(np.sqrt(np.mean(yk**2))) or 1.0
    aref = float(np.sqrt(np.mean(Ak**2))) or 1.0
    lo, hi = float(Uk.min()), float(Uk.max())
    y = yk / ys
    _, blk = np.unique(samples.block[ok], return_inverse=True)
    nb = int(blk.max()) + 1
    ev_of_block = np.zeros(nb, dtype=np.int64)
    ev_of_block[blk] = samples.event[ok]
    fold_of_block = samples.fold_of_event[ev_of_block]
    best = None
    errors = np.full((n_basis.size, pen.size), np.nan)
    for a, M in enumerate(n_basis):
        knots = uniform_knots(lo, hi, int(M))
        stats = section_statistics(model, Uk, Ak, y, blk, nb, knots, aref, zk, J,
                                   None if weight is None else weight[ok])
        # Block-diagonal: the same roughness penalty on every order's, yaw power's and wind input's curve.
        P = np.kron(np.eye(4 * (J + 1) * n_fit), difference_penalty(int(M)))
        folds = fold_errors(stats, fold_of_block, K, P, pen, np.ones(P.shape[0], dtype=bool))
        err, per_fold = folds.sum(axis=0) / n, folds / n  # the sum first: the same error as cv_error's
        errors[a] = err
        j = int(np.argmin(err))
        if best is None or err[j] < best.error:
            best = BasisChoice(error=float(err[j]), n_basis=int(M), penalty=float(pen[j]), knots=knots, stats=stats,
                               P=P, fold_errors=per_fold[:, j])
    return SectionSamples(n=n, n_blocks=nb, y_scale=ys, a_ref=aref, wind_range=(lo, hi), event_of_block=ev_of_block,
                          fold_of_block=fold_of_block, yaw_fallback=yaw_fallback, yaw_ref=yaw_ref, yaw_min=yaw_min,
                          yaw_max=yaw_max, cv_error=errors, best=best)


def eiv_weight(model, samples: CampaignSamples, k: int, sec: SectionSamples, step: float = 0.05,
               chunk: int = 50_000) -> tuple[np.ndarray, float]:
    """Effective-variance weights of section ``k``'s samples and the wind error's share of the residual variance.

    Var(residual) = s0^2 + (d f / d U)^2 se_U^2, with f the first fit's
    (standardised) dA/dt, its slope in U by central differences of ``step``
    m/s (with ``wind_input="additive"`` the sum over the sections' winds of
    (d f / d U_s)^2 se_U^2), se_U from :func:`wind_standard_error`, and s0^2 the rest of the
    mean squared residual (floored at a hundredth of it). Weights are the
    inverse variances over their mean; shape (n_all,) (NaN where unused).
    """
    A, U, dA, Z, J = samples.A, samples.U, samples.dA, samples.Z, samples.yaw_degree
    ok = valid_samples(model.wind_input, A, U, dA, Z, k)
    idx = np.flatnonzero(ok)
    best = sec.best
    Gs, bs, _ = best.stats.total()
    c = as_inputs(model, penalised_solve(Gs, bs, best.P, best.penalty * penalty_scale(Gs, best.P)), J, best.n_basis)
    Uk, Zk = equation_inputs(model.wind_input, U, Z, k)
    zk = None if not J else Zk / sec.yaw_ref
    res = np.empty(idx.size)
    slope2 = np.zeros(idx.size)  # sum over the wind inputs of the squared slopes
    for a in range(0, idx.size, chunk):  # the local design rows of a chunk at a time
        i = idx[a:a + chunk]
        z = None if zk is None else zk[i]
        f0 = input_contributions(Uk[i], A[i, k], best.knots, sec.a_ref, z, J, c).sum(axis=0)
        res[a:a + chunk] = dA[i, k] / sec.y_scale - f0
        # Each wind input's error independent of the others': Var = sum_s (df/dU_s)^2 se_U^2. The model
        # is a sum of one function per input, so df/dU_s is that function's slope: every input is
        # shifted at once and each one's own contribution differenced.
        fp = input_contributions(Uk[i] + step, A[i, k], best.knots, sec.a_ref, z, J, c)
        fm = input_contributions(Uk[i] - step, A[i, k], best.knots, sec.a_ref, z, J, c)
        slope2[a:a + chunk] = (((fp - fm) / (2.0 * step)) ** 2).sum(axis=0)
    v_wind = slope2 * samples.wind_se[idx] ** 2
    # The variance function E[res^2] = s0 + kappa v_wind by least squares on the squared residuals:
    # kappa calibrates se_U (the sections' felt winds differ too, so the spread over-states the error).
    ms = float(np.mean(res**2))
    X = np.column_stack([np.ones(idx.size), v_wind])
    s0, kappa = np.linalg.lstsq(X, res**2, rcond=None)[0]
    kappa = max(float(kappa), 0.0)
    s0 = max(float(s0), 0.01 * ms)
    v = s0 + kappa * v_wind
    out = np.full(U.shape[0], np.nan)
    out[idx] = (1.0 / v) / np.mean(1.0 / v)
    return out, float(kappa * np.mean(v_wind) / np.mean(v))


def choose_smoothing(model, records: list[Record], grid: list[float], prior: int = 0):
    """The wind smoothing chosen by the cross-validated error, its samples and the sections' choices.

    The smoothing is chosen like M and lambda, by the cross-validated dA/dt error over events (the target
    dA/dt and the folds do not depend on it, so the errors compare), with the prior ``grid[prior]`` kept
    unless another candidate's error is below it by more than one standard error of the paired differences
    over the folds (:func:`smoothing_choice`). With ``model.eiv_weights`` each section is then refitted at
    its choice with effective-variance weights.

    Returns
    -------
    cv : ndarray, shape (len(grid),); sigma : float, s; samples : CampaignSamples;
    sections : list of SectionSamples; wind_error_share : ndarray, shape (S,)
    """
    cv = np.full(len(grid), np.nan)
    folds: list = [None] * len(grid)
    kept: dict = {}  # the prior's fit and the best candidate's so far; the others are dropped at once
    for g in [prior] + [i for i in range(len(grid)) if i != prior]:
        samples = campaign_samples(model, [smooth_wind(r, float(grid[g])) for r in records])
        secs = [select_basis(model, samples, k) for k in range(samples.n_sections)]
        cv[g] = float(sum(x.best.error for x in secs))
        folds[g] = np.sum([x.best.fold_errors for x in secs], axis=0)
        if g == prior or smoothing_choice(cv, folds, prior) == g:
            kept = {i: v for i, v in kept.items() if i == prior}
            kept[g] = (float(grid[g]), samples, secs)
        del samples, secs
    sigma, samples, secs = kept[smoothing_choice(cv, folds, prior)]
    share = np.zeros(samples.n_sections)
    if model.eiv_weights and samples.wind_se is not None:
        # Effective variance: refit at the chosen basis and penalty with each sample weighted by the
        # inverse of its residual variance, the wind error's share propagated through the first fit's slope.
        for k in range(samples.n_sections):
            w, share[k] = eiv_weight(model, samples, k, secs[k])
            # one section at a time: the first fit's block statistics (blocks x p x p, hundreds of MB
            # with every section's wind) are dropped before the weighted ones are built
            first, secs[k] = secs[k], None
            secs[k] = replace(select_basis(model, samples, k, weight=w,
                                           fixed=(first.best.n_basis, first.best.penalty)), cv_error=first.cv_error)
            del first
    return cv, sigma, samples, secs, share


def smoothing_candidates(model) -> list[float]:
    """The wind smoothings a fit scores, s: ``wind_smoothing_grid`` (with the prior ``wind_smoothing_s`` first
    when the grid lacks it), or the prior alone."""
    prior = float(model.wind_smoothing_s)
    if model.wind_smoothing_grid is None:
        return [prior]
    grid = [float(x) for x in model.wind_smoothing_grid]
    return grid if prior in grid else [prior] + grid


def smoothing_evidence(model) -> dict | None:
    """A fitted model's wind smoothing and the cross-validated evidence for it, JSON-ready: ``chosen_s`` (s),
    ``prior_s`` (s), ``candidates_s`` (s) and ``cv_error`` (each candidate's summed error per sample of the
    standardised target); None for a model without a smoothing of its own."""
    cv = getattr(model, "wind_smoothing_cv_", None)
    if cv is None or not hasattr(model, "wind_smoothing_grid"):
        return None
    return {"chosen_s": float(model.wind_smoothing_s_), "prior_s": float(model.wind_smoothing_s),
            "candidates_s": smoothing_candidates(model), "cv_error": [float(x) for x in cv]}


def settle_smoothing(model, records) -> tuple[dict, dict]:
    """The wind smoothing chosen once on ``records`` (every event) for every model of a selection.

    Returns
    -------
    params : dict, ``{"wind_smoothing_s": s, "wind_smoothing_grid": None}``: ``model``'s choice among its
        ``wind_smoothing_grid`` (:func:`choose_smoothing`), pinned; ``{}`` without a grid
    evidence : dict, ``{"wind_smoothing": ...}`` (:func:`smoothing_evidence`); ``{}`` without a grid
    """
    if model.wind_smoothing_grid is None:
        return {}, {}
    probe = copy.deepcopy(model)
    shared = fit_shared(probe, records)
    probe.wind_smoothing_cv_, probe.wind_smoothing_s_ = shared.wind_smoothing_cv, shared.wind_smoothing_s
    return ({"wind_smoothing_s": float(shared.wind_smoothing_s), "wind_smoothing_grid": None},
            {"wind_smoothing": smoothing_evidence(probe)})


def smoothing_choice(cv: np.ndarray, folds: list, prior: int = 0) -> int:
    """Index of the chosen smoothing: the prior unless a candidate's summed cross-validated error is below the
    prior's by more than one standard error of the sum of their paired differences over the folds; then the
    lowest of those. With fewer than :data:`SMOOTHING_MIN_FOLDS` folds (events) the prior stays.

    ``cv`` (G,): each candidate's summed error (NaN: not scored yet); ``folds``: each candidate's errors by
    fold, shape (K,), or None when not scored yet.
    """
    best = prior
    for g in range(len(cv)):
        if g == prior or folds[g] is None or not np.isfinite(cv[g]):
            continue
        diff = np.asarray(folds[prior]) - np.asarray(folds[g])
        if diff.size < SMOOTHING_MIN_FOLDS or not np.all(np.isfinite(diff)):
            continue
        se = math.sqrt(diff.size) * float(np.std(diff, ddof=1))
        if float(diff.sum()) > se and cv[g] < cv[best]:
            best = g
    return best


@dataclass(frozen=True)
class SharedFit:
    """Steps 1-3 of a fit (module docstring), shared by every model that differs only in :data:`FINAL_PARAMS`:
    the wind weights (``wind_weights_choice`` "equal", "modal" or "given"; ``wind_weights`` (S,)), the yaw
    degree, the candidate smoothings' cross-validated errors (``wind_smoothing_cv``) and the chosen one
    (``wind_smoothing_s``, s), its samples (their generator positioned for the bootstrap), the sections'
    choices and the wind error's shares of the residual variance (S,)."""

    wind_weights_choice: str
    wind_weights: np.ndarray
    yaw_degree: int
    wind_smoothing_cv: np.ndarray
    wind_smoothing_s: float
    samples: CampaignSamples
    sections: list
    wind_error_share: np.ndarray


def fit_shared(model, records) -> SharedFit:
    """Steps 1-3 of fitting ``model`` to ``records`` (a sequence of Record, or legacy tuples).

    Sets ``wind_weights_`` and ``yaw_degree_`` on ``model`` (the steps read them). Raises InputError for
    bad parameters or fewer than 2 events, ValueError for records of unequal sections.
    """
    check_parameters(model)
    raw = [as_record(r, k) for k, r in enumerate(records)]
    if len(raw) < 2:
        # M, lambda and the wind smoothing are chosen by cross-validation over events
        raise InputError(f"the varying-coefficient model needs at least 2 events (its basis and penalty are "
                         f"chosen by cross-validation over events); got {len(raw)}")
    for rec in raw:
        if rec.n_sections != raw[0].n_sections:
            raise ValueError(f"record {rec.event_id!r} has {rec.n_sections} sections, the first {raw[0].n_sections}")
    weights = model.wind_weights if model.wind_input in ("mean", "sum") else "equal"
    # The weights come from the amplitudes, which the wind's smoothing does not touch.
    model.wind_weights_ = resolve_wind_weights(weights, np.concatenate([r.A for r in raw]))
    grid = smoothing_candidates(model)
    cv, sigma, samples, sections, share = choose_smoothing(model, raw, grid, grid.index(float(model.wind_smoothing_s)))
    return SharedFit(wind_weights_choice=weights if isinstance(weights, str) else "given",
                     wind_weights=model.wind_weights_, yaw_degree=int(model.yaw_degree_), wind_smoothing_cv=cv,
                     wind_smoothing_s=sigma, samples=samples, sections=sections, wind_error_share=share)


def fit_final(model, shared: SharedFit) -> None:
    """Step 4 for ``model`` from ``shared`` (:func:`fit_shared` of a model equal to it outside
    :data:`FINAL_PARAMS`): sets every fitted attribute, the same as a fit of ``model`` alone."""
    check_parameters(model)
    model.penalty_choice_ = model.penalty_choice
    model.wind_weights_choice_ = shared.wind_weights_choice
    model.wind_weights_ = shared.wind_weights
    model.yaw_degree_ = shared.yaw_degree
    model.wind_smoothing_cv_, model.wind_smoothing_s_ = shared.wind_smoothing_cv, shared.wind_smoothing_s
    model.wind_error_share_ = shared.wind_error_share
    # every model draws its bootstrap from the generator where the shared steps left it
    samples = replace(shared.samples, rng=copy.deepcopy(shared.samples.rng))
    for name, value in fitted_arrays(model, samples, shared.sections).items():
        setattr(model, name, value)


def fit_section(model, samples: CampaignSamples, sec: SectionSamples) -> SectionFit:
    """Section ``sec``'s final fit at its chosen basis: the penalty choice, coefficients, bootstrap, confidence sets.

    ``model.penalty_choice_`` "least" or "loeo" re-chooses the penalty on the final fit's leave-one-event-out
    errors (every order kept): the least penalty of their confidence set, or their minimum.
    """
    J, n_ev, rng = samples.yaw_degree, samples.n_events, samples.rng
    pen = np.asarray(model.penalties, dtype=float)
    n_in, n_fit = model.n_inputs(samples.n_sections), fitted_inputs(model, samples.n_sections)
    best = sec.best
    M, lam_rel, stats, P = best.n_basis, best.penalty, best.stats, best.P
    # Per-event statistics: leave-one-event-out fits of the penalty choice and of the confidence sets.
    ev_b, eb, ey = stats.by(sec.event_of_block, n_ev)
    Gs, bs = ev_b.sum(axis=0), eb.sum(axis=0)
    has = np.bincount(sec.event_of_block, minlength=n_ev) > 0
    lams = pen * penalty_scale(Gs, P)
    level, test = model.model_set_level, model.model_set_test
    loss_all = None  # every candidate penalty's leave-one-event-out losses with every order kept
    if model.penalty_choice_ in ("least", "loeo"):
        loss = loss_all = held_out_errors(Gs, bs, ev_b[has], eb[has], ey[has], P, lams,
                                          np.ones(P.shape[0], dtype=bool)).T
        if model.penalty_choice_ == "loeo":
            lam_rel = float(pen[int(np.argmin(loss.sum(axis=1)))])
        else:
            lam_rel = float(pen[confidence_set(loss, level, test)].min())
    keep_orders = np.ones(4, dtype=bool)
    if model.select_orders:
        keep_orders = select_orders(stats, sec.fold_of_block, samples.n_folds, P, lam_rel, (J + 1) * n_fit * M,
                                    best.error * sec.n)
    keep = np.repeat(keep_orders, (J + 1) * n_fit * M)
    lam = lam_rel * penalty_scale(Gs, P)
    c = penalised_solve(Gs, bs, P, lam, keep)
    ys = sec.y_scale
    rss = float(quadratic_error(c, Gs, bs, ey.sum())) * ys**2
    idx = np.flatnonzero(keep)
    H = np.linalg.solve(Gs[idx[:, None], idx] + lam * P[idx[:, None], idx] + 1e-10 * np.eye(idx.size)
                        * np.trace(Gs[idx[:, None], idx]) / idx.size, Gs[idx[:, None], idx])
    to_phys = ys / sec.a_ref ** np.arange(4)  # (4,)
    zscale = sec.yaw_ref ** -np.arange(J + 1.0)  # (J + 1,): coefficients of (sin^2 psi)^j
    L = n_in * M

    def physical(coef):  # (..., p) standardised -> (..., L, 4, J + 1) physical (every wind input's, untied)
        coef = as_inputs(model, coef, J, M)
        return np.moveaxis(coef.reshape(coef.shape[:-1] + (4, J + 1, L)), -1, -3) * to_phys[:, None] * zscale

    n_boot = int(model.n_bootstrap)
    boot = np.zeros((0, L, 4, J + 1))
    if n_boot:
        # Block multiplicities; the resampled statistics are weighted sums of the blocks'.
        nb = sec.n_blocks
        mult = block_counts(nb, n_boot, rng).astype(float)
        Gb, bb, _ = stats.sums(mult)
        boot = physical(penalised_solve(Gb, bb, P, lam, keep))
    # The confidence set of order subsets (leave-one-event-out prediction).
    sets = bool(getattr(model, "model_sets", True))
    loeo = np.full((ORDER_SUBSETS.shape[0], n_ev), np.nan)
    subset = np.zeros((ORDER_SUBSETS.shape[0], L, 4, J + 1))
    for a, orders in enumerate(ORDER_SUBSETS):
        keep_a = np.repeat(orders, (J + 1) * n_fit * M)
        if sets:
            loeo[a, has] = held_out_errors(Gs, bs, ev_b[has], eb[has], ey[has], P, [lam], keep_a)[:, 0]
        subset[a] = physical(penalised_solve(Gs, bs, P, lam, keep_a))
    # The confidence set of penalties (same basis and orders): a penalty's bias is shared by every
    # bootstrap replicate, so the verdict also needs the fits at every penalty whose
    # leave-one-event-out error is not significantly above the best one's to agree.
    subset_plausible, penalty_plausible = np.zeros(ORDER_SUBSETS.shape[0], dtype=bool), np.zeros(pen.size, dtype=bool)
    if sets:
        loss = (loss_all if loss_all is not None and keep.all()
                else held_out_errors(Gs, bs, ev_b[has], eb[has], ey[has], P, lams, keep).T)
        subset_plausible = confidence_set(loeo[:, has], level, test, margin=float(model.order_set_margin))
        penalty_plausible = confidence_set(loss, level, test)
    return SectionFit(coef=physical(c), bootstrap=boot, subset_coef=subset,
                      penalty_coef=physical(penalised_solve(Gs, bs, P, lams, keep)), penalty=lam_rel,
                      penalty_cv=best.penalty, orders=keep_orders, edf=float(np.trace(H)), rss=rss,
                      subset_loeo=loeo, subset_plausible=subset_plausible, penalty_plausible=penalty_plausible)


def fitted_arrays(model, samples: CampaignSamples, secs: list[SectionSamples]) -> dict:
    """Every section's fit (:func:`fit_section`, in order) gathered into the model's fitted attributes by name."""
    S, J = samples.n_sections, samples.yaw_degree
    n_basis = np.array(model.n_basis, dtype=int)
    pen = np.asarray(model.penalties, dtype=float)
    Mmax = int(n_basis.max())
    Lmax = model.n_inputs(S) * Mmax  # coefficients per curve: each wind input's M B-splines, one after another
    n_boot, n_sub = int(model.n_bootstrap), ORDER_SUBSETS.shape[0]
    coef = np.zeros((S, Lmax, 4, J + 1))
    boot = np.zeros((n_boot, S, Lmax, 4, J + 1))
    subset = np.zeros((n_sub, S, Lmax, 4, J + 1))
    pcoef = np.zeros((pen.size, S, Lmax, 4, J + 1))
    out = {"knots_": np.full((S, Mmax + DEGREE + 1), np.nan), "n_basis_": np.zeros(S, dtype=int),
           "penalty_": np.zeros(S), "penalty_cv_": np.zeros(S), "orders_": np.ones((S, 4), dtype=bool),
           "cv_error_": np.full((S, n_basis.size, pen.size), np.nan), "edf_": np.zeros(S),
           "wind_range_": np.zeros((S, 2)), "y_scale_": np.ones(S), "a_ref_": np.ones(S), "rss_": np.zeros(S),
           "subset_loeo_": np.full((n_sub, S), np.nan), "subset_plausible_": np.zeros((n_sub, S), dtype=bool),
           # not saved: for studies of the level
           "subset_loeo_event_": np.full((n_sub, S, len(samples.records)), np.nan),
           "penalty_plausible_": np.zeros((pen.size, S), dtype=bool), "yaw_ref_": np.ones(S),
           "yaw_fallback_": np.zeros(S), "yaw_min_": np.zeros(S), "yaw_max_": np.zeros(S)}
    for k, sec in enumerate(secs):
        fit = fit_section(model, samples, sec)
        M, L = sec.best.n_basis, fit.coef.shape[0]
        coef[k, :L], boot[:, k, :L], subset[:, k, :L], pcoef[:, k, :L] = (fit.coef, fit.bootstrap, fit.subset_coef,
                                                                          fit.penalty_coef)
        out["knots_"][k, :M + DEGREE + 1] = sec.best.knots
        out["yaw_fallback_"][k], out["yaw_ref_"][k], out["yaw_min_"][k] = sec.yaw_fallback, sec.yaw_ref, sec.yaw_min
        out["yaw_max_"][k] = sec.yaw_max
        out["cv_error_"][k] = sec.cv_error
        out["n_basis_"][k], out["penalty_"][k], out["orders_"][k] = M, fit.penalty, fit.orders
        out["penalty_cv_"][k], out["edf_"][k], out["rss_"][k] = fit.penalty_cv, fit.edf, fit.rss
        out["wind_range_"][k] = sec.wind_range
        out["y_scale_"][k], out["a_ref_"][k] = sec.y_scale, sec.a_ref
        out["subset_loeo_"][:, k] = np.nansum(fit.subset_loeo, axis=1) * sec.y_scale**2
        out["subset_loeo_event_"][:, k] = fit.subset_loeo * sec.y_scale**2
        out["subset_plausible_"][:, k] = fit.subset_plausible
        out["penalty_plausible_"][:, k] = fit.penalty_plausible
    for name, arr in (("coef_", coef), ("coef_bootstrap_", boot), ("subset_coef_", subset), ("penalty_coef_", pcoef)):
        out[name] = np.ascontiguousarray(arr[..., 0])  # yaw 0; then the coefficients of (sin^2 psi)^j, j >= 1
        out[name.replace("coef_", "coef_yaw_")] = np.ascontiguousarray(arr[..., 1:])
    out.update(yaw_degree_=J,
               n_samples_=sum(sec.n for sec in secs), n_blocks_=max(sec.n_blocks for sec in secs), n_sections_=S,
               event_ids_=[r.event_id for r in samples.records])
    return out


def event_statistics(model, records: list[Record]) -> list[dict]:
    """Per-event sufficient statistics of every equation of a fitted model (its ``event_statistics``)."""
    J = model.yaw_degree_
    out = []
    U = model.wind_inputs(np.concatenate([r.U for r in records]))
    A = np.concatenate([r.A for r in records])
    dA = np.concatenate([r.dA for r in records])
    Z = np.concatenate([model.yaw_covariate(r, r.n_samples) for r in records]) if J else None
    event = np.concatenate([np.full(r.n_samples, e) for e, r in enumerate(records)])
    E = len(records)
    n_in = fitted_inputs(model, model.n_sections_)
    for k in range(model.n_sections_):
        M = int(model.n_basis_[k])
        knots = model.knots_[k, :M + DEGREE + 1]
        ok = valid_samples(model.wind_input, A, U, dA, Z if J else None, k)
        Uk, Zk = equation_inputs(model.wind_input, U, Z, k)
        zk = None if not J else Zk[ok] / model.yaw_ref_[k]
        stats = section_statistics(model, Uk[ok], A[ok, k], dA[ok, k] / model.y_scale_[k], event[ok], E, knots,
                                   model.a_ref_[k], zk, J)
        G, b, yy = stats.sums(np.eye(E))
        cnt = stats.count
        out.append({"G": G, "b": b, "yy": yy, "n": cnt,
                    "P": np.kron(np.eye(4 * (J + 1) * n_in), difference_penalty(M)),
                    "penalty": float(model.penalty_[k]), "keep": np.repeat(model.orders_[k], (J + 1) * n_in * M),
                    "n_basis": M, "n_inputs": n_in})
    return out
