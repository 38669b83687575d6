"""Permutation tests: orderings of events within strata, and the permutation p-value with ties counted.

The change scans of :mod:`vivbench.analysis.changes` compare the largest split statistic of the
events in time order with its values over random orderings of the events (within strata of
similar wind, where the scan is stratified).
"""

from __future__ import annotations

import numpy as np

__all__ = ["permutation_p_value", "stratified_permutations"]


def stratified_permutations(strata: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` orderings of the events that move each event only to positions of its own stratum, shape (n, E).

    Row r maps positions to events: ordering r puts event ``out[r, j]`` at
    position j, and ``strata[out[r, j]] == strata[j]`` for every j.
    """
    strata = np.asarray(strata)
    slots = np.argsort(strata, kind="stable")  # positions grouped by stratum
    # Events grouped by stratum in the same stratum order, in a random order within each.
    order = np.argsort(strata[None, :] + rng.random((int(n), strata.size)), axis=1, kind="stable")
    out = np.empty((int(n), strata.size), dtype=np.int64)
    out[:, slots] = order
    return out


def permutation_p_value(null: np.ndarray, observed: float, rel_tie: float = 1e-9) -> float:
    """(1 + #{null >= observed}) / (1 + len(null)), a null value within ``rel_tie`` of ``observed`` counted as a tie.

    A permutation that leaves the split's partition as it is gives the observed statistic itself, summed
    in another order: counted as reaching it whatever the rounding (otherwise the p-value of a few
    events would move by one permutation per tie with the order of the sums). ``rel_tie`` is relative
    to the larger of abs(observed) and the null values' largest magnitude.
    """
    null = np.asarray(null, dtype=float)
    scale = max(abs(float(observed)), float(np.max(np.abs(null), initial=0.0)), 1e-300)
    tie = rel_tie * scale
    return float((1 + np.sum(null >= observed - tie)) / (1 + null.size))
