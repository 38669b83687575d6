"""Held-out evidence of candidate campaign models: folds of whole events, held-out losses, the confidence set.

The pieces of :class:`vivbench.analysis.ModelSelection` that fit and score candidates
(the selection's module docstring says what they compute and why):
:func:`event_folds` deals the events to folds, :func:`held_out_losses` scores a fitted
model on events it was not fitted on (their simulations batched), :func:`confidence_set` gives the confidence set
(:func:`one_se_set` and :func:`rank_p_values` its two tests),
and :func:`held_out_task` and :func:`fit_task` are the picklable tasks that fit the
candidates, several at once where they share their costly part (:func:`shared_groups`:
models that differ only in parameters of their ``final_params``, fitted by their
``fit_variants``).
"""

from __future__ import annotations

import dataclasses

import copy
from collections.abc import Sequence

import numpy as np

from vivbench.core.errors import InputError
from vivbench.core.record import Record
from vivbench.models.model_input import measured_input
from vivbench.models.protocol import simulate_many
from vivbench.preprocess.runs import mask_runs
from vivbench.analysis.wind_local import wind_bins_of

__all__ = ["CRITERIA", "RANK_LEVEL", "confidence_set", "dynamics_by_wind", "event_folds", "held_out_loss", "held_out_losses", "one_se_set",
           "rank_p_values", "shared_groups", "variant_params", "fit_group",
           "held_out_task", "fit_task"]

#: Held-out criteria: simulated envelope (output error) or dA/dt (equation error).
CRITERIA = ("output", "derivative")


def event_folds(n_events: int, n_folds: int, seed: int = 0) -> np.ndarray:
    """Fold of every event, shape (n_events,): events dealt in a seeded random order.

    With fewer events than ``n_folds`` every event is its own fold (leave one event out).
    """
    if n_events < 2:
        raise InputError(f"held-out selection needs at least 2 events; got {n_events}")
    order = np.random.default_rng(seed).permutation(n_events)
    k = min(int(n_folds), n_events)
    fold = np.empty(n_events, dtype=int)
    fold[order] = np.arange(n_events) % k
    return fold


def _decimated(record: Record, step_s: float) -> Record:
    """Every k-th sample of the record, k = round(step_s / its median step) (the record itself when k <= 1)."""
    if record.n_samples < 2:
        return record
    k = int(round(step_s / float(np.median(np.diff(record.t)))))
    if k <= 1:
        return record
    sl = slice(None, None, k)
    pick = (lambda x: None if x is None else np.asarray(x)[sl])
    return dataclasses.replace(record, t=record.t[sl], A=record.A[sl], U=record.U[sl], dA=record.dA[sl],
                               yaw=pick(record.yaw))


def held_out_loss(model, record: Record, criterion: str = "output", min_samples: int = 20,
                  step_s: float = 1.0) -> float:
    """Squared prediction error of a fitted model on one record it was not fitted on (:func:`held_out_losses`).

    Returns
    -------
    float, m^2 (output) or m^2/s^2 (derivative); 0 when the record has no valid run
    """
    return float(held_out_losses(model, [record], criterion, min_samples, step_s)[0])


