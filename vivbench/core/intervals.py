"""Intervals where a signal stays above a threshold: runs, short gaps merged, short runs dropped.

One rule shared by the event detector (on the measured amplitude) and by the
synthetic logs' truth (on the true amplitude), so both cut events alike.
"""

from __future__ import annotations

import numpy as np

from vivbench.core.errors import InputError

__all__ = ["threshold_intervals"]


def threshold_intervals(t, above, *, merge_gap_s: float, min_duration_s: float) -> np.ndarray:
    """Time intervals of the runs of ``above``, short gaps merged, short intervals dropped.

    A run of consecutive True samples gives the interval from its first to its
    last sample's time. Two intervals separated by a gap (from the end of one
    to the start of the next) shorter than ``merge_gap_s`` become one; then
    intervals shorter than ``min_duration_s`` are dropped.

    Parameters
    ----------
    t : array_like, shape (n,), s
        Increasing sample times.
    above : array_like of bool, shape (n,)
        True where the signal is above its threshold.
    merge_gap_s : float
        Gaps shorter than this are bridged, s (>= 0).
    min_duration_s : float
        Shortest interval kept, s (>= 0).

    Returns
    -------
    ndarray, shape (n_intervals, 2), s
        Start and end times, sorted and disjoint.
    """
    t = np.asarray(t, dtype=float)
    above = np.asarray(above, dtype=bool)
    if t.ndim != 1 or above.shape != t.shape:
        raise InputError(f"t and above must be 1-D arrays of one length; got shapes {t.shape} and {above.shape}")
    if not (merge_gap_s >= 0 and min_duration_s >= 0):
        raise InputError(f"merge_gap_s and min_duration_s must be >= 0 s; got {merge_gap_s!r}, {min_duration_s!r}")
    if not above.any():
        return np.empty((0, 2))
    edges = np.diff(np.concatenate(([0], above.astype(np.int8), [0])))
    first = np.flatnonzero(edges == 1)
    last = np.flatnonzero(edges == -1) - 1
    starts, ends = t[first], t[last]
    keep = np.concatenate(([True], starts[1:] - ends[:-1] >= merge_gap_s))
    # A merged interval runs from the start of its first run to the end of its last.
    last_of_group = np.concatenate((keep[1:], [True]))
    iv = np.column_stack((starts[keep], ends[last_of_group]))
    return iv[iv[:, 1] - iv[:, 0] >= min_duration_s]
