"""Does the campaign model's assumption hold? Per-event residual checks and a change-point scan over events.

A campaign model (``PooledSINDy`` or ``VaryingCoefficientSINDy``) assumes that
dA/dt is one fixed function of (A, U) over the whole campaign. Changes the wind
does not carry (a damping drift, a retrofit between events) break it, and the
model then averages over them. This module tests that on the model's own
residual e = dA/dt - predict(record), event by event, with nothing from the
generator:

- ``event_residual_ratio``: the event's residual RMS over the median of the
  events' residual RMS (1: a typical event; much larger: the model does not
  describe this event).
- ``event_linear_offset`` delta_e (1/s): the least-squares coefficient of the
  residual on A over the event's samples (all sections pooled),
  delta_e = sum e A / sum A^2. A change of the net linear coefficient that the
  model averaged over shows as delta_e != 0 (negative: the event is more damped
  than the model). Its standard error ``event_linear_offset_se`` is
  block-robust: e A summed over ``block_s`` pieces of the event, the spread of
  the pieces (a cluster-robust sandwich).
- heterogeneity: Cochran's Q = sum_e ((delta_e - mean) / se_e)^2 against
  chi-square with (events - 1) degrees of freedom (``change_heterogeneity_p``).
- change point (:func:`change_point_scan`): for every split of the event
  sequence (events in the order of their start times) the between-group sum of
  squares of delta_e, W1 W2 / (W1 + W2) (m1 - m2)^2 with weights W = sum A^2
  and m the weighted means; the largest over splits is the statistic, its
  p-value (``change_p_value``) the share of random orderings of the events
  giving at least as large a maximum, and the first event after the best split
  is ``change_event``.

:func:`model_change_scan` refits a model that exposes per-event sufficient statistics
(``VaryingCoefficientSINDy.event_statistics``) separately to the events before and after
every split (at its fitted basis and relative penalty; at least ``min_events`` on each
side; each event's equations weighted by the inverse of its mean square of dA/dt,
floored at ``MISFIT_MS_FLOOR`` of the median event's). The statistic is the relative
drop of the penalised residual sum of squares, summed over the equations; its p-value
comes from orderings of the events, by default stratified (:func:`wind_strata`: events
move only among the ``STRATUM_SIZE`` events of most similar wind, so every split keeps
the observed mix of winds on each side). ``yaw_terms=False`` refits on the yaw-free
columns only, ``statistic="standardised"`` puts each split on its own null scale and
``"offset"`` fits one step of the linear coefficient (module ``change_offset``). It also
gives every event its leave-one-event-out misfit (held-out mean squared residual over
the median event's), flagged as "not predicted" when it is a robust outlier (above the
median by more than ``MISFIT_MADS`` scaled median absolute deviations on a log scale)
and at least ``MISFIT_FLOOR`` times the median; the ordered scan then runs over the
unflagged events only. The penalised systems are solved by Cholesky
(:func:`vivbench.regression.spd_solve`).

Per-event "not predicted" flags, each with its false-alarm control:

- ``event_after_change`` (``vivbench pool``): the events from the change the
  scan located, when its permutation p is below ``CHANGE_LEVEL``: a
  campaign-level control (the scan's), not a per-event one.
- :func:`change_relative_flags`: per event after the located change, its
  held-out linear offset against a random-effects model of the offsets of
  the events before it; Benjamini-Hochberg at ``FLAG_FDR``.
- :func:`offset_flags`: change-agnostic, each event's offset against a
  random-effects model of the other events' of its stratum
  (:func:`offset_strata`), the between-event variance integrated over its
  posterior; Benjamini-Hochberg at ``FLAG_FDR``. A block of three or more
  shifted events widens every member's reference and masks itself: it is no
  change detector.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.stats import chi2, false_discovery_control
from scipy.special import ndtr, ndtri, stdtr

from vivbench.analysis.change_offset import offset_gain, offset_parts
from vivbench.core.record import Record
from vivbench.regression.penalised import penalised_solve, penalty_scale, quadratic_error, spd_solve
from vivbench.regression.permutation import permutation_p_value, stratified_permutations

__all__ = ["CHANGE_BLOCK_S", "CHANGE_LEVEL", "CHANGE_STATISTICS", "FLAG_FDR", "MISFIT_FLOOR", "MISFIT_MADS",
           "STRATUM_SIZE", "UNEXPLAINED_REL_RMS",
           "change_point_scan", "change_relative_flags", "event_residual_checks", "model_change_scan",
           "offset_flags", "offset_strata", "statistics_change_scan", "stratified_permutations", "wind_strata"]

#: Block length of the offsets' robust standard errors, s.
CHANGE_BLOCK_S = 120.0
#: Level of the change-point test: a change is reported when its permutation p-value is below it.
CHANGE_LEVEL = 0.05
#: Statistics of the model change scan (:func:`model_change_scan`).
CHANGE_STATISTICS = ("max", "standardised", "offset")
#: Robust outlier rule of the events' held-out misfit: scaled MADs above the median (log scale).
MISFIT_MADS = 3.5
#: ... and at least this many times the median event's held-out mean squared residual.
MISFIT_FLOOR = 2.0
#: Smallest mean square of dA/dt an event is weighted by, relative to the median event's.
MISFIT_MS_FLOOR = 0.1
#: Events per stratum of the stratified null of the model change scan.
STRATUM_SIZE = 4
#: False-discovery rate of the per-event "not predicted" flags (Benjamini-Hochberg over the events tested).
FLAG_FDR = 0.05
#: Residual RMS over the RMS of dA/dt above which an event is "mostly unexplained" (sqrt(1/2): R^2 < 1/2).
UNEXPLAINED_REL_RMS = float(np.sqrt(0.5))


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
        samples, m^2), ``n_valid`` (valid sample-sections), ``n_pieces`` (the
        ``block_s`` pieces behind the standard error, which has ``n_pieces`` - 1
        degrees of freedom); NaN where an event has no valid sample (or, for the
        standard error, fewer than two pieces).
    """
    E = len(records)
    out = {k: np.full(E, np.nan) for k in ("residual_rms", "residual_rel_rms", "linear_offset", "linear_offset_se",
                                           "weight", "n_valid", "n_pieces")}
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
        out["n_pieces"][e] = nb
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
    p = permutation_p_value(null, s[best])
    out.update(change_index=int(idx[best + 1]), p_value=p, detected=bool(p < level))
    return out


