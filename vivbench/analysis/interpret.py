"""Cluster interpretation of a campaign's window models (docs/field_workflow.md).

Every (window, equation) model of every result file ``<event_id>.identify.nc``
of a campaign is one point. Two feature sets describe it:

``"coef"``
    The model's 69 coefficients in its window's regression basis
    (:func:`vivbench.library.basis.window_library`, ``scaling="scaled"``),
    divided by the window RMS of dA/dt: the standardised coefficients that
    STLSQ thresholded. Term (l, i, j) is A_l^i times a degree-j polynomial in
    the window-centred U_l, with unit RMS over the window, so a coefficient of
    0.1 means the term carries a tenth of the RMS of dA/dt. The physical
    coefficients cannot be compared across windows: inside a window U is
    nearly constant, and the physical coefficients of U^0..U^5 are huge with
    alternating signs (the largest physical term of a window can be many
    orders of magnitude above the RMS of dA/dt), so any distance between them
    measures cancellation, not dynamics. The standardised coefficients are
    dimensionless and comparable term by term, so they are clustered as they
    are (no further per-feature scaling; a common scaling would not change
    the partition). Names are the pysindy-style names of the physical terms
    of the same (section, power of A, power of U).
``"order"``
    How the model's RMS contribution to dA/dt splits between the orders
    A^0..A^3 (``order_rms`` of the result, divided by its sum): the regime's
    signature (docs/concepts.md (regimes)), independent of the amplitude.

Clustering is :class:`vivbench.analysis.clustering.DensityPeaks` (automatic
centres by the largest log-gap of rho * delta among eligible points, or a
given number of centres or centre indices). Each cluster is summarised by its
size, its halo, its dominant terms (largest mean ``|standardised coefficient|``),
its mean order shares, and its make-up by identified regime and, when the
campaign's truth is available, by true regime
(:func:`vivbench.validate.truth_window_regimes`); the partition is scored
against the true regimes by the adjusted Rand index and purity.

What the clusters are expected to show: with "coef" features the windows'
models rarely form clusters at all (a dense core and isolated outlying
models); with "order" features the decision graph can show clear centres that
still do not match the regimes, because a 50 s window's regression splits its
dynamics between the orders of A almost arbitrarily (the non-identifiability
of regimes in short windows, docs/concepts.md (regimes)), not because of the
clustering, which recovers well-separated groups of unequal size exactly
(tests). ``vivbench cluster`` reports the adjusted Rand index and purity
against the true regimes of a synthetic campaign, and
``benchmarks/bench_clustering.py`` measures them over the clustering's settings.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import xarray as xr

from vivbench.analysis.clustering import KERNELS, DensityPeaks, order_features
from vivbench.library.basis import window_library
from vivbench.core.terms import feature_names
from vivbench.io.result import read_result
from vivbench.core.errors import InputError

__all__ = ["FEATURE_SETS", "ClusterConfig", "CampaignWindows", "ClusterResult", "campaign_windows", "cluster_scores", "cluster_windows", "standardized_coefficients", "summarize_clusters"]

FEATURE_SETS = ("coef", "order")


def standardized_coefficients(result: xr.Dataset) -> np.ndarray:
    """Each window model's coefficients in its regression basis, per unit RMS of dA/dt.

    Rebuilds each window's scaled basis from the result's A and U (same
    samples and constants as the engine) and maps the physical coefficients
    back through it.

    Parameters
    ----------
    result : xarray.Dataset
        Identification result (``coef``, ``window_start``, ``window_end``, ``A``, ``U``, ``dA``).

    Returns
    -------
    ndarray, shape (W, S, 23 S)
        Dimensionless; NaN for windows without a model.
    """
    t = np.asarray(result["time"].values, dtype=float)
    A = np.asarray(result["A"].values, dtype=float)
    U = np.asarray(result["U"].values, dtype=float)
    dA = np.asarray(result["dA"].values, dtype=float)
    coef = np.asarray(result["coef"].values, dtype=float)
    start = np.asarray(result["window_start"].values, dtype=float)
    end = np.asarray(result["window_end"].values, dtype=float)
    W, S, p = coef.shape
    out = np.full((W, S, p), np.nan)
    if W == 0:
        return out
    # the engine's window sample rule (vivbench.regression.stlsq.window_bounds)
    tol = 1e-6 * float(np.median(np.diff(t)))
    first = np.searchsorted(t, start - tol, side="left")
    stop = np.searchsorted(t, end - tol, side="left")
    offs = np.arange(max(int((stop - first).max()), 1))
    inwin = offs[None, :] < (stop - first)[:, None]
    idx = np.minimum(first[:, None] + offs[None, :], t.size - 1)
    Aw, Uw, dAw = A[idx], U[idx], dA[idx]
    valid = inwin & np.isfinite(Aw).all(-1) & np.isfinite(Uw).all(-1) & np.isfinite(dAw).all(-1)
    fitted = np.isfinite(coef).all(axis=(1, 2)) & (valid.sum(axis=1) > 0)
    if not fitted.any():
        return out
    lib = window_library(Aw[fitted], Uw[fitted], scaling="scaled", valid=valid[fitted])
    n = lib.n_valid[:, None]
    ys = np.sqrt(np.where(valid[fitted][..., None], dAw[fitted] ** 2, 0.0).sum(axis=1) / n)
    ys = np.where(np.isfinite(ys) & (ys > 0), ys, 1.0)
    # coef = to_physical @ xi * ys  (per equation), so xi = to_physical^-1 coef / ys
    xi = np.linalg.solve(lib.to_physical, np.swapaxes(coef[fitted], 1, 2))
    out[fitted] = np.swapaxes(xi, 1, 2) / ys[:, :, None]
    return out


@dataclass(frozen=True, kw_only=True)
class CampaignWindows:
    """All window models of a campaign as points.

    Attributes
    ----------
    event_id, window, equation : ndarray, shape (n,)
        Event, window index in its result file, equation name ("S1"...).
    window_start, window_end : ndarray, shape (n,), s
    regime : ndarray of int, shape (n,)
        Identified regime (0: no model).
    identifiable : ndarray of bool, shape (n,)
    truth_regime : ndarray of int, shape (n,)
        True regime of the window (0: no truth available).
    features : dict
        ``"coef"`` (n, 23 S) standardised coefficients, ``"order"`` (n, 4) order shares.
    coef_names : list of str
        Names of the coefficient features (pysindy style).
    has_truth : bool
        Whether every event had a truth.
    """

    event_id: np.ndarray
    window: np.ndarray
    equation: np.ndarray
    window_start: np.ndarray
    window_end: np.ndarray
    regime: np.ndarray
    identifiable: np.ndarray
    truth_regime: np.ndarray
    features: dict
    coef_names: list
    has_truth: bool

    @property
    def n_points(self) -> int:
        return int(self.event_id.shape[0])


def _truth_regimes(campaign_dir, event_id: str, start, end, tau: float):
    from vivbench.io.event import read_event
    from vivbench.regimes.truth import truth_window_regimes

    path = Path(campaign_dir) / f"{event_id}.nc"
    if not path.exists():
        raise InputError(f"{path}: no event file for result {event_id} in the campaign directory")
    tree = read_event(path)
    if "truth" not in tree.children:
        return None
    return truth_window_regimes(tree["truth"].ds, start, end, tau=tau)


def campaign_windows(result_files: Sequence, campaign_dir=None, *, tau: float = 0.2) -> CampaignWindows:
    """Collect every fitted (window, equation) model of the result files.

    Parameters
    ----------
    result_files : sequence of path-like
        ``<event_id>.identify.nc`` files.
    campaign_dir : path-like, optional
        Directory of the event files (``<event_id>.nc``); their ``/truth``
        gives the true window regimes.
    tau : float
        Regime threshold for the truth (docs/concepts.md (regimes)).

    Returns
    -------
    CampaignWindows
        Windows without a model (NaN coefficients) are left out.
    """
    if len(result_files) == 0:
        raise InputError("no result files given")
    cols = {k: [] for k in ("event_id", "window", "equation", "window_start", "window_end", "regime",
                            "identifiable", "truth_regime", "coef", "order")}
    names, has_truth, n_eq = None, campaign_dir is not None, None
    for path in result_files:
        res = read_result(path)
        eid = str(res.attrs.get("event_id", Path(path).name.split(".")[0]))
        W, S, p = res["coef"].shape
        if n_eq is None:
            n_eq, names = S, feature_names(S)
        elif S != n_eq:
            raise InputError(f"{path}: {S} equations, but earlier results have {n_eq}")
        start = res["window_start"].values.astype(float)
        end = res["window_end"].values.astype(float)
        xi = standardized_coefficients(res)
        truth = _truth_regimes(campaign_dir, eid, start, end, tau) if campaign_dir is not None else None
        if truth is None:
            has_truth = False
            truth = np.zeros((W, S), dtype=int)
        ok = np.isfinite(xi).all(axis=2) & (res["regime"].values > 0)
        w_idx, e_idx = np.nonzero(ok)
        equations = np.asarray([str(e) for e in res["equation"].values]) if "equation" in res.coords else np.array(
            [f"S{k + 1}" for k in range(S)])
        ident = res["identifiable"].values.astype(bool) if "identifiable" in res else np.zeros((W, S), dtype=bool)
        cols["event_id"].append(np.full(w_idx.size, eid, dtype=object))
        cols["window"].append(w_idx)
        cols["equation"].append(equations[e_idx])
        cols["window_start"].append(start[w_idx])
        cols["window_end"].append(end[w_idx])
        cols["regime"].append(res["regime"].values[w_idx, e_idx].astype(int))
        cols["identifiable"].append(ident[w_idx, e_idx])
        cols["truth_regime"].append(np.asarray(truth)[w_idx, e_idx].astype(int))
        cols["coef"].append(xi[w_idx, e_idx])
        cols["order"].append(order_features(res["order_rms"].values[w_idx, e_idx][:, None, :]))
    cat = {k: np.concatenate(v) for k, v in cols.items()}
    if cat["event_id"].size < 2:
        raise InputError(f"the results hold {cat['event_id'].size} fitted window model(s); clustering needs at least 2")
    return CampaignWindows(
        event_id=cat["event_id"].astype(str), window=cat["window"], equation=cat["equation"],
        window_start=cat["window_start"], window_end=cat["window_end"], regime=cat["regime"],
        identifiable=cat["identifiable"], truth_regime=cat["truth_regime"],
        features={"coef": cat["coef"], "order": cat["order"]}, coef_names=names, has_truth=has_truth,
    )


@dataclass(frozen=True, kw_only=True)
class ClusterConfig:
    """Settings of the density-peaks clustering of window models.

    Attributes
    ----------
    kernel : {"cutoff", "gaussian"}
        Local density (the paper: cutoff).
    dc_fraction : float
        d_c as the quantile of the pairwise distances, in (0, 1).
    n_centers : int or None
        Number of clusters; None: automatic centres (DensityPeaks rule).
    centers : tuple of int or None
        Explicit centre indices into the points (overrides ``n_centers``).
    center_delta_factor : float
        Automatic rule: a centre needs delta > this times d_c.
    n_top_terms : int
        Dominant terms listed per cluster.
    """

    kernel: str = "cutoff"
    dc_fraction: float = 0.02
    n_centers: int | None = None
    centers: tuple | None = None
    center_delta_factor: float = 2.0
    n_top_terms: int = 3

    def __post_init__(self) -> None:
        if self.kernel not in KERNELS:
            raise InputError(f"kernel={self.kernel!r} is not known; allowed: {', '.join(KERNELS)}")
        if not 0.0 < self.dc_fraction < 1.0:
            raise InputError(f"dc_fraction={self.dc_fraction} must lie in (0, 1)")
        if self.n_centers is not None and not (isinstance(self.n_centers, (int, np.integer)) and self.n_centers >= 1):
            raise InputError(f"n_centers={self.n_centers!r} must be None or an integer >= 1")
        if self.centers is not None:
            object.__setattr__(self, "centers", tuple(int(c) for c in self.centers))
        if not self.center_delta_factor >= 0:
            raise InputError(f"center_delta_factor={self.center_delta_factor} must be >= 0")
        if self.n_top_terms < 1:
            raise InputError(f"n_top_terms={self.n_top_terms} must be >= 1")

    def estimator(self, n_points: int) -> DensityPeaks:
        if self.n_centers is not None and self.n_centers > n_points:
            raise InputError(f"n_centers={self.n_centers} exceeds the number of window models ({n_points})")
        return DensityPeaks(kernel=self.kernel, neighbor_fraction=self.dc_fraction, n_centers=self.n_centers,
                            centers=self.centers, center_delta_factor=self.center_delta_factor)


@dataclass(frozen=True, kw_only=True)
class ClusterResult:
    """Clustering of one feature set.

    Attributes
    ----------
    feature_set : str
    model : DensityPeaks
        The fitted estimator (``labels_``, ``halo_``, ``rho_``, ``delta_``, ``centers_``).
    summary : list of dict
        One row per cluster (:func:`summarize_clusters`).
    scores : dict
        :func:`cluster_scores` (NaN without truth).
    """

    feature_set: str
    model: DensityPeaks
    summary: list = field(default_factory=list)
    scores: dict = field(default_factory=dict)

    @property
    def n_clusters(self) -> int:
        return int(self.model.centers_.size)


def cluster_scores(labels, truth) -> dict:
    """Adjusted Rand index and purity of a partition against true regimes.

    Parameters
    ----------
    labels : array_like of int, shape (n,)
    truth : array_like of int, shape (n,); 0 = no truth (left out)

    Returns
    -------
    dict
        ``ari`` (sklearn's adjusted_rand_score), ``purity`` (share of points
        whose cluster's most common true regime is their own), ``n_scored``;
        NaN scores when nothing can be scored.
    """
    from sklearn.metrics import adjusted_rand_score

    labels = np.asarray(labels)
    truth = np.asarray(truth)
    ok = truth > 0
    if not ok.any():
        return {"ari": float("nan"), "purity": float("nan"), "n_scored": 0}
    lab, tru = labels[ok], truth[ok]
    table = np.zeros((int(lab.max()) + 1, int(tru.max()) + 1), dtype=int)
    np.add.at(table, (lab, tru), 1)
    return {"ari": float(adjusted_rand_score(tru, lab)), "purity": float(table.max(axis=1).sum() / ok.sum()),
            "n_scored": int(ok.sum())}


def summarize_clusters(labels, halo, windows: CampaignWindows, n_top: int = 3) -> list[dict]:
    """One row per cluster: size, halo, dominant terms, order shares, regime make-up.

    Returns
    -------
    list of dict
        Keys ``label``, ``size``, ``share``, ``halo``, ``dominant_terms``
        (the ``n_top`` largest mean ``|standardised coefficient|``, "name (value)"
        joined by "; "), ``order_share_0..3`` (mean order shares),
        ``identified_regime_1..4`` and ``truth_regime_1..4`` (shares within
        the cluster; truth columns NaN without truth), ``truth_majority``.
    """
    labels = np.asarray(labels)
    halo = np.asarray(halo, dtype=bool)
    coef = windows.features["coef"]
    order = windows.features["order"]
    rows = []
    for lab in range(int(labels.max()) + 1):
        m = labels == lab
        if not m.any():
            continue
        mean_abs = np.abs(coef[m]).mean(axis=0)
        top = np.argsort(-mean_abs, kind="stable")[:n_top]
        row = {"label": lab, "size": int(m.sum()), "share": float(m.mean()), "halo": int(halo[m].sum()),
               "dominant_terms": "; ".join(f"{windows.coef_names[j]} ({mean_abs[j]:.3g})" for j in top)}
        for i in range(4):
            row[f"order_share_{i}"] = float(order[m, i].mean())
        for r in range(1, 5):
            row[f"identified_regime_{r}"] = float((windows.regime[m] == r).mean())
        t = windows.truth_regime[m]
        scored = t > 0
        for r in range(1, 5):
            row[f"truth_regime_{r}"] = float((t[scored] == r).mean()) if scored.any() else float("nan")
        row["truth_majority"] = int(np.bincount(t[scored], minlength=5)[1:].argmax() + 1) if scored.any() else 0
        rows.append(row)
    return rows


def cluster_windows(windows: CampaignWindows, config: ClusterConfig | None = None,
                    feature_sets: Sequence[str] = FEATURE_SETS) -> dict:
    """Cluster the window models of a campaign for each feature set.

    Parameters
    ----------
    windows : CampaignWindows
    config : ClusterConfig
    feature_sets : subset of FEATURE_SETS

    Returns
    -------
    dict
        feature set -> :class:`ClusterResult`.
    """
    config = config or ClusterConfig()
    out = {}
    for name in feature_sets:
        if name not in FEATURE_SETS:
            raise InputError(f"feature set {name!r} is not known; allowed: {', '.join(FEATURE_SETS)}")
        X = windows.features[name]
        model = config.estimator(X.shape[0]).fit(X)
        out[name] = ClusterResult(
            feature_set=name, model=model,
            summary=summarize_clusters(model.labels_, model.halo_, windows, config.n_top_terms),
            scores=cluster_scores(model.labels_, windows.truth_regime),
        )
    return out
