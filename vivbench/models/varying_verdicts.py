"""Identifiability of the varying-coefficient model's regime in each window (docs/concepts.md (regimes)).

A window's regime is the rule of docs/concepts.md (regimes) applied to the model's order
contributions over the window's data. It counts as identifiable when

1. at least ``model.agreement`` of the block-bootstrap replicates of the spline
   coefficients (penalty and basis fixed) give the window the same regime: the
   replicates' curves are the model's confidence band, evaluated on the
   window's own (A, U) rather than on a wind grid; and
2. every plausible model of the confidence set of order subsets
   (``model.subset_plausible_``: models without some of the orders 0, 2, 3
   whose leave-one-event-out prediction error is not significantly above the
   best subset's by the model's ``model_set_test``, a signed-rank test over
   events by default) gives it the same regime. The bootstrap measures variance
   only; a systematic misfit (a forced-only bridge whose forced plateaus the
   model bends with A^2 and A^3 terms) passes it, but then the model without
   those orders predicts the held-out events about as well and disagrees;
3. the fit at every penalty of the confidence set of penalties
   (``model.penalty_plausible_``: the candidate penalties whose
   leave-one-event-out error is not significantly above the best one's, by
   the same test) gives it the same regime. A penalty's smoothing bias is
   shared by every bootstrap replicate, so the bootstrap alone cannot see
   it: a too-large penalty flattens the bell of a_1(U) and can call a wind
   self-excited where the bell has fallen, with every replicate agreeing.
   Few events cannot reject a penalty, and then this check flags less.
   Models loaded from files written before the set go without it.
"""

from __future__ import annotations

import json

import numpy as np

from vivbench.core.errors import InputError
from vivbench.core.record import Record
from vivbench.core.regime import regime_rule
from vivbench.library.splines import DEGREE
from vivbench.models.varying_design import key_groups

__all__ = ["gram_order_stats", "varying_description", "varying_settings_text", "varying_summary", "varying_window_verdicts", "window_grams", "window_order_stats"]


def window_order_stats(r: np.ndarray, A: np.ndarray, t: np.ndarray, window_start, window_end):
    """Window RMS of the order contributions and window mean of r_1 / A.

    Parameters
    ----------
    r : ndarray, shape (..., n, S, 4), m/s
    A : ndarray, shape (n, S), m
    t : ndarray, shape (n,), s
    window_start, window_end : ndarray, shape (W,), s (a window holds start <= t < end)

    Returns
    -------
    R : ndarray, shape (..., W, S, 4), m/s; c1 : ndarray, shape (..., W, S), 1/s;
    n_valid : ndarray, shape (..., W, S)
    """
    lo = np.searchsorted(t, np.asarray(window_start, dtype=float), side="left")
    hi = np.searchsorted(t, np.asarray(window_end, dtype=float), side="left")
    ok = np.isfinite(r).all(axis=-1) & np.isfinite(A)
    okA = ok & (A > 0)
    ax = r.ndim - 3  # the time axis

    def wsum(x):
        c = np.cumsum(x, axis=ax)
        c = np.concatenate([np.zeros_like(np.take(c, [0], axis=ax)), c], axis=ax)
        return np.take(c, hi, axis=ax) - np.take(c, lo, axis=ax)

    rz = np.where(ok[..., None], r, 0.0)
    inv = np.where(okA, 1.0 / np.where(okA, A, 1.0), 0.0)
    nv = wsum(ok.astype(float))
    with np.errstate(invalid="ignore", divide="ignore"):
        R = np.sqrt(wsum(rz**2) / nv[..., None])
        c1 = wsum(rz[..., 1] * inv) / wsum(okA.astype(float))
    return R, c1, nv


