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
from vivbench.validate.recovery import campaign_recovery, regime_scores, rhs_relative_error, truth_window_regimes

__all__ = [
    "BASE_LEVELS", "DESIGNS", "FACTORS", "CompareConfig", "CompareResult", "compare_cells", "compare_config_from_dict",
    "load_compare_config", "plan", "run_comparison",
    "campaign_recovery", "regime_scores", "rhs_relative_error", "truth_window_regimes",
]
