"""Evidence of dynamics by wind: where along the wind the dynamic model beats the quasi-steady map.

The null test of :class:`vivbench.analysis.ModelSelection` asks once per campaign whether the dynamic
candidates predict held-out events better than the quasi-steady map A = g(U). A campaign can show its
dynamics in one range of wind (a lock-in, where the envelope grows and decays) and not in another (above
it, where the envelope only follows the buffeting and the wind): there the split of dA/dt between the
orders of A is the library's fit to a stochastic envelope, not a regime. The held-out output errors are
therefore also summed by wind bin (:func:`vivbench.analysis.held_out_losses` with ``wind_edges``), and a
window is flagged only where its wind lies in a bin in which the chosen model's held-out error is
significantly below the null's (:func:`vivbench.analysis.held_out.dynamics_by_wind`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from vivbench.core.record import Record

__all__ = ["WIND_BINS", "window_wind", "wind_bin_edges", "wind_bins_of"]

#: Wind bins of the local null test when it is asked for (``vivbench pool --wind-bins`` without a number):
#: quantiles of the campaign's measured wind, so that each holds the same share of its samples. The test is
#: off by default (docs/model_selection.md).
WIND_BINS = 6


def wind_bin_edges(records: Sequence[Record], n_bins: int) -> np.ndarray:
    """Edges of ``n_bins`` bins holding equal shares of the records' finite wind samples, shape (<= n_bins + 1,), m/s.

    Repeated quantiles (a wind held constant) merge; with no finite wind, the edges are [0, inf].
    """
    U = np.concatenate([np.ravel(r.U) for r in records]) if records else np.empty(0)
    U = U[np.isfinite(U)]
    if not U.size:
        return np.array([0.0, np.inf])
    edges = np.unique(np.quantile(U, np.linspace(0.0, 1.0, int(n_bins) + 1)))
    return edges if edges.size >= 2 else np.array([edges[0], np.inf])


def wind_bins_of(U: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Bin index of each wind value (below the first edge: 0; above the last: the last bin; NaN: -1)."""
    U = np.asarray(U, dtype=float)
    B = len(edges) - 1
    b = np.clip(np.searchsorted(edges, np.nan_to_num(U, nan=edges[0]), side="right") - 1, 0, B - 1)
    return np.where(np.isfinite(U), b, -1)


def window_wind(U: np.ndarray, t: np.ndarray, window_start, window_end) -> np.ndarray:
    """Mean wind of each window and section, shape (W, S), from ``U`` (n, S) on times ``t`` (n,), s."""
    start = np.atleast_1d(np.asarray(window_start, dtype=float))
    end = np.atleast_1d(np.asarray(window_end, dtype=float))
    U = np.asarray(U, dtype=float)
    ok = np.isfinite(U)
    csum = np.vstack([np.zeros((1, U.shape[1])), np.cumsum(np.where(ok, U, 0.0), axis=0)])
    ccount = np.vstack([np.zeros((1, U.shape[1])), np.cumsum(ok, axis=0)])
    i0, i1 = np.searchsorted(t, start, side="left"), np.searchsorted(t, end, side="left")
    n = ccount[i1] - ccount[i0]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, (csum[i1] - csum[i0]) / n, np.nan)