def _reduced_sums(stats: list[dict]) -> list[dict]:
    """Per equation, every event's statistics on the kept columns as one row, for sums over sets of events.

    Row e of ``Z`` (E, q*q + q + 2) holds G_e (kept block, flattened), b_e (kept), yy_e and trace(G_e) (all
    columns: the penalty's scale is relative to it, as in ``penalised_rss``).
    """
    out = []
    for st in stats:
        idx = np.flatnonzero(st["keep"])
        q, E = idx.size, st["G"].shape[0]
        Gk = st["G"][:, idx[:, None], idx].reshape(E, q * q)
        Z = np.concatenate([Gk, st["b"][:, idx], st["yy"][:, None],
                            np.trace(st["G"], axis1=1, axis2=2)[:, None]], axis=1)
        Pk = st["P"][idx[:, None], idx]
        nz = np.flatnonzero(Pk)  # the penalty is banded: its few non-zeros are added, not a dense q x q
        out.append({"Z": Z, "q": q, "Pk": Pk, "Pk_nz": nz, "Pk_vals": Pk.ravel()[nz],
                    "trP": max(float(np.trace(st["P"])), 1e-300), "penalty": float(st["penalty"])})
    return out


def _rss_of_sums(S: np.ndarray, red: dict) -> np.ndarray:
    """``penalised_rss`` of summed rows of :func:`_reduced_sums`, S shape (N, q*q + q + 2); returns (N,).

    S is overwritten (its G block becomes the penalised system). With H = G + mu P + r I and H c = b,
    ||y - X c||^2 = yy - 2 c'b + c'G c = yy - c'b - mu c'P c - r c'c: no product with G is needed.
    """
    q = red["q"]
    H = S[:, :q * q].reshape(-1, q, q)
    b, yy = S[:, q * q:q * q + q], S[:, q * q + q]
    mu = red["penalty"] * S[:, q * q + q + 1] / red["trP"]
    diag = S[:, :q * q:q + 1]  # the diagonal of every G, a view
    ridge = 1e-10 * diag.sum(axis=1) / max(q, 1)
    nz = red.get("Pk_nz")
    if nz is None:
        H += mu[:, None, None] * red["Pk"]
    else:  # the same sums at the penalty's non-zeros only (no N x q x q temporary)
        S[:, nz] += mu[:, None] * red["Pk_vals"]
    diag += ridge[:, None]
    c = spd_solve(H, b)
    return yy - (c * b).sum(axis=1) - mu * ((c @ red["Pk"]) * c).sum(axis=1) - ridge * (c * c).sum(axis=1)


