"""Definitions every stage shares: library terms, the regime rule (docs/concepts.md (regimes)), TOML and parallel helpers."""

from vivbench.core.terms import (
    A_POWERS,
    U_POWERS,
    SECTIONS,
    reference_section,
    section_exponents,
    feature_exponents,
    feature_names,
    evaluate_library,
)
from vivbench.core.record import Record
from vivbench.core.regime import DEFAULT_TAU, classify_regime, order_rms, regime_rule
from vivbench.core.errors import InputError, error_line, require
from vivbench.core.toml import load_toml
from vivbench.core.parallel import Outcome, run_tasks, parse_scheduler
from vivbench.core.lock import exclusive_directory
from vivbench.core.steps import EXTRA_STEPS
from vivbench.core.intervals import threshold_intervals
from vivbench.core.wind_spectra import davenport_coherence, kaimal_psd

__all__ = [
    "exclusive_directory", "EXTRA_STEPS", "threshold_intervals", "davenport_coherence", "kaimal_psd",
    "A_POWERS", "U_POWERS", "SECTIONS", "reference_section", "section_exponents", "feature_exponents",
    "feature_names", "evaluate_library", "Record", "DEFAULT_TAU", "classify_regime", "order_rms",
    "regime_rule", "InputError", "error_line", "require", "load_toml", "Outcome", "run_tasks", "parse_scheduler",
]
