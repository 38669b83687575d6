"""Scores of event detection against known boundaries: precision, recall and F1 within a margin.

As change-point benchmarks score detectors (TCPDBench, ruptures'
``precision_recall``): each boundary is a point in time, a detected boundary
counts once at most, and it is right when it lies within a margin of a true
one not yet claimed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vivbench.core.errors import InputError

__all__ = ["BoundaryScore", "boundary_f1"]


@dataclass(frozen=True)
class BoundaryScore:
    """Precision, recall and F1 of detected event boundaries.

    Attributes
    ----------
    precision : float
        True positives / detected boundaries (1 when none was detected).
    recall : float
        True positives / true boundaries (1 when there is none).
    f1 : float
        Harmonic mean of precision and recall (0 when both are 0).
    true_positives : int
    n_true, n_detected : int
        Numbers of boundaries (twice the numbers of events).
    """

    precision: float
    recall: float
    f1: float
    true_positives: int
    n_true: int
    n_detected: int


def _intervals(x, name: str) -> np.ndarray:
    a = np.asarray(x, dtype=float).reshape(-1, 2) if np.size(x) else np.empty((0, 2))
    if a.ndim != 2 or a.shape[1] != 2 or not np.all(np.isfinite(a)) or np.any(a[:, 1] < a[:, 0]):
        raise InputError(f"{name} must be (n, 2) finite [start, end] pairs with start <= end (s); got {np.shape(x)}")
    return a


def _matches(truth: np.ndarray, found: np.ndarray, margin: float) -> int:
    """Largest number of one-to-one pairs |t - d| <= margin between two sets of points.

    Greedy over both sets in time order: the earliest unclaimed detection
    within reach of a true point takes it; for points on a line this is a
    maximum matching.
    """
    truth, found = np.sort(truth), np.sort(found)
    i = j = n = 0
    while i < truth.size and j < found.size:
        if found[j] < truth[i] - margin:
            j += 1
        elif found[j] > truth[i] + margin:
            i += 1
        else:
            n, i, j = n + 1, i + 1, j + 1
    return n


def boundary_f1(true_events, detected_events, *, margin_s: float = 120.0) -> BoundaryScore:
    """F1 of detected event boundaries within a margin.

    Every event gives two boundaries, its start and its end. A detected start
    is a true positive when it lies within ``margin_s`` (inclusive) of a true
    event's start that no other detected start has claimed; likewise for ends,
    which are matched only with ends. The pairing is one-to-one and as large as
    possible, so two detected starts near one true start give one true
    positive and one false positive, and a detection that splits a true event
    in two gains one right start and one right end, and two false boundaries
    (the end and the start where it split). Precision is the true positives
    over the detected boundaries, recall over the true ones.

    Parameters
    ----------
    true_events, detected_events : array_like, shape (n, 2), s
        [start, end] of each event, any order.
    margin_s : float
        Largest distance between a detected boundary and the true one it
        matches, s (> 0). Default 120 s.

    Returns
    -------
    BoundaryScore
    """
    if not (isinstance(margin_s, (int, float)) and math.isfinite(margin_s) and margin_s > 0):
        raise InputError(f"margin_s must be a positive number of seconds; got {margin_s!r}")
    truth = _intervals(true_events, "true_events")
    found = _intervals(detected_events, "detected_events")
    tp = _matches(truth[:, 0], found[:, 0], margin_s) + _matches(truth[:, 1], found[:, 1], margin_s)
    n_true, n_found = 2 * truth.shape[0], 2 * found.shape[0]
    precision = tp / n_found if n_found else 1.0
    recall = tp / n_true if n_true else 1.0
    f1 = 2 * precision * recall / (precision + recall) if precision + recall > 0 else 0.0
    return BoundaryScore(precision=precision, recall=recall, f1=f1, true_positives=tp, n_true=n_true,
                         n_detected=n_found)
