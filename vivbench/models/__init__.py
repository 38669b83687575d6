"""Models that turn data into dynamics: window SINDy, the campaign model, simulation and forecasts, refits."""

from vivbench.models.campaign import PooledSINDy, pooled_window_stats
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
from vivbench.models.window import WindowProblem, WindowedSINDy

__all__ = [
    "PooledSINDy", "pooled_window_stats", "RefitConfig", "RefitResult", "EventRefit", "refit_coefficients",
    "refit_event", "simulate_coefficients", "order_rms", "CLIP_MODES", "Simulation", "model_jacobian",
    "simulate_identified", "window_ranges", "forecast", "forecast_coefficients", "forecast_table", "nmse",
    "window_in_force", "WindowProblem", "WindowedSINDy",
]