def window_grams(model: VaryingCoefficientSINDy, record: Record, window_start, window_end) -> dict:
    """Per-window sufficient statistics of the order contributions, linear in the model's coefficients.

    Order i contributes r_i = A^i phi^T theta_i at a sample (phi: the sample's
    design row, :meth:`VaryingCoefficientSINDy.basis_rows`), so over a window
    the mean of r_i^2 is theta_i^T G_i theta_i / n_valid and the mean of
    r_1 / A is m^T theta_1 / n_positive, for any coefficients theta.

    Parameters
    ----------
    model : VaryingCoefficientSINDy (fitted)
    record : Record
    window_start, window_end : array_like, shape (W,), s (a window holds start <= t < end)

    Returns
    -------
    dict
        ``gram`` (W, S, 4, P, P) m^(2i) summed A^(2i) phi phi^T over the valid samples,
        ``mean1`` (W, S, P) summed phi over the valid samples with A > 0,
        ``n_valid`` (W, S), ``n_positive`` (W, S); P = (J + 1) M_max. A sample
        is valid where A and every order's curve are finite (as in :func:`window_order_stats`).
    """
    t, A = record.t, np.asarray(record.A, dtype=float)
    cols, vals = model.basis_rows(record)
    n, S, _ = vals.shape
    P = model.stacked_coefficients().shape[-2]
    lo = np.searchsorted(t, np.asarray(window_start, dtype=float), side="left")
    hi = np.searchsorted(t, np.asarray(window_end, dtype=float), side="left")
    # Disjoint segments between window edges: the Grams are added per segment to each window holding it,
    # the other sums per segment and then per window from its own segments.
    edges = np.unique(np.concatenate([lo, hi, [0]]))
    seg = np.searchsorted(edges, np.arange(n), side="right") - 1
    inside = np.arange(n) < edges[-1]
    G_seg = edges.size - 1
    il, ih = np.searchsorted(edges, lo), np.searchsorted(edges, hi)
    W = lo.size
    gram = np.empty((W, S, 4, P, P))
    mean1 = np.empty((W, S, P))
    n_valid = np.empty((W, S))
    n_pos = np.empty((W, S))
    bounds = np.stack([il, ih], axis=1).ravel()
    # the windows each segment belongs to (a few: windows overlap)
    inwin = (il[None, :] <= np.arange(G_seg)[:, None]) & (np.arange(G_seg)[:, None] < ih[None, :])
    windows_of = [np.flatnonzero(row) for row in inwin]
    empty = ih <= il

    def windowed(per_segment):
        # Each window adds its own few segments (no difference of running sums: a quiet window's
        # A^6-weighted Gram would drown in the rounding of the record's total).
        padded = np.concatenate([per_segment, np.zeros((1,) + per_segment.shape[1:])])
        sums = np.add.reduceat(padded, bounds, axis=0)[::2]
        return np.where(empty.reshape((W,) + (1,) * (per_segment.ndim - 1)), 0.0, sums)

    for k in range(S):  # a few sections
        a_k = A[:, k]
        ok = np.isfinite(vals[:, k]).all(axis=1) & np.isfinite(a_k) & inside
        okA = ok & (a_k > 0)
        gram[:, k] = _window_grams(seg[ok], windows_of, W, cols[ok, k], vals[ok, k], a_k[ok], P)
        aA = a_k[okA]
        # r_1 / A as the direct evaluation forms it: (phi^T theta) A (1 / A)
        wA = cols[okA, k], vals[okA, k] * (aA * (1.0 / aA))[:, None]
        m1 = np.bincount((seg[okA][:, None] * P + wA[0]).ravel(), wA[1].ravel(), minlength=G_seg * P)
        mean1[:, k] = windowed(m1.reshape(G_seg, P))
        n_valid[:, k] = windowed(np.bincount(seg[ok], minlength=G_seg).astype(float))
        n_pos[:, k] = windowed(np.bincount(seg[okA], minlength=G_seg).astype(float))
    return {"gram": gram, "mean1": mean1, "n_valid": n_valid, "n_positive": n_pos}


