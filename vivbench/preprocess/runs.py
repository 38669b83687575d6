"""Valid runs of a record, its gaps and segments, and the common time grid."""

from __future__ import annotations

import math

import numpy as np

from vivbench.core.errors import InputError

__all__ = ["mask_runs", "gap_steps", "first_gap", "check_positive", "check_time", "as_2d", "run_rate", "valid_runs", "trusted_intervals", "intersect_intervals", "segments", "common_grid", "grid_of_intervals", "to_grid"]


# A step between time stamps larger than this multiple of the nominal step is a
# gap in the record (missing samples), even without NaN.
_TIME_JUMP_FACTOR = 1.5


def check_positive(name: str, value: float) -> None:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise InputError(f"{name} must be a positive finite number; got {value!r}")


def _run_bounds(mask: np.ndarray, breaks: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Start and end (exclusive) indices of the runs of True in ``mask``.

    ``breaks[i]`` True splits a run between samples i and i + 1.
    """
    mask = np.asarray(mask, dtype=bool)
    cut = ~(mask[:-1] & mask[1:])
    if breaks is not None:
        cut = cut | breaks
    start = mask.copy()
    start[1:] &= cut
    end = mask.copy()
    end[:-1] &= cut
    return np.flatnonzero(start), np.flatnonzero(end) + 1


def gap_steps(t) -> np.ndarray:
    """Which steps of the sample times ``t``, shape (n,), s, are gaps in the record: shape (n - 1,), True where the
    step exceeds 1.5 times the median step (samples missing without NaN, as between the segments of an
    identification result, whose wind is unknown)."""
    dt = np.diff(np.asarray(t, dtype=float))
    if dt.size == 0:
        return np.zeros(0, dtype=bool)
    return dt > _TIME_JUMP_FACTOR * np.median(dt)


def first_gap(t, start: int = 0, stop: int | None = None) -> int | None:
    """Index i of the first gap step (:func:`gap_steps` of the whole ``t``) from sample i to i + 1 with
    start <= i and i + 1 < stop (default: the last sample), or None when the span has none."""
    steps = gap_steps(t)
    end = steps.size if stop is None else max(min(int(stop) - 1, steps.size), int(start))
    hit = np.flatnonzero(steps[int(start):end])
    return None if hit.size == 0 else int(start) + int(hit[0])


def mask_runs(mask, t=None) -> list[slice]:
    """The runs of True in a boolean mask, shape (n,), as slices in order (none for an all-False mask).

    With the sample times ``t``, shape (n,), s, a run also ends where the step to the next sample exceeds
    1.5 times the median step: a gap in the record (samples missing without NaN, as between the segments
    of an identification result), so that a derivative, a window or a held-out simulation over a run never
    spans it.
    """
    mask = np.asarray(mask, dtype=bool)
    breaks = None
    if t is not None and mask.size > 1:
        breaks = gap_steps(t)
    starts, ends = _run_bounds(mask, breaks)
    return [slice(int(a), int(b)) for a, b in zip(starts, ends)]


def _positions(starts: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Concatenation of arange(s, s + l) over the runs, without a Python loop."""
    offsets = np.cumsum(lengths) - lengths
    return np.arange(int(lengths.sum())) + np.repeat(starts - offsets, lengths)


def segments(valid_mask, min_length: int = 1) -> np.ndarray:
    """Number the contiguous runs of valid samples.

    Parameters
    ----------
    valid_mask : array_like of bool, shape (n,)
        True where the sample is usable.
    min_length : int
        Runs shorter than this many samples are dropped.

    Returns
    -------
    ndarray of int, shape (n,)
        Segment id 0, 1, ... of each sample, in time order; -1 for invalid
        samples and for samples of dropped runs.
    """
    mask = np.asarray(valid_mask, dtype=bool)
    if mask.ndim != 1:
        raise ValueError(f"valid_mask must be one-dimensional; got shape {mask.shape}")
    if not (isinstance(min_length, (int, np.integer)) and min_length >= 1):
        raise ValueError(f"min_length must be an integer >= 1 (samples); got {min_length!r}")
    ids = np.full(mask.shape[0], -1, dtype=int)
    if mask.size == 0:
        return ids
    starts, ends = _run_bounds(mask)
    lengths = ends - starts
    keep = lengths >= min_length
    starts, lengths = starts[keep], lengths[keep]
    ids[_positions(starts, lengths)] = np.repeat(np.arange(starts.size), lengths)
    return ids


def common_grid(intervals, step_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Grid times inside intervals, on integer multiples of the step.

    Parameters
    ----------
    intervals : array_like, shape (k, 2)
        Disjoint [start, end] intervals in increasing order, s.
    step_s : float
        Grid step, s.

    Returns
    -------
    t : ndarray, shape (n,)
        All times m * step_s (m integer) inside the intervals, ends included.
    segment : ndarray of int, shape (n,)
        Index of the interval of each time, renumbered 0, 1, ... over the
        intervals that hold at least one grid time.
    """
    t, segment, _ = grid_of_intervals(intervals, step_s)
    return t, segment


def grid_of_intervals(intervals, step_s: float):
    """:func:`common_grid` plus the mask of intervals that hold a grid time."""
    check_positive("step_s", step_s)
    iv = np.asarray(intervals, dtype=float).reshape(-1, 2)
    if np.any(iv[:, 1] < iv[:, 0]) or np.any(iv[1:, 0] <= iv[:-1, 1]):
        raise ValueError("intervals must be [start, end] pairs with start <= end, disjoint and increasing")
    # A tolerance of a millionth of a step keeps an end that lands on the
    # lattice up to rounding.
    first = np.ceil(iv[:, 0] / step_s - 1e-6).astype(np.int64)
    last = np.floor(iv[:, 1] / step_s + 1e-6).astype(np.int64)
    counts = np.maximum(last - first + 1, 0)
    keep = counts > 0
    first, counts = first[keep], counts[keep]
    m = _positions(first, counts)
    return m * step_s, np.repeat(np.arange(first.size), counts), keep


def to_grid(t_src, x_src, t_grid) -> np.ndarray:
    """Linear interpolation of samples onto grid times.

    Parameters
    ----------
    t_src : array_like, shape (n,)
        Strictly increasing source times, s.
    x_src : array_like, shape (n,) or (n, k)
        Source values; a NaN neighbour makes the interpolated value NaN
        (unless the grid time coincides with a finite sample).
    t_grid : array_like, shape (m,)
        Grid times, s.

    Returns
    -------
    ndarray, shape (m,) or (m, k)
        Interpolated values; NaN outside [t_src[0], t_src[-1]]. Linear
        interpolation suits slow signals (envelope, mean wind) sampled well
        above their bandwidth, as here after the low-pass.
    """
    t_src = check_time(t_src, "t_src")
    x = np.asarray(x_src, dtype=float)
    if x.shape[0] != t_src.shape[0] or x.ndim > 2:
        raise ValueError(f"x_src must have shape (n,) or (n, k) with n = len(t_src) = {t_src.shape[0]}; got {x.shape}")
    tg = np.asarray(t_grid, dtype=float)
    if tg.ndim != 1:
        raise ValueError(f"t_grid must be one-dimensional; got shape {tg.shape}")
    i = np.clip(np.searchsorted(t_src, tg, side="right") - 1, 0, t_src.shape[0] - 2)
    w = (tg - t_src[i]) / (t_src[i + 1] - t_src[i])
    if x.ndim == 2:
        w = w[:, None]
    x0, x1 = x[i], x[i + 1]
    out = np.where(w == 0.0, x0, np.where(w == 1.0, x1, x0 + w * (x1 - x0)))
    outside = (tg < t_src[0]) | (tg > t_src[-1])
    out[outside] = np.nan
    return out


def check_time(t, name: str) -> np.ndarray:
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or t.shape[0] < 2:
        raise InputError(f"{name} must be a one-dimensional array of at least 2 times; got shape {t.shape}")
    if not np.all(np.isfinite(t)):
        raise InputError(f"{name} must be finite (times are authoritative; gaps are NaN in the data, not in time)")
    if np.any(np.diff(t) <= 0):
        raise InputError(f"{name} must be strictly increasing")
    return t


def as_2d(x: np.ndarray) -> np.ndarray:
    return x[:, None] if x.ndim == 1 else x


def run_rate(t: np.ndarray, i0: int, i1: int) -> float:
    """Mean sampling rate of samples i0..i1-1, Hz."""
    return (i1 - 1 - i0) / (t[i1 - 1] - t[i0])


def valid_runs(t, x: np.ndarray, max_gap_s: float):
    """Bridge short gaps and find the valid runs of a (n, k) stream.

    ``t`` is the time array, or a sampling rate (then only NaN splits runs).
    A sample is valid when all k channels are finite. Gaps whose missing
    duration is at most ``max_gap_s`` and that lie between valid samples
    without a time jump are filled by linear interpolation in time.

    Returns
    -------
    filled : ndarray (n, k), starts, ends : ndarray of int
    """
    x = as_2d(np.asarray(x, dtype=float))
    n = x.shape[0]
    if np.ndim(t) == 0:
        t = np.arange(n) / float(t)
        jumps = np.zeros(max(n - 1, 0), dtype=bool)
    else:
        dt = np.diff(t)
        jumps = dt > _TIME_JUMP_FACTOR * np.median(dt)
    valid = np.all(np.isfinite(x), axis=1)
    filled = x.copy()
    if max_gap_s > 0 and not valid.all() and valid.sum() >= 2:
        dt_nominal = float(np.median(np.diff(t)))
        g0, g1 = _run_bounds(~valid)
        inner = (g0 > 0) & (g1 < n)
        g0, g1 = g0[inner], g1[inner]
        missing = t[np.minimum(g1, n - 1)] - t[np.maximum(g0 - 1, 0)] - dt_nominal
        # A time jump next to or inside the gap means more is missing than the NaN count says.
        jump_count = np.concatenate(([0], np.cumsum(jumps)))
        no_jump = jump_count[g1] - jump_count[g0 - 1] == 0
        bridge = (missing <= max_gap_s * (1 + 1e-9)) & no_jump
        if np.any(bridge):
            pos = _positions(g0[bridge], g1[bridge] - g0[bridge])
            for c in range(x.shape[1]):
                filled[pos, c] = np.interp(t[pos], t[valid], x[valid, c])
            valid = valid.copy()
            valid[pos] = True
    starts, ends = _run_bounds(valid, jumps)
    return filled, starts, ends


def trusted_intervals(t: np.ndarray, starts: np.ndarray, ends: np.ndarray, edge_s: float) -> np.ndarray:
    """Intervals (k, 2) of the runs shrunk by edge_s at both ends; empty ones dropped."""
    iv = np.column_stack((t[starts] + edge_s, t[ends - 1] - edge_s)) if starts.size else np.empty((0, 2))
    return iv[iv[:, 1] > iv[:, 0]]


def intersect_intervals(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pairwise intersections of two sets of disjoint sorted intervals, sorted."""
    lo = np.maximum(a[:, None, 0], b[None, :, 0]).ravel()
    hi = np.minimum(a[:, None, 1], b[None, :, 1]).ravel()
    keep = hi > lo
    iv = np.column_stack((lo[keep], hi[keep]))
    return iv[np.argsort(iv[:, 0])]

