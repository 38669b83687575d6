"""Wind and vibration preprocessing, the envelope, its noise floor, sliding windows and differentiation (docs/field_workflow.md)."""

from vivbench.preprocess.band import band_gain
from vivbench.preprocess.chain import Preprocessed, preprocess_arrays
from vivbench.preprocess.config import PreprocessConfig
from vivbench.preprocess.derivative import (
    DERIVATIVE_METHODS,
    Derivative,
    TVDerivativeResult,
    estimate_noise_std,
    tv_derivative,
)
from vivbench.preprocess.noise_floor import band_noise_std, window_amplitude_snr
from vivbench.preprocess.runs import (
    check_positive,
    check_time,
    as_2d,
    run_rate,
    valid_runs,
    mask_runs,
    gap_steps,
    first_gap,
    trusted_intervals,
    intersect_intervals,
    segments,
    common_grid,
    grid_of_intervals,
    to_grid,
)
from vivbench.preprocess.vibration import welch_psd, spectral_peak, modal_frequency, displacement, envelope
from vivbench.preprocess.wind import (
    wind_speed_direction,
    perpendicular_speed,
    mean_wind,
    perpendicular_wind,
    mean_wind_runs,
)
from vivbench.preprocess.windows import window_bounds
from vivbench.preprocess.wind_smoothing import smooth_wind
from vivbench.preprocess.unmeasured_wind import (UNMEASURED_WIND_PRIORS, shifted_unmeasured_wind, unmeasured_wind_error,
                                                 unmeasured_wind_rms)
from vivbench.preprocess.yaw import event_yaw, mean_yaw
from vivbench.preprocess.event_detection import EventDetection, EventDetectionConfig, detect_events
from vivbench.preprocess.event_log import CATALOGUE_COLUMNS, EventCatalogue, cut_events, find_events

__all__ = [
    "band_gain", "Preprocessed", "preprocess_arrays", "PreprocessConfig", "DERIVATIVE_METHODS", "Derivative",
    "TVDerivativeResult", "estimate_noise_std", "tv_derivative", "band_noise_std", "window_amplitude_snr",
    "check_positive", "check_time", "as_2d", "run_rate", "valid_runs", "mask_runs", "gap_steps", "first_gap", "trusted_intervals",
    "intersect_intervals", "segments", "common_grid", "grid_of_intervals", "to_grid", "welch_psd",
    "spectral_peak", "modal_frequency", "displacement", "envelope", "wind_speed_direction",
    "perpendicular_speed", "mean_wind", "perpendicular_wind", "mean_wind_runs", "window_bounds", "mean_yaw",
    "event_yaw", "smooth_wind", "UNMEASURED_WIND_PRIORS", "unmeasured_wind_error",
    "unmeasured_wind_rms", "shifted_unmeasured_wind", "EventDetection", "EventDetectionConfig", "detect_events", "CATALOGUE_COLUMNS",
    "EventCatalogue", "cut_events", "find_events",
]
