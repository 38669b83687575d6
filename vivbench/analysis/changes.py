"""Does the campaign model's assumption hold? Per-event residual checks and a change-point scan over events.

A campaign model (``PooledSINDy`` or ``VaryingCoefficientSINDy``) assumes that
dA/dt is one fixed function of (A, U) over the whole campaign. Changes the wind
does not carry (a damping drift, a retrofit between events) break it, and the
model then averages over them. This module measures that on the model's own
residual e = dA/dt - predict(record), event by event, with nothing from the
generator:

- ``event_residual_ratio``: the event's residual RMS over the median of the
  events' residual RMS (1: a typical event; much larger: the model does not
  describe this event).
- ``event_linear_offset`` delta_e (1/s): the least-squares coefficient of the
  residual on A over the event's samples (all sections pooled),
  delta_e = sum e A / sum A^2. A change of the net linear coefficient (the
  structural damping, the aerodynamic damping) that the model averaged over
  shows as delta_e != 0 (negative: the event is more damped than the model).
  Its standard error ``event_linear_offset_se`` is block-robust: the residual's
  correlation in time is handled by summing e A over ``block_s`` pieces of the
  event and using the spread of the pieces (a cluster-robust sandwich).
- heterogeneity: Cochran's Q = sum_e ((delta_e - mean) / se_e)^2 against
  chi-square with (events - 1) degrees of freedom (p-value
  ``change_heterogeneity_p``): small when the events' offsets differ by more
  than their noise (drift or a step, or a misfit that differs between events).
- change point: for every split of the event sequence (events in the order of
  their start times) the between-group sum of squares of delta_e,
  W1 W2 / (W1 + W2) (m1 - m2)^2 with weights W = sum A^2 (the offsets'
  information under a common noise level) and m the weighted means; the
  largest over splits is the statistic, its p-value
  (``change_p_value``) is the share of random orderings of the events that
  give at least as large a maximum (exchangeable events under "no ordered
  change", so a misfit that merely differs between events does not count),
  and the first event after the best split is ``change_event``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.stats import chi2

from vivbench.core.record import Record

__all__ = ["CHANGE_BLOCK_S", "CHANGE_LEVEL", "event_residual_checks", "change_point_scan"]

#: Block length of the offsets' robust standard errors, s.
CHANGE_BLOCK_S = 120.0
#: Level of the change-point test: a change is reported when its permutation p-value is below it.
CHANGE_LEVEL = 0.05


def event_residual_checks(model, records: Sequence[Record], *, block_s: float = CHANGE_BLOCK_S) -> dict:
    """Per-event residual scores of a fitted campaign model.

    Parameters
    ----------
    model : fitted model of the protocol with ``predict(record)`` (n, S) in m/s
    records : sequence of Record with dA (the records it was fitted on), E of them
    block_s : float, s
        Piece length of the offsets' block-robust standard errors.

    Returns
    -------
    dict of ndarray, shape (E,)
        ``residual_rms`` (m/s), ``residual_ratio`` (1), ``residual_rel_rms``
        (residual RMS over the RMS of dA/dt, 1), ``linear_offset`` and
        ``linear_offset_se`` (1/s), ``weight`` (sum of A^2 over the valid
        samples, m^2), ``n_valid`` (valid sample-sections); NaN where an event
        has no valid sample (or, for the standard error, fewer than two pieces).
    """
    E = len(records)
    out = {k: np.full(E, np.nan) for k in ("residual_rms", "residual_rel_rms", "linear_offset", "linear_offset_se",
                                           "weight", "n_valid")}
    for e, rec in enumerate(records):  # one prediction per event
        res = rec.dA - model.predict(rec)
        ok = np.isfinite(res) & np.isfinite(rec.A)
        n = int(ok.sum())
        out["n_valid"][e] = n
        if n == 0:
            continue
        r = np.where(ok, res, 0.0)
        A = np.where(ok, rec.A, 0.0)
        y = np.where(ok, rec.dA, 0.0)
        out["residual_rms"][e] = np.sqrt(np.sum(r**2) / n)
        out["residual_rel_rms"][e] = np.sqrt(np.sum(r**2) / max(np.sum(y**2), 1e-300))
        den_t, num_t = (A**2).sum(axis=1), (r * A).sum(axis=1)  # (n_samples,)
        den = den_t.sum()
        out["weight"][e] = den
        if den <= 0:
            continue
        delta = num_t.sum() / den
        out["linear_offset"][e] = delta
        piece = np.floor((rec.t - rec.t[0]) / block_s).astype(np.int64)
        _, piece = np.unique(piece, return_inverse=True)
        nb = int(piece.max()) + 1
        if nb >= 2:
            u = np.bincount(piece, weights=num_t - delta * den_t, minlength=nb)
            out["linear_offset_se"][e] = np.sqrt(nb / (nb - 1) * np.sum(u**2)) / den
    med = np.nanmedian(out["residual_rms"]) if np.isfinite(out["residual_rms"]).any() else np.nan
    out["residual_ratio"] = out["residual_rms"] / med
    return out


def _split_statistics(delta: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Between-group weighted sums of squares of every split, for one or many orderings.

    delta, w : shape (..., E); returns shape (..., E - 1), entry k for the split before event k + 1.
    """
    cw = np.cumsum(w, axis=-1)[..., :-1]
    cwd = np.cumsum(w * delta, axis=-1)[..., :-1]
    W = w.sum(axis=-1, keepdims=True)
    Wd = (w * delta).sum(axis=-1, keepdims=True)
    W2 = W - cw
    with np.errstate(invalid="ignore", divide="ignore"):
        m1, m2 = cwd / cw, (Wd - cwd) / W2
        s = cw * W2 / W * (m1 - m2) ** 2
    return np.where((cw > 0) & (W2 > 0), s, 0.0)