def held_out_losses(model, records: Sequence[Record], criterion: str = "output", min_samples: int = 20,
                    step_s: float = 1.0, wind_edges: np.ndarray | None = None) -> np.ndarray:
    """Squared prediction error of a fitted model on each record it was not fitted on (:mod:`vivbench.analysis.selection`).

    The output error's runs of every record are simulated together (:func:`vivbench.models.simulate_many`).

    Parameters
    ----------
    model : fitted model of the protocol
    records : sequence of Record, measured (their wind is transformed as the model's was at fit)
    criterion : "output" (simulated envelope) or "derivative" (dA/dt)
    min_samples : int, runs shorter than this (on the simulation's grid) are not simulated
    step_s : float, s
        Time step of the output error's simulation and sum: the record's wind, once transformed
        as at fit, is taken every ``step_s`` (the envelope and the smoothed wind vary over tens
        of seconds, so the integration's step does not limit the loss).
    wind_edges : ndarray, shape (B + 1,), m/s, optional
        Increasing edges of wind bins: each sample's squared error (per section) is then summed into
        the bin of that section's wind as the model sees it (below the first edge: the first bin; above
        the last: the last).

    Returns
    -------
    ndarray, shape (n_records,), or (n_records, B) with ``wind_edges``; m^2 (output) or m^2/s^2
    (derivative); 0 for a record with no valid run
    """
    edges = None if wind_edges is None else np.asarray(wind_edges, dtype=float)
    B = 1 if edges is None else edges.size - 1
    losses = np.zeros((len(records), B))

    def add(e: int, err2: np.ndarray, U: np.ndarray) -> None:
        if edges is None:
            losses[e, 0] += float(np.sum(err2))
        else:  # a sample without wind has no error counted (derivative) or is not simulated (output)
            b = np.maximum(wind_bins_of(U, edges), 0)
            losses[e] += np.bincount(b.ravel(), weights=err2.ravel(), minlength=B)

    runs, owners = [], []
    for e, record in enumerate(records):
        rec = measured_input(model, record)
        if criterion == "derivative":
            ok = np.isfinite(rec.A).all(axis=1) & np.isfinite(rec.U).all(axis=1)
            f = np.asarray(model.predict(rec), dtype=float)
            good = ok[:, None] & np.isfinite(rec.dA)
            # a sample the model does not predict counts as missed by the whole measured dA/dt
            err = np.where(good, np.where(np.isfinite(f), f - rec.dA, rec.dA), 0.0)
            add(e, err**2, rec.U)
            continue
        rec = _decimated(rec, step_s)
        ok = np.isfinite(rec.A).all(axis=1) & np.isfinite(rec.U).all(axis=1)
        peak = float(np.nanmax(np.abs(rec.A))) if np.isfinite(rec.A).any() else 0.0
        for run in mask_runs(ok, rec.t):
            if run.stop - run.start >= min_samples:
                runs.append((rec, float(rec.t[run.start]), float(rec.t[run.stop - 1]), None))
                owners.append((e, peak, rec))
    for (e, peak, rec), sim in zip(owners, simulate_many(model, runs)):
        d = np.asarray(sim.A_sim, dtype=float) - np.asarray(sim.A_meas, dtype=float)
        d = np.where(np.isfinite(d), d, peak)
        U = None if edges is None else rec.U[np.clip(np.searchsorted(rec.t, sim.t), 0, rec.n_samples - 1)]
        add(e, d**2, U)
    return losses[:, 0] if edges is None else losses


