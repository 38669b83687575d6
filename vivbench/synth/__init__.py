"""The synthetic bridge: wind, aeroelastic force, structure, sensors, truth, campaigns."""

from vivbench.synth.aero import (
    aero_functions,
    amplitude_coefficients,
    amplitude_polynomials,
    exact_coefficients,
    modal_coefficients,
    order_contributions,
    truth_curves,
)
from vivbench.synth.campaign import SCENARIOS, CampaignConfig, CampaignResult, campaign_specs, draw_script, generate_campaign
from vivbench.synth.config import (
    AERO_MODES,
    AeroConfig,
    ChangesConfig,
    DefectConfig,
    GeneratorConfig,
    Polynomial,
    SensorConfig,
    StructureConfig,
    WindConfig,
    bell_polynomial,
    config_from_dict,
    config_to_dict,
    load_config,
)
from vivbench.synth.curves import (
    CURVE_KINDS,
    YAW_SHAPES,
    AsymmetricBell,
    Constant,
    GaussianBell,
    LogisticStep,
    LorentzianBell,
    YawFactor,
    scaled_bell,
    curve_from_data,
    reduced_velocity,
)
from vivbench.synth.draw import draw_aero
from vivbench.synth.family import (
    E_MIX_SHARES,
    E_MIXES,
    FAMILY_ENTROPY,
    FAMILY_FILE,
    FAMILY_VERSION,
    SPLITS,
    FamilyDraw,
    draw_bridge,
    draw_yaw_effect,
    family_seed,
    generate_family_campaign,
)
from vivbench.synth.continuous_log import ContinuousLog, ContinuousLogConfig, generate_continuous_log, write_continuous_log
from vivbench.synth.event import EventSpec, SimulatedEvent, generate_event, simulate_event
from vivbench.synth.turbulence import TurbulenceConfig, davenport_coherence, kaimal_psd, simulate_turbulence
from vivbench.synth.wind import MeanWind, WindScript, anemometer_records, mean_wind

__all__ = [
    "AeroConfig", "CampaignConfig", "ChangesConfig", "amplitude_coefficients", "CampaignResult", "DefectConfig", "EventSpec", "GeneratorConfig",
    "MeanWind", "Polynomial", "SCENARIOS", "SensorConfig", "SimulatedEvent", "StructureConfig",
    "TurbulenceConfig", "WindConfig", "WindScript", "amplitude_polynomials", "anemometer_records",
    "bell_polynomial", "campaign_specs", "config_from_dict", "config_to_dict", "davenport_coherence",
    "draw_script", "exact_coefficients", "generate_campaign", "generate_event", "kaimal_psd", "load_config",
    "mean_wind", "modal_coefficients", "order_contributions", "simulate_event", "simulate_turbulence",
    "AERO_MODES", "AsymmetricBell", "CURVE_KINDS", "YAW_SHAPES", "Constant", "GaussianBell", "LogisticStep", "LorentzianBell", "YawFactor", "scaled_bell",
    "aero_functions", "curve_from_data", "draw_aero", "reduced_velocity", "truth_curves",
    "E_MIXES", "E_MIX_SHARES", "FAMILY_ENTROPY", "FAMILY_FILE", "FAMILY_VERSION", "SPLITS", "FamilyDraw", "draw_bridge", "draw_yaw_effect", "family_seed",
    "generate_family_campaign", "ContinuousLog", "ContinuousLogConfig", "generate_continuous_log",
    "write_continuous_log",
]
