"""The grey-box file ``greybox.nc`` (format ``"vivbench-greybox"``): the fitted grey-box refit and its curves.

Written by :meth:`vivbench.models.GreyBoxRefit.save` (``vivbench greybox``
saves it as :data:`GREYBOX_NAME`), read and checked by :func:`read_greybox`
(and :meth:`~vivbench.models.GreyBoxRefit.load`). It holds everything the
model needs (spline knots and coefficients, their covariance, the bridge's
properties, mode shape and participation factors) and, on the wind grid of
the fitted data, the physical curves Y1, e1, e2, C_L with their bands and
the coefficient curves ``curves`` of docs/concepts.md (coefficient curves) with ``curves_lower`` and
``curves_upper`` (all at yaw 0), and the yaw factor: ``yaw_coef`` c of
1 - c sin^2(yaw) on Y1 and C_L with its band and ``yaw_factor`` against
``yaw`` (degrees); attribute ``yaw_used`` (0: not fitted, factor 1, and files
written before the yaw factor), ``yaw_model`` says how. Documented in
``docs/formats.md``.
"""

from __future__ import annotations

from pathlib import Path

import xarray as xr

from vivbench.io.model_file import ModelFileError, read_model_dataset
from vivbench.io.netcdf import write_netcdf_atomic

__all__ = ["GREYBOX_NAME", "GREYBOX_FORMAT", "GREYBOX_VERSION", "GREYBOX_VARIABLES", "GREYBOX_ATTRIBUTES",
           "write_greybox", "read_greybox"]

GREYBOX_NAME = "greybox.nc"
GREYBOX_FORMAT = "vivbench-greybox"
GREYBOX_VERSION = 1

_FUNCTIONS = ("Y1", "e1", "e2", "C_L")

#: Variables of a grey-box file and their dimensions.
GREYBOX_VARIABLES = {
    "coef": ("function", "basis"),
    "coef_cov": ("parameter", "parameter_"),
    "knots": ("knot",),
    "mode_shape": ("section",),
    "participation": ("section",),
    "curves": ("equation", "order", "wind"),
    "curves_lower": ("equation", "order", "wind"),
    "curves_upper": ("equation", "order", "wind"),
    "reduced_velocity": ("wind",),
    **{f"{name}{suffix}": ("wind",) for name in _FUNCTIONS for suffix in ("", "_lower", "_upper")},
}

#: Root attributes a grey-box file must carry (besides ``format`` and ``format_version``).
GREYBOX_ATTRIBUTES = ("model", "bridge_json", "params_json", "fit_info_json", "wind_min", "wind_max")


def _check(ds: xr.Dataset, path) -> None:
    M = ds.sizes["basis"]
    P = 4 * M + int(bool(int(ds.attrs.get("yaw_used", 0))))  # the yaw coefficient last, when fitted
    if ds.sizes["function"] != 4 or ds.sizes["parameter"] != P or ds.sizes["parameter_"] != P:
        raise ModelFileError(f"{path}: coef must be (4, M) and coef_cov (P, P) with P = 4 M (+1 with the yaw "
                             f"coefficient, attribute yaw_used = 1); got {dict(ds.sizes)}")
    if ds.sizes["knot"] != M + 4:
        raise ModelFileError(f"{path}: {M} cubic B-splines need {M + 4} knots; got {ds.sizes['knot']}")
    if ds.sizes["section"] != ds.sizes["equation"] or ds.sizes["order"] != 4:
        raise ModelFileError(f"{path}: section and equation sizes must match and order must have 4 entries")


def write_greybox(ds: xr.Dataset, path) -> Path:
    """Check and write a grey-box dataset (built by ``GreyBoxRefit.to_dataset``) atomically."""
    missing = [v for v in GREYBOX_VARIABLES if v not in ds.variables]
    missing += [a for a in GREYBOX_ATTRIBUTES if a not in ds.attrs]
    if missing:
        raise ValueError(f"a grey-box dataset needs {', '.join(missing)}")
    for name, dims in GREYBOX_VARIABLES.items():
        if tuple(ds[name].dims) != dims:
            raise ValueError(f"grey-box variable {name} must have dimensions {dims}; got {ds[name].dims}")
    _check(ds, "grey-box dataset")
    ds = ds.copy()
    ds.attrs.update(format=GREYBOX_FORMAT, format_version=GREYBOX_VERSION)
    return Path(write_netcdf_atomic(ds, Path(path)))


def read_greybox(path) -> xr.Dataset:
    """Load and check a grey-box file.

    Raises
    ------
    ModelFileError
        One line naming the file: missing, unreadable, another format or a
        newer version, lacking a variable or attribute, inconsistent sizes.
    """
    ds = read_model_dataset(path, fmt=GREYBOX_FORMAT, max_version=GREYBOX_VERSION, variables=GREYBOX_VARIABLES,
                            what="grey-box")
    missing = [a for a in GREYBOX_ATTRIBUTES if a not in ds.attrs]
    if missing:
        raise ModelFileError(f"{path}: grey-box file lacks the attribute(s) {', '.join(missing)}")
    _check(ds, path)
    return ds
