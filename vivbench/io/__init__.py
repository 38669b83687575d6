"""File formats (one owner per schema: events, identification results, campaign models), field import, data quality."""

from vivbench.io.netcdf import NETCDF_ENGINE, atomic_path, write_netcdf_atomic
from vivbench.io.event import (
    EventFormatError,
    FORMAT,
    FORMAT_VERSION,
    NOMINAL_RATES,
    COEF_UNITS,
    build_event,
    validate_event,
    write_event,
    read_event,
    event_arrays,
    list_events,
    EventSummary,
    read_event_summary,
    peek_event_id,
)
from vivbench.io.event_schema import CHANGE_VARIABLES, CURVE_UNITS, EVENT_ID_PATTERN, validate_root_attributes
from vivbench.io.result import (
    FEATURES_PER_SECTION,
    VariableSpec,
    VARIABLES,
    COORDINATES,
    ATTRIBUTES,
    WINDOW_FIT_VARIABLES,
    ResultFormatError,
    build_result,
    write_result,
    read_result,
    list_results,
    select_results,
    result_path,
    result_noise_std,
    result_wind_distance,
    result_record,
    markdown_table,
    markdown_attributes,
)
from vivbench.io.model_file import ModelFileError, read_model_dataset
from vivbench.io.greybox import (
    GREYBOX_NAME,
    GREYBOX_FORMAT,
    GREYBOX_VERSION,
    write_greybox,
    read_greybox,
)
from vivbench.io.campaign_model import (
    REGIMES_NAME,
    LEGACY_REGIMES_NAME,
    MODEL_NAME,
    REGIMES_FORMAT,
    LEGACY_REGIMES_FORMAT,
    CAMPAIGN_MODEL_FORMAT,
    CAMPAIGN_MODEL_VERSION,
    regimes_file,
    write_campaign_regimes,
    read_campaign_regimes,
    CAMPAIGN_MODEL_CLASSES,
    regimes_model_name,
    write_campaign_model,
    read_campaign_model,
)
from vivbench.io.window_model import (
    WINDOW_MODEL_FORMAT,
    WINDOW_MODEL_VERSION,
    write_window_model,
    read_window_model,
)
from vivbench.io.varying_model import (
    VARYING_MODEL_FORMAT,
    VARYING_MODEL_VERSION,
    varying_model_dataset,
    write_varying_model,
    read_varying_model,
)
from vivbench.io.pysindy_model import (
    PYSINDY_MODEL_FORMAT,
    PYSINDY_MODEL_VERSION,
    pysindy_model_dataset,
    write_pysindy_model,
    read_pysindy_model,
)
from vivbench.io.binned_model import (
    BINNED_MODEL_FORMAT,
    BINNED_MODEL_VERSION,
    binned_model_dataset,
    write_binned_model,
    read_binned_model,
)
from vivbench.io.quality import (
    G,
    MAX_ACC_RMS,
    MAX_WIND_SPEED,
    MIN_WIND_STD,
    ACC_UNITS,
    WIND_UNITS,
    despike,
    check_acc_magnitude,
    check_wind_magnitude,
    check_wind_varies,
)
from vivbench.io.fieldimport import import_event, load_mapping, TIME_FORMATS
from vivbench.io.field_resample import PLAUSIBLE_RATES, FIELD_RATE_TOLERANCE, measured_rate, regular_grid, resample_to_grid
from vivbench.io.field_wind import WIND_FORMATS, WIND_RULES, span_weights, to_east_north_up
from vivbench.io.field_export import export_csv, export_mat

__all__ = [
    "NETCDF_ENGINE", "atomic_path", "write_netcdf_atomic", "EventFormatError", "FORMAT", "FORMAT_VERSION",
    "NOMINAL_RATES", "COEF_UNITS", "build_event", "validate_event", "write_event", "read_event",
    "event_arrays", "list_events", "EventSummary", "read_event_summary", "peek_event_id",
    "CHANGE_VARIABLES", "CURVE_UNITS", "EVENT_ID_PATTERN", "validate_root_attributes",
    "FEATURES_PER_SECTION", "VariableSpec", "VARIABLES", "COORDINATES", "ATTRIBUTES", "WINDOW_FIT_VARIABLES",
    "ResultFormatError", "build_result", "write_result", "read_result", "list_results", "select_results", "result_path",
    "result_record", "result_noise_std", "result_wind_distance", "markdown_table", "markdown_attributes", "ModelFileError", "read_model_dataset",
    "REGIMES_NAME", "LEGACY_REGIMES_NAME", "MODEL_NAME", "REGIMES_FORMAT", "LEGACY_REGIMES_FORMAT",
    "CAMPAIGN_MODEL_FORMAT", "CAMPAIGN_MODEL_VERSION", "regimes_file", "write_campaign_regimes",
    "read_campaign_regimes", "CAMPAIGN_MODEL_CLASSES", "regimes_model_name", "write_campaign_model", "read_campaign_model",
    "GREYBOX_NAME", "GREYBOX_FORMAT", "GREYBOX_VERSION", "write_greybox", "read_greybox",
    "WINDOW_MODEL_FORMAT",
    "WINDOW_MODEL_VERSION", "write_window_model", "read_window_model", "VARYING_MODEL_FORMAT", "VARYING_MODEL_VERSION",
    "varying_model_dataset", "write_varying_model", "read_varying_model", "PYSINDY_MODEL_FORMAT",
    "PYSINDY_MODEL_VERSION", "pysindy_model_dataset", "write_pysindy_model", "read_pysindy_model",
    "BINNED_MODEL_FORMAT", "BINNED_MODEL_VERSION", "binned_model_dataset", "write_binned_model", "read_binned_model",
    "G", "MAX_ACC_RMS", "MAX_WIND_SPEED",
    "MIN_WIND_STD", "ACC_UNITS", "WIND_UNITS", "despike", "check_acc_magnitude", "check_wind_magnitude",
    "check_wind_varies", "import_event", "load_mapping", "export_csv", "export_mat", "TIME_FORMATS",
    "PLAUSIBLE_RATES", "FIELD_RATE_TOLERANCE", "measured_rate", "regular_grid", "resample_to_grid",
    "WIND_FORMATS", "WIND_RULES", "span_weights", "to_east_north_up",
]
