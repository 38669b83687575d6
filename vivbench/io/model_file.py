"""Checks shared by the model files (campaign model, window model, campaign regimes): one-line errors naming the file."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np
import xarray as xr

from vivbench.core.errors import InputError
from vivbench.io.netcdf import NETCDF_ENGINE

__all__ = ["ModelFileError", "read_model_dataset"]


class ModelFileError(InputError):
    """A model file is missing, unreadable, of another format or version, or lacks a variable."""


def read_model_dataset(path, *, fmt: str | tuple[str, ...], max_version: int, variables: Mapping[str, tuple[str, ...]],
                       what: str) -> xr.Dataset:
    """Load a model file into memory and check its format, version and variables.

    Parameters
    ----------
    path : str or Path
    fmt : str or tuple of str
        Required value of the ``format`` attribute (a tuple: any of them, e.g.
        a format's current name and the one earlier versions wrote).
    max_version : int
        Newest ``format_version`` this reader understands (>= 1).
    variables : mapping of name to dims
        Variables the file must hold, each with exactly these dimensions.
    what : str
        What the file is, for messages ("campaign model").

    Returns
    -------
    xarray.Dataset, loaded (the file is closed)

    Raises
    ------
    ModelFileError
        One line naming the file and what is wrong.
    """
    path = Path(path)
    if not path.is_file():
        raise ModelFileError(f"{path}: no such {what} file")
    try:
        with xr.open_dataset(path, engine=NETCDF_ENGINE) as ds:
            ds = ds.load()
    except Exception as exc:  # noqa: BLE001 - any reader failure means "not such a file"
        raise ModelFileError(f"{path}: cannot be read as a NetCDF-4 {what} ({type(exc).__name__})") from exc
    formats = (fmt,) if isinstance(fmt, str) else tuple(fmt)
    if ds.attrs.get("format") not in formats:
        raise ModelFileError(f"{path}: not a {what} file (format attribute is {ds.attrs.get('format')!r}, "
                             f"expected {formats[0]!r})")
    try:
        version = int(ds.attrs.get("format_version"))
    except (TypeError, ValueError):
        raise ModelFileError(f"{path}: format_version attribute missing or not an integer") from None
    if not 1 <= version <= max_version:
        raise ModelFileError(f"{path}: {what} format_version {version} is not supported (1..{max_version})")
    missing = [v for v in variables if v not in ds.variables]
    if missing:
        raise ModelFileError(f"{path}: {what} lacks {', '.join(missing)}")
    for name, dims in variables.items():
        if tuple(ds[name].dims) != tuple(dims):
            raise ModelFileError(f"{path}: {name} must have dimensions {dims}; got {tuple(ds[name].dims)}")
        if np.dtype(ds[name].dtype).kind not in "fiubOUS":
            raise ModelFileError(f"{path}: {name} has unexpected type {ds[name].dtype}")
    return ds
