"""Wind and vibration preprocessing, the envelope, its noise floor, sliding windows and differentiation (DESIGN 3.1)."""

from vivbench.preprocess.band import band_gain
from vivbench.preprocess.chain import (
    PreprocessConfig,
    Preprocessed,
    wind_speed_direction,
    perpendicular_speed,
    mean_wind,
    modal_frequency,
    welch_psd,
    spectral_peak,
    displacement,
    envelope,
    segments,
    common_grid,
    to_grid,
    preprocess_arrays,
)
from vivbench.preprocess.derivative import (
    DERIVATIVE_METHODS,
    Derivative,
    TVDerivativeResult,
    estimate_noise_std,
    tv_derivative,
)
from vivbench.preprocess.noise_floor import band_noise_std, window_amplitude_snr
from vivbench.preprocess.windows import window_bounds

__all__ = [
    "band_gain", "PreprocessConfig", "Preprocessed", "wind_speed_direction", "perpendicular_speed",
    "mean_wind", "modal_frequency", "welch_psd", "spectral_peak", "displacement", "envelope", "segments",
    "common_grid", "to_grid", "preprocess_arrays", "DERIVATIVE_METHODS", "Derivative", "TVDerivativeResult",
    "estimate_noise_std", "tv_derivative", "band_noise_std", "window_amplitude_snr", "window_bounds",
]
