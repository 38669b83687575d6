"""Models that turn data into dynamics: window SINDy, the campaign model, simulation and forecasts, refits."""

from vivbench.models.campaign import PooledSINDy, amplitude_ratios, RATIO_LEVEL
from vivbench.models.binned import BinnedPolynomial
from vivbench.models.campaign_files import campaign_model_file, load_campaign_model
from vivbench.models.curve_support import (EXTRAPOLATED, curves_inside_data, data_wind_range, extrapolated_mask,
                                           mark_extrapolated)
from vivbench.models.greybox import BridgeProperties, GreyBoxRefit, curves_to_functions
from vivbench.models.integrate import Integration, StopRule, rk4
from vivbench.models.protocol import (
    Method,
    FittedModel,
    Predictor,
    Simulator,
    CampaignLevel,
    Persistent,
    HasEquations,
    ModelBase,
    NotFittedError,
    as_record,
    fit_records,
    coef_order_contributions,
    format_equations,
    section_names,
    simulate_windows,
    model_summary,
    model_size,
    model_for_records,
    model_change_inputs,
    recorded_change_scan,
    simulate_many,
    transforms_wind,
    model_curves,
    model_class_path,
    model_description,
    chosen_model,
    model_evidence,
    model_settings_text,
    IDENTIFIABLE_LONG_NAME,
)
from vivbench.models.refit import (
    RefitConfig,
    RefitResult,
    EventRefit,
    refit_coefficients,
    refit_event,
    simulate_coefficients,
    order_rms,
)
from vivbench.models.simulate import (
    CLIP_MODES,
    Simulation,
    model_jacobian,
    simulate_identified,
    window_ranges,
    forecast,
    forecast_coefficients,
    forecast_table,
    nmse,
    window_in_force,
)
from vivbench.models.pysindy_adapter import OTHER_TERMS, PySINDyCampaign, PySINDyCP, PySINDyWindows, term_orders
from vivbench.models.pysindy_variants import (ENSEMBLE_AGGREGATES, PySINDyEnsemble, PySINDySBR, PySINDyWeak,
                                              sbr_available)
from vivbench.models.varying import ORDER_SET_MARGIN, VaryingCoefficientSINDy
from vivbench.models.campaign_verdicts import (WindowRecord, campaign_window_verdicts, pooled_window_stats,
                                               window_record, window_stats, window_sums)
from vivbench.models.varying_verdicts import (gram_order_stats, varying_description, varying_summary,
                                              varying_window_verdicts, window_grams, window_order_stats)
from vivbench.models.wind_weights import modal_wind_weights, weighted_section_mean
from vivbench.models.model_input import measured_input
from vivbench.models.quasi_steady import QuasiSteadyAmplitude
from vivbench.models.window import WindowProblem, EventWindowSINDy
from vivbench.models.window_model import WindowSINDy, nearest_window

__all__ = [
    "QuasiSteadyAmplitude", "campaign_model_file", "load_campaign_model",
    "BridgeProperties", "GreyBoxRefit", "curves_to_functions", "BinnedPolynomial",
    "EXTRAPOLATED", "curves_inside_data", "data_wind_range", "extrapolated_mask", "mark_extrapolated",
    "PooledSINDy", "WindowRecord", "amplitude_ratios", "pooled_window_stats",
    "window_record", "window_stats", "window_sums", "RATIO_LEVEL", "Method", "FittedModel", "Predictor",
    "Simulator", "CampaignLevel", "Persistent", "HasEquations", "ModelBase", "NotFittedError", "as_record",
    "fit_records",
    "coef_order_contributions", "format_equations", "section_names", "simulate_windows", "RefitConfig",
    "RefitResult", "EventRefit", "refit_coefficients", "refit_event", "simulate_coefficients", "order_rms",
    "CLIP_MODES", "Simulation", "model_jacobian", "simulate_identified", "window_ranges", "forecast",
    "forecast_coefficients", "forecast_table", "nmse", "window_in_force", "WindowProblem", "EventWindowSINDy",
    "WindowSINDy", "nearest_window", "VaryingCoefficientSINDy", "ORDER_SET_MARGIN", "modal_wind_weights", "weighted_section_mean",
    "measured_input", "Integration", "StopRule", "rk4",
    "model_summary", "model_size", "model_for_records", "model_change_inputs", "recorded_change_scan", "simulate_many", "transforms_wind", "model_curves",
    "model_class_path", "model_description", "chosen_model", "model_evidence", "model_settings_text", "IDENTIFIABLE_LONG_NAME", "varying_description", "campaign_window_verdicts", "gram_order_stats", "varying_summary",
    "varying_window_verdicts", "window_grams", "window_order_stats",
    "OTHER_TERMS", "PySINDyCampaign", "PySINDyCP", "PySINDyWindows", "term_orders",
    "ENSEMBLE_AGGREGATES", "PySINDyEnsemble", "PySINDySBR", "PySINDyWeak", "sbr_available",
]