def change_point_scan(delta, se, weight, *, n_permutations: int = 999, seed: int = 0,
                      level: float = CHANGE_LEVEL) -> dict:
    """Heterogeneity of the events' linear offsets and the most likely single change over the event sequence.

    Parameters
    ----------
    delta : array_like, shape (E,), 1/s
        Per-event linear offsets (:func:`event_residual_checks`), events in time order.
    se : array_like, shape (E,), 1/s
        Their standard errors (used only by the heterogeneity test).
    weight : array_like, shape (E,), m^2
        Weights of the split statistic (sum of A^2). Events with a non-finite
        offset or weight take no part.
    n_permutations : int
        Random orderings of the events for the p-value.
    seed : int
    level : float
        A change is reported when the p-value is below it.

    Returns
    -------
    dict
        ``split_stat`` (E,) the statistic of the split just before each event
        (NaN for the first and for events taking no part), ``change_index``
        (index of the first event after the best split, -1 if none),
        ``p_value`` (NaN with fewer than 3 events), ``detected`` (bool),
        ``heterogeneity_q`` and ``heterogeneity_p`` (Cochran's Q over the
        events with a finite standard error, and its chi-square p-value).
    """
    delta, se, weight = (np.asarray(x, dtype=float) for x in (delta, se, weight))
    E = delta.size
    use = np.isfinite(delta) & np.isfinite(weight) & (weight > 0)
    idx = np.flatnonzero(use)
    out = {"split_stat": np.full(E, np.nan), "change_index": -1, "p_value": float("nan"), "detected": False,
           "heterogeneity_q": float("nan"), "heterogeneity_p": float("nan")}
    hs = use & np.isfinite(se) & (se > 0)
    if hs.sum() >= 2:
        wv = 1.0 / se[hs] ** 2
        mean = np.sum(wv * delta[hs]) / wv.sum()
        q = float(np.sum(wv * (delta[hs] - mean) ** 2))
        out["heterogeneity_q"], out["heterogeneity_p"] = q, float(chi2.sf(q, hs.sum() - 1))
    if idx.size < 3:
        return out
    d, w = delta[idx], weight[idx]
    s = _split_statistics(d, w)
    out["split_stat"][idx[1:]] = s
    best = int(np.argmax(s))
    rng = np.random.default_rng(seed)
    perm = np.argsort(rng.random((int(n_permutations), idx.size)), axis=1)
    null = _split_statistics(d[perm], w[perm]).max(axis=1)
    p = float((1 + np.sum(null >= s[best])) / (1 + int(n_permutations)))
    out.update(change_index=int(idx[best + 1]), p_value=p, detected=bool(p < level))
    return out
