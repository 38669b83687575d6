"""Recovery metrics as pure functions on arrays.

Each function scores one aspect of an identification against a truth the
testbed computes exactly: regimes (accuracy beside coverage, 4x4 confusion),
support of the coefficient matrices (per term, per section-pooled term and per
order of A), the relative error of the right-hand side, cluster agreement and
forecast NMSE. Nothing here reads files; :mod:`vivbench.validate.campaign`
feeds them.

Support and the synthetic bridge
--------------------------------
In the synthetic bridge the averaged amplitudes are A_k = phi_k Q (docs/concepts.md (the truth)),
so the columns A_1^i U_1^j, A_2^i U_2^j and A_3^i U_3^j of the library are
proportional up to the small per-section offsets of U. The truth matrix
``coef`` (equation, feature) is therefore only one representative of a family
of matrices with the same dynamics: a model that carries a term on another
section's column is as right as the truth, yet term-level scores count it as
one false positive and one false negative. The section-pooled term set
(A^i U^j present in an equation when it is nonzero for any section) and the
orders of A present are what the data can determine; within a 50 s window U is
nearly constant, so even the power j of U is weakly determined and the order
level is the most meaningful. :data:`SUPPORT_NOTES` says this in the outputs.
"""

from __future__ import annotations

import numpy as np

from vivbench.core.terms import section_exponents
from vivbench.core.errors import InputError

__all__ = [
    "REGIMES",
    "SUPPORT_NOTES",
    "confusion_matrix",
    "regime_report",
    "support_mask",
    "pooled_support",
    "order_support",
    "support_counts",
    "support_scores",
    "merge_support_scores",
    "rhs_error_summary",
    "curve_errors",
    "energy_relative_error",
    "curves_rhs",
    "curve_energy_error",
    "cluster_purity",
    "cluster_agreement",
    "forecast_summary",
]

REGIMES = (1, 2, 3, 4)

SUPPORT_NOTES = (
    "In the synthetic bridge A_k = phi_k Q, so the columns A_1^i U_1^j, A_2^i U_2^j and A_3^i U_3^j are nearly "
    "proportional and the truth coefficient matrix is one representative of a family with the same dynamics "
    "(docs/concepts.md (the truth)): term-level support scores count a term placed on another section's column as wrong although "
    "the data cannot tell them apart.",
    "pooled_terms: a term A^i U^j is present in an equation when it is nonzero for any section; this is what "
    "the data can determine across sections.",
    "orders: which orders i of A appear in an equation (any section, any power of U); inside a 50 s window U is "
    "nearly constant, so the power of U is weakly determined too and the order level is the most meaningful.",
)

_QUANTILES = (0.1, 0.25, 0.5, 0.75, 0.9)


def _nan_ratio(num: float, den: float) -> float:
    return float(num) / float(den) if den else float("nan")


# ----------------------------------------------------------------------- regimes


