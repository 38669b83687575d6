"""Preprocessing of the identification chain (docs/field_workflow.md): raw arrays to A and U on one grid.

The chain follows the paper's Section III. Wind: the horizontal speed V and
direction theta come from the east and north components, the component
perpendicular to the span is U~ = V |sin(theta - span azimuth)|, and the
slowly varying mean wind U is a zero-phase low-pass of U~. Vibration: the
vertical acceleration is integrated twice in the frequency domain inside a
band around the VIV mode, and the amplitude A is the Hilbert envelope of that
displacement. Both are put on one coarse time grid (the envelope and the mean
wind are slow) after dropping the samples that the filters corrupt near every
end of the record and near every gap.

Conventions
-----------
- ``u`` points east, ``v`` north (the event file's axes, docs/formats.md).
- ``theta`` is meteorological: the direction the wind blows *from*, in degrees
  clockwise from north in [0, 360). A wind from the west (blowing east,
  ``u > 0, v = 0``) has theta = 270.
- ``span_azimuth_deg`` is the direction of the span axis, degrees clockwise
  from north; azimuths a and a + 180 describe the same span. The wind is
  perpendicular to the span when theta - azimuth is 90 or 270 degrees (the
  paper's Fig. 2) and U~ = V there.

Gaps
----
Gaps are NaN blocks (docs/formats.md), or jumps in the time stamps. Nothing is
interpolated across a gap unless it is no longer than
``PreprocessConfig.max_gap_s`` (default 0: never). Every contiguous valid run
of a stream is filtered on its own and loses ``edge_s`` at both ends; the
output keeps the times trusted by both streams, split into numbered segments.
A time stamp is valid only when every section of the stream is finite there
(``u`` and ``v`` for the wind, ``acc`` for the vibration), so that all
sections share one grid and one segment numbering.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vivbench.preprocess.noise_floor import band_noise_std
from vivbench.preprocess.config import PreprocessConfig
from vivbench.preprocess.runs import as_2d, check_time, grid_of_intervals, intersect_intervals, run_rate, to_grid, trusted_intervals, valid_runs
from vivbench.preprocess.vibration import displacement, envelope, spectral_peak, welch_psd
from vivbench.preprocess.wind import mean_wind_runs, perpendicular_wind

__all__ = ["Preprocessed", "preprocess_arrays"]


@dataclass(frozen=True, kw_only=True, eq=False)
class Preprocessed:
    """Result of :func:`preprocess_arrays`.

    Attributes
    ----------
    t : ndarray, shape (n,)
        Output grid, s from the record's start time.
    A : ndarray, shape (n, n_sections)
        Displacement amplitude (Hilbert envelope), m.
    U : ndarray, shape (n, n_sections)
        Mean wind speed perpendicular to the span, m/s.
    segment : ndarray of int, shape (n,)
        Contiguous segment of each grid time, 0, 1, ... in time order. Never
        differentiate or window across a change of segment.
    segment_bounds : ndarray, shape (n_segments, 2)
        Trusted interval [start, end] of each segment, s.
    edge_s : float
        Edge dropped at each end of every valid run, s
        (``config.settling_s(f_mode_hz)``).
    f_mode_hz : float
        Modal frequency used, Hz.
    f_mode_source : str
        ``"given"`` (from the configuration) or ``"spectrum"`` (found).
    band_hz : tuple of float
        (low, high) edges of the vibration band where the gain reaches 0, Hz.
    span_azimuth_deg : float
        Span azimuth used, degrees from north.
    config : PreprocessConfig
        The settings.
    noise_std : ndarray, shape (n_sections,)
        Accelerometer noise after integration to displacement in the band, m:
        the noise floor of A (:mod:`vivbench.preprocess.noise_floor`); NaN
        where it could not be estimated.
    """

    t: np.ndarray
    A: np.ndarray
    U: np.ndarray
    segment: np.ndarray
    segment_bounds: np.ndarray
    edge_s: float
    f_mode_hz: float
    f_mode_source: str
    band_hz: tuple[float, float]
    span_azimuth_deg: float
    config: PreprocessConfig
    noise_std: np.ndarray

    @property
    def n_segments(self) -> int:
        """Number of contiguous segments."""
        return int(self.segment_bounds.shape[0])


# --------------------------------------------------------------------------- wind


# ---------------------------------------------------------------------- vibration


# ------------------------------------------------------------------ gaps and grid


# --------------------------------------------------------------------- the chain


def preprocess_arrays(
    *,
    wind_time,
    u,
    v,
    accel_time,
    acc,
    span_azimuth_deg: float,
    config: PreprocessConfig | None = None,
) -> Preprocessed:
    """Whole preprocessing chain on arrays: A and U of every section on one grid.

    Parameters
    ----------
    wind_time : array_like, shape (n_w,)
        Anemometer times, s from the record's start (nominally 32 Hz).
    u, v : array_like, shape (n_w, n_sections) or (n_w,)
        Eastward and northward wind, m/s; NaN marks missing data.
    accel_time : array_like, shape (n_a,)
        Accelerometer times, s from the same start (nominally 50 Hz).
    acc : array_like, shape (n_a, n_sections) or (n_a,)
        Vertical deck acceleration, m/s^2; NaN marks missing data.
    span_azimuth_deg : float
        Direction of the span axis, degrees from north (from the event file).
    config : PreprocessConfig, optional
        Settings; defaults as documented there.

    Returns
    -------
    Preprocessed
        The grid, A (m), U (m/s), segment ids and the settings used. The
        output may be empty (no segment long enough); ``n_segments`` says so.

    Notes
    -----
    The modal frequency, when not given, is found once from the whole record
    (all sections and valid runs) and used for every section and segment.
    Each valid run of each stream is processed on its own and trusted from
    ``edge_s`` after its start to ``edge_s`` before its end (``edge_s`` =
    ``config.settling_s(f_mode)``, reported in the result); the output
    segments are the intersections of the two streams' trusted intervals
    that last at least ``min_segment_s``.
    """
    config = PreprocessConfig() if config is None else config
    wind_time = check_time(wind_time, "wind_time")
    accel_time = check_time(accel_time, "accel_time")
    U_tilde = perpendicular_wind(wind_time, u, v, span_azimuth_deg)
    acc = as_2d(np.asarray(acc, dtype=float))
    if acc.ndim != 2 or acc.shape[0] != accel_time.shape[0]:
        raise ValueError(
            f"acc must have shape (n,) or (n, n_sections) with n = len(accel_time) = {accel_time.shape[0]}; "
            f"got {acc.shape}"
        )
    if acc.shape[1] != U_tilde.shape[1]:
        raise ValueError(f"the wind has {U_tilde.shape[1]} sections but the acceleration has {acc.shape[1]}")

    lo, hi = config.search_band_hz
    if config.modal_frequency_hz is not None:
        f_mode, source = float(config.modal_frequency_hz), "given"
        try:
            f_psd, psd = welch_psd(accel_time, acc, config.welch_segment_s, lo, hi)
        except ValueError:  # a given mode needs no spectrum; the noise floor stays unknown
            f_psd = psd = None
    else:
        # One spectrum serves the mode and the noise floor.
        f_psd, psd = welch_psd(accel_time, acc, config.welch_segment_s, lo, hi)
        f_mode, source = spectral_peak(f_psd, psd.sum(axis=1), lo, hi), "spectrum"
    half_width = config.half_width_hz(f_mode)
    if psd is None:
        noise_std = np.full(acc.shape[1], np.nan)
    else:
        noise_std = band_noise_std(f_psd, psd, f_mode, half_width, taper=config.band_taper)
    edge_s = config.settling_s(f_mode)

    U_wind, (w_starts, w_ends) = mean_wind_runs(wind_time, U_tilde, config)
    wind_iv = trusted_intervals(wind_time, w_starts, w_ends, edge_s)

    acc_filled, a_starts, a_ends = valid_runs(accel_time, acc, config.max_gap_s)
    A_acc = np.full_like(acc_filled, np.nan)
    for i0, i1 in zip(a_starts, a_ends):
        # Runs that leave nothing once the edges are dropped are not worth filtering.
        if accel_time[i1 - 1] - accel_time[i0] <= 2.0 * edge_s:
            continue
        y = displacement(
            acc_filled[i0:i1], run_rate(accel_time, i0, i1), f_mode, half_width, taper=config.band_taper
        )
        A_acc[i0:i1] = envelope(y)
    accel_iv = trusted_intervals(accel_time, a_starts, a_ends, edge_s)

    iv = intersect_intervals(wind_iv, accel_iv)
    iv = iv[iv[:, 1] - iv[:, 0] >= config.min_segment_s]
    t_grid, seg, holds = grid_of_intervals(iv, config.grid_step_s)
    iv = iv[holds]
    A = to_grid(accel_time, A_acc, t_grid)
    U = to_grid(wind_time, U_wind, t_grid)
    return Preprocessed(
        t=t_grid,
        A=A,
        U=U,
        segment=seg,
        segment_bounds=iv,
        edge_s=edge_s,
        f_mode_hz=f_mode,
        f_mode_source=source,
        band_hz=(f_mode - half_width, f_mode + half_width),
        span_azimuth_deg=float(span_azimuth_deg),
        config=config,
        noise_std=noise_std,
    )
