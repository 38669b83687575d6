"""The envelope's time constant of a campaign, read from its fitted model, and the events too short for it.

An amplitude relaxes towards the level its wind sustains at the rate -d(dA/dt)/dA: the inverse is the
envelope's time constant, 1/(2 pi f zeta) for a linear structure of frequency f (Hz) and damping ratio
zeta. A fitted campaign model gives that slope wherever it predicts dA/dt; over the windows it flags as
regime 1 (no self-excitation, docs/concepts.md (regimes)), the slope is the relaxation of the forced
response. An event shorter than a few time constants shows an amplitude's change but not how it ends
(docs/model_selection.md).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Callable, Sequence

import numpy as np

from vivbench.core.record import Record
from vivbench.preprocess.runs import mask_runs

__all__ = ["WINDOW_S", "STEP_S", "amplitude_slope", "envelope_time_constant", "short_events", "valid_span"]

#: Windows (s) over which the model's regimes and slopes are read.
WINDOW_S, STEP_S = 50.0, 25.0


def valid_span(record: Record) -> float:
    """Seconds of the record's longest stretch of samples with a finite A at any section and no gap in time
    (:func:`vivbench.preprocess.mask_runs`): a dropout splits an event, as it splits its held-out runs (0 with
    fewer than two such samples)."""
    runs = mask_runs(np.isfinite(record.A).any(axis=1), record.t)
    return max((float(record.t[r.stop - 1] - record.t[r.start]) for r in runs), default=0.0)


def amplitude_slope(model, record: Record, rel: float = 1e-3) -> np.ndarray | None:
    """d(dA/dt)/dA of a model's ``predict`` at the record's samples, by a relative step ``rel`` of A.

    Returns
    -------
    ndarray, shape (n_samples, n_sections), 1/s (NaN where A is 0 or not finite); None for a model
    without ``predict``
    """
    predict = getattr(model, "predict", None)
    if not callable(predict):
        return None
    f0 = np.asarray(predict(record), dtype=float)
    f1 = np.asarray(predict(dataclasses.replace(record, A=record.A * (1.0 + rel))), dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return (f1 - f0) / (record.A * rel)


def envelope_time_constant(model, records: Sequence[Record], verdict: Callable[[Record, np.ndarray, np.ndarray], dict],
                           measured: Callable[[Record], Record] = lambda r: r) -> float:
    """The campaign's envelope time constant (s): -1 / the median over the flagged regime-1 windows of the
    model's median slope d(dA/dt)/dA in the window.

    Parameters
    ----------
    model : fitted model with ``predict``
    records : the campaign's records
    verdict : ``verdict(record, window_start, window_end)`` -> dict with ``regime`` and ``identifiable``
        (W, S), the model's own verdict on its windows of :data:`WINDOW_S` every :data:`STEP_S` seconds
    measured : the record as the model sees it (e.g. its wind smoothed as at fit) for ``predict``

    Returns
    -------
    float, s; NaN when no window is flagged regime 1, the model has no ``predict`` or the median slope is
    not negative
    """
    slopes = []
    for rec in records:
        start = np.arange(rec.t[0], rec.t[-1] - WINDOW_S + 1e-9, STEP_S)
        if start.size == 0:
            continue
        end = start + WINDOW_S
        own = verdict(rec, start, end)
        keep = (np.asarray(own["regime"]) == 1) & np.asarray(own["identifiable"], dtype=bool)
        if not keep.any():
            continue
        slope = amplitude_slope(model, measured(rec))
        if slope is None:
            return float("nan")
        lo, hi = np.searchsorted(rec.t, start, side="left"), np.searchsorted(rec.t, end, side="right")
        for w, k in zip(*np.nonzero(keep)):  # one median per flagged window
            inside = slope[lo[w]:hi[w], k]
            slopes.append(np.nanmedian(inside) if np.isfinite(inside).any() else np.nan)
    slopes = np.asarray(slopes, dtype=float)
    slopes = slopes[np.isfinite(slopes)]
    if slopes.size == 0 or np.median(slopes) >= 0:
        return float("nan")
    return float(-1.0 / np.median(slopes))


def short_events(event_ids: Sequence[str], durations: Sequence[float], time_constant: float,
                 n_time_constants: float) -> list[str]:
    """The events whose duration (s) is under ``n_time_constants`` time constants (every event when the time
    constant is NaN: none is known to be long enough)."""
    if not math.isfinite(time_constant):
        return [str(e) for e in event_ids]
    return [str(e) for e, d in zip(event_ids, durations) if d < n_time_constants * time_constant]
