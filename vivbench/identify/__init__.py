"""The identification chain: preprocessing, derivatives, library, windowed SINDy, regimes."""

from vivbench.identify.clustering import KERNELS, DensityPeaks, coefficient_features, decision_graph, order_features
from vivbench.identify.derivative import DERIVATIVE_METHODS, Derivative, TVDerivativeResult, estimate_noise_std, tv_derivative
from vivbench.identify.engine import DEFAULT_THRESHOLDS, SOLVERS, StlsqPath, StlsqSettings, WindowedSINDy, aicc, stlsq_path, window_bounds
from vivbench.identify.forecast import CLIP_MODES, Simulation, forecast, forecast_coefficients, forecast_table, nmse, simulate_identified, window_in_force, window_ranges
from vivbench.identify.interpret import (
    FEATURE_SETS,
    CampaignWindows,
    ClusterConfig,
    ClusterResult,
    campaign_windows,
    cluster_scores,
    cluster_windows,
    read_result,
    standardized_coefficients,
    summarize_clusters,
)
from vivbench.identify.identifiability import basis_orders, order_contributions_basis, window_regimes
from vivbench.identify.noise_floor import band_noise_std, window_amplitude_snr
from vivbench.identify.optimizers import OPTIMIZERS, OptimizerOptions, ensemble_path, run_optimizer, sr3_path
from vivbench.identify.library import SCALINGS, WindowLibrary, condition_number, library_cond, window_library
from vivbench.identify.pooled import POOLED_NAME, PooledSINDy, pool_results, pooled_window_stats, with_campaign_model, write_pooled
from vivbench.identify.pipeline import IdentifyConfig, identify_event, identify_files, list_results, result_path
from vivbench.identify.refit import (
    EventRefit,
    RefitConfig,
    RefitResult,
    refit_coefficients,
    refit_event,
    simulate_coefficients,
)
from vivbench.identify.preprocess import (
    Preprocessed,
    PreprocessConfig,
    common_grid,
    displacement,
    envelope,
    mean_wind,
    modal_frequency,
    perpendicular_speed,
    preprocess_arrays,
    segments,
    to_grid,
    wind_speed_direction,
)

__all__ = [
    "DEFAULT_THRESHOLDS", "DERIVATIVE_METHODS", "Derivative", "IdentifyConfig", "PreprocessConfig", "Preprocessed",
    "SCALINGS", "SOLVERS", "StlsqPath", "StlsqSettings", "TVDerivativeResult", "WindowLibrary", "WindowedSINDy",
    "aicc", "basis_orders", "common_grid", "condition_number", "displacement", "envelope", "estimate_noise_std",
    "identify_event", "identify_files", "list_results", "library_cond", "mean_wind", "modal_frequency", "order_contributions_basis",
    "perpendicular_speed", "preprocess_arrays", "result_path", "segments", "stlsq_path", "to_grid", "tv_derivative",
    "window_bounds", "window_library", "window_regimes", "wind_speed_direction",
    "KERNELS", "DensityPeaks", "coefficient_features", "decision_graph", "order_features",
    "POOLED_NAME", "PooledSINDy", "pool_results", "pooled_window_stats", "with_campaign_model", "write_pooled",
    "CLIP_MODES", "Simulation", "forecast", "forecast_coefficients", "forecast_table", "nmse", "simulate_identified",
    "window_in_force", "window_ranges",
    "FEATURE_SETS", "CampaignWindows", "ClusterConfig", "ClusterResult", "campaign_windows", "cluster_scores",
    "cluster_windows", "read_result", "standardized_coefficients", "summarize_clusters",
    "OPTIMIZERS", "OptimizerOptions", "ensemble_path", "run_optimizer", "sr3_path",
    "EventRefit", "RefitConfig", "RefitResult", "refit_coefficients", "refit_event", "simulate_coefficients",
    "band_noise_std", "window_amplitude_snr",
]