def one_se_set(losses: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The confidence set of candidates by the one-standard-error rule over events.

    Parameters
    ----------
    losses : ndarray, shape (C, E)
        Held-out loss of every candidate on every event.

    Returns
    -------
    in_set : ndarray of bool, shape (C,)
        Candidates whose summed loss exceeds the best's by at most one standard error of the
        paired sum of differences over events (the best is always in).
    excess : ndarray, shape (C,)
        Summed loss minus the best's (0 for the best).
    se : ndarray, shape (C,)
        Standard error of that sum: sqrt(E) times the standard deviation of the per-event
        differences (0 for the best).
    """
    L = np.asarray(losses, dtype=float)
    if L.ndim != 2 or L.shape[0] < 1:
        raise ValueError(f"losses must have shape (n_candidates, n_events); got {L.shape}")
    total = L.sum(axis=1)
    best = int(np.argmin(total))
    diff = L - L[best]
    E = L.shape[1]
    se = np.sqrt(E) * diff.std(axis=1, ddof=1) if E > 1 else np.zeros(L.shape[0])
    excess = total - total[best]
    return excess <= se, excess, se


#: One-sided level of the signed-rank test of :func:`confidence_set`.
RANK_LEVEL = 0.05


def rank_p_values(losses: np.ndarray) -> np.ndarray:
    """One-sided Wilcoxon signed-rank p-values of every candidate's per-event loss above the best's.

    ``losses`` (C, E) are as in :func:`one_se_set`. Returns an ndarray of shape (C,): the
    p-value of the hypothesis that the candidate's per-event excess over the best candidate
    (the lowest summed loss) is not centred above zero, by :func:`scipy.stats.wilcoxon`
    (``alternative="greater"``; zero differences dropped); 1 for the best, for a candidate whose
    every difference is zero, and with fewer than two events.
    """
    from scipy.stats import wilcoxon

    L = np.asarray(losses, dtype=float)
    if L.ndim != 2 or L.shape[0] < 1:
        raise ValueError(f"losses must have shape (n_candidates, n_events); got {L.shape}")
    diff = L - L[int(np.argmin(L.sum(axis=1)))]
    p = np.ones(L.shape[0])
    if L.shape[1] < 2:
        return p
    for i in np.flatnonzero(np.any(diff != 0.0, axis=1)):
        p[i] = float(wilcoxon(diff[i], alternative="greater").pvalue)
    return p


def confidence_set(losses: np.ndarray, *, rank_level: float = RANK_LEVEL
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The confidence set of candidates: not significantly worse than the best by either of two tests.

    A candidate leaves the set when its summed held-out loss exceeds the best's by more than one
    standard error (:func:`one_se_set`), or when its per-event losses lie above the best's more
    consistently than chance allows (:func:`rank_p_values` below ``rank_level``). The second test
    matters where a few events dominate the sums: their spread inflates the standard error, while a
    candidate that loses on nearly every event is still worse.

    Parameters
    ----------
    losses : ndarray, shape (C, E)
        Held-out loss of every candidate on every event.
    rank_level : float, in (0, 1)
        Level of the one-sided signed-rank test.

    Returns
    -------
    in_set : ndarray of bool, shape (C,)
    excess, se : ndarray, shape (C,), as :func:`one_se_set`
    p_rank : ndarray, shape (C,), as :func:`rank_p_values`
    """
    if not 0.0 < rank_level < 1.0:
        raise ValueError(f"rank_level must be in (0, 1); got {rank_level!r}")
    in_se, excess, se = one_se_set(losses)
    p = rank_p_values(losses)
    return in_se & (p >= rank_level), excess, se, p


def dynamics_by_wind(model_losses: np.ndarray, null_losses: np.ndarray,
                     min_events: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per wind bin, whether the model's held-out error is significantly below the null model's.

    Parameters
    ----------
    model_losses, null_losses : ndarray, shape (E, B)
        Held-out loss of the chosen model and of the null model on every event, summed by wind bin.
    min_events : int
        Fewest events with samples in a bin for a test there (fewer: not shown).

    Returns
    -------
    shown : ndarray of bool, shape (B,)
        The null lies outside the one-standard-error set of the pair over the bin's events.
    excess, se : ndarray, shape (B,)
        The null's summed loss above the model's and its standard error (NaN where not tested).
    n_events : ndarray of int, shape (B,)
        Events with samples in the bin.
    """
    M, N = np.asarray(model_losses, dtype=float), np.asarray(null_losses, dtype=float)
    B = M.shape[1]
    shown, excess, se = np.zeros(B, dtype=bool), np.full(B, np.nan), np.full(B, np.nan)
    present = (M > 0) | (N > 0)
    n_events = present.sum(axis=0)
    for b in np.flatnonzero(n_events >= min_events):
        ev = present[:, b]
        in_set, _, s = one_se_set(np.vstack([M[ev, b], N[ev, b]]))
        excess[b], se[b] = float(N[ev, b].sum() - M[ev, b].sum()), float(s.max())
        shown[b] = not bool(in_set[1])  # the null is out of the pair's set: the model is the better, significantly
    return shown, excess, se, n_events


def _unfitted(model, **params):
    """A fresh copy of an unfitted model with ``params`` set where it has them (e.g. n_bootstrap)."""
    m = copy.deepcopy(model)
    if callable(getattr(m, "get_params", None)) and callable(getattr(m, "set_params", None)):
        own = m.get_params()
        m.set_params(**{k: v for k, v in params.items() if k in own})
    return m


def _fit(model, records):
    fitted = model.fit(list(records))
    return model if fitted is None else fitted


def variant_params(model, **overrides) -> dict:
    """What distinguishes ``model`` within its group of :func:`shared_groups`: its ``final_params``' values,
    with ``overrides`` where it has them (e.g. n_bootstrap)."""
    own = model.get_params() if callable(getattr(model, "get_params", None)) else {}
    return {**{k: own[k] for k in getattr(model, "final_params", ()) if k in own},
            **{k: v for k, v in overrides.items() if k in own}}


def shared_groups(models: Sequence) -> list[list[int]]:
    """Indices of ``models`` grouped so that each group can be fitted at once.

    Models of one class with ``fit_variants`` whose parameters are equal outside its
    ``final_params`` share one group (:meth:`vivbench.models.VaryingCoefficientSINDy.fit_variants`
    fits them together); every other model is a group of its own. Groups are in the order of
    their first member.
    """
    keys, groups = {}, []
    for i, m in enumerate(models):
        final = getattr(m, "final_params", None)
        if callable(getattr(m, "fit_variants", None)) and final is not None and callable(getattr(m, "get_params", None)):
            key = (type(m), repr(sorted((k, v) for k, v in m.get_params().items() if k not in final)))
        else:
            key = ("alone", i)
        if key not in keys:
            keys[key] = len(groups)
            groups.append([])
        groups[keys[key]].append(i)
    return groups


def fit_group(model, variants: Sequence[dict], records) -> list:
    """Fitted copies of ``model``, one per variant (parameters to set): at once with its ``fit_variants``
    (variants of its ``final_params``, :func:`shared_groups`), else one fit each."""
    own = getattr(model, "fit_variants", None)
    if callable(own) and getattr(model, "final_params", None) is not None:
        return list(own(list(records), list(variants)))
    return [_fit(_unfitted(model, **v), records) for v in variants]


def held_out_task(task: dict) -> dict:
    """Fit a group of candidates (:func:`shared_groups`) without a fold's events and score them on those
    events (a picklable top-level task).

    ``task["folds"]`` lists the folds to run in turn (default every fold): one task per (group, fold)
    keeps every worker busy, one per group sends the records to a worker once. The losses of the events
    of the folds not run are NaN. With ``wind_edges`` in the task, the losses are also returned by wind
    bin (``binned``, shape (variants, events, bins)).
    """
    records, fold, criterion, variants = task["records"], task["fold"], task["criterion"], task["variants"]
    edges = task.get("wind_edges")
    folds = task.get("folds")
    folds = range(int(fold.max()) + 1) if folds is None else folds
    loss = np.full((len(variants), len(records)), np.nan)
    binned = None if edges is None else np.full((len(variants), len(records), len(edges) - 1), np.nan)
    for f in folds:
        fitted = fit_group(task["model"], variants, [r for r, g in zip(records, fold) if g != f])
        held = np.flatnonzero(fold == f)
        for v, model in enumerate(fitted):
            out = held_out_losses(model, [records[i] for i in held], criterion, wind_edges=edges)
            if edges is None:
                loss[v, held] = out
            else:
                binned[v, held], loss[v, held] = out, out.sum(axis=1)
    return {"loss": loss, "binned": binned}


def fit_task(task: dict) -> list:
    """Fit a group of variants of a model to records (:func:`fit_group`; a picklable top-level task)."""
    return fit_group(task["model"], task["variants"], task["records"])
