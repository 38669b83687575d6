"""The regime rule applied to models and to the truth, and identifiability verdicts (DESIGN 2.5)."""

from vivbench.regimes.truth import truth_window_regimes
from vivbench.regimes.window import label_windows, window_regimes
from vivbench.regimes.model import model_window_regimes

__all__ = [
    "truth_window_regimes", "label_windows", "window_regimes", "model_window_regimes",
]
