"""Regression: batched least squares, penalised least squares from sufficient statistics, confidence sets of
models, the block bootstrap's resampling, the STLSQ threshold path
with AICc, pysindy-backed optimisers."""

from vivbench.regression.bootstrap import DRAWS, block_counts
from vivbench.regression.lstsq import NestedFactors, as_batches, empty_path
from vivbench.regression.optimizers import (
    OPTIMIZERS,
    OptimizerOptions,
    run_optimizer,
    sr3_path,
    ensemble_path,
)
from vivbench.regression.model_set import MODEL_SET_TESTS, confidence_set
from vivbench.regression.permutation import permutation_p_value, stratified_permutations
from vivbench.regression.penalised import (DEFAULT_RIDGE, held_out_errors, penalised_rss, penalised_solve,
                                           penalty_scale, quadratic_error, spd_solve)
from vivbench.regression.settings import DEFAULT_THRESHOLDS, SOLVERS, StlsqSettings
from vivbench.regression.stlsq import StlsqPath, aicc, stlsq_path

__all__ = [
    "NestedFactors", "as_batches", "empty_path", "OPTIMIZERS", "OptimizerOptions", "run_optimizer",
    "sr3_path", "ensemble_path", "DEFAULT_THRESHOLDS", "SOLVERS", "StlsqSettings", "StlsqPath", "aicc",
    "stlsq_path", "DEFAULT_RIDGE", "held_out_errors", "penalised_rss", "penalised_solve", "penalty_scale",
    "quadratic_error", "spd_solve", "MODEL_SET_TESTS", "confidence_set", "DRAWS",
    "block_counts", "permutation_p_value", "stratified_permutations",
]