def _window_grams(seg: np.ndarray, windows_of: list, n_windows: int, cols: np.ndarray, vals: np.ndarray,
                  a: np.ndarray, P: int) -> np.ndarray:
    """Per window and order i, sum of A^(2i) phi phi^T over the window's samples, shape (n_windows, 4, P, P).

    seg (m,) segment (piece between window edges) of each sample, ``windows_of[g]`` the windows segment g
    belongs to; cols, vals (m, Q) the non-zero entries of each design row phi
    (:meth:`VaryingCoefficientSINDy.basis_rows`); a (m,) amplitudes, m. The samples of a segment whose
    winds lie in the same knot intervals share their Q columns: each such group gives one dense product
    (A^i V)^T (A^i V) per order (BLAS, Q x Q), added at its columns to each window holding the segment,
    instead of 4 Q^2 scattered additions per sample. Each window sums its own samples only (no difference
    of running sums: a quiet window's A^6-weighted Gram would drown in the rounding of the record's total).
    Equal to the per-sample sums up to rounding.
    """
    out = np.zeros((n_windows, P, P, 4))
    m = seg.size
    if m == 0:
        return out.transpose(0, 3, 1, 2)
    # Group key: the segment, then the row's columns; a row's columns follow from the first of every run
    # of DEGREE + 1 consecutive B-splines (renumbered after each step, so the key cannot overflow).
    key = seg.astype(np.int64)
    for q in range(0, cols.shape[1], DEGREE + 1):
        key = np.unique(key * P + cols[:, q], return_inverse=True)[1].ravel()
    order, _keys, starts, ends = key_groups(key)
    # A^i times the row, every order at once: (4, Q, m), samples in group order
    Y = (a[order][None, :] ** np.arange(4)[:, None])[:, None, :] * vals[order].T[None, :, :]
    cs, ss = cols[order], seg[order]
    for lo, hi in zip(starts, ends):  # one batched BLAS product per group (a few per segment), not per sample
        wins = windows_of[ss[lo]]
        if wins.size == 0:
            continue
        Yg = Y[:, :, lo:hi]
        c = cs[lo]
        out[wins[:, None, None], c[None, :, None], c[None, None, :]] += (Yg @ Yg.transpose(0, 2, 1)).transpose(1, 2, 0)
    return out.transpose(0, 3, 1, 2)


def gram_order_stats(stats: dict, theta: np.ndarray):
    """Window RMS of the order contributions and mean of r_1 / A for coefficient sets ``theta``.

    Parameters
    ----------
    stats : dict from :func:`window_grams`
    theta : ndarray, shape (R, S, P, 4) (:meth:`VaryingCoefficientSINDy.stacked_coefficients`)

    Returns
    -------
    R : ndarray, shape (R, W, S, 4), m/s (NaN without a valid sample);
    c1 : ndarray, shape (R, W, S), 1/s (NaN without a valid sample with A > 0)
    """
    G, m1 = stats["gram"], stats["mean1"]
    W, S, _, P, _ = G.shape
    nR = theta.shape[0]
    quad = np.empty((nR, W, S, 4))
    for k in range(S):
        for i in range(4):  # one matrix product per equation and order, all windows and sets at once
            th = theta[:, k, :, i]  # (R, P)
            X = (G[:, k, i].reshape(W * P, P) @ th.T).reshape(W, P, nR)
            quad[:, :, k, i] = np.einsum("wpr,rp->rw", X, th)
    with np.errstate(invalid="ignore", divide="ignore"):
        R = np.sqrt(np.maximum(quad, 0.0) / stats["n_valid"][None, :, :, None])
        c1 = np.einsum("wkp,rkp->rwk", m1, theta[..., 1]) / stats["n_positive"][None]
    return R, c1


