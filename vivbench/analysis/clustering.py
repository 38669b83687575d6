"""Density-peaks clustering of window models (Rodriguez and Laio, Science 2014; docs/field_workflow.md).

Each point i gets a local density rho_i and the distance delta_i to its nearest
denser point. Cluster centres are the points with both large rho and large
delta (outliers of gamma = rho * delta on the decision graph); every other point
takes the label of its nearest denser neighbour, so labels are propagated down
the density order.

Conventions (and where they differ from ``pydpc``, the reference in the benchmark):

- Density. ``kernel="cutoff"`` is the paper's rho_i = #{j != i : d_ij < d_c};
  ``kernel="gaussian"`` is rho_i = sum_{j != i} exp(-(d_ij / d_c)^2), the kernel
  ``pydpc`` uses (it has no cutoff kernel). The point itself is not counted.
- d_c from ``neighbor_fraction`` f: the m = n(n-1)/2 pairwise distances are
  sorted and d_c is the one at index floor(0.5 + f m) (clipped to m - 1), i.e. the
  f-quantile, so that on average a fraction f of the other points lie within
  d_c. This is the same quantile rule as ``pydpc``.
- Density order and ties. Points are ranked by decreasing rho; ties (frequent
  with the integer cutoff density) are broken first by the Gaussian density with
  the same d_c, then by the sum of distances to all points (smaller first), and
  only then by index. The first two keys depend on the geometry only, so the
  result does not depend on the order in which the points are given unless two
  points are tied on all of them (duplicated points, or exact symmetries).
  ``pydpc`` breaks ties by an unstable argsort.
- delta and the nearest denser point: delta_i = min over denser j of d_ij; among
  equidistant denser points the densest wins (as in ``pydpc``). The densest
  point has no denser point: as in the paper, its delta is its largest distance
  to any other point (``pydpc`` uses the largest delta of the other points
  instead), and its ``nearest_denser_`` is -1.
- Labels 0..k-1 are given to the centres in order of decreasing density
  (``pydpc`` numbers them in order of increasing index).
- Halo (Rodriguez-Laio): the border density of cluster c is the largest mean
  density (rho_i + rho_j) / 2 over pairs closer than d_c with i in c and j in
  another cluster; a point is halo when its density is below the border density
  of its cluster. Same rule as ``pydpc`` with ``border_only=False``.

Automatic centres (``n_centers=None`` and no ``centers``), following the
paper's reading of the decision graph (centres have an anomalously large delta
and are not isolated): a point is eligible when delta_i >
``center_delta_factor`` * d_c (far from any denser point, not just a
fluctuation of the density inside a cluster) and rho_i >= rho_min, the density
one neighbour at distance d_c contributes (1 for the cutoff kernel, e^-1 for the
Gaussian one): an isolated point has a large delta too, but it is an outlier,
not a centre. The densest point is always eligible; for this ranking its delta
(the largest distance, a convention) is replaced by the largest delta of the
other eligible points. Eligible deltas are sorted in decreasing order and
followed by a sentinel, the largest delta of the non-eligible points with
rho >= rho_min (if any). The centres are the top k eligible points, k
maximising the log-ratio gap log(delta_(k)) - log(delta_(k+1)): the centres are
the group whose distance to any denser point stands out of the rest by the
largest factor. With a single eligible point and no sentinel the result is one
cluster. Ranking by delta rather than by gamma = rho * delta keeps small or
sparse clusters: their peaks have a low rho, and a gap in gamma then only
reflects the difference in the clusters' sizes (tested on blobs of 60, 40 and
25 points).

Memory is O(n^2) (the full distance matrix); intended for a few thousand points.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.distance import pdist, squareform
from vivbench.core.errors import InputError

__all__ = ["KERNELS", "DensityPeaks", "coefficient_features", "decision_graph", "order_features"]

KERNELS = ("cutoff", "gaussian")

_BLOCK_ROWS = 512  # rows of the distance matrix handled at once (bounds temporaries to ~ 512 n)


def _cutoff_from_fraction(condensed: np.ndarray, fraction: float) -> float:
    m = condensed.shape[0]
    k = min(int(np.floor(0.5 + fraction * m)), m - 1)
    return float(np.partition(condensed, k)[k])


def _gaussian_density(dist: np.ndarray, dc: float) -> np.ndarray:
    # exp(0) = 1 on the diagonal is the self term, removed
    out = np.empty(dist.shape[0])
    for start in range(0, dist.shape[0], _BLOCK_ROWS):
        block = dist[start : start + _BLOCK_ROWS]
        out[start : start + _BLOCK_ROWS] = np.exp(-((block / dc) ** 2)).sum(axis=1) - 1.0
    return out


def _cutoff_density(dist: np.ndarray, dc: float) -> np.ndarray:
    # the diagonal (d_ii = 0 < d_c) is the self term, removed
    return (dist < dc).sum(axis=1).astype(float) - 1.0


def _nearest_denser(dist: np.ndarray, rank: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """delta and nearest denser index from a masked minimum over each row block."""
    n = dist.shape[0]
    delta = np.empty(n)
    nearest = np.empty(n, dtype=np.intp)
    for start in range(0, n, _BLOCK_ROWS):
        rows = slice(start, start + _BLOCK_ROWS)
        denser = rank[None, :] < rank[rows, None]
        masked = np.where(denser, dist[rows], np.inf)
        dmin = masked.min(axis=1)
        # among equidistant denser points take the densest (lowest rank)
        tie_key = np.where(masked == dmin[:, None], rank[None, :], n)
        nearest[rows] = tie_key.argmin(axis=1)
        delta[rows] = dmin
    top = int(np.argmin(rank))
    delta[top] = dist[top].max()
    nearest[top] = -1
    return delta, nearest


def _propagate(nearest: np.ndarray, is_center: np.ndarray) -> np.ndarray:
    """Index of the centre each point reaches by following nearest-denser links."""
    root = np.where(is_center, np.arange(nearest.shape[0]), nearest)
    # pointer jumping: chain depth halves per pass, so O(log n) passes
    while True:
        nxt = root[root]
        if np.array_equal(nxt, root):
            return root
        root = nxt


def _border_density(dist: np.ndarray, rho: np.ndarray, labels: np.ndarray, dc: float, k: int) -> np.ndarray:
    border = np.zeros(k)
    for start in range(0, dist.shape[0], _BLOCK_ROWS):
        rows = slice(start, start + _BLOCK_ROWS)
        across = (dist[rows] < dc) & (labels[rows, None] != labels[None, :])
        mean_rho = np.where(across, 0.5 * (rho[rows, None] + rho[None, :]), 0.0)
        np.maximum.at(border, labels[rows], mean_rho.max(axis=1))
    return border


def _auto_centers(rho: np.ndarray, delta: np.ndarray, rank: np.ndarray, dc: float, factor: float,
                  rho_min: float) -> np.ndarray:
    top = int(np.argmin(rank))
    dense = rho >= rho_min
    eligible = (delta > factor * dc) & dense
    eligible[top] = True
    # the densest point's delta (its largest distance) is a convention, not a
    # measured separation; ranked with it, it would dwarf every other centre
    others = eligible.copy()
    others[top] = False
    value = delta.copy()
    value[top] = delta[others].max() if others.any() else delta[top]
    idx = np.flatnonzero(eligible)
    # decreasing delta, ties by density rank so the choice is deterministic
    idx = idx[np.lexsort((rank[idx], -value[idx]))]
    values = value[idx]
    rest = value[dense & ~eligible]
    if rest.size:
        values = np.append(values, rest.max())
    if values.shape[0] == 1:
        return idx
    tiny = np.finfo(float).tiny
    logs = np.log(np.maximum(values, tiny))
    k = int(np.argmax(logs[:-1] - logs[1:])) + 1
    return idx[:k]


class DensityPeaks:
    """Density-peaks clustering (Rodriguez and Laio 2014) with a scikit-learn style interface.

    Parameters
    ----------
    kernel : {"cutoff", "gaussian"}
        Local density: number of points closer than d_c (the paper), or the
        Gaussian sum exp(-(d/d_c)^2) (smoother, fewer ties; what ``pydpc`` uses).
    dc : float or None
        Cutoff distance d_c in the units of the features. None: from
        ``neighbor_fraction``.
    neighbor_fraction : float
        Fraction in (0, 1) of the pairwise distances below d_c when ``dc`` is None.
    n_centers : int or None
        Number of clusters; the densest point plus the n_centers - 1 others of
        largest gamma. None: automatic rule (module docstring) unless
        ``centers`` is given.
    centers : sequence of int or None
        Explicit centre indices (must include the densest point, which has no
        denser point to be assigned to). Overrides ``n_centers``.
    halo : bool
        Compute the Rodriguez-Laio halo mask ``halo_``.
    center_delta_factor : float
        Automatic rule: a centre needs delta > center_delta_factor * d_c.

    Attributes
    ----------
    dc_ : float
    rho_, delta_, gamma_ : ndarray, shape (n_points,)
    nearest_denser_ : ndarray of int, shape (n_points,), -1 for the densest point
    order_ : ndarray of int, shape (n_points,), point indices by decreasing density
    centers_ : ndarray of int, shape (n_clusters,), by decreasing density
    labels_ : ndarray of int, shape (n_points,), values 0..n_clusters-1
    border_density_ : ndarray, shape (n_clusters,) (only if ``halo``)
    halo_ : ndarray of bool, shape (n_points,) (all False if not ``halo``)
    """

    def __init__(
        self,
        *,
        kernel: str = "cutoff",
        dc: float | None = None,
        neighbor_fraction: float = 0.02,
        n_centers: int | None = None,
        centers=None,
        halo: bool = True,
        center_delta_factor: float = 2.0,
    ):
        self.kernel = kernel
        self.dc = dc
        self.neighbor_fraction = neighbor_fraction
        self.n_centers = n_centers
        self.centers = centers
        self.halo = halo
        self.center_delta_factor = center_delta_factor

    def get_params(self, deep: bool = True) -> dict:
        """Constructor parameters (scikit-learn convention)."""
        names = ("kernel", "dc", "neighbor_fraction", "n_centers", "centers", "halo", "center_delta_factor")
        return {name: getattr(self, name) for name in names}

    def _validate(self, n: int) -> None:
        if self.kernel not in KERNELS:
            raise InputError(f"kernel={self.kernel!r} is not known; allowed: {KERNELS}")
        if self.dc is not None and not (np.isfinite(self.dc) and self.dc > 0):
            raise InputError(f"dc={self.dc} must be a positive finite distance or None")
        if not 0.0 < self.neighbor_fraction < 1.0:
            raise InputError(f"neighbor_fraction={self.neighbor_fraction} must lie in (0, 1)")
        if self.n_centers is not None and not 1 <= int(self.n_centers) <= n:
            raise InputError(f"n_centers={self.n_centers} must be None or an integer in [1, {n}]")
        if not self.center_delta_factor >= 0:
            raise InputError(f"center_delta_factor={self.center_delta_factor} must be >= 0")

    def fit(self, X, y=None) -> "DensityPeaks":
        """Cluster the rows of X.

        Parameters
        ----------
        X : array_like, shape (n_points, n_features)
            Points (e.g. window models from ``coefficient_features``); Euclidean distance.
        y : ignored

        Returns
        -------
        self
        """
        X = np.asarray(X, dtype=float)
        if X.ndim != 2 or X.shape[0] < 2 or not np.all(np.isfinite(X)):
            raise ValueError(f"X must be a finite 2-D array with at least 2 rows, got shape {X.shape}")
        n = X.shape[0]
        self._validate(n)
        condensed = pdist(X)
        dc = float(self.dc) if self.dc is not None else _cutoff_from_fraction(condensed, self.neighbor_fraction)
        if not dc > 0:
            raise InputError("d_c from neighbor_fraction is 0 (too many duplicated points); give dc or a larger fraction")
        dist = squareform(condensed)
        del condensed
        gauss = _gaussian_density(dist, dc)
        rho = gauss if self.kernel == "gaussian" else _cutoff_density(dist, dc)
        order = np.lexsort((np.arange(n), dist.sum(axis=1), -gauss, -rho))
        rank = np.empty(n, dtype=np.intp)
        rank[order] = np.arange(n)
        delta, nearest = _nearest_denser(dist, rank)
        gamma = rho * delta

        top = int(order[0])
        if self.centers is not None:
            centers = np.unique(np.asarray(self.centers, dtype=np.intp))
            if centers.size == 0 or centers.min() < 0 or centers.max() >= n:
                raise InputError(f"centers must be a non-empty list of indices in [0, {n})")
            if top not in centers:
                raise InputError(f"centers must include the densest point (index {top}); it has no denser point to follow")
        elif self.n_centers is not None:
            others = order[1:][np.lexsort((rank[order[1:]], -gamma[order[1:]]))]
            centers = np.concatenate(([top], others[: int(self.n_centers) - 1]))
        else:
            rho_min = 1.0 if self.kernel == "cutoff" else float(np.exp(-1.0))
            centers = _auto_centers(rho, delta, rank, dc, self.center_delta_factor, rho_min)
        centers = centers[np.argsort(rank[centers])]

        is_center = np.zeros(n, dtype=bool)
        is_center[centers] = True
        center_label = np.full(n, -1, dtype=np.intp)
        center_label[centers] = np.arange(centers.shape[0])
        labels = center_label[_propagate(nearest, is_center)]

        self.dc_ = dc
        self.rho_ = rho
        self.delta_ = delta
        self.gamma_ = gamma
        self.nearest_denser_ = nearest
        self.order_ = order
        self.centers_ = centers
        self.labels_ = labels
        if self.halo:
            self.border_density_ = _border_density(dist, rho, labels, dc, centers.shape[0])
            self.halo_ = rho < self.border_density_[labels]
        else:
            self.halo_ = np.zeros(n, dtype=bool)
        return self

    def fit_predict(self, X, y=None) -> np.ndarray:
        """``fit(X).labels_``."""
        return self.fit(X).labels_


def decision_graph(rho, delta, centers, path) -> None:
    """Write the decision graph (delta against rho, centres highlighted) as a PNG.

    Parameters
    ----------
    rho, delta : array_like, shape (n_points,)
    centers : array_like of int
        Indices of the centres, drawn in red and numbered by label.
    path : str or path-like
        Output file (PNG, Agg backend, no timestamp in the metadata).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rho = np.asarray(rho, dtype=float)
    delta = np.asarray(delta, dtype=float)
    centers = np.asarray(centers, dtype=np.intp)
    fig, ax = plt.subplots(figsize=(5, 4))
    ax.scatter(rho, delta, s=12, color="0.5", label="points")
    ax.scatter(rho[centers], delta[centers], s=40, color="tab:red", label="centres")
    for label, i in enumerate(centers):
        ax.annotate(str(label), (rho[i], delta[i]), textcoords="offset points", xytext=(4, 4))
    pos = delta[delta > 0]
    if pos.size and pos.max() > 1e3 * np.median(pos):
        # isolated points sit orders of magnitude above the rest: a linear axis hides the centres
        ax.set_yscale("log")
    ax.set_xlabel(r"local density $\rho$")
    ax.set_ylabel(r"distance to nearest denser point $\delta$")
    ax.legend(loc="best")
    fig.tight_layout()
    fig.savefig(path, format="png", metadata={"Software": None})
    plt.close(fig)


