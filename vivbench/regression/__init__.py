"""Sparse regression: batched least squares, the STLSQ threshold path with AICc, pysindy-backed optimisers."""

from vivbench.regression.optimizers import (
    OPTIMIZERS,
    OptimizerOptions,
    run_optimizer,
    sr3_path,
    ensemble_path,
)
from vivbench.regression.stlsq import DEFAULT_THRESHOLDS, SOLVERS, StlsqSettings, StlsqPath, aicc, stlsq_path

__all__ = [
    "OPTIMIZERS", "OptimizerOptions", "run_optimizer", "sr3_path", "ensemble_path", "DEFAULT_THRESHOLDS",
    "SOLVERS", "StlsqSettings", "StlsqPath", "aicc", "stlsq_path",
]
