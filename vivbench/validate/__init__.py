"""How well the identification chain recovers the truth of synthetic campaigns."""

from vivbench.validate.recovery import campaign_recovery, regime_scores, rhs_relative_error, truth_window_regimes
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
    "METRIC_COLUMNS", "SWEEP_PARAMETERS", "SweepConfig", "SweepResult", "SweepTask", "campaign_recovery",
    "load_sweep_config", "plot_recovery", "regime_scores", "rhs_relative_error", "run_sweep", "run_sweep_task",
    "sweep_config_from_dict", "sweep_summary", "sweep_tasks", "truth_window_regimes",
]
