"""Data quality of sensor records: plausibility of units, spikes, dropouts, a wind that never varies.

Used on the two paths a user's data takes: :mod:`vivbench.io.fieldimport` (raw
field files to an event file) and :func:`vivbench.analysis.identify_event`
(event file to identification). Each problem is either repaired, with the
repair counted in ``quality_*`` attributes of the output, or refused with a
one-line :class:`ValueError` that says what is wrong and how to fix it.

Repairs
-------
- Spikes: a sample further than ``threshold`` robust standard deviations
  (1.4826 x the median absolute deviation, MAD) from the median of its block
  of ``block_s`` seconds, and as far from the median of its 7 nearest
  samples, is replaced by NaN (runs up to 0.1 s are bridged linearly by the
  identification). Blocks are short (10 s, about
  three cycles of a 0.3 Hz VIV mode) so that the growth of a vibration is not
  mistaken for spikes; a sinusoid's peaks lie about one robust standard
  deviation from its median, far below the default of 8.
- NaN (dropouts, spikes removed): the preprocessing splits the record into
  segments at every NaN (see :mod:`vivbench.preprocess.chain`).

Refusals
--------
- Acceleration whose magnitude no bridge deck reaches (robust RMS, 1.4826
  MAD, above :data:`MAX_ACC_RMS`), or whose median is 1 g in another unit (gravity seen by
  an accelerometer that reports in g, milli-g or mm/s^2): the hint names the
  unit it looks like. Acceleration in g WITHOUT a gravity offset is 9.8 times
  too small but otherwise plausible and cannot be told from a quiet deck by
  magnitude: that mistake is not detected.
- Wind whose median horizontal speed exceeds :data:`MAX_WIND_SPEED` (km/h or
  knots given as m/s beyond storm speeds). A wind in km/h below that is not
  detected.
- A wind that never varies at a section: the library's U terms are then
  collinear with the constant term and no model is identifiable.
"""

from __future__ import annotations

import warnings

import numpy as np
from scipy import ndimage
from vivbench.core.errors import InputError

__all__ = [
    "G",
    "MAX_ACC_RMS",
    "MAX_WIND_SPEED",
    "MIN_WIND_STD",
    "ACC_UNITS",
    "WIND_UNITS",
    "despike",
    "check_acc_magnitude",
    "check_wind_magnitude",
    "check_wind_varies",
]

#: Standard gravity, m/s^2.
G = 9.80665
#: Largest plausible RMS of a bridge deck's vertical acceleration, m/s^2 (0.5 g;
#: comfort limits are about 0.5 m/s^2 and strong VIV of long spans stays near 1 m/s^2).
MAX_ACC_RMS = 5.0
#: Largest plausible median horizontal wind speed over an event, m/s.
MAX_WIND_SPEED = 75.0
#: A section's perpendicular wind with a standard deviation below this (m/s) never varies.
MIN_WIND_STD = 1e-3
#: Accepted acceleration units (exact strings) and their factor to m/s^2.
ACC_UNITS = {
    "m/s^2": 1.0, "m s-2": 1.0, "m/s2": 1.0,
    "g": G,
    "mm/s^2": 1e-3, "mm s-2": 1e-3, "mm/s2": 1e-3,
    "milli-g": 1e-3 * G, "mg": 1e-3 * G,
}
#: Accepted wind units (exact strings) and their factor to m/s.
WIND_UNITS = {
    "m/s": 1.0, "m s-1": 1.0,
    "km/h": 1.0 / 3.6,
    "knots": 1852.0 / 3600.0, "kn": 1852.0 / 3600.0, "kt": 1852.0 / 3600.0,
}
# Gravity offset recognised when the mean is within this fraction of 1 g.
_GRAVITY_TOLERANCE = 0.1
# Robust scale of a normal sample from its MAD.
_MAD_TO_SIGMA = 1.4826
# Samples of the short median a spike must also stand out from: runs of up to 3 samples are spikes.
_SHORT_WINDOW = 7