def coefficient_features(coef, *, return_mask: bool = False):
    """Window-model coefficients as standardised feature vectors.

    Parameters
    ----------
    coef : array_like, shape (n_windows, 3, 69)
        Coefficients of each window model (sections x library terms); any
        (n_windows, ...) shape is accepted and flattened per window.
    return_mask : bool
        Also return the boolean mask (length 207) of the kept features.

    Returns
    -------
    features : ndarray, shape (n_windows, n_kept)
        Flattened coefficients z-scored across windows (zero mean, unit
        population standard deviation per feature); features that do not vary
        across windows (e.g. terms never selected) carry no information and are
        dropped, so n_kept <= 207.
    mask : ndarray of bool, shape (207,)
        Only if ``return_mask``.
    """
    coef = np.asarray(coef, dtype=float)
    if coef.ndim < 2:
        raise ValueError(f"coef must have shape (n_windows, ...), got {coef.shape}")
    flat = coef.reshape(coef.shape[0], -1)
    mean = flat.mean(axis=0)
    std = flat.std(axis=0)
    # relative threshold: round-off on a constant column must not count as variance
    keep = std > 1e-12 * np.maximum(np.abs(mean), 1.0)
    features = (flat[:, keep] - mean[keep]) / std[keep]
    return (features, keep) if return_mask else features


def order_features(order_rms) -> np.ndarray:
    """Order-of-A RMS contributions as shares of each window's total.

    Parameters
    ----------
    order_rms : array_like, shape (n_windows, 3, 4)
        Non-negative RMS contribution of each order A^0..A^3 to each section's
        dA/dt (units of dA/dt, m s^-1).

    Returns
    -------
    ndarray, shape (n_windows, 12)
        Each window's 12 values divided by their sum, so a window is described
        by how its dynamics split between orders and sections, independently of
        its amplitude. Windows whose total is 0 get all-zero shares.
    """
    x = np.asarray(order_rms, dtype=float)
    if x.ndim < 2:
        raise ValueError(f"order_rms must have shape (n_windows, ...), got {x.shape}")
    if np.any(x < 0):
        raise ValueError("order_rms must be non-negative (RMS contributions)")
    flat = x.reshape(x.shape[0], -1)
    total = flat.sum(axis=1, keepdims=True)
    return np.divide(flat, total, out=np.zeros_like(flat), where=total > 0)
