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
from vivbench.io.result import ResultFormatError, build_result, list_results, result_path, read_result, write_result
from vivbench.io.campaign_model import POOLED_NAME, write_pooled
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
from vivbench.io.fieldimport import import_event, load_mapping, export_csv, export_mat, TIME_FORMATS

__all__ = [
    "NETCDF_ENGINE", "atomic_path", "write_netcdf_atomic", "EventFormatError", "FORMAT", "FORMAT_VERSION",
    "NOMINAL_RATES", "COEF_UNITS", "build_event", "validate_event", "write_event", "read_event",
    "event_arrays", "list_events", "EventSummary", "read_event_summary", "peek_event_id", "ResultFormatError",
    "build_result", "list_results", "result_path", "read_result", "write_result", "POOLED_NAME",
    "write_pooled", "G", "MAX_ACC_RMS", "MAX_WIND_SPEED", "MIN_WIND_STD", "ACC_UNITS", "WIND_UNITS",
    "despike", "check_acc_magnitude", "check_wind_magnitude", "check_wind_varies", "import_event",
    "load_mapping", "export_csv", "export_mat", "TIME_FORMATS",
]