def varying_window_verdicts(model: VaryingCoefficientSINDy, record: Record, window_start, window_end,
                            chunk: int = 25) -> dict:
    """Regimes of a fitted :class:`VaryingCoefficientSINDy` over a record's windows, and their identifiability.

    Parameters
    ----------
    model : VaryingCoefficientSINDy (fitted, ``n_bootstrap`` > 0 for any window to be identifiable)
    record : Record
    window_start, window_end : array_like, shape (W,), s
    chunk : int
        Replicates evaluated together by the direct evaluation, used only when
        some coefficients are not finite (memory: chunk x n_samples x S x 4 floats).

    Returns
    -------
    dict
        ``regime`` (W, S) int8 (0: no valid sample), ``identifiable`` (W, S) bool,
        ``agreement`` (W, S) share of replicates with the same regime (NaN
        without replicates), ``order_rms`` (W, S, 4) m/s.

    Notes
    -----
    The window statistics of every coefficient set (point estimate,
    replicates, order subsets) come from per-window Gram matrices computed
    once per record (:func:`window_grams`); they equal the direct evaluation
    of the order contributions at every sample up to rounding.
    """
    if not getattr(model, "model_sets", True):
        raise InputError("this varying-coefficient model was fitted with model_sets=False (to predict only): "
                         "it gives no window verdict; refit it with model_sets=True")
    theta_sets = [model.stacked_coefficients()[None],
                  model.stacked_coefficients(model.coef_bootstrap_, model.coef_yaw_bootstrap_),
                  model.stacked_coefficients(model.subset_coef_, model.subset_coef_yaw_)]
    used = np.zeros(theta_sets[0].shape[-3:-1], dtype=bool)  # (S, P): the entries the design rows reach
    L, n_in = model.coef_.shape[1], model.n_inputs(model.n_sections_)
    for k, M in enumerate(np.asarray(model.n_basis_, dtype=int)):
        used[k] = (np.arange(used.shape[1]) % L) < n_in * M  # entry j L + s M + m (basis_rows)
    if getattr(model, "penalty_coef_", None) is not None:
        theta_sets.append(model.stacked_coefficients(model.penalty_coef_, model.penalty_coef_yaw_))
    if not all(np.isfinite(th[..., used, :]).all() for th in theta_sets):
        return _direct_verdicts(model, record, window_start, window_end, chunk)
    stats = window_grams(model, record, window_start, window_end)
    R, c1 = gram_order_stats(stats, theta_sets[0])
    R, c1 = R[0], c1[0]
    nv = stats["n_valid"]
    point = np.where(nv > 0, regime_rule(np.nan_to_num(R), c1, model.tau), 0).astype(np.int8)
    B = model.coef_bootstrap_.shape[0]
    if B == 0:
        return {"regime": point, "identifiable": np.zeros(point.shape, dtype=bool),
                "agreement": np.full(point.shape, np.nan), "order_rms": R}
    Rb, c1b = gram_order_stats(stats, theta_sets[1])
    agree = (regime_rule(np.nan_to_num(Rb), c1b, model.tau) == point[None]).sum(axis=0) / B
    Rs, c1s = gram_order_stats(stats, theta_sets[2])
    pen = None
    if len(theta_sets) > 3:
        Rp, c1p = gram_order_stats(stats, theta_sets[3])
        pen = regime_rule(np.nan_to_num(Rp), c1p, model.tau)
    return _verdict(model, point, agree, R, regime_rule(np.nan_to_num(Rs), c1s, model.tau), pen)


def _verdict(model, point, agree, R, sub, pen=None) -> dict:
    """Combine the bootstrap agreement, the model set's regimes ``sub`` (n_subsets, W, S) and the penalty
    set's ``pen`` (n_penalties, W, S; None: no penalty set) into the verdict."""
    # Every plausible model of the confidence sets of order subsets and of penalties must give the same regime.
    plaus = model.subset_plausible_[:, None, :]
    set_agree = np.all((sub == point[None]) | ~plaus, axis=0)
    if pen is not None:
        set_agree &= np.all((pen == point[None]) | ~model.penalty_plausible_[:, None, :], axis=0)
    return {"regime": point, "identifiable": (agree >= model.agreement) & (point > 0) & set_agree,
            "agreement": agree, "order_rms": R, "model_set_agree": set_agree}


def _direct_verdicts(model, record, window_start, window_end, chunk) -> dict:
    """:func:`varying_window_verdicts` by evaluating every coefficient set at every sample (slow, NaN-safe)."""
    t, A = record.t, record.A
    R, c1, nv = window_order_stats(model.order_contributions(record), A, t, window_start, window_end)
    point = np.where(nv > 0, regime_rule(np.nan_to_num(R), c1, model.tau), 0).astype(np.int8)
    B = model.coef_bootstrap_.shape[0]
    if B == 0:
        return {"regime": point, "identifiable": np.zeros(point.shape, dtype=bool),
                "agreement": np.full(point.shape, np.nan), "order_rms": R}
    same = np.zeros(point.shape)
    for c0 in range(0, B, chunk):
        r = model.replicate_order_contributions(record, c0, c0 + chunk)
        Rb, c1b, _ = window_order_stats(r, A, t, window_start, window_end)
        same += (regime_rule(np.nan_to_num(Rb), c1b, model.tau) == point[None]).sum(axis=0)
    Rs, c1s, _ = window_order_stats(model.subset_order_contributions(record), A, t, window_start, window_end)
    pen, r = None, model.penalty_order_contributions(record)
    if r is not None:
        Rp, c1p, _ = window_order_stats(r, A, t, window_start, window_end)
        pen = regime_rule(np.nan_to_num(Rp), c1p, model.tau)
    return _verdict(model, point, same / B, R, regime_rule(np.nan_to_num(Rs), c1s, model.tau), pen)


