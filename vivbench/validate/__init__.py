"""How well the identification chain recovers the truth of synthetic campaigns, and method comparisons."""

from vivbench.validate.compare import (
    BASE_LEVELS,
    DESIGNS,
    FACTORS,
    CompareConfig,
    CompareResult,
    compare_cells,
    compare_config_from_dict,
    load_compare_config,
    plan,
    run_comparison,
)
from vivbench.validate.campaign import read_cluster_labels, read_forecast_tables, validate_campaign, write_validation
from vivbench.validate.metrics import (
    REGIMES,
    SUPPORT_NOTES,
    cluster_agreement,
    cluster_purity,
    confusion_matrix,
    forecast_summary,
    merge_support_scores,
    order_support,
    pooled_support,
    regime_report,
    rhs_error_summary,
    support_counts,
    support_mask,
    support_scores,
)
from vivbench.validate.plateau import Plateau, clearest_plateau, measured_plateau, truth_plateau
from vivbench.validate.pooled import pooled_recovery
from vivbench.validate.recovery import (
    campaign_recovery,
    model_window_rhs_errors,
    recovery_by_event,
    regime_scores,
    rhs_relative_error,
    window_rhs_errors,
)
from vivbench.regimes.truth import truth_window_regimes
from vivbench.validate.sweep import (
    METRIC_COLUMNS,
    SWEEP_PARAMETERS,
    SweepConfig,
    SweepResult,
    SweepTask,
    load_sweep_config,
    run_sweep,
    run_sweep_task,
    sweep_config_from_dict,
    sweep_tasks,
)
from vivbench.validate.sweep_figures import plot_recovery, sweep_summary

__all__ = [
    "BASE_LEVELS", "DESIGNS", "FACTORS", "CompareConfig", "CompareResult", "compare_cells", "compare_config_from_dict",
    "load_compare_config", "plan", "run_comparison",
    "METRIC_COLUMNS", "SWEEP_PARAMETERS", "SweepConfig", "SweepResult", "SweepTask", "load_sweep_config",
    "plot_recovery", "run_sweep", "run_sweep_task", "sweep_config_from_dict", "sweep_summary", "sweep_tasks",
    "Plateau",
    "clearest_plateau",
    "measured_plateau",
    "truth_plateau",
    "REGIMES",
    "SUPPORT_NOTES",
    "campaign_recovery",
    "cluster_agreement",
    "cluster_purity",
    "confusion_matrix",
    "forecast_summary",
    "merge_support_scores",
    "order_support",
    "pooled_recovery",
    "pooled_support",
    "read_cluster_labels",
    "read_forecast_tables",
    "recovery_by_event",
    "regime_report",
    "regime_scores",
    "rhs_error_summary",
    "rhs_relative_error",
    "support_counts",
    "support_mask",
    "support_scores",
    "truth_window_regimes",
    "validate_campaign",
    "window_rhs_errors",
    "model_window_rhs_errors",
    "write_validation",
]
