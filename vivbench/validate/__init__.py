"""How well the identification chain recovers the truth of synthetic campaigns."""

from vivbench.validate.pooled import pooled_recovery
from vivbench.validate.recovery import campaign_recovery, regime_scores, rhs_relative_error, truth_window_regimes

__all__ = ["campaign_recovery", "pooled_recovery", "regime_scores", "rhs_relative_error", "truth_window_regimes"]