def confusion_matrix(truth: np.ndarray, identified: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
    """Counts of true regime (rows) against identified regime (columns).

    Parameters
    ----------
    truth, identified : ndarray of int, same shape
        Regimes 1..4; 0 means no truth (``truth``) or no model (``identified``),
        and such entries are left out.
    mask : ndarray of bool, same shape, optional
        Only entries where it is True are counted.

    Returns
    -------
    ndarray of int64, shape (4, 4)
        Entry [a - 1, b - 1] counts true regime a identified as b.
    """
    truth = np.asarray(truth).ravel()
    identified = np.asarray(identified).ravel()
    if truth.shape != identified.shape:
        raise ValueError(f"truth and identified must have the same size; got {truth.size} and {identified.size}")
    keep = np.isin(truth, REGIMES) & np.isin(identified, REGIMES)
    if mask is not None:
        keep &= np.asarray(mask, dtype=bool).ravel()
    idx = (truth[keep].astype(np.int64) - 1) * 4 + (identified[keep].astype(np.int64) - 1)
    return np.bincount(idx, minlength=16).reshape(4, 4)


def regime_report(identified: np.ndarray, truth: np.ndarray, identifiable: np.ndarray) -> dict:
    """Regime accuracy and confusion, identifiable window-equations apart.

    Parameters
    ----------
    identified, truth : ndarray of int, same shape, e.g. (n_windows, n_equations)
        Regimes 1..4; 0: no model / no truth (not scored).
    identifiable : ndarray of bool, same shape

    Returns
    -------
    dict
        ``n`` (scored window-equations), ``n_no_model`` (truth known but no
        model), ``coverage`` (share of scored flagged identifiable) and
        ``groups`` with ``identifiable``, ``not_identifiable`` and ``all``,
        each ``{"n", "accuracy", "confusion"}`` (accuracy NaN for an empty
        group; confusion a 4x4 list, rows true regime 1..4, columns
        identified 1..4).
    """
    identified = np.asarray(identified).ravel()
    truth = np.asarray(truth).ravel()
    ok = np.asarray(identifiable, dtype=bool).ravel()
    if not (identified.shape == truth.shape == ok.shape):
        raise ValueError(f"identified, truth and identifiable must have the same size; got {identified.size}, {truth.size}, {ok.size}")
    scored = np.isin(truth, REGIMES) & np.isin(identified, REGIMES)
    groups = {}
    for name, mask in (("identifiable", ok), ("not_identifiable", ~ok), ("all", np.ones_like(ok))):
        cm = confusion_matrix(truth, identified, mask)
        n = int(cm.sum())
        groups[name] = {"n": n, "accuracy": _nan_ratio(np.trace(cm), n), "confusion": cm.tolist()}
    return {
        "n": int(scored.sum()),
        "n_no_model": int((np.isin(truth, REGIMES) & ~np.isin(identified, REGIMES)).sum()),
        "coverage": float(ok[scored].mean()) if scored.any() else float("nan"),
        "groups": groups,
    }


# ----------------------------------------------------------------------- support


def support_mask(coef: np.ndarray, tol: float = 0.0) -> np.ndarray:
    """Terms present in coefficient matrices: finite and ``|coef| > tol``.

    Parameters
    ----------
    coef : ndarray, shape (..., n_features)

    Returns
    -------
    ndarray of bool, same shape
    """
    coef = np.asarray(coef, dtype=float)
    with np.errstate(invalid="ignore"):
        return np.isfinite(coef) & (np.abs(coef) > tol)


def _by_section(support: np.ndarray, n_sections: int) -> np.ndarray:
    support = np.asarray(support, dtype=bool)
    n_terms = section_exponents().shape[0]
    if support.shape[-1] != n_terms * n_sections:
        raise ValueError(f"support must have {n_terms * n_sections} features ({n_sections} sections x {n_terms}) on its last axis; got {support.shape[-1]}")
    return support.reshape(*support.shape[:-1], n_sections, n_terms)


def pooled_support(support: np.ndarray, n_sections: int = 3) -> np.ndarray:
    """Section-pooled term set: A^i U^j present for any section.

    Parameters
    ----------
    support : ndarray of bool, shape (..., 23 * n_sections), library order of :mod:`vivbench.core.terms`

    Returns
    -------
    ndarray of bool, shape (..., 23), in the order of :func:`vivbench.core.terms.section_exponents`
    """
    return _by_section(support, n_sections).any(axis=-2)


def order_support(support: np.ndarray, n_sections: int = 3) -> np.ndarray:
    """Orders i of A present (any section, any power of U).

    Parameters
    ----------
    support : ndarray of bool, shape (..., 23 * n_sections)

    Returns
    -------
    ndarray of bool, shape (..., 4), orders 0..3
    """
    pooled = pooled_support(support, n_sections)
    order = section_exponents()[:, 0]
    return np.stack([pooled[..., order == i].any(axis=-1) for i in range(4)], axis=-1)


def support_counts(identified: np.ndarray, truth: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """True positives, false positives and false negatives along the last axis.

    Parameters
    ----------
    identified : ndarray of bool, shape (..., n)
    truth : ndarray of bool, broadcastable to ``identified``

    Returns
    -------
    tp, fp, fn : ndarray of int, shape ``identified.shape[:-1]``
    """
    identified = np.asarray(identified, dtype=bool)
    truth = np.broadcast_to(np.asarray(truth, dtype=bool), identified.shape)
    return ((identified & truth).sum(-1), (identified & ~truth).sum(-1), (~identified & truth).sum(-1))


def _pr(tp, fp, fn) -> dict:
    tp, fp, fn = int(np.sum(tp)), int(np.sum(fp)), int(np.sum(fn))
    return {"tp": tp, "fp": fp, "fn": fn, "precision": _nan_ratio(tp, tp + fp), "recall": _nan_ratio(tp, tp + fn)}


def support_scores(coef_identified: np.ndarray, coef_true: np.ndarray, *, mask: np.ndarray | None = None,
                   n_sections: int | None = None, tol: float = 0.0) -> dict:
    """Support precision and recall of identified models against the truth matrix.

    Counts are pooled (micro-averaged) over the scored models: precision =
    sum TP / sum (TP + FP), recall = sum TP / sum (TP + FN).

    Parameters
    ----------
    coef_identified : ndarray, shape (..., n_equations, n_features)
        E.g. (n_windows, S, 23 S) for S sections. A model with any non-finite coefficient (no
        model fitted) is left out.
    coef_true : ndarray, shape (n_equations, n_features)
        The exact truth (one representative of a family, see the module notes).
    mask : ndarray of bool, shape (..., n_equations), optional
        Score only these models (e.g. the identifiable ones).
    n_sections : int, optional
        Number of sections S; default ``n_features // 23`` (the library has 23 terms per section).
    tol : float
        A coefficient counts as present when ``|coef| > tol`` (physical units).

    Returns
    -------
    dict
        ``n`` (models scored), ``n_terms_identified``, ``n_terms_true``,
        ``mean_terms_per_model``; ``terms`` (the 23 * n_sections columns),
        ``pooled_terms`` (the 23 section-pooled A^i U^j) and ``orders`` (orders
        of A), each ``{"tp", "fp", "fn", "precision", "recall",
        "n_candidates", "precision_dense_model"}`` (the last: the precision
        of a model holding every candidate, the chance level to beat);
        ``order_counts`` (list of 4 such dicts, orders 0..3, counted over
        models); ``order_recall`` and ``order_precision`` (lists of 4, NaN
        where undefined); ``notes``.
    """
    coef_identified = np.asarray(coef_identified, dtype=float)
    coef_true = np.asarray(coef_true, dtype=float)
    if coef_identified.shape[-2:] != coef_true.shape:
        raise InputError(f"identified models have shape {coef_identified.shape[-2:]} per window; the truth has {coef_true.shape}")
    if n_sections is None:
        n_sections = coef_true.shape[-1] // section_exponents().shape[0]
    valid = np.isfinite(coef_identified).all(axis=-1)
    if mask is not None:
        valid &= np.asarray(mask, dtype=bool)
    sid = support_mask(coef_identified[valid], tol)  # (n, n_features)
    eq = np.broadcast_to(np.arange(coef_true.shape[0]), valid.shape)[valid]
    strue = support_mask(coef_true, tol)[eq]
    levels = {
        "terms": (sid, strue),
        "pooled_terms": (pooled_support(sid, n_sections), pooled_support(strue, n_sections)),
        "orders": (order_support(sid, n_sections), order_support(strue, n_sections)),
    }
    out = {"n": int(valid.sum()), "n_terms_identified": int(sid.sum()), "n_terms_true": int(strue.sum())}
    for name, (a, b) in levels.items():
        out[name] = _pr(*support_counts(a, b))
        # a model with every candidate term scores recall 1 and this precision: the chance level
        out[name]["n_candidates"] = int(b.size)
    oi, ot = levels["orders"]
    # per order: counts over models (axis 0), one column per order
    out["order_counts"] = [_pr(*support_counts(oi[:, i:i + 1], ot[:, i:i + 1])) for i in range(4)]
    return _finish_support(out)


def _finish_support(out: dict) -> dict:
    for level in ("terms", "pooled_terms", "orders"):
        c = out[level]
        c["precision_dense_model"] = _nan_ratio(c["tp"] + c["fn"], c["n_candidates"])
    out["mean_terms_per_model"] = _nan_ratio(out["n_terms_identified"], out["n"])
    out["order_recall"] = [c["recall"] for c in out["order_counts"]]
    out["order_precision"] = [c["precision"] for c in out["order_counts"]]
    out["notes"] = list(SUPPORT_NOTES)
    if out["orders"]["n_candidates"] and out["orders"]["tp"] + out["orders"]["fn"] == out["orders"]["n_candidates"]:
        out["notes"].append("Every scored true model holds all four orders of A, so order-level precision is 1 for "
                            "any model and says nothing; compare precisions with precision_dense_model (a model "
                            "with every candidate term).")
    return out


def merge_support_scores(parts: list[dict]) -> dict:
    """Pool the counts of several :func:`support_scores` results (e.g. one per event).

    Returns
    -------
    dict, as :func:`support_scores`, with counts summed and ratios recomputed
    """
    out = {k: int(sum(p[k] for p in parts)) for k in ("n", "n_terms_identified", "n_terms_true")}
    for level in ("terms", "pooled_terms", "orders"):
        out[level] = _pr(*(sum(p[level][k] for p in parts) for k in ("tp", "fp", "fn")))
        out[level]["n_candidates"] = int(sum(p[level]["n_candidates"] for p in parts))
    out["order_counts"] = [_pr(*(sum(p["order_counts"][i][k] for p in parts) for k in ("tp", "fp", "fn")))
                           for i in range(4)]
    return _finish_support(out)


# ----------------------------------------------------------------------- dynamics


def _quantile_summary(values: np.ndarray, quantiles) -> dict:
    v = np.asarray(values, dtype=float).ravel()
    v = v[np.isfinite(v)]
    out = {"n": int(v.size)}
    qs = np.quantile(v, quantiles) if v.size else np.full(len(quantiles), np.nan)
    out["median"] = float(np.median(v)) if v.size else float("nan")
    out.update({f"q{round(100 * q):02d}": float(x) for q, x in zip(quantiles, qs)})
    return out


def rhs_error_summary(errors: np.ndarray, active: np.ndarray | None = None, quantiles=_QUANTILES) -> dict:
    """Median and quantiles of relative RHS errors, windows with dynamics apart.

    Parameters
    ----------
    errors : ndarray, any shape, e.g. (n_windows, n_equations)
        Relative RMS errors (:func:`vivbench.validate.rhs_relative_error`);
        non-finite entries (no model, or no true dynamics) are left out and
        counted in ``n_nonfinite``.
    active : ndarray of bool, same shape, optional
        Window-equations with dynamics (see :func:`vivbench.validate.window_rhs_errors`).
    quantiles : sequence of float in [0, 1]

    Returns
    -------
    dict
        ``all`` and, when ``active`` is given, ``active`` and ``inactive``:
        each ``{"n", "median", "q10", ...}``; ``n_nonfinite``; ``active_share``
        (share of window-equations with dynamics, NaN without ``active``).
    """
    errors = np.asarray(errors, dtype=float)
    out = {"all": _quantile_summary(errors, quantiles), "n_nonfinite": int((~np.isfinite(errors)).sum())}
    if active is not None:
        active = np.asarray(active, dtype=bool)
        if active.shape != errors.shape:
            raise ValueError(f"active must have the shape of errors {errors.shape}; got {active.shape}")
        out["active"] = _quantile_summary(errors[active], quantiles)
        out["inactive"] = _quantile_summary(errors[~active], quantiles)
        out["active_share"] = float(active.mean()) if active.size else float("nan")
    else:
        out["active_share"] = float("nan")
    return out


# ----------------------------------------------------------------------- coefficient curves


def _interp_curves(curves: np.ndarray, wind: np.ndarray, U: np.ndarray) -> np.ndarray:
    """Curves (4, n_wind) linearly interpolated to speeds U (n,), shape (n, 4); NaN outside the grid."""
    out = np.stack([np.interp(U, wind, c, left=np.nan, right=np.nan) for c in curves], axis=1)
    return out


def _rel_rms(x: np.ndarray, ref: np.ndarray) -> float:
    ok = np.isfinite(x) & np.isfinite(ref)
    if not ok.any():
        return float("nan")
    den = np.sqrt(np.mean(ref[ok] ** 2))
    return float(np.sqrt(np.mean((x[ok] - ref[ok]) ** 2)) / den) if den > 0 else float("nan")


def energy_relative_error(f_model, f_true) -> float:
    """Energy-weighted relative RMS error of a prediction over every sample.

    sqrt(sum (f_model - f_true)^2 / sum f_true^2) over the samples where both
    are finite: the large values (large-amplitude phases, where VIV matters)
    weigh as their energy, unlike a median of per-window errors.

    Parameters
    ----------
    f_model, f_true : array_like, same shape (any), same units (e.g. dA/dt in m/s)
        A sample missing in the prediction (NaN) counts as a total miss: its
        true value enters the error as well as the denominator.

    Returns
    -------
    float, dimensionless; NaN when no true sample is finite or all are zero
    """
    f_model = np.asarray(f_model, dtype=float)
    f_true = np.asarray(f_true, dtype=float)
    if f_model.shape != f_true.shape:
        raise ValueError(f"f_model and f_true must have the same shape; got {f_model.shape} and {f_true.shape}")
    ok = np.isfinite(f_true)
    den = float(np.sum(f_true[ok] ** 2))
    if not ok.any() or den <= 0:
        return float("nan")
    miss = np.where(np.isfinite(f_model[ok]), f_model[ok] - f_true[ok], f_true[ok])
    return float(np.sqrt(np.sum(miss**2) / den))


def curves_rhs(curves: np.ndarray, wind: np.ndarray, U: np.ndarray, A: np.ndarray) -> np.ndarray:
    """dA_k/dt that coefficient curves give at samples: sum_i a_ki(U_k) A_k^i.

    Parameters
    ----------
    curves : ndarray, shape (S, 4, n_wind), a_ki in m^(1-i)/s on ``wind``
    wind : ndarray, shape (n_wind,), m/s, increasing
    U, A : ndarray, shape (n, S), m/s and m

    Returns
    -------
    ndarray, shape (n, S), m/s
        Curves linearly interpolated in wind; NaN outside the grid or where a curve is NaN.
    """
    curves = np.asarray(curves, dtype=float)
    U, A = np.asarray(U, dtype=float), np.asarray(A, dtype=float)
    S = curves.shape[0]
    if curves.ndim != 3 or curves.shape[1] != 4 or U.shape != A.shape or U.ndim != 2 or U.shape[1] != S:
        raise ValueError(f"curves must be (S, 4, n_wind) and U, A (n, S); got {curves.shape}, {U.shape}, {A.shape}")
    out = np.empty(U.shape)
    powers = np.arange(4)
    for k in range(S):
        out[:, k] = np.sum(_interp_curves(curves[k], np.asarray(wind, dtype=float), U[:, k]) * A[:, k, None] ** powers,
                           axis=1)
    return out


def curve_energy_error(curves: np.ndarray, wind: np.ndarray, U: np.ndarray, A: np.ndarray, dA_true: np.ndarray,
                       wind_range=None) -> float:
    """Energy-weighted relative RMS error of the dA/dt that curves give at the true (A, U) of every sample.

    :func:`energy_relative_error` of :func:`curves_rhs` against ``dA_true``
    (the truth's curves' :func:`curves_rhs` at the same samples, or the
    truth's dA/dt)
    over every sample and equation: a sample where the curves are missing
    (NaN) counts as a total miss, but samples whose U_k lies outside
    equation k's ``wind_range`` (where the curves are extrapolations) are
    left out of numerator and denominator.

    Parameters
    ----------
    curves : ndarray, shape (S, 4, n_wind), m^(1-i)/s; wind : ndarray, shape (n_wind,), m/s
    U, A, dA_true : ndarray, shape (n, S), m/s, m and m/s: the truth's samples and the reference dA/dt
    wind_range : array_like, shape (S, 2), m/s, optional
        The fitted data's [U_min, U_max] per equation
        (:func:`vivbench.models.data_wind_range`); None scores every sample.

    Returns
    -------
    float, dimensionless (NaN when no sample is scored)
    """
    dA_true = np.asarray(dA_true, dtype=float)
    U = np.asarray(U, dtype=float)
    f_model = curves_rhs(curves, wind, U, A)
    if dA_true.shape != f_model.shape:
        raise ValueError(f"dA_true must have the shape of U and A {f_model.shape}; got {dA_true.shape}")
    if wind_range is not None:
        rng = np.asarray(wind_range, dtype=float)
        if rng.shape != (U.shape[1], 2):
            raise ValueError(f"wind_range must have shape ({U.shape[1]}, 2) ([U_min, U_max] per equation); "
                             f"got {rng.shape}")
        with np.errstate(invalid="ignore"):
            inside = (U >= rng[None, :, 0]) & (U <= rng[None, :, 1])
        dA_true = np.where(inside, dA_true, np.nan)
    return energy_relative_error(f_model, dA_true)


def curve_errors(curves: np.ndarray, wind: np.ndarray, true_curves: np.ndarray, true_wind: np.ndarray,
                 U: np.ndarray, A: np.ndarray, self_excited: np.ndarray) -> dict:
    """Errors of a campaign-level model's coefficient curves (docs/concepts.md (coefficient curves)) over the lock-in range.

    Parameters
    ----------
    curves : ndarray, shape (S, 4, n_wind)
        The model's a_ki(U) in m^(1-i)/s on ``wind``.
    wind : ndarray, shape (n_wind,), m/s, increasing
    true_curves : ndarray, shape (S, 4, n_true)
        The truth's curves on ``true_wind`` (m/s, increasing).
    true_wind : ndarray, shape (n_true,), m/s
    U, A : ndarray, shape (n, S), m/s and m
        The truth's samples (all events of the campaign).
    self_excited : ndarray of bool, shape (n, S)
        Samples whose true regime is self-excited (2..4, docs/concepts.md (regimes)).

    Returns
    -------
    dict of lists, one entry per equation k
        ``lock_in_wind`` ([U_min, U_max] m/s of the self-excited samples, the
        lock-in range; None without any), ``linear`` (relative RMS error of the
        net linear coefficient a_k1 over the model's wind points inside the
        lock-in range, against the truth's interpolated there), ``total``
        (relative RMS error of sum_i a_ki(U_k) A_k^i over the self-excited
        samples: the dA/dt the curves give where the truth is self-excited),
        ``n_wind`` and ``n_samples`` (points scored). NaN where nothing is scored.
    """
    curves, true_curves = np.asarray(curves, dtype=float), np.asarray(true_curves, dtype=float)
    wind, true_wind = np.asarray(wind, dtype=float), np.asarray(true_wind, dtype=float)
    U, A = np.asarray(U, dtype=float), np.asarray(A, dtype=float)
    mask = np.asarray(self_excited, dtype=bool)
    S = curves.shape[0]
    if curves.shape[:2] != (S, 4) or true_curves.shape[:2] != (S, 4):
        raise ValueError(f"curves and true_curves must have shape (S, 4, n_wind); got {curves.shape}, {true_curves.shape}")
    if U.shape != A.shape or U.shape != mask.shape or U.ndim != 2 or U.shape[1] != S:
        raise ValueError(f"U, A and self_excited must have shape (n, {S}); got {U.shape}, {A.shape}, {mask.shape}")
    out = {"lock_in_wind": [], "linear": [], "total": [], "n_wind": [], "n_samples": []}
    powers = np.arange(4)
    for k in range(S):
        sel = mask[:, k] & np.isfinite(U[:, k]) & np.isfinite(A[:, k])
        if not sel.any():
            out["lock_in_wind"].append(None)
            out["linear"].append(float("nan"))
            out["total"].append(float("nan"))
            out["n_wind"].append(0)
            out["n_samples"].append(0)
            continue
        lo, hi = float(U[sel, k].min()), float(U[sel, k].max())
        g = (wind >= lo) & (wind <= hi)
        a_true = np.interp(wind[g], true_wind, true_curves[k, 1], left=np.nan, right=np.nan)
        Uk, Ak = U[sel, k], A[sel, k]
        Apow = Ak[:, None] ** powers
        f_model = np.sum(_interp_curves(curves[k], wind, Uk) * Apow, axis=1)
        f_true = np.sum(_interp_curves(true_curves[k], true_wind, Uk) * Apow, axis=1)
        out["lock_in_wind"].append([lo, hi])
        out["linear"].append(_rel_rms(curves[k, 1, g], a_true))
        out["total"].append(_rel_rms(f_model, f_true))
        out["n_wind"].append(int(g.sum()))
        out["n_samples"].append(int(np.sum(np.isfinite(f_model) & np.isfinite(f_true))))
    return out


# ----------------------------------------------------------------------- clusters


def cluster_purity(labels: np.ndarray, truth: np.ndarray) -> float:
    """Share of points whose cluster's most common true class is their own.

    Parameters
    ----------
    labels, truth : ndarray of int, shape (n,)

    Returns
    -------
    float in (0, 1]; NaN for no points
    """
    from sklearn.metrics.cluster import contingency_matrix

    labels = np.asarray(labels).ravel()
    truth = np.asarray(truth).ravel()
    if labels.size == 0:
        return float("nan")
    c = contingency_matrix(truth, labels)  # (classes, clusters)
    return float(c.max(axis=0).sum() / labels.size)


def cluster_agreement(labels: np.ndarray, truth: np.ndarray, halo: np.ndarray | None = None, *,
                      ignore_halo: bool = True) -> dict:
    """Adjusted Rand index and purity of cluster labels against truth regimes.

    Parameters
    ----------
    labels : ndarray of int, shape (n,)
        Cluster labels (any integers; permuting them changes nothing).
    truth : ndarray of int, shape (n,)
        True regimes 1..4; 0 (no truth) is left out.
    halo : ndarray of bool, shape (n,), optional
        Halo points of density-peaks clustering.
    ignore_halo : bool
        Leave the halo points out (when ``halo`` is given).

    Returns
    -------
    dict
        ``n`` (points scored), ``n_halo_ignored``, ``n_clusters``, ``ari``
        (sklearn's adjusted Rand index; 1 is perfect, about 0 is chance),
        ``purity``.
    """
    from sklearn.metrics import adjusted_rand_score

    labels = np.asarray(labels).ravel()
    truth = np.asarray(truth).ravel()
    if labels.shape != truth.shape:
        raise ValueError(f"labels and truth must have the same size; got {labels.size} and {truth.size}")
    keep = np.isin(truth, REGIMES)
    n_halo = 0
    if halo is not None and ignore_halo:
        halo = np.asarray(halo, dtype=bool).ravel()
        n_halo = int((keep & halo).sum())
        keep &= ~halo
    lab, tru = labels[keep], truth[keep]
    return {
        "n": int(keep.sum()),
        "n_halo_ignored": n_halo,
        "n_clusters": int(np.unique(lab).size),
        "ari": float(adjusted_rand_score(tru, lab)) if lab.size else float("nan"),
        "purity": cluster_purity(lab, tru),
    }


# ----------------------------------------------------------------------- forecasts


def forecast_summary(nmse: np.ndarray, stopped: np.ndarray, d: np.ndarray, quantiles=_QUANTILES) -> list[dict]:
    """NMSE of forecasts per averaging length d, stopped runs counted apart.

    A stopped (blown-up) forecast has no meaningful NMSE over the horizon: it
    is counted in ``n_stopped`` and never enters the statistics; a completed
    run without a finite NMSE is counted in ``n_nonfinite``.

    Parameters
    ----------
    nmse : ndarray of float, shape (n,)
        One value per forecast, e.g. per (event, d) or (event, d, section).
    stopped : ndarray of bool, shape (n,)
    d : ndarray of float, shape (n,), s

    Returns
    -------
    list of dict, one per distinct d (ascending): ``d_s``, ``n``,
    ``n_stopped``, ``stopped_share``, ``n_nonfinite``, ``n_completed``
    (finite NMSE), ``median``, the quantiles and ``share_below_1`` (of the
    completed runs: better than predicting the mean), all over completed runs.
    """
    nmse = np.asarray(nmse, dtype=float).ravel()
    stopped = np.asarray(stopped, dtype=bool).ravel()
    d = np.asarray(d, dtype=float).ravel()
    if not (nmse.shape == stopped.shape == d.shape):
        raise ValueError(f"nmse, stopped and d must have the same size; got {nmse.size}, {stopped.size}, {d.size}")
    rows = []
    for dv in np.unique(d):
        sel = d == dv
        done = sel & ~stopped
        finite = done & np.isfinite(nmse)
        summ = _quantile_summary(nmse[finite], quantiles)
        n = int(sel.sum())
        row = {"d_s": float(dv), "n": n, "n_stopped": int((sel & stopped).sum()),
               "stopped_share": float((sel & stopped).sum() / n), "n_nonfinite": int((done & ~np.isfinite(nmse)).sum()),
               "n_completed": summ.pop("n")}
        row.update(summ)
        row["share_below_1"] = float(np.mean(nmse[finite] < 1.0)) if finite.any() else float("nan")
        rows.append(row)
    return rows
