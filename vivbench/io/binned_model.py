"""Files of the binned baseline (:class:`vivbench.models.BinnedPolynomial`), format ``"vivbench-binned-model"``.

Written by ``BinnedPolynomial.save``, read by :func:`read_binned_model` (``BinnedPolynomial.load``).
Variables: ``bins`` (bin) the indices b of the fitted wind bins, ``coef`` (bin, equation, power) the
coefficients c_bki in m^(1-i)/s (NaN for empty bin-equations), ``n_fit`` (bin, equation) the samples of
each bin-equation, ``wind_range`` (bound) in m/s. Attributes: ``model``, ``params_json`` (the constructor's
parameters), ``format`` / ``format_version``.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import xarray as xr

from vivbench.io.model_file import ModelFileError, read_model_dataset
from vivbench.io.netcdf import write_netcdf_atomic

__all__ = ["BINNED_MODEL_FORMAT", "BINNED_MODEL_VERSION", "BINNED_MODEL_NAME", "binned_model_dataset",
           "write_binned_model", "read_binned_model"]

BINNED_MODEL_FORMAT = "vivbench-binned-model"
BINNED_MODEL_VERSION = 1
#: The ``model`` attribute of the file.
BINNED_MODEL_NAME = "BinnedPolynomial"

_VARIABLES = {"bins": ("bin",), "coef": ("bin", "equation", "power"), "n_fit": ("bin", "equation"),
              "wind_range": ("bound",)}


def binned_model_dataset(fitted: Mapping[str, object], *, params_json: str, equations) -> xr.Dataset:
    """The file's dataset from the fitted attributes ``bins_``, ``coef_``, ``n_fit_``, ``wind_range_``."""
    data = {"bins": (("bin",), np.asarray(fitted["bins_"], dtype=np.int64)),
            "coef": (("bin", "equation", "power"), np.asarray(fitted["coef_"], dtype=float),
                     {"units": "m^(1-power) s-1"}),
            "n_fit": (("bin", "equation"), np.asarray(fitted["n_fit_"], dtype=np.int64)),
            "wind_range": (("bound",), np.asarray(fitted["wind_range_"], dtype=float), {"units": "m/s"})}
    attrs = {"model": BINNED_MODEL_NAME, "params_json": params_json, "format": BINNED_MODEL_FORMAT,
             "format_version": BINNED_MODEL_VERSION}
    return xr.Dataset(data, coords={"equation": list(equations)}, attrs=attrs)


def write_binned_model(ds: xr.Dataset, path) -> Path:
    """Write a binned-model dataset (:func:`binned_model_dataset`, which carries the format) atomically."""
    if ds.attrs.get("format") != BINNED_MODEL_FORMAT:
        raise ValueError(f"not a binned-model dataset (format attribute {ds.attrs.get('format')!r})")
    return Path(write_netcdf_atomic(ds, Path(path)))


def read_binned_model(path) -> tuple[dict, dict]:
    """The constructor's parameters and the fitted attributes (``bins_``, ``coef_``, ``n_fit_``, ``wind_range_``,
    ``n_sections_``) of a binned-model file.

    Raises
    ------
    ModelFileError
        One line naming the file: missing, unreadable, of another format, version or model, lacking a part.
    """
    ds = read_model_dataset(path, fmt=BINNED_MODEL_FORMAT, max_version=BINNED_MODEL_VERSION, variables=_VARIABLES,
                            what="binned model")
    if ds.attrs.get("model") != BINNED_MODEL_NAME or "params_json" not in ds.attrs:
        raise ModelFileError(f"{path}: not a {BINNED_MODEL_NAME} file with its params_json attribute")
    fitted = {"bins_": np.asarray(ds["bins"].values).astype(int), "coef_": np.asarray(ds["coef"].values, dtype=float),
              "n_fit_": np.asarray(ds["n_fit"].values).astype(int),
              "wind_range_": np.asarray(ds["wind_range"].values, dtype=float), "n_sections_": int(ds.sizes["equation"])}
    return json.loads(ds.attrs["params_json"]), fitted
