"""The identification-result files ``<event_id>.identify.nc``."""

from __future__ import annotations

from pathlib import Path

import xarray as xr

from vivbench.io.netcdf import NETCDF_ENGINE
from vivbench.core.errors import InputError

__all__ = ["list_results", "result_path", "read_result"]

def list_results(results_dir) -> list[Path]:
    """The ``<event_id>.identify.nc`` files of a directory, sorted.

    Raises
    ------
    ValueError
        The directory does not exist or holds no result file (the message names it).
    """
    d = Path(results_dir)
    if not d.is_dir():
        raise InputError(f"{d}: not a directory of identification results")
    files = sorted(d.glob("*.identify.nc"))
    if not files:
        raise InputError(f"{d}: no identification results (<event_id>.identify.nc) in this directory")
    return files


def result_path(out_dir: str | Path, event_id: str) -> Path:
    """Where the result of event ``event_id`` is written in ``out_dir``."""
    return Path(out_dir) / f"{event_id}.identify.nc"



_REQUIRED = ("coef", "order_rms", "regime", "window_start", "window_end", "A", "U", "dA")


def read_result(path) -> xr.Dataset:
    """Load an identification result into memory and check what later stages read.

    Raises
    ------
    ValueError
        One line naming the file: missing, unreadable, or lacking a variable.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such result file")
    try:
        with xr.open_dataset(path, engine=NETCDF_ENGINE) as ds:
            ds = ds.load()
    except Exception as exc:  # noqa: BLE001 - any reader failure means "not a result file"
        raise InputError(f"{path}: cannot be read as a NetCDF-4 result ({type(exc).__name__})") from exc
    if ds.attrs.get("format") != "vivbench-identify":
        raise InputError(f"{path}: not an identification result (format attribute is {ds.attrs.get('format')!r})")
    missing = [v for v in _REQUIRED if v not in ds.variables]
    if missing:
        raise InputError(f"{path}: result lacks {', '.join(missing)}")
    if ds["coef"].ndim != 3 or ds["coef"].shape[2] != 23 * ds["coef"].shape[1]:
        raise InputError(f"{path}: coef must have shape (window, equation, 23 x sections); got {ds['coef'].shape}")
    return ds

