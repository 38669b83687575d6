"""The regime rule applied to models and to the truth, and identifiability verdicts (docs/concepts.md (regimes))."""

from vivbench.models.campaign_verdicts import campaign_window_verdicts
from vivbench.regimes.greybox import greybox_draws, greybox_window_verdicts
from vivbench.regimes.model import measured_verdicts, model_verdicts, model_window_regimes
from vivbench.regimes.truth import truth_window_regimes
from vivbench.models.varying_verdicts import gram_order_stats, varying_window_verdicts, window_grams, window_order_stats
from vivbench.regimes.window import label_windows, window_regimes

__all__ = [
    "campaign_window_verdicts", "model_window_regimes", "truth_window_regimes", "label_windows",
    "window_regimes", "varying_window_verdicts", "window_order_stats", "greybox_draws", "greybox_window_verdicts",
    "window_grams", "gram_order_stats", "measured_verdicts", "model_verdicts",
]
