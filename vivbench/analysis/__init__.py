"""The identification chain over events and campaigns, density-peaks clustering and its interpretation."""

from vivbench.analysis.clustering import (
    KERNELS,
    DensityPeaks,
    coefficient_features,
    decision_graph,
    order_features,
)
from vivbench.analysis.greybox import GreyBoxOutcome, campaign_warm_start, greybox_results, results_frequency
from vivbench.analysis.identify import IdentifyConfig, identify_event, identify_files
from vivbench.analysis.interpret import (
    FEATURE_SETS,
    ClusterConfig,
    CampaignWindows,
    ClusterResult,
    campaign_windows,
    cluster_scores,
    cluster_windows,
    standardized_coefficients,
    summarize_clusters,
)
from vivbench.analysis.pool import (
    CAMPAIGN_DERIVATIVE,
    pool_results,
    records_from_results,
    with_campaign_model,
    campaign_model_file,
    load_campaign_model,
    campaign_wind_smoothing,
)
from vivbench.analysis.held_out import (
    CRITERIA,
    RANK_LEVEL,
    confidence_set,
    dynamics_by_wind,
    event_folds,
    fit_group,
    fit_task,
    held_out_loss,
    held_out_losses,
    held_out_task,
    one_se_set,
    rank_p_values,
    shared_groups,
    variant_params,
)
from vivbench.analysis.candidates import settle_candidates, yaw_free_counterpart
from vivbench.analysis.selection import (
    VARYING_OPTIONS,
    MODEL_CLASSES,
    POOLED_COMPLEXITY,
    VARYING_PRIORS,
    Candidate,
    LIMIT_TIME_CONSTANTS,
    ModelSelection,
    SINGLE_SECTION_SHARE,
    STRUCTURAL_OPTIONS,
    perturbed_wind,
    varying_selection,
    wind_error_scale,
    without_yaw,
)
from vivbench.analysis.time_constant import amplitude_slope, envelope_time_constant, short_events, valid_span
from vivbench.analysis.wind_inputs import with_yaw
from vivbench.analysis.wind_local import WIND_BINS, window_wind, wind_bin_edges, wind_bins_of
from vivbench.preprocess.yaw import event_yaw  # re-exported: analysis is where campaign scripts look
from vivbench.preprocess.wind_smoothing import smooth_wind  # re-exported, likewise

__all__ = [
    "KERNELS", "DensityPeaks", "coefficient_features", "decision_graph", "order_features", "IdentifyConfig",
    "identify_event", "identify_files", "FEATURE_SETS", "ClusterConfig", "CampaignWindows", "ClusterResult",
    "campaign_windows", "cluster_scores", "cluster_windows", "standardized_coefficients",
    "summarize_clusters", "CAMPAIGN_DERIVATIVE", "pool_results", "records_from_results",
    "with_campaign_model", "campaign_model_file", "load_campaign_model", "campaign_wind_smoothing", "event_yaw", "smooth_wind", "with_yaw",
    "CRITERIA", "VARYING_OPTIONS", "MODEL_CLASSES", "POOLED_COMPLEXITY", "VARYING_PRIORS", "Candidate", "LIMIT_TIME_CONSTANTS", "ModelSelection", "SINGLE_SECTION_SHARE", "STRUCTURAL_OPTIONS", "event_folds", "held_out_loss", "held_out_losses",
    "RANK_LEVEL", "confidence_set", "one_se_set", "rank_p_values", "perturbed_wind", "shared_groups", "variant_params", "fit_group", "held_out_task", "fit_task",
    "varying_selection", "wind_error_scale", "without_yaw", "yaw_free_counterpart", "settle_candidates",
    "amplitude_slope", "envelope_time_constant", "short_events", "valid_span",
    "WIND_BINS", "dynamics_by_wind", "window_wind", "wind_bin_edges", "wind_bins_of",
    "GreyBoxOutcome", "campaign_warm_start", "greybox_results", "results_frequency",
]