def _split_gain(reduced: list[dict], order: np.ndarray, splits: np.ndarray) -> np.ndarray:
    """Relative drop of the penalised RSS when fitting before/after each split, summed over equations.

    reduced: :func:`_reduced_sums`; order (R, E) event orderings; splits (K,) numbers of events before
    the split (increasing); returns (R, K). The sums before every split of every ordering are running
    sums of the events' rows in that ordering; the whole-campaign fit does not depend on the ordering and is solved once.
    """
    R, E = order.shape
    gain = np.zeros((R, splits.size))
    for red in reduced:
        total = red["Z"].sum(axis=0)
        full = float(_rss_of_sums(total[None].copy(), red)[0])
        # the sums before every split: each split's from the previous one's plus the events in between
        # (R E rows added in place, not a product of the (R K, E) 0/1 membership with the rows)
        Z = red["Z"]
        pre = np.empty((R, splits.size, Z.shape[1]))
        for r in range(R):  # orderings and splits, not samples: one row addition each
            o = order[r]
            pre[r, 0] = Z[o[:splits[0]]].sum(axis=0)
            for j in range(1, splits.size):
                between = o[splits[j - 1]:splits[j]]
                np.add(pre[r, j - 1], Z[between[0]] if between.size == 1 else Z[between].sum(axis=0), out=pre[r, j])
        pre = pre.reshape(R * splits.size, -1)
        post = total[None] - pre
        rss = _rss_of_sums(pre, red) + _rss_of_sums(post, red)
        gain += ((full - rss) / max(full, 1e-300)).reshape(R, splits.size)
    return gain


def model_change_scan(model, records: Sequence[Record], *, min_events: int = 3, n_permutations: int = 99,
                      seed: int = 0, level: float = CHANGE_LEVEL, chunk: int = 8, null: str = "stratified",
                      stratum_size: int = STRATUM_SIZE, statistic: str = "max",
                      yaw_terms: bool = True) -> dict:
    """The most likely single change of the campaign model over the event sequence, and per-event misfit flags.

    Parameters
    ----------
    model : fitted model with ``event_statistics(records)`` (``VaryingCoefficientSINDy``)
    records : sequence of Record, the events in time order (the records the model was fitted on)
    min_events : int
        Fewest events on each side of a split.
    n_permutations : int
        Random orderings of the events for the p-value.
    seed : int
    level : float
        A change is reported when the p-value is below it.
    chunk : int
        Orderings refitted together (memory: chunk x events x p^2 floats per equation).
    null : {"stratified", "permutation"}
        Orderings of the null distribution: ``"stratified"`` (default) permutes
        events only within strata of ``stratum_size`` events of similar wind
        (:func:`wind_strata`), so every split of every ordering keeps the
        observed mix of wind regimes on each side; ``"permutation"`` permutes
        all events (exact only if all events are exchangeable, which a
        campaign whose wind regimes follow a pattern in time is not).
    stratum_size : int
        Events per stratum (the last stratum takes the remainder).
    statistic : {"max", "standardised", "offset"}
        ``"max"`` (default): the largest split gain over splits.
        ``"standardised"``: the largest over splits of the gain standardised
        by the null orderings' mean and standard deviation at that split
        (every split judged on its own null scale; same orderings and cost).
        ``"offset"``: the largest over splits of the relative drop of the
        whole campaign's penalised RSS when the events after the split get
        their own shift of the linear coefficient (one parameter per
        equation, the form of a step of structural damping, -2 pi f
        delta zeta), instead of a refit of every curve on each side.
    yaw_terms : bool
        True (default): the split refits use every column of the model,
        its yaw terms included. False: the split refits (observed and null)
        use only the yaw-free columns (j = 0), at the model's basis and
        penalty: the scan then asks whether the function of (A, U) changes,
        not its yaw terms, which each side's few events determine poorly.
        The misfit flags always use the whole model.

    Returns
    -------
    dict
        ``split_gain`` (E,) relative RSS drop of the split just before each
        event (NaN where not allowed), ``change_index`` (first event after the
        best split, -1 without one), ``p_value``, ``detected`` (bool),
        ``misfit`` (E,) leave-one-event-out mean squared residual over the
        median event's, ``misfit_flag`` (E,) bool (robust outliers, see the
        module docstring), with ``null="stratified"`` ``strata`` (E,) the
        stratum of each event (-1: not scanned).
    """
    return statistics_change_scan(model.event_statistics(records), min_events=min_events,
                                  n_permutations=n_permutations, seed=seed, level=level, chunk=chunk, null=null,
                                  stratum_size=stratum_size, statistic=statistic, yaw_terms=yaw_terms)


