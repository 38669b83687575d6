"""Settings of the preprocessing chain (docs/field_workflow.md)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vivbench.core.errors import InputError
from vivbench.preprocess.runs import check_positive

__all__ = ["PreprocessConfig"]


# The dropped edge must cover this many time constants of each filter.
_SETTLING_TIME_CONSTANTS = 3.0


@dataclass(frozen=True, kw_only=True)
class PreprocessConfig:
    """Settings of the preprocessing chain.

    Parameters
    ----------
    wind_cutoff_hz : float
        Cut-off of the low-pass that turns U~ into the mean wind U, Hz. The
        default 1/60 Hz keeps the dynamics of the 10-60 min mean wind
        (docs/concepts.md (the bridge and the wind)) and removes turbulence with periods shorter than about a
        minute; a 50 s SINDy window then sees a nearly constant U, as the
        paper's amplitude equation assumes.
    wind_filter_order : int
        Order of the Butterworth low-pass. It is applied forward and backward
        (``scipy.signal.sosfiltfilt``): zero phase, squared magnitude, so U is
        not delayed with respect to A.
    band_half_width : float
        Half-width of the vibration band as a fraction of the modal
        frequency, 0 < value < 1 (default 0.3: the band is f_mode +- 30 %).
        Narrow it when other modes lie within 30 % of the VIV mode.
    band_half_width_hz : float or None
        Half-width of the band in Hz; when given it replaces
        ``band_half_width``.
    band_taper : float
        Fraction of the half-width over which the band's gain falls from 1 to
        0 along a raised cosine (0 < value <= 1). Smooth edges keep the ringing
        of the band filter short.
    modal_frequency_hz : float or None
        Frequency of the vibration mode, Hz. None (default) finds it from the
        acceleration spectrum in ``search_band_hz``: other bridges have other
        modes.
    search_band_hz : tuple of float
        (low, high) band searched for the spectral peak when the modal
        frequency is not given, Hz.
    welch_segment_s : float
        Length of the Welch sections of the spectrum, s (resolution about
        1 / value Hz before the peak is interpolated).
    edge_s : float
        Seconds dropped at both ends of every valid run of each stream, at
        least: the chain drops max(edge_s, three time constants of either
        filter), see :meth:`settling_s`. The time constants are
        1 / (2 pi wind_cutoff_hz) for the wind low-pass (9.5 s by default) and
        1 / (pi band_taper half-width) for the vibration band, whose ringing
        is set by its raised-cosine edges (6.5 s for the default band around
        0.327 Hz). The default 60 s covers both for modes above about 0.11 Hz:
        the band filter's end ringing has then decayed over several of its
        time constants.
    grid_step_s : float
        Step of the output grid, s. Grid times are integer multiples of the
        step (counted from the record's start time), so grids of different
        records and of the truth line up. A few Hz is plenty: A and U are slow.
    max_gap_s : float
        Longest gap (missing duration, s) bridged by linear interpolation
        before filtering. The default 0 bridges nothing: any NaN sample splits
        the record. Set it to a few sample steps to bridge isolated dropouts.
    min_segment_s : float
        Shortest output segment kept, s (after the edges are dropped). The
        default 60 s holds one 50 s SINDy window.
    """

    wind_cutoff_hz: float = 1.0 / 60.0
    wind_filter_order: int = 4
    band_half_width: float = 0.3
    band_half_width_hz: float | None = None
    band_taper: float = 0.5
    modal_frequency_hz: float | None = None
    search_band_hz: tuple[float, float] = (0.05, 2.0)
    welch_segment_s: float = 300.0
    edge_s: float = 60.0
    grid_step_s: float = 0.25
    max_gap_s: float = 0.0
    min_segment_s: float = 60.0

    def __post_init__(self) -> None:
        check_positive("wind_cutoff_hz", self.wind_cutoff_hz)
        order = self.wind_filter_order
        if isinstance(order, bool) or not (isinstance(order, (int, np.integer)) and 1 <= order <= 10):
            raise InputError(f"wind_filter_order must be an integer from 1 to 10; got {self.wind_filter_order!r}")
        if not (isinstance(self.band_half_width, (int, float)) and 0.0 < self.band_half_width < 1.0):
            raise InputError(
                f"band_half_width is a fraction of the modal frequency and must lie strictly between 0 and 1; "
                f"got {self.band_half_width!r}"
            )
        if self.band_half_width_hz is not None:
            check_positive("band_half_width_hz", self.band_half_width_hz)
        if not (isinstance(self.band_taper, (int, float)) and 0.0 < self.band_taper <= 1.0):
            raise InputError(f"band_taper must lie in (0, 1]; got {self.band_taper!r}")
        if self.modal_frequency_hz is not None:
            check_positive("modal_frequency_hz", self.modal_frequency_hz)
        band = tuple(self.search_band_hz)
        if len(band) != 2 or not all(math.isfinite(b) for b in band) or not 0.0 < band[0] < band[1]:
            raise InputError(f"search_band_hz must be (low, high) with 0 < low < high, Hz; got {self.search_band_hz!r}")
        object.__setattr__(self, "search_band_hz", (float(band[0]), float(band[1])))
        check_positive("welch_segment_s", self.welch_segment_s)
        check_positive("grid_step_s", self.grid_step_s)
        check_positive("min_segment_s", self.min_segment_s)
        if not (isinstance(self.max_gap_s, (int, float)) and math.isfinite(self.max_gap_s) and self.max_gap_s >= 0):
            raise InputError(f"max_gap_s must be a finite number >= 0 (0 bridges no gap); got {self.max_gap_s!r}")
        if not (isinstance(self.edge_s, (int, float)) and math.isfinite(self.edge_s) and self.edge_s >= 0):
            raise InputError(f"edge_s must be a finite number of seconds >= 0; got {self.edge_s!r}")

    @property
    def wind_settling_s(self) -> float:
        """Three time constants of the wind low-pass, 3 / (2 pi wind_cutoff_hz), s."""
        return _SETTLING_TIME_CONSTANTS / (2.0 * math.pi * self.wind_cutoff_hz)

    def half_width_hz(self, f_mode: float) -> float:
        """Half-width of the vibration band around ``f_mode`` (Hz), Hz."""
        if self.band_half_width_hz is not None:
            return float(self.band_half_width_hz)
        return float(self.band_half_width * f_mode)

    def band_settling_s(self, f_mode: float) -> float:
        """Three time constants of the band filter around ``f_mode`` (Hz), 3 / (pi taper half-width), s."""
        return _SETTLING_TIME_CONSTANTS / (math.pi * self.band_taper * self.half_width_hz(f_mode))

    def settling_s(self, f_mode: float) -> float:
        """Edge dropped at each end of every valid run for a mode at ``f_mode`` (Hz), s."""
        return max(float(self.edge_s), self.wind_settling_s, self.band_settling_s(f_mode))