def varying_summary(model: VaryingCoefficientSINDy) -> dict:
    """The varying model's ``campaign_summary`` (:func:`vivbench.models.model_summary`).

    Per equation the basis size, penalty, effective degrees of freedom and RSS (the splines
    themselves are in the model's own file); the attribute ``model`` names the class.
    """
    return {
        "variables": {
            "n_basis": (("equation",), model.n_basis_.astype(np.int32), {"units": "1", "long_name": "cubic B-splines per curve"}),
            "penalty": (("equation",), model.penalty_, {"units": "1", "long_name": "relative second-difference penalty"}),
            "edf": (("equation",), model.edf_, {"units": "1", "long_name": "effective degrees of freedom"}),
            "rss": (("equation",), model.rss_, {"units": "m2 s-2"}),
        },
        "coords": {},
        "attrs": {"n_samples": model.n_samples_, "n_blocks": model.n_blocks_, "model": type(model).__name__,
                  "note": "", "model_config_json": model.to_json(),
                  "wind_smoothing_s": float(model.fitted_wind_smoothing())},
        "verdicts": {"identifiable": "bootstrap agreement on the regime reaches the agreement level and the "
                                    "amplitude is above the noise floor"},
    }


def varying_description(regimes) -> dict:
    """The varying model's ``report_description`` (:func:`vivbench.models.model_description`).

    Parameters
    ----------
    regimes : xarray.Dataset, the model's ``campaign.regimes.nc``
    """
    smoothing = float(regimes.attrs.get("wind_smoothing_s", 0.0))
    text = ("One varying-coefficient model dA_k/dt = sum_i a_ki(U) A_k^i for the whole campaign, the curves "
            "penalised cubic B-splines in U (`vivbench.models.varying`, `vivbench pool --model varying`). A "
            "window's regime is the rule of docs/concepts.md (regimes) applied to this model's order contributions over the "
            "window's data; it counts as identifiable when at least "
            f"{json.loads(regimes.attrs['model_config_json'])['agreement']:.0%} of block-bootstrap replicates "
            "of the spline coefficients agree, every order subset in the model's confidence set "
            "(leave-one-event-out) gives the same regime, and the amplitude is above the noise floor. "
            f"The measured wind (and its yaw, a second covariate when the results store it: "
            f"{'yes' if int(regimes.attrs.get('wind_yaw', 0)) else 'no'}) is smoothed over "
            f"{smoothing:g} s (Gaussian sigma) before the fit and every evaluation on measured records; "
            "the truth's felt wind is used as it is. "
            f"B-splines per curve: {', '.join(str(int(k)) for k in regimes['n_basis'].values)}; "
            f"{int(regimes.attrs['n_samples'])} samples in {int(regimes.attrs['n_blocks'])} blocks; "
            f"coverage {float(regimes.attrs['coverage']):.3f}.")
    return {"text": text, "pool_options": " --model varying"}


def varying_settings_text(model) -> str:
    """One line on a fitted :class:`vivbench.models.VaryingCoefficientSINDy`'s settings (its ``settings_text``)."""
    return (f"VaryingCoefficientSINDy, cubic B-splines per curve {', '.join(str(int(k)) for k in model.n_basis_)} "
            f"({model.wind_weights_choice_} wind weights, {model.penalty_choice_} penalty, "
            f"yaw degree {model.yaw_degree_}, wind smoothing {model.fitted_wind_smoothing():g} s)")