def statistics_change_scan(stats: list[dict], *, min_events: int = 3, n_permutations: int = 99, seed: int = 0,
                           level: float = CHANGE_LEVEL, chunk: int = 8, null: str = "stratified",
                           stratum_size: int = STRATUM_SIZE, statistic: str = "max",
                           yaw_terms: bool = True) -> dict:
    """:func:`model_change_scan` on per-event statistics (``VaryingCoefficientSINDy.event_statistics``).

    Parameters
    ----------
    stats : list of dict, one per equation
        ``G`` (E, p, p), ``b`` (E, p), ``yy`` (E,), ``n`` (E,), ``P``, ``penalty``, ``keep``
        (the events in time order; a subset of events is a slice of every array).
    min_events, n_permutations, seed, level, chunk, null, stratum_size, statistic, yaw_terms
        As :func:`model_change_scan`.

    Returns
    -------
    dict
        As :func:`model_change_scan`.
    """
    if null not in ("stratified", "permutation"):
        raise ValueError(f"null must be 'stratified' or 'permutation'; got {null!r}")
    if statistic not in CHANGE_STATISTICS:
        raise ValueError(f"statistic must be one of {', '.join(CHANGE_STATISTICS)}; got {statistic!r}")
    if int(stratum_size) < 2:
        raise ValueError(f"stratum_size must be an integer >= 2; got {stratum_size!r}")
    stats = _equal_event_weights(stats)
    E = int(stats[0]["n"].size)
    out = {"split_gain": np.full(E, np.nan), "change_index": -1, "p_value": float("nan"), "detected": False}
    # Leave-one-event-out misfit of every event (all equations pooled).
    loo, cnt = np.zeros(E), np.zeros(E)
    for st in stats:
        loo += _held_out_error(st["G"], st["b"], st["yy"], st)
        cnt += st["n"]
    with np.errstate(invalid="ignore", divide="ignore"):
        mse = np.where(cnt > 0, loo / cnt, np.nan)
        misfit = mse / np.nanmedian(mse)
        logm = np.log(misfit)
    mad = 1.4826 * np.nanmedian(np.abs(logm - np.nanmedian(logm)))
    out["misfit"] = misfit
    out["misfit_flag"] = (np.isfinite(logm) & (logm > np.nanmedian(logm) + MISFIT_MADS * max(mad, 1e-12))
                          & (misfit >= MISFIT_FLOOR))
    # The ordered scan runs over the events the others predict: one event far off (flagged) would
    # otherwise pull the split towards itself.
    use = np.flatnonzero(~out["misfit_flag"] & np.isfinite(misfit))
    stats = [{**st, "G": st["G"][use], "b": st["b"][use], "yy": st["yy"][use]} for st in stats]
    if not yaw_terms:
        stats = [{**st, "keep": st["keep"] & _yaw_free_columns(st)} for st in stats]
    n_use = use.size
    splits = np.arange(max(int(min_events), 1), n_use - max(int(min_events), 1) + 1)
    if splits.size == 0:
        return out
    if statistic == "offset":
        reduced = offset_parts(stats)

        def split_gain(order):
            return offset_gain(reduced, order, splits)
    else:
        reduced = _reduced_sums(stats)

        def split_gain(order):
            return _split_gain(reduced, order, splits)
    gain = split_gain(np.arange(n_use)[None])[0]
    out["split_gain"][use[splits]] = gain
    best = int(np.argmax(gain))
    rng = np.random.default_rng(seed)
    if null == "stratified":
        strata = wind_strata(stats, stratum_size)
        out["strata"] = np.full(E, -1)
        out["strata"][use] = strata
        perms = stratified_permutations(strata, int(n_permutations), rng)
    else:
        perms = np.argsort(rng.random((int(n_permutations), n_use)), axis=1)
    null_gain = (np.concatenate([split_gain(perms[i:i + chunk])
                                 for i in range(0, perms.shape[0], chunk)]) if n_permutations
                 else np.zeros((0, splits.size)))
    observed = gain
    if statistic == "standardised" and null_gain.shape[0] > 1:
        # Every split on its own null scale: splits of unequal coverage have unequal null gains.
        mu, sd = null_gain.mean(axis=0), null_gain.std(axis=0)
        sd = np.maximum(sd, 1e-12 * max(float(np.abs(mu).max()), 1e-300))
        observed, null_gain = (gain - mu) / sd, (null_gain - mu) / sd
        best = int(np.argmax(observed))
    p = permutation_p_value(null_gain.max(axis=1), observed[best])
    out.update(change_index=int(use[splits[best]]), p_value=p, detected=bool(p < level))
    return out


