"""How well the identification chain recovers the truth of synthetic campaigns."""

from vivbench.validate.plateau import Plateau, clearest_plateau, measured_plateau, truth_plateau
from vivbench.validate.recovery import campaign_recovery, regime_scores, rhs_relative_error, truth_window_regimes

__all__ = ["campaign_recovery", "regime_scores", "rhs_relative_error", "truth_window_regimes",
           "Plateau", "clearest_plateau", "measured_plateau", "truth_plateau"]
