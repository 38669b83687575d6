"""Window-model files: the per-event window coefficients of :class:`vivbench.models.WindowSINDy`.

Format ``"vivbench-window-model"``, version :data:`WINDOW_MODEL_VERSION`:
coordinates ``event`` (event ids), ``equation``, ``feature``; per window
(dimension ``window``, all events concatenated) ``coef`` (window, equation,
feature) in physical units (dA/dt in m/s), ``window_start`` and
``window_end`` (s), ``window_event`` (index into ``event``), ``threshold``,
``n_terms``, ``rss``, ``aicc`` (window, equation); attribute ``params_json``.
"""

from __future__ import annotations

from pathlib import Path

import xarray as xr

from vivbench.io.model_file import ModelFileError, read_model_dataset
from vivbench.io.netcdf import write_netcdf_atomic

__all__ = ["WINDOW_MODEL_FORMAT", "WINDOW_MODEL_VERSION", "write_window_model", "read_window_model"]

WINDOW_MODEL_FORMAT = "vivbench-window-model"
WINDOW_MODEL_VERSION = 1

_VARIABLES = {
    "coef": ("window", "equation", "feature"),
    "window_start": ("window",),
    "window_end": ("window",),
    "window_event": ("window",),
    "threshold": ("window", "equation"),
    "n_terms": ("window", "equation"),
    "rss": ("window", "equation"),
    "aicc": ("window", "equation"),
}


def write_window_model(ds: xr.Dataset, path) -> Path:
    """Check and write a window-model file atomically (``format`` attributes are set here)."""
    missing = [v for v in _VARIABLES if v not in ds.variables]
    if missing or "event" not in ds.coords or "params_json" not in ds.attrs:
        raise ValueError(f"a window model dataset needs {', '.join(missing + ['event', 'params_json'])}")
    ds = ds.copy()
    ds.attrs.update(format=WINDOW_MODEL_FORMAT, format_version=WINDOW_MODEL_VERSION)
    return Path(write_netcdf_atomic(ds, Path(path)))


def read_window_model(path) -> xr.Dataset:
    """Load and check a window-model file.

    Raises
    ------
    ModelFileError
        One line naming the file and what is wrong.
    """
    ds = read_model_dataset(path, fmt=WINDOW_MODEL_FORMAT, max_version=WINDOW_MODEL_VERSION, variables=_VARIABLES,
                            what="window model")
    S, p = ds.sizes["equation"], ds.sizes["feature"]
    if p != 23 * S:
        raise ModelFileError(f"{path}: feature must have 23 x equation = {23 * S} entries; got {p}")
    if "event" not in ds.coords or "params_json" not in ds.attrs:
        raise ModelFileError(f"{path}: window model lacks the event coordinate or the params_json attribute")
    ev = ds["window_event"].values
    if ev.size and (ev.min() < 0 or ev.max() >= ds.sizes["event"]):
        raise ModelFileError(f"{path}: window_event must index the event coordinate (0..{ds.sizes['event'] - 1})")
    return ds