def _block_nanmedian(blocks: np.ndarray) -> np.ndarray:
    """Median over axis 1 ignoring NaN, shape (n_blocks, 1, k).

    Plain medians for the blocks without NaN (nearly all of them: numpy's
    NaN-aware median is several times slower); the NaN-aware one only for the
    few blocks with gaps or padding. A block that is all NaN (a dropout) has no
    median; its samples stay NaN.
    """
    med = np.median(blocks, axis=1, keepdims=True)
    gaps = np.isnan(med[:, 0, :])
    if gaps.any():
        b, j = np.nonzero(gaps)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            med[b, 0, j] = np.nanmedian(blocks[b, :, j], axis=1)
    return med


def despike(x, rate_hz: float, *, threshold: float = 8.0, block_s: float = 10.0, floor: float = 0.0,
            bridge_s: float = 0.0):
    """Replace spikes by NaN with a blockwise median / MAD rule.

    Parameters
    ----------
    x : array_like, shape (n,) or (n, k)
        Samples at a nominally uniform rate; NaN marks missing data.
    rate_hz : float
        Sampling rate, Hz (sets the block length).
    threshold : float
        Spike when ``|x - median| > threshold * 1.4826 * max(MAD, floor)``
        within the sample's block AND the sample is that far from the median
        of its 7 nearest samples (a spike is short: runs of up to 3 samples;
        a gust whose neighbours are as high is not a spike). Infinite values
        are always spikes.
    block_s : float
        Block length, s.
    floor : float
        Lower bound of the MAD, unit of ``x`` (sensor resolution), so that a
        block of constant or quantised samples does not flag every change.
    bridge_s : float
        Runs of spike samples no longer than this (s) between two valid
        samples are filled by linear interpolation instead of NaN, so that an
        isolated spike does not split the record. Original NaN are never filled.

    Returns
    -------
    cleaned : ndarray, shape of ``x`` (float64)
        ``x`` with the spikes set to NaN (or bridged).
    n_spikes : int
        Number of spike samples found.
    n_bridged : int
        Number of them filled by interpolation.
    """
    if not (threshold > 0 and block_s > 0 and rate_hz > 0 and floor >= 0):
        raise InputError(
            f"despike needs threshold, block_s, rate_hz > 0 and floor >= 0; got {threshold}, {block_s}, {rate_hz}, {floor}"
        )
    x = np.array(x, dtype=np.float64)
    shape = x.shape
    x2 = x.reshape(shape[0], -1)
    n, k = x2.shape
    length = max(int(round(block_s * rate_hz)), 3)
    n_blocks = -(-n // length)
    padded = np.full((n_blocks * length, k), np.nan)
    padded[:n] = x2
    blocks = padded.reshape(n_blocks, length, k)
    med = _block_nanmedian(blocks)
    mad = _block_nanmedian(np.abs(blocks - med))
    limit = threshold * _MAD_TO_SIGMA * np.maximum(mad, floor)
    with np.errstate(invalid="ignore"):
        far = np.abs(blocks - med) > limit
        limit_rows = np.broadcast_to(limit, blocks.shape).reshape(-1, k)[:n]
    # A spike is also short: it stands out from the median of its 7 nearest samples,
    # which a gust or the growth of a vibration (neighbours as high) does not.
    # Missing samples count as the block median there (NaN-aware medians are slow).
    med_rows = np.broadcast_to(med, blocks.shape).reshape(-1, k)[:n]
    filled = np.where(np.isfinite(x2), x2, np.nan_to_num(med_rows))
    spike = far.reshape(-1, k)[:n].copy()
    rows, cols = np.nonzero(spike)
    if rows.size:
        # The short median only where the block rule already fired (rare):
        # a running median over every sample cost more than the rest of the
        # screening. Reflection without repeating the edge sample, as
        # scipy.ndimage's "mirror" mode, so the result equals median_filter's.
        half = _SHORT_WINDOW // 2
        if n > half:
            padded_rows = np.pad(filled, ((half, half), (0, 0)), mode="reflect")
            near = padded_rows[rows[:, None] + np.arange(_SHORT_WINDOW)[None, :], cols[:, None]]
            local = np.median(near, axis=1)
        else:
            local = ndimage.median_filter(filled, size=(_SHORT_WINDOW, 1), mode="mirror")[rows, cols]
        with np.errstate(invalid="ignore"):
            spike[rows, cols] = np.abs(x2[rows, cols] - local) > limit_rows[rows, cols]
    spike |= np.isinf(x2)
    x2[spike] = np.nan
    max_run = int(np.floor(bridge_s * rate_hz + 1e-9))
    n_bridged = 0
    if max_run > 0 and spike.any():
        idx = np.arange(n)
        for j in np.flatnonzero(spike.any(axis=0)):  # a few channels, not a loop over samples
            ok = np.isfinite(x2[:, j])
            if ok.sum() < 2:
                continue
            prev = np.maximum.accumulate(np.where(ok, idx, -1))
            nxt = np.minimum.accumulate(np.where(ok, idx, n)[::-1])[::-1]
            # Bridge only runs made of spikes alone, with valid samples on both sides.
            spike_only = np.concatenate(([0], np.cumsum(~ok & ~spike[:, j])))
            fill = spike[:, j] & (prev >= 0) & (nxt < n) & (nxt - prev - 1 <= max_run)
            fill &= spike_only[np.minimum(nxt, n - 1)] - spike_only[np.maximum(prev, 0)] == 0
            if fill.any():
                x2[fill, j] = np.interp(idx[fill], idx[ok], x2[ok, j])
                n_bridged += int(fill.sum())
    return x2.reshape(shape), int(spike.sum()), n_bridged


def _robust_stats(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Median and robust standard deviation (1.4826 MAD) of each column, ignoring NaN and inf.

    Robust so that a few spikes cannot make a record look like another unit.
    """
    x = np.where(np.isfinite(values), values, np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        med = np.nanmedian(x, axis=0)
        scale = _MAD_TO_SIGMA * np.nanmedian(np.abs(x - med), axis=0)
    return np.atleast_1d(med), np.atleast_1d(scale)


def check_acc_magnitude(acc, units: str = "m/s^2", *, where: str = "acc", labels=None, fix: str = "in the mapping") -> None:
    """Refuse acceleration whose magnitude betrays the wrong unit.

    The level is the median and the spread the robust standard deviation
    (1.4826 MAD) of each column, so that spikes do not count.

    Parameters
    ----------
    acc : array_like, shape (n,) or (n, k)
        Raw values in ``units`` (NaN allowed).
    units : str
        Declared unit, a key of :data:`ACC_UNITS`.
    where : str
        Start of the message (file name and column).
    labels : sequence of str, optional
        Names of the k columns (sections) for the message.
    fix : str
        Where the unit is set, completing "set units = ... <fix>".

    Raises
    ------
    ValueError
        One line: the measured magnitude, what it looks like, and the fix.
    """
    factor = ACC_UNITS[units]
    raw = np.asarray(acc, dtype=np.float64).reshape(np.shape(acc)[0], -1)
    labels = list(labels) if labels is not None else [str(j) for j in range(raw.shape[1])]
    med, spread = _robust_stats(raw)
    for j, label in enumerate(labels):
        if not np.isfinite(med[j]):
            continue
        level = f"acc median {med[j]:.3g}, robust RMS {spread[j]:.3g}"
        mean_si, std_si = med[j] * factor, spread[j] * factor
        if abs(abs(mean_si) / G - 1.0) <= _GRAVITY_TOLERANCE and std_si <= MAX_ACC_RMS:
            continue  # gravity in the declared unit: a static offset the band filter removes
        gravity_in = [u for u in _ACC_CANONICAL if ACC_UNITS[u] != factor
                      and abs(abs(med[j]) * ACC_UNITS[u] / G - 1.0) <= _GRAVITY_TOLERANCE]
        if gravity_in:
            cand = gravity_in[0]
            raise InputError(
                f"{where} {label}: {level} (declared {units}) looks like {cand} including gravity; "
                f'set units = "{cand}" {fix}'
            )
        if std_si > MAX_ACC_RMS:
            cands = [u for u in _ACC_CANONICAL if spread[j] * ACC_UNITS[u] <= MAX_ACC_RMS and ACC_UNITS[u] < factor]
            hint = " or ".join(f'"{u}"' for u in cands) if cands else "a smaller unit"
            si = f" = {std_si:.3g} m/s^2" if factor != 1.0 else ""
            raise InputError(
                f"{where} {label}: {level} {units}{si} is implausible for a bridge deck (limit {MAX_ACC_RMS:g} m/s^2); "
                f"it looks like {hint}: set units = {hint} {fix}"
            )


_ACC_CANONICAL = ("m/s^2", "g", "mm/s^2", "mg")
_WIND_CANONICAL = ("m/s", "km/h", "knots")


def check_wind_magnitude(u, v, units: str = "m/s", *, where: str = "wind", labels=None, fix: str = "in the mapping") -> None:
    """Refuse horizontal wind whose median speed exceeds :data:`MAX_WIND_SPEED` in m/s.

    Parameters
    ----------
    u, v : array_like, shape (n,) or (n, k)
        Raw east and north components in ``units`` (a key of :data:`WIND_UNITS`).
    where, labels, fix : as for :func:`check_acc_magnitude`.
    """
    factor = WIND_UNITS[units]
    u = np.asarray(u, dtype=np.float64)
    speed = np.hypot(u, np.asarray(v, dtype=np.float64)).reshape(u.shape[0], -1)
    speed = np.where(np.isfinite(speed), speed, np.nan)
    labels = list(labels) if labels is not None else [str(j) for j in range(speed.shape[1])]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        med = np.atleast_1d(np.nanmedian(speed, axis=0))
    for j, label in enumerate(labels):
        if np.isfinite(med[j]) and med[j] * factor > MAX_WIND_SPEED:
            cands = [w for w in _WIND_CANONICAL if WIND_UNITS[w] < factor and med[j] * WIND_UNITS[w] <= MAX_WIND_SPEED]
            hint = " or ".join(f'"{w}"' for w in cands) if cands else "another unit"
            raise InputError(
                f"{where} {label}: median horizontal wind speed {med[j]:.3g} {units}"
                + (f" = {med[j] * factor:.3g} m/s" if factor != 1.0 else "")
                + f" is beyond any storm (limit {MAX_WIND_SPEED:g} m/s); it looks like {hint}: set units = {hint} {fix}"
            )


def check_wind_varies(U_tilde, *, where: str = "wind", labels=None) -> None:
    """Refuse a wind that never varies at some section.

    Parameters
    ----------
    U_tilde : array_like, shape (n, k)
        Perpendicular wind speed of each section, m/s (NaN allowed).

    Raises
    ------
    ValueError
        When a section's standard deviation over its finite samples is below
        :data:`MIN_WIND_STD`: the library terms in U are then collinear with
        the constant term (a singular library).
    """
    x = np.asarray(U_tilde, dtype=np.float64)
    x = np.where(np.isfinite(x), x, np.nan).reshape(x.shape[0], -1)
    labels = list(labels) if labels is not None else [str(j) for j in range(x.shape[1])]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        std = np.atleast_1d(np.nanstd(x, axis=0))
    flat = [lab for lab, s in zip(labels, std) if np.isfinite(s) and s < MIN_WIND_STD]
    if flat:
        raise InputError(
            f"{where}: the wind perpendicular to the span never varies at {', '.join(flat)} (standard deviation "
            f"below {MIN_WIND_STD:g} m/s): the library's U terms are collinear with the constant term, so no model "
            f"is identifiable; check the anemometer"
        )