def _yaw_free_columns(st: dict) -> np.ndarray:
    """Columns of the design without a yaw factor (j = 0), shape (p,) bool.

    The columns are ordered (i, j, s, m): amplitude power i (4), yaw power j (J + 1), wind input s
    (``n_inputs``, 1 unless the model sums every section's wind), basis m (``n_basis``).
    """
    M, p = int(st["n_basis"]) * int(st.get("n_inputs", 1)), st["G"].shape[-1]
    J1 = p // (4 * M)
    if 4 * M * J1 != p:
        raise ValueError(f"statistics of {p} columns are not 4 x (J + 1) x {M} (n_inputs x n_basis)")
    return (np.arange(p) // M) % J1 == 0


def _equal_event_weights(stats: list[dict]) -> list[dict]:
    """Copies of the per-event statistics with every event weighted alike (the caller's arrays stay as they are).

    Every event's statistics over its own mean square of dA/dt, so that one
    event with large dynamics (a high plateau extrapolated in A) cannot
    dominate; but at least ``MISFIT_MS_FLOOR`` of the median event's, so that
    an event with almost no dynamics is not judged on the relative error of
    near-zero values.
    """
    out = []
    for st in stats:
        with np.errstate(invalid="ignore", divide="ignore"):
            ms = np.where(st["n"] > 0, st["yy"] / np.maximum(st["n"], 1), np.nan)
            floor = MISFIT_MS_FLOOR * np.nanmedian(ms) if np.isfinite(ms).any() else 0.0
            w = np.where(st["n"] > 0, 1.0 / np.maximum(ms, floor), 0.0)
            w = np.where(np.isfinite(w), w, 0.0)
        out.append({**st, "G": st["G"] * w[:, None, None], "b": st["b"] * w[:, None], "yy": st["yy"] * w})
    return out


def wind_strata(stats: list[dict], size: int = STRATUM_SIZE) -> np.ndarray:
    """Strata of events of similar wind for the stratified null, shape (E,) int.

    Each event's occupation of the wind basis (the row sums of the constant
    term's block of X_e^T X_e: the B-splines sum to one, so entry m counts the
    event's samples near the basis function m) gives its mean position on the
    wind axis; the events are ranked by it and cut into groups of ``size``
    consecutive ranks (the last group takes fewer than ``size`` / 2 left over).

    Parameters
    ----------
    stats : list of dict, per equation (``G`` (E, p, p) and ``n_basis``, the first equation's used)
    size : int, events per stratum
    """
    st = stats[0]
    M = int(st["n_basis"])
    L = M * int(st.get("n_inputs", 1))  # with several wind inputs: every section's wind, averaged
    occ = np.clip(st["G"][:, :L, :L].sum(axis=2), 0.0, None)  # (E, L)
    with np.errstate(invalid="ignore", divide="ignore"):
        centre = (occ * (np.arange(L) % M)).sum(axis=1) / occ.sum(axis=1)
    rank = np.empty(centre.size, dtype=np.int64)
    rank[np.argsort(np.nan_to_num(centre, nan=-1.0), kind="stable")] = np.arange(centre.size)
    n_full = max(int(np.round(centre.size / size)), 1)
    return np.minimum(rank // size, n_full - 1)


def _subset_coefficients(G, b, st, train=None) -> np.ndarray:
    """Each event's coefficients fitted to the ``train`` events other than itself, shape (E, q) (kept columns).

    ``train`` (E,) bool, default all events (leave-one-event-out); standardised units.
    """
    idx = np.flatnonzero(st["keep"])
    train = np.ones(G.shape[0], dtype=bool) if train is None else np.asarray(train, dtype=bool)
    tG, tb = G[train].sum(axis=0), b[train].sum(axis=0)
    Gk = (tG[None] - G * train[:, None, None])[:, idx[:, None], idx]
    bk = (tb[None] - b * train[:, None])[:, idx]
    # the penalty's scale from the kept block of G
    return penalised_solve(Gk, bk, st["P"][idx[:, None], idx], st["penalty"] * penalty_scale(Gk, st["P"]))


def _held_out_error(G, b, yy, st, train=None) -> np.ndarray:
    """Each event's squared error under the model fitted to the ``train`` events other than itself, shape (E,).

    ``train`` (E,) bool, default all events (leave-one-event-out); standardised units.
    """
    idx = np.flatnonzero(st["keep"])
    c = _subset_coefficients(G, b, st, train)
    return quadratic_error(c, G[:, idx[:, None], idx], b[:, idx], yy)

def _benjamini_hochberg(p: np.ndarray, fdr: float) -> np.ndarray:
    """Rejections of the Benjamini-Hochberg step-up rule at ``fdr`` over the finite p-values, shape of p, bool."""
    p = np.asarray(p, dtype=float)
    out = np.zeros(p.shape, dtype=bool)
    ok = np.flatnonzero(np.isfinite(p))
    if ok.size:
        out[ok] = false_discovery_control(p[ok], method="bh") <= fdr
    return out


def offset_strata(residual_rel_rms, *, threshold: float = UNEXPLAINED_REL_RMS) -> np.ndarray:
    """Which events' dA/dt the campaign model mostly does not explain: the strata of :func:`offset_flags`.

    Parameters
    ----------
    residual_rel_rms : array_like, shape (E,), 1
        The events' residual RMS over their RMS of dA/dt (:func:`event_residual_checks`).
    threshold : float
        Above it (default sqrt(1/2): the model explains less than half of the
        event's mean square of dA/dt) the event is in stratum 1.

    Returns
    -------
    ndarray of int8, shape (E,)
        1: mostly unexplained, 0: otherwise (also where the ratio is NaN).
    """
    rel = np.asarray(residual_rel_rms, dtype=float)
    if not 0.0 < threshold:
        raise ValueError(f"threshold must be positive (a ratio of RMS values); got {threshold}")
    with np.errstate(invalid="ignore"):
        return (rel > threshold).astype(np.int8)


def offset_flags(delta, se, *, n_pieces=None, stratum=None, between: str = "posterior",
                 fdr: float = FLAG_FDR) -> dict:
    """Events whose linear offset departs from the other events' of their stratum by more than the events' spread.

    A change-agnostic "not predicted" flag: each event's offset delta_e
    (:func:`event_residual_checks`) is compared with a normal random-effects
    model of the *other* events' offsets in its stratum (between-event
    variance tau^2, so the usual spread of a misspecified model's offsets is
    part of the null, calibrated on the events themselves); two-sided
    p-values, Benjamini-Hochberg over all tested events at ``fdr``.

    ``between="posterior"`` (default): the p-value is the posterior predictive
    one of a new event, tau integrated over its posterior given the other
    events (uniform prior on tau >= 0, flat prior on the mean, which is
    integrated out: Gelman et al., *Bayesian Data Analysis*, sec. 5.4-5.5),
    p_e = int p(tau | others) P(|D| >= |delta_e - mu(tau)|) dtau with D normal
    of variance se_e^2 + tau^2 + var(mu | tau). ``"dersimonian_laird"``
    (the former rule): tau^2 fixed at its DerSimonian-Laird moment estimate.
    Why the posterior: with 20 events tau is poorly known, and its point
    estimate is often near 0 when the others' standard errors are large;
    an event whose own se_e is small (a brief event of few pieces) is then
    judged against se_e alone and flagged for an ordinary offset. Integrating over tau is a scale mixture
    of normals, heavier-tailed exactly where tau is uncertain, with no tuning
    constant (a Student-t between-event model would need its degrees of
    freedom, which 20 events cannot estimate).

    ``stratum``: events are judged only against the others of their own
    stratum (:func:`offset_strata`: whether the model explains at least
    half of the event's dA/dt). Why: events whose wind is outside the lock-in
    range have amplitudes of a few mm, where dA/dt is mostly buffeting that
    the deterministic model leaves in its residual (residual RMS 0.78-1.00 of
    dA/dt's on seeds 41-48 and bridge B, against at most 0.62 for every other
    event); their offsets spread several times wider than the others' and
    were the remaining false flags. A stratum of fewer than 4 events (3
    others) gives its events no test (p NaN: not assessable).

    With ``n_pieces`` each p-value is Student-t with the Welch-Satterthwaite
    degrees of freedom (se_e^2 + rest)^2 / (se_e^4 / (n_pieces_e - 1)), the
    other events' terms taken as known (:func:`_satterthwaite_p`): se_e comes
    from the event's own few pieces; without, normal.

    Parameters
    ----------
    delta, se : array_like, shape (E,), 1/s
    n_pieces : array_like, shape (E,), optional
        Pieces behind each se (``event_residual_checks``' ``n_pieces``).
    stratum : array_like of int, shape (E,), optional (default: one stratum)
    between : {"posterior", "dersimonian_laird"}
    fdr : float, false-discovery rate of the flags

    Returns
    -------
    dict
        ``z`` (E,): the signed normal quantile of the p-value (equal to the
        random-effects z-score with ``"dersimonian_laird"`` and no
        ``n_pieces``), ``p`` (E,) (NaN where an event has no finite offset and
        standard error or its stratum fewer than 3 others that have),
        ``flag`` (E,) bool.
    """
    if between not in _BETWEEN:
        raise ValueError(f"between must be one of {sorted(_BETWEEN)}; got {between!r}")
    delta, se = np.asarray(delta, dtype=float), np.asarray(se, dtype=float)
    stratum = np.zeros(delta.size, dtype=np.int64) if stratum is None else np.asarray(stratum)
    if stratum.shape != delta.shape:
        raise ValueError(f"stratum has shape {stratum.shape}; the offsets {delta.shape}")
    npc = None if n_pieces is None else np.asarray(n_pieces, dtype=float)
    ok = np.isfinite(delta) & np.isfinite(se) & (se > 0)
    z, p = np.full(delta.size, np.nan), np.full(delta.size, np.nan)
    for e in np.flatnonzero(ok):  # one random-effects fit per event (events, not samples)
        o = ok & (stratum == stratum[e])
        o[e] = False
        z[e], p[e] = _BETWEEN[between](delta[e], se[e], delta[o], se[o], None if npc is None else npc[e])
    return {"z": z, "p": p, "flag": _benjamini_hochberg(p, fdr)}


def _satterthwaite_p(z, se, rest, n_pieces) -> np.ndarray:
    """Two-sided p-values of z = d / sqrt(se^2 + rest): Student-t with Welch-Satterthwaite degrees of freedom.

    se^2 is estimated from ``n_pieces`` - 1 degrees of freedom, ``rest`` (the
    reference's variance terms) is taken as known; ``n_pieces`` None (or < 2): normal.
    """
    z = np.asarray(z, dtype=float)
    if n_pieces is None:
        return 2.0 * ndtr(-np.abs(z))
    nu = np.asarray(n_pieces, dtype=float) - 1.0
    v = np.asarray(se, dtype=float) ** 2
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        df = (v + rest) ** 2 / (v**2 / nu)
    df = np.where(np.isfinite(df) & (nu >= 1), df, np.inf)
    return 2.0 * stdtr(df, -np.abs(z))  # the special function: the distribution object costs 0.1 ms a call


def _signed_quantile(p: float, sign: float) -> float:
    """The z-score whose two-sided normal p-value is p, with the offset's sign."""
    return float(-np.sign(sign) * ndtri(p / 2.0)) if np.isfinite(p) else float("nan")


def _dl_p(d: float, s: float, ref: np.ndarray, ref_se: np.ndarray, n_pieces) -> tuple[float, float]:
    """z and p of d against the DerSimonian-Laird random-effects model of ``ref`` (NaN with fewer than 3)."""
    z, rest = _random_effects_z(d, s, ref, ref_se)
    if not np.isfinite(z):
        return float("nan"), float("nan")
    p = float(_satterthwaite_p(z, s, rest, n_pieces))
    return (z if n_pieces is None else _signed_quantile(p, z)), p


def _posterior_p(d: float, s: float, ref: np.ndarray, ref_se: np.ndarray, n_pieces,
                 n_grid: int = 128) -> tuple[float, float]:
    """z and posterior predictive p of d against a normal random-effects model of ``ref``, tau integrated out.

    Uniform prior on tau on a grid of ``n_grid`` points from 0 to three times
    the span of the reference (its largest distance from the median plus
    its largest standard error; the posterior decays as tau^-(J-1) beyond
    it); flat prior on the mean, integrated out analytically given tau.
    NaN with fewer than 3 reference events.
    """
    if ref.size < 3:
        return float("nan"), float("nan")
    v = ref_se**2
    span = np.max(np.abs(ref - np.median(ref))) + np.sqrt(np.max(v))
    tau = np.linspace(0.0, 3.0 * span, n_grid)
    w = 1.0 / (v[None, :] + tau[:, None] ** 2)  # (grid, J)
    var_mu = 1.0 / w.sum(axis=1)
    mu = var_mu * (w @ ref)
    log_post = 0.5 * (np.log(var_mu) + np.log(w).sum(axis=1) - (w * (ref[None, :] - mu[:, None]) ** 2).sum(axis=1))
    post = np.exp(log_post - log_post.max())
    post /= post.sum()
    rest = tau**2 + var_mu
    zg = (d - mu) / np.sqrt(s**2 + rest)
    pg = _satterthwaite_p(zg, np.full(tau.size, s), rest, None if n_pieces is None else np.full(tau.size, n_pieces))
    p = float(np.clip(post @ pg, 0.0, 1.0))
    return _signed_quantile(p, d - post @ mu), p


def _random_effects_z(d: float, s: float, ref: np.ndarray, ref_se: np.ndarray) -> tuple[float, float]:
    """z-score of the estimate d (standard error s) against the random-effects model of ``ref``.

    DerSimonian-Laird between-event variance tau^2 of the reference estimates; NaN with fewer than 3.
    Returns z and the reference's share of its variance, tau^2 + var(mu) (the rest is s^2).
    """
    if ref.size < 3:
        return float("nan"), float("nan")
    w = 1.0 / ref_se**2
    mu_fe = np.sum(w * ref) / w.sum()
    q = np.sum(w * (ref - mu_fe) ** 2)
    tau2 = max(0.0, (q - (ref.size - 1)) / (w.sum() - np.sum(w**2) / w.sum()))
    wr = 1.0 / (ref_se**2 + tau2)
    mu = np.sum(wr * ref) / wr.sum()
    rest = tau2 + 1.0 / wr.sum()
    return float((d - mu) / np.sqrt(s**2 + rest)), float(rest)


_BETWEEN = {"posterior": _posterior_p, "dersimonian_laird": _dl_p}


def change_relative_flags(stats: list[dict], change_index: int, se, a_ref, y_scale, *, n_pieces=None,
                          between: str = "dersimonian_laird", fdr: float = FLAG_FDR) -> dict:
    """Events from a located change on whose held-out linear offset departs from the events' before it.

    Every event gets its held-out linear offset delta_e: the least-squares
    coefficient of its dA/dt residual on A (all sections pooled, as
    :func:`event_residual_checks`) under the model refitted to all *other*
    events (at the fitted basis and penalty, every event weighted alike as in
    the scan). Why all others and not only the events before the change: a
    model of the few events before it extrapolates to the winds and
    amplitudes of the later events and gives them large offsets without any
    change; the model of all other events covers every event's (A, U) as
    well as the campaign allows. Under a step of the linear coefficient by
    D, that model averages over both sides, and the events before and after
    the step get offsets about D apart. The null is calibrated on the events
    before the change: a random-effects model of their held-out offsets
    (DerSimonian-Laird tau^2, so their own spread counts); an event after the
    change gets the two-sided normal p-value of its offset's z-score against
    it, with its block-robust standard error ``se`` (of the campaign model's
    residual); Benjamini-Hochberg over the events from the change on, at
    ``fdr``. So the flags are defined only relative to the located change,
    and they see a change of the linear coefficient (structural or
    aerodynamic damping) best.

    ``between`` as in :func:`offset_flags`; the default stays the
    DerSimonian-Laird point estimate here, because the reference is only the
    few events before the change, whose tau the posterior leaves very
    uncertain, so that it would rarely flag a later event. These flags
    inherit the scan's campaign-level control.

    Parameters
    ----------
    stats : list of dict, per equation (``VaryingCoefficientSINDy.event_statistics``), events in time order
    change_index : int, the first event after the change (e.g. ``model_change_scan``'s ``change_index``;
        outside 3..E-1: no test)
    se : array_like, shape (E,), 1/s, the offsets' standard errors (:func:`event_residual_checks`)
    a_ref, y_scale : array_like, shape (S,), m and m/s: the model's per-equation scales of A and dA/dt
        (``VaryingCoefficientSINDy.a_ref_``, ``y_scale_``), to give the offsets in 1/s
    n_pieces : array_like, shape (E,), optional: Student-t p-values as in :func:`offset_flags`
    between : {"dersimonian_laird", "posterior"}, the between-event variance of the reference (see above)
    fdr : float

    Returns
    -------
    dict
        ``offset_held_out`` (E,) 1/s, ``z`` and ``p`` (E,) (NaN before the change and everywhere
        without a test), ``flag`` (E,) bool.
    """
    E = int(stats[0]["n"].size)
    k = int(change_index)
    out = {name: np.full(E, np.nan) for name in ("offset_held_out", "z", "p")}
    out["flag"] = np.zeros(E, dtype=bool)
    if not 3 <= k < E:
        return out
    se = np.asarray(se, dtype=float)
    num, den = np.zeros(E), np.zeros(E)
    for st, wst, ar, ys in zip(stats, _equal_event_weights(stats), np.asarray(a_ref, float),
                               np.asarray(y_scale, float)):
        idx = np.flatnonzero(st["keep"])
        c = _subset_coefficients(wst["G"], wst["b"], wst)  # (E, q), each event held out
        Ge, be = st["G"][:, idx[:, None], idx], st["b"][:, idx]
        # Columns summing to A / a_ref: order 1, yaw power 0, all M B-splines (layout (i, j, s, m)); with
        # n_inputs wind inputs they sum to n_inputs A / a_ref.
        n_in = int(st.get("n_inputs", 1))
        lin = np.zeros(st["G"].shape[1])
        lin[st["G"].shape[1] // 4:st["G"].shape[1] // 4 + n_in * int(st["n_basis"])] = 1.0 / n_in
        s_ = lin[idx]
        num += (be - np.einsum("epq,eq->ep", Ge, c)) @ s_ * ar * ys  # sum of A e, m^2/s
        den += np.einsum("p,epq,q->e", s_, Ge, s_) * ar**2  # sum of A^2, m^2
    with np.errstate(invalid="ignore", divide="ignore"):
        delta = np.where(den > 0, num / den, np.nan)
    out["offset_held_out"] = delta
    ok = np.isfinite(delta) & np.isfinite(se) & (se > 0)
    before = np.arange(E) < k
    ref = before & ok
    if between not in _BETWEEN:
        raise ValueError(f"between must be one of {sorted(_BETWEEN)}; got {between!r}")
    npc = None if n_pieces is None else np.asarray(n_pieces, dtype=float)
    for e in np.flatnonzero(~before & ok):  # events after the change, one test each
        out["z"][e], out["p"][e] = _BETWEEN[between](delta[e], se[e], delta[ref], se[ref],
                                                     None if npc is None else npc[e])
    out["flag"] = _benjamini_hochberg(out["p"], fdr)
    return out
